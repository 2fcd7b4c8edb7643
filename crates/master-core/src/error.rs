//! Why the core turns a job or a result away. Each is told to a peer as
//! text (`JobFailed`, the package's failure): the types name the cases, the
//! messages stay the wire's.

use vtfarm_proto::WireError;
use vtfarm_scheduler::SubmitError;

use crate::stages::StageRejected;

/// Why a submitted (or journaled) job cannot be queued.
#[derive(Debug, thiserror::Error)]
pub enum JobRejected {
    #[error("bad scene: {0}")]
    BadScene(WireError),
    #[error("the job's scene is unknown")]
    UnknownScene,
    /// A reflector id out of range or listed twice.
    #[error("{0}")]
    BadReflectors(WireError),
    #[error("a job needs reflectors and at least one frame")]
    Empty,
    #[error("a job with components (aux) needs linear frames")]
    ComponentsNeedLinearFrames,
    #[error("bad frame set-up: {0}")]
    BadFrame(WireError),
    #[error("{0}")]
    Scheduler(#[from] SubmitError),
}

/// Why a package's result is refused (the package fails).
#[derive(Debug, thiserror::Error)]
pub enum ResultRejected {
    #[error("malformed result: {0}")]
    Malformed(#[from] WireError),
    /// Pixel ownership: the result writes a pixel the frame's ID buffer
    /// gives to a triangle outside its package.
    #[error("result writes pixel ({x}, {y}), which its package does not own")]
    ForeignPixel { x: u32, y: u32 },
    /// A whole frame's package must come back finished (the worker
    /// composites it), not as pixels for the master to composite.
    #[error("a package's pixels for a whole frame, which must come back finished")]
    PixelsForWholeFrame,
    /// Only a whole frame's package comes back finished.
    #[error("a finished frame for a package that is not a whole frame")]
    FinishedFrameForSplitPackage,
    /// A progressive frame's stage out of order (or a stage for a frame
    /// of one, or none for a progressive one).
    #[error(transparent)]
    Stage(#[from] StageRejected),
    /// A finished frame is not what the job asked for.
    #[error("finished frame's {what} is {found}, the job's is {expected}")]
    FinishedFrameMismatch {
        what: &'static str,
        found: String,
        expected: String,
    },
}
