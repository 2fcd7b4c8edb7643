//! Glare studies: every cover-glass design variant of a study file rendered
//! from every eye point, each frame measured with `vtfarm-glare`, and the
//! results written as images, `summary.csv`, `summary.json` and a
//! self-contained `report.html`.
//!
//! - [`plan`]: loads every variant's scene and makes its frames (one per
//!   sun position and eye point, each looking at the instrument cluster)
//!   before anything is rendered, so a broken variant fails the study at
//!   once. A sun sweep ([`sun`]) changes only the frames' lighting: frames
//!   of one variant share its scene, so workers keep its BVH.
//! - [`StudyWriter`]: takes rendered frames in any order (from the embedded
//!   farm or a cluster; the frame's pixels do not depend on which), measures
//!   them and writes their images; [`StudyWriter::finish`] writes the
//!   summaries and the report.
//!
//! - [`wire_study`], [`variant_job`]: the study as farm jobs, frames sent
//!   coarse to fine; [`StudyWriter::sent_frame`] maps a frame back.
//!
//! Architecture invariant: no rendering and no networking here; the caller
//! runs the frames (`vtfarm study`, `vtfarm submit`). Outputs are a pure
//! function of the frames, so the same study gives byte-identical files on
//! one machine and on a cluster (no timings in them).

mod farm;
mod glint;
mod masks;
pub mod order;
mod provenance;
mod report;
pub mod sun;
mod table;

use std::path::{Path, PathBuf};

use glam::Vec3;
use serde::Serialize;
use vtfarm_glare::{AmbientCondition, GlareInput, LogRange, Params, Summary, Thresholds};
use vtfarm_job::JobError;
use vtfarm_job::study::{MetricsSpec, Sourced, Study, SunSweep, UtcTime};
use vtfarm_render::FrameSetup;
use vtfarm_scene::{Camera, LightKind, Lighting, ObjectId, Scene, TriangleId};
use vtfarm_vertex::{FrameImage, Quality};

pub use farm::{variant_job, wire_study};
pub use masks::InstrumentMasks;
pub use provenance::{HASH, InputFile, Provenance, RunInfo, command_line, quality_warning};

/// Why a study could not be planned or written.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    #[error(transparent)]
    Job(#[from] JobError),
    #[error(
        "{file}: variant {variant:?}: metrics.{key} names object {object:?}, which the scene lacks (objects: {objects})"
    )]
    UnknownObject {
        file: PathBuf,
        variant: String,
        key: &'static str,
        object: String,
        objects: String,
    },
    #[error("{file}: eye {eye} at {position}: {why}")]
    BadEye {
        file: PathBuf,
        eye: usize,
        position: Vec3,
        why: vtfarm_scene::OutOfBounds,
    },
    #[error("{path}: {cause}")]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error(transparent)]
    Image(#[from] vtfarm_imaging::ImageError),
    #[error("frame of variant {variant} eye {eye}: {why}")]
    Frame {
        variant: usize,
        eye: usize,
        why: String,
    },
    #[error(
        "study {study} has variants of {has:?} frames, {} plans {planned:?}: attach with the study file it was submitted from",
        file.display()
    )]
    OtherStudy {
        study: vtfarm_proto::JobId,
        has: Vec<u32>,
        file: PathBuf,
        planned: Vec<u32>,
    },
    #[error("writing the plots: {0}")]
    Plot(String),
    #[error(
        "{file}: [sun] sweeps the sun, but the base job's lighting has no directional light to turn (add a [[lighting.lights]] with kind = \"directional\")"
    )]
    NoSun { file: PathBuf },
    #[error(
        "{file}: [sun]: the sun is below the horizon at every time of the sweep (from {first} to {last})"
    )]
    SunAlwaysDown {
        file: PathBuf,
        first: UtcTime,
        last: UtcTime,
    },
}

/// One sun position of a study: where the frames' directional lights come
/// from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunPosition {
    /// Degrees relative to the vehicle, clockwise from straight ahead (see
    /// [`sun`]).
    pub azimuth_deg: f32,
    /// Degrees above the horizon.
    pub elevation_deg: f32,
    /// The time of a date/time sweep.
    pub time: Option<UtcTime>,
}

