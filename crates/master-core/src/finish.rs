//! A split frame's last step, off the driver's task: its image encoded for
//! the wire ([`FrameEncodeRequest`], `Output::EncodeFrame`, answered by
//! `MasterCore::frame_encoded`). Why: at 1080p the encoding costs the
//! master more than compositing the whole frame's results, and on the
//! driver it held every other input meanwhile (the next split frames'
//! results and packages), so a farm's split frames could finish no faster
//! than one encoding each. The core delivers a job's finished frames in
//! order ([`Finishing`]): one encoded early waits for the frames before it,
//! and the job's end waits for its last frame.
//!
//! A job whose frames go out in 8-bit sRGB has its base frame converted
//! ahead, with its rasterizing ([`SrgbBytes`]); results write only
//! reflector pixels, so the encoding converts only the rectangle they
//! wrote (at 1080p the cockpit's glass is a fraction of the frame, and the
//! whole conversion was most of the encoding's parallel part).

use std::collections::VecDeque;

use vtfarm_imaging::Image;
use vtfarm_proto::{FrameStats, WireFrameAux, WireImage, WireImageFormat};
use vtfarm_raster::IdBuffer;
use vtfarm_vertex::PixelRect;

use crate::core::{Assembled, AssembledPixels};

/// A base frame's 8-bit sRGB bytes (RGB interleaved, as
/// [`Image::to_srgb8`]), converted with the base frame when its job's
/// frames go out in sRGB, off the path from a split frame's last result to
/// its delivery. The buffer goes from frame to frame with the base frame's
/// image (a fresh one's page faults cost as much as filling it).
#[derive(Clone, Default)]
pub(crate) struct SrgbBytes {
    buffer: Vec<u8>,
    /// Whether `buffer` holds the base frame's bytes (else whatever an
    /// earlier frame left there).
    of_base: bool,
}

impl SrgbBytes {
    /// Converts the base frame `base` into the buffer, all of it
    /// (whatever the buffer held).
    pub(crate) fn convert_base(&mut self, base: &Image) {
        base.to_srgb8_into(&mut self.buffer);
        self.of_base = true;
    }

    /// Whether the buffer holds the base frame's bytes.
    pub(crate) fn of_base(&self) -> bool {
        self.of_base
    }

    /// The wire image of `image`, the base frame these bytes hold with
    /// results written over it within `written` only: that rectangle
    /// converted into the base's bytes, then compressed as
    /// [`WireImage::encode`] compresses: exactly its bytes, per pixel.
    /// The buffer holds `image`'s bytes after, no longer the base's.
    ///
    /// # Panics
    /// If the buffer does not hold a base frame of `image`'s size.
    fn encode_written(&mut self, image: &Image, written: PixelRect) -> WireImage {
        assert!(self.of_base, "the base frame's bytes were converted ahead");
        self.of_base = false;
        let written = written.clamped(image.width, image.height);
        let (columns, rows) = (written.x0..written.x1, written.y0..written.y1);
        image.to_srgb8_region_into(&mut self.buffer, columns, rows);
        let format = WireImageFormat::Srgb8;
        WireImage::from_uncompressed(image.width, image.height, format, &self.buffer)
    }
}

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
    /// The last frame's uncompressed bytes, this one's buffer where its
    /// base frame's sRGB bytes were not converted ahead.
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

    /// Whether its base frame's sRGB bytes were converted ahead: only the
    /// pixels results wrote are converted here.
    pub fn converts_written_pixels_only(&self) -> bool {
        self.format == WireImageFormat::Srgb8 && self.image.srgb.of_base()
    }

    /// The frame's image (and components) as the wire carries them; the
    /// frame's buffers come back with it for a later base frame.
    pub fn encode(self) -> EncodedFrame {
        let written_only = self.converts_written_pixels_only();
        let FrameEncodeRequest {
            job,
            frame,
            image,
            format,
            delivered,
            mut scratch,
        } = self;
        let Assembled {
            pixels,
            written,
            mut srgb,
        } = image;
        let color = pixels.color();
        let wire = if written_only {
            srgb.encode_written(color, written)
        } else {
            WireImage::encode_reusing(color, format, &mut scratch)
        };
        let aux = match &pixels {
            AssembledPixels::Components(image) if delivered => Some(WireFrameAux::encode(image)),
            AssembledPixels::Components(_) | AssembledPixels::Color(_) => None,
        };
        EncodedFrame {
            job,
            frame,
            image: wire,
            aux,
            buffers: (pixels.into_color(), srgb),
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
    /// The frame's colour buffer and sRGB bytes, for a later base frame.
    pub(crate) buffers: (Image, SrgbBytes),
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
    /// Its colour buffer and sRGB bytes, once encoded.
    pub(crate) buffers: Option<(Image, SrgbBytes)>,
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
                frame.buffers = Some(encoded.buffers);
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
