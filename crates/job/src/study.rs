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
    /// The `[sun]` sweep; `None`: the base job's sun only.
    pub sun: Option<SunSweep>,
}

/// Sun positions a study sweeps: every position is one more frame per eye
/// point and variant, lit by the base job's directional lights (the sun)
/// turned to it.
#[derive(Clone, Debug, PartialEq)]
pub enum SunSweep {
    /// Every azimuth with every elevation, relative to the vehicle: azimuth
    /// clockwise seen from above from straight ahead (90° right, 270° left),
    /// elevation above the horizon in (0°, 90°].
    Grid {
        azimuths_deg: Vec<f32>,
        elevations_deg: Vec<f32>,
    },
    /// The sun at each of `times` (UTC) seen from a vehicle at latitude and
    /// longitude (degrees, north and east positive) driving towards compass
    /// heading `heading_deg` (0° north, 90° east).
    Times {
        times: Vec<UtcTime>,
        latitude_deg: f64,
        longitude_deg: f64,
        heading_deg: f64,
    },
}

/// The most sun positions a sweep may have.
pub const MAX_SUN_POSITIONS: usize = 10_000;

/// An instant in UTC, to the second.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct UtcTime {
    /// Seconds since 1970-01-01T00:00:00Z.
    pub unix_seconds: i64,
}

impl UtcTime {
    /// The instant of a civil date and time at a UTC offset in minutes
    /// (local = UTC + offset); `None` for a date or time that does not exist.
    pub fn from_civil(
        year: i32,
        month: u32,
        day: u32,
        hour: u32,
        minute: u32,
        second: u32,
        offset_minutes: i32,
    ) -> Option<UtcTime> {
        let leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
        let days_in_month = match month {
            1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
            4 | 6 | 9 | 11 => 30,
            2 if leap => 29,
            2 => 28,
            _ => return None,
        };
        if !(1..=days_in_month).contains(&day) || hour > 23 || minute > 59 || second > 59 {
            return None;
        }
        // Days since 1970-01-01 (H. Hinnant's days_from_civil).
        let y = i64::from(year) - i64::from(month <= 2);
        let era = y.div_euclid(400);
        let year_of_era = y - era * 400;
        let m = i64::from(month);
        let day_of_year = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + i64::from(day) - 1;
        let day_of_era = year_of_era * 365 + year_of_era / 4 - year_of_era / 100 + day_of_year;
        let days = era * 146_097 + day_of_era - 719_468;
        let seconds =
            days * 86_400 + i64::from(hour) * 3600 + i64::from(minute) * 60 + i64::from(second)
                - i64::from(offset_minutes) * 60;
        Some(UtcTime {
            unix_seconds: seconds,
        })
    }

    /// (year, month, day, hour, minute, second) in UTC.
    pub fn civil(self) -> (i64, u32, u32, u32, u32, u32) {
        let days = self.unix_seconds.div_euclid(86_400);
        let secs = self.unix_seconds.rem_euclid(86_400) as u32;
        // H. Hinnant's civil_from_days.
        let z = days + 719_468;
        let era = z.div_euclid(146_097);
        let day_of_era = z - era * 146_097;
        let year_of_era =
            (day_of_era - day_of_era / 1460 + day_of_era / 36_524 - day_of_era / 146_096) / 365;
        let day_of_year = day_of_era - (365 * year_of_era + year_of_era / 4 - year_of_era / 100);
        let mp = (5 * day_of_year + 2) / 153;
        let day = (day_of_year - (153 * mp + 2) / 5 + 1) as u32;
        let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
        let year = year_of_era + era * 400 + i64::from(month <= 2);
        (year, month, day, secs / 3600, secs / 60 % 60, secs % 60)
    }
}

