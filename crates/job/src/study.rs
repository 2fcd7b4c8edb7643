//! Study files: a glare study renders every cover-glass design variant from
//! every eye point of a driver's eye ellipse (or an explicit list) and
//! measures the glare of each frame. `configs/cockpit-study.toml` is the
//! annotated reference of the format; [`load_study`] reads one.
//!
//! A study names a base job file for everything the frames share (scene,
//! lighting, reflectors, quality, image size); each variant replaces the
//! scene: a cover-glass design of the built-in cockpit or an OBJ file. Like
//! job files, every mistake (an unknown key, an empty eye ellipse, a variant
//! file that does not exist) is reported with its file and line before any
//! rendering starts.

use std::path::{Path, PathBuf};

use glam::{Mat3, Vec3};
use serde::Deserialize;
use toml::Spanned;

use crate::parse::{Source, Vec3Value};
use crate::{Job, JobError, SceneSource, load_job};

/// Eye points sampled on an eye ellipse besides its centre, by default.
pub const DEFAULT_ELLIPSE_POINTS: u32 = 8;

/// A parsed and validated study file.
#[derive(Clone, Debug, PartialEq)]
pub struct Study {
    /// The study file (named in errors; relative paths are relative to it).
    pub file: PathBuf,
    pub name: String,
    /// The base job: scene, lighting, reflectors, quality and image size.
    pub job: Job,
    /// Overrides of the base job's image size.
    pub width: Option<u32>,
    pub height: Option<u32>,
    /// What every eye point looks at; `None`: the base camera's target
    /// (the cockpit's instrument cluster).
    pub look_at: Option<Vec3>,
    /// The eye points, the nominal eye (ellipse centre) first.
    pub eyes: Vec<Vec3>,
    pub variants: Vec<Variant>,
    pub metrics: MetricsSpec,
}

/// One cover-glass design.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    pub name: String,
    pub scene: SceneSource,
}

/// The `[metrics]` keys; `None` keeps the glare crate's documented default
/// (and its source). Luminances are in cd/m², illuminances in lux.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MetricsSpec {
    /// Reflected luminance above which a glass pixel counts as glare.
    pub veiling_luminance_cd_m2: Option<Sourced>,
    /// Minimum contrast ratio of the markings.
    pub min_contrast: Option<Sourced>,
    /// The ambient condition: diffuse illuminance on the display.
    pub ambient_illuminance_lux: Option<Sourced>,
    /// Diffuse reflectance of the cover glass under the ambient condition.
    pub glass_diffuse_reflectance: Option<f32>,
    /// The heat maps' logarithmic scale (the same for every frame).
    pub heat_min_cd_m2: Option<f32>,
    pub heat_max_cd_m2: Option<f32>,
    /// Objects behind the glass that make up the instrument area.
    pub instrument_objects: Vec<String>,
    /// Objects of the instrument markings (needles, ticks, numerals).
    pub marking_objects: Vec<String>,
}

/// A setting with where it comes from: the study's `<key>_source`, or
/// "set in <study file>" when only the value is given.
#[derive(Clone, Debug, PartialEq)]
pub struct Sourced {
    pub value: f32,
    pub source: String,
}

/// An eye ellipse as automotive eyellipses are given: a centre, three
/// semi-axes along the scene's lateral (x), vertical (y) and fore-aft (z)
/// axes, turned by `tilt` degrees about the lateral axis (the side-view
/// inclination) and then `yaw` degrees about the vertical.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EyeEllipse {
    pub centre: Vec3,
    pub semi_axes: Vec3,
    pub tilt_deg: f32,
    pub yaw_deg: f32,
}

