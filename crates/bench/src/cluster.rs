//! `vtfarm bench cluster`: a real farm over QUIC on 127.0.0.1, all in this
//! process: a master (endpoint, handshake, scheduler), workers dialling it
//! with `run_worker`, and a submitter running a job of several frames (the
//! cockpit seen from slightly different eyes). The job runs twice, each time
//! on a fresh master in a fresh cluster directory: first with one worker,
//! then with two. Every worker announces one thread, but all of them trace
//! on this process's one rayon pool (`--threads`, default 2): on a 2-core
//! machine that is the honest comparison, and the two-worker figure then
//! shows the farm's own cost (packages, round trips, balancing) rather than
//! more compute.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use glam::Vec3;
use serde::Serialize;
use tokio::task::JoinHandle;
use vtfarm_cockpit::CockpitConfig;
use vtfarm_master::FarmRules;
use vtfarm_master::{server, spawn_master};
use vtfarm_method::MethodKind;
use vtfarm_proto::{FrameStats, HandshakePolicy, Role, SceneData};
use vtfarm_render::FrameSetup;
use vtfarm_submit::{JobOptions, run_job, wire_job};
use vtfarm_transport::client::{ClientOptions, connect};
use vtfarm_transport::{CLOSE_NORMAL, CLUSTER_FILE, ClusterConfig, Link};
use vtfarm_vertex::Quality;
use vtfarm_worker::{DrainSignal, Engine, WorkerConfig, run_worker};

use super::{CockpitJob, write_json};