/// One variant ready to render.
#[derive(Clone, Debug)]
pub struct PlannedVariant {
    pub name: String,
    /// A file-name-safe form of the name, unique in the study.
    pub slug: String,
    pub scene: Scene,
    pub reflectors: Vec<TriangleId>,
    /// One set-up per frame: sun by sun, every eye point in the study's
    /// eye order (frame `sun * eyes + eye`; see [`StudyPlan::frame_at`]).
    pub setups: Vec<FrameSetup>,
    instrument_objects: Vec<ObjectId>,
    marking_objects: Vec<ObjectId>,
}

/// A study ready to render.
#[derive(Clone, Debug)]
pub struct StudyPlan {
    pub name: String,
    pub file: PathBuf,
    pub eyes: Vec<Vec3>,
    /// The swept sun positions above the horizon; empty without a `[sun]`
    /// sweep (the base job's sun, [`StudyPlan::base_sun`], lights every frame).
    pub suns: Vec<SunPosition>,
    /// Times of the sweep with the sun below the horizon: not rendered.
    pub suns_below_horizon: Vec<UtcTime>,
    /// A grid sweep's (azimuths, elevations): `suns` holds them elevation
    /// by elevation.
    pub sun_grid: Option<(usize, usize)>,
    /// The direction of the base job's sun, if it has one.
    pub base_sun: Option<SunPosition>,
    pub variants: Vec<PlannedVariant>,
    pub params: Params,
    /// Glass pixels at or above this reflected luminance are the sun's glint.
    pub glint: vtfarm_glare::GlintThreshold,
    /// The heat maps' logarithmic scale, the same for every frame.
    pub heat_range: LogRange,
    /// The base job's reflection method.
    pub method: vtfarm_method::MethodKind,
    /// The quality level of every frame (the base job's, or the command
    /// line's).
    pub quality: Quality,
    /// Every frame's image size, pixels.
    pub width: u32,
    pub height: u32,
    /// The files the study was made from, with their hashes.
    pub inputs: Vec<InputFile>,
    /// The base job's `[output]` exposure of the frames' PNG images.
    pub exposure: vtfarm_imaging::Exposure,
}

impl StudyPlan {
    pub fn frames(&self) -> usize {
        self.variants.len() * self.frames_per_variant()
    }

    /// Frames of one variant: eye points times sun positions.
    pub fn frames_per_variant(&self) -> usize {
        self.eyes.len() * self.suns.len().max(1)
    }

    /// The (sun, eye) of a variant's frame index; the sun is `None` without a
    /// sweep.
    pub fn frame_at(&self, frame: usize) -> (Option<usize>, usize) {
        let eyes = self.eyes.len();
        let sun = (!self.suns.is_empty()).then_some(frame / eyes);
        (sun, frame % eyes)
    }

    /// "eye 3" or "sun 12 eye 3": a variant's frame for the user.
    pub fn frame_name(&self, frame: usize) -> String {
        match self.frame_at(frame) {
            (Some(sun), eye) => format!("sun {sun} eye {eye}"),
            (None, eye) => format!("eye {eye}"),
        }
    }

    /// The sun lighting a frame of the given sun index.
    pub fn sun(&self, sun: Option<usize>) -> Option<SunPosition> {
        sun.map_or(self.base_sun, |s| Some(self.suns[s]))
    }
}

