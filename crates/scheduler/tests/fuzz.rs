//! Random sequences of inputs (joins, leaves, heartbeats, requests, results,
//! failures, timeouts, submissions at priorities, cancellations, pauses,
//! resumes and priority changes, so several jobs run at once, pause and go
//! on), with worker, package and job ids that are often unknown or stale.
//! The scheduler must never panic, keep its invariants after every input,
//! accept a result only for a package the worker runs, and complete every
//! item of a frame exactly once. (Random farms, with links, crashes and
//! slowdowns, run on the real master in `vtfarm-farmsim`'s tests.)

mod common;

use std::collections::BTreeMap;
use std::time::Duration;

use proptest::prelude::*;
use vtfarm_scheduler::{
    Assignment, Event, FrameWork, JobId, PackageId, PackageMeasure, QueueOptions, Scheduler,
    SchedulerConfig, WorkerId,
};

#[derive(Clone, Debug)]
enum Op {
    Join {
        worker: u8,
        threads: u8,
    },
    Leave {
        worker: u8,
    },
    Heartbeat {
        worker: u8,
    },
    /// Every worker 0..8 sends a heartbeat (so that some survive timeouts).
    HeartbeatAll,
    Request {
        worker: u8,
    },
    /// A result, mostly for a package the test thinks is running (`pick`
    /// chooses), sometimes for an old assignment or an unknown package; from
    /// the package's own worker or from `worker`.
    Done {
        pick: u16,
        own: bool,
        worker: u8,
        busy_ms: u16,
        split: bool,
    },
    Fail {
        pick: u16,
        own: bool,
        worker: u8,
    },
    /// `handle_timeout` now, or at the next deadline (jumping the clock).
    Timeout {
        jump: bool,
    },
    Advance {
        ms: u16,
    },
    Submit {
        job: u8,
        frames: u8,
        items: u8,
        priority: i8,
    },
    Cancel {
        job: u8,
    },
    Pause {
        job: u8,
    },
    Resume {
        job: u8,
    },
    Priority {
        job: u8,
        priority: i8,
    },
    /// The master's time for one of the job's base frames (0 is ignored).
    BaseFrameCost {
        job: u8,
        ms: u16,
    },
    /// The master made a base frame of the job ahead.
    BaseFrameAhead {
        job: u8,
        frame: u8,
    },
}

fn op() -> impl Strategy<Value = Op> {
    let worker = 0u8..8;
    prop_oneof![
        3 => (worker.clone(), 0u8..5).prop_map(|(worker, threads)| Op::Join { worker, threads }),
        1 => worker.clone().prop_map(|worker| Op::Leave { worker }),
        1 => worker.clone().prop_map(|worker| Op::Heartbeat { worker }),
        2 => Just(Op::HeartbeatAll),
        8 => worker.clone().prop_map(|worker| Op::Request { worker }),
        10 => (any::<u16>(), prop::bool::weighted(0.9), worker.clone(), any::<u16>(), any::<bool>())
            .prop_map(|(pick, own, worker, busy_ms, split)| Op::Done { pick, own, worker, busy_ms, split }),
        1 => (any::<u16>(), prop::bool::weighted(0.9), worker).prop_map(|(pick, own, worker)| Op::Fail { pick, own, worker }),
        2 => prop::bool::weighted(0.3).prop_map(|jump| Op::Timeout { jump }),
        3 => prop_oneof![0u16..500, 0u16..20_000].prop_map(|ms| Op::Advance { ms }),
        2 => (0u8..4, 0u8..4, 0u8..60, -2i8..3).prop_map(|(job, frames, items, priority)| Op::Submit { job, frames, items, priority }),
        1 => (0u8..4).prop_map(|job| Op::Cancel { job }),
        1 => (0u8..4).prop_map(|job| Op::Pause { job }),
        1 => (0u8..4).prop_map(|job| Op::Resume { job }),
        1 => (0u8..4, -2i8..3).prop_map(|(job, priority)| Op::Priority { job, priority }),
        1 => (0u8..4, 0u16..400).prop_map(|(job, ms)| Op::BaseFrameCost { job, ms }),
        1 => (0u8..4, 0u8..4).prop_map(|(job, frame)| Op::BaseFrameAhead { job, frame }),
    ]
}

