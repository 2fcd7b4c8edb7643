//! `vtfarm study` (an embedded farm) and the study side of `vtfarm submit`
//! (a cluster): every variant is one farm job whose frames are its sun
//! positions times its eye points, so the farm balances the study frame by
//! frame, and the workers keep the variant's scene and BVH for all of them
//! (a sun position changes only the lighting).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use vtfarm_embedded::LocalFarm;
use vtfarm_master::FarmRules;
use vtfarm_proto::SceneData;
use vtfarm_study::{StudyPlan, StudyReport, StudyWriter};
use vtfarm_submit::progress::Progress;
use vtfarm_submit::{JobEvent, JobOptions, run_job, wire_job};
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

/// Runs the study's variants over `link`, each variant's frames coarse to
/// fine ([`StudyPlan::frame_order`]), into `writer`.
async fn render_study(
    link: &mut Link,
    plan: &StudyPlan,
    writer: &mut StudyWriter<'_>,
) -> Result<()> {
    let bar = Progress::new(plan.frames() as u64, "frames", "");
    let order = plan.frame_order();
    for (v, variant) in plan.variants.iter().enumerate() {
        bar.set_message(variant.name.clone());
        let data = SceneData::from_scene(&variant.scene);
        let name = format!("{} / {}", plan.name, variant.name);
        let options = JobOptions {
            method: plan.method,
            aux: true,
        };
        let setups: Vec<_> = order.iter().map(|&f| variant.setups[f].clone()).collect();
        let job = vtfarm_proto::WireJob {
            kind: vtfarm_proto::WireJobKind::Study,
            ..wire_job(&name, &data, &setups, &variant.reflectors, options)
        };
        let mut failure = None;
        run_job(link, job, &data, |event| {
            if let JobEvent::FrameDone(f) = event {
                let frame = order[f.frame as usize];
                let written = match &f.components {
                    Some(components) => writer
                        .frame(v, frame, components)
                        .map(|row| row.summary.mean_reflected_luminance_cd_m2),
                    None => Err(vtfarm_study::StudyError::Frame {
                        variant: v,
                        eye: plan.frame_at(frame).1,
                        why: "the master sent no components".into(),
                    }),
                };
                match written {
                    Ok(mean) => bar.println(format!(
                        "{} {}: mean reflected luminance {mean:.1} cd/m²",
                        variant.name,
                        plan.frame_name(frame)
                    )),
                    Err(e) => {
                        failure.get_or_insert(e);
                    }
                }
                bar.inc(1);
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
