//! The farm commands of the CLI: the embedded master behind `render`,
//! `submit` and `status` against a running master, and the `--cluster`
//! and `--master` options every command that dials the master shares.

use std::path::{Path, PathBuf};
use vtfarm_proto::JobId;

use anyhow::{Context, Result, bail};
use vtfarm_embedded::LocalFarm;
use vtfarm_master::FarmRules;
use vtfarm_method::MethodKind;
use vtfarm_proto::{FrameStats, Role, SceneData, WireImageFormat, WireJob, WireStudy};
use vtfarm_render::FrameSetup;
use vtfarm_render::output::ImageFormat;
use vtfarm_scene::Scene;
use vtfarm_submit::listing::{self, FrameRecord};
use vtfarm_submit::progress::Progress;
use vtfarm_submit::{
    FinishedFrame, JobEvent, JobOptions, RemoteJob, RemoteStudy, StudyEvent, run_job,
    run_remote_job, run_remote_study, wire_job,
};
use vtfarm_transport::ClusterConfig;
use vtfarm_transport::client::{ClientOptions, connect};
use vtfarm_vertex::Quality;

use crate::shared::runtime;

/// Options of `vtfarm submit`.
#[derive(clap::Args)]
pub(crate) struct SubmitArgs {
    /// The job file (TOML), or a study file (one with a `[study]` table,
    /// e.g. configs/cockpit-study.toml): the study is one job of kind
    /// `study` on the cluster, its variants jobs under it; OUTPUT gets what
    /// `vtfarm study` writes.
    #[arg(value_name = "JOB_OR_STUDY")]
    job: PathBuf,
    /// The cluster file from `vtfarm cluster init`.
    #[arg(long)]
    cluster: PathBuf,
    /// The master's HOST:PORT (default: the cluster file's).
    #[arg(long)]
    master: Option<String>,
    /// Output directory for frame_NNNN.png (or .exr), frame_NNNN_timeline.svg
    /// (where each frame's time went) and stats.json; created if missing.
    #[arg(short, long)]
    output: PathBuf,
    /// The frames' format: png (8-bit sRGB, at the exposure of the job's
    /// output section) or exr (OpenEXR, linear cd/m², RGB and Y; with --aux
    /// also the reflected and transmitted layers).
    #[arg(long, default_value = "png", value_parser = parse_frame_format)]
    format: vtfarm_render::output::ImageFormat,
    /// Follow job JOB that the master already has (submitted from another
    /// shell, or before this one lost the master) instead of submitting
    /// the job file again; the job file still names the scene and outputs.
    /// A study's id with the study file it was submitted from.
    #[arg(long, value_name = "JOB")]
    attach: Option<u64>,
    /// Also write each frame's auxiliary outputs (mask, reflected and
    /// transmitted components, reflected-object map) into OUTPUT/frame_NNNN/.
    #[arg(long)]
    aux: bool,
    /// Overrides the job's (or the study's base job's) quality level.
    #[arg(long, value_parser = crate::shared::quality_parser())]
    quality: Option<Quality>,
    #[command(flatten)]
    size: crate::shared::ImageSize,
    /// The job's priority: higher runs first, equal ones in submission
    /// order; negative values go behind the default.
    #[arg(
        long,
        value_name = "N",
        default_value_t = 0,
        allow_negative_numbers = true
    )]
    priority: i32,
    /// The job's name in `vtfarm jobs` (default: the job file's name).
    #[arg(long, value_name = "NAME")]
    name: Option<String>,
    /// Print the job's id and what happens to it as JSON lines on stdout
    /// (`{"event":"accepted","job":3,"frames":40}`, …) for scripts; the
    /// lines for people go to stderr.
    #[arg(long)]
    json: bool,
}

/// `--cluster` and `--master`: how a command reaches the master.
#[derive(clap::Args)]
pub(crate) struct ClusterArgs {
    /// The cluster file from `vtfarm cluster init`.
    #[arg(long)]
    cluster: PathBuf,
    /// The master's HOST:PORT (default: the cluster file's).
    #[arg(long)]
    master: Option<String>,
}

impl ClusterArgs {
    pub(crate) fn client_options(&self) -> Result<ClientOptions> {
        client_options(&self.cluster, &self.master)
    }
}

/// `png` or `exr`, the frame formats of `vtfarm submit`.
fn parse_frame_format(name: &str) -> Result<vtfarm_render::output::ImageFormat, String> {
    use vtfarm_render::output::ImageFormat;
    match name {
        "png" => Ok(ImageFormat::Png),
        "exr" => Ok(ImageFormat::Exr),
        other => Err(format!(
            "unsupported frame format {other:?}; supported: png (8-bit sRGB), exr (OpenEXR, linear cd/m²)"
        )),
    }
}

