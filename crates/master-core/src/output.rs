//! What the master core asks its driver to do ([`Output`]).

use vtfarm_proto::JobId;
use vtfarm_proto::Message;

use crate::frames::base::BaseFrameRequest;
use crate::frames::finish::FrameEncodeRequest;
use crate::peers::ConnId;
use crate::record::Record;
use crate::view::GlareRequest;

/// What the core asks the driver to do.
#[derive(Debug)]
pub enum Output {
    Send(ConnId, Box<Message>),
    /// Drop the connection, logging why.
    Close(ConnId, String),
    /// Keep this in the job journal (only when the core is persistent).
    Persist(Record),
    /// Send `conn` the journal's `FrameDone`s of `job`, frames `frames`, in
    /// order, before anything that follows; a frame the journal cannot give
    /// back goes to `MasterCore::replay_failed` (rendered again).
    Replay {
        conn: ConnId,
        job: JobId,
        frames: std::ops::Range<u32>,
    },
    /// Rasterize a base frame (CPU work, off the driver's task) and hand it
    /// to `MasterCore::base_frame_ready`.
    RasterizeBase(BaseFrameRequest),
    /// Compute the glare figures of the view's stage just put on view (CPU
    /// work, off the driver's task, after the stage is shown; a driver may
    /// drop a request a newer one replaced before it started) and hand them
    /// to `MasterCore::view_figures_ready`.
    ViewGlare(GlareRequest),
    /// Encode a finished split frame for the wire (CPU work, off the
    /// driver's task: `finish.rs` says why) and hand it to
    /// `MasterCore::frame_encoded`.
    EncodeFrame(FrameEncodeRequest),
}
