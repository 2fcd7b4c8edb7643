//! `vtfarm bench view`: the interactive view's latency as a user sees it.
//! A localhost farm of processes (a master and `--workers` workers of
//! `--bin`, default this executable, each worker `--worker-threads 1`)
//! renders one cockpit frame as the view's source; then the bench moves the
//! eye `--moves` times through the master's HTTP API (`POST /api/view`)
//! and times each move until each stage (preview, refine, full) is listed
//! as rendered on the dashboard's event stream (`GET /api/events`) and the
//! last stage's image, at the display's width, is in (`GET
//! /view/image.png?width=`; the stages before it are meshes the page draws),
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
use std::pin::pin;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail, ensure};
use futures_util::StreamExt;
use http_body_util::{BodyDataStream, BodyExt, Full, Limited};
use hyper::body::{Body, Bytes, Incoming};
use hyper::client::conn::http1;
use hyper::{Method, Request, Response, StatusCode, header};
use hyper_util::rt::TokioIo;
use serde::Serialize;
use serde_json::Value;
use sse_stream::SseByteStream;
use tokio::net::TcpStream;
use tokio::sync::mpsc;
// The box the server keeps the view's eye in: the bench's eyes stay within
// it, or the server would clamp some of them together.
use vtfarm_master::view::{EYE_BOX, STAGES};
use vtfarm_render::{FrameSetup, RenderOptions, Renderer};
use vtfarm_vertex::Quality;

use super::{CockpitFrameArgs, write_json};

mod page;

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
    /// The width in pixels the view is shown at: each stage counts as on
    /// screen once `GET /view/image.png?width=` answered it, as the
    /// dashboard asks (its 384 CSS pixels at a device pixel ratio of 2).
    #[arg(long, default_value_t = 768)]
    display_width: u32,
    /// Seconds a move's stages, the source frame or a single-frame job may
    /// take before the bench gives up with an error naming what it waited for.
    #[arg(long, default_value_t = 120.0)]
    timeout: f64,
    /// Also writes the figures as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Also drives the dashboard in headless Chromium (`chromium` on PATH;
    /// WebGL2 on SwiftShader, a 1400×1000 window), which draws the view
    /// itself: `--moves` arrow-key moves, each until its full stage is
    /// drawn, then a 2 s drag at 30 mouse moves a second; prints the
    /// page's own timings.
    #[arg(long)]
    browser: bool,
}

/// The most worker processes and threads per worker the bench starts.
const MAX_WORKERS: usize = 64;
const MAX_WORKER_THREADS: usize = 256;

/// The longest `--timeout`, in seconds (an hour).
const MAX_TIMEOUT_SECONDS: f64 = 3600.0;

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

/// Events read but not yet taken by the bench: beyond that the reader
/// waits, so a stream the bench does not follow holds bounded memory.
const EVENTS_QUEUED: usize = 1024;

