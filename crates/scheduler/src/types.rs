//! The plain data the scheduler takes in and hands out: identifiers, a
//! frame's work, an assignment and a package's measurements.

use std::fmt;
use std::time::Duration;

/// A worker, as the driver names it (for example one number per connection).
///
/// A worker that reconnects should get a fresh id: results that were in
/// flight for its old connection then cannot be mistaken for new ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct WorkerId(pub u64);

/// A package: a contiguous run of one frame's work items. The id stays the
/// same across retries and for both copies of a straggler duplicate; it is
/// never reused for another package.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct PackageId(pub u64);

/// A job, as the driver names it; unique among the jobs queued or running.
/// The one job id of the farm: the wire, the master and the CLI use it too,
/// and serde (JSON and bincode alike) sees it as the bare number.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    PartialOrd,
    Ord,
    Hash,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(transparent)]
pub struct JobId(pub u64);

impl fmt::Display for WorkerId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "worker {}", self.0)
    }
}

impl fmt::Display for PackageId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "package {}", self.0)
    }
}

/// The number alone, so that messages read "job 7" wherever they say `job {id}`.
impl fmt::Display for JobId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.0, f)
    }
}

/// A job id as typed on a command line: the number alone.
impl std::str::FromStr for JobId {
    type Err = std::num::ParseIntError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        s.parse().map(JobId)
    }
}

/// The work of one frame: the work items (reflector triangle ids) in the
/// order packages should follow. The caller sorts them in spatial (Morton)
/// order, so a contiguous run of them is a compact region.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FrameWork {
    pub items: Vec<u32>,
}

/// A package handed to a worker, to be sent by the driver.
#[derive(Clone, Debug, PartialEq)]
pub struct Assignment {
    pub worker: WorkerId,
    pub package: PackageId,
    pub job: JobId,
    /// Index of the frame in its job, from 0.
    pub frame: u32,
    /// The work items, a contiguous run of the frame's items in its order.
    pub items: Vec<u32>,
    /// Estimated cost of the items, in the job's cost units.
    pub estimated_cost: f64,
    /// How long the scheduler expects the package to take from assignment to
    /// result on this worker; running much longer makes it a straggler.
    pub expected: Duration,
    /// Whether this is the second copy of a straggler (the first result wins).
    pub duplicate: bool,
    /// Whether the package is its whole frame ([`Event::FrameStarted`](crate::Event::FrameStarted)'s
    /// `whole`): every item of the frame, for the worker to render end to end.
    pub whole: bool,
}

/// What a worker measured while computing a package, sent with its result.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PackageMeasure {
    /// Time the worker spent computing the package (transfers excluded).
    pub busy: Duration,
    /// How `busy` splits over the items: one non-negative number per item of
    /// the package, in the order of [`Assignment::items`], in any unit (for
    /// example thread-seconds); only the ratios are used. When empty or
    /// malformed, `busy` is split in proportion to the estimates.
    pub item_seconds: Vec<f64>,
    /// Rays traced, for the statistics.
    pub rays: u64,
    /// Bytes the worker received for the package (the assignment).
    pub bytes_in: u64,
    /// Bytes the worker sent back (the result).
    pub bytes_out: u64,
}

/// How a job joins the queue ([`Scheduler::submit_job_with`](crate::Scheduler::submit_job_with)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct QueueOptions {
    /// Higher starts first; equal priorities start in id order.
    pub priority: i32,
    /// Queued paused: it starts once resumed.
    pub paused: bool,
    /// Every frame split, none whole
    /// ([`Scheduler::submit_interactive_job`](crate::Scheduler::submit_interactive_job)).
    pub interactive: bool,
}
