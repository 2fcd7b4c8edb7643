//! The dashboard view's routes for the page that draws the scene itself
//! (WebGL2): the view's source scene as GLB with its camera and lights,
//! the stage messages as they come (`vtfarm_master_core::stream`), and the
//! page's modules with the vendored three.js, embedded in the binary.
//! Merged into [`crate::http`]'s router, behind its host and token checks.

use std::sync::{Arc, Mutex};
use vtfarm_proto::JobId;

use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde::{Deserialize, Serialize};
use vtfarm_master_core::MasterCore;
use vtfarm_master_core::view::{EYE_BOX, ViewSource};
use vtfarm_proto::SceneHash;
use vtfarm_scene::LightKind;
use vtfarm_vertex::ShadowViews;

use crate::driver::MasterHandle;

/// A JavaScript expression for a driver of the dashboard (a browser test,
/// `vtfarm bench view --browser`): a promise that resolves to `value` once
/// `condition` holds on the page, checked at once and at each
/// `vtfarm-view-changed` the page dispatches (a move sent, a stage come or
/// drawn), or after `bound_ms` to `state` as JSON, for the error.
pub fn view_reaches(condition: &str, value: &str, state: &str, bound_ms: u64) -> String {
    format!(
        r#"new Promise((resolve) => {{
            const check = () => {{
                if (!({condition})) return;
                document.removeEventListener("vtfarm-view-changed", check);
                resolve({value});
            }};
            document.addEventListener("vtfarm-view-changed", check);
            setTimeout(() => resolve(JSON.stringify({state})), {bound_ms});
            check();
        }})"#
    )
}

/// The page's files: path under `/assets/`, content type, bytes.
const ASSETS: [(&str, &str, &str); 7] = [
    (
        "vendor/three/three.module.min.js",
        JS,
        include_str!("../assets/vendor/three/three.module.min.js"),
    ),
    (
        "vendor/three/loaders/GLTFLoader.js",
        JS,
        include_str!("../assets/vendor/three/loaders/GLTFLoader.js"),
    ),
    (
        "vendor/three/utils/BufferGeometryUtils.js",
        JS,
        include_str!("../assets/vendor/three/utils/BufferGeometryUtils.js"),
    ),
    (
        "vendor/three/LICENSE",
        "text/plain; charset=utf-8",
        include_str!("../assets/vendor/three/LICENSE"),
    ),
    (
        "view/stream.js",
        JS,
        include_str!("../assets/view/stream.js"),
    ),
    ("view/scene.js", JS, include_str!("../assets/view/scene.js")),
    (
        "view/controls.js",
        JS,
        include_str!("../assets/view/controls.js"),
    ),
];

const JS: &str = "text/javascript; charset=utf-8";

/// The view's routes; `S` is the router's state (the routes keep their own).
pub(crate) fn routes<S: Clone + Send + Sync + 'static>(master: MasterHandle) -> Router<S> {
    let state = ViewHttp {
        master,
        glb: Arc::default(),
        setup: Arc::default(),
    };
    Router::new()
        .route("/view/stream", get(stream))
        .route("/view/scene.glb", get(scene_glb))
        .route("/view/setup.json", get(setup_json))
        .route("/api/view/stages", get(stages_json))
        .route("/assets/{*path}", get(asset))
        .with_state(state)
}

#[derive(Clone)]
struct ViewHttp {
    master: MasterHandle,
    /// The last scene served as GLB, encoded once per scene.
    glb: Arc<Mutex<Option<(SceneHash, Bytes)>>>,
    /// The last source's `setup.json`, made once per source job (its
    /// shadow views rasterize the frame around the reflectors).
    setup: Arc<Mutex<Option<(JobId, Bytes)>>>,
}

async fn asset(Path(path): Path<String>) -> Response {
    match ASSETS.iter().find(|(p, _, _)| *p == path) {
        Some((_, kind, text)) => (
            [
                (header::CONTENT_TYPE, *kind),
                (header::CACHE_CONTROL, "no-cache"),
            ],
            *text,
        )
            .into_response(),
        None => (StatusCode::NOT_FOUND, "no such file\n").into_response(),
    }
}

/// `?job=ID`: which kept source (the current move's, else the newest).
#[derive(Deserialize)]
struct SourceQuery {
    job: Option<JobId>,
}

fn source_of(core: &MasterCore, job: Option<JobId>) -> Option<(JobId, ViewSource)> {
    core.views().source(job).map(|(id, s)| (id, s.clone()))
}

