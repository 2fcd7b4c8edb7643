//! `vtfarm cancel`, `pause`, `resume`, `requeue` and `priority`: one request
//! each (`ControlJob`) from a submitter connection; each prints the job as
//! it is afterwards and fails naming the master's reason.

use anyhow::{Result, bail};
use vtfarm_proto::JobAction;
use vtfarm_proto::JobId;

use crate::farm::ClusterArgs;
use crate::shared::runtime;

/// Options of `vtfarm cancel`.
#[derive(clap::Args)]
pub(crate) struct CancelArgs {
    /// The jobs to cancel (ids from `vtfarm jobs`).
    #[arg(value_name = "JOB", required = true)]
    jobs: Vec<u64>,
    #[command(flatten)]
    cluster: ClusterArgs,
}

/// Options of `vtfarm pause` and `vtfarm resume`.
#[derive(clap::Args)]
pub(crate) struct JobArgs {
    #[arg(value_name = "JOB")]
    job: u64,
    #[command(flatten)]
    cluster: ClusterArgs,
}

/// Options of `vtfarm requeue`.
#[derive(clap::Args)]
pub(crate) struct RequeueArgs {
    /// A finished job (completed, failed or cancelled).
    #[arg(value_name = "JOB")]
    job: u64,
    /// Only the frames it did not finish (those of a failed or cancelled
    /// job); without, every frame again.
    #[arg(long)]
    failed: bool,
    #[command(flatten)]
    cluster: ClusterArgs,
}

/// Options of `vtfarm priority`.
#[derive(clap::Args)]
pub(crate) struct PriorityArgs {
    #[arg(value_name = "JOB")]
    job: u64,
    /// Higher runs first (default of a submitted job: 0); negative values
    /// go behind.
    #[arg(value_name = "N", allow_negative_numbers = true)]
    priority: i32,
    #[command(flatten)]
    cluster: ClusterArgs,
}

/// `vtfarm cancel JOB…`: every job is asked; fails if any was refused.
pub(crate) fn cancel(args: CancelArgs) -> Result<()> {
    let mut refused = 0;
    for &job in &args.jobs {
        if let Err(e) = control(&args.cluster, job, JobAction::Cancel, "cancelling") {
            eprintln!("error: {e:#}");
            refused += 1;
        }
    }
    if refused > 0 {
        bail!("{refused} of {} job(s) not cancelled", args.jobs.len());
    }
    Ok(())
}

pub(crate) fn pause(args: JobArgs) -> Result<()> {
    control(&args.cluster, args.job, JobAction::Pause, "pausing")
}

pub(crate) fn resume(args: JobArgs) -> Result<()> {
    control(&args.cluster, args.job, JobAction::Resume, "resuming")
}

pub(crate) fn requeue(args: RequeueArgs) -> Result<()> {
    let action = JobAction::Requeue {
        failed_only: args.failed,
    };
    control(&args.cluster, args.job, action, "requeueing")
}

pub(crate) fn priority(args: PriorityArgs) -> Result<()> {
    let action = JobAction::SetPriority(args.priority);
    control(&args.cluster, args.job, action, "setting the priority of")
}

/// Asks the master and prints the job's new state.
fn control(cluster: &ClusterArgs, job: u64, action: JobAction, doing: &str) -> Result<()> {
    let options = cluster.client_options()?;
    let outcome = runtime()?.block_on(vtfarm_submit::control_job(&options, JobId(job), action));
    let summary = outcome.map_err(|e| anyhow::anyhow!("{doing} job {job}: {e}"))?;
    println!(
        "job {}: {} (priority {}, {}/{} frames done)",
        summary.id,
        summary.state.name(),
        summary.priority,
        summary.frames_done,
        summary.frames_total
    );
    Ok(())
}