#[derive(clap::Args)]
pub struct ClusterArgs {
    #[arg(long, default_value_t = 640)]
    width: u32,
    #[arg(long, default_value_t = 360)]
    height: u32,
    /// Frames of the job (the first one includes the workers' BVH builds).
    #[arg(long, default_value_t = 3)]
    frames: usize,
    #[arg(long, value_parser = crate::support::parse_quality, default_value = "full")]
    quality: Quality,
    /// Cockpit detail (1.0 ≈ 100k triangles).
    #[arg(long, default_value_t = CockpitConfig::DEFAULT_DETAIL)]
    detail: f32,
    /// Threads of the process's rayon pool, shared by all workers.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Also writes the figures as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// One frame as the submitter saw it.
#[derive(Serialize)]
struct FrameFigures {
    frame: usize,
    wall_seconds: f64,
    packages: u32,
    imbalance: f64,
    /// Sum of the workers' busy times over the wall time: how many workers
    /// were busy on average.
    busy_speedup: f64,
    /// Sum of the workers' bytes in and out.
    bytes: u64,
    stats: FrameStats,
}

/// One job run on a farm of `workers` workers.
#[derive(Serialize)]
struct RunFigures {
    workers: usize,
    frames: Vec<FrameFigures>,
    /// Mean frame wall time without the first frame (all frames if only one).
    mean_wall_seconds: f64,
    /// Wall time of the whole job as the submitter saw it (scene upload included).
    job_seconds: f64,
}

#[derive(Serialize)]
struct ClusterFigures {
    width: u32,
    height: u32,
    quality: &'static str,
    scene_triangles: usize,
    reflector_triangles: usize,
    pool_threads: usize,
    runs: Vec<RunFigures>,
    /// Mean frame wall time of one worker over that of two.
    speedup_two_over_one: f64,
}

pub(crate) fn run(args: ClusterArgs) -> Result<()> {
    if args.frames == 0 || args.threads == 0 {
        bail!("--frames and --threads must be at least 1");
    }
    crate::support::set_threads(Some(args.threads))?;
    let job = CockpitJob::new(args.detail, args.width, args.height, args.quality)?;
    // Frame k moves the eye k centimetres to the right and half that up.
    let setups: Vec<FrameSetup> = (0..args.frames)
        .map(|k| {
            let mut setup = job.setup.clone();
            setup.camera.eye += Vec3::new(0.01, 0.005, 0.0) * k as f32;
            setup
        })
        .collect();
    let dir = tempfile::Builder::new()
        .prefix("vtfarm-bench-cluster-")
        .tempdir()
        .context("creating a temporary directory")?;
    let runtime = crate::support::runtime()?;
    let mut runs = Vec::new();
    for workers in [1, 2] {
        eprintln!(
            "running {} frame(s) on a fresh master with {workers} worker(s) ...",
            args.frames
        );
        let run_dir = dir.path().join(format!("farm-{workers}"));
        let (stats, job_seconds) = runtime.block_on(run_farm(&run_dir, &job, &setups, workers))?;
        runs.push(run_figures(workers, stats, job_seconds));
    }
    runtime.shutdown_timeout(Duration::from_secs(2));
    let figures = ClusterFigures {
        width: args.width,
        height: args.height,
        quality: args.quality.name(),
        scene_triangles: job.scene.triangles.len(),
        reflector_triangles: job.reflectors.len(),
        pool_threads: args.threads,
        speedup_two_over_one: runs[0].mean_wall_seconds / runs[1].mean_wall_seconds.max(1e-9),
        runs,
    };
    print_figures(&figures);
    if let Some(path) = &args.json {
        write_json(path, &figures)?;
    }
    Ok(())
}

fn run_figures(workers: usize, stats: Vec<FrameStats>, job_seconds: f64) -> RunFigures {
    let frames: Vec<FrameFigures> = stats
        .into_iter()
        .enumerate()
        .map(|(frame, stats)| FrameFigures {
            frame,
            wall_seconds: stats.wall_micros as f64 / 1e6,
            packages: stats.packages,
            imbalance: stats.imbalance,
            busy_speedup: stats.speedup,
            bytes: stats.workers.iter().map(|w| w.bytes_in + w.bytes_out).sum(),
            stats,
        })
        .collect();
    let steady = if frames.len() > 1 {
        &frames[1..]
    } else {
        &frames[..]
    };
    let mean_wall_seconds =
        steady.iter().map(|f| f.wall_seconds).sum::<f64>() / steady.len().max(1) as f64;
    RunFigures {
        workers,
        frames,
        mean_wall_seconds,
        job_seconds,
    }
}

/// Starts a master on 127.0.0.1 (cluster files in `dir`) and `workers`
/// workers, runs the job and tears everything down. Returns the frames'
/// statistics and the job's wall time.
async fn run_farm(
    dir: &Path,
    job: &CockpitJob,
    setups: &[FrameSetup],
    workers: usize,
) -> Result<(Vec<FrameStats>, f64)> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    // Bind first, so that the cluster file names the port actually used.
    let identity = server::identity(dir, &["127.0.0.1".into()])?;
    let endpoint = server::bind("127.0.0.1:0".parse()?, &identity)?;
    let address = endpoint.local_addr()?;
    let cluster = ClusterConfig::generate(&address.to_string(), &identity)?;
    cluster.save(&dir.join(CLUSTER_FILE))?;
    let (master, master_task) = spawn_master(FarmRules::default());
    let server_task = tokio::spawn(server::serve(
        endpoint.clone(),
        HandshakePolicy::new(cluster.token.clone(), "bench"),
        master,
    ));
    let options = ClientOptions {
        master: cluster.master.clone(),
        token: cluster.token.clone(),
        fingerprint: cluster.fingerprint.clone(),
    };
    let worker_tasks: Vec<JoinHandle<_>> = (0..workers)
        .map(|k| {
            tokio::spawn(run_worker(
                options.clone(),
                format!("bench-{k}"),
                1,
                Engine::new(Some(dir.join(format!("cache-{k}")))),
                WorkerConfig::default(),
                DrainSignal::never(),
            ))
        })
        .collect();
    let result = async {
        let mut conn = connect(&options, Role::Submitter).await?;
        wait_for_workers(&mut conn.link, workers).await?;
        let data = SceneData::from_scene(&job.scene);
        let options = JobOptions {
            method: MethodKind::VertexTracing,
            aux: false,
        };
        let wire = wire_job("bench-cluster", &data, setups, &job.reflectors, options);
        let start = Instant::now();
        let frames = run_job(&mut conn.link, wire, &data, |_| {}).await;
        let job_seconds = start.elapsed().as_secs_f64();
        conn.connection.close(CLOSE_NORMAL, b"done");
        let _ = tokio::time::timeout(Duration::from_secs(2), conn.endpoint.wait_idle()).await;
        let stats = frames?.into_iter().map(|f| f.stats).collect();
        anyhow::Ok((stats, job_seconds))
    }
    .await;
    for task in &worker_tasks {
        task.abort();
    }
    endpoint.close(CLOSE_NORMAL, b"bench done");
    server_task.abort();
    master_task.abort();
    result
}

