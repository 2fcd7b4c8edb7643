//! The state machine driven by hand: one test per transition of the tables
//! in the crate documentation, the sizing and estimation formulas, and the
//! refusal of bad inputs.

mod common;

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use vtfarm_scheduler::{
    Assignment, CancelError, Event, FrameWork, JobFailure, JobId, JoinError, LossCause, PackageId,
    PackageMeasure, PackageSizing, PackageState, ReportError, Scheduler, SchedulerConfig,
    SubmitError, WorkerError, WorkerId, WorkerState,
};

/// A scheduler with a clock, and short names for the inputs.
struct Farm {
    s: Scheduler,
    now: Duration,
    /// [`Farm::run_to_end`]'s workers: the packages each holds, and the
    /// one it computes (from, until).
    queued: BTreeMap<WorkerId, VecDeque<Assignment>>,
    computing: BTreeMap<WorkerId, (Duration, Duration, Assignment)>,
}

const W0: WorkerId = WorkerId(0);
const W1: WorkerId = WorkerId(1);
const W2: WorkerId = WorkerId(2);
const W3: WorkerId = WorkerId(3);
const JOB: JobId = JobId(7);

impl Farm {
    fn new() -> Farm {
        Farm::with(SchedulerConfig::default())
    }

    fn with(config: SchedulerConfig) -> Farm {
        Farm {
            s: Scheduler::new(config),
            now: Duration::ZERO,
            queued: BTreeMap::new(),
            computing: BTreeMap::new(),
        }
    }

    /// A farm with `workers` single-threaded workers and a job of `frames`
    /// frames of `items` items (ids 100..).
    fn running(workers: u64, items: u32, frames: usize) -> Farm {
        let mut farm = Farm::new();
        for w in 0..workers {
            farm.join(WorkerId(w));
        }
        farm.submit(JOB, items, frames);
        farm
    }

    fn at_ms(&mut self, ms: u64) -> &mut Farm {
        self.now = Duration::from_millis(ms);
        self
    }

    fn join(&mut self, w: WorkerId) {
        self.s.worker_joined(self.now, w, 1).expect("join");
    }

    fn submit(&mut self, job: JobId, items: u32, frames: usize) {
        let frame = FrameWork {
            items: (100..100 + items).collect(),
        };
        self.s
            .submit_job(self.now, job, vec![frame; frames])
            .expect("submit");
    }

    /// The worker asks; what it gets now, if anything.
    fn request(&mut self, w: WorkerId) -> Option<Assignment> {
        self.s.request_work(self.now, w).expect("request");
        let mut got = self.assignments();
        assert!(got.len() <= 1, "{got:?}");
        got.pop()
    }

    fn assignments(&mut self) -> Vec<Assignment> {
        std::iter::from_fn(|| self.s.poll_assignment()).collect()
    }

    fn events(&mut self) -> Vec<Event> {
        std::iter::from_fn(|| self.s.poll_event()).collect()
    }

    /// Reports `a` done by `w`, busy for the time since `now` started.
    fn done(&mut self, w: WorkerId, a: &Assignment) -> Result<(), ReportError> {
        let measure = PackageMeasure {
            busy: Duration::from_millis(10),
            ..PackageMeasure::default()
        };
        self.s.package_done(self.now, w, a.package, measure)
    }

    fn fail(&mut self, w: WorkerId, a: &Assignment) -> Result<(), ReportError> {
        self.s
            .package_failed(self.now, w, a.package, format!("boom on {w}"))
    }

    fn state(&self, p: PackageId) -> Option<PackageState> {
        self.s.package_state(p)
    }

    fn valid(&self) {
        self.s.validate().expect("invariants");
    }

    /// The least a test needs to run jobs on the scheduler alone: each
    /// worker computes its packages one at a time, an item taking
    /// `cost(item)` seconds, reports each at once and asks for more when it
    /// has none; deadlines are handled when due. `asking` workers ask
    /// first. Runs until nothing is left to happen or the next thing lies
    /// after `until`; returns what the scheduler gave out, with the times.
    /// No links, no master: those are `vtfarm-farmsim`'s.
    fn run_to_end(
        &mut self,
        asking: &[WorkerId],
        until: Duration,
        cost: &dyn Fn(u32) -> f64,
    ) -> Log {
        let mut log = Log::default();
        for &w in asking {
            self.s.request_work(self.now, w).expect("request");
        }
        loop {
            for a in self.assignments() {
                log.assignments.push((self.now, a.clone()));
                self.queued.entry(a.worker).or_default().push_back(a);
            }
            log.events
                .extend(self.events().into_iter().map(|e| (self.now, e)));
            // Idle workers start their next package.
            for (&w, queue) in &mut self.queued {
                if !self.computing.contains_key(&w) {
                    if let Some(a) = queue.pop_front() {
                        let seconds: f64 = a.items.iter().map(|&i| cost(i)).sum();
                        let end = self.now + Duration::from_secs_f64(seconds);
                        self.computing.insert(w, (self.now, end, a));
                    }
                }
            }
            let finish = (self.computing.iter())
                .map(|(&w, (_, end, _))| (*end, w))
                .min();
            let deadline = self.s.poll_timeout();
            let next = finish.map(|(end, _)| end).into_iter().chain(deadline).min();
            let Some(next) = next.filter(|&t| t <= until) else {
                return log;
            };
            self.now = self.now.max(next);
            match finish {
                Some((end, w)) if Some(end) == Some(next) => {
                    let (start, _, a) = self.computing.remove(&w).expect("computing");
                    let measure = PackageMeasure {
                        busy: end - start,
                        item_seconds: a.items.iter().map(|&i| cost(i)).collect(),
                        ..PackageMeasure::default()
                    };
                    // A cancelled copy's result is refused, as it should be.
                    let _ = self.s.package_done(self.now, w, a.package, measure);
                    if self.queued.get(&w).is_none_or(|q| q.is_empty()) {
                        self.s.request_work(self.now, w).expect("request");
                    }
                }
                _ => self.s.handle_timeout(self.now),
            }
        }
    }
}

/// What [`Farm::run_to_end`] saw, with the times.
#[derive(Debug, Default)]
struct Log {
    assignments: Vec<(Duration, Assignment)>,
    events: Vec<(Duration, Event)>,
}

