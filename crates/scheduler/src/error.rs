//! Why the scheduler refused an input: one enum per kind of operation. A
//! refused input changes nothing (apart from the counters of ignored results),
//! so the driver may log it and go on.

use thiserror::Error;

use crate::{JobId, PackageId, WorkerId};

/// Why [`Scheduler::worker_joined`](crate::Scheduler::worker_joined) refused.
#[derive(Clone, Debug, Error, PartialEq, Eq)]
pub enum JoinError {
    #[error("{0} is already connected")]
    AlreadyConnected(WorkerId),
}

/// Why an input from a worker (heartbeat, request, leaving) was refused.
#[derive(Clone, Debug, Error, PartialEq, Eq)]
pub enum WorkerError {
    /// The worker never joined, left, or was lost to a heartbeat timeout.
    #[error("{0} is not connected")]
    NotConnected(WorkerId),
}

/// Why a package result (done or failed) was ignored. Each is counted in
/// [`Counters`](crate::Counters).
#[derive(Clone, Debug, Error, PartialEq, Eq)]
pub enum ReportError {
    /// The worker never joined, left, or was lost to a heartbeat timeout.
    #[error("{0} is not connected")]
    NotConnected(WorkerId),
    /// No package with this id was ever handed out.
    #[error("{0} was never handed out")]
    UnknownPackage(PackageId),
    /// The package is finished: done, failed, cancelled, or its frame or job
    /// is over. A cancelled straggler copy's late result lands here.
    #[error("{0} is already finished")]
    Finished(PackageId),
    /// The package runs, but not on this worker (any more).
    #[error("{package} is not assigned to {worker}")]
    NotAssigned {
        package: PackageId,
        worker: WorkerId,
    },
}

/// Why [`Scheduler::submit_job`](crate::Scheduler::submit_job) refused.
#[derive(Clone, Debug, Error, PartialEq, Eq)]
pub enum SubmitError {
    #[error("job {0} is already queued or running")]
    DuplicateJob(JobId),
}

/// Why [`Scheduler::cancel_job`](crate::Scheduler::cancel_job) refused.
#[derive(Clone, Debug, Error, PartialEq, Eq)]
pub enum CancelError {
    #[error("job {0} is neither queued nor running")]
    UnknownJob(JobId),
}

/// A broken internal invariant found by
/// [`Scheduler::validate`](crate::Scheduler::validate): a bug in this crate.
#[derive(Clone, Debug, Error, PartialEq, Eq)]
#[error("scheduler invariant broken: {0}")]
pub struct InvariantError(pub String);
