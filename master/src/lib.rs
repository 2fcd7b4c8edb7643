//! The farm master: accepts workers and submitted jobs, runs jobs from a
//! queue frame by frame, hands out packages on demand through the pure
//! `vtfarm-scheduler` state machine, and composites the returned bitmaps
//! over the base frame it rasterized.
//!
//! The logic, without sockets or clock, is `vtfarm-master-core`
//! ([`MasterCore`]); this crate runs it:
//!
//! - [`driver`]: the async task around the core; links in, messages out.
//! - [`server`]: the QUIC endpoint and handshake.
//! - [`journal`]: the job journal in the state directory (restarts, re-attaching).
//! - [`http`]: the dashboard, status API and Prometheus metrics; reads the
//!   core's state through the driver, owns none.
//! - [`timeline`]: a frame's phases as SVG (beside `vtfarm submit`'s frames, in the dashboard).
//! - `view_http`: the view's scene (GLB), stage stream and page modules, merged into `http`.
//!
//! The submitter's side of the protocol is `vtfarm-submit`; the master
//! with local workers in one process (`vtfarm render`) is `vtfarm-embedded`.

#[cfg(feature = "cli")]
pub mod cli;
pub mod driver;
pub mod http;
pub mod journal;
pub mod server;
pub mod timeline;
mod view_http;

pub use driver::{MasterHandle, spawn_master, spawn_persistent_master};
pub use journal::{Journal, JournalWriter};
pub use view_http::view_reaches;
pub use vtfarm_master_core::{
    ATTACH_GRACE, BaseFrameRequest, ConnId, EncodedFrame, FarmRules, FrameEncodeRequest,
    MasterCore, Output, Peer, Record, StoredJob, stream, telemetry, view,
};
/// The job message, for the core's users (tests, the farm simulator).
pub use vtfarm_proto::{JobOptions, wire_job};
