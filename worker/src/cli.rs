//! The worker's command line, shared by `vtfarm worker` and the standalone
//! `vtfarm-worker` binary.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Parser;
use vtfarm_transport::ClusterConfig;

use crate::{ClientOptions, DrainSignal, Engine, WorkerConfig, run_worker};

/// Runs a render worker that dials the master and traces task packages.
#[derive(clap::Args, Debug, Clone)]
pub struct WorkerArgs {
    /// The cluster file written by `vtfarm cluster init` (token, certificate fingerprint, master address).
    #[arg(long)]
    pub cluster: PathBuf,
    /// The master's HOST:PORT (default: the address in the cluster file).
    #[arg(long)]
    pub master: Option<String>,
    /// Threads for tracing (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Make every package take this many times its compute time (≥ 1), to
    /// emulate a slower machine.
    #[arg(long, default_value_t = 1.0)]
    pub slowdown: f64,
    /// Traced samples a package may use per pixel of its frame before it
    /// fails as a runaway.
    #[arg(long, default_value_t = crate::engine::SAMPLES_PER_PIXEL_BUDGET)]
    pub sample_budget: u64,
    /// A name for logs and `vtfarm status` (default: the host name).
    #[arg(long)]
    pub name: Option<String>,
    /// Where scenes are cached by content hash (default: ~/.cache/vtfarm/scenes).
    #[arg(long)]
    pub cache: Option<PathBuf>,
}

#[derive(Parser)]
#[command(name = "vtfarm-worker", version, about = "vtfarm render worker")]
struct Standalone {
    #[command(flatten)]
    args: WorkerArgs,
}

/// Runs the worker until the master shuts it down or SIGTERM drains it.
pub fn run(args: WorkerArgs) -> Result<()> {
    let cluster = ClusterConfig::load(&args.cluster)?;
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    // Already set (e.g. by an embedding program): keep that pool.
    let _ = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global();
    let options = ClientOptions {
        master: args.master.clone().unwrap_or(cluster.master.clone()),
        token: cluster.token.clone(),
        fingerprint: cluster.fingerprint.clone(),
    };
    let name = args.name.clone().unwrap_or_else(default_name);
    let cache = args.cache.clone().unwrap_or_else(default_cache);
    let config = WorkerConfig {
        slowdown: args.slowdown.max(1.0),
        samples_per_pixel_budget: args.sample_budget,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async {
        let (raise, drain) = DrainSignal::new();
        watch_for_sigterm(raise)?;
        run_worker(
            options,
            name,
            threads as u32,
            Engine::new(Some(cache)),
            config,
            drain,
        )
        .await
        .map_err(anyhow::Error::from)
    })
}

/// SIGTERM drains the worker: it finishes its package and says goodbye.
#[cfg(unix)]
fn watch_for_sigterm(raise: tokio::sync::watch::Sender<bool>) -> Result<()> {
    use tokio::signal::unix::{SignalKind, signal};
    let mut sigterm = signal(SignalKind::terminate()).context("installing the SIGTERM handler")?;
    tokio::spawn(async move {
        if sigterm.recv().await.is_some() {
            tracing::info!("SIGTERM: draining");
            let _ = raise.send(true);
        }
    });
    Ok(())
}

#[cfg(not(unix))]
fn watch_for_sigterm(_raise: tokio::sync::watch::Sender<bool>) -> Result<()> {
    Ok(())
}

fn default_name() -> String {
    std::env::var("HOSTNAME")
        .ok()
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| format!("worker-{}", std::process::id()))
}

fn default_cache() -> PathBuf {
    std::env::var_os("HOME")
        .map_or_else(std::env::temp_dir, PathBuf::from)
        .join(".cache/vtfarm/scenes")
}

/// The standalone binary's entry point.
pub fn main() -> std::process::ExitCode {
    vtfarm_transport::init_logging();
    match run(Standalone::parse().args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", vtfarm_transport::error_report(e.as_ref()));
            std::process::ExitCode::FAILURE
        }
    }
}