impl EyeEllipse {
    /// The centre, then `n` points spread evenly over the ellipsoid's
    /// surface (a Fibonacci lattice; deterministic).
    pub fn sample(&self, n: u32) -> Vec<Vec3> {
        let rotation = Mat3::from_rotation_y(self.yaw_deg.to_radians())
            * Mat3::from_rotation_x(self.tilt_deg.to_radians());
        let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
        let mut points = vec![self.centre];
        points.extend((0..n).map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).max(0.0).sqrt();
            let phi = golden * i as f32;
            let unit = Vec3::new(r * phi.cos(), y, r * phi.sin());
            self.centre + rotation * (unit * self.semi_axes)
        }));
        points
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStudy {
    study: RawHeader,
    eyes: Option<RawEyes>,
    #[serde(default)]
    variants: Vec<Spanned<RawVariant>>,
    #[serde(default)]
    metrics: RawMetrics,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHeader {
    name: Option<String>,
    job: Spanned<PathBuf>,
    width: Option<Spanned<u32>>,
    height: Option<Spanned<u32>>,
    look_at: Option<Vec3Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEyes {
    points: Option<Spanned<Vec<Vec3Value>>>,
    ellipse: Option<RawEllipse>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEllipse {
    centre: Vec3Value,
    semi_axes: Vec3Value,
    #[serde(default)]
    tilt: f32,
    #[serde(default)]
    yaw: f32,
    points: Option<Spanned<u32>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVariant {
    name: Spanned<String>,
    glass: Option<Spanned<String>>,
    glass_tilt: Option<Spanned<f32>>,
    glass_radius: Option<Spanned<f32>>,
    obj: Option<Spanned<PathBuf>>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMetrics {
    veiling_luminance_cd_m2: Option<Spanned<f32>>,
    veiling_luminance_source: Option<String>,
    min_contrast: Option<Spanned<f32>>,
    min_contrast_source: Option<String>,
    ambient_illuminance_lux: Option<Spanned<f32>>,
    ambient_source: Option<String>,
    glass_diffuse_reflectance: Option<Spanned<f32>>,
    heat_min_cd_m2: Option<Spanned<f32>>,
    heat_max_cd_m2: Option<Spanned<f32>>,
    instrument_objects: Option<Vec<String>>,
    marking_objects: Option<Vec<String>>,
    // Unit-less keys of earlier versions, refused with their replacement.
    veiling_luminance: Option<Spanned<f32>>,
    luminance_scale: Option<Spanned<f32>>,
    heat_scale: Option<Spanned<f32>>,
}

/// The cockpit's instrument area: dial faces, markings, needles and lamps.
pub const COCKPIT_INSTRUMENT_OBJECTS: [&str; 4] =
    ["dial_faces", "dial_markings", "needles", "warning_lamps"];
/// The cockpit's instrument markings.
pub const COCKPIT_MARKING_OBJECTS: [&str; 2] = ["dial_markings", "needles"];

/// Whether the file at `path` is a study file (it has a `[study]` table)
/// rather than a job file; unreadable or broken files count as jobs, whose
/// loader then reports the problem.
pub fn is_study_file(path: &Path) -> bool {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|text| text.parse::<toml::Table>().ok())
        .is_some_and(|table| table.contains_key("study"))
}

/// Reads and validates a study file and its base job.
pub fn load_study(path: &Path) -> Result<Study, JobError> {
    let text = std::fs::read_to_string(path).map_err(|source| JobError::Read {
        file: path.to_owned(),
        source,
    })?;
    parse_study(&text, path)
}

/// Validates the text of a study file (`origin` is its path; the base job
/// file and variant OBJ files are resolved against its directory and must
/// exist).
pub fn parse_study(text: &str, origin: &Path) -> Result<Study, JobError> {
    let source = Source { file: origin, text };
    let raw: RawStudy = toml::from_str(text).map_err(|e| source.toml_error(&e))?;
    let header = raw.study;
    let job_path = source.existing_file("study.job", &header.job)?;
    let job = load_job(&job_path)?;
    let (width, height) = source.image_size("study", &header.width, &header.height)?;
    let look_at = source.point("study.look_at", &header.look_at)?;
    let eyes = source.study_eyes(raw.eyes)?;
    let variants = raw
        .variants
        .iter()
        .enumerate()
        .map(|(i, v)| source.variant(i, v, &job))
        .collect::<Result<Vec<_>, _>>()?;
    if variants.is_empty() {
        return Err(source.error(
            None,
            "a study needs at least one [[variants]] table (name plus glass = \"...\" or obj = \"...\")",
        ));
    }
    if let Some(twin) = variants
        .iter()
        .enumerate()
        .find(|(i, v)| variants[..*i].iter().any(|w| w.name == v.name))
    {
        return Err(source.error_at(
            &raw.variants[twin.0].get_ref().name,
            format!(
                "variants[{}]: the name {:?} is used twice",
                twin.0, twin.1.name
            ),
        ));
    }
    let metrics = source.metrics(&raw.metrics)?;
    Ok(Study {
        file: origin.to_owned(),
        name: header.name.unwrap_or_else(|| {
            origin
                .file_stem()
                .map_or("study".into(), |s| s.to_string_lossy().into_owned())
        }),
        job,
        width,
        height,
        look_at,
        eyes,
        variants,
        metrics,
    })
}

impl Source<'_> {
    fn study_eyes(&self, raw: Option<RawEyes>) -> Result<Vec<Vec3>, JobError> {
        const WHICH: &str = "give [eyes] either points = [[x, y, z], ...] or an [eyes.ellipse]";
        let Some(raw) = raw else {
            return Err(self.error(None, format!("missing [eyes]: {WHICH}")));
        };
        match raw {
            RawEyes {
                points: Some(points),
                ellipse: None,
            } => {
                if points.get_ref().is_empty() {
                    return Err(
                        self.error_at(&points, "eyes.points is empty: list at least one eye point")
                    );
                }
                points
                    .get_ref()
                    .iter()
                    .enumerate()
                    .map(|(i, p)| self.vec3(&format!("eyes.points[{i}]"), p, "finite", |_| true))
                    .collect()
            }
            RawEyes {
                points: None,
                ellipse: Some(ellipse),
            } => self.ellipse(ellipse),
            RawEyes {
                points: Some(points),
                ellipse: Some(_),
            } => Err(self.error_at(&points, format!("[eyes]: {WHICH}, not both"))),
            RawEyes {
                points: None,
                ellipse: None,
            } => Err(self.error(None, format!("[eyes] is empty: {WHICH}"))),
        }
    }

    fn ellipse(&self, raw: RawEllipse) -> Result<Vec<Vec3>, JobError> {
        let centre = self.vec3("eyes.ellipse.centre", &raw.centre, "finite", |_| true)?;
        let semi_axes = self.vec3(
            "eyes.ellipse.semi_axes",
            &raw.semi_axes,
            "metres, finite and not negative",
            |a| a >= 0.0,
        )?;
        if semi_axes == Vec3::ZERO {
            return Err(self.error_at(
                &raw.semi_axes,
                "eyes.ellipse.semi_axes = [0, 0, 0]: the eye ellipse is empty (give its lateral, vertical and fore-aft semi-axes in metres)",
            ));
        }
        for (key, angle) in [("tilt", raw.tilt), ("yaw", raw.yaw)] {
            if !angle.is_finite() {
                return Err(self.error_at(
                    &raw.centre,
                    format!("eyes.ellipse.{key} must be finite degrees"),
                ));
            }
        }
        let n = match &raw.points {
            Some(p) => self.check(
                "eyes.ellipse.points",
                p,
                "at least 1 (eye points besides the centre)",
                |n| (1..=10_000).contains(&n),
            )?,
            None => DEFAULT_ELLIPSE_POINTS,
        };
        Ok(EyeEllipse {
            centre,
            semi_axes,
            tilt_deg: raw.tilt,
            yaw_deg: raw.yaw,
        }
        .sample(n))
    }

    fn variant(
        &self,
        index: usize,
        raw: &Spanned<RawVariant>,
        job: &Job,
    ) -> Result<Variant, JobError> {
        let table = format!("variants[{index}]");
        let v = raw.get_ref();
        let name = v.name.get_ref().trim().to_owned();
        if name.is_empty() {
            return Err(self.error_at(&v.name, format!("{table}.name is empty")));
        }
        let scene = match (&v.obj, &v.glass) {
            (Some(obj), None) => {
                if let Some(key) = [
                    ("glass_tilt", v.glass_tilt.is_some()),
                    ("glass_radius", v.glass_radius.is_some()),
                ]
                .into_iter()
                .find_map(|(k, given)| given.then_some(k))
                {
                    return Err(self.error_at(
                        obj,
                        format!("{table}.{key} applies to glass variants only, not to obj"),
                    ));
                }
                SceneSource::Obj(self.existing_file(&format!("{table}.obj"), obj)?)
            }
            (None, Some(_)) => {
                let SceneSource::Cockpit(config) = &job.scene else {
                    return Err(self.error(
                        Some(raw.span()),
                        format!("{table}: glass variants need a base job with builtin = \"cockpit\" ({} loads an OBJ scene)", job.file.display()),
                    ));
                };
                let glass = self.glass_design(&table, &v.glass, &v.glass_tilt, &v.glass_radius)?;
                SceneSource::Cockpit(crate::CockpitConfig { glass, ..*config })
            }
            (Some(obj), Some(_)) => {
                return Err(self.error_at(
                    obj,
                    format!("{table}: give glass = \"...\" or obj = \"...\", not both"),
                ));
            }
            (None, None) => {
                return Err(self.error(
                    Some(raw.span()),
                    format!("{table} ({name:?}) needs glass = \"current|flat|flat-tilted|cylindrical|ellipsoidal\" or obj = \"path.obj\""),
                ));
            }
        };
        Ok(Variant { name, scene })
    }

    fn metrics(&self, raw: &RawMetrics) -> Result<MetricsSpec, JobError> {
        let retired = [
            (
                &raw.veiling_luminance,
                "metrics.veiling_luminance is unit-less; give veiling_luminance_cd_m2 (cd/m²: the old value times the old luminance_scale, or times 10,000 without one)",
            ),
            (
                &raw.luminance_scale,
                "metrics.luminance_scale is gone: luminances are in cd/m² by vtfarm's photometric convention (10,000 cd/m² per unit of rendered radiance; README, \"Photometric units\")",
            ),
            (
                &raw.heat_scale,
                "metrics.heat_scale is unit-less; give heat_max_cd_m2 (and heat_min_cd_m2) for the heat maps' logarithmic scale in cd/m²",
            ),
        ];
        if let Some((Some(value), why)) = retired.into_iter().find(|(v, _)| v.is_some()) {
            return Err(self.error_at(value, why));
        }
        let positive = |x: f32| x.is_finite() && x > 0.0;
        let names = |given: &Option<Vec<String>>, default: &[&str]| {
            given
                .clone()
                .unwrap_or_else(|| default.iter().map(|s| (*s).to_owned()).collect())
        };
        let given_here = format!("set in {}", self.file.display());
        let sourced = |value: Option<f32>, source: &Option<String>| {
            value.map(|value| Sourced {
                value,
                source: source.clone().unwrap_or_else(|| given_here.clone()),
            })
        };
        let heat_min = self.check_opt(
            "metrics.heat_min_cd_m2",
            &raw.heat_min_cd_m2,
            "positive",
            positive,
        )?;
        let heat_max = self.check_opt(
            "metrics.heat_max_cd_m2",
            &raw.heat_max_cd_m2,
            "positive",
            positive,
        )?;
        if let (Some(lo), Some(hi), Some(at)) = (heat_min, heat_max, &raw.heat_max_cd_m2) {
            if hi <= lo {
                return Err(self.error_at(
                    at,
                    format!("metrics.heat_max_cd_m2 = {hi} must be above heat_min_cd_m2 = {lo}"),
                ));
            }
        }
        Ok(MetricsSpec {
            veiling_luminance_cd_m2: sourced(
                self.check_opt(
                    "metrics.veiling_luminance_cd_m2",
                    &raw.veiling_luminance_cd_m2,
                    "finite and not negative",
                    |x| x.is_finite() && x >= 0.0,
                )?,
                &raw.veiling_luminance_source,
            ),
            min_contrast: sourced(
                self.check_opt(
                    "metrics.min_contrast",
                    &raw.min_contrast,
                    "at least 1",
                    |x| x.is_finite() && x >= 1.0,
                )?,
                &raw.min_contrast_source,
            ),
            ambient_illuminance_lux: sourced(
                self.check_opt(
                    "metrics.ambient_illuminance_lux",
                    &raw.ambient_illuminance_lux,
                    "finite and not negative",
                    |x| x.is_finite() && x >= 0.0,
                )?,
                &raw.ambient_source,
            ),
            glass_diffuse_reflectance: self.check_opt(
                "metrics.glass_diffuse_reflectance",
                &raw.glass_diffuse_reflectance,
                "0 to 1",
                |x| (0.0..=1.0).contains(&x),
            )?,
            heat_min_cd_m2: heat_min,
            heat_max_cd_m2: heat_max,
            instrument_objects: names(&raw.instrument_objects, &COCKPIT_INSTRUMENT_OBJECTS),
            marking_objects: names(&raw.marking_objects, &COCKPIT_MARKING_OBJECTS),
        })
    }
}

impl Study {
    /// The base job with `variant`'s scene.
    pub fn variant_job(&self, variant: &Variant) -> Job {
        Job {
            scene: variant.scene.clone(),
            ..self.job.clone()
        }
    }
}
