//! What the subcommands share: loading a job with the command line's
//! overrides and the cube-map reflector warning; the
//! `--quality` parser, thread pool, async runtime and JSON output come from
//! `vtfarm_bench::support`, which the benchmarks share too.

use std::path::Path;

use anyhow::Result;
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use vtfarm_render::FrameSetup;
use vtfarm_vertex::Quality;

pub(crate) use vtfarm_bench::support::{parse_quality, runtime, set_threads, write_json};

/// The `--quality` parser of the user's commands: `parse_quality` with the
/// levels listed in `--help` (and in the error after a wrong one).
pub(crate) fn quality_parser() -> impl TypedValueParser<Value = Quality> {
    let levels = Quality::ALL.map(|q| PossibleValue::new(q.name()).help(quality_help(q)));
    PossibleValuesParser::new(levels).try_map(|name| parse_quality(&name))
}

/// One line per level for `--help`.
fn quality_help(quality: Quality) -> &'static str {
    match quality {
        Quality::Preview => "the reflector's vertices only, interpolated between them",
        Quality::Refine => "adaptive edge refinement where the reflection changes",
        Quality::Full => "refine plus per-pixel tracing where faces still disagree",
        Quality::Reference => "every reflector pixel traced (the ground truth)",
    }
}

/// `--width` and `--height`: the image size, overriding the job's.
#[derive(clap::Args, Clone, Copy, Debug, Default)]
pub(crate) struct ImageSize {
    /// Image width in pixels (default: the job's). Given without --height,
    /// the height follows from the job's aspect ratio.
    #[arg(long, value_parser = image_side)]
    pub(crate) width: Option<u32>,
    /// Image height in pixels (default: the job's). Given without --width,
    /// the width follows from the job's aspect ratio.
    #[arg(long, value_parser = image_side)]
    pub(crate) height: Option<u32>,
}

/// One side given on the command line, checked by the camera's own rule so
/// that a bad value is blamed on the option, not on the job file.
fn image_side(text: &str) -> std::result::Result<u32, String> {
    let pixels: u32 = text.parse().map_err(|e| format!("{e}"))?;
    vtfarm_scene::Camera::check_side("side", pixels).map_err(|e| format!("must be {}", e.rule))
}

impl ImageSize {
    /// Whether either dimension is given.
    pub(crate) fn is_set(self) -> bool {
        self.width.is_some() || self.height.is_some()
    }

    /// The size for a job of `job_width` × `job_height`: both given, both
    /// taken; one given, the other scaled to keep the job's aspect ratio
    /// (rounded to the nearest pixel, at least 1).
    pub(crate) fn resolve(self, job_width: u32, job_height: u32) -> (u32, u32) {
        let scaled = |given: u32, from: u32, to: u32| {
            let exact = f64::from(given) * f64::from(to) / f64::from(from.max(1));
            (exact.round() as u32).max(1)
        };
        match (self.width, self.height) {
            (Some(w), Some(h)) => (w, h),
            (Some(w), None) => (w, scaled(w, job_width, job_height)),
            (None, Some(h)) => (scaled(h, job_height, job_width), h),
            (None, None) => (job_width, job_height),
        }
    }
}

/// A job file made ready to render: its scene, reflectors and one set-up per frame.
pub(crate) struct PreparedJob {
    pub(crate) job: vtfarm_job::Job,
    pub(crate) scene: vtfarm_scene::Scene,
    pub(crate) reflectors: Vec<vtfarm_scene::TriangleId>,
    pub(crate) setups: Vec<FrameSetup>,
}

/// Loads a job file, applies the command line's overrides and makes the
/// frames' set-ups (the camera, then one per extra eye point).
pub(crate) fn prepare_job(
    path: &Path,
    quality: Option<Quality>,
    size: ImageSize,
) -> Result<PreparedJob> {
    let mut job = vtfarm_job::load_job(path)?;
    if let Some(q) = quality {
        job.vertex.quality = q;
    }
    let loaded = job.load_scene()?;
    let mut camera = loaded.camera;
    (camera.width, camera.height) = size.resolve(camera.width, camera.height);
    if size.is_set() {
        vtfarm_scene::Camera::check_size(camera.width, camera.height)
            .map_err(|e| anyhow::anyhow!("--width/--height (command line): {e}"))?;
    }
    let reflectors = job.reflector_triangles(&loaded.scene, &loaded.object_aliases)?;
    let setups = job
        .frames(&camera)?
        .into_iter()
        .map(|camera| FrameSetup {
            camera,
            lighting: loaded.lighting.clone(),
            trace: job.trace,
            vertex: job.vertex,
        })
        .collect();
    Ok(PreparedJob {
        job,
        scene: loaded.scene,
        reflectors,
        setups,
    })
}

/// The cube-map search supports convex and concave reflectors only: says so
/// for each reflector object that is neither.
pub(crate) fn warn_unsupported_reflectors(
    method: vtfarm_method::MethodKind,
    scene: &vtfarm_scene::Scene,
    reflectors: &[vtfarm_scene::TriangleId],
) {
    for warning in vtfarm_cubemap::unsupported_reflector_warnings(method, scene, reflectors) {
        eprintln!("warning: {warning}");
    }
}

#[cfg(test)]
mod tests {
    use super::ImageSize;

    #[test]
    fn one_side_alone_keeps_the_aspect_ratio_and_both_are_taken_as_given() {
        let size = |width, height| ImageSize { width, height };
        assert_eq!(size(None, None).resolve(1280, 720), (1280, 720));
        assert_eq!(size(Some(640), None).resolve(1280, 720), (640, 360));
        assert_eq!(size(None, Some(1080)).resolve(1280, 720), (1920, 1080));
        assert_eq!(size(Some(100), None).resolve(1280, 720), (100, 56)); // 56.25
        assert_eq!(size(Some(1), None).resolve(1280, 720), (1, 1)); // never 0
        assert_eq!(size(Some(50), Some(70)).resolve(1280, 720), (50, 70));
    }
}
