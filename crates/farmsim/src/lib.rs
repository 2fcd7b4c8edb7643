//! The farm simulator: one discrete-event driver ([`Farm`]) over the real
//! master core ([`vtfarm_master_core::MasterCore`]) and worker sessions
//! ([`vtfarm_worker::WorkerSession`]) on a virtual clock. Every decision —
//! which frame starts when, package sizes, held results, stragglers,
//! requeues — is made by the same code as in the real farm; only the work
//! and the wires are replaced by models. Two cost models plug in:
//! - [`rendered`]: the test harness ([`TestFarm`]). Workers render for real
//!   and only traced samples take time; fault knobs (kills, partitions,
//!   duplicated results, draining, master restarts on a journal, submitter
//!   loss and re-attach). The master's integration tests run on it.
//! - [`recorded`]: `vtfarm bench simulate`. Costs recorded from a real frame,
//!   modelled CPUs and links; [`simulate_farm`] measures each frame.
//!
//! The model, one for both:
//! - **CPU.** Each machine has cores shared fairly by its running jobs (a
//!   job runs on its threads at most): a worker with one core that sets a
//!   frame up while it traces a package runs both at half speed, as the real
//!   worker does; a package cancelled while it runs stops at once. The master has its own machine: its base frame is spread
//!   over its cores, and its driver handles one input at a time, each
//!   costing CPU ([`MasterCosts`]); inputs queue meanwhile. Its journal
//!   thread and the submitter each take finished frames one at a time. A finished split
//!   frame's encoding runs beside the driver, on the master's cores. With
//!   [`FarmConfig::shared_cores`] everything runs on one machine (a
//!   localhost farm), and [`FarmConfig::background_threads`] stand for
//!   other work there.
//! - **Links.** Each worker's link and the master's one shared link, each a
//!   rate plus a latency. A message holds *both* links for its size over
//!   the slower rate (QUIC streams pass packets on as they arrive, so a
//!   message is not sent over one link and then forwarded over the other),
//!   one message at a time per direction, and arrives a latency after its
//!   last byte left. An infinite rate leaves the latency alone; an unlimited
//!   master link is held by no message. The submitter sits on the master's
//!   machine: its messages cost no link.
//! - **Clock.** The driver jumps to the next event, deadline or finished CPU
//!   job; nothing sleeps or reads a clock, so a run replays exactly.

pub mod farm;
pub mod recorded;
pub mod rendered;

use std::time::Duration;

pub use farm::{
    CostModel, Delivery, Farm, FarmConfig, JobJournal, MasterCosts, PackageRun, PackageWork,
    SimWorker, WorkerSpec, stand_in_result,
};
pub use recorded::{
    FarmCosts, FarmFrame, FarmJob, SimulationConfig, background_threads_for, cpu_per_frame,
    simulate_farm, steady_background_cores, steady_frame_seconds,
};
pub use rendered::{Rendered, SAMPLE_COST, StageRun, TEST_LATENCY, TestFarm};

/// Why a recorded simulation gave no figures.
#[derive(Debug, thiserror::Error)]
pub enum SimulationError {
    #[error(
        "the simulated farm delivered {delivered} of {frames} frames by {at:?} of virtual time"
    )]
    Unfinished {
        delivered: usize,
        frames: usize,
        at: Duration,
    },
    #[error("no number of other threads uses {cores} cores beside the farm")]
    NoBackground { cores: f64 },
}