impl Log {
    fn extend(&mut self, more: Log) {
        self.assignments.extend(more.assignments);
        self.events.extend(more.events);
    }
}

// ----- Package transitions -----

#[test]
fn the_transition_table_in_code_matches_the_documentation() {
    use PackageState::*;
    let all = [Queued, Assigned, Duplicated, Done, Failed, Cancelled];
    let documented = [
        (Queued, Assigned),
        (Assigned, Duplicated),
        (Assigned, Done),
        (Duplicated, Done),
        (Assigned, Queued),
        (Duplicated, Assigned),
        (Assigned, Failed),
        (Queued, Cancelled),
        (Assigned, Cancelled),
        (Duplicated, Cancelled),
    ];
    for from in all {
        for to in all {
            assert_eq!(
                from.may_become(to),
                documented.contains(&(from, to)),
                "{from:?} -> {to:?}"
            );
        }
        assert_eq!(from.is_final(), all.iter().all(|&to| !from.may_become(to)));
    }
    use WorkerState::*;
    let workers = [Idle, Waiting, Busy, Gone];
    let documented = [
        (Idle, Waiting),
        (Busy, Waiting),
        (Waiting, Busy),
        (Waiting, Idle),
        (Busy, Idle),
        (Gone, Idle),
        (Idle, Gone),
        (Waiting, Gone),
        (Busy, Gone),
    ];
    for from in workers {
        for to in workers {
            assert_eq!(from.may_become(to), documented.contains(&(from, to)));
        }
    }
}

#[test]
fn new_to_assigned_takes_the_first_unassigned_items() {
    let mut farm = Farm::running(2, 100, 1);
    let a = farm.request(W0).expect("work");
    let b = farm.request(W1).expect("work");
    assert_eq!(farm.state(a.package), Some(PackageState::Assigned));
    assert_eq!(a.items[0], 100);
    assert_eq!(
        b.items[0],
        *a.items.last().expect("items") + 1,
        "contiguous runs"
    );
    assert!(!a.duplicate && a.job == JOB && a.frame == 0);
    farm.valid();
}

#[test]
fn assigned_to_done_and_the_frame_completes() {
    let mut farm = Farm::running(1, 1, 1);
    let a = farm.request(W0).expect("work");
    assert_eq!(a.items, [100]);
    farm.at_ms(50);
    farm.done(W0, &a).expect("accepted");
    let events = farm.events();
    assert!(
        matches!(&events[2], Event::FrameComplete { frame: 0, stats, .. }
        if stats.items == 1 && stats.packages == 1 && stats.wall == Duration::from_millis(50))
    );
    assert_eq!(events[3], Event::JobComplete { job: JOB });
    assert_eq!(farm.s.worker_state(W0), Some(WorkerState::Idle));
    farm.valid();
}

#[test]
fn assigned_to_queued_when_the_worker_leaves_and_queued_to_assigned() {
    let mut farm = Farm::running(2, 100, 1);
    let a = farm.request(W0).expect("work");
    let _ = farm.events();
    farm.s.worker_left(farm.now, W0).expect("left");
    assert_eq!(farm.state(a.package), Some(PackageState::Queued));
    assert_eq!(
        farm.events(),
        [Event::WorkerLost {
            worker: W0,
            cause: LossCause::Left,
            requeued: vec![a.package]
        }]
    );
    farm.valid();
    // The queued package goes first, whole when it is not much bigger than
    // the taker's target.
    let b = farm.request(W1).expect("work");
    assert_eq!((b.package, &b.items), (a.package, &a.items));
    assert_eq!(farm.state(a.package), Some(PackageState::Assigned));
    farm.valid();
}

#[test]
fn a_big_queued_package_is_split_for_its_taker() {
    let mut farm = Farm::running(1, 1000, 1);
    let a = farm.request(W0).expect("work");
    farm.at_ms(100);
    farm.done(W0, &a).expect("done");
    // W0 measured 100 units/s; W1 with 8 threads is taken for 800 and gets a
    // large package: 990 / (2 · 900) s at 800 units/s, 440 items.
    farm.s.worker_joined(farm.now, W1, 8).expect("join");
    let big = farm.request(W1).expect("work");
    assert_eq!(big.items.len(), 440);
    farm.s.worker_left(farm.now, W1).expect("left");
    // W2 (1 thread) aims at 990 / (2 · 200) s at 100 units/s: 247.5 units,
    // rounded to 248 items.
    farm.join(W2);
    let head = farm.request(W2).expect("work");
    assert_ne!(head.package, big.package, "the first part is a new package");
    assert_eq!(head.items[..], big.items[..248]);
    assert_eq!(farm.state(big.package), Some(PackageState::Queued));
    farm.valid();
    // The rest stays queued under the old id and goes next, whole.
    let tail = farm.request(W0).expect("work");
    assert_eq!(
        (tail.package, &tail.items[..]),
        (big.package, &big.items[248..])
    );
    farm.valid();
}

#[test]
fn assigned_to_queued_on_a_heartbeat_timeout() {
    let mut farm = Farm::running(2, 100, 1);
    let a = farm.request(W0).expect("work");
    farm.at_ms(5000);
    farm.s.heartbeat(farm.now, W1).expect("alive");
    assert_eq!(farm.s.poll_timeout(), Some(Duration::from_secs(10)));
    farm.s.handle_timeout(Duration::from_secs(10));
    assert_eq!(farm.state(a.package), Some(PackageState::Queued));
    assert_eq!(farm.s.worker_state(W0), Some(WorkerState::Gone));
    assert_eq!(farm.s.worker_state(W1), Some(WorkerState::Idle));
    assert!(farm.events().contains(&Event::WorkerLost {
        worker: W0,
        cause: LossCause::HeartbeatTimeout,
        requeued: vec![a.package]
    }));
    assert_eq!(farm.s.poll_timeout(), Some(Duration::from_secs(15)));
    // Its late result is refused.
    assert_eq!(farm.done(W0, &a), Err(ReportError::NotConnected(W0)));
    farm.valid();
}

/// Two workers; W0 holds the only package of a 1-item frame, W1 waits.
fn straggling() -> (Farm, Assignment) {
    let mut farm = Farm::running(2, 1, 1);
    let a = farm.request(W0).expect("work");
    assert_eq!(farm.request(W1), None);
    (farm, a)
}

