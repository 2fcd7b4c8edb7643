//! `vtfarm bench view`: the interactive view's latency as a user sees it.
//! A localhost farm of processes (a master and `--workers` workers of
//! `--bin`, default this executable, each worker `--worker-threads 1`)
//! renders one cockpit frame as the view's source; then the bench moves the
//! eye `--moves` times through the master's HTTP API (`POST /api/view`)
//! and times the dashboard's event stream (`GET /api/events`) from each
//! move until each stage (preview, refine, full) is listed as rendered,
//! with the phases the master's timeline records for each stage's frame.
//! Beside it: the same eyes rendered in this process at each quality, and
//! optionally single-frame jobs timed from submission to image
//! (`--single-frames`). Several `--bin` run in turn, each on a fresh farm,
//! and are compared with the first (ratios of the medians).
//!
//! The bench is a client of the HTTP API, the event stream and the
//! command line only, so it measures any server that keeps them (an older
//! build through `--bin`). Every wait is bounded; the processes are
//! stopped on every way out ([`Processes`]'s drop, and the kernel's
//! parent-death signal if this process is killed).

use std::fs::File;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail, ensure};
use serde::Serialize;
use serde_json::Value;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
// The box the server keeps the view's eye in: the bench's eyes stay within
// it, or the server would clamp some of them together.
use vtfarm_master::view::EYE_BOX;
use vtfarm_render::{FrameSetup, RenderOptions, Renderer};
use vtfarm_vertex::Quality;

use super::{CockpitFrameArgs, write_json};

