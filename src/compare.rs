//! `vtfarm compare`: every reflection method on the job's first view,
//! measured against the per-pixel reference.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, Result};
use vtfarm_compare::{run_all, sheet, standard_methods};
use vtfarm_method::{OwnedFrame, ReflectionMethod, VertexTracing};

/// Options of `vtfarm compare`.
#[derive(clap::Args)]
pub(crate) struct CompareArgs {
    /// The job file (TOML); its first frame is compared.
    job: PathBuf,
    /// Output directory: one PNG per method, sheet.png, compare.json.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    size: crate::shared::ImageSize,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

/// `vtfarm compare`.
pub(crate) fn compare(args: CompareArgs) -> Result<()> {
    crate::shared::set_threads(args.threads)?;
    let crate::shared::PreparedJob {
        job,
        scene,
        reflectors,
        setups,
    } = crate::shared::prepare_job(&args.job, None, args.size)?;
    let setup = setups
        .into_iter()
        .next()
        .context("a job has at least one frame")?;
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    crate::shared::warn_unsupported_reflectors(
        vtfarm_method::MethodKind::CubeMap,
        &scene,
        &reflectors,
    );
    let owned = OwnedFrame::new(
        Arc::new(scene),
        setup.camera,
        setup.lighting,
        setup.trace,
        reflectors,
    );
    let base = owned.base_frame();
    let frame = owned.frame();
    let methods = standard_methods(job.vertex);
    let methods: Vec<&dyn ReflectionMethod> = methods.iter().map(|m| m.as_ref()).collect();
    let bar =
        vtfarm_submit::progress::Progress::new(methods.len() as u64 + 1, "methods", "compare");
    let mut started = false;
    let runs = run_all(
        &frame,
        &base,
        &VertexTracing::reference(),
        &methods,
        &mut |name| {
            if std::mem::replace(&mut started, true) {
                bar.inc(1);
            }
            bar.set_message(name.to_owned());
        },
    );
    bar.finish();

    println!(
        "{:<14} {:>9} {:>9} {:>10} {:>10} {:>9} {:>11} {:>12}",
        "method", "time s", "setup s", "rays", "searches", "MAE", "off >8/255", "reflect MAE"
    );
    let mut figures = Vec::new();
    for run in &runs {
        let f = run.figures();
        println!(
            "{:<14} {:>9.3} {:>9.3} {:>10} {:>10} {:>9.3} {:>10.3}% {:>12.3}",
            f.method,
            f.seconds,
            f.setup_seconds,
            f.rays,
            f.searches,
            f.mean_abs,
            f.share_off * 100.0,
            f.reflected_mean_abs
        );
        vtfarm_render::output::write_image(
            &args.output.join(format!("{}.png", f.method)),
            &run.image.color,
            &vtfarm_imaging::Exposure::default(),
            None,
        )?;
        figures.push(f);
    }
    let sheet_path = args.output.join("sheet.png");
    sheet(&runs).write_png(&sheet_path)?;
    let json_path = args.output.join("compare.json");
    crate::shared::write_json(&json_path, &figures)?;
    println!(
        "errors against `reference` on its {} reflector pixels (8-bit sRGB steps); wrote {} images, {} and {}",
        runs[0].error.pixels,
        runs.len(),
        sheet_path.display(),
        json_path.display()
    );
    Ok(())
}
