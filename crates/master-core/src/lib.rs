//! The farm master's logic, free of I/O: connections, messages and the
//! driver's results in; messages, closes, journal records and base frames to
//! rasterize out ([`Output`]), around the pure `vtfarm-scheduler` state
//! machine. It reads no clock (every input carries `now`), opens no socket
//! or file and starts no thread; the server crate (`vtfarm-master`: driver,
//! QUIC server, HTTP, journal) runs it.
//!
//! - [`MasterCore`]: jobs, packages, compositing, status.
//! - [`FarmRules`]: the scheduling rules a master runs.
//! - [`JobRejected`], [`ResultRejected`]: why it turns a job or a result away.
//! - [`jobs`]: the jobs as users see them (states and their table,
//!   listing, retention of finished jobs).
//! - [`record`]: what the core asks the journal to keep and reads back.
//! - [`telemetry`]: the core's counters and kept frames, for the dashboard.
//! - [`FrameEncodeRequest`]: a finished split frame's encoding, off the
//!   driver's task (`finish.rs`), delivered in order.
//! - `ahead`: base frames made ahead of a batch job's tail, and the
//!   master's measured time per base frame, for the scheduler's tail rule.
//! - [`view`]: the interactive view (move the eye, progressive stages, glare);
//!   `stages`: a progressive frame's stages composited in place;
//!   [`stream`]: the stage messages the view streams to the page.

mod core;
mod error;
mod frames;
pub mod jobs;
mod output;
mod peers;
pub mod record;
mod recovery;
mod rules;
mod stages;
mod status;
pub mod stream;
pub mod telemetry;
#[cfg(test)]
mod testkit;
pub mod view;

pub use crate::core::{ATTACH_GRACE, MasterCore};
pub use error::{JobRejected, ResultRejected};
pub use frames::base::{BaseFrame, BaseFrameRequest};
pub use frames::finish::{EncodedFrame, FrameEncodeRequest};
pub use jobs::{JobControlError, JobEntry, JobState, JobTable, Retention};
pub use output::Output;
pub use peers::{ConnId, Peer};
pub use record::{DamagedJob, KEPT_FRAME_RETRY, Record, StoredJob, Written};
pub use rules::FarmRules;
pub use stages::StageRejected;
pub use status::LiveFrame;