#[derive(clap::Args)]
pub struct ViewArgs {
    /// The frame, and the threads of the local renders beside the farm.
    #[command(flatten)]
    frame: CockpitFrameArgs,
    /// The vtfarm binary the master, the workers and the submitter run
    /// (default: this one); repeat to compare builds, each on a fresh farm.
    #[arg(long)]
    bin: Vec<PathBuf>,
    /// Worker processes.
    #[arg(long, default_value_t = 2)]
    workers: usize,
    /// Each worker's `--threads`.
    #[arg(long, default_value_t = 1)]
    worker_threads: usize,
    /// Timed eye moves (after one untimed warm-up move).
    #[arg(long, default_value_t = 5)]
    moves: usize,
    /// How far each move goes, in metres (left and right in turn, each a
    /// little higher than the last, so no two eyes are equal).
    #[arg(long, default_value_t = 0.01)]
    step: f32,
    /// Single-frame jobs submitted after the moves, each timed from its
    /// submission to its image.
    #[arg(long, default_value_t = 0)]
    single_frames: usize,
    /// Seconds a move's stages, the source frame or a single-frame job may
    /// take before the bench gives up with an error naming what it waited for.
    #[arg(long, default_value_t = 120.0)]
    timeout: f64,
    /// Also writes the figures as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// The most worker processes and threads per worker the bench starts.
const MAX_WORKERS: usize = 64;
const MAX_WORKER_THREADS: usize = 256;

/// The longest `--timeout`, in seconds (an hour).
const MAX_TIMEOUT_SECONDS: f64 = 3600.0;

/// The stages a move of the view renders, in order, as the master names them.
const STAGES: [Quality; 3] = [Quality::Preview, Quality::Refine, Quality::Full];

/// The pause after a move's last stage before the next move: longer than
/// the event stream's coalescing interval (100 ms), so that each move finds
/// the stream idle, as a user's first move after looking does.
const MOVE_PAUSE: Duration = Duration::from_millis(300);

/// How long the farm's processes may take to start and connect.
const START_TIMEOUT: Duration = Duration::from_secs(60);

/// How long one HTTP request to the master may take.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(30);

/// The most bytes the bench reads of one HTTP answer or one event.
const MAX_BODY: usize = 256 << 20;

/// One move: when each stage was on screen after it, and each stage's
/// frame as the master recorded it (where the server lists it).
#[derive(Clone, Debug, Default, Serialize)]
struct MoveFigures {
    offset: [f32; 3],
    /// Seconds from the move's request to the first event listing the stage.
    on_screen_seconds: [f64; 3],
    frames: [Option<StageFrame>; 3],
}

/// A stage's frame on the master's timeline (`FrameStats`, seconds).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
struct StageFrame {
    /// The master's wall time from the frame's first assignment to its last result.
    wall: f64,
    /// The master's base frame (the `base` phases).
    base: f64,
    /// The busiest worker's frame set-up, packages computing and packages
    /// or results in flight (`setup`, `package`, `sending` phases).
    setup: f64,
    packages: f64,
    sending: f64,
}

/// A single-frame job: submission to image as the submitter saw it, and
/// the frame's wall time on the master.
#[derive(Clone, Debug, Serialize)]
struct SingleFrame {
    /// From the submission to the frame's arrival (`stats.json`'s `arrival_micros`).
    submit_to_image_seconds: f64,
    /// The submitter's whole run (its start, scene and connection included).
    process_seconds: f64,
    wall_seconds: f64,
}

/// Median and 90th percentile (nearest rank) of some figures.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
struct Spread {
    median: f64,
    p90: f64,
}

impl Spread {
    /// `None` for no figures.
    fn of(values: impl IntoIterator<Item = f64>) -> Option<Spread> {
        let mut v: Vec<f64> = values.into_iter().collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 {
            v[n / 2]
        } else {
            (v[n / 2 - 1] + v[n / 2]) / 2.0
        };
        // Nearest rank: the smallest value with at least 90% at or below it.
        let rank = (0.9 * n as f64).ceil() as usize;
        Some(Spread {
            median,
            p90: v[rank.clamp(1, n) - 1],
        })
    }
}

/// One binary's farm: its moves and single frames.
#[derive(Serialize)]
struct FarmFigures {
    bin: PathBuf,
    moves: Vec<MoveFigures>,
    single_frames: Vec<SingleFrame>,
    load_average_before: String,
    load_average_after: String,
}

/// The same eyes rendered in this process, seconds per quality.
#[derive(Serialize)]
struct LocalFigures {
    threads: usize,
    seconds: [Vec<f64>; 3],
}

#[derive(Serialize)]
struct ViewFigures {
    width: u32,
    height: u32,
    detail: f32,
    workers: usize,
    worker_threads: usize,
    farms: Vec<FarmFigures>,
    local: LocalFigures,
}

pub(crate) fn run(args: ViewArgs) -> Result<()> {
    ensure!(
        args.workers >= 1 && args.worker_threads >= 1 && args.moves >= 1,
        "--workers, --worker-threads and --moves must be at least 1"
    );
    // Each worker is a process of this machine and each thread a pool
    // thread of it: a localhost farm, not a cluster.
    ensure!(
        args.workers <= MAX_WORKERS && args.worker_threads <= MAX_WORKER_THREADS,
        "--workers at most {MAX_WORKERS}, --worker-threads at most {MAX_WORKER_THREADS} (a localhost farm)"
    );
    ensure!(
        args.timeout.is_finite() && args.timeout > 0.0 && args.timeout <= MAX_TIMEOUT_SECONDS,
        "--timeout must be a positive number of seconds, at most {MAX_TIMEOUT_SECONDS}"
    );
    let offsets = move_offsets(args.moves + 1, args.step)?;
    let singles = single_frame_offsets(args.single_frames, args.step)?;
    let bins = match args.bin.as_slice() {
        [] => vec![std::env::current_exe().context("finding this executable")?],
        bins => bins.to_vec(),
    };
    for bin in &bins {
        ensure!(bin.is_file(), "--bin {}: no such file", bin.display());
    }
    let job = args.frame.set_up(Quality::Full)?;
    let timeout = Duration::from_secs_f64(args.timeout);
    let runtime = crate::support::runtime()?;
    let mut farms = Vec::new();
    for bin in &bins {
        let load_average_before = crate::support::load_average();
        eprintln!(
            "{}: a master and {} worker(s) ...",
            bin.display(),
            args.workers
        );
        let dir = tempfile::Builder::new()
            .prefix("vtfarm-bench-view-")
            .tempdir()
            .context("creating a temporary directory")?;
        let mut farm = Processes::start(bin, dir.path(), args.workers, args.worker_threads)?;
        let result = runtime.block_on(async {
            tokio::time::timeout(START_TIMEOUT, farm.wait_for_workers(args.workers))
                .await
                .map_err(|_| farm.failure("the workers did not all connect within 60 s"))??;
            let source = farm
                .source_job(&job.setup, args.frame.detail, timeout)
                .await?;
            let mut moves = Vec::new();
            let mut events = EventStream::open(farm.http).await?;
            for (k, &offset) in offsets.iter().enumerate() {
                let timed = k > 0;
                let figures = farm
                    .time_move(&mut events, source, offset, timeout)
                    .await
                    .with_context(|| format!("move {k} (offset {offset:?} m)"))?;
                let s = figures.on_screen_seconds;
                eprintln!(
                    "  move {k}{}: preview {:.3} s, refine {:.3} s, full {:.3} s",
                    if timed { "" } else { " (warm-up)" },
                    s[0],
                    s[1],
                    s[2]
                );
                if timed {
                    moves.push(figures);
                }
                tokio::time::sleep(MOVE_PAUSE).await;
            }
            let mut single_frames = Vec::new();
            for (k, &offset) in singles.iter().enumerate() {
                let frame = farm
                    .time_single_frame(&job.setup, args.frame.detail, offset, k, timeout)
                    .await?;
                eprintln!(
                    "  single frame {k}: submission to image {:.3} s",
                    frame.submit_to_image_seconds
                );
                single_frames.push(frame);
            }
            anyhow::Ok((moves, single_frames))
        });
        drop(farm);
        let (moves, single_frames) = result?;
        farms.push(FarmFigures {
            bin: bin.clone(),
            moves,
            single_frames,
            load_average_before,
            load_average_after: crate::support::load_average(),
        });
    }
    runtime.shutdown_timeout(Duration::from_secs(2));
    eprintln!("rendering the same eyes in this process ...");
    let local = local_renders(&job.scene, &job.reflectors, &job.setup, &offsets[1..]);
    let figures = ViewFigures {
        width: job.setup.camera.width,
        height: job.setup.camera.height,
        detail: args.frame.detail,
        workers: args.workers,
        worker_threads: args.worker_threads,
        farms,
        local,
    };
    print_figures(&figures, &args, job.scene.triangles.len());
    if let Some(path) = &args.json {
        write_json(path, &figures)?;
    }
    Ok(())
}

/// The eyes' offsets from the source eye: left and right of it in turn
/// (`step` apart), each `step / 10` higher than the last, so every move
/// goes about `step` and no two eyes are equal.
fn move_offsets(moves: usize, step: f32) -> Result<Vec<[f32; 3]>> {
    let offsets: Vec<[f32; 3]> = (0..moves)
        .map(|k| {
            let side = if k % 2 == 0 { 0.5 } else { -0.5 };
            [side * step, (k + 1) as f32 * step / 10.0, 0.0]
        })
        .collect();
    within_eye_box(&offsets, "--moves and --step")?;
    Ok(offsets)
}

/// The single-frame jobs' eye offsets: below the source eye, apart from
/// the moves' and from each other.
fn single_frame_offsets(frames: usize, step: f32) -> Result<Vec<[f32; 3]>> {
    let offsets: Vec<[f32; 3]> = (0..frames)
        .map(|k| [0.0, -((k + 1) as f32) * step / 10.0, 0.0])
        .collect();
    within_eye_box(&offsets, "--single-frames and --step")?;
    Ok(offsets)
}

fn within_eye_box(offsets: &[[f32; 3]], options: &str) -> Result<()> {
    let largest = (offsets.iter().flatten()).fold(0.0f32, |m, v| m.max(v.abs()));
    ensure!(
        largest.is_finite() && largest <= EYE_BOX,
        "{options} put the eye {largest} m from the source eye; the view keeps it within {EYE_BOX} m"
    );
    Ok(())
}

/// The farm's processes, stopped when this is dropped: each asked to end
/// (SIGTERM), then killed after a bounded wait, and reaped.
struct Processes {
    bin: PathBuf,
    dir: PathBuf,
    cluster: PathBuf,
    http: SocketAddr,
    children: Vec<(String, Child)>,
}

/// How long a stopped process may take to end before it is killed.
const STOP_GRACE: Duration = Duration::from_secs(3);

impl Processes {
    /// `vtfarm cluster init`, then a master (QUIC and HTTP on free ports of
    /// 127.0.0.1) and `workers` workers, each its own process with its own
    /// scene cache; logs in `dir`.
    fn start(bin: &Path, dir: &Path, workers: usize, threads: usize) -> Result<Processes> {
        let quic_port = std::net::UdpSocket::bind("127.0.0.1:0")?
            .local_addr()?
            .port();
        let http = std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?;
        let master = format!("127.0.0.1:{quic_port}");
        let cluster_dir = dir.join("cluster");
        let init = Command::new(bin)
            .args(["cluster", "init", "--master", &master, "-o"])
            .arg(&cluster_dir)
            .output()
            .with_context(|| format!("running {} cluster init", bin.display()))?;
        ensure!(
            init.status.success(),
            "{} cluster init failed: {}",
            bin.display(),
            String::from_utf8_lossy(&init.stderr)
        );
        let mut farm = Processes {
            bin: bin.to_owned(),
            dir: dir.to_owned(),
            cluster: cluster_dir.join("cluster.toml"),
            http,
            children: Vec::new(),
        };
        let cluster = farm.cluster.clone();
        farm.spawn("master", |c| {
            c.arg("master").arg("--cluster").arg(&cluster).args([
                "--listen",
                &master,
                "--http",
                &http.to_string(),
            ]);
        })?;
        for k in 0..workers {
            let cache = dir.join(format!("cache-{k}"));
            farm.spawn(&format!("worker-{k}"), |c| {
                c.arg("worker")
                    .arg("--cluster")
                    .arg(&cluster)
                    .args(["--threads", &threads.to_string()])
                    .args(["--name", &format!("bench-{k}")])
                    .arg("--cache")
                    .arg(&cache);
            })?;
        }
        Ok(farm)
    }