/// The sun positions of a sweep, those above the horizon first, then the
/// times with the sun below it.
fn sun_positions(sweep: &SunSweep) -> (Vec<SunPosition>, Vec<UtcTime>) {
    match sweep {
        SunSweep::Grid {
            azimuths_deg,
            elevations_deg,
        } => {
            let positions = elevations_deg
                .iter()
                .flat_map(|&elevation_deg| {
                    azimuths_deg.iter().map(move |&azimuth_deg| SunPosition {
                        azimuth_deg: azimuth_deg.rem_euclid(360.0),
                        elevation_deg,
                        time: None,
                    })
                })
                .collect();
            (positions, Vec::new())
        }
        SunSweep::Times {
            times,
            latitude_deg,
            longitude_deg,
            heading_deg,
        } => {
            let mut up = Vec::new();
            let mut down = Vec::new();
            for &time in times {
                let p =
                    sun::solar_position(time.unix_seconds as f64, *latitude_deg, *longitude_deg);
                if p.elevation_deg > 0.0 {
                    up.push(SunPosition {
                        azimuth_deg: sun::relative_azimuth_deg(p.azimuth_deg, *heading_deg) as f32,
                        elevation_deg: p.elevation_deg as f32,
                        time: Some(time),
                    });
                } else {
                    down.push(time);
                }
            }
            (up, down)
        }
    }
}

/// `base` with every directional light (the sun) coming from `sun`.
fn lighting_with_sun(base: &Lighting, sun: &SunPosition) -> Lighting {
    let travel = -sun::direction_to_sun(sun.azimuth_deg, sun.elevation_deg);
    let mut lighting = base.clone();
    for light in &mut lighting.lights {
        if let LightKind::Directional { direction, .. } = &mut light.kind {
            *direction = travel;
        }
    }
    lighting
}

/// The direction of the first directional light of `lighting`.
fn base_sun(lighting: &Lighting) -> Option<SunPosition> {
    lighting.lights.iter().find_map(|light| match light.kind {
        LightKind::Directional { direction, .. } => {
            let (azimuth_deg, elevation_deg) = sun::vehicle_angles(-direction);
            Some(SunPosition {
                azimuth_deg,
                elevation_deg,
                time: None,
            })
        }
        LightKind::Point { .. } => None,
    })
}

/// Default bottom of the heat maps' scale.
pub const DEFAULT_HEAT_MIN_CD_M2: f32 = 1.0;
/// Default top of the heat maps' scale: a strong window reflection.
pub const DEFAULT_HEAT_MAX_CD_M2: f32 = 10_000.0;

/// The glare parameters of a study's `[metrics]`: each given value with its
/// source, the glare crate's documented defaults (and theirs) otherwise.
fn glare_params(metrics: &MetricsSpec) -> Params {
    let defaults = Params::default();
    let pick = |given: &Option<Sourced>, value: f32, source: String| {
        given
            .as_ref()
            .map_or((value, source), |s| (s.value, s.source.clone()))
    };
    let (min_contrast, min_contrast_source) = pick(
        &metrics.min_contrast,
        defaults.thresholds.min_contrast,
        defaults.thresholds.min_contrast_source,
    );
    let (veiling_luminance_cd_m2, veiling_luminance_source) = pick(
        &metrics.veiling_luminance_cd_m2,
        defaults.thresholds.veiling_luminance_cd_m2,
        defaults.thresholds.veiling_luminance_source,
    );
    let (illuminance_lux, source) = pick(
        &metrics.ambient_illuminance_lux,
        defaults.ambient.illuminance_lux,
        defaults.ambient.source,
    );
    Params {
        thresholds: Thresholds {
            min_contrast,
            min_contrast_source,
            veiling_luminance_cd_m2,
            veiling_luminance_source,
        },
        ambient: AmbientCondition {
            illuminance_lux,
            glass_diffuse_reflectance: metrics
                .glass_diffuse_reflectance
                .unwrap_or(defaults.ambient.glass_diffuse_reflectance),
            source,
        },
        ..defaults
    }
}

/// Reads a study file and plans it ([`plan`]): every variant loaded before
/// anything renders.
pub fn plan_file(path: &Path, quality: Option<Quality>) -> Result<StudyPlan, StudyError> {
    plan(&vtfarm_job::study::load_study(path)?, quality)
}

