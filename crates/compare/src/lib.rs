//! `vtfarm compare`'s engine: every reflection method on the same frame,
//! each composited over the same base frame and measured against the
//! per-pixel reference on the reference's reflector pixels, plus a
//! side-by-side sheet of the images and their error maps.
//!
//! Pure: the caller rasterizes the base frame and writes files.

use std::time::Duration;

use glam::Vec3;
use serde::Serialize;
use vtfarm_imaging::{Image, encode_srgb8};
use vtfarm_method::{MethodCounters, MethodFrame, MethodKind, ReflectionMethod};
use vtfarm_render::{ErrorFigures, compare, method};
use vtfarm_vertex::{FrameImage, PixelRect, Quality, VertexSettings};

/// One method's frame and figures.
#[derive(Clone, Debug)]
pub struct MethodRun {
    pub name: String,
    pub image: FrameImage,
    pub counters: MethodCounters,
    /// The composited colour against the reference.
    pub error: ErrorFigures,
    /// Mean absolute difference of the reflected component alone (8-bit
    /// sRGB steps per channel) over the reference's reflector pixels.
    pub reflected_mean_abs: f64,
}

/// The figures of one method, as printed and written to `compare.json`.
#[derive(Clone, Debug, Serialize)]
pub struct MethodFigures {
    pub method: String,
    pub seconds: f64,
    pub setup_seconds: f64,
    pub rays: u64,
    pub searches: u64,
    pub pixels: u64,
    pub mean_abs: f64,
    pub share_off: f64,
    pub max_abs: u8,
    pub reflected_mean_abs: f64,
}

impl MethodRun {
    pub fn figures(&self) -> MethodFigures {
        let secs = |d: Duration| d.as_secs_f64();
        MethodFigures {
            method: self.name.clone(),
            seconds: secs(self.counters.time),
            setup_seconds: secs(self.counters.setup_time),
            rays: self.counters.rays,
            searches: self.counters.searches,
            pixels: self.counters.pixels,
            mean_abs: self.error.mean_abs,
            share_off: self.error.share_off,
            max_abs: self.error.max_abs,
            reflected_mean_abs: self.reflected_mean_abs,
        }
    }
}

/// Renders `frame` with the reference and then every method; each image is
/// the base frame with that method's reflector pixels. The reference comes
/// first in the result.
pub fn run_all(
    frame: &MethodFrame<'_>,
    base: &Image,
    reference: &dyn ReflectionMethod,
    methods: &[&dyn ReflectionMethod],
    progress: &mut dyn FnMut(&str),
) -> Vec<MethodRun> {
    let render = |method: &dyn ReflectionMethod| {
        let output = method.render(frame);
        let full = PixelRect::full(base.width, base.height);
        let mut image = FrameImage::new(base.clone(), full);
        image.composite(&output.bitmap);
        (image, output.counters)
    };
    progress(&reference.name());
    let (reference_image, counters) = render(reference);
    let mut runs = vec![MethodRun {
        name: reference.name(),
        error: compare(&reference_image, &reference_image),
        reflected_mean_abs: 0.0,
        image: reference_image.clone(),
        counters,
    }];
    for method in methods {
        progress(&method.name());
        let (image, counters) = render(*method);
        runs.push(MethodRun {
            name: method.name(),
            error: compare(&image, &reference_image),
            reflected_mean_abs: reflected_error(&image, &reference_image),
            image,
            counters,
        });
    }
    runs
}

/// Mean absolute difference of the reflected components over the
/// reference's reflector pixels, in 8-bit sRGB steps per channel.
pub fn reflected_error(test: &FrameImage, reference: &FrameImage) -> f64 {
    let (mut sum, mut n) = (0u64, 0u64);
    for i in reference.glass() {
        let a = encode_srgb8(test.pixel(i).reflected);
        let b = encode_srgb8(reference.pixel(i).reflected);
        sum += (0..3).map(|k| u64::from(a[k].abs_diff(b[k]))).sum::<u64>();
        n += 3;
    }
    sum as f64 / n.max(1) as f64
}

