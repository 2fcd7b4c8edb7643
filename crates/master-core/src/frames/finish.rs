//! A split frame's last step, off the driver's task: its image encoded for
//! the wire ([`FrameEncodeRequest`], `Output::EncodeFrame`, answered by
//! `MasterCore::frame_encoded`). Why: at 1080p the encoding costs the
//! master more than compositing the whole frame's results, and on the
//! driver it would hold every other input meanwhile (the next split
//! frames' results and packages), so a farm's split frames could finish no
//! faster than one encoding each. The core delivers a job's finished frames in
//! order ([`Finishing`]): one encoded early waits for the frames before it,
//! and the job's end waits for its last frame.
//!
//! A job whose frames go out in 8-bit sRGB has its base frame converted
//! ahead, with its rasterizing ([`SrgbBytes`]); results write only
//! reflector pixels, so the encoding converts only the rectangle they
//! wrote (at 1080p the cockpit's glass is a fraction of the frame, and the
//! whole conversion was most of the encoding's parallel part).

use std::collections::VecDeque;
use vtfarm_proto::JobId;

use vtfarm_imaging::Image;
use vtfarm_proto::{FrameStats, WireFrameAux, WireImage, WireImageFormat};
use vtfarm_raster::IdBuffer;

use super::assembly::{Assembled, AssembledPixels};
use super::base::SrgbBytes;

/// A finished split frame to encode (CPU work, off the driver's task): what
/// [`FrameEncodeRequest::encode`] needs.
pub struct FrameEncodeRequest {
    pub job: JobId,
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
    pub job: JobId,
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

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use vtfarm_vertex::{PixelRect, SparseBitmap};

    use super::*;
    use crate::frames::assembly::ResultPixels;
    use crate::frames::base::BaseFrame;

    /// An image with a different colour in (nearly) every pixel, by `seed`.
    fn gradient(width: u32, height: u32, seed: f32) -> Image {
        let pixels = (0..width * height)
            .map(|i| {
                let (x, y) = ((i % width) as f32, (i / width) as f32);
                Vec3::new(x / width as f32, y / height as f32, seed) * (1.0 + seed)
            })
            .collect();
        Image {
            width,
            height,
            pixels,
        }
    }

    /// Pixels of `rect` a result writes: every other one, in `seed`'s colour.
    fn written_pixels(rect: PixelRect, seed: f32) -> Vec<(u32, u32, Vec3)> {
        (rect.pixels())
            .filter(|(x, y)| (x + y) % 2 == 0)
            .map(|(x, y)| (x, y, Vec3::new(seed, 1.0 - seed, 0.5 * seed)))
            .collect()
    }

    /// A result over `rect` in the form a frame of `components` composites.
    fn result(width: u32, rect: PixelRect, seed: f32, components: bool) -> ResultPixels {
        let written = written_pixels(rect, seed);
        if !components {
            let colors = (written.iter())
                .map(|&(x, y, c)| ((y * width + x) as usize, c))
                .collect();
            return ResultPixels::Colors {
                bounds: rect,
                colors,
            };
        }
        let mask = (rect.pixels()).map(|(x, y)| (x + y) % 2 == 0).collect();
        let n = written.len();
        ResultPixels::Bitmap(SparseBitmap {
            x0: rect.x0,
            y0: rect.y0,
            width: rect.x1 - rect.x0,
            height: rect.y1 - rect.y0,
            mask,
            color: written.iter().map(|&(_, _, c)| c).collect(),
            reflected: vec![Vec3::splat(0.1); n],
            transmitted: vec![Vec3::splat(0.2); n],
            reflected_object: vec![3; n],
        })
    }

