//! The TOML schema (serde structs mirroring the file) and its validation into
//! a [`Job`]. Every table denies unknown keys so a misspelt key is an error,
//! and checked values are wrapped in `Spanned` so an error can point at the
//! line of the offending key.

use std::fmt::Display;
use std::ops::Range;
use std::path::{Path, PathBuf};

use glam::Vec3;
use serde::Deserialize;
use toml::Spanned;
use vtfarm_cockpit::{COVER_GLASS, GlassDesign};
use vtfarm_method::MethodKind;
use vtfarm_scene::bounds::{self, OutOfBounds};
use vtfarm_scene::{Camera, Light, LightKind, Lighting, photometry};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{Quality, Transmission, VertexSettings};

use crate::{
    CameraSpec, CockpitConfig, Job, JobError, LightingSpec, Location, MaterialOverride,
    OutputSettings, ReflectorSelector, SceneSource, ToneCurve, obj_camera_missing,
};

/// Names accepted by `scene.builtin`.
const BUILTINS: [&str; 1] = ["cockpit"];

pub(crate) type Vec3Value = Spanned<[f32; 3]>;

/// A reflector selector and where the file names it (`None`: a default).
type LocatedSelector = (ReflectorSelector, Option<Range<usize>>);

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawJob {
    scene: Option<Spanned<RawScene>>,
    #[serde(default)]
    camera: RawCamera,
    #[serde(default)]
    lighting: RawLighting,
    reflectors: Option<Spanned<RawReflectors>>,
    #[serde(default)]
    quality: RawQuality,
    #[serde(default)]
    frames: RawFrames,
    #[serde(default)]
    materials: std::collections::BTreeMap<Spanned<String>, RawMaterial>,
    #[serde(default)]
    output: RawOutput,
}