/// The scheduler plus everything the test knows independently of it.
struct Model {
    s: Scheduler,
    now: Duration,
    issued: Vec<Assignment>,
    /// Assignments the test has not reported a result for.
    outstanding: Vec<(WorkerId, PackageId)>,
    /// The latest assignment of each package to each worker.
    latest: BTreeMap<(WorkerId, PackageId), Assignment>,
    /// The frames of each job, as last submitted.
    jobs: BTreeMap<JobId, Vec<FrameWork>>,
    /// Accepted completions per item of each (job, frame) of the running job.
    completed: BTreeMap<(JobId, u32), BTreeMap<u32, u32>>,
}

impl Model {
    fn pick(&mut self, pick: u16, own: bool, worker: u8) -> (WorkerId, PackageId) {
        let other = WorkerId(u64::from(worker));
        let index = usize::from(pick);
        let (owner, package) = if pick < 50_000 && !self.outstanding.is_empty() {
            self.outstanding.swap_remove(index % self.outstanding.len())
        } else if pick < 60_000 && !self.issued.is_empty() {
            let a = &self.issued[index % self.issued.len()];
            (a.worker, a.package)
        } else {
            (other, PackageId(u64::from(pick) + 1_000_000))
        };
        (if own { owner } else { other }, package)
    }

    fn apply(&mut self, op: &Op) -> Result<(), TestCaseError> {
        let now = self.now;
        let w = |id: &u8| WorkerId(u64::from(*id));
        match op {
            Op::Join { worker, threads } => {
                let _ = self.s.worker_joined(now, w(worker), u32::from(*threads));
            }
            Op::Leave { worker } => {
                let _ = self.s.worker_left(now, w(worker));
            }
            Op::Heartbeat { worker } => {
                let _ = self.s.heartbeat(now, w(worker));
            }
            Op::HeartbeatAll => {
                for worker in 0..8 {
                    let _ = self.s.heartbeat(now, w(&worker));
                }
            }
            Op::Request { worker } => {
                let _ = self.s.request_work(now, w(worker));
            }
            Op::Done {
                pick,
                own,
                worker,
                busy_ms,
                split,
            } => {
                let (worker, package) = self.pick(*pick, *own, *worker);
                let items = self
                    .latest
                    .get(&(worker, package))
                    .map_or(0, |a| a.items.len());
                let measure = PackageMeasure {
                    busy: Duration::from_millis(u64::from(*busy_ms)),
                    // Sometimes a usable split, sometimes a malformed one.
                    item_seconds: if *split {
                        vec![0.5; items]
                    } else {
                        vec![f64::NAN]
                    },
                    rays: 1,
                    bytes_in: 2,
                    bytes_out: 3,
                };
                if self.s.package_done(now, worker, package, measure).is_ok() {
                    let Some(a) = self.latest.get(&(worker, package)) else {
                        return Err(TestCaseError::fail(format!(
                            "accepted {package} from {worker}, never assigned to it"
                        )));
                    };
                    let done = self.completed.entry((a.job, a.frame)).or_default();
                    for item in &a.items {
                        let count = done.entry(*item).or_insert(0);
                        *count += 1;
                        prop_assert_eq!(*count, 1, "item {} completed twice", item);
                    }
                }
            }
            Op::Fail { pick, own, worker } => {
                let (worker, package) = self.pick(*pick, *own, *worker);
                let _ = self
                    .s
                    .package_failed(now, worker, package, "fuzz".to_string());
            }
            Op::Timeout { jump } => {
                let deadline = self.s.poll_timeout().filter(|_| *jump);
                let at = deadline.unwrap_or(now).max(now);
                self.now = at;
                self.s.handle_timeout(at);
            }
            Op::Advance { ms } => self.now += Duration::from_millis(u64::from(*ms)),
            Op::Submit {
                job,
                frames,
                items,
                priority,
            } => {
                let frame = FrameWork {
                    items: (0..u32::from(*items)).map(|i| i * 7 + 3).collect(),
                };
                let frames = vec![frame; usize::from(*frames)];
                let job = JobId(u64::from(*job));
                let options = QueueOptions {
                    priority: i32::from(*priority),
                    ..QueueOptions::default()
                };
                if self
                    .s
                    .submit_job_with(now, job, frames.clone(), options)
                    .is_ok()
                {
                    self.jobs.insert(job, frames);
                }
            }
            Op::Cancel { job } => {
                let _ = self.s.cancel_job(now, JobId(u64::from(*job)));
            }
            Op::Pause { job } => {
                let _ = self.s.pause_job(now, JobId(u64::from(*job)));
            }
            Op::Resume { job } => {
                let _ = self.s.resume_job(now, JobId(u64::from(*job)));
            }
            Op::Priority { job, priority } => {
                let job = JobId(u64::from(*job));
                let _ = self.s.set_priority(now, job, i32::from(*priority));
            }
            Op::BaseFrameCost { job, ms } => {
                let cost = Duration::from_millis(u64::from(*ms));
                let _ = self.s.base_frame_cost(now, JobId(u64::from(*job)), cost);
            }
            Op::BaseFrameAhead { job, frame } => {
                let job = JobId(u64::from(*job));
                let _ = self.s.base_frame_ahead(now, job, u32::from(*frame));
            }
        }
        self.drain()
    }