impl std::fmt::Display for UtcTime {
    /// RFC 3339 in UTC, e.g. `2026-06-21T08:00:00Z`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (y, mo, d, h, mi, s) = self.civil();
        write!(f, "{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{s:02}Z")
    }
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
    /// Reflected luminance from which a glass pixel is the sun's glint.
    pub glint_luminance_cd_m2: Option<Sourced>,
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
/// "set in `<study file>`" when only the value is given.
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
    sun: Option<Spanned<RawSun>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSun {
    azimuths: Option<Spanned<Vec<f32>>>,
    elevations: Option<Spanned<Vec<f32>>>,
    start: Option<Spanned<toml::value::Datetime>>,
    end: Option<Spanned<toml::value::Datetime>>,
    step_minutes: Option<Spanned<u32>>,
    latitude: Option<Spanned<f64>>,
    longitude: Option<Spanned<f64>>,
    heading: Option<Spanned<f64>>,
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
    glint_luminance_cd_m2: Option<Spanned<f32>>,
    glint_luminance_source: Option<String>,
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
    crate::read_job_text(path).is_ok_and(|text| is_study_text(&text))
}

/// Whether `text` is a study file's: a TOML table with a `[study]` table.
pub(crate) fn is_study_text(text: &str) -> bool {
    text.parse::<toml::Table>()
        .is_ok_and(|table| table.contains_key("study"))
}