/// `[materials."NAME"]`: what a job changes in one material of the scene.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaterial {
    ka: Option<Vec3Value>,
    kd: Option<Vec3Value>,
    ks: Option<Vec3Value>,
    shininess: Option<Spanned<f32>>,
    kr: Option<Vec3Value>,
    kt: Option<Vec3Value>,
    ior: Option<Spanned<f32>>,
    thin: Option<bool>,
    emission_cd_m2: Option<Spanned<f32>>,
    emission_color: Option<Vec3Value>,
    texture: Option<Spanned<PathBuf>>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    white_cd_m2: Option<Spanned<f32>>,
    tone: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    builtin: Option<Spanned<String>>,
    obj: Option<Spanned<PathBuf>>,
    gltf: Option<Spanned<PathBuf>>,
    detail: Option<Spanned<f32>>,
    glass_segments: Option<Spanned<u32>>,
    glass: Option<Spanned<String>>,
    glass_tilt: Option<Spanned<f32>>,
    glass_radius: Option<Spanned<f32>>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    camera: Option<Spanned<String>>,
    eye: Option<Vec3Value>,
    target: Option<Vec3Value>,
    up: Option<Vec3Value>,
    fov_y: Option<Spanned<f32>>,
    width: Option<Spanned<u32>>,
    height: Option<Spanned<u32>>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLighting {
    ambient: Option<Vec3Value>,
    ambient_illuminance_lux: Option<Spanned<f32>>,
    background: Option<Vec3Value>,
    background_luminance_cd_m2: Option<Spanned<f32>>,
    lights: Option<Vec<RawLight>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLight {
    kind: Spanned<RawLightKind>,
    position: Option<Vec3Value>,
    direction: Option<Vec3Value>,
    color: Option<Vec3Value>,
    intensity: Option<Spanned<f32>>,
    illuminance_lux: Option<Spanned<f32>>,
    angular_diameter_deg: Option<Spanned<f32>>,
}

#[derive(Clone, Copy, Deserialize)]
#[serde(rename_all = "lowercase")]
enum RawLightKind {
    Point,
    Directional,
}

impl RawLightKind {
    fn name(self) -> &'static str {
        match self {
            RawLightKind::Point => "point",
            RawLightKind::Directional => "directional",
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReflectors {
    #[serde(default)]
    objects: Vec<Spanned<String>>,
    #[serde(default)]
    materials: Vec<Spanned<String>>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawQuality {
    level: Option<Spanned<String>>,
    epsilon: Option<Spanned<f32>>,
    pixel_floor: Option<Spanned<f32>>,
    flatness: Option<Spanned<f32>>,
    max_refine_depth: Option<Spanned<u32>>,
    max_trace_depth: Option<Spanned<u32>>,
    fresnel: Option<bool>,
    method: Option<Spanned<String>>,
    max_edge: Option<Spanned<f32>>,
    transmission: Option<Spanned<String>>,
    capture_cd_m2: Option<Spanned<f32>>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFrames {
    #[serde(default)]
    eyes: Vec<Vec3Value>,
}

/// See [`crate::parse_job`].
pub(crate) fn parse(text: &str, origin: &Path) -> Result<Job, JobError> {
    let source = Source { file: origin, text };
    let raw: RawJob = toml::from_str(text).map_err(|e| {
        if crate::study::is_study_text(text) {
            // A study file handed to a command that renders one job: point
            // at the commands that take it instead of at its `[study]` key.
            let header = text
                .lines()
                .scan(0, |start, line| {
                    let at = *start;
                    *start += line.len() + 1;
                    Some((at, line))
                })
                .find(|(_, line)| line.trim() == "[study]");
            source.error(
                header.map(|(start, line)| start..start + line.len()),
                "this is a study file, not a job file: run it with `vtfarm study FILE -o DIR` \
                 (or `vtfarm submit FILE` on a cluster)",
            )
        } else {
            source.toml_error(&e)
        }
    })?;
    let scene = source.scene(raw.scene)?;
    let is_obj = matches!(scene, SceneSource::Obj(_) | SceneSource::Gltf(_));
    let camera_name = raw.camera.camera.as_ref().map(|n| n.get_ref().clone());
    if let (Some(name), false) = (&raw.camera.camera, matches!(scene, SceneSource::Gltf(_))) {
        return Err(source.error_at(
            name,
            "camera.camera names a camera of a glTF scene; this scene has none",
        ));
    }
    let camera = source.camera(&raw.camera, is_obj && camera_name.is_none())?;
    let eyes = source.eyes(&raw.frames, &camera)?;
    let lighting = source.lighting(&raw.lighting)?;
    let (trace, vertex) = source.quality(&raw.quality)?;
    let method = source.method(&raw.quality)?;
    let output = source.output(&raw.output)?;
    // Where the keys checked against the scene stand (see `Job::locations`).
    let c = &raw.camera;
    let mut spans: Vec<(String, Range<usize>)> = [
        ("camera", c.camera.as_ref().map(Spanned::span)),
        ("eye", c.eye.as_ref().map(Spanned::span)),
        ("target", c.target.as_ref().map(Spanned::span)),
        ("up", c.up.as_ref().map(Spanned::span)),
        ("fov_y", c.fov_y.as_ref().map(Spanned::span)),
        ("width", c.width.as_ref().map(Spanned::span)),
        ("height", c.height.as_ref().map(Spanned::span)),
    ]
    .into_iter()
    .filter_map(|(key, span)| Some((format!("camera.{key}"), span?)))
    .collect();
    spans.extend(
        (raw.frames.eyes.iter().enumerate()).map(|(i, e)| (format!("frames.eyes[{i}]"), e.span())),
    );
    let reflectors = source.reflectors(raw.reflectors, is_obj)?;
    spans.extend((reflectors.iter()).filter_map(|(r, span)| Some((r.key(), span.clone()?))));
    let reflectors = reflectors.into_iter().map(|(r, _)| r).collect();
    let materials = (raw.materials.iter())
        .map(|(name, m)| source.material(name, m))
        .collect::<Result<Vec<_>, _>>()?;
    for (name, m) in &raw.materials {
        let key = MaterialOverride::key_of(name.get_ref());
        if let Some(texture) = &m.texture {
            spans.push((format!("{key}.texture"), texture.span()));
        }
        spans.push((key, name.span()));
    }
    // Every key located in one sweep over the text (linear in its length,
    // however many keys: a job may list 100,000 eye points).
    let starts: Vec<usize> = spans.iter().map(|(_, span)| span.start).collect();
    let locations = (spans.into_iter().map(|(key, _)| key))
        .zip(Location::all(text, &starts))
        .collect();
    Ok(Job {
        materials,
        camera_name,
        locations,
        file: origin.to_owned(),
        scene,
        camera,
        lighting,
        reflectors,
        trace,
        vertex,
        method,
        eyes,
        output,
    })
}

/// The job file being validated, for turning spans into located errors.
pub(crate) struct Source<'a> {
    pub(crate) file: &'a Path,
    pub(crate) text: &'a str,
}

impl Source<'_> {
    /// A TOML syntax or schema error, located and quoting its line (toml's
    /// messages do not name the key; quoting the line does).
    pub(crate) fn toml_error(&self, e: &toml::de::Error) -> JobError {
        let line = e.span().map_or("", |span| self.line_at(span.start).trim());
        let message = e.message().trim_end();
        self.error(
            e.span(),
            if line.is_empty() {
                message.to_owned()
            } else {
                format!("{message}, in `{line}`")
            },
        )
    }

    pub(crate) fn error(&self, span: Option<Range<usize>>, message: impl Into<String>) -> JobError {
        JobError::Invalid {
            file: self.file.to_owned(),
            location: span.map(|span| Location::of(self.text, span.start)),
            message: message.into(),
        }
    }

    /// The text of the line holding byte `offset`.
    pub(crate) fn line_at(&self, offset: usize) -> &str {
        let start = self
            .text
            .get(..offset)
            .and_then(|t| t.rfind('\n'))
            .map_or(0, |i| i + 1);
        self.text[start..].lines().next().unwrap_or("")
    }

    pub(crate) fn error_at<T>(&self, value: &Spanned<T>, message: impl Into<String>) -> JobError {
        self.error(Some(value.span()), message)
    }

    /// A domain bound broken by the value of `key` (a domain type's
    /// `validate` said so), located at that key when it was given.
    pub(crate) fn out_of_bounds<T>(
        &self,
        key: &str,
        value: Option<&Spanned<T>>,
        e: &OutOfBounds,
    ) -> JobError {
        self.error(value.map(Spanned::span), e.message_for(key))
    }

    /// An image side (`camera.width`, `study.height`): [`Camera::check_side`].
    pub(crate) fn image_side(
        &self,
        key: &str,
        value: &Option<Spanned<u32>>,
    ) -> Result<Option<u32>, JobError> {
        value
            .as_ref()
            .map(|v| {
                Camera::check_side("side", *v.get_ref())
                    .map_err(|e| self.out_of_bounds(key, Some(v), &e))
            })
            .transpose()
    }

    /// A given width and height: [`Camera::check_size`] (each side, and the
    /// pixel count against the memory bound), located at the height.
    pub(crate) fn image_size(
        &self,
        table: &str,
        width: &Option<Spanned<u32>>,
        height: &Option<Spanned<u32>>,
    ) -> Result<(Option<u32>, Option<u32>), JobError> {
        let w = self.image_side(&format!("{table}.width"), width)?;
        let h = self.image_side(&format!("{table}.height"), height)?;
        if let (Some(w), Some(h)) = (w, h) {
            Camera::check_size(w, h).map_err(|e| {
                self.out_of_bounds(
                    &format!("{table}.width × {table}.height"),
                    height.as_ref(),
                    &e,
                )
            })?;
        }
        Ok((w, h))
    }

    /// The value if `ok` accepts it, else "`key = value`: must be {rule}".
    pub(crate) fn check<T: Copy + Display>(
        &self,
        key: &str,
        value: &Spanned<T>,
        rule: &str,
        ok: impl FnOnce(T) -> bool,
    ) -> Result<T, JobError> {
        let v = *value.get_ref();
        if ok(v) {
            Ok(v)
        } else {
            Err(self.error_at(value, format!("{key} = {v}: must be {rule}")))
        }
    }

    pub(crate) fn check_opt<T: Copy + Display>(
        &self,
        key: &str,
        value: &Option<Spanned<T>>,
        rule: &str,
        ok: impl FnOnce(T) -> bool,
    ) -> Result<Option<T>, JobError> {
        value
            .as_ref()
            .map(|v| self.check(key, v, rule, ok))
            .transpose()
    }

    /// A vector whose components satisfy `ok` (finite, at least).
    pub(crate) fn vec3(
        &self,
        key: &str,
        value: &Vec3Value,
        rule: &str,
        ok: fn(f32) -> bool,
    ) -> Result<Vec3, JobError> {
        let v = Vec3::from_array(*value.get_ref());
        if v.to_array().into_iter().all(|c| c.is_finite() && ok(c)) {
            Ok(v)
        } else {
            Err(self.error_at(value, format!("{key} = {v}: must be {rule}")))
        }
    }

    /// A point: finite and within [`bounds::MAX_COORDINATE`].
    pub(crate) fn point(
        &self,
        key: &str,
        value: &Option<Vec3Value>,
    ) -> Result<Option<Vec3>, JobError> {
        self.checked(key, value, |v| bounds::point("point", Vec3::from_array(v)))
    }

    pub(crate) fn color(
        &self,
        key: &str,
        value: &Option<Vec3Value>,
    ) -> Result<Option<Vec3>, JobError> {
        value
            .as_ref()
            .map(|v| self.vec3(key, v, "finite and not negative", |c| c >= 0.0))
            .transpose()
    }

    /// The cockpit's cover-glass design from `glass` (and `glass_tilt` /
    /// `glass_radius` for the designs that need them); `table` names the
    /// keys' table in messages (`scene`, `variants[2]`).
    pub(crate) fn glass_design(
        &self,
        table: &str,
        glass: &Option<Spanned<String>>,
        tilt: &Option<Spanned<f32>>,
        radius: &Option<Spanned<f32>>,
    ) -> Result<GlassDesign, JobError> {
        const DESIGNS: &str = "current, flat, flat-tilted, cylindrical, ellipsoidal";
        let Some(name) = glass else {
            return Ok(GlassDesign::Current);
        };
        let needs = |key: &str, value: Option<f32>| {
            value.ok_or_else(|| {
                self.error_at(
                    name,
                    format!("{table}.glass = {:?} needs {table}.{key}", name.get_ref()),
                )
            })
        };
        Ok(match name.get_ref().as_str() {
            "current" => GlassDesign::Current,
            "flat" => GlassDesign::Flat,
            "ellipsoidal" => GlassDesign::Ellipsoidal,
            "flat-tilted" => GlassDesign::FlatTilted {
                degrees: needs(
                    "glass_tilt",
                    self.check_opt(
                        &format!("{table}.glass_tilt"),
                        tilt,
                        "degrees between -60 and 60",
                        |d| d.is_finite() && d.abs() <= 60.0,
                    )?,
                )?,
            },
            "cylindrical" => GlassDesign::Cylindrical {
                radius: needs(
                    "glass_radius",
                    self.check_opt(
                        &format!("{table}.glass_radius"),
                        radius,
                        "metres, at least 0.15",
                        |r| r.is_finite() && r >= 0.15,
                    )?,
                )?,
            },
            other => {
                return Err(self.error_at(
                    name,
                    format!("unknown {table}.glass {other:?}; valid: {DESIGNS}"),
                ));
            }
        })
    }

    /// An OBJ path relative to the file's directory, which must exist.
    pub(crate) fn existing_file(
        &self,
        key: &str,
        path: &Spanned<PathBuf>,
    ) -> Result<PathBuf, JobError> {
        // Relative to the file, so a job and its model move together.
        let dir = self.file.parent().unwrap_or(Path::new(""));
        let resolved = dir.join(path.get_ref());
        if resolved.is_file() {
            Ok(resolved)
        } else {
            let message = format!(
                "{key}: no such file {} (a relative path is relative to the directory of {})",
                resolved.display(),
                self.file.display()
            );
            Err(self.error_at(path, message))
        }
    }

    fn scene(&self, raw: Option<Spanned<RawScene>>) -> Result<SceneSource, JobError> {
        const WHICH: &str = "set one of builtin = \"cockpit\", obj = \"path/to/model.obj\" or gltf = \"path/to/model.glb\"";
        let Some(raw) = raw else {
            return Err(self.error(None, format!("missing [scene]: {WHICH}")));
        };
        let span = raw.span();
        let mut raw = raw.into_inner();
        if let Some(gltf) = raw.gltf.take() {
            if let Some(other) = raw
                .builtin
                .as_ref()
                .map(Spanned::span)
                .or(raw.obj.as_ref().map(Spanned::span))
            {
                return Err(self.error(Some(other), format!("[scene]: {WHICH}, not two")));
            }
            let builtin_only = [
                ("detail", raw.detail.map(|v| v.span())),
                ("glass_segments", raw.glass_segments.map(|v| v.span())),
                ("glass", raw.glass.map(|v| v.span())),
                ("glass_tilt", raw.glass_tilt.map(|v| v.span())),
                ("glass_radius", raw.glass_radius.map(|v| v.span())),
            ];
            if let Some((key, span)) = builtin_only.into_iter().find_map(|(k, s)| Some((k, s?))) {
                return Err(self.error(
                    Some(span),
                    format!("scene.{key} applies to builtin scenes only, not to gltf"),
                ));
            }
            return Ok(SceneSource::Gltf(self.existing_file("scene.gltf", &gltf)?));
        }
        match (raw.builtin.clone(), raw.obj.clone()) {
            (Some(_), Some(obj)) => Err(self.error_at(&obj, format!("[scene]: {WHICH}, not both"))),
            (None, None) => Err(self.error(Some(span), format!("[scene]: {WHICH}"))),
            (Some(name), None) => {
                if !BUILTINS.contains(&name.get_ref().as_str()) {
                    let message = format!(
                        "unknown scene.builtin {:?}; valid: {}",
                        name.get_ref(),
                        BUILTINS.join(", ")
                    );
                    return Err(self.error_at(&name, message));
                }
                let default = CockpitConfig::default();
                let glass =
                    self.glass_design("scene", &raw.glass, &raw.glass_tilt, &raw.glass_radius)?;
                let config = CockpitConfig {
                    glass,
                    detail: raw.detail.as_ref().map_or(default.detail, |d| *d.get_ref()),
                    glass_segments: (raw.glass_segments.as_ref())
                        .map_or(default.glass_segments, |n| *n.get_ref()),
                };
                config.validate().map_err(|e| match e.field {
                    "detail" => self.out_of_bounds("scene.detail", raw.detail.as_ref(), &e),
                    _ => {
                        self.out_of_bounds("scene.glass_segments", raw.glass_segments.as_ref(), &e)
                    }
                })?;
                Ok(SceneSource::Cockpit(config))
            }
            (None, Some(obj)) => {
                let builtin_only = [
                    ("detail", raw.detail.map(|v| v.span())),
                    ("glass_segments", raw.glass_segments.map(|v| v.span())),
                    ("glass", raw.glass.map(|v| v.span())),
                    ("glass_tilt", raw.glass_tilt.map(|v| v.span())),
                    ("glass_radius", raw.glass_radius.map(|v| v.span())),
                ];
                if let Some((key, span)) = builtin_only.into_iter().find_map(|(k, s)| Some((k, s?)))
                {
                    return Err(self.error(
                        Some(span),
                        format!("scene.{key} applies to builtin scenes only, not to obj"),
                    ));
                }
                let path = self.existing_file("scene.obj", &obj)?;
                Ok(SceneSource::Obj(path))
            }
        }
    }

    fn camera(&self, raw: &RawCamera, is_obj: bool) -> Result<CameraSpec, JobError> {
        let (width, height) = self.image_size("camera", &raw.width, &raw.height)?;
        let mut spec = CameraSpec {
            eye: self.point("camera.eye", &raw.eye)?,
            target: self.point("camera.target", &raw.target)?,
            up: self.checked("camera.up", &raw.up, |v| {
                Camera::check_up(Vec3::from_array(v))
            })?,
            fov_y_deg: self.checked("camera.fov_y", &raw.fov_y, Camera::check_fov)?,
            width,
            height,
        };
        if is_obj {
            spec.up.get_or_insert(Vec3::Y);
            if let Err(missing) = spec.complete() {
                return Err(self.error(None, obj_camera_missing(&missing)));
            }
        }
        // Check the view here when it is fully known, to point at a line;
        // otherwise `Job::frames` checks it against the cockpit's camera.
        if let (Some(eye), Some(target), Some(up)) = (spec.eye, spec.target, spec.up) {
            if let Err(e) = Camera::check_view(eye, target, up) {
                // Point at the key most likely wrong (up may be the OBJ default).
                let (key, blamed) = match e.field {
                    "up" if raw.up.is_some() => ("camera.up", &raw.up),
                    "up" => ("camera.target", &raw.target),
                    _ => ("camera.eye", &raw.eye),
                };
                return Err(self.out_of_bounds(key, blamed.as_ref(), &e));
            }
        }
        Ok(spec)
    }

    /// A given value that `validate` (a domain type's check) accepts.
    fn checked<T: Copy, U>(
        &self,
        key: &str,
        value: &Option<Spanned<T>>,
        validate: impl FnOnce(T) -> Result<U, OutOfBounds>,
    ) -> Result<Option<U>, JobError> {
        value
            .as_ref()
            .map(|v| validate(*v.get_ref()).map_err(|e| self.out_of_bounds(key, Some(v), &e)))
            .transpose()
    }

    fn eyes(&self, raw: &RawFrames, camera: &CameraSpec) -> Result<Vec<Vec3>, JobError> {
        raw.eyes
            .iter()
            .enumerate()
            .map(|(i, value)| {
                let key = format!("frames.eyes[{i}]");
                let eye = bounds::point("eye", Vec3::from_array(*value.get_ref()))
                    .map_err(|e| self.out_of_bounds(&key, Some(value), &e))?;
                if let (Some(target), Some(up)) = (camera.target, camera.up) {
                    if let Err(e) = Camera::check_view(eye, target, up) {
                        return Err(self.error_at(value, e.message_for(&key)));
                    }
                }
                Ok(eye)
            })
            .collect()
    }

    fn lighting(&self, raw: &RawLighting) -> Result<LightingSpec, JobError> {
        if let Some(lights) = &raw.lights {
            Lighting::validate_count(lights.len()).map_err(|e| {
                let first_too_many = lights.get(Lighting::MAX_LIGHTS).map(|l| &l.kind);
                self.out_of_bounds("lighting.lights", first_too_many, &e)
            })?;
        }
        Ok(LightingSpec {
            lights: raw
                .lights
                .as_ref()
                .map(|lights| {
                    lights
                        .iter()
                        .enumerate()
                        .map(|(i, l)| self.light(i, l))
                        .collect()
                })
                .transpose()?,
            ambient: self.photometric_or_color(
                ("lighting.ambient", &raw.ambient),
                (
                    "lighting.ambient_illuminance_lux",
                    &raw.ambient_illuminance_lux,
                ),
                photometry::ambient,
            )?,
            background: self.photometric_or_color(
                ("lighting.background", &raw.background),
                (
                    "lighting.background_luminance_cd_m2",
                    &raw.background_luminance_cd_m2,
                ),
                photometry::grey,
            )?,
        })
    }

    /// A colour given either in render units (`color_key`) or as a grey of
    /// the photometric quantity under `unit_key`, converted by `convert`;
    /// giving both is an error at the second.
    fn photometric_or_color(
        &self,
        (color_key, color): (&str, &Option<Vec3Value>),
        (unit_key, value): (&str, &Option<Spanned<f32>>),
        convert: impl FnOnce(f32) -> Vec3,
    ) -> Result<Option<Vec3>, JobError> {
        match (color, value) {
            (Some(_), Some(v)) => Err(self.error_at(
                v,
                format!("{unit_key}: give {unit_key} or {color_key} (render units), not both"),
            )),
            (None, Some(v)) => Ok(Some(convert(self.check(
                unit_key,
                v,
                "finite and not negative",
                |x| x.is_finite() && x >= 0.0,
            )?))),
            (_, None) => self.color(color_key, color),
        }
    }

    fn light(&self, index: usize, raw: &RawLight) -> Result<Light, JobError> {
        let key = |name: &str| format!("lighting.lights[{index}].{name}");
        let kind = *raw.kind.get_ref();
        let (needs, forbids, needed, forbidden) = match kind {
            RawLightKind::Point => ("position", "direction", &raw.position, &raw.direction),
            RawLightKind::Directional => ("direction", "position", &raw.direction, &raw.position),
        };
        let name = kind.name();
        if let Some(value) = forbidden {
            let message = format!(
                "{}: a {name} light has a {needs}, not a {forbids}",
                key(forbids)
            );
            return Err(self.error_at(value, message));
        }
        let Some(value) = needed else {
            let message = format!("{}: a {name} light needs {needs} = [x, y, z]", key("kind"));
            return Err(self.error_at(&raw.kind, message));
        };
        let v = Vec3::from_array(*value.get_ref());
        let color = raw
            .color
            .as_ref()
            .map_or(Vec3::ONE, |c| Vec3::from_array(*c.get_ref()));
        let light = Light {
            kind: match kind {
                RawLightKind::Point => {
                    if let Some(d) = &raw.angular_diameter_deg {
                        let message = format!(
                            "{}: a point light has no disc; angular_diameter_deg is for directional lights",
                            key("angular_diameter_deg")
                        );
                        return Err(self.error_at(d, message));
                    }
                    LightKind::Point { position: v }
                }
                RawLightKind::Directional => LightKind::Directional {
                    direction: v,
                    // A sun given in lux has the sun's disc unless told
                    // otherwise; a light in render units is a point.
                    angular_diameter_deg: raw.angular_diameter_deg.as_ref().map_or(
                        if raw.illuminance_lux.is_some() {
                            vtfarm_scene::SUN_ANGULAR_DIAMETER_DEG
                        } else {
                            0.0
                        },
                        |d| *d.get_ref(),
                    ),
                },
            },
            color,
            intensity: self.light_intensity(index, kind, raw, color)?,
        };
        // The bounds are the light's own (`Light::validate`); locate them here.
        light.validate().map_err(|e| {
            let (name, span) = match e.field {
                "color" => ("color", raw.color.as_ref().map(Spanned::span)),
                "intensity" => ("intensity", raw.intensity.as_ref().map(Spanned::span)),
                "angular_diameter_deg" => (
                    "angular_diameter_deg",
                    raw.angular_diameter_deg.as_ref().map(Spanned::span),
                ),
                _ => (needs, Some(value.span())),
            };
            self.error(span, e.message_for(&key(name)))
        })?;
        Ok(light)
    }

    /// `intensity` (render units) or, for directional lights,
    /// `illuminance_lux` converted by the photometric convention.
    fn light_intensity(
        &self,
        index: usize,
        kind: RawLightKind,
        raw: &RawLight,
        color: Vec3,
    ) -> Result<f32, JobError> {
        let key = format!("lighting.lights[{index}].illuminance_lux");
        let Some(lux) = &raw.illuminance_lux else {
            return Ok(raw.intensity.as_ref().map_or(1.0, |i| *i.get_ref()));
        };
        if let RawLightKind::Point = kind {
            return Err(self.error_at(
                lux,
                format!("{key}: point lights have no distance falloff, so no photometric unit; give intensity (render units) or make the light directional"),
            ));
        }
        if let Some(intensity) = &raw.intensity {
            return Err(self.error_at(
                intensity,
                format!("lighting.lights[{index}]: give illuminance_lux or intensity (render units), not both"),
            ));
        }
        let lux = self.check(&key, lux, "finite and not negative", |x| {
            x.is_finite() && x >= 0.0
        })?;
        photometry::directional_intensity(color, lux).ok_or_else(|| {
            self.error(
                raw.color.as_ref().map(Spanned::span),
                format!("lighting.lights[{index}].color = {color}: a light given in lux needs a colour with luminance (not black)"),
            )
        })
    }

    fn reflectors(
        &self,
        raw: Option<Spanned<RawReflectors>>,
        is_obj: bool,
    ) -> Result<Vec<LocatedSelector>, JobError> {
        let Some(raw) = raw else {
            return if is_obj {
                Err(self.error(
                    None,
                    "an OBJ scene needs [reflectors] with objects = [...] or materials = [...]",
                ))
            } else {
                Ok(vec![(
                    ReflectorSelector::Object(COVER_GLASS.to_owned()),
                    None,
                )])
            };
        };
        let span = raw.span();
        let raw = raw.into_inner();
        let named = |name: Spanned<String>| (Some(name.span()), name.into_inner());
        let selectors: Vec<LocatedSelector> = (raw.objects.into_iter().map(named))
            .map(|(span, n)| (ReflectorSelector::Object(n), span))
            .chain(
                (raw.materials.into_iter().map(named))
                    .map(|(span, n)| (ReflectorSelector::Material(n), span)),
            )
            .collect();
        if selectors.is_empty() {
            return Err(self.error(
                Some(span),
                "[reflectors] selects nothing: list objects = [...] or materials = [...]",
            ));
        }
        Ok(selectors)
    }

    /// One `[materials."NAME"]` table: every value checked, nothing yet
    /// matched against the scene.
    fn material(
        &self,
        name: &Spanned<String>,
        raw: &RawMaterial,
    ) -> Result<MaterialOverride, JobError> {
        let key = |field: &str| format!("{}.{field}", MaterialOverride::key_of(name.get_ref()));
        let reflectance = |field: &str, value: &Option<Vec3Value>| {
            value
                .as_ref()
                .map(|v| {
                    self.vec3(&key(field), v, "between 0 and 1", |c| {
                        (0.0..=1.0).contains(&c)
                    })
                })
                .transpose()
        };
        let emission = match (&raw.emission_cd_m2, &raw.emission_color) {
            (None, Some(color)) => {
                return Err(self.error_at(
                    color,
                    format!("{}: give emission_cd_m2 too", key("emission_color")),
                ));
            }
            (None, None) => None,
            (Some(cd_m2), color) => {
                let cd_m2 = self.check(
                    &key("emission_cd_m2"),
                    cd_m2,
                    "finite and not negative",
                    |x| x.is_finite() && x >= 0.0,
                )?;
                let color = self
                    .color(&key("emission_color"), color)?
                    .unwrap_or(Vec3::ONE);
                let emission = photometry::emission(color, cd_m2).ok_or_else(|| {
                    self.error(
                        raw.emission_color.as_ref().map(Spanned::span),
                        format!(
                            "{} = {color}: an emitter needs a colour with luminance (not black)",
                            key("emission_color")
                        ),
                    )
                })?;
                Some(emission)
            }
        };
        Ok(MaterialOverride {
            name: name.get_ref().clone(),
            ambient: reflectance("ka", &raw.ka)?,
            diffuse: reflectance("kd", &raw.kd)?,
            specular: reflectance("ks", &raw.ks)?,
            shininess: self.check_opt(
                &key("shininess"),
                &raw.shininess,
                "finite, 0 to 10000",
                |s| s.is_finite() && (0.0..=10_000.0).contains(&s),
            )?,
            reflectance: reflectance("kr", &raw.kr)?,
            transmittance: reflectance("kt", &raw.kt)?,
            ior: self.check_opt(&key("ior"), &raw.ior, "finite, 1 to 4", |n| {
                n.is_finite() && (1.0..=4.0).contains(&n)
            })?,
            thin: raw.thin.unwrap_or(false),
            emission,
            texture: raw
                .texture
                .as_ref()
                .map(|t| self.existing_file(&key("texture"), t))
                .transpose()?,
        })
    }

    fn output(&self, raw: &RawOutput) -> Result<OutputSettings, JobError> {
        let mut output = OutputSettings::default();
        if let Some(white) = &raw.white_cd_m2 {
            let v = *white.get_ref();
            if !(v.is_finite() && v > 0.0) {
                return Err(self.error_at(
                    white,
                    format!("output.white_cd_m2 = {v}: must be a positive, finite luminance"),
                ));
            }
            output.white_cd_m2 = v;
        }
        if let Some(tone) = &raw.tone {
            output.tone = ToneCurve::from_name(tone.get_ref()).ok_or_else(|| {
                let valid: Vec<&str> = ToneCurve::ALL.iter().map(|t| t.name()).collect();
                self.error_at(
                    tone,
                    format!(
                        "unknown output.tone {:?}; valid: {}",
                        tone.get_ref(),
                        valid.join(", ")
                    ),
                )
            })?;
        }
        Ok(output)
    }

    fn method(&self, raw: &RawQuality) -> Result<MethodKind, JobError> {
        let Some(name) = &raw.method else {
            return Ok(MethodKind::default());
        };
        MethodKind::from_name(name.get_ref()).ok_or_else(|| {
            let valid: Vec<&str> = MethodKind::ALL.iter().map(|m| m.name()).collect();
            self.error_at(
                name,
                format!(
                    "unknown quality.method {:?}; valid: {}",
                    name.get_ref(),
                    valid.join(", ")
                ),
            )
        })
    }

    fn quality(&self, raw: &RawQuality) -> Result<(TraceSettings, VertexSettings), JobError> {
        let mut trace = TraceSettings::default();
        let mut vertex = VertexSettings::default();
        if let Some(level) = &raw.level {
            vertex.quality = Quality::from_name(level.get_ref()).ok_or_else(|| {
                let valid: Vec<&str> = Quality::ALL.iter().map(|q| q.name()).collect();
                self.error_at(
                    level,
                    format!(
                        "unknown quality.level {:?}; valid: {}",
                        level.get_ref(),
                        valid.join(", ")
                    ),
                )
            })?;
        }
        if let Some(epsilon) = &raw.epsilon {
            // The file speaks 8-bit steps; the vertex tracer compares colours in 0..1.
            vertex.epsilon = *epsilon.get_ref() / 255.0;
        }
        if let Some(floor) = &raw.pixel_floor {
            vertex.pixel_floor = *floor.get_ref();
        }
        if let Some(flatness) = &raw.flatness {
            vertex.flatness = *flatness.get_ref();
        }
        if let Some(depth) = &raw.max_refine_depth {
            vertex.max_depth = *depth.get_ref();
        }
        if let Some(max_edge) = &raw.max_edge {
            vertex.max_edge = *max_edge.get_ref();
        }
        if let Some(capture) = &raw.capture_cd_m2 {
            vertex.capture_cd_m2 = *capture.get_ref();
        }
        if let Some(name) = &raw.transmission {
            vertex.transmission = Transmission::from_name(name.get_ref()).ok_or_else(|| {
                let valid: Vec<&str> = Transmission::ALL.iter().map(|t| t.name()).collect();
                self.error_at(
                    name,
                    format!(
                        "unknown quality.transmission {:?}; valid: {}",
                        name.get_ref(),
                        valid.join(", ")
                    ),
                )
            })?;
        }
        if let Some(depth) = &raw.max_trace_depth {
            trace.max_depth = *depth.get_ref();
        }
        // The bounds are the settings' own; the file's keys locate them.
        vertex.validate().map_err(|e| match e.field {
            // Quoted in the file's unit, 8-bit steps (the rule does not depend on it).
            "epsilon" => self.error(
                raw.epsilon.as_ref().map(Spanned::span),
                OutOfBounds {
                    value: raw
                        .epsilon
                        .as_ref()
                        .map_or(e.value.clone(), |v| v.get_ref().to_string()),
                    ..e.clone()
                }
                .message_for("quality.epsilon"),
            ),
            "pixel_floor" => {
                self.out_of_bounds("quality.pixel_floor", raw.pixel_floor.as_ref(), &e)
            }
            "flatness" => self.out_of_bounds("quality.flatness", raw.flatness.as_ref(), &e),
            "max_depth" => self.out_of_bounds(
                "quality.max_refine_depth",
                raw.max_refine_depth.as_ref(),
                &e,
            ),
            "max_edge" => self.out_of_bounds("quality.max_edge", raw.max_edge.as_ref(), &e),
            "capture_cd_m2" => {
                self.out_of_bounds("quality.capture_cd_m2", raw.capture_cd_m2.as_ref(), &e)
            }
            // Not a job file key: the defaults are valid.
            _ => self.error(None, format!("quality: vertex {e}")),
        })?;
        trace.validate().map_err(|e| {
            self.out_of_bounds("quality.max_trace_depth", raw.max_trace_depth.as_ref(), &e)
        })?;
        if let Some(fresnel) = raw.fresnel {
            trace.fresnel = fresnel;
        }
        Ok((trace, vertex))
    }
}
