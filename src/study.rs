//! `vtfarm study` (an embedded farm) and the study side of `vtfarm submit`
//! (a cluster, where the study is one job of kind `study`); the study's
//! jobs are `vtfarm_study`'s. Both write each frame through [`write_frame`].

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use vtfarm_embedded::LocalFarm;
use vtfarm_master::FarmRules;
use vtfarm_study::{StudyPlan, StudyReport, StudyWriter};
use vtfarm_submit::progress::Progress;
use vtfarm_submit::{FinishedFrame, JobEvent, run_job};
use vtfarm_transport::Link;
use vtfarm_vertex::Quality;

/// Options of `vtfarm study`.
#[derive(clap::Args)]
pub(crate) struct StudyArgs {
    /// The study file (TOML): design variants x eye points, e.g.
    /// configs/cockpit-study.toml, optionally x sun positions (a `[sun]`
    /// grid or date range, e.g. configs/cockpit-sun-study.toml).
    study: PathBuf,
    /// Output directory: per-frame images, summary.csv, summary.json, report.html.
    #[arg(short, long)]
    output: PathBuf,
    /// Overrides the base job's quality level.
    #[arg(long, value_parser = crate::shared::quality_parser())]
    quality: Option<Quality>,
    /// Local workers of the embedded master (they share the cores).
    #[arg(long, default_value_t = 2)]
    local_workers: usize,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

/// `vtfarm study`.
pub(crate) fn study(args: StudyArgs) -> Result<()> {
    crate::shared::set_threads(args.threads)?;
    let plan = vtfarm_study::plan_file(&args.study, args.quality)?;
    let threads = (args.threads)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let workers = format!(
        "local, {} worker(s) sharing {threads} threads",
        args.local_workers
    );
    let report = crate::shared::runtime()?.block_on(async {
        let farm = LocalFarm::start(args.local_workers, FarmRules::default());
        let mut link = farm.submitter();
        let report = render_and_write(&mut link, &plan, &args.output, workers).await;
        farm.shutdown().await;
        report
    })?;
    println!("{}", report.table(&args.output));
    if !report.missing_frames.is_empty() {
        std::process::exit(130);
    }
    Ok(())
}

/// Runs the study over `link` (to an embedded or remote master) and writes
/// its outputs into `dir`, rendered by `workers`; on Ctrl-C, a partial
/// report of the frames done, which lists those it lacks.
pub(crate) async fn render_and_write(
    link: &mut Link,
    plan: &StudyPlan,
    dir: &Path,
    workers: String,
) -> Result<StudyReport> {
    let mut writer = StudyWriter::new(plan, dir)?;
    let interrupted = tokio::select! {
        result = render_study(link, plan, &mut writer) => {
            result?;
            false
        }
        _ = tokio::signal::ctrl_c() => true,
    };
    let run = vtfarm_study::RunInfo::of_this_process(crate::VERSION, workers);
    if !interrupted {
        return Ok(writer.finish(&run)?);
    }
    let done = writer.done();
    let report = writer.finish_partial(&run)?;
    eprintln!(
        "interrupted: wrote a partial report of {done} of {} frames (it lists those it lacks)",
        plan.frames()
    );
    Ok(report)
}

/// Measures and writes frame `sent` of variant `v` (see
/// [`StudyWriter::sent_frame`]) and says so.
pub(crate) fn write_frame(
    writer: &mut StudyWriter<'_>,
    frame: (usize, u32),
    order: &[usize],
    finished: &FinishedFrame,
    bar: &Progress,
) -> Result<(), vtfarm_study::StudyError> {
    bar.println(writer.sent_frame(frame, order, finished.components.as_ref())?);
    bar.inc(1);
    Ok(())
}

/// Runs the study's variants over `link`, each variant one job of its
/// frames coarse to fine, into `writer`.
async fn render_study(
    link: &mut Link,
    plan: &StudyPlan,
    writer: &mut StudyWriter<'_>,
) -> Result<()> {
    let bar = Progress::new(plan.frames() as u64, "frames", "");
    let order = plan.frame_order();
    for (v, variant) in plan.variants.iter().enumerate() {
        bar.set_message(variant.name.clone());
        let (job, data) = vtfarm_study::variant_job(plan, v, &order);
        let mut failure = None;
        run_job(link, job, &data, |event| {
            if let JobEvent::FrameDone(f) = event {
                if let Err(e) = write_frame(writer, (v, f.frame), &order, f, &bar) {
                    failure.get_or_insert(e);
                }
            }
        })
        .await
        .with_context(|| format!("variant {:?}", variant.name))?;
        if let Some(e) = failure {
            return Err(e).with_context(|| format!("variant {:?}", variant.name));
        }
    }
    bar.finish();
    Ok(())
}
