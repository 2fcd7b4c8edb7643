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
use vtfarm_scene::{
    Camera, DAYLIGHT_SKY_CD_M2, DAYLIGHT_SUN_DIRECTION, DAYLIGHT_SUN_LUX, Light, Lighting,
    Material, ObjectId, Scene, Texture, TextureId, Triangle, TriangleId, fresnel_reflectance,
};
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
    /// `camera.camera`: a camera of the glTF scene, the base of the other
    /// `[camera]` keys (width and height are the job's).
    pub camera_name: Option<String>,
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
    /// `[materials."NAME"]`: changes to the scene's materials, in name order.
    pub materials: Vec<MaterialOverride>,
    /// The `[output]` keys: how the PNG images show the linear colours.
    pub output: OutputSettings,
    /// Where the keys checked against the scene stand in the file
    /// (`camera.eye`, `frames.eyes[1]`, `reflectors object "glass"`,
    /// `materials."glass"`), so those errors name the line too.
    pub locations: BTreeMap<String, Location>,
}

/// A job's `[materials."NAME"]` table: the given keys replace the scene
/// material's values, in render units (colours linear RGB, 0 to 1).
///
/// `kd` also sets the ambient reflectance unless `ka` is given (as MTL does
/// without `Ka`). `thin = true` makes the material a thin sheet of glass:
/// it transmits `1 - kr` (unless `kt` is given) and rays pass it straight
/// (its index of refraction serves the Fresnel weights only: `Material::thin`).
/// `emission_cd_m2` (with `emission_color`, white by default) makes it
/// glow; `texture` is a base-colour texture (MTL's `map_Kd`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MaterialOverride {
    pub name: String,
    pub ambient: Option<Vec3>,
    pub diffuse: Option<Vec3>,
    pub specular: Option<Vec3>,
    pub shininess: Option<f32>,
    pub reflectance: Option<Vec3>,
    pub transmittance: Option<Vec3>,
    pub ior: Option<f32>,
    pub thin: bool,
    pub emission: Option<Vec3>,
    /// Already resolved against the job file's directory.
    pub texture: Option<PathBuf>,
}

impl MaterialOverride {
    /// The key in [`Job::locations`] (and messages) of the table for `name`.
    pub fn key_of(name: &str) -> String {
        format!("materials.{name:?}")
    }

    /// `material` with the given keys replaced; the texture is the caller's
    /// (it needs the scene's texture list).
    fn apply(&self, material: &mut Material) {
        if let Some(kd) = self.diffuse {
            material.diffuse = kd;
            material.ambient = kd;
        }
        let fields = [
            (&mut material.ambient, self.ambient),
            (&mut material.specular, self.specular),
            (&mut material.reflectance, self.reflectance),
            (&mut material.transmittance, self.transmittance),
            (&mut material.emission, self.emission),
        ];
        for (field, value) in fields {
            if let Some(value) = value {
                *field = value;
            }
        }
        if let Some(shininess) = self.shininess {
            material.shininess = shininess;
        }
        if let Some(ior) = self.ior {
            material.ior = ior;
        }
    }
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
    /// A glTF 2.0 file (`.gltf` or `.glb`), resolved likewise.
    Gltf(PathBuf),
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

/// Second names of a scene's objects, which `[reflectors] objects` also
/// selects by: each glTF mesh name a node's name hides, with the objects of
/// the nodes that instance the mesh
/// ([`vtfarm_scene::gltf::ImportedGltf::mesh_objects`]); empty for OBJ
/// files and the cockpit.
pub type ObjectAliases = BTreeMap<String, Vec<ObjectId>>;

/// Selects reflector triangles by the name of their object (a glTF node's
/// or its mesh's, [`ObjectAliases`]) or material.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ReflectorSelector {
    Object(String),
    Material(String),
}