/// Loads every variant's scene and makes the frames; `quality` overrides the
/// base job's level.
pub fn plan(study: &Study, quality: Option<Quality>) -> Result<StudyPlan, StudyError> {
    let params = glare_params(&study.metrics);
    let heat_range = LogRange {
        min_cd_m2: study
            .metrics
            .heat_min_cd_m2
            .unwrap_or(DEFAULT_HEAT_MIN_CD_M2),
        max_cd_m2: study
            .metrics
            .heat_max_cd_m2
            .unwrap_or(DEFAULT_HEAT_MAX_CD_M2),
    };
    // The base job's own scene gives the lighting and the camera every
    // variant shares, so that designs are compared under the same light.
    let base = study.job.load_scene()?;
    let base_sun = base_sun(&base.lighting);
    let (suns, suns_below_horizon) = study.sun.as_ref().map(sun_positions).unwrap_or_default();
    let sun_grid = match &study.sun {
        Some(SunSweep::Grid {
            azimuths_deg,
            elevations_deg,
        }) => Some((azimuths_deg.len(), elevations_deg.len())),
        _ => None,
    };
    if study.sun.is_some() {
        if base_sun.is_none() {
            return Err(StudyError::NoSun {
                file: study.file.clone(),
            });
        }
        if suns.is_empty() {
            return Err(StudyError::SunAlwaysDown {
                file: study.file.clone(),
                first: suns_below_horizon[0],
                last: suns_below_horizon[suns_below_horizon.len() - 1],
            });
        }
    }
    // One lighting per sun position (the base lighting without a sweep).
    let lightings: Vec<Lighting> = if suns.is_empty() {
        vec![base.lighting.clone()]
    } else {
        suns.iter()
            .map(|s| lighting_with_sun(&base.lighting, s))
            .collect()
    };
    // The same eye points for every variant.
    let cameras = study
        .eyes
        .iter()
        .enumerate()
        .map(|(i, &eye)| {
            eye_camera(study, &base.camera, eye).map_err(|why| StudyError::BadEye {
                file: study.file.clone(),
                eye: i,
                position: eye,
                why,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let vertex = vtfarm_vertex::VertexSettings {
        quality: quality.unwrap_or(study.job.vertex.quality),
        ..study.job.vertex
    };
    let mut variants = Vec::with_capacity(study.variants.len());
    let mut slugs: Vec<String> = Vec::new();
    for variant in &study.variants {
        let job = study.variant_job(variant);
        let vtfarm_job::JobScene {
            scene,
            object_aliases,
        } = job.scene_only()?;
        let reflectors = job.reflector_triangles(&scene, &object_aliases)?;
        let objects = |key: &'static str, names: &[String]| {
            names
                .iter()
                .map(|n| {
                    scene.object_id(n).ok_or_else(|| StudyError::UnknownObject {
                        file: study.file.clone(),
                        variant: variant.name.clone(),
                        key,
                        object: n.clone(),
                        objects: scene
                            .objects
                            .iter()
                            .map(|o| o.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", "),
                    })
                })
                .collect::<Result<Vec<_>, _>>()
        };
        let instrument_objects = objects("instrument_objects", &study.metrics.instrument_objects)?;
        let marking_objects = objects("marking_objects", &study.metrics.marking_objects)?;
        let setups = lightings
            .iter()
            .flat_map(|lighting| {
                cameras.iter().map(|&camera| FrameSetup {
                    camera,
                    lighting: lighting.clone(),
                    trace: study.job.trace,
                    vertex,
                })
            })
            .collect();
        let slug = unique_slug(&variant.name, &slugs);
        slugs.push(slug.clone());
        variants.push(PlannedVariant {
            name: variant.name.clone(),
            slug,
            scene,
            reflectors,
            setups,
            instrument_objects,
            marking_objects,
        });
    }
    Ok(StudyPlan {
        name: study.name.clone(),
        file: study.file.clone(),
        eyes: study.eyes.clone(),
        suns,
        suns_below_horizon,
        base_sun,
        variants,
        params,
        glint: (study.metrics.glint_luminance_cd_m2.as_ref()).map_or_else(
            vtfarm_glare::GlintThreshold::default,
            |s| vtfarm_glare::GlintThreshold {
                luminance_cd_m2: s.value,
                source: s.source.clone(),
            },
        ),
        heat_range,
        method: study.job.method,
        quality: vertex.quality,
        width: cameras.first().map_or(0, |c| c.width),
        height: cameras.first().map_or(0, |c| c.height),
        inputs: provenance::input_files(study)?,
        sun_grid,
        exposure: study.job.output.exposure(),
    })
}

/// The camera of one eye point: the base camera moved to `eye`, looking at
/// the study's `look_at` (default: the base camera's target).
fn eye_camera(
    study: &Study,
    base: &Camera,
    eye: Vec3,
) -> Result<Camera, vtfarm_scene::OutOfBounds> {
    let camera = Camera {
        eye,
        target: study.look_at.unwrap_or(base.target),
        width: study.width.unwrap_or(base.width),
        height: study.height.unwrap_or(base.height),
        ..*base
    };
    camera.validate()?;
    Ok(camera)
}

/// Lower-case letters, digits and dashes; numbered when taken.
fn unique_slug(name: &str, taken: &[String]) -> String {
    let mut slug = String::new();
    for c in name.chars() {
        if c.is_ascii_alphanumeric() {
            slug.push(c.to_ascii_lowercase());
        } else if !slug.ends_with('-') && !slug.is_empty() {
            slug.push('-');
        }
    }
    let slug = slug.trim_end_matches('-');
    let base = if slug.is_empty() { "variant" } else { slug };
    let mut candidate = base.to_owned();
    let mut n = 2;
    while taken.contains(&candidate) {
        candidate = format!("{base}-{n}");
        n += 1;
    }
    candidate
}

/// One measured frame: a row of `summary.csv`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameRow {
    pub variant: String,
    pub eye_index: usize,
    pub eye: [f32; 3],
    /// Index into the study's sun sweep; `None` without one.
    pub sun_index: Option<usize>,
    /// The swept sun's direction relative to the vehicle; `None` without a
    /// sweep (a fixed sun is the study's, [`StudyPlan::sun_setting`]).
    pub sun_azimuth_deg: Option<f32>,
    pub sun_elevation_deg: Option<f32>,
    /// The UTC time of a date/time sweep (RFC 3339).
    pub sun_time: Option<String>,
    /// Images relative to the output directory.
    pub image: String,
    pub heat_map: String,
    pub object_map: String,
    pub summary: Summary,
    /// The sun's glint in the frame (none below the glint threshold).
    pub glint: vtfarm_glare::Glint,
    /// The marking contrast with the glint's veiling luminance added (the
    /// direct-sun case); `None` without a glint or markings.
    pub direct_sun_contrast: Option<f32>,
}

/// Measures frames and writes their outputs.
pub struct StudyWriter<'a> {
    plan: &'a StudyPlan,
    dir: PathBuf,
    rows: Vec<Option<FrameRow>>,
}

impl<'a> StudyWriter<'a> {
    /// Creates the output directory.
    pub fn new(plan: &'a StudyPlan, dir: &Path) -> Result<Self, StudyError> {
        std::fs::create_dir_all(dir).map_err(|cause| StudyError::Io {
            path: dir.to_owned(),
            cause,
        })?;
        Ok(StudyWriter {
            plan,
            dir: dir.to_owned(),
            rows: vec![None; plan.frames()],
        })
    }

    /// Measures rendered frame `frame` of `variant` (an index into its
    /// set-ups: [`StudyPlan::frame_at`] gives its sun and eye; its colour
    /// with the reflected/transmitted components and the reflected-object
    /// map) and writes its image, heat map and object map.
    pub fn frame(
        &mut self,
        variant: usize,
        frame_index: usize,
        frame: &FrameImage,
    ) -> Result<&FrameRow, StudyError> {
        let (sun, eye) = self.plan.frame_at(frame_index);
        let bad = |why: String| StudyError::Frame { variant, eye, why };
        let planned = self
            .plan
            .variants
            .get(variant)
            .ok_or_else(|| bad("no such variant".into()))?;
        let setup = planned
            .setups
            .get(frame_index)
            .ok_or_else(|| bad("no such frame".into()))?;
        let camera = setup.camera;
        if (frame.color.width, frame.color.height) != (camera.width, camera.height) {
            return Err(bad(format!(
                "size {}x{}, expected {}x{}",
                frame.color.width, frame.color.height, camera.width, camera.height
            )));
        }
        let components = frame.components();
        let masks = InstrumentMasks::new(
            &planned.scene,
            &camera,
            &planned.reflectors,
            &components.mask,
            &planned.instrument_objects,
            &planned.marking_objects,
        );
        let names: Vec<String> = planned
            .scene
            .objects
            .iter()
            .map(|o| o.name.clone())
            .collect();
        let input =
            GlareInput::from_components(&components, &masks.instrument, &masks.marking, &names);
        let params = &self.plan.params;
        let analysis = vtfarm_glare::analyze(&input, params).map_err(|e| bad(e.to_string()))?;
        // The legends are the report's, as text beside the maps.
        let (heat, _) = vtfarm_glare::heat_map_frame(&input, params, Some(self.plan.heat_range))
            .map_err(|e| bad(e.to_string()))?;
        let (objects, _) =
            vtfarm_glare::object_map_frame(&input, params).map_err(|e| bad(e.to_string()))?;

        let rel = match sun {
            Some(sun) => format!("{}/sun_{sun:03}/eye_{eye:02}", planned.slug),
            None => format!("{}/eye_{eye:02}", planned.slug),
        };
        let dir = self.dir.join(&rel);
        std::fs::create_dir_all(&dir).map_err(|cause| StudyError::Io {
            path: dir.clone(),
            cause,
        })?;
        frame
            .color
            .write_png_exposed(&dir.join("image.png"), &self.plan.exposure)?;
        // The linear frame in cd/m² with its components as layers.
        vtfarm_render::output::write_exr(&dir.join("image.exr"), &frame.color, Some(&components))?;
        heat.write_png(&dir.join("heat.png"))?;
        objects.write_png(&dir.join("objects.png"))?;
        // The per-pixel figures, for engineers' own analysis (0 off the
        // glass; contrast NaN where it is not evaluated).
        let shape = [camera.height as usize, camera.width as usize];
        let contrast: Vec<f32> = analysis
            .contrast
            .per_pixel
            .iter()
            .map(|c| c.unwrap_or(f32::NAN))
            .collect();
        for (name, data) in [
            ("reflected_luminance", &analysis.reflected_luminance),
            ("transmitted_luminance", &analysis.transmitted_luminance),
            ("veiling_ratio", &analysis.veiling_ratio),
            ("contrast", &contrast),
        ] {
            vtfarm_imaging::write_npy_f32(&dir.join(format!("{name}.npy")), &shape, data)?;
        }
        let (glint, direct_sun_contrast) = glint::frame_glint(
            &planned.scene,
            &camera,
            &masks,
            &analysis.reflected_luminance,
            &analysis.summary,
            &self.plan.glint,
        );
        // A frame names its sun only in a sweep (see `SunSetting`).
        let sun_position = sun.map(|s| self.plan.suns[s]);
        let row = FrameRow {
            variant: planned.name.clone(),
            eye_index: eye,
            eye: self.plan.eyes[eye].to_array(),
            sun_index: sun,
            sun_azimuth_deg: sun_position.map(|s| s.azimuth_deg),
            sun_elevation_deg: sun_position.map(|s| s.elevation_deg),
            sun_time: sun_position.and_then(|s| s.time).map(|t| t.to_string()),
            image: format!("{rel}/image.png"),
            heat_map: format!("{rel}/heat.png"),
            object_map: format!("{rel}/objects.png"),
            summary: analysis.summary,
            glint,
            direct_sun_contrast,
        };
        let slot = &mut self.rows[variant * self.plan.frames_per_variant() + frame_index];
        Ok(slot.insert(row))
    }

    /// Writes `summary.csv`, `summary.json` and `report.html` made as `run`
    /// says; fails naming the first frame that is missing.
    pub fn finish(self, run: &RunInfo) -> Result<StudyReport, StudyError> {
        if let Some(m) = self.missing().first() {
            return Err(StudyError::Frame {
                variant: m.variant_index,
                eye: m.eye_index,
                why: "never rendered".into(),
            });
        }
        self.finish_partial(run)
    }

    /// The frames not measured yet, in frame order.
    pub fn missing(&self) -> Vec<MissingFrame> {
        let per_variant = self.plan.frames_per_variant();
        (self.rows.iter().enumerate())
            .filter(|(_, r)| r.is_none())
            .map(|(i, _)| {
                let (sun_index, eye_index) = self.plan.frame_at(i % per_variant);
                MissingFrame {
                    variant_index: i / per_variant,
                    variant: self.plan.variants[i / per_variant].name.clone(),
                    sun_index,
                    eye_index,
                }
            })
            .collect()
    }

    /// Frames measured so far.
    pub fn done(&self) -> usize {
        self.rows.iter().filter(|r| r.is_some()).count()
    }

    /// Writes the summaries and the report from the frames measured so far
    /// (a study not finished: interrupted, or followed while it runs); they
    /// list the frames they lack.
    pub fn finish_partial(self, run: &RunInfo) -> Result<StudyReport, StudyError> {
        let missing = self.missing();
        let rows = self.rows.into_iter().flatten().collect();
        let provenance = provenance::Provenance::new(self.plan, run);
        report::write_all(self.plan, &self.dir, rows, &provenance, missing)
    }
}

/// A frame a report lacks.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MissingFrame {
    #[serde(skip)]
    pub variant_index: usize,
    pub variant: String,
    pub sun_index: Option<usize>,
    pub eye_index: usize,
}