#[test]
fn assigned_to_duplicated_when_a_package_straggles() {
    let (mut farm, a) = straggling();
    // Expected 1 s (1 unit at the initial rate of 1 unit/s), straggler at 2×.
    assert_eq!(a.expected, Duration::from_secs(1));
    assert_eq!(farm.s.poll_timeout(), Some(Duration::from_secs(2)));
    farm.s.handle_timeout(Duration::from_millis(1999));
    assert!(farm.assignments().is_empty());
    farm.s.handle_timeout(Duration::from_secs(2));
    let copy = farm.assignments().pop().expect("duplicate");
    assert_eq!(
        (copy.worker, copy.package, copy.duplicate),
        (W1, a.package, true)
    );
    assert_eq!(farm.state(a.package), Some(PackageState::Duplicated));
    farm.valid();
}

#[test]
fn duplicated_to_done_cancels_the_other_copy_and_ignores_its_result() {
    let (mut farm, a) = straggling();
    farm.s.handle_timeout(Duration::from_secs(2));
    let copy = farm.assignments().pop().expect("duplicate");
    let _ = farm.events();
    farm.at_ms(2500);
    farm.done(W1, &copy).expect("first result wins");
    let events = farm.events();
    assert_eq!(
        events[0],
        Event::PackageCancelled {
            worker: W0,
            package: a.package
        }
    );
    assert!(matches!(&events[1], Event::FrameComplete { stats, .. }
        if stats.duplicates == 1 && stats.cancelled_copies == 1));
    assert_eq!(farm.done(W0, &a), Err(ReportError::Finished(a.package)));
    assert_eq!(farm.s.counters().results_finished, 1);
    // W0 did not finish in 2.5 s: its rate is now at most 1 unit / 2.5 s.
    let w0 = &farm.s.workers()[0];
    assert_eq!(w0.rate, Some(0.4));
    farm.valid();
}

#[test]
fn duplicated_to_assigned_when_one_copy_is_lost_or_fails() {
    for lose in [true, false] {
        let (mut farm, a) = straggling();
        farm.s.handle_timeout(Duration::from_secs(2));
        let copy = farm.assignments().pop().expect("duplicate");
        if lose {
            farm.s.worker_left(farm.now, W0).expect("left");
        } else {
            farm.fail(W1, &copy).expect("failed");
        }
        assert_eq!(farm.state(a.package), Some(PackageState::Assigned));
        farm.valid();
    }
}

#[test]
fn assigned_to_queued_on_failure_and_retried_on_another_worker() {
    let mut farm = Farm::running(2, 1, 1);
    let a = farm.request(W0).expect("work");
    farm.fail(W0, &a).expect("failed");
    assert_eq!(farm.state(a.package), Some(PackageState::Queued));
    // W0 failed it and W1 has not: W0 waits, W1 gets it.
    assert_eq!(farm.request(W0), None);
    let b = farm.request(W1).expect("retry");
    assert_eq!(b.package, a.package);
    farm.valid();
}

#[test]
fn assigned_to_failed_on_the_third_worker_fails_the_job() {
    let mut farm = Farm::running(4, 1, 1);
    farm.submit(JobId(8), 1, 1);
    let mut errors = Vec::new();
    for w in [W0, W1, W2] {
        let a = farm.request(w).expect("retry");
        farm.fail(w, &a).expect("failed");
        errors.push((w, format!("boom on {w}")));
    }
    let events = farm.events();
    let failed = events.iter().find_map(|e| match e {
        Event::JobFailed {
            job,
            reason,
            errors,
        } => Some((*job, *reason, errors.clone())),
        _ => None,
    });
    assert_eq!(
        failed,
        Some((JOB, JobFailure::PackageFailed(PackageId(0)), errors))
    );
    // The next job starts and runs.
    assert!(events.contains(&Event::JobStarted {
        job: JobId(8),
        frames: 1
    }));
    let next = farm.request(W3).expect("next job");
    assert_eq!(next.job, JobId(8));
    farm.valid();
}

#[test]
fn cancelling_the_running_job_cancels_its_packages() {
    let mut farm = Farm::running(2, 100, 2);
    let a = farm.request(W0).expect("work");
    let b = farm.request(W1).expect("work");
    let _ = farm.events();
    farm.s.cancel_job(farm.now, JOB).expect("cancel");
    assert_eq!(
        farm.events(),
        [
            Event::PackageCancelled {
                worker: W0,
                package: a.package
            },
            Event::PackageCancelled {
                worker: W1,
                package: b.package
            },
            Event::JobCancelled { job: JOB },
        ]
    );
    assert_eq!(farm.done(W0, &a), Err(ReportError::Finished(a.package)));
    assert_eq!(farm.s.worker_state(W1), Some(WorkerState::Idle));
    assert_eq!(
        farm.s.cancel_job(farm.now, JOB),
        Err(CancelError::UnknownJob(JOB))
    );
    farm.valid();
}

#[test]
fn cancelling_a_queued_job_removes_it() {
    let mut farm = Farm::running(1, 10, 1);
    farm.submit(JobId(8), 10, 1);
    assert_eq!(farm.s.queue().waiting, [JobId(8)]);
    farm.s.cancel_job(farm.now, JobId(8)).expect("cancel");
    assert!(farm.s.queue().waiting.is_empty());
    assert_eq!(
        farm.events().last(),
        Some(&Event::JobCancelled { job: JobId(8) })
    );
}

// ----- Worker transitions -----

#[test]
fn worker_states_follow_the_table() {
    let mut farm = Farm::new();
    farm.join(W0);
    assert_eq!(farm.s.worker_state(W0), Some(WorkerState::Idle));
    assert_eq!(farm.request(W0), None);
    assert_eq!(farm.s.worker_state(W0), Some(WorkerState::Waiting));
    farm.submit(JOB, 100, 1);
    let a = farm.assignments().pop().expect("work once there is some");
    assert_eq!(farm.s.worker_state(W0), Some(WorkerState::Busy));
    // Asking ahead while busy (a pipelining driver).
    let b = farm.request(W0).expect("second package");
    assert_eq!(farm.s.worker_state(W0), Some(WorkerState::Busy));
    farm.done(W0, &a).expect("done");
    farm.done(W0, &b).expect("done");
    assert_eq!(farm.s.worker_state(W0), Some(WorkerState::Idle));
    farm.s.worker_left(farm.now, W0).expect("left");
    assert_eq!(farm.s.worker_state(W0), Some(WorkerState::Gone));
    assert_eq!(
        farm.s.heartbeat(farm.now, W0),
        Err(WorkerError::NotConnected(W0))
    );
    farm.join(W0);
    assert_eq!(farm.s.worker_state(W0), Some(WorkerState::Idle));
    assert_eq!(
        farm.s.worker_joined(farm.now, W0, 4),
        Err(JoinError::AlreadyConnected(W0))
    );
    farm.valid();
}

