//! Shared helpers of the scheduler tests: the master's rules and seeded
//! draws.

// Each test binary uses only some of the helpers.
#![allow(dead_code)]

use rand::{Rng as _, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

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