impl ReflectorSelector {
    /// Whether `triangle` of `scene` (whose objects have `aliases` as
    /// second names) is selected.
    pub fn matches(&self, scene: &Scene, aliases: &ObjectAliases, triangle: &Triangle) -> bool {
        match self {
            ReflectorSelector::Object(name) => {
                let named = scene.objects.get(triangle.object.index());
                named.is_some_and(|o| o.name == *name)
                    || aliases
                        .get(name)
                        .is_some_and(|objects| objects.contains(&triangle.object))
            }
            ReflectorSelector::Material(name) => scene
                .materials
                .get(triangle.material.index())
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
    /// The objects' second names, for [`Job::reflector_triangles`].
    pub object_aliases: ObjectAliases,
    /// What the job filled in for the scene (the default light, Fresnel
    /// reflectance for a reflector): each is also logged as a warning.
    pub notes: Vec<String>,
}

/// A job's scene with its objects' second names ([`Job::scene_only`]).
#[derive(Clone, Debug)]
pub struct JobScene {
    pub scene: Scene,
    pub object_aliases: ObjectAliases,
}

/// The most bytes of a job or study file.
pub const MAX_JOB_FILE_BYTES: u64 = 16 << 20;

/// The text of a job or study file: a regular file of at most
/// [`MAX_JOB_FILE_BYTES`].
pub(crate) fn read_job_text(path: &Path) -> Result<String, JobError> {
    vtfarm_scene::file::read_regular_text(path, MAX_JOB_FILE_BYTES).map_err(|source| {
        JobError::Read {
            file: path.to_owned(),
            source,
        }
    })
}

/// Reads and validates a job file.
pub fn load_job(path: &Path) -> Result<Job, JobError> {
    let text = read_job_text(path)?;
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
        let (scene, aliases, camera, lighting) = match &self.scene {
            SceneSource::Cockpit(config) => {
                let cockpit = vtfarm_cockpit::cockpit(config);
                (
                    cockpit.scene,
                    ObjectAliases::new(),
                    self.camera.over(&cockpit.camera),
                    self.lighting.over(cockpit.lighting),
                )
            }
            SceneSource::Obj(_) => {
                let camera = self
                    .camera
                    .complete()
                    .map_err(|missing| self.invalid(None, obj_camera_missing(&missing)))?;
                let JobScene {
                    scene,
                    object_aliases,
                } = self.loaded_scene()?;
                (
                    scene,
                    object_aliases,
                    camera,
                    self.lighting.over(Lighting::default()),
                )
            }
            SceneSource::Gltf(path) => {
                let imported = self.gltf(path)?;
                let camera = match &self.camera_name {
                    None => self
                        .camera
                        .complete()
                        .map_err(|missing| self.invalid(None, obj_camera_missing(&missing)))?,
                    Some(name) => self.gltf_camera(name, &imported.cameras)?,
                };
                (
                    imported.scene,
                    imported.mesh_objects,
                    camera,
                    self.lighting.over(Lighting::default()),
                )
            }
        };
        let (scene, mut notes) = self.prepare(scene, &aliases)?;
        let lighting = match (&self.scene, &self.lighting.lights) {
            // A file with no light of its own, and the job sets none.
            (SceneSource::Obj(_) | SceneSource::Gltf(_), None) => {
                notes.push(default_light_note());
                let daylight = Lighting::daylight();
                LightingSpec {
                    lights: Some(daylight.lights.clone()),
                    ambient: self.lighting.ambient.or(Some(daylight.ambient)),
                    background: self.lighting.background.or(Some(daylight.background)),
                }
                .over(lighting)
            }
            _ => lighting,
        };
        for note in &notes {
            tracing::warn!("{}: {note}", self.file.display());
        }
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
            object_aliases: aliases,
            notes,
        })
    }

    /// The scene alone, with the job's material changes but without
    /// resolving camera or lighting (a glare study takes those from its base
    /// job for every design variant).
    pub fn scene_only(&self) -> Result<JobScene, JobError> {
        let JobScene {
            scene,
            object_aliases,
        } = self.loaded_scene()?;
        let (scene, notes) = self.prepare(scene, &object_aliases)?;
        for note in &notes {
            tracing::warn!("{}: {note}", self.file.display());
        }
        Ok(JobScene {
            scene,
            object_aliases,
        })
    }

    /// `scene` with the job's `[materials]` applied, then Fresnel
    /// reflectance for the reflectors' materials that have `Ni` > 1 and no
    /// other reflectance (the usual export of glass), then `thin`; returns
    /// notes for the user about what the job filled in.
    fn prepare(
        &self,
        mut scene: Scene,
        aliases: &ObjectAliases,
    ) -> Result<(Scene, Vec<String>), JobError> {
        let mut notes = Vec::new();
        let mut overridden = vec![None; scene.materials.len()];
        for change in &self.materials {
            let Some(id) = scene.material_id(&change.name) else {
                let key = MaterialOverride::key_of(&change.name);
                return Err(self.invalid(
                    Some(&key),
                    format!(
                        "[{key}]: the scene has no material {:?} (materials: {})",
                        change.name,
                        sorted_names(scene.materials.iter().map(|m| &m.name)).join(", ")
                    ),
                ));
            };
            change.apply(&mut scene.materials[id.index()]);
            if let Some(path) = &change.texture {
                let key = format!("{}.texture", MaterialOverride::key_of(&change.name));
                let texture =
                    Texture::load(path).map_err(|e| self.invalid(Some(&key), e.to_string()))?;
                if scene.corner_uvs.is_empty() {
                    return Err(self.invalid(
                        Some(&key),
                        format!("{key}: the scene has no texture coordinates (vt) to map it with"),
                    ));
                }
                scene.textures.push(texture);
                scene.materials[id.index()].diffuse_texture =
                    Some(scene.textures.len() as TextureId - 1);
            }
            overridden[id.index()] = Some(change);
        }
        let mut is_reflector_material = vec![false; scene.materials.len()];
        for triangle in &scene.triangles {
            if (self.reflectors.iter()).any(|r| r.matches(&scene, aliases, triangle)) {
                is_reflector_material[triangle.material.index()] = true;
            }
        }
        for (id, material) in scene.materials.iter_mut().enumerate() {
            let given_kr = overridden[id].is_some_and(|o| o.reflectance.is_some());
            if is_reflector_material[id]
                && !given_kr
                && material.reflectance == Vec3::ZERO
                && material.ior > 1.0
            {
                let kr = fresnel_reflectance(material.ior);
                material.reflectance = Vec3::splat(kr);
                notes.push(format!(
                    "reflector material {:?} has no Kr and no illum 3 to 7, but Ni {}: it \
                     reflects by Fresnel at normal incidence, kr = {kr:.4} (set \
                     [{}] kr = [r, g, b] to choose)",
                    material.name,
                    material.ior,
                    MaterialOverride::key_of(&material.name)
                ));
            }
            if let Some(change) = overridden[id].filter(|o| o.thin) {
                if change.transmittance.is_none() {
                    material.transmittance = Vec3::ONE - material.reflectance;
                }
                material.thin = true;
            }
        }
        Ok((scene, notes))
    }

    /// The glTF file of the job, its warnings logged.
    fn gltf(&self, path: &Path) -> Result<vtfarm_scene::gltf::ImportedGltf, JobError> {
        let options = ObjOptions {
            keep_uvs: self.materials.iter().any(|m| m.texture.is_some()),
            ..ObjOptions::default()
        };
        vtfarm_scene::gltf::load_gltf(path, &options).map_err(|error| JobError::Gltf {
            file: self.file.clone(),
            error: Box::new(error),
        })
    }

    /// The glTF camera `name` with the job's `[camera]` keys over it.
    fn gltf_camera(
        &self,
        name: &str,
        cameras: &[vtfarm_scene::gltf::GltfCamera],
    ) -> Result<Camera, JobError> {
        let Some(c) = cameras.iter().find(|c| c.name == name) else {
            let names: Vec<&str> = cameras.iter().map(|c| c.name.as_str()).collect();
            return Err(self.invalid(
                Some("camera.camera"),
                format!(
                    "camera.camera = {name:?}: the glTF file has no such camera (cameras: {})",
                    if names.is_empty() {
                        "none".to_owned()
                    } else {
                        names.join(", ")
                    }
                ),
            ));
        };
        let (Some(width), Some(height)) = (self.camera.width, self.camera.height) else {
            return Err(self.invalid(
                Some("camera.camera"),
                "[camera] needs width and height with a glTF camera".to_owned(),
            ));
        };
        let base = Camera {
            eye: c.eye,
            target: c.target,
            up: c.up,
            fov_y_deg: c.fov_y_deg,
            width,
            height,
        };
        Ok(self.camera.over(&base))
    }

    /// The scene as its source gives it.
    fn loaded_scene(&self) -> Result<JobScene, JobError> {
        let scene = match &self.scene {
            SceneSource::Gltf(path) => {
                let imported = self.gltf(path)?;
                return Ok(JobScene {
                    scene: imported.scene,
                    object_aliases: imported.mesh_objects,
                });
            }
            SceneSource::Cockpit(config) => vtfarm_cockpit::cockpit(config).scene,
            SceneSource::Obj(path) => {
                let options = ObjOptions {
                    keep_uvs: self.materials.iter().any(|m| m.texture.is_some()),
                    ..ObjOptions::default()
                };
                load_obj(path, &options).map_err(|error| JobError::Obj {
                    file: self.file.clone(),
                    obj: path.clone(),
                    error: Box::new(error),
                })?
            }
        };
        Ok(JobScene {
            scene,
            object_aliases: ObjectAliases::new(),
        })
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
    /// matches (objects by their names and `aliases`, see
    /// [`ObjectAliases`]). Fails on a selector that matches nothing, listing
    /// the scene's object and material names.
    pub fn reflector_triangles(
        &self,
        scene: &Scene,
        aliases: &ObjectAliases,
    ) -> Result<Vec<TriangleId>, JobError> {
        let mut chosen = vec![false; scene.triangles.len()];
        for selector in &self.reflectors {
            let mut matched = false;
            for (chosen, triangle) in chosen.iter_mut().zip(&scene.triangles) {
                if selector.matches(scene, aliases, triangle) {
                    *chosen = true;
                    matched = true;
                }
            }
            if !matched {
                return Err(JobError::NoReflector {
                    file: self.file.clone(),
                    location: self.locations.get(&selector.key()).copied(),
                    selector: Box::new(selector.clone()),
                    objects: sorted_names(
                        (scene.objects.iter().map(|o| &o.name)).chain(aliases.keys()),
                    ),
                    materials: sorted_names(scene.materials.iter().map(|m| &m.name)),
                });
            }
        }
        // Walking the triangles in order keeps the ids sorted and unique.
        let triangles: Vec<TriangleId> = (0..)
            .map(TriangleId)
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
#[derive(Clone, Debug, PartialEq)]
pub struct DullReflector {
    pub object: String,
    pub material: String,
    /// The largest channel of the material's Phong highlight (`Ks`).
    pub specular: f32,
    /// Its index of refraction (`Ni`).
    pub ior: f32,
}

impl fmt::Display for DullReflector {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "reflector object {:?} has material {:?}, which reflects nothing, so its reflection \
             is black: it has no Kr, no illum 3, 4 or 6 with Ks",
            self.object, self.material
        )?;
        if self.specular > 0.0 {
            write!(f, " (its Ks {} is only a highlight)", self.specular)?;
        }
        write!(
            f,
            ", no illum 5 or 7, and its Ni {} is not above 1 (no Fresnel); set [{}] kr = \
             [r, g, b] or ior = 1.5 in the job (or Kr in the MTL)",
            self.ior,
            MaterialOverride::key_of(&self.material)
        )
    }
}