/// What [`StudyWriter::finish`] wrote.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StudyReport {
    pub frames: Vec<FrameRow>,
    /// Frames not rendered (a partial report); empty when complete.
    pub missing_frames: Vec<MissingFrame>,
    /// Variants best first.
    pub ranking: Vec<VariantScore>,
}

/// A variant's figures over all eye points; the ranking sorts by the mean
/// glare area share, then the worst low-contrast share, then the mean
/// reflected luminance (all lower is better).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct VariantScore {
    pub variant: String,
    pub mean_glare_area_share: f32,
    pub worst_glare_area_share: f32,
    pub worst_low_contrast_share: f32,
    pub mean_reflected_luminance_cd_m2: f32,
    pub peak_reflected_luminance_cd_m2: f32,
    /// The objects causing the glare over all the variant's frames, the
    /// culprit first (at most [`CULPRITS`]; none without glare): by the
    /// glare area they cause, then the luminance they add above the
    /// threshold ([`vtfarm_glare::rank_objects`], summed over the frames).
    pub glare_culprits: Vec<Culprit>,
    /// The object whose reflection covers the most glass over all frames,
    /// at any luminance (not necessarily a glare source), and its share of
    /// the glass.
    pub most_covering_object: Option<Coverage>,
    /// The variant's worst frames, worst first (by mean reflected
    /// luminance): where the sun and the eye make the glass brightest.
    pub worst_cases: Vec<WorstCase>,
}

