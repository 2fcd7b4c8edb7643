//! Shared helpers of the scheduler tests: seeded workloads and checks on
//! simulation reports.

// Each test binary uses only some of the helpers.
#![allow(dead_code)]

pub(crate) mod sim;

use std::collections::BTreeMap;

use rand::{Rng as _, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use sim::{SimFrame, SimJob, SimReport};
use vtfarm_scheduler::{Event, JobId, WorkerId};

/// Frames in flight of the pipelined configurations these tests run
/// (`SchedulerConfig::pipelined`); vtfarm's master runs the protocol's
/// `vtfarm_proto::FRAMES_IN_FLIGHT`, of which this crate knows nothing.
pub(crate) const FRAMES_IN_FLIGHT: u32 = 8;

/// The master's rules with every frame split into packages (no whole
/// frames), for the tests of how split frames are shared.
pub(crate) fn split_pipelined() -> vtfarm_scheduler::SchedulerConfig {
    vtfarm_scheduler::SchedulerConfig {
        whole_frames: false,
        ..vtfarm_scheduler::SchedulerConfig::default().pipelined(FRAMES_IN_FLIGHT)
    }
}

/// Seeded workloads from the workspace's one test generator
/// (`rand_xoshiro`), so they are the same on every run.
pub(crate) struct Rng(Xoshiro256PlusPlus);

impl Rng {
    pub(crate) fn new(seed: u64) -> Rng {
        Rng(Xoshiro256PlusPlus::seed_from_u64(seed))
    }

    /// Uniform in [0, 1).
    pub(crate) fn unit(&mut self) -> f64 {
        self.0.random()
    }
}

/// A frame of `n` items (ids 1000..) whose true costs (seconds at speed 1)
/// vary between `base` and `3·base`, plus a hot spot: the items in
/// `hot` (a range of positions) cost `hot_factor` times more.
pub(crate) fn uneven_frame(
    n: usize,
    seed: u64,
    base: f64,
    hot: std::ops::Range<usize>,
    hot_factor: f64,
) -> SimFrame {
    let mut rng = Rng::new(seed);
    let items: Vec<u32> = (0..n as u32).map(|i| 1000 + i).collect();
    let costs = (0..n)
        .map(|i| {
            let c = base * (1.0 + 2.0 * rng.unit());
            if hot.contains(&i) { c * hot_factor } else { c }
        })
        .collect();
    SimFrame { items, costs }
}

/// A job of `frames` copies of one frame (the same items and true costs
/// every frame, as for a still camera).
pub(crate) fn repeated_job(id: u64, frame: &SimFrame, frames: usize) -> SimJob {
    SimJob {
        id: JobId(id),
        submit_at: std::time::Duration::ZERO,
        frames: vec![frame.clone(); frames],
    }
}

/// Every completed frame covered each of its items exactly once, and no
/// invariant broke.
pub(crate) fn assert_exactly_once(report: &SimReport, jobs: &[SimJob]) {
    assert!(report.violations.is_empty(), "{:?}", report.violations);
    for frame in &report.frames {
        let job = jobs
            .iter()
            .find(|j| j.id == frame.job)
            .expect("job of frame");
        let items = &job.frames[frame.frame as usize].items;
        let expected: BTreeMap<u32, u32> = items.iter().map(|&i| (i, 1)).collect();
        assert_eq!(
            frame.completions, expected,
            "{} frame {}",
            frame.job, frame.frame
        );
    }
}

/// Each worker's share of the frame's true cost.
pub(crate) fn shares(frame: &sim::SimFrameReport) -> BTreeMap<WorkerId, f64> {
    let total: f64 = frame.true_cost.values().sum();
    frame
        .true_cost
        .iter()
        .map(|(&w, &c)| (w, c / total))
        .collect()
}

/// The events of a report without their times, for matching.
pub(crate) fn events(report: &SimReport) -> Vec<&Event> {
    report.events.iter().map(|(_, e)| e).collect()
}