// ----- Policy -----

#[test]
fn package_sizes_follow_guided_self_scheduling() {
    let mut farm = Farm::running(1, 1000, 1);
    // Before any measurement: 1 unit/s, target clamped to the 10 s maximum.
    let a = farm.request(W0).expect("work");
    assert_eq!(a.items.len(), 10);
    // Round trip 0.1 s for 10 units: 100 units/s. Target
    // 990 / (2 · 100) = 4.95 s, so 495 units: half the remaining work.
    farm.at_ms(100);
    farm.done(W0, &a).expect("done");
    let b = farm.request(W0).expect("work");
    assert_eq!(b.items.len(), 495);
    // A new worker with 2 threads starts at 2 × the mean rate per thread:
    // 200 units/s of a total 300, target 495 / (2 · 300) = 0.825 s, so 165
    // units.
    farm.s.worker_joined(farm.now, W1, 2).expect("join");
    let c = farm.request(W1).expect("work");
    assert_eq!(c.items.len(), 165);
    assert_eq!(c.expected, Duration::from_millis(825));
    farm.valid();
}

/// Under frame affinity a package is sized within its frame's crew, but
/// never larger than guided self-scheduling over the whole job gives: in a
/// job that is short for the farm (or near a job's end) every worker
/// shares the last frames, so their packages shrink for all of them.
#[test]
fn packages_near_a_jobs_end_are_sized_for_every_worker() {
    // 16 workers at the prior rate of 1 unit/s, frames of 60 items of 1
    // unit; crews of max(16 / (8 − 3), 4) = 4 workers.
    let check = |frames: usize, expected: usize| {
        let mut farm = Farm::with(common::split_pipelined());
        for w in 0..16 {
            farm.join(WorkerId(w));
        }
        farm.submit(JOB, 60, frames);
        let a = farm.request(W0).expect("work");
        assert_eq!(a.items.len(), expected, "a job of {frames} frames");
        farm.valid();
    };
    // A long job: the crew's share binds, 60 / (2 · 4) = 7.5 units (the
    // cut closer to it by the later item: 8).
    check(20, 8);
    // Two frames: the job's 120 units over 2 · 16 workers, 3.75 units.
    check(2, 4);
    // One frame: 60 / (2 · 16) = 1.875 units.
    check(1, 2);
}

/// Under frame affinity the workers are spread over the frames in flight
/// but three: frames complete in order, so the oldest frame while its last
/// packages run and the frames done but waiting for it hold their slots,
/// and a crew whose frame has nothing left to hand out must find one free
/// to start the next frame (with no room it would spread over the other
/// crews' frames, each worker setting a frame up for a small share).
#[test]
fn crews_leave_three_of_the_frames_in_flight_free() {
    let mut farm = Farm::with(common::split_pipelined());
    for w in 0..40 {
        farm.join(WorkerId(w));
    }
    farm.submit(JOB, 80, 20);
    let mut crews = std::collections::BTreeMap::<u32, usize>::new();
    for w in 0..40 {
        let a = farm.request(WorkerId(w)).expect("work");
        *crews.entry(a.frame).or_default() += 1;
    }
    // 40 workers over 8 − 3 frames: crews of 8.
    let expected: std::collections::BTreeMap<u32, usize> = (0..5).map(|f| (f, 8)).collect();
    assert_eq!(crews, expected);
    farm.valid();
}

#[test]
fn packages_are_large_early_and_small_late() {
    let mut farm = Farm::new();
    let workers = [W0, W1, W2, W3];
    for w in workers {
        farm.join(w);
    }
    farm.submit(JOB, 2000, 2);
    let log = farm.run_to_end(&workers, Duration::from_secs(3600), &|_| 0.005);
    let sizes: Vec<usize> = (log.assignments.iter())
        .filter(|(_, a)| a.frame == 1)
        .map(|(_, a)| a.items.len())
        .collect();
    // Each round of 4 takes about 1/k = half of the rest, down to the
    // minimum duration (20 ms = 4 items).
    assert!(sizes[0] >= 200, "{sizes:?}");
    assert!(sizes.windows(5).all(|w| w[4] <= w[0]), "{sizes:?}");
    assert!(
        sizes[sizes.len() - 4..].iter().all(|&s| s <= 5),
        "{sizes:?}"
    );
    assert!(
        log.events
            .iter()
            .any(|(_, e)| *e == Event::JobComplete { job: JOB })
    );
    farm.valid();
}

/// Job 3 comes first and starts (nothing runs); job 1, submitted at once,
/// outranks it (equal priority, lower id) and takes every worker from its
/// first package on; job 2 comes later, starts on a worker job 1 has
/// nothing for (its last packages run), and still outranks 3.
#[test]
fn jobs_run_by_rank_and_the_first_job_starts_when_none_runs() {
    let mut farm = Farm::new();
    let workers = [W0, W1, W2];
    for w in workers {
        farm.join(w);
    }
    // 100 items of 10 to 30 ms.
    let mut rng = common::Rng::new(9);
    let costs: Vec<f64> = (0..100).map(|_| 0.01 * (1.0 + 2.0 * rng.unit())).collect();
    let cost = |item: u32| costs[(item - 100) as usize];
    farm.submit(JobId(3), 100, 2);
    farm.submit(JobId(1), 100, 2);
    let mut log = farm.run_to_end(&workers, Duration::from_millis(100), &cost);
    farm.submit(JobId(2), 100, 2);
    log.extend(farm.run_to_end(&[], Duration::from_secs(3600), &cost));
    let order: Vec<String> = (log.events.iter())
        .filter_map(|(_, e)| match e {
            Event::JobStarted { job, .. } => Some(format!("start {}", job.0)),
            Event::FrameComplete { job, frame, .. } => Some(format!("frame {}.{frame}", job.0)),
            Event::JobComplete { job } => Some(format!("end {}", job.0)),
            _ => None,
        })
        .collect();
    assert_eq!(
        order,
        [
            "start 3",
            "start 1",
            "start 2",
            "frame 1.0",
            "frame 1.1",
            "end 1",
            "frame 2.0",
            "frame 2.1",
            "end 2",
            "frame 3.0",
            "frame 3.1",
            "end 3"
        ]
    );
    farm.valid();
}