/// Culprits named per frame and per variant.
pub const CULPRITS: usize = 3;

/// An object causing glare, and how much of it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Culprit {
    pub name: String,
    /// Glass pixels over the glare threshold whose reflection shows it.
    pub glare_pixels: usize,
    /// `glare_pixels` / all glare pixels (of the frame or the variant).
    pub glare_share: f32,
    /// `Σ (L_r − threshold)` over those pixels, cd/m² × pixels.
    pub excess_luminance_cd_m2: f32,
}

/// The glass area an object's reflection covers, at any luminance.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Coverage {
    pub name: String,
    /// Its glass pixels / all glass pixels.
    pub coverage_share: f32,
}

/// One of a variant's worst frames.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WorstCase {
    /// Index into [`StudyReport::frames`].
    pub frame: usize,
    pub eye_index: usize,
    pub sun_index: Option<usize>,
    pub sun_azimuth_deg: Option<f32>,
    pub sun_elevation_deg: Option<f32>,
    pub sun_time: Option<String>,
    pub mean_reflected_luminance_cd_m2: f32,
    pub low_contrast_share: f32,
    /// The objects causing that frame's glare, the culprit first (see
    /// [`VariantScore::glare_culprits`]).
    pub glare_culprits: Vec<Culprit>,
    /// The object covering the most glass in that frame.
    pub most_covering_object: Option<Coverage>,
}

