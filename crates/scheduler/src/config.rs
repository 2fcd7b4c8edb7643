//! The scheduler's settings and their defaults.

use std::time::Duration;

/// Settings of the scheduler. [`SchedulerConfig::default`] documents the
/// defaults; every one of them is a policy knob, none is needed for
/// correctness.
#[derive(Clone, Debug, PartialEq)]
pub struct SchedulerConfig {
    /// A worker that sends nothing (heartbeat, request or result) for this
    /// long is lost and its packages go back to the queue. Default 10 s, for
    /// workers that send a heartbeat every 2 s or so.
    pub heartbeat_timeout: Duration,
    /// Package sizing: see [`PackageSizing`].
    pub sizing: PackageSizing,
    /// Straggler cut near the end of a frame; `None` turns it off.
    pub straggler: Option<StragglerPolicy>,
    /// Failure handling: see [`RetryPolicy`].
    pub retry: RetryPolicy,
    /// Cost estimation: see [`CostEstimation`].
    pub estimation: CostEstimation,
    /// Whether requests for work lapse when a frame starts, so that workers
    /// ask again once they have set the new frame up (vtfarm's workers
    /// rebuild ID buffers per frame; counting that set-up as package time
    /// would skew their measured rates). Default `false`: requests carry over.
    pub requests_lapse_at_frame_start: bool,
    /// How many frames of a job may run at once (pipelining): the next frame
    /// starts as soon as the newest running one has nothing left to hand
    /// out, so that idle workers take its packages while older frames'
    /// last packages finish; frames still complete in order. Default 1 (no
    /// pipelining); values below 1 are read as 1.
    pub frames_in_flight: u32,
    /// Frame affinity (for workers that set a frame up before its first
    /// package, as vtfarm's do): a worker keeps taking work of the frames
    /// it already has, and each running frame's fresh work goes to a crew
    /// of about `workers / (frames_in_flight - 3)` workers (at least 4), so a worker
    /// sets up only some of the frames instead of every one. A worker
    /// whose frames have nothing left joins a frame whose crew is short,
    /// else starts the next frame, else helps the oldest frame with work
    /// left. Package sizes follow the frame's crew, bounded by the whole
    /// job's remaining work over every worker. Default `false`.
    pub frame_affinity: bool,
    /// Whole frames for batch work (with [`SchedulerConfig::frame_affinity`]):
    /// while a running job has more frames not started than workers may
    /// work on it, a frame starts whole — one package of all its items for
    /// one worker, which then renders the frame end to end — and up to
    /// [`WHOLE_FRAMES_PER_WORKER`](crate::WHOLE_FRAMES_PER_WORKER) whole
    /// frames per worker are in flight. The job's tail (its last frames, as
    /// many as the measured costs allow), single-frame jobs and jobs no
    /// wider than the farm are split as without it. See the crate
    /// documentation for the rule and its reason. Default `false`.
    pub whole_frames: bool,
}

impl Default for SchedulerConfig {
    fn default() -> Self {
        SchedulerConfig {
            heartbeat_timeout: Duration::from_secs(10),
            sizing: PackageSizing::default(),
            straggler: Some(StragglerPolicy::default()),
            retry: RetryPolicy::default(),
            estimation: CostEstimation::default(),
            requests_lapse_at_frame_start: false,
            frames_in_flight: 1,
            frame_affinity: false,
            whole_frames: false,
        }
    }
}

impl SchedulerConfig {
    /// The rules for workers that set a frame up when its first package for
    /// them comes (vtfarm's): `frames_in_flight` split frames pipelined with
    /// frame affinity, so that a worker sets up only the frames of its crew,
    /// whole frames for batch work, and requests carry over a frame start.
    /// vtfarm's master takes it with the protocol's `FRAMES_IN_FLIGHT`
    /// (`vtfarm_master_core::FarmRules`).
    pub fn pipelined(self, frames_in_flight: u32) -> Self {
        SchedulerConfig {
            requests_lapse_at_frame_start: false,
            frames_in_flight,
            frame_affinity: true,
            whole_frames: true,
            ..self
        }
    }
}

