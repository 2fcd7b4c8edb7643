//! The master's command line (`vtfarm master`, `vtfarm cluster init`),
//! shared with the standalone `vtfarm-master` binary.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Parser;
use tracing::info;
use vtfarm_master_core::{FarmRules, Retention};
use vtfarm_proto::HandshakePolicy;
use vtfarm_transport::{CLUSTER_FILE, ClusterConfig};

use crate::journal::Journal;
use crate::{driver::spawn_persistent_master, http, server};

/// Runs the master: accepts workers and jobs.
#[derive(clap::Args, Debug, Clone)]
pub struct MasterArgs {
    /// The cluster file from `vtfarm cluster init`; the master's key and
    /// certificate live beside it.
    #[arg(long)]
    pub cluster: PathBuf,
    /// Address to listen on (default: all interfaces, the cluster file's port).
    #[arg(long)]
    pub listen: Option<SocketAddr>,
    /// Address of the dashboard, status API and `/metrics`. Peers other
    /// than loopback must send the cluster token as a bearer token.
    #[arg(long, default_value = "127.0.0.1:7879")]
    pub http: SocketAddr,
    /// A host name browsers may call the dashboard by, besides localhost
    /// and its addresses (a proxy's name, say); repeat for several.
    #[arg(long = "http-allowed-host", value_name = "NAME")]
    pub http_allowed_hosts: Vec<String>,
    /// Ask loopback peers for the cluster token too: for a proxy on the
    /// same host that adds no `Forwarded`/`X-Forwarded-For` header.
    #[arg(long)]
    pub http_require_token: bool,
    /// Finished jobs (completed, failed, cancelled) kept listed, with their
    /// frames for `submit --attach`; the earliest finished go first (at
    /// most 10000).
    #[arg(long, value_name = "N", default_value_t = Retention::DEFAULT.max_jobs as u64,
          value_parser = clap::value_parser!(u64).range(0..=Retention::MAX_JOBS as u64))]
    pub keep_jobs: u64,
    /// Hours a finished job is kept at most (at most 87600, ten years).
    #[arg(long, value_name = "HOURS", default_value_t = Retention::DEFAULT.max_age.as_secs() / 3600,
          value_parser = clap::value_parser!(u64).range(0..=87_600))]
    pub keep_jobs_hours: u64,
}

/// Creates a cluster: the master's key and certificate, and `cluster.toml`.
#[derive(clap::Args, Debug, Clone)]
pub struct ClusterInitArgs {
    /// Directory for cluster.toml, master.crt.der and master.key.der.
    #[arg(short, long)]
    pub output: PathBuf,
    /// The address workers and submitters dial (HOST:PORT).
    #[arg(long, default_value = "127.0.0.1:7878")]
    pub master: String,
}

#[derive(Parser)]
#[command(name = "vtfarm-master", version, about = "vtfarm master")]
struct Standalone {
    #[command(flatten)]
    args: MasterArgs,
}

/// `vtfarm cluster init`: returns the path of the written cluster file.
pub fn cluster_init(args: &ClusterInitArgs) -> Result<PathBuf> {
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let host = args
        .master
        .rsplit_once(':')
        .map_or(args.master.as_str(), |(h, _)| h)
        .trim_matches(['[', ']'])
        .to_owned();
    let identity = server::identity(&args.output, &[host])?;
    let config = ClusterConfig::generate(&args.master, &identity)?;
    let path = args.output.join(CLUSTER_FILE);
    config.save(&path)?;
    Ok(path)
}

/// Runs the master until the process is stopped.
pub fn run(args: MasterArgs) -> Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(serve(&args))
}

/// Binds and serves (inside a runtime).
pub async fn serve(args: &MasterArgs) -> Result<()> {
    let cluster = ClusterConfig::load(&args.cluster)?;
    let state_dir = args.cluster.parent().unwrap_or(Path::new("."));
    let identity = vtfarm_transport::MasterIdentity::load(state_dir)?;
    if identity.fingerprint() != cluster.fingerprint {
        anyhow::bail!(
            "{}: the fingerprint does not match the certificate in {}",
            args.cluster.display(),
            state_dir.display()
        );
    }
    let listen = match args.listen {
        Some(a) => a,
        None => {
            let port = cluster
                .master
                .rsplit_once(':')
                .and_then(|(_, p)| p.parse().ok())
                .context("cluster file: master has no port")?;
            SocketAddr::from(([0, 0, 0, 0], port))
        }
    };
    let endpoint = server::bind(listen, &identity)?;
    info!(address = %endpoint.local_addr()?, "master listening");
    println!("master listening on {}", endpoint.local_addr()?);
    // Jobs and finished frames are journaled beside the key: a restarted
    // master resumes them.
    let journal = Journal::open(state_dir)?;
    let rules = FarmRules {
        retention: Retention {
            max_jobs: args.keep_jobs as usize, // at most Retention::MAX_JOBS
            max_age: std::time::Duration::from_secs(args.keep_jobs_hours.saturating_mul(3600)),
        },
        ..FarmRules::default()
    };
    let (handle, _task) = spawn_persistent_master(rules, journal);
    let http = http::bind(args.http).await?;
    info!(address = %http.local_addr()?, "dashboard listening");
    println!("dashboard on http://{}/", http.local_addr()?);
    let access = http::HttpAccess {
        allowed_hosts: args.http_allowed_hosts.clone(),
        require_token: args.http_require_token,
        ..http::HttpAccess::new(cluster.token.clone())
    };
    let limits = http::HttpLimits::default();
    tokio::spawn(http::serve(http, handle.clone(), access, limits));
    server::serve(
        endpoint,
        HandshakePolicy::new(cluster.token.clone(), "vtfarm-master"),
        handle,
    )
    .await;
    Ok(())
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
