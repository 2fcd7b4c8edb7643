//! States of packages and workers with their allowed transitions, and the
//! read-only views behind a `status` command.

use std::time::Duration;

use crate::{JobId, WorkerId};

/// The state of a package; the crate documentation has the transition table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum PackageState {
    /// Waiting at the front of the frame's queue for a worker (it came back
    /// from a lost or failed worker).
    Queued,
    /// One worker runs it.
    Assigned,
    /// Two workers run it (straggler cut); the first result wins.
    Duplicated,
    /// Its result was accepted. Final.
    Done,
    /// It failed on too many workers and failed its job. Final.
    Failed,
    /// Its job was cancelled or failed. Final.
    Cancelled,
}

impl PackageState {
    /// Whether the transition table allows `self → to`. Packages are created
    /// straight into [`PackageState::Assigned`].
    pub fn may_become(self, to: PackageState) -> bool {
        use PackageState::*;
        matches!(
            (self, to),
            (Queued, Assigned)
                | (Assigned, Duplicated | Done | Queued | Failed)
                | (Duplicated, Assigned | Done)
                | (Queued | Assigned | Duplicated, Cancelled)
        )
    }

    /// Whether no transition leaves this state.
    pub fn is_final(self) -> bool {
        matches!(
            self,
            PackageState::Done | PackageState::Failed | PackageState::Cancelled
        )
    }
}

/// The state of a worker; the crate documentation has the transition table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum WorkerState {
    /// Connected, runs nothing and has not asked for work.
    Idle,
    /// Has asked for work and got none yet (it may still run packages, when
    /// the driver asks ahead).
    Waiting,
    /// Runs at least one package and has not asked for more.
    Busy,
    /// Left or lost to a heartbeat timeout; joining again makes it idle.
    Gone,
}

impl WorkerState {
    /// Whether the transition table allows `self → to`. Workers are created
    /// by joining, straight into [`WorkerState::Idle`].
    pub fn may_become(self, to: WorkerState) -> bool {
        use WorkerState::*;
        matches!(
            (self, to),
            (Idle, Waiting)
                | (Waiting, Busy | Idle)
                | (Busy, Idle | Waiting)
                | (Gone, Idle)
                | (Idle | Waiting | Busy, Gone)
        )
    }
}

/// One worker, for a `status` listing.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkerStatus {
    pub worker: WorkerId,
    pub state: WorkerState,
    pub threads: u32,
    /// Estimated rate from assignment to result (transfers included), in cost
    /// units per second: what package sizing uses. `None` before the worker
    /// finished a package.
    pub rate: Option<f64>,
    /// Compute rate (busy time only), in cost units per second: the median
    /// over its recent packages. It converts measured times into item costs.
    pub compute_rate: Option<f64>,
    /// Packages it runs now.
    pub running: usize,
    /// Totals since it first joined.
    pub packages_done: u64,
    pub items_done: u64,
    pub busy: Duration,
    pub failures: u64,
}

/// The job queue, for a `status` listing.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct QueueStatus {
    /// Jobs waiting, in the order they will run.
    pub waiting: Vec<JobId>,
    /// The running jobs, in rank order (the first gets workers first).
    pub running: Vec<JobProgress>,
}

/// Progress of a running job.
#[derive(Clone, Debug, PartialEq)]
pub struct JobProgress {
    pub job: JobId,
    /// Index of the current frame.
    pub frame: u32,
    pub frames: u32,
    /// Items of the current frame done so far.
    pub items_done: usize,
    pub items_total: usize,
    /// Its packages running now (of any of its frames).
    pub packages_running: usize,
    /// Paused: it hands out nothing new.
    pub paused: bool,
    /// Workers that get no more of this job's work.
    pub blocklisted: Vec<WorkerId>,
}

/// Inputs the scheduler ignored, by reason (see
/// [`ReportError`](crate::ReportError)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    pub results_not_connected: u64,
    pub results_unknown_package: u64,
    pub results_finished: u64,
    pub results_not_assigned: u64,
}

impl Counters {
    /// All ignored results together.
    pub fn ignored_results(&self) -> u64 {
        self.results_not_connected
            + self.results_unknown_package
            + self.results_finished
            + self.results_not_assigned
    }
}
