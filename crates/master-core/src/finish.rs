//! A split frame's last step, off the driver's task: its image encoded for
//! the wire ([`FrameEncodeRequest`], `Output::EncodeFrame`, answered by
//! `MasterCore::frame_encoded`). Why: at 1080p the encoding costs the
//! master more than compositing the whole frame's results, and on the
//! driver it held every other input meanwhile (the next split frames'
//! results and packages), so a farm's split frames could finish no faster
//! than one encoding each. The core delivers a job's finished frames in
//! order ([`Finishing`]): one encoded early waits for the frames before it,
//! and the job's end waits for its last frame.

use std::collections::VecDeque;

use vtfarm_imaging::Image;
use vtfarm_proto::{FrameStats, WireFrameAux, WireImage, WireImageFormat};
use vtfarm_raster::IdBuffer;

use crate::core::Assembled;

/// A finished split frame to encode (CPU work, off the driver's task): what
/// [`FrameEncodeRequest::encode`] needs.
pub struct FrameEncodeRequest {
    pub job: u64,
    pub frame: u32,
    pub(crate) image: Assembled,
    pub(crate) format: WireImageFormat,
    /// Whether a submitter or the journal gets it (with the components a
    /// job asks for); else only the dashboard's list of finished frames
    /// (a view's frame, whose stages went to the view as they came).
    pub(crate) delivered: bool,
    /// The last frame's uncompressed bytes, this one's buffer.
    pub(crate) scratch: Vec<u8>,
}

impl std::fmt::Debug for FrameEncodeRequest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let color = self.image.color();
        write!(
            f,
            "FrameEncodeRequest(job {}, frame {}, {}x{} {:?})",
            self.job, self.frame, color.width, color.height, self.format
        )
    }
}

impl FrameEncodeRequest {
    /// Whether it goes only to the dashboard's list (a view's frame): the
    /// real driver encodes those on its task, so they never compete with
    /// the glare figures of the stage on view, asked for just before.
    pub fn for_dashboard_only(&self) -> bool {
        !self.delivered
    }

    /// The frame's image (and components) as the wire carries them; the
    /// frame's buffers come back with it for a later base frame.
    pub fn encode(self) -> EncodedFrame {
        let FrameEncodeRequest {
            job,
            frame,
            image,
            format,
            delivered,
            mut scratch,
        } = self;
        let wire = WireImage::encode_reusing(image.color(), format, &mut scratch);
        let aux = match &image {
            Assembled::Components(image) if delivered => Some(WireFrameAux::encode(image)),
            Assembled::Components(_) | Assembled::Color(_) => None,
        };
        EncodedFrame {
            job,
            frame,
            image: wire,
            aux,
            color: image.into_color(),
            scratch,
        }
    }
}

/// A frame [`FrameEncodeRequest::encode`] encoded, for
/// `MasterCore::frame_encoded`.
pub struct EncodedFrame {
    pub job: u64,
    pub frame: u32,
    pub(crate) image: WireImage,
    pub(crate) aux: Option<WireFrameAux>,
    /// The frame's colour buffer, for a later base frame.
    pub(crate) color: Image,
    pub(crate) scratch: Vec<u8>,
}

impl std::fmt::Debug for EncodedFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "EncodedFrame(job {}, frame {})", self.job, self.frame)
    }
}

/// A finished frame on its way out: its stats, its ID buffer (for a later
/// base frame) and, once encoded, its wire image.
pub(crate) struct FinishedFrame {
    pub(crate) frame: u32,
    pub(crate) stats: FrameStats,
    pub(crate) ids: Option<IdBuffer>,
    /// `None` while it is being encoded.
    pub(crate) encoded: Option<(WireImage, Option<WireFrameAux>)>,
    pub(crate) color: Option<Image>,
}

/// What a job has still to tell, in order: finished frames (each sent once
/// it and those before it are encoded) and, last, that it is complete.
pub(crate) enum Finishing {
    Frame(Box<FinishedFrame>),
    Complete,
}

/// A job's [`Finishing`] queue.
#[derive(Default)]
pub(crate) struct FinishQueue(VecDeque<Finishing>);

impl FinishQueue {
    pub(crate) fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    pub(crate) fn push(&mut self, item: Finishing) {
        self.0.push_back(item);
    }

    /// The highest frame waiting here.
    pub(crate) fn last_frame(&self) -> Option<u32> {
        (self.0.iter().rev()).find_map(|f| match f {
            Finishing::Frame(frame) => Some(frame.frame),
            Finishing::Complete => None,
        })
    }

    /// Records `encoded` with its frame: whether a frame waited for it
    /// (none does when its job ended meanwhile), and its uncompressed
    /// bytes' buffer back for the next frame.
    pub(crate) fn encoded(&mut self, encoded: EncodedFrame) -> (bool, Vec<u8>) {
        let waiting = self.0.iter_mut().find_map(|f| match f {
            Finishing::Frame(frame) if frame.frame == encoded.frame && frame.encoded.is_none() => {
                Some(frame)
            }
            _ => None,
        });
        match waiting {
            Some(frame) => {
                frame.encoded = Some((encoded.image, encoded.aux));
                frame.color = Some(encoded.color);
                (true, encoded.scratch)
            }
            None => (false, encoded.scratch),
        }
    }

    /// The next thing to tell, when it is ready (an encoded frame, or the
    /// job's end with every frame before it told).
    pub(crate) fn pop_ready(&mut self) -> Option<Finishing> {
        match self.0.front()? {
            Finishing::Frame(frame) if frame.encoded.is_none() => None,
            _ => self.0.pop_front(),
        }
    }
}