    /// Starts `bin` with the arguments `args` sets, output to `dir/NAME.log`.
    fn spawn(&mut self, name: &str, args: impl FnOnce(&mut Command)) -> Result<()> {
        let log = File::create(self.dir.join(format!("{name}.log")))?;
        let mut command = Command::new(&self.bin);
        args(&mut command);
        command
            .env("RUST_LOG", "warn")
            .stdin(Stdio::null())
            .stdout(log.try_clone()?)
            .stderr(log);
        end_with_this_process(&mut command);
        let child = (command.spawn()).with_context(|| format!("starting the {name}"))?;
        self.children.push((name.to_owned(), child));
        Ok(())
    }

    /// An error saying `what`, with any process that ended and its log's end.
    fn failure(&mut self, what: &str) -> anyhow::Error {
        let mut text = what.to_owned();
        for (name, child) in &mut self.children {
            if let Ok(Some(status)) = child.try_wait() {
                let log = std::fs::read_to_string(self.dir.join(format!("{name}.log")));
                let log = log.unwrap_or_default();
                let tail: Vec<&str> = log.lines().rev().take(10).collect();
                text += &format!("\nthe {name} ended ({status}); its log ends:");
                for line in tail.into_iter().rev() {
                    text += &format!("\n  {line}");
                }
            }
        }
        anyhow::anyhow!(text)
    }

