//! What the scheduler reports to its driver ([`Event`]) and the statistics of
//! a finished frame ([`FrameStats`]).

use std::time::Duration;

use crate::{JobId, PackageId, WorkerId};

/// Something the driver should know or act on, from
/// [`Scheduler::poll_event`](crate::Scheduler::poll_event), in the order it
/// happened.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// A job left the queue and runs now (the driver may send its scene to
    /// the workers).
    JobStarted { job: JobId, frames: u32 },
    /// A paused job that had started is resumed and goes on where it
    /// stopped: its running frames go on (the driver may announce them to
    /// the workers again).
    JobResumed { job: JobId },
    /// A frame of a running job started.
    FrameStarted {
        job: JobId,
        frame: u32,
        items: usize,
        /// Whether the frame is whole ([`SchedulerConfig::whole_frames`](crate::SchedulerConfig::whole_frames)):
        /// all its items go to one worker as one package (and again as one
        /// when that worker is lost or fails it), so the worker renders the
        /// frame end to end; else packages split it over workers.
        whole: bool,
    },
    /// Every item of the frame is done, exactly once.
    FrameComplete {
        job: JobId,
        frame: u32,
        stats: FrameStats,
    },
    /// Every frame of the job is complete.
    JobComplete { job: JobId },
    /// The job was given up; the scheduler moves on to the next one.
    JobFailed {
        job: JobId,
        reason: JobFailure,
        /// The failures behind it, each with the worker that reported it.
        errors: Vec<(WorkerId, String)>,
    },
    /// The job was cancelled by [`Scheduler::cancel_job`](crate::Scheduler::cancel_job).
    JobCancelled { job: JobId },
    /// The worker failed too many packages of the job and gets no more of its
    /// work (packages it still runs may finish).
    WorkerBlocklisted { worker: WorkerId, job: JobId },
    /// The worker left or missed its heartbeats; the packages it ran went back
    /// to the front of the queue. After a heartbeat timeout the driver should
    /// drop the connection.
    WorkerLost {
        worker: WorkerId,
        cause: LossCause,
        requeued: Vec<PackageId>,
    },
    /// The worker should stop the package: the other copy of a straggler won,
    /// or the job ended. A result it still sends is ignored.
    PackageCancelled {
        worker: WorkerId,
        package: PackageId,
    },
}

/// Why a job failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JobFailure {
    /// The package failed on as many different workers as
    /// [`RetryPolicy::package_failures`](crate::RetryPolicy::package_failures).
    PackageFailed(PackageId),
    /// Work is left but every connected worker is blocklisted for the job.
    NoEligibleWorker,
}

/// How a worker was lost.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LossCause {
    /// [`Scheduler::worker_left`](crate::Scheduler::worker_left): a disconnect.
    Left,
    /// Nothing arrived from it for the heartbeat timeout.
    HeartbeatTimeout,
}

/// Statistics of one finished frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// From the first assignment of the frame to its last result.
    pub wall: Duration,
    /// Items in the frame.
    pub items: usize,
    /// Packages that completed (each once).
    pub packages: u32,
    /// Straggler copies handed out.
    pub duplicates: u32,
    /// Copies cancelled because the other copy won.
    pub cancelled_copies: u32,
    /// Failed attempts (each retried or ending the job).
    pub failures: u32,
    /// Packages that went back to the queue from a lost worker.
    pub requeued: u32,
    /// One entry per worker whose result was accepted, by worker id.
    pub workers: Vec<WorkerFrameStats>,
}

/// One worker's share of a frame: the packages whose result was accepted.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkerFrameStats {
    pub worker: WorkerId,
    /// Sum of the reported busy times.
    pub busy: Duration,
    pub packages: u32,
    /// Items (triangles).
    pub items: u32,
    /// Estimated cost of the items, in the job's cost units.
    pub estimated_cost: f64,
    pub rays: u64,
    pub bytes_in: u64,
    pub bytes_out: u64,
}

impl FrameStats {
    /// Sum of the workers' busy times: what one worker would have needed.
    pub fn total_busy(&self) -> Duration {
        self.workers.iter().map(|w| w.busy).sum()
    }

    /// Load imbalance `(max busy − mean busy) / mean busy` over the workers
    /// that took part; 0 when none did.
    pub fn imbalance(&self) -> f64 {
        let busy: Vec<f64> = self.workers.iter().map(|w| w.busy.as_secs_f64()).collect();
        let mean = busy.iter().sum::<f64>() / busy.len().max(1) as f64;
        let max = busy.iter().copied().fold(0.0, f64::max);
        if mean > 0.0 { (max - mean) / mean } else { 0.0 }
    }

    /// How many workers were busy on average: `total busy / wall`; 0 for a
    /// frame without wall time.
    pub fn speedup(&self) -> f64 {
        let wall = self.wall.as_secs_f64();
        if wall > 0.0 {
            self.total_busy().as_secs_f64() / wall
        } else {
            0.0
        }
    }
}