/// Reads and validates a study file and its base job.
pub fn load_study(path: &Path) -> Result<Study, JobError> {
    let text = crate::read_job_text(path)?;
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
    let sun = raw.sun.as_ref().map(|sun| source.sun(sun)).transpose()?;
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
        sun,
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

    fn sun(&self, raw: &Spanned<RawSun>) -> Result<SunSweep, JobError> {
        const WHICH: &str = "give [sun] either azimuths = [...] and elevations = [...] (degrees relative to the vehicle) or start = 2026-06-21T08:00:00Z with latitude, longitude and heading";
        let sun = raw.get_ref();
        let grid = sun.azimuths.is_some() || sun.elevations.is_some();
        let times = sun.start.is_some()
            || sun.end.is_some()
            || sun.step_minutes.is_some()
            || sun.latitude.is_some()
            || sun.longitude.is_some()
            || sun.heading.is_some();
        match (grid, times) {
            (true, false) => self.sun_grid(raw),
            (false, true) => self.sun_times(raw),
            (true, true) => Err(self.error(Some(raw.span()), format!("[sun]: {WHICH}, not both"))),
            (false, false) => Err(self.error(Some(raw.span()), format!("[sun] is empty: {WHICH}"))),
        }
    }

    fn sun_grid(&self, raw: &Spanned<RawSun>) -> Result<SunSweep, JobError> {
        let sun = raw.get_ref();
        let list =
            |key: &str, value: &Option<Spanned<Vec<f32>>>, rule: &str, ok: fn(f32) -> bool| {
                let Some(value) = value else {
                    return Err(self.error(
                        Some(raw.span()),
                        format!("[sun] needs sun.{key} too: a grid takes azimuths and elevations"),
                    ));
                };
                let angles = value.get_ref();
                if angles.is_empty() {
                    return Err(self.error_at(value, format!("sun.{key} is empty")));
                }
                if let Some(bad) = angles.iter().find(|&&a| !ok(a)) {
                    return Err(self.error_at(value, format!("sun.{key}: {bad} must be {rule}")));
                }
                Ok(angles.clone())
            };
        let azimuths_deg = list("azimuths", &sun.azimuths, "finite degrees", |a| {
            a.is_finite()
        })?;
        let elevations_deg = list(
            "elevations",
            &sun.elevations,
            "degrees above the horizon, over 0 and at most 90",
            |e| e > 0.0 && e <= 90.0,
        )?;
        if azimuths_deg.len() * elevations_deg.len() > MAX_SUN_POSITIONS {
            return Err(self.error(
                Some(raw.span()),
                format!(
                    "[sun]: {} x {} positions, at most {MAX_SUN_POSITIONS}",
                    azimuths_deg.len(),
                    elevations_deg.len()
                ),
            ));
        }
        Ok(SunSweep::Grid {
            azimuths_deg,
            elevations_deg,
        })
    }

    fn sun_times(&self, raw: &Spanned<RawSun>) -> Result<SunSweep, JobError> {
        let sun = raw.get_ref();
        let required = |key: &str,
                        value: &Option<Spanned<f64>>,
                        rule: &str,
                        ok: fn(f64) -> bool| match value {
            Some(v) => self.check(&format!("sun.{key}"), v, rule, ok),
            None => Err(self.error(
                Some(raw.span()),
                format!("[sun] with start = ... needs sun.{key}: {rule}"),
            )),
        };
        let latitude_deg = required(
            "latitude",
            &sun.latitude,
            "degrees from -90 to 90, north positive",
            |x| (-90.0..=90.0).contains(&x),
        )?;
        let longitude_deg = required(
            "longitude",
            &sun.longitude,
            "degrees from -180 to 180, east positive",
            |x| (-180.0..=180.0).contains(&x),
        )?;
        let heading_deg = required(
            "heading",
            &sun.heading,
            "the compass direction the vehicle drives, finite degrees (0 north, 90 east)",
            f64::is_finite,
        )?;
        let Some(start) = &sun.start else {
            return Err(self.error(
                Some(raw.span()),
                "[sun] needs start = 2026-06-21T08:00:00Z (a date, time and UTC offset)",
            ));
        };
        let start_time = self.utc_time("sun.start", start)?;
        let times = match (&sun.end, &sun.step_minutes) {
            (None, None) => vec![start_time],
            (Some(end), Some(step)) => {
                let end_time = self.utc_time("sun.end", end)?;
                if end_time < start_time {
                    return Err(self.error_at(end, "sun.end is before sun.start"));
                }
                let step =
                    i64::from(self.check("sun.step_minutes", step, "at least 1", |s| s >= 1)?) * 60;
                let count = (end_time.unix_seconds - start_time.unix_seconds) / step + 1;
                if count > MAX_SUN_POSITIONS as i64 {
                    return Err(self.error_at(end, format!("[sun]: {count} times from start to end, at most {MAX_SUN_POSITIONS}: take a longer step_minutes")));
                }
                (0..count)
                    .map(|k| UtcTime {
                        unix_seconds: start_time.unix_seconds + k * step,
                    })
                    .collect()
            }
            (Some(end), None) => return Err(self.error_at(end, "sun.end needs sun.step_minutes")),
            (None, Some(step)) => return Err(self.error_at(step, "sun.step_minutes needs sun.end")),
        };
        Ok(SunSweep::Times {
            times,
            latitude_deg,
            longitude_deg,
            heading_deg,
        })
    }

    fn utc_time(
        &self,
        key: &str,
        value: &Spanned<toml::value::Datetime>,
    ) -> Result<UtcTime, JobError> {
        use toml::value::Offset;
        let v = value.get_ref();
        let (Some(date), Some(time), Some(offset)) = (v.date, v.time, v.offset) else {
            return Err(self.error_at(value, format!("{key} = {v}: give a date, a time and a UTC offset, e.g. 2026-06-21T08:00:00Z or 2026-06-21T10:00:00+02:00")));
        };
        let offset_minutes = match offset {
            Offset::Z => 0,
            Offset::Custom { minutes } => i32::from(minutes),
        };
        UtcTime::from_civil(
            i32::from(date.year),
            u32::from(date.month),
            u32::from(date.day),
            u32::from(time.hour),
            u32::from(time.minute),
            u32::from(time.second),
            offset_minutes,
        )
        .ok_or_else(|| self.error_at(value, format!("{key} = {v}: no such date or time")))
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
            glint_luminance_cd_m2: sourced(
                self.check_opt(
                    "metrics.glint_luminance_cd_m2",
                    &raw.glint_luminance_cd_m2,
                    "positive",
                    positive,
                )?,
                &raw.glint_luminance_source,
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