#[test]
fn cost_estimates_carry_over_to_the_next_frame() {
    let config = SchedulerConfig {
        sizing: PackageSizing {
            guided_factor: 1.0,
            max_duration: Duration::from_secs(1000),
            ..PackageSizing::default()
        },
        ..SchedulerConfig::default()
    };
    let mut farm = Farm::with(config);
    farm.join(W0);
    let frames = vec![
        FrameWork {
            items: vec![1, 2, 3, 4],
        },
        FrameWork {
            items: vec![1, 2, 3, 4, 99],
        },
    ];
    farm.s.submit_job(farm.now, JOB, frames).expect("submit");
    // First frame: uniform, 1 unit per item; the whole frame at 4 units/s.
    let a = farm.request(W0).expect("work");
    assert_eq!((a.items.len(), a.estimated_cost), (4, 4.0));
    farm.at_ms(8000);
    let measure = PackageMeasure {
        busy: Duration::from_secs(8),
        item_seconds: vec![1.0, 1.0, 1.0, 5.0],
        ..PackageMeasure::default()
    };
    farm.s
        .package_done(farm.now, W0, a.package, measure)
        .expect("done");
    // 4 units in 8 busy seconds: 0.5 units/s, so items cost 0.5, 0.5, 0.5
    // and 2.5; the new item 99 gets their mean, 1.
    let b = farm.request(W0).expect("work");
    assert_eq!(b.items, [1, 2, 3, 4, 99]);
    assert_eq!(b.estimated_cost, 5.0);
    farm.valid();
}

// ----- Refusals -----

#[test]
fn bad_results_are_refused_and_counted() {
    let mut farm = Farm::running(2, 100, 1);
    let a = farm.request(W0).expect("work");
    let unknown = Assignment {
        package: PackageId(999),
        ..a.clone()
    };
    assert_eq!(
        farm.done(W0, &unknown),
        Err(ReportError::UnknownPackage(PackageId(999)))
    );
    assert_eq!(
        farm.done(W1, &a),
        Err(ReportError::NotAssigned {
            package: a.package,
            worker: W1
        })
    );
    assert_eq!(farm.fail(W3, &a), Err(ReportError::NotConnected(W3)));
    farm.done(W0, &a).expect("done");
    assert_eq!(farm.done(W0, &a), Err(ReportError::Finished(a.package)));
    let counters = farm.s.counters();
    assert_eq!(counters.ignored_results(), 4);
    assert_eq!(
        (
            counters.results_unknown_package,
            counters.results_not_assigned,
            counters.results_not_connected,
            counters.results_finished
        ),
        (1, 1, 1, 1)
    );
    assert_eq!(
        farm.s.request_work(farm.now, W3),
        Err(WorkerError::NotConnected(W3))
    );
    farm.valid();
}

#[test]
fn job_ids_are_unique_among_queued_and_running_jobs() {
    let mut farm = Farm::running(0, 10, 1);
    let twice = farm.s.submit_job(farm.now, JOB, Vec::new());
    assert_eq!(twice, Err(SubmitError::DuplicateJob(JOB)));
}

#[test]
fn empty_jobs_and_frames_complete_at_once() {
    let mut farm = Farm::new();
    farm.s
        .submit_job(farm.now, JobId(1), Vec::new())
        .expect("submit");
    farm.s
        .submit_job(farm.now, JobId(2), vec![FrameWork::default()])
        .expect("submit");
    let events = farm.events();
    assert_eq!(
        events[..2],
        [
            Event::JobStarted {
                job: JobId(1),
                frames: 0
            },
            Event::JobComplete { job: JobId(1) },
        ]
    );
    assert!(
        matches!(&events[4], Event::FrameComplete { job: JobId(2), stats, .. } if stats.items == 0)
    );
    assert_eq!(events[5], Event::JobComplete { job: JobId(2) });
    assert!(!farm.s.has_jobs());
}

#[test]
fn a_job_waits_while_no_worker_is_connected() {
    let mut farm = Farm::running(1, 10, 1);
    farm.s.worker_left(farm.now, W0).expect("left");
    let events = farm.events();
    assert!(!events.iter().any(|e| matches!(e, Event::JobFailed { .. })));
    farm.join(W1);
    assert!(farm.request(W1).is_some());
}

#[test]
fn time_going_backwards_is_read_as_now() {
    let mut farm = Farm::running(1, 10, 1);
    farm.at_ms(5000);
    let a = farm.request(W0).expect("work");
    farm.at_ms(1000);
    farm.done(W0, &a).expect("done");
    farm.valid();
}

#[test]
fn status_shows_progress_and_rates() {
    let mut farm = Farm::running(2, 100, 3);
    let a = farm.request(W0).expect("work");
    farm.at_ms(100);
    farm.done(W0, &a).expect("done");
    let queue = farm.s.queue();
    let progress = queue.running.first().expect("running");
    assert_eq!((progress.job, progress.frame, progress.frames), (JOB, 0, 3));
    assert_eq!((progress.items_done, progress.items_total), (10, 100));
    let workers = farm.s.workers();
    assert_eq!(workers[0].packages_done, 1);
    assert_eq!(workers[0].rate, Some(100.0));
    assert_eq!(workers[0].compute_rate, Some(1000.0));
    assert_eq!(workers[1].rate, None);
}

#[test]
fn requests_lapse_at_a_frame_start_when_configured() {
    let config = SchedulerConfig {
        requests_lapse_at_frame_start: true,
        ..SchedulerConfig::default()
    };
    let mut farm = Farm::with(config);
    farm.join(W0);
    farm.join(W1);
    farm.submit(JOB, 1, 2);
    // W0 takes the one item of frame 0; W1 asks and waits.
    let first = farm.request(W0).expect("frame 0 has work");
    assert!(farm.request(W1).is_none());
    farm.done(W0, &first).expect("accepted");
    // Frame 1 started: W1's old request lapsed, nobody gets work unasked.
    assert!(farm.assignments().is_empty());
    assert_eq!(farm.s.worker_state(W1), Some(WorkerState::Idle));
    // Asking again (after setting the frame up) gets it.
    assert_eq!(farm.request(W1).expect("frame 1 has work").frame, 1);
    farm.valid();
}

