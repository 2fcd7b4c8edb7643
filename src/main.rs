//! `vtfarm`: the command-line program. Thin: it parses arguments, loads the
//! job, drives `vtfarm-render` and prints progress and tables.

mod bench;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_render::{FrameSetup, RenderOptions, RenderedFrame, Renderer, output};
use vtfarm_vertex::Quality;

#[derive(Parser)]
#[command(
    name = "vtfarm",
    version,
    about = "Distributed adaptive progressive vertex tracing"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Renders a job to an image (PNG, or linear float32 .npy by extension).
    Render(RenderArgs),
    /// Scene tools.
    #[command(subcommand)]
    Scene(SceneCommand),
    /// Benchmarks.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
}

#[derive(clap::Args)]
struct RenderArgs {
    /// The job file (TOML), e.g. configs/cockpit.toml.
    job: PathBuf,
    /// Output image: .png (8-bit sRGB) or .npy (linear float32).
    #[arg(short, long, default_value = "out.png")]
    output: PathBuf,
    /// Overrides the job's quality level.
    #[arg(long, value_parser = parse_quality)]
    quality: Option<Quality>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Overrides the image width and height.
    #[arg(long)]
    width: Option<u32>,
    #[arg(long)]
    height: Option<u32>,
    /// Writes the auxiliary outputs (mask, reflected component, reflected-object map, wireframe) here.
    #[arg(long)]
    aux: Option<PathBuf>,
    /// Reflector triangles per task package.
    #[arg(long, default_value_t = RenderOptions::default().package_size)]
    package_size: usize,
}

#[derive(Subcommand)]
enum SceneCommand {
    /// Writes a built-in scene as OBJ + MTL.
    Export {
        /// The built-in scene's name (`cockpit`).
        name: String,
        /// Output directory.
        #[arg(short, long)]
        output: PathBuf,
        /// Detail factor (1.0 ≈ 100k triangles, 2.1 ≈ 210k).
        #[arg(long, default_value_t = CockpitConfig::DEFAULT_DETAIL)]
        detail: f32,
    },
}

fn parse_quality(s: &str) -> Result<Quality, String> {
    Quality::from_name(s)
        .ok_or_else(|| format!("unknown quality '{s}' (preview, refine, full, reference)"))
}

fn main() -> std::process::ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Render(args) => render(args),
        Command::Scene(SceneCommand::Export {
            name,
            output,
            detail,
        }) => export_scene(&name, &output, detail),
        Command::Bench(b) => bench::run(b),
    }
}

/// Sets the size of rayon's global pool (once, before any parallel work).
fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("setting the thread count")?;
    }
    Ok(())
}

fn render(args: RenderArgs) -> Result<()> {
    set_threads(args.threads)?;
    let mut job = vtfarm_job::load_job(&args.job)?;
    if let Some(q) = args.quality {
        job.vertex.quality = q;
    }
    let loaded = job.load_scene()?;
    let mut camera = loaded.camera;
    camera.width = args.width.unwrap_or(camera.width);
    camera.height = args.height.unwrap_or(camera.height);
    let reflectors = job.reflector_triangles(&loaded.scene)?;
    let renderer = Renderer::new(Arc::new(loaded.scene), reflectors);
    let setup = FrameSetup {
        camera,
        lighting: loaded.lighting,
        trace: job.trace,
        vertex: job.vertex,
    };
    let options = RenderOptions {
        package_size: args.package_size,
        collect_faces: args.aux.is_some(),
    };
    let bar = ProgressBar::new(renderer.reflectors().len() as u64).with_style(
        ProgressStyle::with_template(
            "{spinner} {msg} [{bar:40}] {pos}/{len} reflector triangles ({elapsed})",
        )
        .expect("template is valid")
        .progress_chars("=> "),
    );
    bar.set_message(job.vertex.quality.name());
    let frame = renderer.render(&setup, &options, &mut |done, _| bar.set_position(done));
    bar.finish_and_clear();
    output::write_image(&args.output, &frame)
        .with_context(|| format!("writing {}", args.output.display()))?;
    if let Some(dir) = &args.aux {
        output::write_aux(dir, &frame, renderer.scene())?;
    }
    print_summary(
        &frame,
        renderer.scene().triangles.len(),
        renderer.reflectors().len(),
        job.vertex.quality,
    );
    println!("wrote {}", args.output.display());
    Ok(())
}

fn print_summary(
    frame: &RenderedFrame,
    scene_triangles: usize,
    reflector_triangles: usize,
    quality: Quality,
) {
    let s = &frame.stats;
    let rows: [(&str, String); 12] = [
        ("quality", quality.name().to_owned()),
        ("scene triangles", scene_triangles.to_string()),
        ("reflector triangles", reflector_triangles.to_string()),
        ("traced triangles", s.traced_triangles.to_string()),
        ("visible vertices", s.visible_vertices.to_string()),
        ("refined edges", s.refined_edges.to_string()),
        (
            "traced samples",
            format!(
                "{} ({} vertices + {} filled pixels)",
                s.samples(),
                s.vertex_samples,
                s.filled_pixels
            ),
        ),
        ("reflector pixels", s.pixels.to_string()),
        (
            "base frame",
            format!("{:.3} s", frame.raster_time.as_secs_f64()),
        ),
        (
            "vertex tracing",
            format!("{:.3} s", s.vertex_time.as_secs_f64()),
        ),
        (
            "triangle filling",
            format!("{:.3} s", s.fill_time.as_secs_f64()),
        ),
        ("total", format!("{:.3} s", frame.total_time.as_secs_f64())),
    ];
    for (name, value) in rows {
        println!("{name:>20}  {value}");
    }
}

fn export_scene(name: &str, dir: &Path, detail: f32) -> Result<()> {
    if name != "cockpit" {
        bail!("unknown built-in scene '{name}' (available: cockpit)");
    }
    let c = cockpit(&CockpitConfig {
        detail,
        ..CockpitConfig::default()
    });
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    vtfarm_scene::obj::write_obj(&c.scene, dir, name)?;
    println!(
        "wrote {} triangles to {}",
        c.scene.triangles.len(),
        dir.join(format!("{name}.obj")).display()
    );
    Ok(())
}