/// The name the background (rays leaving the scene: sky past the windows)
/// takes among the culprits.
pub const BACKGROUND_CULPRIT: &str = "background (rays leaving the scene)";

impl Culprit {
    /// The culprits of a frame's glare, at most [`CULPRITS`]: its ranked
    /// objects that cause glare, and the background where glare pixels
    /// mirror no object ([`BACKGROUND_CULPRIT`]), ranked alike.
    pub fn of_frame(summary: &Summary) -> Vec<Culprit> {
        let mut all = Culprit::candidates(summary);
        all.truncate(CULPRITS);
        all
    }

    /// Every glare source of a frame, the culprit first (see
    /// [`Culprit::of_frame`]).
    fn candidates(summary: &Summary) -> Vec<Culprit> {
        let share = |pixels: usize| {
            if summary.glare_pixels == 0 {
                0.0
            } else {
                (pixels as f64 / summary.glare_pixels as f64) as f32
            }
        };
        let background = (summary.background_glare_pixels > 0).then(|| Culprit {
            name: BACKGROUND_CULPRIT.to_owned(),
            glare_pixels: summary.background_glare_pixels,
            glare_share: share(summary.background_glare_pixels),
            excess_luminance_cd_m2: summary.background_excess_luminance_cd_m2,
        });
        let mut all: Vec<Culprit> = (summary.objects.iter())
            .filter(|o| o.glare_pixels > 0)
            .map(|o| Culprit {
                name: o.name.clone(),
                glare_pixels: o.glare_pixels,
                glare_share: o.glare_share,
                excess_luminance_cd_m2: o.excess_luminance_cd_m2,
            })
            .chain(background)
            .collect();
        // Objects come ranked; the background takes its place among them.
        all.sort_by(|a, b| {
            (b.glare_pixels.cmp(&a.glare_pixels)).then(
                b.excess_luminance_cd_m2
                    .total_cmp(&a.excess_luminance_cd_m2),
            )
        });
        all
    }
}