/// The distinct (object, material) pairs among `triangles` whose material
/// has no reflectance, in triangle order.
pub fn dull_reflectors(scene: &Scene, triangles: &[TriangleId]) -> Vec<DullReflector> {
    let mut seen = std::collections::BTreeSet::new();
    let mut dull = Vec::new();
    for &t in triangles {
        let triangle = &scene.triangles[t.index()];
        let material = &scene.materials[triangle.material.index()];
        if material.reflectance.max_element() <= 0.0
            && seen.insert((triangle.object, triangle.material))
        {
            dull.push(DullReflector {
                object: scene.objects[triangle.object.index()].name.clone(),
                material: material.name.clone(),
                specular: material.specular.max_element(),
                ior: material.ior,
            });
        }
    }
    dull
}

/// The warning for a scene given no light: what it gets instead, and how to
/// set lights.
fn default_light_note() -> String {
    let d = DAYLIGHT_SUN_DIRECTION;
    format!(
        "the scene has no light and the job sets none: it is lit by the default daylight, a \
         sun of {DAYLIGHT_SUN_LUX} lx travelling along [{}, {}, {}] and a sky of \
         {DAYLIGHT_SKY_CD_M2} cd/m² (background and ambient light); set your own with \
         [[lighting.lights]] kind = \"directional\", direction = [x, y, z], illuminance_lux = \
         ... (or lights = [] for none) and lighting.ambient_illuminance_lux, \
         lighting.background_luminance_cd_m2",
        d.x, d.y, d.z
    )
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
