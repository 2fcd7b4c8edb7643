//! What the subcommands share: loading a job with the command line's
//! overrides, progress bars and the cube-map reflector warning; the
//! `--quality` parser, thread pool, async runtime and JSON output come from
//! `vtfarm_bench::support`, which the benchmarks share too.

use std::borrow::Cow;
use std::path::Path;

use anyhow::Result;
use indicatif::{ProgressBar, ProgressStyle};
use vtfarm_render::FrameSetup;
use vtfarm_vertex::Quality;

pub(crate) use vtfarm_bench::support::{parse_quality, runtime, set_threads, write_json};

/// A job file made ready to render: its scene, reflectors and one set-up per frame.
pub(crate) struct PreparedJob {
    pub(crate) job: vtfarm_job::Job,
    pub(crate) scene: vtfarm_scene::Scene,
    pub(crate) reflectors: Vec<u32>,
    pub(crate) setups: Vec<FrameSetup>,
}

/// Loads a job file, applies the command line's overrides and makes the
/// frames' set-ups (the camera, then one per extra eye point).
pub(crate) fn prepare_job(
    path: &Path,
    quality: Option<Quality>,
    width: Option<u32>,
    height: Option<u32>,
) -> Result<PreparedJob> {
    let mut job = vtfarm_job::load_job(path)?;
    if let Some(q) = quality {
        job.vertex.quality = q;
    }
    let loaded = job.load_scene()?;
    let mut camera = loaded.camera;
    camera.width = width.unwrap_or(camera.width);
    camera.height = height.unwrap_or(camera.height);
    let reflectors = job.reflector_triangles(&loaded.scene)?;
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
    reflectors: &[u32],
) {
    use vtfarm_method::MethodKind;
    if !matches!(method, MethodKind::CubeMap | MethodKind::CubeMapGrid) {
        return;
    }
    for group in vtfarm_method::reflector_groups(scene, reflectors) {
        if let Some(warning) = vtfarm_cubemap::classify(scene, &group).warning() {
            let object = scene.triangles[group[0] as usize].object;
            let name = &scene.objects[object as usize].name;
            eprintln!("warning: reflector {name:?}: {warning}");
        }
    }
}

/// A progress bar counting `total` `unit`s (reflector triangles, frames).
pub(crate) fn progress_bar(
    total: u64,
    unit: &str,
    message: impl Into<Cow<'static, str>>,
) -> ProgressBar {
    let template = format!("{{spinner}} {{msg}} [{{bar:40}}] {{pos}}/{{len}} {unit} ({{elapsed}})");
    let bar = ProgressBar::new(total).with_style(
        ProgressStyle::with_template(&template)
            .expect("template is valid")
            .progress_chars("=> "),
    );
    bar.set_message(message);
    bar
}