impl Coverage {
    /// The object covering the most glass in a frame.
    pub fn of_frame(summary: &Summary) -> Option<Coverage> {
        (summary.objects.iter())
            .max_by(|a, b| (a.covered_pixels.cmp(&b.covered_pixels)).then(b.object.cmp(&a.object)))
            .map(|o| Coverage {
                name: o.name.clone(),
                coverage_share: o.coverage_share,
            })
    }
}

/// How the study set the sun, for the report: the frames' sun is described
/// as it was set, never as a sweep that did not happen.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "setting", rename_all = "snake_case")]
pub enum SunSetting {
    /// A `[sun]` sweep: each frame names its sun position.
    Sweep { positions: usize },
    /// The base job's directional light, the same in every frame (angles
    /// relative to the vehicle).
    FixedFromJob {
        azimuth_deg: f32,
        elevation_deg: f32,
    },
    /// No directional light.
    None,
}

impl StudyPlan {
    /// How this study sets the sun.
    pub fn sun_setting(&self) -> SunSetting {
        match (self.suns.len(), self.base_sun) {
            (0, Some(sun)) => SunSetting::FixedFromJob {
                azimuth_deg: sun.azimuth_deg,
                elevation_deg: sun.elevation_deg,
            },
            (0, None) => SunSetting::None,
            (positions, _) => SunSetting::Sweep { positions },
        }
    }
}

#[cfg(test)]
mod tests;
