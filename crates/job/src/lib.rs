//! Job files: one TOML file describes a render (the scene, the camera and any
//! extra eye points, the lights, which surfaces are reflectors, and the
//! quality settings). `configs/cockpit.toml` is the annotated reference of the
//! format; [`load_job`] reads one into a [`Job`].
//!
//! Parsing checks everything that can be checked without the scene, so a
//! mistake is reported at once with its file, line and column. What depends on
//! the scene (the cockpit's default camera and lights, which names exist) is
//! resolved by [`Job::load_scene`] and [`Job::reflector_triangles`].
//!
//! Architecture invariant: this crate only turns text into settings and a
//! scene; it renders nothing.

mod error;
mod parse;
pub mod study;

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use glam::Vec3;
use vtfarm_method::MethodKind;
use vtfarm_scene::obj::{ObjOptions, load_obj};
use vtfarm_scene::{Camera, Light, Lighting, Scene, Triangle, TriangleId};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::VertexSettings;

pub use error::{JobError, Location};
pub use vtfarm_cockpit::{CockpitConfig, GlassDesign};

/// A parsed and validated job file.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    /// The job file the job came from: named in every error, and relative
    /// paths in it are relative to its directory.
    pub file: PathBuf,
    pub scene: SceneSource,
    /// The `[camera]` keys; see [`CameraSpec`].
    pub camera: CameraSpec,
    /// The `[lighting]` keys; see [`LightingSpec`].
    pub lighting: LightingSpec,
    /// What reflects (never empty).
    pub reflectors: Vec<ReflectorSelector>,
    pub trace: TraceSettings,
    pub vertex: VertexSettings,
    /// The reflection method (`[quality] method`).
    pub method: MethodKind,
    /// Extra eye points from `[frames]`, each one more frame looking at the
    /// camera's target.
    pub eyes: Vec<Vec3>,
    /// The `[output]` keys: how the PNG images show the linear colours.
    pub output: OutputSettings,
    /// Where the keys checked against the scene stand in the file
    /// (`camera.eye`, `frames.eyes[1]`, `reflectors object "glass"`), so
    /// those errors name the line too.
    pub locations: BTreeMap<String, Location>,
}

/// The `[output]` keys of a job: the PNG's exposure. OpenEXR and `.npy`
/// images keep the linear values whatever these say.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputSettings {
    /// The luminance a PNG shows as white (cd/m²): positive and finite.
    /// Default [`OutputSettings::DEFAULT_WHITE_CD_M2`], the render unit.
    pub white_cd_m2: f32,
    /// The tone curve after the exposure ([`ToneCurve::Clip`] by default).
    pub tone: ToneCurve,
}

pub use vtfarm_imaging::{Exposure, ToneCurve};

impl OutputSettings {
    /// White at one render unit (10,000 cd/m²), the PNGs vtfarm always wrote.
    pub const DEFAULT_WHITE_CD_M2: f32 = vtfarm_scene::photometry::CD_M2_PER_UNIT;

    /// The PNG exposure these settings make.
    pub fn exposure(&self) -> Exposure {
        Exposure {
            scale: vtfarm_scene::photometry::exposure_scale(self.white_cd_m2),
            tone: self.tone,
        }
    }
}

impl Default for OutputSettings {
    fn default() -> Self {
        OutputSettings {
            white_cd_m2: OutputSettings::DEFAULT_WHITE_CD_M2,
            tone: ToneCurve::Clip,
        }
    }
}

/// Where the scene comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum SceneSource {
    /// The built-in procedural truck cockpit.
    Cockpit(CockpitConfig),
    /// An OBJ file; the path is already resolved against the job file's directory.
    Obj(PathBuf),
}

/// The `[camera]` keys that were given. A given key overrides the scene's own
/// camera (the cockpit's driver view). OBJ files carry no camera, so for them
/// parsing requires every key except `up`, which defaults to +Y.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraSpec {
    pub eye: Option<Vec3>,
    pub target: Option<Vec3>,
    pub up: Option<Vec3>,
    /// Vertical field of view in degrees.
    pub fov_y_deg: Option<f32>,
    pub width: Option<u32>,
    pub height: Option<u32>,
}

impl CameraSpec {
    /// `base` with the given keys replaced.
    pub fn over(&self, base: &Camera) -> Camera {
        Camera {
            eye: self.eye.unwrap_or(base.eye),
            target: self.target.unwrap_or(base.target),
            up: self.up.unwrap_or(base.up),
            fov_y_deg: self.fov_y_deg.unwrap_or(base.fov_y_deg),
            width: self.width.unwrap_or(base.width),
            height: self.height.unwrap_or(base.height),
        }
    }

