//! The master's scheduling rules: the scheduler's policy knobs, which a
//! master may set, over the farm's protocol rules, which it may not (its
//! workers set a frame up when its first package comes and keep
//! [`FRAMES_IN_FLIGHT`] frames prepared). [`FarmRules::default`] is exactly
//! what a master runs; nothing rewrites it on the way in.

use std::time::Duration;

use vtfarm_proto::{FRAMES_IN_FLIGHT, PEER_TIMEOUT};
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
        }
    }
}

impl FarmRules {
    /// The scheduler's configuration under these rules: [`FRAMES_IN_FLIGHT`]
    /// frames pipelined with frame affinity (a worker sets up only its
    /// crew's frames), and requests for work carry over a frame start.
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
        // Whole frames wait for the workers to render them end to end: the
        // core still rasterizes a base frame for every frame in flight.
        SchedulerConfig {
            whole_frames: false,
            ..pipelined
        }
    }
}
