//! `vtfarm`: the command-line program. Thin: it parses arguments, loads the
//! job, drives `vtfarm-render` and prints progress and tables.

mod compare;
mod control;
mod farm;
mod jobs;
mod shared;
mod study;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_render::{RenderOptions, Renderer, output};
use vtfarm_vertex::Quality;

use crate::shared::{
    ImageSize, PreparedJob, prepare_job, quality_parser, set_threads, warn_unsupported_reflectors,
};

/// vtfarm's version with the commit it is built from (see build.rs).
pub(crate) const VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (commit ",
    env!("VTFARM_COMMIT"),
    ")"
);

#[derive(Parser)]
#[command(
    name = "vtfarm",
    version = VERSION,
    about = "Distributed adaptive progressive vertex tracing"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The user's commands first, in the order a newcomer meets them; the
/// benchmarks last.
#[derive(Subcommand)]
enum Command {
    /// Renders a job's first frame to an image.
    #[command(about = format!(
        "Renders a job's first frame to an image, by the output's extension: {}",
        vtfarm_render::output::ImageFormat::SUPPORTED
    ))]
    Render(RenderArgs),
    /// Runs a glare study (design variants x eye points, optionally x sun
    /// positions) and writes its images, summary and report.
    Study(study::StudyArgs),
    /// Renders the job's view with every reflection method and measures each
    /// against the per-pixel reference.
    Compare(compare::CompareArgs),
    /// Creates the files of a cluster (key, certificate, cluster.toml).
    #[command(subcommand)]
    Cluster(ClusterCommand),
    /// Runs the farm master (accepts workers and jobs over QUIC).
    Master(vtfarm_master::cli::MasterArgs),
    /// Runs a farm worker that dials the master.
    Worker(vtfarm_worker::cli::WorkerArgs),
    /// Submits a job or a study to a running master and writes its frames
    /// (or the study's outputs).
    Submit(farm::SubmitArgs),
    /// Lists the master's workers (with their measured throughput) and queue.
    Status(farm::StatusArgs),
    /// Lists the master's jobs: state, priority, frames, times, host.
    Jobs(jobs::JobsArgs),
    /// Cancels jobs: queued ones never run, running ones stop at once.
    Cancel(control::CancelArgs),
    /// Pauses a job: it gets no new work; what runs finishes and is kept.
    Pause(control::JobArgs),
    /// Resumes a paused job.
    Resume(control::JobArgs),
    /// Queues a finished job again (every frame, or only its unfinished ones).
    Requeue(control::RequeueArgs),
    /// Sets a job's priority (higher runs first).
    Priority(control::PriorityArgs),
    /// Scene tools (export the built-in cockpit as OBJ + MTL or as GLB).
    #[command(subcommand)]
    Scene(SceneCommand),
    /// Benchmarks: the paper's Table 1, ray and rasterizer throughput, the
    /// farm simulator and a localhost cluster.
    #[command(subcommand)]
    Bench(vtfarm_bench::BenchCommand),
}

#[derive(Subcommand)]
enum ClusterCommand {
    /// Creates the master's key and certificate and DIR/cluster.toml (address, token, fingerprint).
    Init(vtfarm_master::cli::ClusterInitArgs),
}

#[derive(clap::Args)]
struct RenderArgs {
    /// The job file (TOML), e.g. configs/cockpit.toml.
    job: PathBuf,
    /// Output image: .png (8-bit sRGB, the job's [output] exposure), .exr
    /// (OpenEXR, linear cd/m², RGB and Y; with --aux also the reflected and
    /// transmitted layers) or .npy (linear float32, render units). A missing
    /// directory is created.
    #[arg(short, long, default_value = "out.png")]
    output: PathBuf,
    /// Overrides the job's quality level.
    #[arg(long, value_parser = quality_parser())]
    quality: Option<Quality>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    #[command(flatten)]
    size: ImageSize,
    /// Writes the auxiliary outputs here (mask, reflected and transmitted
    /// components, reflected-object map, wireframe).
    #[arg(long)]
    aux: Option<PathBuf>,
    /// Local workers of the embedded master (they share the cores).
    #[arg(long, default_value_t = 2)]
    local_workers: usize,
}

#[derive(Subcommand)]
enum SceneCommand {
    /// Writes a built-in scene as OBJ + MTL, or as binary glTF.
    Export {
        /// The built-in scene's name (`cockpit`).
        name: String,
        /// Output directory.
        #[arg(short, long)]
        output: PathBuf,
        /// Detail factor (1.0 ≈ 100k triangles, 2.1 ≈ 210k).
        #[arg(long, default_value_t = CockpitConfig::DEFAULT_DETAIL)]
        detail: f32,
        /// `obj` (OBJ + MTL) or `glb` (binary glTF 2.0).
        #[arg(long, default_value = "obj", value_parser = ["obj", "glb"])]
        format: String,
    },
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    // The daemons say what they do (joins, leaves, jobs); the other
    // commands only warn.
    match cli.command {
        Command::Master(_) | Command::Worker(_) => vtfarm_transport::init_logging(),
        _ => vtfarm_transport::init_logging_at("warn"),
    }
    match run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", vtfarm_transport::error_report(e.as_ref()));
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
            format,
        }) => export_scene(&name, &output, detail, &format),
        Command::Bench(b) => vtfarm_bench::run(b),
        Command::Master(args) => vtfarm_master::cli::run(args),
        Command::Worker(args) => vtfarm_worker::cli::run(args),
        Command::Study(args) => study::study(args),
        Command::Compare(args) => compare::compare(args),
        Command::Submit(args) => farm::submit(args),
        Command::Status(args) => farm::status(args),
        Command::Jobs(args) => jobs::jobs(args),
        Command::Cancel(args) => control::cancel(args),
        Command::Pause(args) => control::pause(args),
        Command::Resume(args) => control::resume(args),
        Command::Requeue(args) => control::requeue(args),
        Command::Priority(args) => control::priority(args),
        Command::Cluster(ClusterCommand::Init(args)) => {
            let path = vtfarm_master::cli::cluster_init(&args)?;
            println!(
                "wrote {} (copy it to every worker and submitter)",
                path.display()
            );
            Ok(())
        }
    }
}