    /// The camera when every key is given, else the missing keys' names.
    pub fn complete(&self) -> Result<Camera, Vec<&'static str>> {
        match *self {
            CameraSpec {
                eye: Some(eye),
                target: Some(target),
                up: Some(up),
                fov_y_deg: Some(fov_y_deg),
                width: Some(width),
                height: Some(height),
            } => Ok(Camera {
                eye,
                target,
                up,
                fov_y_deg,
                width,
                height,
            }),
            _ => Err([
                ("eye", self.eye.is_none()),
                ("target", self.target.is_none()),
                ("up", self.up.is_none()),
                ("fov_y", self.fov_y_deg.is_none()),
                ("width", self.width.is_none()),
                ("height", self.height.is_none()),
            ]
            .into_iter()
            .filter_map(|(key, missing)| missing.then_some(key))
            .collect()),
        }
    }
}

/// The `[lighting]` keys that were given; each overrides the scene's own
/// lighting (the cockpit's sun and daylight, or [`Lighting::default`] with
/// no lights for OBJ files). `lights: Some(vec![])` means "no lights".
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LightingSpec {
    pub lights: Option<Vec<Light>>,
    pub ambient: Option<Vec3>,
    pub background: Option<Vec3>,
}

impl LightingSpec {
    /// `base` with the given keys replaced.
    pub fn over(&self, base: Lighting) -> Lighting {
        Lighting {
            lights: self.lights.clone().unwrap_or(base.lights),
            ambient: self.ambient.unwrap_or(base.ambient),
            background: self.background.unwrap_or(base.background),
        }
    }
}

/// Selects reflector triangles by the name of their object or material.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ReflectorSelector {
    Object(String),
    Material(String),
}

impl ReflectorSelector {
    /// Whether `triangle` of `scene` is selected.
    pub fn matches(&self, scene: &Scene, triangle: &Triangle) -> bool {
        match self {
            ReflectorSelector::Object(name) => scene
                .objects
                .get(triangle.object as usize)
                .is_some_and(|o| o.name == *name),
            ReflectorSelector::Material(name) => scene
                .materials
                .get(triangle.material as usize)
                .is_some_and(|m| m.name == *name),
        }
    }
}

impl ReflectorSelector {
    /// Its key in [`Job::locations`].
    pub fn key(&self) -> String {
        format!("reflectors {self}")
    }
}

impl fmt::Display for ReflectorSelector {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReflectorSelector::Object(name) => write!(f, "object {name:?}"),
            ReflectorSelector::Material(name) => write!(f, "material {name:?}"),
        }
    }
}

/// A loaded scene with the job's camera, frames and lighting resolved against it.
#[derive(Clone, Debug)]
pub struct LoadedScene {
    pub scene: Scene,
    /// The job's camera: `[camera]` over the scene's own camera.
    pub camera: Camera,
    /// One camera per frame: `camera` first, then one per `[frames]` eye
    /// (same target, up, field of view and size).
    pub frames: Vec<Camera>,
    pub lighting: Lighting,
}

/// Reads and validates a job file.
pub fn load_job(path: &Path) -> Result<Job, JobError> {
    let text = std::fs::read_to_string(path).map_err(|source| JobError::Read {
        file: path.to_owned(),
        source,
    })?;
    parse_job(&text, path)
}

/// Validates the text of a job file. `origin` is the file's path: errors name
/// it, relative paths are resolved against its directory, and a referenced
/// OBJ file must exist.
pub fn parse_job(text: &str, origin: &Path) -> Result<Job, JobError> {
    parse::parse(text, origin)
}

impl Job {
    /// Generates the cockpit or loads the OBJ file, and resolves the camera,
    /// frames and lighting against it.
    pub fn load_scene(&self) -> Result<LoadedScene, JobError> {
        let (scene, camera, lighting) = match &self.scene {
            SceneSource::Cockpit(config) => {
                let cockpit = vtfarm_cockpit::cockpit(config);
                (
                    cockpit.scene,
                    self.camera.over(&cockpit.camera),
                    self.lighting.over(cockpit.lighting),
                )
            }
            SceneSource::Obj(_) => {
                let camera = self
                    .camera
                    .complete()
                    .map_err(|missing| self.invalid(None, obj_camera_missing(&missing)))?;
                let scene = self.scene_only()?;
                (scene, camera, self.lighting.over(Lighting::default()))
            }
        };
        // Scenes made in code or read from files meet the same bounds as on the wire.
        scene
            .validate()
            .map_err(|e| self.invalid(None, format!("the scene is unusable: {e}")))?;
        let frames = self.frames(&camera)?;
        Ok(LoadedScene {
            scene,
            camera,
            frames,
            lighting,
        })
    }

    /// The scene alone, without resolving camera or lighting (a glare study
    /// takes those from its base job for every design variant).
    pub fn scene_only(&self) -> Result<Scene, JobError> {
        match &self.scene {
            SceneSource::Cockpit(config) => Ok(vtfarm_cockpit::cockpit(config).scene),
            SceneSource::Obj(path) => {
                load_obj(path, &ObjOptions::default()).map_err(|error| JobError::Obj {
                    file: self.file.clone(),
                    obj: path.clone(),
                    error: Box::new(error),
                })
            }
        }
    }