/// The source's scene as GLB (`vtfarm scene export --format glb`).
async fn scene_glb(State(state): State<ViewHttp>, query: Query<SourceQuery>) -> Response {
    let job = query.job;
    let Some(found) = state.master.inspect(move |c| source_of(c, job)).await else {
        return unavailable();
    };
    let Some((_, source)) = found else {
        return (StatusCode::NOT_FOUND, "no scene kept for the view\n").into_response();
    };
    let cached = state.glb.lock().expect("not poisoned").clone();
    let bytes = match cached.filter(|(hash, _)| *hash == source.scene_hash) {
        Some((_, bytes)) => bytes,
        None => {
            let scene = source.scene.clone();
            let encoded =
                tokio::task::spawn_blocking(move || vtfarm_scene::gltf::encode_glb(&scene))
                    .await
                    .expect("the encoder does not panic");
            let bytes = match encoded {
                Ok(glb) => Bytes::from(glb),
                Err(e) => {
                    let message = format!("the view's scene cannot be written as GLB: {e}\n");
                    return (StatusCode::INTERNAL_SERVER_ERROR, message).into_response();
                }
            };
            *state.glb.lock().expect("not poisoned") = Some((source.scene_hash, bytes.clone()));
            bytes
        }
    };
    ([(header::CONTENT_TYPE, "model/gltf-binary")], bytes).into_response()
}

/// What the page needs besides the scene: the source job's camera and
/// lights, the reflectors and the box the eye moves in.
#[derive(Serialize)]
struct ViewSetup {
    job: JobId,
    scene: String,
    eye: [f32; 3],
    target: [f32; 3],
    up: [f32; 3],
    fov_y_deg: f32,
    width: u32,
    height: u32,
    ambient: [f32; 3],
    background: [f32; 3],
    lights: Vec<LightSetup>,
    /// The objects the reflector triangles belong to (the GLB's node names).
    reflector_objects: Vec<String>,
    eye_box: f32,
    /// Per material of the scene (the GLB's order), whether it casts a
    /// shadow (`vtfarm_trace::casts_shadow`).
    shadow_casting: Vec<bool>,
    shadows: ShadowSetup,
}

/// The shadow maps of what the glass shows behind it, as the CPU's
/// thin-glass pass makes them (`vtfarm_vertex::ShadowViews`): per light,
/// its map's camera or `null` (that light is never shadowed).
#[derive(Serialize)]
struct ShadowSetup {
    size: u32,
    bias: f32,
    cameras: Vec<Option<CameraSetup>>,
}

#[derive(Serialize)]
struct CameraSetup {
    eye: [f32; 3],
    target: [f32; 3],
    up: [f32; 3],
    fov_y_deg: f32,
}

#[derive(Serialize)]
struct LightSetup {
    /// `point` (at `vector`) or `directional` (shining along `vector`).
    kind: &'static str,
    vector: [f32; 3],
    radiance: [f32; 3],
}