#[test]
fn an_arrived_result_held_by_the_driver_is_not_a_straggler() {
    let (mut farm, a) = straggling();
    // The result is here at 0.5 s, but the driver checks it only later.
    farm.at_ms(500);
    farm.s
        .package_arrived(farm.now, W0, a.package)
        .expect("arrived");
    // Only the heartbeats are due now (W1 asked at 0 s).
    assert_eq!(farm.s.poll_timeout(), Some(Duration::from_secs(10)));
    farm.s.handle_timeout(Duration::from_secs(3));
    assert!(farm.assignments().is_empty(), "no copy of a held result");
    assert_eq!(farm.state(a.package), Some(PackageState::Assigned));
    // Accepted at 3 s: the rate counts the time up to its arrival.
    farm.at_ms(3000);
    farm.done(W0, &a).expect("accepted");
    let w0 = farm.s.workers()[0].clone();
    assert_eq!(w0.rate, Some(2.0));
    farm.valid();
}

#[test]
fn pipelined_frames_start_when_the_running_frame_has_nothing_left() {
    let config = SchedulerConfig {
        frames_in_flight: 2,
        ..common::split_pipelined()
    };
    let mut farm = Farm::with(config);
    farm.join(W0);
    farm.join(W1);
    farm.submit(JOB, 2, 3);
    let a = farm.request(W0).expect("frame 0");
    let b = farm.request(W1).expect("frame 0");
    assert_eq!(
        (a.frame, b.frame, a.items.len(), b.items.len()),
        (0, 0, 1, 1)
    );
    // Frame 0 has nothing left to hand out: frame 1 starts, frame 0 runs on.
    let started: Vec<u32> = (farm.events().into_iter())
        .filter_map(|e| match e {
            Event::FrameStarted { frame, .. } => Some(frame),
            _ => None,
        })
        .collect();
    assert_eq!(started, [0, 1]);
    farm.valid();
    // W1 is done and, set up for frame 1, takes its work while W0 is busy.
    farm.at_ms(100);
    farm.done(W1, &b).expect("accepted");
    let c = farm.request(W1).expect("frame 1");
    assert_eq!(c.frame, 1);
    let d = farm.request(W1).expect("frame 1, asking ahead");
    assert_eq!(d.frame, 1);
    farm.valid();
    // Only two frames run at once: frame 1 has nothing left, frame 2 waits
    // for frame 0.
    assert!(farm.events().is_empty());
    farm.at_ms(200);
    farm.done(W1, &c).expect("accepted");
    farm.done(W1, &d).expect("accepted");
    assert!(farm.events().is_empty(), "frame 1 completes after frame 0");
    farm.at_ms(300);
    farm.done(W0, &a).expect("accepted");
    let order: Vec<(&str, u32)> = (farm.events().iter())
        .filter_map(|e| match e {
            Event::FrameComplete { frame, .. } => Some(("complete", *frame)),
            Event::FrameStarted { frame, .. } => Some(("started", *frame)),
            _ => None,
        })
        .collect();
    assert_eq!(order, [("complete", 0), ("complete", 1), ("started", 2)]);
    assert_eq!(farm.s.queue().running[0].frame, 2);
    farm.valid();
}

#[test]
fn a_lost_worker_requeues_its_packages_in_both_pipelined_frames() {
    // Without frame affinity, which would keep W0 on frame 0.
    let mut farm = Farm::with(SchedulerConfig {
        frame_affinity: false,
        ..SchedulerConfig::default().pipelined(common::FRAMES_IN_FLIGHT)
    });
    farm.join(W0);
    farm.join(W1);
    farm.submit(JOB, 2, 2);
    let a = farm.request(W0).expect("frame 0");
    let b = farm.request(W1).expect("frame 0");
    let _ = farm.events();
    farm.at_ms(100);
    let c = farm.request(W0).expect("frame 1, asking ahead");
    assert_eq!(c.frame, 1);
    farm.s.worker_left(farm.now, W0).expect("left");
    assert_eq!(farm.state(a.package), Some(PackageState::Queued));
    assert_eq!(farm.state(c.package), Some(PackageState::Queued));
    farm.valid();
    // W1 redoes frame 0's package first, then frame 1's.
    farm.done(W1, &b).expect("accepted");
    let redo = farm.request(W1).expect("requeued");
    assert_eq!((redo.frame, &redo.items), (0, &a.items));
    farm.done(W1, &redo).expect("accepted");
    let next = farm.request(W1).expect("requeued");
    assert_eq!((next.frame, &next.items), (1, &c.items));
    farm.valid();
}

// ----- Whole frames -----

/// The master's rules over two workers and a job of `frames` frames of 6
/// items.
fn whole_farm(frames: usize) -> Farm {
    let mut farm = Farm::with(SchedulerConfig::default().pipelined(common::FRAMES_IN_FLIGHT));
    farm.join(W0);
    farm.join(W1);
    farm.submit(JOB, 6, frames);
    farm
}

fn started_whole(events: &[Event]) -> Vec<(u32, bool)> {
    (events.iter())
        .filter_map(|e| match e {
            Event::FrameStarted { frame, whole, .. } => Some((*frame, *whole)),
            _ => None,
        })
        .collect()
}

#[test]
fn a_deep_job_starts_whole_frames_and_splits_its_last_ones() {
    let mut farm = whole_farm(4);
    let a = farm.request(W0).expect("frame 0");
    let b = farm.request(W1).expect("frame 1");
    // Whole: every item of the frame in one package, marked so.
    assert_eq!((a.frame, a.items.len(), a.whole), (0, 6, true));
    assert_eq!((b.frame, b.items.len(), b.whole), (1, 6, true));
    // Frames 2 and 3 start with 2 and 1 frames left, no more than the
    // workers: split.
    let c = farm.request(W0).expect("frame 2, asking ahead");
    assert!(!c.whole && c.items.len() < 6, "{c:?}");
    farm.valid();
    let starts = started_whole(&farm.events());
    assert_eq!(&starts[..3], [(0, true), (1, true), (2, false)]);
}