    /// Waits until the master lists `workers` workers (the caller bounds it).
    async fn wait_for_workers(&mut self, workers: usize) -> Result<()> {
        loop {
            if let Ok(status) = get_json(self.http, "/api/status").await {
                let listed = status["workers"].as_array().map_or(0, Vec::len);
                if listed >= workers {
                    return Ok(());
                }
            }
            if (self.children.iter_mut()).any(|(_, c)| matches!(c.try_wait(), Ok(Some(_)))) {
                return Err(self.failure("a process of the farm ended"));
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// Submits the cockpit at `setup`'s eye as a one-frame job, waits for
    /// it and answers its id among the view's sources (the newest).
    async fn source_job(
        &mut self,
        setup: &FrameSetup,
        detail: f32,
        timeout: Duration,
    ) -> Result<u64> {
        eprintln!("  the source frame (the workers load the scene) ...");
        self.submit(setup, detail, [0.0; 3], "source", timeout)
            .await?;
        let dashboard = get_json(self.http, "/api/dashboard").await?;
        let sources = dashboard["view"]["sources"].as_array();
        let newest = sources
            .and_then(|s| s.last())
            .and_then(|s| s["job"].as_u64());
        newest.context("the master lists no job for the view after the source frame")
    }

    /// Runs `vtfarm submit` of a one-frame cockpit job at `setup`'s eye
    /// moved by `offset`, bounded by `timeout`; answers its process's wall
    /// time and its output directory.
    async fn submit(
        &mut self,
        setup: &FrameSetup,
        detail: f32,
        offset: [f32; 3],
        name: &str,
        timeout: Duration,
    ) -> Result<(Duration, PathBuf)> {
        let job = self.dir.join(format!("{name}.toml"));
        std::fs::write(&job, one_frame_job(setup, detail, offset))?;
        let out = self.dir.join(name);
        let start = Instant::now();
        let mut command = tokio::process::Command::new(&self.bin);
        command
            .arg("submit")
            .arg(&job)
            .arg("--cluster")
            .arg(&self.cluster)
            .arg("-o")
            .arg(&out)
            .env("RUST_LOG", "warn")
            .stdin(Stdio::null())
            .kill_on_drop(true);
        let run = tokio::time::timeout(timeout, command.output()).await;
        let Ok(output) = run else {
            return Err(self.failure(&format!(
                "the {name} job did not finish within {} s",
                timeout.as_secs_f64()
            )));
        };
        let output = output.context("running vtfarm submit")?;
        if !output.status.success() {
            let what = format!(
                "the {name} job failed: {}",
                String::from_utf8_lossy(&output.stderr).trim()
            );
            return Err(self.failure(&what));
        }
        Ok((start.elapsed(), out))
    }

    /// A single-frame job: submission to image, and its frame's wall time.
    async fn time_single_frame(
        &mut self,
        setup: &FrameSetup,
        detail: f32,
        offset: [f32; 3],
        k: usize,
        timeout: Duration,
    ) -> Result<SingleFrame> {
        let name = format!("single-{k}");
        let (process, out) = self.submit(setup, detail, offset, &name, timeout).await?;
        let path = out.join("stats.json");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        let stats: Value =
            serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))?;
        let frame = &stats[0];
        let micros = |key: &str| {
            (frame[key].as_u64())
                .with_context(|| format!("{}: frame 0 has no {key}", path.display()))
        };
        Ok(SingleFrame {
            submit_to_image_seconds: micros("arrival_micros")? as f64 / 1e6,
            process_seconds: process.as_secs_f64(),
            wall_seconds: micros("wall_micros")? as f64 / 1e6,
        })
    }

    /// Moves the view's eye to `offset` from the source's and follows the
    /// event stream until every stage of the move is listed as rendered.
    async fn time_move(
        &mut self,
        events: &mut EventStream,
        source: u64,
        offset: [f32; 3],
        timeout: Duration,
    ) -> Result<MoveFigures> {
        events.discard_pending()?;
        let sent = Instant::now();
        let body = serde_json::json!({ "job": source, "offset": offset }).to_string();
        let (status, reply) = request(self.http, "POST", "/api/view", Some(&body)).await?;
        ensure!(
            status == 200,
            "POST /api/view answered {status}: {}",
            String::from_utf8_lossy(&reply).trim()
        );
        let reply: Value = serde_json::from_slice(&reply).context("POST /api/view: not JSON")?;
        let job = reply["job"]
            .as_u64()
            .context("POST /api/view answered no job")?;
        let deadline = tokio::time::Instant::from_std(sent + timeout);
        let mut watch = MoveWatch::new(job, offset);
        while !watch.done() {
            let event = tokio::time::timeout_at(deadline, events.next()).await;
            let Ok(event) = event else {
                bail!(
                    "the {} stage was not on screen within {} s",
                    watch.missing().name(),
                    timeout.as_secs_f64()
                );
            };
            let (at, event) = event?;
            watch.saw(at.saturating_duration_since(sent), &event)?;
        }
        Ok(watch.figures)
    }
}

impl Drop for Processes {
    fn drop(&mut self) {
        for (_, child) in &self.children {
            // SAFETY: `kill` only sends a signal to our own child's pid.
            unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
        }
        let deadline = Instant::now() + STOP_GRACE;
        for (_, child) in &mut self.children {
            while matches!(child.try_wait(), Ok(None)) && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Asks the kernel to stop the child (SIGTERM) when the thread that started
/// it ends, so a bench killed by a signal leaves no farm behind. (The
/// processes are started from the main thread, which lives as long as the
/// bench.)
#[cfg(target_os = "linux")]
fn end_with_this_process(command: &mut Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: the closure runs in the child between fork and exec and only
    // calls `prctl`, which is async-signal-safe.
    unsafe {
        command.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
            Ok(())
        });
    }
}

#[cfg(not(target_os = "linux"))]
fn end_with_this_process(_: &mut Command) {}

/// A one-frame job of the built-in cockpit at `setup`'s size and eye
/// moved by `offset` (the eye given explicitly, everything else the
/// cockpit's and the job file's defaults, as `setup` was made).
fn one_frame_job(setup: &FrameSetup, detail: f32, offset: [f32; 3]) -> String {
    let eye = setup.camera.eye + glam::Vec3::from(offset);
    // Floats in Debug form: always with a point (TOML's floats).
    format!(
        "[scene]\nbuiltin = \"cockpit\"\ndetail = {detail:?}\n\
         [camera]\nwidth = {}\nheight = {}\neye = [{:?}, {:?}, {:?}]\n\
         [quality]\nlevel = \"full\"\n",
        setup.camera.width, setup.camera.height, eye.x, eye.y, eye.z
    )
}

/// What a move's events have shown so far: the stages listed as rendered
/// (`view.outcomes`) for the move's job, and their frames (`frames`).
struct MoveWatch {
    job: u64,
    seen: [bool; 3],
    figures: MoveFigures,
}

impl MoveWatch {
    fn new(job: u64, offset: [f32; 3]) -> MoveWatch {
        MoveWatch {
            job,
            seen: [false; 3],
            figures: MoveFigures {
                offset,
                ..MoveFigures::default()
            },
        }
    }

    fn done(&self) -> bool {
        self.seen.iter().all(|s| *s)
    }

    /// The first stage not yet seen (the last one when all are).
    fn missing(&self) -> Quality {
        let k = self.seen.iter().position(|s| !s).unwrap_or(2);
        STAGES[k]
    }