/// Options of `vtfarm status`.
#[derive(clap::Args)]
pub(crate) struct StatusArgs {
    /// The cluster file from `vtfarm cluster init`.
    #[arg(long)]
    cluster: PathBuf,
    /// The master's HOST:PORT (default: the cluster file's).
    #[arg(long)]
    master: Option<String>,
}

/// What `render_embedded` renders.
pub(crate) struct EmbeddedJob<'a> {
    pub(crate) name: &'a str,
    pub(crate) scene: &'a Scene,
    pub(crate) setup: &'a FrameSetup,
    pub(crate) reflectors: &'a [vtfarm_scene::TriangleId],
    pub(crate) method: MethodKind,
    /// Also return the per-pixel components.
    pub(crate) aux: bool,
}

/// Renders one frame through an embedded master with `workers` local workers.
pub(crate) fn render_embedded(
    job: EmbeddedJob<'_>,
    workers: usize,
    bar: &Progress,
) -> Result<FinishedFrame> {
    let EmbeddedJob {
        name,
        scene,
        setup,
        reflectors,
        method,
        aux,
    } = job;
    runtime()?.block_on(async {
        let farm = LocalFarm::start(workers, FarmRules::default());
        let mut link = farm.submitter();
        let data = SceneData::from_scene(scene);
        let options = JobOptions { method, aux };
        let job = wire_job(
            name,
            &data,
            std::slice::from_ref(setup),
            reflectors,
            options,
        );
        let frames = run_job(&mut link, job, &data, |event| {
            if let JobEvent::Progress { done, .. } = event {
                bar.set_position(done.into());
            }
        })
        .await;
        // Every task ends before the runtime does (see `LocalFarm`).
        farm.shutdown().await;
        frames?
            .into_iter()
            .next()
            .context("the master returned no frame")
    })
}

pub(crate) fn client_options(cluster: &Path, master: &Option<String>) -> Result<ClientOptions> {
    let config = ClusterConfig::load(cluster)?;
    Ok(ClientOptions {
        master: master.clone().unwrap_or(config.master),
        token: config.token,
        fingerprint: config.fingerprint,
    })
}

/// Writes a finished frame of `vtfarm submit` as `format` (PNG under
/// `exposure`, or OpenEXR with the components as layers when the job kept
/// them).
fn write_frame(
    path: &Path,
    frame: &vtfarm_submit::FinishedFrame,
    format: ImageFormat,
    exposure: &vtfarm_imaging::Exposure,
) -> Result<()> {
    match (format, frame.image.linear()) {
        (ImageFormat::Png, _) if exposure.is_identity() => frame.image.write_png(path)?,
        (_, None) => bail!("the master sent an sRGB frame for linear output"),
        (_, Some(image)) => {
            let components = frame.components.as_ref().map(|c| c.components());
            vtfarm_render::output::write_image(path, image, exposure, components.as_ref())?
        }
    }
    Ok(())
}