#[test]
fn a_lost_or_failed_whole_frame_goes_back_whole() {
    let mut farm = whole_farm(6);
    let a = farm.request(W0).expect("frame 0");
    assert!(a.whole);
    farm.s.worker_left(farm.now, W0).expect("left");
    assert_eq!(farm.state(a.package), Some(PackageState::Queued));
    farm.valid();
    // W1 takes frame 0 again, all of it, though its target is smaller.
    let again = farm.request(W1).expect("requeued");
    assert_eq!(
        (again.package, again.frame, &again.items),
        (a.package, 0, &a.items)
    );
    assert!(again.whole);
    farm.fail(W1, &again).expect("failure accepted");
    assert_eq!(farm.state(a.package), Some(PackageState::Queued));
    farm.join(W2);
    let third = farm.request(W2).expect("requeued after the failure");
    assert_eq!((third.package, &third.items), (a.package, &a.items));
    farm.valid();
}

/// Two workers on a 40-frame job with 2 frames in flight; W1 holds frame 0
/// while W0 finishes whole frames as fast as it gets them: the frames W0
/// got, then W1 finishes frame 0 and the frames that start then.
/// `base_frame` is the master's time per base frame, reported first where
/// given (the tail measured once W0's first frame is done).
fn whole_frames_behind_a_slow_one(base_frame: Option<Duration>) -> (Vec<u32>, Vec<u32>) {
    let mut farm = Farm::with(SchedulerConfig {
        frames_in_flight: 2,
        ..SchedulerConfig::default().pipelined(common::FRAMES_IN_FLIGHT)
    });
    farm.join(W0);
    farm.join(W1);
    farm.submit(JOB, 6, 40);
    if let Some(cost) = base_frame {
        farm.s
            .base_frame_cost(farm.now, JOB, cost)
            .expect("running");
    }
    let oldest = farm.request(W1).expect("frame 0");
    let mut later = Vec::new();
    while let Some(a) = farm.request(W0) {
        assert!(a.whole, "{a:?}");
        farm.done(W0, &a).expect("accepted");
        later.push(a.frame);
        assert!(later.len() <= 10, "{later:?}");
    }
    farm.valid();
    farm.at_ms(50);
    farm.done(W1, &oldest).expect("accepted");
    let next = farm.assignments().iter().map(|a| a.frame).collect();
    farm.valid();
    (later, next)
}

/// Whole frames in flight are bounded by the workers: each runs one and
/// holds one ahead, and, once the tail is measured, `frames_in_flight`
/// more may be done waiting for an older one (frames complete in order).
#[test]
fn whole_frames_in_flight_follow_the_workers() {
    let (later, next) = whole_frames_behind_a_slow_one(Some(Duration::from_millis(1)));
    // Frame 0 (W1's) holds the others: 2 + 2 · 2 = 6 frames in flight,
    // then W0 waits.
    assert_eq!(later, [1, 2, 3, 4, 5]);
    assert_eq!(next, [6]);
}

/// Before the tail is measured (no base frame's time reported), a job's
/// start commits no whole frames beyond the workers' own two: one more
/// would wait for a third round while the tail's split frames, done,
/// waited for it.
#[test]
fn an_unmeasured_tail_holds_whole_frames_to_two_per_worker() {
    let (later, next) = whole_frames_behind_a_slow_one(None);
    // 2 · 2 = 4 frames in flight, then W0 waits.
    assert_eq!(later, [1, 2, 3]);
    assert_eq!(next, [4]);
}

#[test]
fn an_interactive_jobs_frames_are_all_split() {
    let mut farm = Farm::with(SchedulerConfig::default().pipelined(common::FRAMES_IN_FLIGHT));
    farm.join(W0);
    farm.join(W1);
    let frame = FrameWork {
        items: (100..106).collect(),
    };
    farm.s
        .submit_interactive_job(farm.now, JOB, vec![frame; 3])
        .expect("submit");
    let a = farm.request(W0).expect("frame 0");
    let b = farm.request(W1).expect("frame 0");
    assert!(!a.whole && !b.whole && a.items.len() < 6, "{a:?} {b:?}");
    // Three frames on two workers would start whole in a batch job.
    assert_eq!(started_whole(&farm.events())[0], (0, false));
    farm.valid();
}

// ----- Several jobs at once -----

/// The running jobs, in rank order.
fn running_jobs(farm: &Farm) -> Vec<JobId> {
    farm.s.queue().running.iter().map(|r| r.job).collect()
}

/// Two workers, two jobs: job 1's one package runs on W0 and job 2 has 10
/// items; W1 got job 2's work.
fn two_jobs_running() -> (Farm, Assignment, Assignment) {
    let mut farm = Farm::new();
    farm.join(W0);
    farm.join(W1);
    farm.submit(JobId(1), 1, 1);
    farm.submit(JobId(2), 10, 1);
    let a = farm.request(W0).expect("work");
    let b = farm.request(W1).expect("work");
    (farm, a, b)
}

#[test]
fn a_second_job_runs_on_a_worker_the_first_has_nothing_for() {
    let (mut farm, a, b) = two_jobs_running();
    // Job 1's only package runs: W1 takes job 2's work instead of idling.
    assert_eq!((a.job, b.job), (JobId(1), JobId(2)));
    assert_eq!(running_jobs(&farm), [JobId(1), JobId(2)]);
    assert!(farm.s.queue().waiting.is_empty());
    farm.valid();
    farm.at_ms(100);
    farm.done(W0, &a).expect("done");
    assert!(
        farm.events()
            .contains(&Event::JobComplete { job: JobId(1) })
    );
    let c = farm.request(W0).expect("work");
    assert_eq!(c.job, JobId(2));
    farm.valid();
}

#[test]
fn a_job_at_its_frames_in_flight_limit_lets_the_next_job_use_the_worker() {
    let mut farm = Farm::new(); // one frame in flight
    farm.join(W0);
    farm.join(W1);
    farm.submit(JobId(1), 1, 3);
    farm.submit(JobId(2), 10, 1);
    let a = farm.request(W0).expect("work");
    // Frame 0's one package runs and frame 1 may not start yet.
    let b = farm.request(W1).expect("work");
    assert_eq!((a.job, a.frame), (JobId(1), 0));
    assert_eq!(b.job, JobId(2));
    // Frame 0 done: frame 1 starts, and job 1 comes first again.
    farm.at_ms(50);
    farm.done(W0, &a).expect("done");
    let c = farm.request(W0).expect("work");
    assert_eq!((c.job, c.frame), (JobId(1), 1));
    farm.valid();
}