/// Asks the master for its status until `workers` workers are connected.
async fn wait_for_workers(link: &mut Link, workers: usize) -> Result<()> {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let reply = (link.status().await).context("the master closed the connection")?;
        if reply.workers.len() >= workers {
            return Ok(());
        }
        if Instant::now() > deadline {
            bail!(
                "only {} of {workers} workers connected within 30 s",
                reply.workers.len()
            );
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Wall time minus the busiest worker's busy time.
fn not_busy_seconds(frame: &FrameFigures) -> f64 {
    let busiest = frame.stats.workers.iter().map(|w| w.busy_micros).max();
    (frame.wall_seconds - busiest.unwrap_or(0) as f64 / 1e6).max(0.0)
}

fn print_figures(f: &ClusterFigures) {
    println!(
        "bench cluster — cockpit {} triangles, {}x{} {}, cover glass {} triangles; QUIC on 127.0.0.1, one process",
        f.scene_triangles, f.width, f.height, f.quality, f.reflector_triangles
    );
    println!(
        "each run: a fresh master; workers announce 1 thread each but share this process's {}-thread rayon pool",
        f.pool_threads
    );
    println!(
        "columns: wall = first assignment to last result (master); not busy = wall - the busiest worker's busy time (transfers, set-up, waiting); bytes = workers' bytes in + out"
    );
    for run in &f.runs {
        println!(
            "{} worker(s): job {:.3} s (scene upload and BVH builds included)",
            run.workers, run.job_seconds
        );
        println!(
            "  {:>5} {:>9} {:>9} {:>8} {:>9} {:>9} {:>11}   busy s per worker",
            "frame", "wall s", "not busy", "packages", "imbalance", "busy/wall", "bytes",
        );
        for frame in &run.frames {
            let busy: Vec<String> = frame
                .stats
                .workers
                .iter()
                .map(|w| format!("{} {:.3}", w.name, w.busy_micros as f64 / 1e6))
                .collect();
            println!(
                "  {:>5} {:>9.3} {:>9.3} {:>8} {:>8.1}% {:>9.2} {:>11}   {}",
                frame.frame,
                frame.wall_seconds,
                not_busy_seconds(frame),
                frame.packages,
                frame.imbalance * 100.0,
                frame.busy_speedup,
                frame.bytes,
                busy.join(", ")
            );
        }
        println!(
            "  mean frame wall time{}: {:.3} s",
            if run.frames.len() > 1 {
                " without frame 0 (the first frame builds the BVHs)"
            } else {
                ""
            },
            run.mean_wall_seconds
        );
        let not_busy: Vec<f64> = run.frames.iter().map(not_busy_seconds).collect();
        if let [first, rest @ ..] = not_busy.as_slice() {
            let later = rest.iter().sum::<f64>() / rest.len().max(1) as f64;
            if !rest.is_empty() && later > 0.01 && later > 3.0 * first {
                println!(
                    "  note: later frames spend {later:.3} s outside the busiest worker's packages, frame 0 {first:.3} s: \
                     a worker's frame set-up (ID buffers) seems to fall inside their wall time \
                     (a work request left from the previous frame gets the next frame's first package)"
                );
            }
        }
    }
    println!(
        "speed-up of 2 workers over 1: {:.2} (mean frame wall times; both runs trace on the same {} pool threads, so the ideal is 1.0 where one worker already fills them)",
        f.speedup_two_over_one, f.pool_threads
    );
}