/// The bounding rectangle (x0, y0, x1, y1) of the mask's pixels grown by
/// `margin`, or the whole image for an empty mask.
fn mask_rect(image: &FrameImage, margin: u32) -> (u32, u32, u32, u32) {
    let (w, h) = (image.color.width, image.color.height);
    let mut rect = (u32::MAX, u32::MAX, 0, 0);
    for i in image.glass() {
        let (x, y) = (i as u32 % w, i as u32 / w);
        rect = (
            rect.0.min(x),
            rect.1.min(y),
            rect.2.max(x + 1),
            rect.3.max(y + 1),
        );
    }
    if rect.0 == u32::MAX {
        return (0, 0, w, h);
    }
    (
        rect.0.saturating_sub(margin),
        rect.1.saturating_sub(margin),
        (rect.2 + margin).min(w),
        (rect.3 + margin).min(h),
    )
}

/// Error of `test` against `reference` per pixel: the largest channel
/// difference in 8-bit steps, mapped to the inferno ramp with 32 steps at the
/// top (black outside the reference's reflector pixels).
pub fn error_map(test: &FrameImage, reference: &FrameImage) -> Image {
    let mut map = Image::new(reference.color.width, reference.color.height, Vec3::ZERO);
    for i in reference.glass() {
        let a = encode_srgb8(test.color.pixels[i]);
        let b = encode_srgb8(reference.color.pixels[i]);
        let worst = (0..3).map(|k| a[k].abs_diff(b[k])).max().unwrap_or(0);
        map.pixels[i] = vtfarm_glare::ramp_color(f32::from(worst) / 32.0);
    }
    map
}

/// One column per method, cropped to the reflectors: its name, the image and
/// below it its error map against the reference (the first run).
pub fn sheet(runs: &[MethodRun]) -> Image {
    const GAP: u32 = 8;
    const TEXT_SCALE: u32 = 2;
    let label_height = vtfarm_glare::GLYPH_HEIGHT * TEXT_SCALE + 2 * GAP;
    let Some(reference) = runs.first() else {
        return Image::new(1, 1, Vec3::ZERO);
    };
    let (x0, y0, x1, y1) = mask_rect(&reference.image, 16);
    let (cw, ch) = (x1 - x0, y1 - y0);
    let width = runs.len() as u32 * (cw + GAP) + GAP;
    let height = label_height + 2 * ch + 2 * GAP;
    let mut sheet = Image::new(width, height, Vec3::splat(0.05));
    for (k, run) in runs.iter().enumerate() {
        let left = GAP + k as u32 * (cw + GAP);
        vtfarm_glare::draw_text(
            &mut sheet,
            i64::from(left),
            i64::from(GAP),
            &run.name,
            TEXT_SCALE,
            Vec3::ONE,
        );
        let errors = error_map(&run.image, &reference.image);
        for (row, source) in [
            (label_height, &run.image.color),
            (label_height + ch + GAP, &errors),
        ] {
            for y in 0..ch {
                for x in 0..cw {
                    sheet.set(left + x, row + y, source.get(x0 + x, y0 + y));
                }
            }
        }
    }
    sheet
}

/// Every method `vtfarm compare` measures besides the reference: vertex
/// tracing at its three levels (with the job's thresholds), cube maps with
/// and without the interpolation grid, PVRR and the environment-map baseline.
pub fn standard_methods(vertex: VertexSettings) -> Vec<Box<dyn ReflectionMethod>> {
    let mut methods: Vec<Box<dyn ReflectionMethod>> =
        [Quality::Preview, Quality::Refine, Quality::Full]
            .into_iter()
            .map(|quality| {
                method(
                    MethodKind::VertexTracing,
                    VertexSettings { quality, ..vertex },
                )
            })
            .collect();
    methods.extend(
        MethodKind::ALL
            .into_iter()
            .filter(|k| k.per_reflector())
            .map(|k| method(k, vertex)),
    );
    methods
}