/// `vtfarm submit`.
pub(crate) fn submit(args: SubmitArgs) -> Result<()> {
    if vtfarm_job::study::is_study_file(&args.job) {
        return submit_study(args);
    }
    let crate::shared::PreparedJob {
        job,
        scene,
        reflectors,
        setups,
    } = crate::shared::prepare_job(&args.job, args.quality, args.size)?;
    crate::shared::warn_unsupported_reflectors(job.method, &scene, &reflectors);
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let client = client_options(&args.cluster, &args.master)?;
    let name = args.name.clone().unwrap_or_else(|| {
        (args.job.file_name()).map_or("job".into(), |n| n.to_string_lossy().into_owned())
    });
    let output = args.output.clone();
    let (priority, json) = (args.priority, args.json);
    let again = AttachHint::of(&args);
    let (args_aux, attach, format) = (args.aux, args.attach, args.format);
    let exposure = job.output.exposure();
    let mut arrivals = std::collections::BTreeMap::new();
    let frames = runtime()?.block_on(async {
        let data = SceneData::from_scene(&scene);
        let options = JobOptions {
            method: job.method,
            aux: args_aux,
        };
        let wire = wire_job(&name, &data, &setups, &reflectors, options);
        // Only PNGs at the default exposure are written: 8-bit sRGB
        // frames, a quarter of the bytes of linear ones before
        // compression, and no conversion here.
        let png_only = format == ImageFormat::Png && exposure.is_identity();
        let image = if args_aux || !png_only {
            WireImageFormat::LinearF32
        } else {
            WireImageFormat::Srgb8
        };
        let wire = WireJob {
            image,
            priority,
            ..wire
        };
        let start = match attach {
            Some(job) => RemoteJob::Attach { job: JobId(job) },
            None => RemoteJob::Submit {
                job: wire,
                scene: &data,
            },
        };
        let bar = Progress::new(reflectors.len() as u64, "reflector triangles", "frame");
        let say = |line: String| bar.println(line);
        let submitted = std::time::Instant::now();
        let accepted = std::cell::Cell::new(attach.map(JobId));
        let run = run_remote_job(&client, start, |event| {
            let line = json.then(|| event.json_line()).flatten();
            match event {
                JobEvent::Accepted { job, frames } => {
                    accepted.set(Some(job));
                    match line {
                        Some(line) => println!("{line}"),
                        None => say(format!("job {job} accepted: {frames} frame(s)")),
                    }
                }
                JobEvent::Progress { frame, done, .. } => {
                    bar.set_message(format!("frame {frame}"));
                    bar.set_position(done.into());
                }
                JobEvent::Warning(warning) => say(format!("warning: {warning}")),
                JobEvent::StateChanged { job, state, reason } => match line {
                    Some(line) => println!("{line}"),
                    None => say(format!("job {job} is {}: {reason}", state.name())),
                },
                JobEvent::FrameDone(f) => {
                    arrivals.insert(f.frame, submitted.elapsed().as_micros() as u64);
                    let path = output.join(format!("frame_{:04}.{}", f.frame, format.extension()));
                    if let Err(e) = write_frame(&path, f, format, &exposure) {
                        say(format!("error: {e:#}"));
                    }
                    let timeline = output.join(format!("frame_{:04}_timeline.svg", f.frame));
                    let svg = vtfarm_master::timeline::timeline_svg(&f.stats);
                    if let Err(e) = std::fs::write(&timeline, svg) {
                        say(format!("error: {}: {e}", timeline.display()));
                    }
                    if let Some(components) = &f.components {
                        let dir = output.join(format!("frame_{:04}", f.frame));
                        if let Err(e) =
                            vtfarm_render::output::write_aux(&dir, components, &[], &scene)
                        {
                            say(format!("error: {e}"));
                        }
                    }
                    say(format!(
                        "frame {}: {} ({})",
                        f.frame,
                        path.display(),
                        listing::frame_line(&f.stats)
                    ));
                }
            }
        });
        // Ctrl-C leaves the job to the farm: say so, and how to come back.
        let result = tokio::select! {
            result = run => result,
            _ = tokio::signal::ctrl_c() => {
                bar.finish();
                match accepted.get() {
                    Some(job) => eprintln!("{}", again.message("job", job)),
                    None => eprintln!("interrupted before the master accepted the job"),
                }
                std::process::exit(130);
            }
        };
        bar.finish();
        anyhow::Ok(result?)
    })?;
    let path = args.output.join("stats.json");
    crate::shared::write_json(&path, &FrameRecord::of(&frames, &arrivals))?;
    if json {
        println!("{}", listing::done_json_line(frames.len(), "stats", &path));
        return Ok(());
    }
    for f in &frames {
        println!("frame {}:", f.frame);
        print!("{}", listing::frame_table(&f.stats));
    }
    println!("wrote {} frame(s) and {} ", frames.len(), path.display());
    Ok(())
}

/// How to follow an interrupted `vtfarm submit`'s job again or stop it:
/// the same command with `--attach`, and `vtfarm cancel`.
struct AttachHint {
    job_file: PathBuf,
    cluster: PathBuf,
    output: PathBuf,
}

impl AttachHint {
    fn of(args: &SubmitArgs) -> AttachHint {
        AttachHint {
            job_file: args.job.clone(),
            cluster: args.cluster.clone(),
            output: args.output.clone(),
        }
    }

    /// The hint for `what` (a job or a study) `job`.
    fn message(&self, what: &str, job: JobId) -> String {
        let (file, cluster, output) = (
            self.job_file.display(),
            self.cluster.display(),
            self.output.display(),
        );
        format!(
            "interrupted: {what} {job} keeps running on the farm.\n  \
             follow it again: vtfarm submit {file} --cluster {cluster} --output {output} --attach {job}\n  \
             stop it:         vtfarm cancel {job} --cluster {cluster}"
        )
    }
}

