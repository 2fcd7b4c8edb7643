//! A frame as it is assembled: results checked for pixel ownership and
//! composited over its base frame, its timeline and totals.

use std::time::Duration;

use glam::Vec3;
use vtfarm_imaging::Image;
use vtfarm_proto::{
    FramePhase, FrameStart, PackageResult, PhaseKind, WireBitmap, WireFrameAux, WireImage,
};
use vtfarm_raster::IdBuffer;
use vtfarm_scene::TriangleId;
use vtfarm_vertex::{FrameImage, PackageStats, PixelRect, SparseBitmap};

use super::base::{BaseFrame, SrgbBytes};
use crate::error::ResultRejected;
use crate::peers::ConnId;
use crate::stages::StageProgress;

/// The frame being assembled (its index is `start.frame`).
pub(crate) struct FrameAssembly {
    pub(crate) start: FrameStart,
    /// A whole frame: its worker finishes it, the core forwards `finished`.
    pub(crate) whole: bool,
    /// A whole frame's image and components as its worker sent them.
    pub(crate) finished: Option<(WireImage, Option<WireFrameAux>)>,
    /// The frame's ID buffer: which reflector triangle owns each pixel;
    /// `None` until the base frame is rasterized.
    pub(crate) ids: Option<IdBuffer>,
    /// Empty until the base frame is rasterized.
    pub(crate) image: Assembled,
    /// Results that came before the ID buffer, to check once it is there:
    /// (connection, result, its wire size).
    pub(crate) held: Vec<(ConnId, PackageResult, u64)>,
    /// When the frame started (master time) and where its time went.
    pub(crate) started: Duration,
    pub(crate) phases: Vec<FramePhase>,
    pub(crate) totals: PackageStats,
    pub(crate) triangles_done: u64,
    /// A progressive frame's stages as they come in (`stages.rs`).
    pub(crate) progress: Option<StageProgress<ResultPixels>>,
}

impl FrameAssembly {
    /// Frame `start` starting at `now`, awaiting its base frame (a split
    /// frame) or its worker's finished image (a whole one).
    pub(crate) fn new(
        start: FrameStart,
        whole: bool,
        now: Duration,
        progress: Option<StageProgress<ResultPixels>>,
    ) -> FrameAssembly {
        FrameAssembly {
            start,
            whole,
            finished: None,
            ids: None,
            // The base frame, when it comes; until then results are held.
            image: Assembled::awaiting_base(),
            held: Vec::new(),
            started: now,
            phases: Vec::new(),
            totals: PackageStats::default(),
            triangles_done: 0,
            progress,
        }
    }

    /// The base frame is here at `now`: the frame starts from `image`, its
    /// pixels owned as `ids` says.
    pub(crate) fn based(&mut self, image: Assembled, ids: IdBuffer, now: Duration) {
        self.image = image;
        self.ids = Some(ids);
        let base = phase(
            self.started,
            "master".into(),
            PhaseKind::Base,
            self.started,
            now,
        );
        self.phases.push(base);
    }

    /// A result from the worker named `name`, its package handed out (or
    /// its last stage in) at `assigned_at`, arrived at `now`: on the
    /// timeline the set-up first (it starts when the package arrives),
    /// then the computing; what the worker's times leave of the interval
    /// is the way there and back.
    pub(crate) fn record_package(
        &mut self,
        name: String,
        assigned_at: Duration,
        now: Duration,
        result: &PackageResult,
    ) {
        let set_up = (assigned_at + Duration::from_micros(result.setup_micros)).min(now);
        let computed = now
            .saturating_sub(Duration::from_micros(result.busy_micros))
            .max(set_up);
        let t0 = self.started;
        if set_up > assigned_at {
            let setup = phase(t0, name.clone(), PhaseKind::Setup, assigned_at, set_up);
            self.phases.push(setup);
        }
        self.phases.extend([
            phase(t0, name.clone(), PhaseKind::Sending, set_up, computed),
            phase(t0, name, PhaseKind::Package, computed, now),
        ]);
    }
}

/// A frame as results are composited over its base frame: its pixels, the
/// rectangle results wrote, and the base frame's sRGB bytes (the encoding
/// converts only that rectangle into them, `finish.rs`).
pub(crate) struct Assembled {
    pub(crate) pixels: AssembledPixels,
    /// The union of the composited results' rectangles: every pixel
    /// written over the base frame lies inside.
    pub(crate) written: PixelRect,
    pub(crate) srgb: SrgbBytes,
}

/// A frame's pixels: the colour only, or with the per-pixel components
/// when the job asks for them (a view's jobs always do). No output of a
/// colour-only job reads the components, so their planes are not made.
pub(crate) enum AssembledPixels {
    Color(Image),
    Components(FrameImage),
}

impl AssembledPixels {
    pub(crate) fn color(&self) -> &Image {
        match self {
            AssembledPixels::Color(color) => color,
            AssembledPixels::Components(image) => &image.color,
        }
    }