    /// An event of the dashboard's stream, `after` the move was requested.
    fn saw(&mut self, after: Duration, event: &Value) -> Result<()> {
        let outcomes = event["view"]["outcomes"].as_array().map_or(&[][..], |o| o);
        for outcome in outcomes {
            if outcome["job"].as_u64() != Some(self.job) {
                continue;
            }
            match outcome["kind"].as_str() {
                Some("rendered") => {
                    let quality = outcome["quality"].as_str().unwrap_or_default();
                    let Some(k) = STAGES.iter().position(|q| q.name() == quality) else {
                        bail!("the view lists an unknown stage '{quality}'");
                    };
                    if !self.seen[k] {
                        self.seen[k] = true;
                        self.figures.on_screen_seconds[k] = after.as_secs_f64();
                    }
                }
                Some("cancelled") => bail!(
                    "the master cancelled the move's job {} before its {} stage",
                    self.job,
                    self.missing().name()
                ),
                _ => {}
            }
        }
        let frames = event["frames"].as_array().map_or(&[][..], |f| f);
        for frame in frames {
            let index = frame["frame"].as_u64().unwrap_or(u64::MAX) as usize;
            if frame["job"].as_u64() == Some(self.job) && index < STAGES.len() {
                self.figures.frames[index] = Some(StageFrame::from_stats(&frame["stats"]));
            }
        }
        Ok(())
    }
}

impl StageFrame {
    /// From a `FrameStats` as JSON; phases of kinds it does not know are
    /// left out (a newer server may add some).
    fn from_stats(stats: &Value) -> StageFrame {
        let mut frame = StageFrame {
            wall: stats["wall_micros"].as_u64().unwrap_or(0) as f64 / 1e6,
            ..StageFrame::default()
        };
        // Per worker and kind: the time covered by its phases (a package in
        // flight overlaps the one computing: the worker asks one ahead).
        let mut by_worker = std::collections::BTreeMap::<(&str, &str), Vec<(u64, u64)>>::new();
        for phase in stats["phases"].as_array().map_or(&[][..], |p| p) {
            let micros = |key: &str| phase[key].as_u64().unwrap_or(0);
            let who = phase["who"].as_str().unwrap_or_default();
            let kind = phase["kind"].as_str().unwrap_or_default();
            let span = (micros("start_micros"), micros("end_micros"));
            by_worker.entry((who, kind)).or_default().push(span);
        }
        let by_worker =
            (by_worker.into_iter()).map(|(key, spans)| (key, covered_micros(spans) as f64 / 1e6));
        for ((who, kind), total) in by_worker {
            let busiest = match (who, kind) {
                ("master", "base") => &mut frame.base,
                (_, "setup") => &mut frame.setup,
                (_, "package") => &mut frame.packages,
                (_, "sending") => &mut frame.sending,
                _ => continue,
            };
            *busiest = busiest.max(total);
        }
        frame
    }
}

/// The time the union of `spans` (start, end) covers.
fn covered_micros(mut spans: Vec<(u64, u64)>) -> u64 {
    spans.sort_unstable();
    let (mut covered, mut reached) = (0, 0);
    for (start, end) in spans {
        let start = start.max(reached);
        if end > start {
            covered += end - start;
            reached = end;
        }
    }
    covered
}

/// `GET path` answered as JSON (an error for any status but 200).
async fn get_json(address: SocketAddr, path: &str) -> Result<Value> {
    let (status, body) = request(address, "GET", path, None).await?;
    ensure!(status == 200, "GET {path} answered {status}");
    serde_json::from_slice(&body).with_context(|| format!("GET {path}: not JSON"))
}

/// One HTTP/1.1 request over a fresh connection (closed after it), with
/// an optional JSON body: the status and the body (de-chunked), bounded by
/// [`MAX_BODY`] and [`REQUEST_TIMEOUT`].
async fn request(
    address: SocketAddr,
    method: &str,
    path: &str,
    json: Option<&str>,
) -> Result<(u16, Vec<u8>)> {
    let answer = tokio::time::timeout(REQUEST_TIMEOUT, exchange(address, method, path, json));
    (answer.await).with_context(|| format!("{method} {path}: no answer within 30 s"))?
}

async fn exchange(
    address: SocketAddr,
    method: &str,
    path: &str,
    json: Option<&str>,
) -> Result<(u16, Vec<u8>)> {
    let mut stream = TcpStream::connect(address)
        .await
        .with_context(|| format!("connecting to the master's HTTP at {address}"))?;
    let body = json.unwrap_or_default();
    let head = format!(
        "{method} {path} HTTP/1.1\r\nHost: {address}\r\nConnection: close\r\n\
         Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    );
    stream.write_all(head.as_bytes()).await?;
    let mut answer = Vec::new();
    (&mut stream)
        .take(MAX_BODY as u64)
        .read_to_end(&mut answer)
        .await?;
    let (status, chunked, start) = parse_head(&answer)
        .with_context(|| format!("{method} {path}: not an HTTP answer"))?
        .context("the answer ended within its head")?;
    let raw = &answer[start..];
    if !chunked {
        return Ok((status, raw.to_vec()));
    }
    let mut body = Vec::new();
    let mut decoder = Dechunker::default();
    decoder.feed(raw, &mut body)?;
    Ok((status, body))
}

/// An HTTP answer's head: its status, whether its body is chunked, and
/// where the body starts; `Ok(None)` while the head is incomplete.
fn parse_head(bytes: &[u8]) -> Result<Option<(u16, bool, usize)>> {
    let Some(end) = bytes.windows(4).position(|w| w == b"\r\n\r\n") else {
        return Ok(None);
    };
    let head = std::str::from_utf8(&bytes[..end]).context("the head is not UTF-8")?;
    let mut lines = head.split("\r\n");
    let status_line = lines.next().unwrap_or_default();
    let status = (status_line.split(' ').nth(1))
        .and_then(|s| s.parse().ok())
        .with_context(|| format!("no status in '{status_line}'"))?;
    let chunked = lines.any(|line| {
        line.split_once(':').is_some_and(|(k, v)| {
            k.trim().eq_ignore_ascii_case("transfer-encoding")
                && v.to_ascii_lowercase().contains("chunked")
        })
    });
    Ok(Some((status, chunked, end + 4)))
}

/// HTTP/1.1 chunked transfer decoding, fed as bytes arrive.
#[derive(Default)]
struct Dechunker {
    /// Bytes of a size line or a chunk's closing CRLF not yet complete.
    pending: Vec<u8>,
    /// Bytes left of the current chunk's data.
    left: usize,
    /// The CRLF after a chunk's data is still due.
    closing: bool,
    ended: bool,
}

impl Dechunker {
    /// Decodes `input`, appending the data to `out`.
    fn feed(&mut self, mut input: &[u8], out: &mut Vec<u8>) -> Result<()> {
        while !input.is_empty() && !self.ended {
            if self.left > 0 {
                let n = self.left.min(input.len());
                out.extend_from_slice(&input[..n]);
                (self.left, input) = (self.left - n, &input[n..]);
                self.closing = self.left == 0;
                continue;
            }
            let Some(eol) = input.iter().position(|&b| b == b'\n') else {
                self.pending.extend_from_slice(input);
                ensure!(
                    self.pending.len() <= 4096,
                    "a chunk's size line is too long"
                );
                return Ok(());
            };
            self.pending.extend_from_slice(&input[..=eol]);
            input = &input[eol + 1..];
            let line = std::mem::take(&mut self.pending);
            let line = std::str::from_utf8(&line).context("a chunk's size line is not UTF-8")?;
            let line = line.trim_end_matches(['\r', '\n']);
            if self.closing {
                ensure!(line.is_empty(), "a chunk's data does not end with CRLF");
                self.closing = false;
                continue;
            }
            let size = line.split(';').next().unwrap_or_default().trim();
            let size = usize::from_str_radix(size, 16)
                .with_context(|| format!("'{line}' is not a chunk size"))?;
            ensure!(size <= MAX_BODY, "a chunk of {size} bytes is too large");
            self.left = size;
            self.ended = size == 0;
        }
        Ok(())
    }
}

/// Server-sent events, parsed as lines arrive: an event's `data:` lines
/// joined, handed out at the blank line that ends it.
#[derive(Default)]
struct EventParser {
    line: Vec<u8>,
    data: String,
    kind: String,
}

/// One parsed server-sent event.
#[derive(Debug, PartialEq)]
struct SseEvent {
    kind: String,
    data: String,
}

impl EventParser {
    /// Parses `bytes`, pushing each completed event.
    fn feed(&mut self, bytes: &[u8], events: &mut Vec<SseEvent>) -> Result<()> {
        for &b in bytes {
            if b != b'\n' {
                self.line.push(b);
                ensure!(self.line.len() <= MAX_BODY, "an event line is too long");
                continue;
            }
            let line = std::mem::take(&mut self.line);
            let line = std::str::from_utf8(&line).context("an event line is not UTF-8")?;
            let line = line.strip_suffix('\r').unwrap_or(line);
            if line.is_empty() {
                if !self.data.is_empty() || !self.kind.is_empty() {
                    events.push(SseEvent {
                        kind: std::mem::take(&mut self.kind),
                        data: std::mem::take(&mut self.data),
                    });
                }
                continue;
            }
            let (field, value) = line.split_once(':').unwrap_or((line, ""));
            let value = value.strip_prefix(' ').unwrap_or(value);
            match field {
                "event" => self.kind = value.to_owned(),
                "data" => {
                    if !self.data.is_empty() {
                        self.data.push('\n');
                    }
                    self.data.push_str(value);
                }
                _ => {} // comments (empty field), id, retry
            }
        }
        Ok(())
    }
}

/// The dashboard's event stream: each `farm` event's JSON with the time it
/// was read, from a task of its own (so events are timed as they come, not
/// when the bench asks).
struct EventStream {
    events: mpsc::UnboundedReceiver<Result<(Instant, Value)>>,
    reader: tokio::task::JoinHandle<()>,
}

impl EventStream {
    async fn open(address: SocketAddr) -> Result<EventStream> {
        let mut stream = TcpStream::connect(address)
            .await
            .with_context(|| format!("connecting to the master's HTTP at {address}"))?;
        let head = format!("GET /api/events HTTP/1.1\r\nHost: {address}\r\n\r\n");
        stream.write_all(head.as_bytes()).await?;
        let (send, events) = mpsc::unbounded_channel();
        let reader = tokio::spawn(async move {
            if let Err(e) = read_events(stream, &send).await {
                let _ = send.send(Err(e));
            }
        });
        Ok(EventStream { events, reader })
    }

    /// The next `farm` event.
    async fn next(&mut self) -> Result<(Instant, Value)> {
        match self.events.recv().await {
            Some(event) => event,
            None => bail!("the event stream ended"),
        }
    }

    /// Drops the events read so far (a failure of the stream is kept).
    fn discard_pending(&mut self) -> Result<()> {
        while let Ok(event) = self.events.try_recv() {
            event?;
        }
        Ok(())
    }
}

impl Drop for EventStream {
    fn drop(&mut self) {
        self.reader.abort();
    }
}

async fn read_events(
    mut stream: TcpStream,
    send: &mpsc::UnboundedSender<Result<(Instant, Value)>>,
) -> Result<()> {
    let mut buffer = vec![0; 1 << 16];
    let mut head = Vec::new();
    let (status, chunked, start) = loop {
        let n = stream.read(&mut buffer).await?;
        ensure!(n > 0, "the event stream closed before its head");
        head.extend_from_slice(&buffer[..n]);
        ensure!(head.len() <= 1 << 20, "the event stream's head is too long");
        if let Some(parsed) = parse_head(&head)? {
            break parsed;
        }
    };
    ensure!(status == 200, "GET /api/events answered {status}");
    let mut dechunker = chunked.then(Dechunker::default);
    let mut parser = EventParser::default();
    let (mut body, mut events) = (Vec::new(), Vec::new());
    let mut input = head.split_off(start);
    loop {
        match &mut dechunker {
            Some(d) => d.feed(&input, &mut body)?,
            None => body.append(&mut input),
        }
        parser.feed(&body, &mut events)?;
        body.clear();
        let at = Instant::now();
        for event in events.drain(..) {
            if event.kind == "farm" {
                let json = serde_json::from_str(&event.data).context("an event is not JSON")?;
                if send.send(Ok((at, json))).is_err() {
                    return Ok(());
                }
            }
        }
        let n = stream.read(&mut buffer).await?;
        ensure!(n > 0, "the event stream ended");
        input = buffer[..n].to_vec();
    }
}

/// Renders each move's eye at each quality in this process (after one
/// untimed frame: the shadow maps built, as a running renderer has them),
/// wall seconds each, set-up included.
fn local_renders(
    scene: &std::sync::Arc<vtfarm_scene::Scene>,
    reflectors: &[u32],
    setup: &FrameSetup,
    offsets: &[[f32; 3]],
) -> LocalFigures {
    let renderer = Renderer::new(scene.clone(), reflectors.to_vec());
    let options = RenderOptions::default();
    let at = |offset: [f32; 3], quality| {
        let mut s = setup.clone();
        s.camera.eye += glam::Vec3::from(offset);
        s.vertex.quality = quality;
        s
    };
    renderer.render(&at([0.0; 3], Quality::Preview), &options, &mut |_, _| {});
    let seconds = STAGES.map(|quality| {
        (offsets.iter())
            .map(|&offset| {
                let setup = at(offset, quality);
                let start = Instant::now();
                renderer.render(&setup, &options, &mut |_, _| {});
                start.elapsed().as_secs_f64()
            })
            .collect()
    });
    LocalFigures {
        threads: rayon::current_num_threads(),
        seconds,
    }
}

fn print_figures(f: &ViewFigures, args: &ViewArgs, triangles: usize) {
    println!(
        "bench view — cockpit {triangles} triangles (detail {}), {}x{}; a master and {} worker process(es) of --threads {} on 127.0.0.1; \
         {} moves of {} m through POST /api/view (after one warm-up move), each timed until the event stream lists the stage",
        f.detail, f.width, f.height, f.workers, f.worker_threads, args.moves, args.step
    );
    println!(
        "columns: on screen = move to the first event listing the stage; the stage's frame as the master's timeline has it \
         (medians): wall = its first assignment to its last result, base = the master's base frame, set-up / packages / in flight = \
         the busiest worker's; local = the same eye rendered in this process on {} thread(s), set-up included",
        f.local.threads
    );
    let ms = |s: Option<f64>| s.map_or("-".to_owned(), |s| format!("{:.0}", s * 1e3));
    for farm in &f.farms {
        println!(
            "{} (load average {} before, {} after)",
            farm.bin.display(),
            farm.load_average_before,
            farm.load_average_after
        );
        println!(
            "  {:<8} {:>10} {:>8} | {:>8} {:>8} {:>8} {:>9} {:>9} | {:>8}",
            "stage",
            "median ms",
            "p90 ms",
            "wall",
            "base",
            "set-up",
            "packages",
            "in flight",
            "local ms"
        );
        for (k, quality) in STAGES.iter().enumerate() {
            let on_screen = Spread::of(farm.moves.iter().map(|m| m.on_screen_seconds[k]));
            let frames: Vec<&StageFrame> = farm
                .moves
                .iter()
                .filter_map(|m| m.frames[k].as_ref())
                .collect();
            let phase = |get: fn(&StageFrame) -> f64| {
                Spread::of(frames.iter().map(|f| get(f))).map(|s| s.median)
            };
            let local = Spread::of(f.local.seconds[k].iter().copied());
            println!(
                "  {:<8} {:>10} {:>8} | {:>8} {:>8} {:>8} {:>9} {:>9} | {:>8}",
                quality.name(),
                ms(on_screen.map(|s| s.median)),
                ms(on_screen.map(|s| s.p90)),
                ms(phase(|f| f.wall)),
                ms(phase(|f| f.base)),
                ms(phase(|f| f.setup)),
                ms(phase(|f| f.packages)),
                ms(phase(|f| f.sending)),
                ms(local.map(|s| s.median)),
            );
        }
        if let Some(spread) = single_frame_spread(farm) {
            println!(
                "  single-frame jobs ({}): submission to image median {} ms, p90 {} ms (the master's frame wall median {} ms)",
                farm.single_frames.len(),
                ms(Some(spread.0.median)),
                ms(Some(spread.0.p90)),
                ms(Some(spread.1.median)),
            );
        }
    }
    let [first, rest @ ..] = f.farms.as_slice() else {
        return;
    };
    for farm in rest {
        let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) if b > 0.0 => format!("{:.2}", a / b),
            _ => "-".to_owned(),
        };
        let stage = |farm: &FarmFigures, k: usize| {
            Spread::of(farm.moves.iter().map(|m| m.on_screen_seconds[k])).map(|s| s.median)
        };
        let single = |farm: &FarmFigures| single_frame_spread(farm).map(|s| s.0.median);
        println!(
            "{} over {} (medians): preview {}, refine {}, full {}, single frame {}",
            first.bin.display(),
            farm.bin.display(),
            ratio(stage(first, 0), stage(farm, 0)),
            ratio(stage(first, 1), stage(farm, 1)),
            ratio(stage(first, 2), stage(farm, 2)),
            ratio(single(first), single(farm)),
        );
    }
}

/// The single frames' submission-to-image and master wall spreads.
fn single_frame_spread(farm: &FarmFigures) -> Option<(Spread, Spread)> {
    let frames = &farm.single_frames;
    Some((
        Spread::of(frames.iter().map(|s| s.submit_to_image_seconds))?,
        Spread::of(frames.iter().map(|s| s.wall_seconds))?,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_and_the_90th_percentile_by_nearest_rank() {
        assert_eq!(Spread::of([]), None);
        let one = Spread::of([0.4]).unwrap();
        assert_eq!((one.median, one.p90), (0.4, 0.4));
        // Odd count: the middle; p90 of 5 is the 5th (ceil 4.5).
        let five = Spread::of([0.53, 0.40, 0.47, 0.44, 0.50]).unwrap();
        assert_eq!((five.median, five.p90), (0.47, 0.53));
        // Even count: the mean of the two middle ones; p90 of 10 is the 9th.
        let ten = Spread::of((1..=10).map(f64::from)).unwrap();
        assert_eq!((ten.median, ten.p90), (5.5, 9.0));
    }

    #[test]
    fn chunked_bodies_decode_however_the_bytes_are_cut() {
        let wire = b"4\r\nWiki\r\n7;ext=1\r\npedia i\r\nB\r\nn \r\nchunks.\r\n0\r\n\r\n";
        for cut in 1..wire.len() {
            let (mut decoder, mut out) = (Dechunker::default(), Vec::new());
            for piece in wire.chunks(cut) {
                decoder.feed(piece, &mut out).unwrap();
            }
            assert_eq!(out, b"Wikipedia in \r\nchunks.", "pieces of {cut}");
            assert!(decoder.ended);
        }
        let mut out = Vec::new();
        let error = Dechunker::default().feed(b"zz\r\n", &mut out).unwrap_err();
        assert_eq!(error.to_string(), "'zz' is not a chunk size");
        let error = (Dechunker::default().feed(b"2\r\nabX\r\n", &mut out)).unwrap_err();
        assert_eq!(error.to_string(), "a chunk's data does not end with CRLF");
    }

    #[test]
    fn server_sent_events_join_their_data_lines_and_end_at_a_blank_line() {
        let wire = "event: farm\ndata: {\"a\":\ndata: 1}\n\n: a comment\n\nevent: farm\r\ndata:{}\r\n\r\nevent: farm\ndata: 2";
        for cut in 1..wire.len() {
            let (mut parser, mut events) = (EventParser::default(), Vec::new());
            for piece in wire.as_bytes().chunks(cut) {
                parser.feed(piece, &mut events).unwrap();
            }
            let farm = |data: &str| SseEvent {
                kind: "farm".into(),
                data: data.into(),
            };
            // The last event has no blank line yet: not handed out.
            assert_eq!(events, [farm("{\"a\":\n1}"), farm("{}")], "pieces of {cut}");
        }
    }

    #[test]
    fn http_heads_give_the_status_the_coding_and_the_body() {
        let answer = b"HTTP/1.1 200 OK\r\ncontent-type: text/event-stream\r\nTransfer-Encoding: chunked\r\n\r\n5\r\n";
        assert_eq!(
            parse_head(answer).unwrap(),
            Some((200, true, answer.len() - 3))
        );
        let answer = b"HTTP/1.1 400 Bad Request\r\ncontent-length: 4\r\n\r\nbad\n";
        assert_eq!(
            parse_head(answer).unwrap(),
            Some((400, false, answer.len() - 4))
        );
        assert_eq!(parse_head(b"HTTP/1.1 200 OK\r\nconte").unwrap(), None);
        assert!(parse_head(b"garbage\r\n\r\n").is_err());
    }

    /// A move's stages are timed at the first event that lists each for the
    /// move's job (other jobs' outcomes and frames ignored), with each
    /// stage's frame phases; a cancelled move is an error naming the stage.
    #[test]
    fn a_move_is_timed_by_the_first_event_listing_each_stage() {
        let rendered = |job: u64, quality: &str| serde_json::json!({ "kind": "rendered", "generation": 1, "job": job, "quality": quality });
        let stats = serde_json::json!({
            "wall_micros": 300_000,
            "phases": [
                { "who": "master", "kind": "base", "start_micros": 0, "end_micros": 60_000 },
                { "who": "w0", "kind": "setup", "start_micros": 1_000, "end_micros": 101_000 },
                { "who": "w0", "kind": "package", "start_micros": 101_000, "end_micros": 201_000 },
                { "who": "w0", "kind": "package", "start_micros": 210_000, "end_micros": 260_000 },
                { "who": "w1", "kind": "package", "start_micros": 5_000, "end_micros": 105_000 },
                { "who": "w1", "kind": "sending", "start_micros": 105_000, "end_micros": 107_000 },
                { "who": "w1", "kind": "sending", "start_micros": 106_000, "end_micros": 108_000 },
                { "who": "w1", "kind": "later", "start_micros": 0, "end_micros": 9_000_000 },
            ],
        });
        let event = |outcomes: Vec<Value>, frames: Vec<Value>| serde_json::json!({ "view": { "outcomes": outcomes }, "frames": frames });
        let mut watch = MoveWatch::new(7, [0.005, 0.001, 0.0]);
        let ms = Duration::from_millis;
        watch
            .saw(ms(50), &event(vec![rendered(6, "preview")], vec![]))
            .unwrap();
        assert_eq!(watch.missing(), Quality::Preview);
        let first = event(
            vec![rendered(6, "full"), rendered(7, "preview")],
            vec![serde_json::json!({ "seq": 4, "job": 7, "frame": 0, "stats": stats })],
        );
        watch.saw(ms(120), &first).unwrap();
        watch.saw(ms(150), &first).unwrap();
        let second = event(
            vec![
                rendered(7, "preview"),
                rendered(7, "refine"),
                rendered(7, "full"),
            ],
            vec![],
        );
        assert!(!watch.done());
        watch.saw(ms(400), &second).unwrap();
        assert!(watch.done());
        assert_eq!(watch.figures.on_screen_seconds, [0.12, 0.4, 0.4]);
        let preview = watch.figures.frames[0].clone().unwrap();
        let p = &preview;
        let figures = [p.wall, p.base, p.setup, p.packages, p.sending];
        // w0's two packages, not w1's one; w1's overlapping transfers
        // once; the unknown kind left out.
        let expected = [0.3, 0.06, 0.1, 0.15, 0.003];
        assert!(
            figures
                .iter()
                .zip(expected)
                .all(|(a, b)| (a - b).abs() < 1e-9),
            "{preview:?}"
        );
        assert!(watch.figures.frames[1].is_none());

        let mut watch = MoveWatch::new(8, [0.0; 3]);
        let cancelled = serde_json::json!({ "kind": "cancelled", "generation": 2, "job": 8 });
        let error = watch.saw(
            ms(10),
            &event(vec![rendered(8, "preview"), cancelled], vec![]),
        );
        assert_eq!(
            error.unwrap_err().to_string(),
            "the master cancelled the move's job 8 before its refine stage"
        );
    }

    #[test]
    fn the_eyes_differ_and_stay_within_the_eye_box() {
        let moves = move_offsets(6, 0.01).unwrap();
        let singles = single_frame_offsets(3, 0.01).unwrap();
        let all: Vec<_> = moves.iter().chain(&singles).collect();
        for (i, a) in all.iter().enumerate() {
            assert!(all[i + 1..].iter().all(|b| b != a), "{a:?} twice");
        }
        // Each move goes about one step.
        for w in moves.windows(2) {
            let d = glam::Vec3::from(w[1]) - glam::Vec3::from(w[0]);
            assert!((d.length() - 0.01).abs() < 0.0002, "{d:?}");
        }
        let error = move_offsets(200, 0.01).unwrap_err().to_string();
        assert!(
            error.starts_with("--moves and --step put the eye 0.2 m"),
            "{error}"
        );
        assert!(error.ends_with("within 0.15 m"), "{error}");
    }

    #[test]
    fn a_one_frame_job_names_the_moved_eye_and_the_size() {
        let job = crate::CockpitJob::new(0.3, 64, 36, Quality::Full).unwrap();
        let text = one_frame_job(&job.setup, 0.3, [0.0, 0.5, 0.0]);
        let parsed = vtfarm_job::parse_job(&text, Path::new("view.toml")).unwrap();
        let loaded = parsed.load_scene().unwrap();
        assert_eq!((loaded.camera.width, loaded.camera.height), (64, 36));
        let expected = job.setup.camera.eye + glam::Vec3::new(0.0, 0.5, 0.0);
        assert!((loaded.camera.eye - expected).length() < 1e-5);
        assert_eq!(parsed.vertex.quality, Quality::Full);
    }
}