/// How big a package is (guided self-scheduling, "large early, small late").
///
/// A package for worker `w` aims at the duration
/// `target = clamp(remaining_cost / (guided_factor · total_rate), min_duration, max_duration)`
/// and so at the cost `target · rate(w)`, where `remaining_cost` is the
/// estimated cost of the frame's unassigned work and `total_rate` the sum of
/// the rates of the workers that may work on the job. Early packages are
/// large (few round trips), late ones small, so all workers finish together.
#[derive(Clone, Debug, PartialEq)]
pub struct PackageSizing {
    /// `k` above: each package takes `1/k` of the worker's fair share of the
    /// remaining work. Default 2 (factoring); 1 is classic guided
    /// self-scheduling. Values below 1 are read as 1.
    pub guided_factor: f64,
    /// Lower bound of the target duration, so that round trips and per-package
    /// overhead stay small against the work. Default 5 ms.
    pub min_duration: Duration,
    /// Upper bound of the target duration, so that a lost worker never takes
    /// much work with it. Default 10 s.
    pub max_duration: Duration,
    /// A queued package (one coming back from a lost or failed worker) whose
    /// estimated cost exceeds `split_factor` times the taker's target is split
    /// and only its first part is handed out. Default 1.5.
    pub split_factor: f64,
}

impl Default for PackageSizing {
    fn default() -> Self {
        PackageSizing {
            guided_factor: 2.0,
            min_duration: Duration::from_millis(5),
            max_duration: Duration::from_secs(10),
            split_factor: 1.5,
        }
    }
}

/// When a package counts as a straggler. Near the end of a frame (nothing
/// left to hand out) a package running longer than
/// `max(factor · expected, min_delay)` is also given to a waiting worker;
/// the first result wins and the other copy is cancelled.
#[derive(Clone, Debug, PartialEq)]
pub struct StragglerPolicy {
    /// Default 2.
    pub factor: f64,
    /// Default 10 ms, so that tiny packages are not duplicated for jitter.
    pub min_delay: Duration,
}

impl Default for StragglerPolicy {
    fn default() -> Self {
        StragglerPolicy {
            factor: 2.0,
            min_delay: Duration::from_millis(10),
        }
    }
}

/// What failures cost (Flamenco's rules).
#[derive(Clone, Debug, PartialEq)]
pub struct RetryPolicy {
    /// A worker that failed this many packages of a job gets no more of that
    /// job's work. Default 3.
    pub worker_failures_per_job: u32,
    /// A package that failed on this many different workers fails its job.
    /// Default 3.
    pub package_failures: u32,
}

impl Default for RetryPolicy {
    fn default() -> Self {
        RetryPolicy {
            worker_failures_per_job: 3,
            package_failures: 3,
        }
    }
}

/// Starting points and smoothing of the cost and rate estimates.
#[derive(Clone, Debug, PartialEq)]
pub struct CostEstimation {
    /// Estimated cost of every item in a job's first frame: the job's cost
    /// unit. Later frames measure costs in the same unit. Default 1.
    pub initial_item_cost: f64,
    /// Rate (cost units per second) assumed per thread of a worker before any
    /// worker has finished a package. Only the first packages depend on it;
    /// default 1 (an item per second per thread, deliberately slow, so that
    /// the first packages are small).
    pub initial_rate_per_thread: f64,
    /// Weight of a new observation in a worker's exponentially smoothed rate.
    /// Default 0.3.
    pub rate_smoothing: f64,
}

impl Default for CostEstimation {
    fn default() -> Self {
        CostEstimation {
            initial_item_cost: 1.0,
            initial_rate_per_thread: 1.0,
            rate_smoothing: 0.3,
        }
    }
}
