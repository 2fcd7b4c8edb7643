//! The farm master's logic, free of I/O: connections, messages and the
//! driver's results in; messages, closes, journal records and base frames to
//! rasterize out ([`Output`]), around the pure `vtfarm-scheduler` state
//! machine. It reads no clock (every input carries `now`), opens no socket
//! or file and starts no thread; the server crate (`vtfarm-master`: driver,
//! QUIC server, HTTP, journal) runs it.
//!
//! - [`MasterCore`]: owns the parts below and routes each input to them
//!   (`core/`: one method per input and per scheduler event), and the pump.
//! - `peers`: connections and peers ([`ConnId`], [`Peer`]): names, the
//!   frames each worker keeps.
//! - `frames`: frame assembly and compositing: jobs being rendered,
//!   packages in flight, base frames (made ahead of a batch job's tail),
//!   finished frames encoded off the driver's task ([`FrameEncodeRequest`])
//!   and delivered in order.
//! - `recovery`: the journal's side: frames kept until written, repairs of
//!   frames the journal cannot give back, damaged jobs.
//! - `status`: the farm's status and the live frame ([`LiveFrame`]).
//! - [`FarmRules`]: the scheduling rules a master runs.
//! - [`JobRejected`], [`ResultRejected`]: why it turns a job or a result away.
//! - [`jobs`]: the jobs as users see them (states and their table,
//!   studies over their variants, listing, retention of finished jobs).
//! - [`record`]: what the core asks the journal to keep and reads back.
//! - [`telemetry`]: the core's counters and kept frames, for the dashboard.
//! - [`view`]: the interactive view (move the eye, progressive stages, glare);
//!   `stages`: a progressive frame's stages composited in place;
//!   [`stream`]: the stage messages the view streams to the page.
//!
//! Parts import only lower parts, never `core`; none derives serde (the
//! server maps them at its boundary).

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
