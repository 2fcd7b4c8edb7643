//! The master's scheduling rules: the scheduler's policy knobs, which a
//! master may set, over the farm's protocol rules, which it may not (its
//! workers set a frame up when its first package comes and keep
//! [`FRAMES_IN_FLIGHT`] frames prepared). [`FarmRules::default`] is exactly
//! what a master runs; nothing rewrites it on the way in.

use std::time::Duration;

use vtfarm_proto::{FRAMES_IN_FLIGHT, PEER_TIMEOUT};

use crate::jobs::Retention;
use vtfarm_scheduler::{
    CostEstimation, PackageSizing, RetryPolicy, SchedulerConfig, StragglerPolicy,
};

/// What a master may choose about scheduling; each field means what the
/// field of the same name in [`SchedulerConfig`] means, with its default.
#[derive(Clone, Debug, PartialEq)]
pub struct FarmRules {
    /// A worker silent this long is lost and its packages are requeued.
    pub heartbeat_timeout: Duration,
    pub sizing: PackageSizing,
    /// `None`: no straggler copies near the end of a frame.
    pub straggler: Option<StragglerPolicy>,
    pub retry: RetryPolicy,
    pub estimation: CostEstimation,
    /// Whole frames for batch work (`SchedulerConfig::whole_frames`; the
    /// worker renders a whole frame end to end); `false` splits every
    /// frame into packages.
    pub whole_frames: bool,
    /// How many finished jobs stay listed, and for how long (not a
    /// scheduler knob: the master core's).
    pub retention: Retention,
}

impl Default for FarmRules {
    /// The scheduler's defaults, with [`PEER_TIMEOUT`] for the heartbeat
    /// timeout (QUIC's idle timeout is the same).
    fn default() -> Self {
        let SchedulerConfig {
            sizing,
            straggler,
            retry,
            estimation,
            ..
        } = SchedulerConfig::default();
        FarmRules {
            heartbeat_timeout: PEER_TIMEOUT,
            sizing,
            straggler,
            retry,
            estimation,
            whole_frames: true,
            retention: Retention::DEFAULT,
        }
    }
}

impl FarmRules {
    /// The scheduler's configuration under these rules: [`FRAMES_IN_FLIGHT`]
    /// split frames pipelined with frame affinity (a worker sets up only
    /// its crew's frames), whole frames for batch work (the worker renders
    /// them end to end), and requests for work carry over a frame start.
    pub fn scheduler_config(&self) -> SchedulerConfig {
        let pipelined = SchedulerConfig {
            heartbeat_timeout: self.heartbeat_timeout,
            sizing: self.sizing.clone(),
            straggler: self.straggler.clone(),
            retry: self.retry.clone(),
            estimation: self.estimation.clone(),
            ..SchedulerConfig::default()
        }
        .pipelined(FRAMES_IN_FLIGHT as u32);
        SchedulerConfig {
            whole_frames: self.whole_frames,
            ..pipelined
        }
    }
}