async fn setup_json(State(state): State<ViewHttp>, query: Query<SourceQuery>) -> Response {
    let job = query.job;
    let Some(found) = state.master.inspect(move |c| source_of(c, job)).await else {
        return unavailable();
    };
    let Some((job, source)) = found else {
        return (StatusCode::NOT_FOUND, "no scene kept for the view\n").into_response();
    };
    let cached = state.setup.lock().expect("not poisoned").clone();
    if let Some((_, json)) = cached.filter(|(j, _)| *j == job) {
        return json_response(json);
    }
    let camera = source.setup.camera;
    let lighting = &source.setup.lighting;
    let scene = &source.scene;
    let views = {
        let (scene, lights) = (scene.clone(), lighting.lights.clone());
        let is_reflector = vtfarm_render::reflector_flags(&scene, &source.reflectors);
        tokio::task::spawn_blocking(move || {
            ShadowViews::for_frame(&scene, &camera, &lights, &is_reflector)
        })
        .await
        .expect("the shadow views do not panic")
    };
    let shadows = ShadowSetup {
        size: views.size,
        bias: views.bias,
        cameras: (views.cameras.iter())
            .map(|c| {
                c.map(|c| CameraSetup {
                    eye: c.eye.to_array(),
                    target: c.target.to_array(),
                    up: c.up.to_array(),
                    fov_y_deg: c.fov_y_deg,
                })
            })
            .collect(),
    };
    let mut reflector_objects: Vec<String> = (source.reflectors.iter())
        .filter_map(|&t| scene.triangles.get(t.index()))
        .map(|t| scene.objects[t.object.index()].name.clone())
        .collect();
    reflector_objects.sort();
    reflector_objects.dedup();
    let lights = (lighting.lights.iter())
        .map(|l| {
            let (kind, vector) = match l.kind {
                LightKind::Point { position } => ("point", position),
                LightKind::Directional { direction, .. } => ("directional", direction),
            };
            LightSetup {
                kind,
                vector: vector.to_array(),
                radiance: l.radiance().to_array(),
            }
        })
        .collect();
    let setup = ViewSetup {
        job,
        scene: source.name.clone(),
        eye: camera.eye.to_array(),
        target: camera.target.to_array(),
        up: camera.up.to_array(),
        fov_y_deg: camera.fov_y_deg,
        width: camera.width,
        height: camera.height,
        ambient: lighting.ambient.to_array(),
        background: lighting.background.to_array(),
        lights,
        reflector_objects,
        eye_box: EYE_BOX,
        shadow_casting: scene
            .materials
            .iter()
            .map(vtfarm_trace::casts_shadow)
            .collect(),
        shadows,
    };
    let json = Bytes::from(serde_json::to_vec(&setup).expect("JSON of plain values"));
    *state.setup.lock().expect("not poisoned") = Some((job, json.clone()));
    json_response(json)
}

fn json_response(json: Bytes) -> Response {
    ([(header::CONTENT_TYPE, "application/json")], json).into_response()
}

/// Where a stage stream stands: the move it follows and how many of that
/// move's messages it sent.
struct Following {
    master: MasterHandle,
    changes: tokio::sync::watch::Receiver<u64>,
    generation: u64,
    sent: usize,
}

/// The view's stage messages as they come, each framed by its length
/// (`u32`, little-endian): the current move's so far, then each new one;
/// a newer move's from its first, never an outdated move's after it.
async fn stream(State(state): State<ViewHttp>) -> Response {
    let mut changes = state.master.changes();
    changes.mark_changed();
    let following = Following {
        master: state.master.clone(),
        changes,
        generation: 0,
        sent: 0,
    };
    let body = futures_util::stream::unfold(following, |mut f| async move {
        loop {
            f.changes.changed().await.ok()?;
            f.changes.mark_unchanged();
            let (generation, from) = (f.generation, f.sent);
            let read = move |c: &MasterCore| {
                let stream = c.views().stream();
                let from = if stream.generation == generation {
                    from
                } else {
                    0
                };
                let new: Vec<_> = (stream.messages.get(from..).unwrap_or_default().iter())
                    .map(|m| m.bytes.clone())
                    .collect();
                (stream.generation, from + new.len(), new)
            };
            let (generation, sent, new) = f.master.inspect(read).await?;
            (f.generation, f.sent) = (generation, sent);
            if new.is_empty() {
                continue;
            }
            let mut chunk = Vec::with_capacity(new.iter().map(|m| m.len() + 4).sum());
            for m in &new {
                chunk.extend((m.len() as u32).to_le_bytes());
                chunk.extend_from_slice(&m[..]);
            }
            return Some((Ok::<_, std::convert::Infallible>(Bytes::from(chunk)), f));
        }
    });
    Response::builder()
        .header(header::CONTENT_TYPE, "application/octet-stream")
        .header(header::CACHE_CONTROL, "no-store")
        .body(Body::from_stream(body))
        .expect("a valid response")
}

/// The current move's stage messages so far: each one's stage, size and
/// the server's part of it (move received to message made, ms).
async fn stages_json(State(state): State<ViewHttp>) -> Response {
    let read = |c: &MasterCore| {
        let stream = c.views().stream();
        let stages: Vec<serde_json::Value> = (stream.messages.iter())
            .map(|m| {
                serde_json::json!({
                    "quality": m.quality.name(),
                    "bytes": m.bytes.len(),
                    "server_ms": m.after.as_secs_f64() * 1e3,
                })
            })
            .collect();
        serde_json::json!({ "generation": stream.generation, "stages": stages })
    };
    match state.master.inspect(read).await {
        Some(json) => axum::Json(json).into_response(),
        None => unavailable(),
    }
}

fn unavailable() -> Response {
    (StatusCode::SERVICE_UNAVAILABLE, "the master has stopped\n").into_response()
}