#[test]
fn a_worker_blocklisted_for_one_job_works_on_the_next() {
    let mut farm = Farm::new();
    farm.join(W0);
    farm.join(W1);
    farm.submit(JobId(1), 100, 1);
    farm.submit(JobId(2), 10, 1);
    let _held = farm.request(W0).expect("work");
    for _ in 0..3 {
        let a = farm.request(W1).expect("work");
        assert_eq!(a.job, JobId(1));
        farm.fail(W1, &a).expect("failed");
    }
    let events = farm.events();
    assert!(events.contains(&Event::WorkerBlocklisted {
        worker: W1,
        job: JobId(1)
    }));
    // Job 1 still has work, but none for W1.
    let progress = &farm.s.queue().running[0];
    assert!(progress.items_done < progress.items_total);
    let b = farm.request(W1).expect("work of the next job");
    assert_eq!(b.job, JobId(2));
    farm.valid();
}

#[test]
fn a_higher_priority_job_takes_each_worker_at_its_next_request_and_stops_nothing() {
    let mut farm = Farm::running(2, 100, 2);
    let a = farm.request(W0).expect("work");
    let b = farm.request(W1).expect("work");
    let _ = farm.events();
    let options = vtfarm_scheduler::QueueOptions {
        priority: 5,
        ..Default::default()
    };
    let high = JobId(9);
    let frame = FrameWork {
        items: (0..100).collect(),
    };
    (farm.s)
        .submit_job_with(farm.now, high, vec![frame], options)
        .expect("submit");
    // Nobody waits: it starts when a worker asks, and no package is stopped.
    assert!(farm.events().is_empty());
    farm.at_ms(100);
    farm.done(W0, &a).expect("done");
    let c = farm.request(W0).expect("work");
    assert_eq!(c.job, high);
    assert_eq!(running_jobs(&farm), [high, JOB]);
    // W1's package of the lower job finishes and counts; W1 goes over too.
    farm.done(W1, &b).expect("the running package counts");
    let d = farm.request(W1).expect("work");
    assert_eq!(d.job, high);
    let events = farm.events();
    assert!(
        !events
            .iter()
            .any(|e| matches!(e, Event::PackageCancelled { .. })),
        "{events:?}"
    );
    farm.valid();
}

#[test]
fn a_pause_of_one_of_two_running_jobs_holds_only_its_new_work() {
    let (mut farm, a, b) = two_jobs_running();
    farm.join(W2);
    farm.s.pause_job(farm.now, JobId(2)).expect("pause");
    // Job 1 has nothing left to hand out, job 2 is paused: W2 waits.
    assert_eq!(farm.request(W2), None);
    assert_eq!(running_jobs(&farm), [JobId(1), JobId(2)]);
    assert!(farm.s.queue().running[1].paused);
    // Both running packages finish and count.
    farm.at_ms(100);
    farm.done(W0, &a).expect("done");
    farm.done(W1, &b).expect("done while paused");
    assert_eq!(farm.request(W1), None);
    assert_eq!(farm.s.queue().running[0].items_done, b.items.len());
    let _ = farm.events();
    farm.s.resume_job(farm.now, JobId(2)).expect("resume");
    assert_eq!(farm.events()[0], Event::JobResumed { job: JobId(2) });
    // The waiting workers get its work again.
    let resumed = farm.assignments();
    assert_eq!(
        resumed
            .iter()
            .map(|x| (x.worker, x.job))
            .collect::<Vec<_>>(),
        [(W2, JobId(2)), (W1, JobId(2))]
    );
    farm.valid();
}

#[test]
fn cancelling_one_of_two_running_jobs_cancels_exactly_its_packages() {
    let (mut farm, a, b) = two_jobs_running();
    farm.join(W2);
    let c = farm.request(W2).expect("work");
    assert_eq!(c.job, JobId(2));
    let _ = farm.events();
    farm.s.cancel_job(farm.now, JobId(2)).expect("cancel");
    assert_eq!(
        farm.events(),
        [
            Event::PackageCancelled {
                worker: W1,
                package: b.package
            },
            Event::PackageCancelled {
                worker: W2,
                package: c.package
            },
            Event::JobCancelled { job: JobId(2) },
        ]
    );
    assert_eq!(running_jobs(&farm), [JobId(1)]);
    assert_eq!(farm.state(a.package), Some(PackageState::Assigned));
    farm.at_ms(100);
    farm.done(W0, &a).expect("job 1 goes on");
    assert!(
        farm.events()
            .contains(&Event::JobComplete { job: JobId(1) })
    );
    farm.valid();
}

#[test]
fn rates_are_measured_per_job() {
    let (mut farm, a, b) = two_jobs_running();
    farm.at_ms(100);
    farm.done(W0, &a).expect("done");
    farm.done(W1, &b).expect("done");
    // W1 measured job 2 (its unit: b.items.len() items in 0.1 s); W0 has
    // no rate in job 2 yet and starts from W1's per thread, not from its
    // rate in job 1.
    let w1 = farm.s.workers()[1].rate.expect("measured");
    assert!((w1 - b.items.len() as f64 / 0.1).abs() < 1e-6, "{w1}");
    let c = farm.request(W0).expect("work");
    assert_eq!(c.job, JobId(2));
    assert!((c.expected.as_secs_f64() - c.estimated_cost / w1).abs() < 1e-6);
    farm.valid();
}

/// The master's base-frame measures name a running job; for any other
/// (never submitted, or over) they are refused and change nothing.
#[test]
fn base_frame_measures_of_a_job_not_running_are_refused() {
    let mut farm = Farm::running(1, 4, 1);
    let other = JobId(99);
    let unknown = Err(CancelError::UnknownJob(other));
    let cost = Duration::from_millis(60);
    assert_eq!(farm.s.base_frame_cost(farm.now, other, cost), unknown);
    assert_eq!(farm.s.base_frame_ahead(farm.now, other, 0), unknown);
    assert_eq!(farm.s.base_frame_cost(farm.now, JOB, cost), Ok(()));
    assert_eq!(farm.s.base_frame_ahead(farm.now, JOB, 0), Ok(()));
}