    /// The colour buffer alone.
    pub(crate) fn into_color(self) -> Image {
        match self {
            AssembledPixels::Color(color) => color,
            AssembledPixels::Components(image) => image.color,
        }
    }
}

impl Assembled {
    /// Starts from the base frame, with components over `components` (the
    /// reflectors' rectangle) when the job asks for them.
    pub(crate) fn new(base: BaseFrame, components: Option<PixelRect>) -> (Assembled, IdBuffer) {
        let BaseFrame { image, ids, srgb } = base;
        let pixels = match components {
            Some(bounds) => AssembledPixels::Components(FrameImage::new(image, bounds)),
            None => AssembledPixels::Color(image),
        };
        let assembled = Assembled {
            pixels,
            written: PixelRect::EMPTY,
            srgb,
        };
        (assembled, ids)
    }

    /// Nothing yet: the base frame is on its way.
    pub(crate) fn awaiting_base() -> Assembled {
        Assembled {
            pixels: AssembledPixels::Color(Image::black(0, 0)),
            written: PixelRect::EMPTY,
            srgb: SrgbBytes::default(),
        }
    }

    pub(crate) fn color(&self) -> &Image {
        self.pixels.color()
    }

    /// The frame with its components, when the job asks for them.
    pub(crate) fn components(&self) -> Option<&FrameImage> {
        match &self.pixels {
            AssembledPixels::Components(image) => Some(image),
            AssembledPixels::Color(_) => None,
        }
    }

    /// Decodes a result into what this frame composites (the colours
    /// straight from the wire when that is all it keeps) and checks pixel
    /// ownership: every pixel it writes must be one that `ids` gives to a
    /// triangle `owned` accepts.
    pub(crate) fn check(
        &self,
        bitmap: WireBitmap,
        ids: &IdBuffer,
        owned: impl Fn(TriangleId) -> bool,
    ) -> Result<ResultPixels, ResultRejected> {
        let (width, height) = (self.color().width, self.color().height);
        let foreign = |(x, y): (u32, u32)| ResultRejected::ForeignPixel { x, y };
        match self.pixels {
            AssembledPixels::Color(_) => {
                let colors = bitmap.colors_within(width, height)?;
                // Inside the frame: `colors_within` checked.
                let bounds = bitmap_rect(bitmap.x0, bitmap.y0, bitmap.width, bitmap.height);
                // The ID buffer is the frame's size: every index is in it.
                match (colors.iter())
                    .find(|(i, _)| !TriangleId::from_raw(ids.triangle[*i]).is_some_and(&owned))
                {
                    Some(&(i, _)) => Err(foreign((i as u32 % width, i as u32 / width))),
                    None => Ok(ResultPixels::Colors { bounds, colors }),
                }
            }
            AssembledPixels::Components(_) => {
                let bitmap = bitmap.into_bitmap_within(width, height)?;
                match bitmap.foreign_pixel(ids, owned) {
                    Some(pixel) => Err(foreign(pixel)),
                    None => Ok(ResultPixels::Bitmap(bitmap)),
                }
            }
        }
    }

    /// Writes a checked result's pixels ([`FrameImage::composite`]),
    /// adding its rectangle to the written one.
    pub(crate) fn composite(&mut self, pixels: &ResultPixels) {
        self.written = self.written.union(pixels.bounds());
        match (&mut self.pixels, pixels) {
            (AssembledPixels::Color(color), ResultPixels::Colors { colors, .. }) => {
                for &(i, c) in colors {
                    color.pixels[i] = c;
                }
            }
            (AssembledPixels::Components(image), ResultPixels::Bitmap(bitmap)) => {
                image.composite(bitmap)
            }
            // `check` decodes for the kind of assembly it is called on, and
            // a frame's kind is set once, with its base frame.
            _ => unreachable!("a result decoded for another kind of frame"),
        }
    }
}

/// A checked result: pixels to composite, or a whole frame finished.
pub(crate) enum Accepted {
    Composite(ResultPixels),
    Finished(WireImage, Option<WireFrameAux>),
}

/// A checked result in the form its frame composites: frame indices and
/// colours (with the rectangle they lie in), or the whole bitmap with the
/// components.
pub(crate) enum ResultPixels {
    Colors {
        bounds: PixelRect,
        colors: Vec<(usize, Vec3)>,
    },
    Bitmap(SparseBitmap),
}

impl ResultPixels {
    /// The rectangle every pixel it writes lies in.
    pub(crate) fn bounds(&self) -> PixelRect {
        match self {
            ResultPixels::Colors { bounds, .. } => *bounds,
            ResultPixels::Bitmap(bitmap) => {
                bitmap_rect(bitmap.x0, bitmap.y0, bitmap.width, bitmap.height)
            }
        }
    }
}