    /// A frame whose base frame was converted to sRGB ahead, in a buffer
    /// that held another frame's bytes, encodes to exactly the bytes of
    /// its composited image converted whole: the written rectangle holds
    /// every composited pixel, and the base's conversion left nothing of
    /// the other frame. Colour-only frames and frames with components,
    /// results far apart and none.
    #[test]
    fn a_frame_converted_ahead_encodes_as_its_whole_conversion() {
        let (width, height) = (97, 61);
        let rect = |x0, y0, x1, y1| PixelRect { x0, y0, x1, y1 };
        let results = [
            rect(3, 4, 20, 9),
            rect(60, 40, 97, 61),
            rect(10, 50, 12, 52),
        ];
        for components in [false, true] {
            for count in 0..=results.len() {
                let mut srgb = SrgbBytes::default();
                // Another frame's bytes, larger: converted over.
                srgb.convert_base(&gradient(width + 5, height, 0.9));
                let image = gradient(width, height, 0.1);
                srgb.convert_base(&image);
                let ids = IdBuffer::new(width, height);
                let base = BaseFrame { image, ids, srgb };
                let bounds = components.then_some(rect(0, 0, width, height));
                let (mut assembled, _) = Assembled::new(base, bounds);
                for (k, &r) in results.iter().take(count).enumerate() {
                    assembled.composite(&result(width, r, 0.3 * k as f32, components));
                }
                let expected = WireImage::encode(assembled.color(), WireImageFormat::Srgb8);
                let request = FrameEncodeRequest {
                    job: JobId(1),
                    frame: 0,
                    image: assembled,
                    format: WireImageFormat::Srgb8,
                    delivered: true,
                    scratch: Vec::new(),
                };
                assert!(request.converts_written_pixels_only());
                let encoded = request.encode();
                assert!(
                    encoded.image == expected,
                    "components {components}, {count} results: other bytes"
                );
            }
        }
    }

    /// A job whose frames do not go out in sRGB has no bytes converted
    /// ahead: its frames are encoded whole, in its format.
    #[test]
    fn a_frame_not_converted_ahead_is_encoded_whole() {
        let (width, height) = (31, 17);
        let base = BaseFrame {
            image: gradient(width, height, 0.4),
            ids: IdBuffer::new(width, height),
            srgb: SrgbBytes::default(),
        };
        let (mut assembled, _) = Assembled::new(base, None);
        let written = PixelRect {
            x0: 2,
            y0: 3,
            x1: 9,
            y1: 8,
        };
        assembled.composite(&result(width, written, 0.7, false));
        for format in [WireImageFormat::Srgb8, WireImageFormat::LinearF32] {
            let pixels = AssembledPixels::Color(assembled.color().clone());
            let expected = WireImage::encode(pixels.color(), format);
            let request = FrameEncodeRequest {
                job: JobId(1),
                frame: 0,
                image: Assembled {
                    pixels,
                    written,
                    srgb: SrgbBytes::default(),
                },
                format,
                delivered: true,
                scratch: vec![0xab; 7],
            };
            assert!(!request.converts_written_pixels_only());
            assert!(request.encode().image == expected, "{format:?}");
        }
    }

    fn finished(frame: u32) -> Finishing {
        Finishing::Frame(Box::new(FinishedFrame {
            frame,
            stats: FrameStats::default(),
            ids: None,
            encoded: None,
            buffers: None,
        }))
    }

    fn encoded(frame: u32) -> EncodedFrame {
        EncodedFrame {
            job: JobId(1),
            frame,
            image: WireImage::encode(&Image::black(1, 1), WireImageFormat::Srgb8),
            aux: None,
            buffers: (Image::black(1, 1), SrgbBytes::default()),
            scratch: vec![7; 3],
        }
    }

    fn told(queue: &mut FinishQueue) -> Vec<Option<u32>> {
        std::iter::from_fn(|| queue.pop_ready())
            .map(|f| match f {
                Finishing::Frame(frame) => Some(frame.frame),
                Finishing::Complete => None,
            })
            .collect()
    }

    /// A frame encoded early waits for the frames before it, and the
    /// job's end for its last frame.
    #[test]
    fn finished_frames_are_told_in_order_and_the_end_after_them() {
        let mut queue = FinishQueue::default();
        for frame in [4, 5] {
            queue.push(finished(frame));
        }
        queue.push(Finishing::Complete);
        assert_eq!(queue.last_frame(), Some(5));
        assert_eq!(queue.encoded(encoded(5)), (true, vec![7; 3]));
        assert!(told(&mut queue).is_empty(), "frame 4 is not encoded yet");
        assert!(queue.encoded(encoded(4)).0);
        assert_eq!(told(&mut queue), vec![Some(4), Some(5), None]);
        assert!(queue.is_empty());
    }

    /// A frame whose job ended meanwhile waits nowhere: its buffer comes
    /// back all the same.
    #[test]
    fn a_frame_encoded_for_nobody_is_not_taken() {
        let mut queue = FinishQueue::default();
        queue.push(finished(1));
        assert_eq!(queue.encoded(encoded(2)), (false, vec![7; 3]));
        assert!(queue.encoded(encoded(1)).0);
        assert!(!queue.encoded(encoded(1)).0, "encoded once");
    }
}