/// `vtfarm submit` of a study file: the study is one job on the cluster
/// (its variants jobs under it), followed until every frame is in, or
/// followed again with `--attach`; the outputs are `vtfarm study`'s.
fn submit_study(args: SubmitArgs) -> Result<()> {
    if args.size.is_set() || args.aux {
        bail!(
            "--width, --height and --aux apply to job files; a study file sets its own size and always keeps the components"
        );
    }
    let plan = vtfarm_study::plan_file(&args.job, args.quality)?;
    let client = client_options(&args.cluster, &args.master)?;
    let again = AttachHint::of(&args);
    let json = args.json;
    let mut writer = vtfarm_study::StudyWriter::new(&plan, &args.output)?;
    let order = plan.frame_order();
    let (study, scenes) = vtfarm_study::wire_study(&plan, args.priority);
    let study = WireStudy {
        name: args.name.clone().unwrap_or(study.name),
        ..study
    };
    let start = match args.attach {
        Some(study) => RemoteStudy::Attach {
            study: JobId(study),
        },
        None => RemoteStudy::Submit {
            study,
            scenes: &scenes,
        },
    };
    let workers = format!("the cluster's workers (master {})", client.master);
    let bar = Progress::new(plan.frames() as u64, "frames", "");
    let say = |line: String| bar.println(line);
    let accepted = std::cell::Cell::new(args.attach.map(JobId));
    let variant_name = |v: usize| plan.variants[v].name.clone();
    let outcome = runtime()?.block_on(async {
        let run = run_remote_study(&client, start, |event| {
            let line = json.then(|| event.json_line(variant_name)).flatten();
            match event {
                StudyEvent::Accepted { study, variants } => {
                    accepted.set(Some(study));
                    let has: Vec<u32> = variants.iter().map(|&(_, frames)| frames).collect();
                    plan.check_variant_frames(study, &has).map_err(|e| e.to_string())?;
                    let frames: u32 = has.iter().sum();
                    let jobs: Vec<JobId> = variants.iter().map(|&(job, _)| job).collect();
                    match line {
                        Some(line) => println!("{line}"),
                        None => say(format!("study {study} accepted: {} variant(s) (jobs {jobs:?}), {frames} frame(s)", jobs.len())),
                    }
                }
                StudyEvent::FrameDone { variant, frame } => {
                    crate::study::write_frame(&mut writer, (variant, frame.frame), &order, frame, &bar)
                        .map_err(|e| e.to_string())?;
                }
                StudyEvent::Warning(warning) => say(format!("warning: {warning}")),
                StudyEvent::StateChanged { variant, job, state, reason } => match line {
                    Some(line) => println!("{line}"),
                    None => say(format!("variant {:?} (job {job}) is {}: {reason}", variant_name(variant), state.name())),
                },
            }
            Ok(())
        });
        // Ctrl-C leaves the study to the farm: a partial report of what
        // is in, and how to come back.
        tokio::select! {
            result = run => Some(result),
            _ = tokio::signal::ctrl_c() => None,
        }
    });
    bar.finish();
    let run = vtfarm_study::RunInfo::of_this_process(crate::VERSION, workers);
    let Some(result) = outcome else {
        let done = writer.done();
        let report = writer.finish_partial(&run)?;
        eprintln!(
            "wrote a partial report of {done} of {} frames (it lists those it lacks): {}",
            plan.frames(),
            args.output.display()
        );
        drop(report);
        match accepted.get() {
            Some(study) => eprintln!("{}", again.message("study", study)),
            None => eprintln!("interrupted before the master accepted the study"),
        }
        std::process::exit(130);
    };
    result?;
    let report = writer.finish(&run)?;
    if json {
        let summary = args.output.join("summary.json");
        println!(
            "{}",
            listing::done_json_line(plan.frames(), "summary", &summary)
        );
        return Ok(());
    }
    println!("{}", report.table(&args.output));
    Ok(())
}

/// Prints a frame's per-worker table.
pub(crate) fn print_frame_stats(s: &FrameStats) {
    print!("{}", listing::frame_table(s));
}

/// `vtfarm status`.
pub(crate) fn status(args: StatusArgs) -> Result<()> {
    let options = client_options(&args.cluster, &args.master)?;
    let reply = runtime()?.block_on(async move {
        let mut conn = connect(&options, Role::Submitter).await?;
        let reply = (conn.link.status().await).context("the master closed the connection")?;
        conn.connection
            .close(vtfarm_transport::CLOSE_NORMAL, b"done");
        conn.endpoint.wait_idle().await;
        anyhow::Ok(reply)
    })?;
    print!("{}", listing::status_table(&reply));
    Ok(())
}