fn render(args: RenderArgs) -> Result<()> {
    // A wrong extension is refused before anything renders.
    let format = output::ImageFormat::of(&args.output)?;
    set_threads(args.threads)?;
    let PreparedJob {
        job,
        scene,
        reflectors,
        setups,
    } = prepare_job(&args.job, args.quality, args.size)?;
    // `render` writes one image: the job's first frame.
    let setup = setups
        .into_iter()
        .next()
        .context("a job has at least one frame")?;

    warn_unsupported_reflectors(job.method, &scene, &reflectors);
    let bar = vtfarm_submit::progress::Progress::new(
        reflectors.len() as u64,
        "reflector triangles",
        job.vertex.quality.name(),
    );
    let scene_triangles = scene.triangles.len();
    let in_process_aux = args
        .aux
        .as_ref()
        .filter(|_| job.method == vtfarm_method::MethodKind::VertexTracing);
    if let Some(dir) = in_process_aux {
        // The wireframe needs the refined faces, which stay in this process.
        let renderer = Renderer::new(Arc::new(scene), reflectors);
        let options = RenderOptions {
            collect_faces: true,
            ..RenderOptions::default()
        };
        let frame = renderer.render(&setup, &options, &mut |done, _| bar.set_position(done));
        bar.finish();
        let components = (format == output::ImageFormat::Exr).then(|| frame.image.components());
        let exposure = job.output.exposure();
        output::write_image(
            &args.output,
            &frame.image.color,
            &exposure,
            components.as_ref(),
        )?;
        output::write_aux(dir, &frame.image, &frame.faces, renderer.scene())?;
        let timings = [
            ("base frame", frame.raster_time),
            ("total", frame.total_time),
        ];
        print_summary(
            &frame.stats,
            &timings,
            scene_triangles,
            renderer.reflectors().len(),
            job.vertex.quality,
        );
    } else {
        let name = args
            .job
            .file_name()
            .map_or("job".into(), |n| n.to_string_lossy().into_owned());
        let embedded = farm::EmbeddedJob {
            name: &name,
            scene: &scene,
            setup: &setup,
            reflectors: &reflectors,
            method: job.method,
            aux: args.aux.is_some(),
        };
        let frame = farm::render_embedded(embedded, args.local_workers, &bar)?;
        bar.finish();
        let image =
            (frame.image.linear()).context("the master sent an sRGB frame for linear output")?;
        let components = (frame.components.as_ref())
            .filter(|_| format == output::ImageFormat::Exr)
            .map(|c| c.components());
        let exposure = job.output.exposure();
        output::write_image(&args.output, image, &exposure, components.as_ref())?;
        if let (Some(dir), Some(components)) = (&args.aux, &frame.components) {
            output::write_aux(dir, components, &[], &scene)?;
        }
        let stats = vtfarm_vertex::PackageStats::from(frame.stats.totals);
        let timings = [(
            "frame (wall)",
            std::time::Duration::from_micros(frame.stats.wall_micros),
        )];
        println!("{:>20}  {}", "method", job.method.name());
        print_summary(
            &stats,
            &timings,
            scene_triangles,
            reflectors.len(),
            job.vertex.quality,
        );
        farm::print_frame_stats(&frame.stats);
    }
    println!("wrote {}", args.output.display());
    Ok(())
}

fn print_summary(
    s: &vtfarm_vertex::PackageStats,
    timings: &[(&str, std::time::Duration)],
    scene_triangles: usize,
    reflector_triangles: usize,
    quality: Quality,
) {
    let rows = [
        ("quality", quality.name().to_owned()),
        ("scene triangles", scene_triangles.to_string()),
        ("reflector triangles", reflector_triangles.to_string()),
    ];
    for (name, value) in rows.into_iter().chain(s.rows()) {
        println!("{name:>20}  {value}");
    }
    for (name, time) in timings {
        println!("{name:>20}  {:.3} s", time.as_secs_f64());
    }
}

fn export_scene(name: &str, dir: &Path, detail: f32, format: &str) -> Result<()> {
    if name != "cockpit" {
        bail!("unknown built-in scene '{name}' (available: cockpit)");
    }
    let c = cockpit(&CockpitConfig {
        detail,
        ..CockpitConfig::default()
    });
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let file = dir.join(format!("{name}.{format}"));
    match format {
        "glb" => vtfarm_scene::gltf::write_glb(&c.scene, &file)?,
        _ => vtfarm_scene::obj::write_obj(&c.scene, dir, name)?,
    }
    println!(
        "wrote {} triangles to {}",
        c.scene.triangles.len(),
        file.display()
    );
    Ok(())
}