    fn drain(&mut self) -> Result<(), TestCaseError> {
        while let Some(a) = self.s.poll_assignment() {
            self.latest.insert((a.worker, a.package), a.clone());
            self.outstanding.push((a.worker, a.package));
            self.issued.push(a);
        }
        while let Some(event) = self.s.poll_event() {
            match event {
                Event::JobStarted { job, .. } => {
                    self.completed.retain(|(j, _), _| *j != job);
                }
                Event::FrameComplete { job, frame, stats } => {
                    let items = &self.jobs[&job][frame as usize].items;
                    let done = self.completed.remove(&(job, frame)).unwrap_or_default();
                    prop_assert_eq!(done.len(), items.len());
                    prop_assert!(items.iter().all(|i| done.get(i) == Some(&1)));
                    prop_assert_eq!(stats.items, items.len());
                    let by_workers: u32 = stats.workers.iter().map(|w| w.items).sum();
                    prop_assert_eq!(by_workers as usize, items.len());
                    prop_assert!(stats.imbalance() >= 0.0 && stats.speedup() >= 0.0);
                }
                Event::JobComplete { job }
                | Event::JobFailed { job, .. }
                | Event::JobCancelled { job } => {
                    self.jobs.remove(&job);
                }
                _ => {}
            }
        }
        if let Err(e) = self.s.validate() {
            return Err(TestCaseError::fail(e.to_string()));
        }
        Ok(())
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn random_inputs_never_panic_nor_complete_an_item_twice(
        ops in prop::collection::vec(op(), 0..300),
        heartbeat_s in 1u64..60,
        farm in any::<bool>(),
    ) {
        let config = SchedulerConfig {
            heartbeat_timeout: Duration::from_secs(heartbeat_s),
            ..SchedulerConfig::default()
        };
        // The master's rules too: lapsing requests and pipelined frames.
        let config = if farm { config.pipelined(common::FRAMES_IN_FLIGHT) } else { config };
        let mut model = Model {
            s: Scheduler::new(config),
            now: Duration::ZERO,
            issued: Vec::new(),
            outstanding: Vec::new(),
            latest: BTreeMap::new(),
            jobs: BTreeMap::new(),
            completed: BTreeMap::new(),
        };
        for op in &ops {
            model.apply(op)?;
            let _ = model.s.workers();
            let _ = model.s.queue();
        }
    }
}
