//! The farm master's scheduler and load balancer (paper §4: demand-driven,
//! central, dynamic load balancing), as a deterministic state machine in the
//! style of `quinn-proto`.
//!
//! Architecture invariant: this crate does no I/O and reads no clock. It
//! knows nothing of rendering or networking: a frame's work is a list of work
//! items (reflector triangle ids, already in Morton order), workers and
//! packages are opaque ids, and time is the `now: Duration` (time since the
//! master started) passed to every input. Inputs are the `Scheduler` methods
//! `worker_joined`, `worker_left`, `heartbeat`, `request_work`,
//! `package_arrived`, `package_done`, `package_failed`, `submit_job`, `submit_interactive_job`, `cancel_job`,
//! `base_frame_cost`, `base_frame_ahead` and `handle_timeout`; outputs are polled with `poll_assignment`, `poll_event`
//! and `poll_timeout`. The same inputs give the same outputs, bit for bit (no
//! hash-map order, no threads). Its tests drive it alone, inputs and time in,
//! assignments and events out; farm scenarios (links, speeds, faults) run on
//! `vtfarm-farmsim`, which drives the real master core around it.
//!
//! A driver feeds inputs and sends what comes out:
//!
//! ```
//! use std::time::Duration;
//! use vtfarm_scheduler::{FrameWork, JobId, PackageMeasure, Scheduler, SchedulerConfig, WorkerId};
//!
//! let mut scheduler = Scheduler::new(SchedulerConfig::default());
//! let mut now = Duration::ZERO;
//! scheduler.worker_joined(now, WorkerId(1), 8)?;
//! let frame = FrameWork { items: vec![4, 5, 6] };
//! scheduler.submit_job(now, JobId(1), vec![frame])?;
//! scheduler.request_work(now, WorkerId(1))?;
//! while let Some(package) = scheduler.poll_assignment() {
//!     // The driver sends the package; later the worker's result arrives.
//!     now += Duration::from_millis(50);
//!     let measure = PackageMeasure { busy: Duration::from_millis(40), ..Default::default() };
//!     scheduler.package_done(now, package.worker, package.package, measure)?;
//!     scheduler.request_work(now, package.worker)?;
//! }
//! while let Some(event) = scheduler.poll_event() {
//!     println!("{event:?}"); // JobStarted, FrameStarted, FrameComplete, JobComplete
//! }
//! assert!(!scheduler.has_jobs());
//! // A real driver also calls `handle_timeout` when `poll_timeout` comes.
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Policy
//!
//! * **Demand-driven.** A worker asks ([`Scheduler::request_work`]) and gets
//!   one package, now or as soon as there is work. A job's frames run one
//!   after another; with [`SchedulerConfig::frames_in_flight`] above 1 the
//!   next frame starts as soon as the newest running one has nothing left
//!   to hand out, so idle workers take its packages while older frames'
//!   last ones finish (frames complete in order; older frames' requeued
//!   work first).
//! * **Several jobs, by rank.** Jobs rank by priority (the view's jobs
//!   carry the highest), then id (submission order), and several run at
//!   once: a waiting worker takes work of the first job in rank order that
//!   has work it may take, starting a queued one when it gets there; only
//!   when a job has nothing for this worker (its frames-in-flight limit
//!   reached, the worker blocklisted, its remaining work all running, or
//!   it is paused) does the worker go on to the next. Why: a job's tail,
//!   a single frame or a job at its limit would otherwise leave workers
//!   idle while other work waits. So a job of a higher priority takes the
//!   workers as their running packages finish (no package is stopped for
//!   it) and the lower one goes on with the workers it cannot use; a
//!   paused job hands out nothing new, its running packages finish and
//!   count, and it goes on where it stopped when resumed
//!   ([`Event::JobResumed`]). The first job starts when none runs; others
//!   start when a waiting worker reaches them. Rates are measured per job
//!   (each job's costs are in its own unit), and frame affinity and whole
//!   frames hold within each job. Split frames share the master's
//!   `frames_in_flight` base frames by rank: beside the one frame each
//!   running job has, a job starts a split frame ahead only while it and
//!   the jobs ranked before it run fewer, so a lower job never holds the
//!   slots a higher one needs.
//! * **Frame affinity** ([`SchedulerConfig::frame_affinity`], the farm's
//!   rules, for workers that set a frame up before its first package): a
//!   waiting worker takes work of a running frame it already has (oldest
//!   first), else requeued work of any frame, else joins a frame whose crew
//!   (the workers that took their last own package of it) is short of
//!   `max(workers / (frames_in_flight − 3), 4)` (frames complete in order:
//!   three slots are left for the oldest frame's last packages, frames
//!   done but waiting for it, and the next frame a crew starts), else
//!   starts the next frame, else, when none may start, helps the oldest
//!   frame with work left. Packages are sized within the frame's crew, and
//!   never larger than guided self-scheduling over the whole job gives (its
//!   unassigned and unstarted work over every worker), so near a job's end
//!   every worker shares the last frames in small packages. A worker so
//!   sets up only its crew's frames, not every frame.
//! * **Whole frames** ([`SchedulerConfig::whole_frames`], the farm's rules):
//!   while a running job has more frames not started than workers may work
//!   on it, a frame starts whole — one package of all its items for one
//!   worker (a crew of one), never split, and requeued whole when its worker
//!   is lost or fails it. Why: every worker on a frame pays that frame's
//!   set-up (ID buffers, buffers behind the glass, shadow maps; about a
//!   quarter of a worker's work per frame in vtfarm), and the master pays
//!   a base frame and the compositing of every split frame; with whole
//!   frames each frame is set up once, by the worker that renders it end to
//!   end, and throughput grows with every worker. Latency is what counts
//!   at the job's tail, for single-frame jobs and for the interactive view
//!   (each move a job of one frame), so those frames are split as below
//!   and every worker shares them. The tail is the job's last frames, no
//!   more than the workers, and no more than the master can make the base
//!   frames of (one at a time) within the time of one whole frame on a
//!   worker: a tail frame split later than that would wait for the master
//!   longer than it would take whole. Both times are measured — a whole
//!   frame's busy time as its packages report it, the master's time per
//!   base frame by [`Scheduler::base_frame_cost`] — and a base frame the
//!   master made ahead ([`Scheduler::base_frame_ahead`], while the whole
//!   frames ran and it had little else to do) costs nothing there. Until
//!   both are measured the tail is no more than `frames_in_flight` frames.
//!   The last frame is always split. A slow
//!   worker never holds the frames the others wait for: a whole frame
//!   whose worker runs `factor` times longer than its rate, as now
//!   measured, predicts is copied to a waiting worker — at once when it is
//!   the oldest running frame (frames complete in order), else once no frame
//!   may start — and once none may, so is one a waiting worker would finish
//!   in under `1 / factor` of the time its holder still needs.
//!   [`Event::FrameStarted`] and [`Assignment::whole`] say which mode a
//!   frame runs in, decided when it starts.
//! * **Frames in flight.** Split frames: at most
//!   [`SchedulerConfig::frames_in_flight`] (each holds the master's base
//!   frame and the image being composited). Whole frames: the master holds
//!   no base frame, only finished frames waiting for an older one (frames
//!   complete in order), so they follow the farm's width: up to
//!   `frames_in_flight` + [`WHOLE_FRAMES_PER_WORKER`] (2) per worker —
//!   each worker runs one and holds the next (it asks one package ahead),
//!   and `frames_in_flight` more may be done, waiting for a slower
//!   worker's; the master's memory so stays at that many finished images
//!   and a worker's at two frames. Those `frames_in_flight` more only once
//!   the tail is measured: before, at a job's start, they would be whole
//!   frames that no worker takes before its third round, and the tail's
//!   split frames, done, would wait for them (frames complete in order)
//!   while the other workers idle.
//! * **Held results.** A driver that checks results only later (the master
//!   waits for the frame's base image) reports them with
//!   [`Scheduler::package_arrived`] first: such a package is no straggler and
//!   its worker's rate counts only up to the arrival.
//! * **Package size** (guided self-scheduling, "large early, small late"):
//!   a package for worker `w` is the next contiguous run of unassigned items
//!   whose estimated cost is closest to `target · rate(w)`, with
//!   `target = clamp(remaining / (k · Σ rate), min_duration, max_duration)`,
//!   see [`PackageSizing`]. `rate(w)` is the worker's cost units per second
//!   from assignment to result (so a slow link counts), smoothed
//!   exponentially over its packages; a new worker starts from the mean rate
//!   per thread of the measured workers times its threads.
//! * **Cost estimates** carry over from frame to frame within a job (see
//!   `costs.rs`): the first frame is uniform, later ones use each item's
//!   measured cost and the mean for new items.
//! * **Faults.** A worker that leaves or misses its heartbeats loses its
//!   packages to the front of the queue. Near the end of a frame (nothing
//!   left to hand out) a package running `max(factor · expected, min_delay)`
//!   is also given to a waiting worker; the first result wins and the other
//!   copy is cancelled ([`Event::PackageCancelled`]). A failed package is
//!   retried on another worker; a worker that failed 3 packages of a job is
//!   blocklisted for it; a package that failed on 3 different workers fails
//!   the job, as does work left when every connected worker is blocklisted.
//!   A frame therefore completes while one worker that may work on the job
//!   remains connected. Results that are late, duplicate, from the wrong
//!   worker or for unknown packages are refused ([`ReportError`]) and
//!   counted ([`Counters`]).
//!
//! # Package states
//!
//! A package is created when a worker takes unassigned items (or the first
//! part of a queued package that is too big for it), directly as `Assigned`.
//! Each change is made by one function of `scheduler/transitions.rs`, through
//! `Package::set_state`, which checks [`PackageState::may_become`]:
//!
//! | from | to | when | function |
//! |---|---|---|---|
//! | (new) | Assigned | a waiting worker takes unassigned items or splits a queued package | `assign` |
//! | Queued | Assigned | a waiting worker takes the queued package | `assign` |
//! | Assigned | Duplicated | straggler: nothing left to hand out, the copy runs past its deadline, a worker waits | `assign` |
//! | Assigned, Duplicated | Done | the first result arrives (the other copy is cancelled) | `complete` |
//! | Assigned | Queued | its worker is lost | `lose` |
//! | Assigned | Queued | it failed, on fewer than 3 different workers so far | `fail_attempt` |
//! | Duplicated | Assigned | one copy's worker is lost | `lose` |
//! | Duplicated | Assigned | one copy failed | `fail_attempt` |
//! | Assigned | Failed | it failed on the 3rd different worker (the job fails) | `fail_attempt` |
//! | Queued, Assigned, Duplicated | Cancelled | its job is cancelled or fails | `abandon_job` |
//!
//! Done, Failed and Cancelled are final. A package's items never change
//! except when a queued package is split: its first part becomes a new
//! package and the rest stays queued under the old id (both keep the failure
//! history).
//!
//! # Worker states
//!
//! A worker's state follows from whether it is connected, has asked for work
//! and runs packages ([`WorkerState`], checked by
//! [`WorkerState::may_become`]):
//!
//! | from | to | when | function |
//! |---|---|---|---|
//! | (new), Gone | Idle | it joins | `worker_joined` |
//! | Idle, Busy | Waiting | it asks for work | `request_work` |
//! | Waiting | Busy | it gets a package | `assign` |
//! | Waiting | Idle | a frame starts and requests lapse (`SchedulerConfig::requests_lapse_at_frame_start`) | `lapse_requests` |
//! | Busy | Idle | its last package is done, failed or cancelled | `complete`, `fail_attempt`, `cancel_losing_copy`, `abandon_job` |
//! | Idle, Waiting, Busy | Gone | it leaves or misses its heartbeats | `lose` |
//!
//! Being blocklisted is not a state: it holds for one job, and a blocklisted
//! worker that waits gets work again from the next job.
//!
//! # Job states
//!
//! Queued (`submit_job`, `submit_interactive_job`, `submit_job_with`) → Running
//! (`start_queued`: none runs, or a waiting worker reaches it in rank order;
//! see Several jobs) → Complete (`finish_oldest_frame`), Failed
//! (`fail_job`) or Cancelled (`cancel_job`); a queued job may be cancelled
//! directly. Several jobs may be Running at once. `pause_job` holds a
//! queued job back and keeps a running one from handing out new packages
//! or starting frames (its running packages finish and count; it stays
//! running); `resume_job` lets it go on; `set_priority` reorders. The
//! master core's `JobState` is the users' view of these.

mod config;
mod costs;
mod error;
mod event;
mod frame;
mod scheduler;
mod status;
mod types;

pub use config::{CostEstimation, PackageSizing, RetryPolicy, SchedulerConfig, StragglerPolicy};
pub use error::{CancelError, InvariantError, JoinError, ReportError, SubmitError, WorkerError};
pub use event::{Event, FrameStats, JobFailure, LossCause, WorkerFrameStats};
pub use scheduler::{Scheduler, WHOLE_FRAMES_PER_WORKER};
pub use status::{Counters, JobProgress, PackageState, QueueStatus, WorkerState, WorkerStatus};
pub use types::{Assignment, FrameWork, JobId, PackageId, PackageMeasure, QueueOptions, WorkerId};
