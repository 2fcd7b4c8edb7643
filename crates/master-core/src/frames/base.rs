//! A split frame's base frame: what the driver rasterizes off its task
//! ([`BaseFrameRequest`]) and the buffers kept from finished frames for
//! later base frames ([`Spares`]).

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use vtfarm_proto::JobId;

use vtfarm_imaging::Image;
use vtfarm_proto::{WireImage, WireImageFormat};
use vtfarm_raster::IdBuffer;
use vtfarm_render::{BaseExtent, FrameSetup};
use vtfarm_scene::Scene;
use vtfarm_vertex::PixelRect;

/// A base frame to rasterize: what [`BaseFrameRequest::rasterize`] needs.
#[derive(Clone, Debug)]
pub struct BaseFrameRequest {
    pub job: JobId,
    pub frame: u32,
    pub(super) scene: Arc<Scene>,
    /// Per scene triangle, whether it is one of the job's reflectors (glass
    /// that is none is blended over what lies behind it).
    pub(super) is_reflector: Arc<[bool]>,
    /// The job's: whether its glass that is no reflector was warned about.
    pub(super) warned_glass: Arc<AtomicBool>,
    pub(super) setup: FrameSetup,
    /// Also convert it to 8-bit sRGB: the job's frames go out so
    /// (`finish.rs`). A view's job does not: its frames go only to the
    /// dashboard's list, off the view's latency, which its base frame is on.
    pub(super) srgb: bool,
    /// The whole frame, or (a view whose page draws the scene) only what
    /// its packages look at.
    pub(super) extent: BaseExtent,
    /// A finished frame's buffers to rasterize into.
    pub(super) spare: Option<Box<BaseFrame>>,
}

impl BaseFrameRequest {
    /// The shaded base frame and its ID buffer (and its sRGB bytes where
    /// the job's frames go out in sRGB), in a finished frame's buffers
    /// where the master has some (`vtfarm_render::base_frame_into`).
    pub fn rasterize(self) -> BaseFrame {
        let BaseFrame {
            mut image,
            mut ids,
            mut srgb,
        } = self.spare.map_or_else(BaseFrame::empty, |spare| *spare);
        vtfarm_render::base_frame_into(
            &self.scene,
            &self.setup,
            &self.is_reflector,
            self.extent,
            (&mut image, &mut ids),
            &self.warned_glass,
        );
        if self.srgb {
            srgb.convert_base(&image);
        } else {
            // Not held unused with a base frame made ahead.
            srgb = SrgbBytes::default();
        }
        BaseFrame { image, ids, srgb }
    }

    /// Whether it rasterizes into a finished frame's buffers.
    pub fn reuses_buffers(&self) -> bool {
        self.spare.is_some()
    }

    /// Whether it also converts the base frame to sRGB (all of it).
    pub fn converts_to_srgb(&self) -> bool {
        self.srgb
    }
}

/// A split frame's base frame ([`BaseFrameRequest::rasterize`]): the shaded
/// image, its ID buffer and its sRGB bytes (converted where the job's
/// frames go out in sRGB). A finished frame's buffers are kept for a later
/// frame's base frame: rasterizing and converting into them spares the
/// page faults of fresh buffers (at 1080p as much CPU as the work itself).
#[derive(Clone)]
pub struct BaseFrame {
    pub(crate) image: Image,
    pub(crate) ids: IdBuffer,
    pub(crate) srgb: SrgbBytes,
}

impl BaseFrame {
    pub(super) fn empty() -> BaseFrame {
        BaseFrame {
            image: Image::black(0, 0),
            ids: IdBuffer::new(0, 0),
            srgb: SrgbBytes::default(),
        }
    }
}

impl std::fmt::Debug for BaseFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (width, height) = (self.image.width, self.image.height);
        let srgb = self.srgb.of_base();
        write!(f, "BaseFrame({width}x{height}, sRGB converted: {srgb})")
    }
}

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
    pub(super) fn encode_written(&mut self, image: &Image, written: PixelRect) -> WireImage {
        assert!(self.of_base, "the base frame's bytes were converted ahead");
        self.of_base = false;
        let written = written.clamped(image.width, image.height);
        let (columns, rows) = (written.x0..written.x1, written.y0..written.y1);
        image.to_srgb8_region_into(&mut self.buffer, columns, rows);
        let format = WireImageFormat::Srgb8;
        WireImage::from_uncompressed(image.width, image.height, format, &self.buffer)
    }
}

/// Spare base-frame buffers kept: two (a 1080p image, ID buffer and sRGB
/// bytes are about 56 MB); base frames beyond them rasterize into fresh
/// buffers.
const SPARE_BASES: usize = 2;

/// Finished frames' buffers kept for the next base frames (at most
/// [`SPARE_BASES`]).
#[derive(Default)]
pub(crate) struct Spares(Vec<BaseFrame>);

impl Spares {
    /// Keeps a base frame's buffers (or a finished frame's) for a later
    /// base frame; beyond [`SPARE_BASES`] they go.
    pub(crate) fn keep(&mut self, base: BaseFrame) {
        if self.0.len() < SPARE_BASES {
            self.0.push(base);
        }
    }

    /// Buffers for the next base frame, if any are kept.
    pub(crate) fn take(&mut self) -> Option<BaseFrame> {
        self.0.pop()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base(width: u32) -> BaseFrame {
        BaseFrame {
            image: Image::black(width, 1),
            ids: IdBuffer::new(width, 1),
            srgb: SrgbBytes::default(),
        }
    }

    /// Two spare buffers are kept, the newest given out first; more go.
    #[test]
    fn at_most_two_spare_base_frames_are_kept_newest_first() {
        let mut spares = Spares::default();
        for width in 1..=3 {
            spares.keep(base(width));
        }
        assert_eq!(spares.take().map(|b| b.image.width), Some(2));
        assert_eq!(spares.take().map(|b| b.image.width), Some(1));
        assert!(spares.take().is_none());
    }
}