/// The rectangle of a result's bitmap (its corner and sides, inside the
/// frame once checked).
pub(crate) fn bitmap_rect(x0: u32, y0: u32, width: u32, height: u32) -> PixelRect {
    PixelRect {
        x0,
        y0,
        x1: x0 + width,
        y1: y0 + height,
    }
}

/// A timeline phase from `start` to `end`, in microseconds from `t0`.
pub(crate) fn phase(
    t0: Duration,
    who: String,
    kind: PhaseKind,
    start: Duration,
    end: Duration,
) -> FramePhase {
    let micros = |t: Duration| t.saturating_sub(t0).as_micros() as u64;
    FramePhase {
        who,
        kind,
        start_micros: micros(start),
        end_micros: micros(end),
    }
}

#[cfg(test)]
mod tests {
    use vtfarm_proto::{FrameStart, WireBitmapParts};

    use super::*;

    const MS: Duration = Duration::from_millis(1);

    fn rect(x0: u32, y0: u32, x1: u32, y1: u32) -> PixelRect {
        PixelRect { x0, y0, x1, y1 }
    }

    /// A 4 × 2 base frame whose left half belongs to triangle 0 and right
    /// half to triangle 1.
    fn halves() -> BaseFrame {
        let mut ids = IdBuffer::new(4, 2);
        for (i, t) in ids.triangle.iter_mut().enumerate() {
            *t = u32::from(i % 4 >= 2);
        }
        BaseFrame {
            image: Image::black(4, 2),
            ids,
            srgb: SrgbBytes::default(),
        }
    }

    /// A bitmap writing pixel (`x`, 0) white.
    fn one_pixel(x: u32) -> WireBitmap {
        let bitmap = SparseBitmap {
            x0: x,
            y0: 0,
            width: 1,
            height: 1,
            mask: vec![true],
            color: vec![Vec3::ONE],
            reflected: vec![Vec3::ZERO],
            transmitted: vec![Vec3::ZERO],
            reflected_object: vec![0],
        };
        WireBitmap::encode(&bitmap, WireBitmapParts::All)
    }

    /// A result may write only the pixels its triangles own; what it may
    /// write is composited over the base frame, its rectangle remembered.
    #[test]
    fn a_result_writes_only_pixels_its_triangles_own() {
        for components in [None, Some(rect(0, 0, 4, 2))] {
            let (mut assembled, ids) = Assembled::new(halves(), components);
            let only_0 = |t: TriangleId| t == TriangleId(0);
            let foreign = assembled.check(one_pixel(3), &ids, only_0).err();
            let pixel = Some(ResultRejected::ForeignPixel { x: 3, y: 0 });
            assert_eq!(format!("{foreign:?}"), format!("{pixel:?}"));
            let pixels = assembled.check(one_pixel(1), &ids, only_0).unwrap();
            assembled.composite(&pixels);
            assert_eq!(assembled.written, rect(1, 0, 2, 1));
            assert_eq!(assembled.color().pixels[1], Vec3::ONE);
            assert_eq!(assembled.color().pixels[0], Vec3::ZERO, "the base frame");
            assert_eq!(assembled.components().is_some(), components.is_some());
        }
    }

    /// A result's time on the timeline: the worker's set-up from the
    /// package's hand-out, its computing before it arrived, the way there
    /// and back between; the base frame from the frame's start.
    #[test]
    fn a_frames_timeline_splits_a_package_into_setup_sending_and_computing() {
        let start = FrameStart {
            job: vtfarm_proto::JobId(1),
            frame: 0,
            scene: Default::default(),
            setup: (&crate::testkit::frame()).into(),
            reflectors: vec![0],
            method: vtfarm_method::MethodKind::VertexTracing.into(),
            aux: false,
            image: vtfarm_proto::WireImageFormat::LinearF32,
            stages: Vec::new(),
        };
        let mut assembly = FrameAssembly::new(start, false, 10 * MS, None);
        let (image, ids) = Assembled::new(halves(), None);
        assembly.based(image, ids, 30 * MS);
        let result = PackageResult {
            id: 7,
            pixels: vtfarm_proto::ResultPixels::Bitmap(one_pixel(0)),
            stats: Default::default(),
            busy_micros: 40_000,
            setup_micros: 5_000,
            triangle_samples: vec![1],
            stage: None,
            mesh: None,
        };
        assembly.record_package("w".into(), 20 * MS, 100 * MS, &result);
        let spans: Vec<_> = (assembly.phases.iter())
            .map(|p| (p.kind, p.start_micros / 1000, p.end_micros / 1000))
            .collect();
        assert_eq!(
            spans,
            [
                (PhaseKind::Base, 0, 20),
                (PhaseKind::Setup, 10, 15),
                (PhaseKind::Sending, 15, 50),
                (PhaseKind::Package, 50, 90),
            ]
        );
    }
}