    /// One camera per frame: `camera` itself, then `camera` moved to each
    /// extra eye. Each must pass [`Camera::validate`] (parsing checks what it
    /// can without the scene; the cockpit's default camera and command-line
    /// sizes are checked here), with the error at the key's line.
    pub fn frames(&self, camera: &Camera) -> Result<Vec<Camera>, JobError> {
        let extra = self
            .eyes
            .iter()
            .enumerate()
            .map(|(i, &eye)| (format!("frames.eyes[{i}]"), eye));
        std::iter::once(("camera.eye".to_owned(), camera.eye))
            .chain(extra)
            .map(|(eye_key, eye)| {
                let frame = Camera { eye, ..*camera };
                frame.validate().map_err(|e| {
                    let extra_eye = eye_key != "camera.eye";
                    match e.field {
                        // This eye, or the view it makes with the target and up vector.
                        "eye" => self.invalid(Some(&eye_key), e.message_for(&eye_key)),
                        "up" if extra_eye => {
                            self.invalid(Some(&eye_key), format!("{eye_key} = {eye}: {e}"))
                        }
                        field => {
                            let key = match field {
                                "fov_y_deg" => "camera.fov_y".to_owned(),
                                "width × height" => "camera.height".to_owned(),
                                field => format!("camera.{field}"),
                            };
                            self.invalid(Some(&key), e.message_for(&key))
                        }
                    }
                })?;
                Ok(frame)
            })
            .collect()
    }

    /// The sorted, de-duplicated ids of all triangles any reflector selector
    /// matches. Fails on a selector that matches nothing, listing the scene's
    /// object and material names.
    pub fn reflector_triangles(&self, scene: &Scene) -> Result<Vec<TriangleId>, JobError> {
        let mut chosen = vec![false; scene.triangles.len()];
        for selector in &self.reflectors {
            let mut matched = false;
            for (chosen, triangle) in chosen.iter_mut().zip(&scene.triangles) {
                if selector.matches(scene, triangle) {
                    *chosen = true;
                    matched = true;
                }
            }
            if !matched {
                return Err(JobError::NoReflector {
                    file: self.file.clone(),
                    location: self.locations.get(&selector.key()).copied(),
                    selector: Box::new(selector.clone()),
                    objects: sorted_names(scene.objects.iter().map(|o| &o.name)),
                    materials: sorted_names(scene.materials.iter().map(|m| &m.name)),
                });
            }
        }
        // Walking the triangles in order keeps the ids sorted and unique.
        let triangles: Vec<TriangleId> = (0..)
            .zip(chosen)
            .filter_map(|(id, chosen)| chosen.then_some(id))
            .collect();
        for dull in dull_reflectors(scene, &triangles) {
            tracing::warn!("{}: {dull}", self.file.display());
        }
        Ok(triangles)
    }

    /// An error about the job, at the line of `key` when the file gave it.
    fn invalid(&self, key: Option<&str>, message: String) -> JobError {
        JobError::Invalid {
            file: self.file.clone(),
            location: key.and_then(|k| self.locations.get(k)).copied(),
            message,
        }
    }
}

/// A reflector whose material reflects nothing: its reflection is black
/// and its reflected-object map empty. The message names the fix.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DullReflector {
    pub object: String,
    pub material: String,
}

impl fmt::Display for DullReflector {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "reflector object {:?} has material {:?}, which has no reflectance: its reflection \
             is black; give the material `Kr r g b` in the MTL (or `illum 3` with `Ks`, or `Ni` \
             for glass)",
            self.object, self.material
        )
    }
}

/// The distinct (object, material) pairs among `triangles` whose material
/// has no reflectance, in triangle order.
pub fn dull_reflectors(scene: &Scene, triangles: &[TriangleId]) -> Vec<DullReflector> {
    let mut seen = std::collections::BTreeSet::new();
    let mut dull = Vec::new();
    for &t in triangles {
        let triangle = &scene.triangles[t as usize];
        let material = &scene.materials[triangle.material as usize];
        if material.reflectance.max_element() <= 0.0
            && seen.insert((triangle.object, triangle.material))
        {
            dull.push(DullReflector {
                object: scene.objects[triangle.object as usize].name.clone(),
                material: material.name.clone(),
            });
        }
    }
    dull
}

/// The message for an OBJ scene's camera lacking `missing` keys.
fn obj_camera_missing(missing: &[&str]) -> String {
    format!(
        "[camera] needs {} for an OBJ scene (OBJ files carry no camera)",
        missing.join(", ")
    )
}

/// Names sorted and without repeats, for listing in messages.
fn sorted_names<'a>(names: impl Iterator<Item = &'a String>) -> Vec<String> {
    let mut names: Vec<String> = names.cloned().collect();
    names.sort();
    names.dedup();
    names
}