/// One move: when each stage was listed and on screen after it, and each
/// stage's frame as the master recorded it (where the server lists it).
#[derive(Clone, Debug, Default, Serialize)]
struct MoveFigures {
    offset: [f32; 3],
    /// Seconds from the move's request to the first event listing the stage.
    listed_seconds: [f64; 3],
    /// Seconds from the move's request until the view's image, asked for
    /// at the display's width after the event listing the stage, was in
    /// (the stage's or a newer one's): the last stage's only, as the stages
    /// before it carry meshes, which the page draws (`--browser`).
    on_screen_seconds: [Option<f64>; 3],
    frames: [Option<StageFrame>; 3],
    /// The server's part of each stage: from the move's arrival to the
    /// stage's message for the page (`GET /api/view/stages`); `None` from
    /// a server without it.
    server_seconds: [Option<f64>; 3],
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
    /// The dashboard's own timings in Chromium (`--browser`).
    page: Option<page::PageFigures>,
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
        args.workers >= 1 && args.worker_threads >= 1 && args.moves >= 1 && args.display_width >= 1,
        "--workers, --worker-threads, --moves and --display-width must be at least 1"
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
    let chromium = match args.browser {
        true => Some(vtfarm_browser::which_chromium().context("--browser")?),
        false => None,
    };
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
                    .time_move(&mut events, source, offset, args.display_width, timeout)
                    .await
                    .with_context(|| format!("move {k} (offset {offset:?} m)"))?;
                let mut figures = figures;
                figures.server_seconds = farm.server_part().await;
                let (listed, full) = (figures.listed_seconds, figures.on_screen_seconds[2]);
                eprintln!(
                    "  move {k}{}: preview listed {:.3} s, refine listed {:.3} s, full on screen {:.3} s",
                    if timed { "" } else { " (warm-up)" },
                    listed[0],
                    listed[1],
                    full.unwrap_or(f64::NAN),
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
            let page = match &chromium {
                Some(chromium) => {
                    eprintln!("  the dashboard in Chromium ...");
                    let page = page::measure(chromium, farm.http, source, args.moves, timeout);
                    Some(page.await.context("--browser")?)
                }
                None => None,
            };
            anyhow::Ok((moves, single_frames, page))
        });
        drop(farm);
        let (moves, single_frames, page) = result?;
        farms.push(FarmFigures {
            bin: bin.clone(),
            moves,
            single_frames,
            page,
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
        // SIGTERM when this thread ends: the processes are started from the
        // main thread, which lives as long as the bench.
        vtfarm_browser::end_with_this_thread(&mut command, libc::SIGTERM);
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
        display_width: u32,
        timeout: Duration,
    ) -> Result<MoveFigures> {
        events.discard_pending()?;
        let sent = Instant::now();
        // As the page that draws the scene moves it (the master's base
        // frame then covers only what the packages look at).
        let body = serde_json::json!({ "job": source, "offset": offset, "page_draws_scene": true })
            .to_string();
        let (status, reply) = request(self.http, Method::POST, "/api/view", Some(&body)).await?;
        ensure!(
            status == StatusCode::OK,
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
            let listed = watch.saw(at.saturating_duration_since(sent), &event)?;
            let last = STAGES.len() - 1;
            if listed.contains(&last) {
                let path = format!("/view/image.png?width={display_width}&stage={job}");
                let (status, _) = request(self.http, Method::GET, &path, None).await?;
                ensure!(status == StatusCode::OK, "GET {path} answered {status}");
                watch.figures.on_screen_seconds[last] = Some(sent.elapsed().as_secs_f64());
            }
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

impl Processes {
    /// The current move's stages' server part, seconds (`None` for a
    /// stage not streamed, or a server without `GET /api/view/stages`).
    async fn server_part(&self) -> [Option<f64>; 3] {
        let mut part = [None; 3];
        let Ok(stages) = get_json(self.http, "/api/view/stages").await else {
            return part;
        };
        for stage in stages["stages"].as_array().map_or(&[][..], |s| s) {
            let quality = stage["quality"].as_str().unwrap_or_default();
            if let Some(k) = STAGES.iter().position(|q| q.name() == quality) {
                part[k] = stage["server_ms"].as_f64().map(|ms| ms / 1e3);
            }
        }
        part
    }
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

    /// An event of the dashboard's stream, `after` the move was requested;
    /// answers the stages it lists first (by index in [`STAGES`]).
    fn saw(&mut self, after: Duration, event: &Value) -> Result<Vec<usize>> {
        let mut listed = Vec::new();
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
                        self.figures.listed_seconds[k] = after.as_secs_f64();
                        listed.push(k);
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
        Ok(listed)
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
    let (status, body) = request(address, Method::GET, path, None).await?;
    ensure!(status == StatusCode::OK, "GET {path} answered {status}");
    serde_json::from_slice(&body).with_context(|| format!("GET {path}: not JSON"))
}

/// One request with an optional JSON body over a fresh connection: the
/// status and the whole body, bounded by [`MAX_BODY`] and [`REQUEST_TIMEOUT`].
async fn request(
    address: SocketAddr,
    method: Method,
    path: &str,
    json: Option<&str>,
) -> Result<(StatusCode, Bytes)> {
    let what = format!("{method} {path}");
    let exchange = async {
        let response = send(address, method, path, json).await?;
        let status = response.status();
        let body = Limited::new(response.into_body(), MAX_BODY).collect().await;
        let body = body.map_err(|e| anyhow!("reading the answer: {e}"))?;
        anyhow::Ok((status, body.to_bytes()))
    };
    let answer = tokio::time::timeout(REQUEST_TIMEOUT, exchange).await;
    answer
        .with_context(|| format!("{what}: no answer within 30 s"))?
        .context(what)
}

/// Sends a request to the master's HTTP API over a connection of its own
/// (hyper's HTTP/1 client; the connection ends with the answer's body) and
/// answers its head.
async fn send(
    address: SocketAddr,
    method: Method,
    path: &str,
    json: Option<&str>,
) -> Result<Response<Incoming>> {
    let mut builder = Request::builder()
        .method(method)
        .uri(path)
        // The master checks `Host` against the address it listens on.
        .header(header::HOST, address.to_string());
    if json.is_some() {
        builder = builder.header(header::CONTENT_TYPE, "application/json");
    }
    let body = Full::new(Bytes::from(json.unwrap_or_default().to_owned()));
    let request = builder.body(body)?;
    let stream = TcpStream::connect(address)
        .await
        .with_context(|| format!("connecting to the master's HTTP at {address}"))?;
    let (mut sender, connection) = http1::handshake(TokioIo::new(stream)).await?;
    tokio::spawn(connection);
    Ok(sender.send_request(request).await?)
}

/// The dashboard's event stream: each `farm` event's JSON with the time it
/// was read, from a task of its own (so events are timed as they come, not
/// when the bench asks).
struct EventStream {
    events: mpsc::Receiver<Result<(Instant, Value)>>,
    reader: tokio::task::JoinHandle<()>,
}

impl EventStream {
    async fn open(address: SocketAddr) -> Result<EventStream> {
        let path = "/api/events";
        let response =
            tokio::time::timeout(REQUEST_TIMEOUT, send(address, Method::GET, path, None));
        let response = (response.await).context("GET /api/events: no answer within 30 s")??;
        let status = response.status();
        ensure!(status == StatusCode::OK, "GET {path} answered {status}");
        let (send, events) = mpsc::channel(EVENTS_QUEUED);
        let reader = tokio::spawn(async move {
            if let Err(e) = read_events(response.into_body(), MAX_BODY, &send).await {
                let _ = send.send(Err(e)).await;
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

/// Reads the event stream's `farm` events (as JSON, with the time each
/// was read) into `send` until the stream fails or ends, or nobody listens;
/// it may not run `limit` bytes without an event (what the parser holds).
async fn read_events<B>(
    body: B,
    limit: usize,
    send: &mpsc::Sender<Result<(Instant, Value)>>,
) -> Result<()>
where
    B: Body<Data = Bytes>,
    B::Error: std::error::Error + Send + Sync + 'static,
{
    // The bytes read since the last event: what the parser may hold.
    let unparsed = Arc::new(AtomicUsize::new(0));
    let counted = unparsed.clone();
    let bytes = BodyDataStream::new(body).map(move |piece| {
        let piece = piece.map_err(std::io::Error::other)?;
        let held = counted.fetch_add(piece.len(), Ordering::Relaxed) + piece.len();
        if held > limit {
            let why = format!("the stream ran {limit} bytes without an event");
            return Err(std::io::Error::other(why));
        }
        Ok(piece)
    });
    let mut events = pin!(SseByteStream::new(bytes));
    while let Some(event) = events.next().await {
        // A failure of the body is the crate's `Body` error around ours.
        let event = event.map_err(|e| match e {
            sse_stream::Error::Body(source) => anyhow::Error::from_boxed(source),
            other => other.into(),
        });
        let event = event.context("the event stream")?;
        let at = Instant::now();
        unparsed.store(0, Ordering::Relaxed);
        if event.event.as_deref() != Some("farm") {
            continue;
        }
        let data = event.data.unwrap_or_default();
        let json = serde_json::from_str(&data).context("an event is not JSON")?;
        if send.send(Ok((at, json))).await.is_err() {
            return Ok(());
        }
    }
    bail!("the event stream ended")
}

/// Renders each move's eye at each quality in this process (after one
/// untimed frame: the shadow maps built, as a running renderer has them),
/// wall seconds each, set-up included.
fn local_renders(
    scene: &std::sync::Arc<vtfarm_scene::Scene>,
    reflectors: &[vtfarm_scene::TriangleId],
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
         {} moves of {} m through POST /api/view (after one warm-up move), each timed until the event stream lists each stage \
         and the last one's image at {} px wide is in",
        f.detail,
        f.width,
        f.height,
        f.workers,
        f.worker_threads,
        args.moves,
        args.step,
        args.display_width
    );
    println!(
        "columns: on screen = move to the view's image (GET /view/image.png?width=, asked for after the first event listing \
         the stage) in hand, for the last stage only (the stages before it are meshes, which the page draws: --browser); listed = move to that event; server = the master's part, the move's arrival to the stage's \
         message for the page (GET /api/view/stages); the stage's frame as the master's timeline has it \
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
            "  {:<8} {:>10} {:>8} {:>7} {:>7} | {:>8} {:>8} {:>8} {:>9} {:>9} | {:>8}",
            "stage",
            "median ms",
            "p90 ms",
            "listed",
            "server",
            "wall",
            "base",
            "set-up",
            "packages",
            "in flight",
            "local ms"
        );
        for (k, quality) in STAGES.iter().enumerate() {
            let on_screen = Spread::of(farm.moves.iter().filter_map(|m| m.on_screen_seconds[k]));
            let listed = Spread::of(farm.moves.iter().map(|m| m.listed_seconds[k]));
            let frames: Vec<&StageFrame> = farm
                .moves
                .iter()
                .filter_map(|m| m.frames[k].as_ref())
                .collect();
            let phase = |get: fn(&StageFrame) -> f64| {
                Spread::of(frames.iter().map(|f| get(f))).map(|s| s.median)
            };
            let local = Spread::of(f.local.seconds[k].iter().copied());
            let server = Spread::of(farm.moves.iter().filter_map(|m| m.server_seconds[k]));
            println!(
                "  {:<8} {:>10} {:>8} {:>7} {:>7} | {:>8} {:>8} {:>8} {:>9} {:>9} | {:>8}",
                quality.name(),
                ms(on_screen.map(|s| s.median)),
                ms(on_screen.map(|s| s.p90)),
                ms(listed.map(|s| s.median)),
                ms(server.map(|s| s.median)),
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
        if let Some(figures) = &farm.page {
            page::print(figures);
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
        let server = |farm: &FarmFigures, k: usize| {
            Spread::of(farm.moves.iter().filter_map(|m| m.server_seconds[k])).map(|s| s.median)
        };
        let full_on_screen = |farm: &FarmFigures| {
            Spread::of(farm.moves.iter().filter_map(|m| m.on_screen_seconds[2])).map(|s| s.median)
        };
        let single = |farm: &FarmFigures| single_frame_spread(farm).map(|s| s.0.median);
        println!(
            "{} over {} (medians): server's part preview {}, refine {}, full {}; full on screen {}; single frame {}",
            first.bin.display(),
            farm.bin.display(),
            ratio(server(first, 0), server(farm, 0)),
            ratio(server(first, 1), server(farm, 1)),
            ratio(server(first, 2), server(farm, 2)),
            ratio(full_on_screen(first), full_on_screen(farm)),
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
    use http_body_util::StreamBody;
    use hyper::body::Frame;

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

    /// The farm events of an event stream cut into `pieces` bytes, read
    /// with `limit`, and how the reading ended.
    async fn farm_events(wire: &str, pieces: usize, limit: usize) -> (Vec<Value>, String) {
        let body = futures_util::stream::iter(wire.as_bytes().chunks(pieces)).map(|piece| {
            Ok::<_, std::convert::Infallible>(Frame::data(Bytes::from(piece.to_vec())))
        });
        let (send, mut events) = mpsc::channel(EVENTS_QUEUED);
        let end = read_events(StreamBody::new(body), limit, &send).await;
        let mut read = Vec::new();
        while let Ok(event) = events.try_recv() {
            read.push(event.unwrap().1);
        }
        (read, format!("{:#}", end.unwrap_err()))
    }

    #[tokio::test]
    async fn the_event_stream_gives_each_farm_event_however_the_bytes_are_cut() {
        let wire = "event: farm\ndata: {\"a\":\ndata: 1}\n\n: a comment\n\nevent: other\ndata: 3\n\n\
                    event: farm\r\ndata:{}\r\n\r\nevent: farm\ndata: 2";
        for pieces in 1..=wire.len() {
            let (events, end) = farm_events(wire, pieces, wire.len()).await;
            // The last event has no blank line yet: not handed out.
            let expected = [serde_json::json!({ "a": 1 }), serde_json::json!({})];
            assert_eq!(events, expected, "pieces of {pieces}");
            assert_eq!(end, "the event stream ended");
        }
    }

    #[tokio::test]
    async fn an_event_over_the_limit_or_not_json_ends_the_stream() {
        let long = format!(
            "event: farm\ndata: {{}}\n\nevent: farm\ndata: \"{}\"\n\n",
            "x".repeat(100)
        );
        let (events, end) = farm_events(&long, 10, 64).await;
        assert_eq!(events, [serde_json::json!({})]);
        assert_eq!(
            end,
            "the event stream: the stream ran 64 bytes without an event"
        );
        let (events, end) = farm_events("event: farm\ndata: {\n\n", 4, 64).await;
        assert!(events.is_empty());
        assert!(end.starts_with("an event is not JSON: "), "{end}");
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
        let listed = watch
            .saw(ms(50), &event(vec![rendered(6, "preview")], vec![]))
            .unwrap();
        assert!(listed.is_empty(), "another move's stage");
        assert_eq!(watch.missing(), Quality::Preview);
        let first = event(
            vec![rendered(6, "full"), rendered(7, "preview")],
            vec![serde_json::json!({ "seq": 4, "job": 7, "frame": 0, "stats": stats })],
        );
        assert_eq!(watch.saw(ms(120), &first).unwrap(), [0]);
        assert!(
            watch.saw(ms(150), &first).unwrap().is_empty(),
            "listed before"
        );
        let second = event(
            vec![
                rendered(7, "preview"),
                rendered(7, "refine"),
                rendered(7, "full"),
            ],
            vec![],
        );
        assert!(!watch.done());
        assert_eq!(watch.saw(ms(400), &second).unwrap(), [1, 2]);
        assert!(watch.done());
        assert_eq!(watch.figures.listed_seconds, [0.12, 0.4, 0.4]);
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
