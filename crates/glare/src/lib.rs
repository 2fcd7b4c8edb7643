//! Glare metrics of a rendered frame: how bright the reflections on the
//! instrument cover glass are, how much they veil what is seen through the
//! glass, and how much contrast the instrument markings keep under them.
//!
//! Everything here is a pure function of a [`GlareInput`] (borrowed per-pixel
//! buffers, usually taken from a composited
//! frame's [`vtfarm_vertex::Components`] with [`GlareInput::from_components`])
//! and [`Params`]. The two image builders ([`heat_map`], [`object_map`])
//! return linear [`vtfarm_imaging::Image`]s; writing them (e.g. with
//! `Image::write_png`) is the caller's job.
//!
//! # Units and formulas
//!
//! * **Luminance** is in cd/m², by the convention of
//!   [`vtfarm_scene::photometry`]: per pixel `L = s · Y(c)` with
//!   `Y(c) = 0.2126 R + 0.7152 G + 0.0722 B` ([`luminance`]) and `s` the
//!   [`Params::cd_m2_per_unit`], by default the renderer's
//!   [`CD_M2_PER_UNIT`] (10,000 cd/m² per unit of rendered radiance).
//!   Non-finite or negative colour values count as luminance 0, so no metric
//!   is ever NaN.
//! * **Reflected / transmitted luminance maps** ([`reflected_luminance`],
//!   [`transmitted_luminance`]): `L_r` and `L_t` per glass pixel, 0 outside
//!   the glass mask. `L_r` is the veiling (reflected) luminance on the glass.
//! * **Ambient condition** ([`AmbientCondition`]): the glass also scatters
//!   the ambient illuminance `E` diffusely with its diffuse reflectance `ρ_d`,
//!   a uniform veil `L_a = ρ_d · E / π` over the instruments.
//! * **Veiling ratio** ([`veiling_ratio`]): `V = L_r / max(L_t, f)` per glass
//!   pixel (0 outside), with `f` the [`Params::luminance_floor_cd_m2`], so
//!   that a black background gives a large finite ratio instead of infinity.
//! * **Marking contrast** ([`contrast`]):
//!   `CR = (L_hi + L_r + L_a) / (L_lo + L_r + L_a)`, where `L_hi`/`L_lo` are
//!   the brighter and the darker of the marking luminance `L_m` and the
//!   background luminance `L_b` (both transmitted luminances): the contrast
//!   ratio of display ergonomics (ISO 15008) with the reflections added to
//!   both. For bright markings on a dark dial this is
//!   `(L_m + L_r + L_a) / (L_b + L_r + L_a)`; brighter over darker makes
//!   `CR ≥ 1` for dark-on-light dials too. Without reflection or veil
//!   `CR = L_m / L_b`; as `L_r` grows `CR` falls towards 1. Both numerator
//!   and denominator are floored at `f`. See [`contrast`] for the choice of
//!   `L_b` (the mean background luminance of the instrument area).
//! * **Summary** ([`summarize`]): peak and mean of `L_r` over the glass, the
//!   share of glass pixels with `L_r` above
//!   [`Thresholds::veiling_luminance_cd_m2`], the share of the evaluated
//!   instrument area with `CR` below [`Thresholds::min_contrast`], and the
//!   objects seen in the reflections ranked by the glare they cause: the
//!   glass area over the glare threshold whose reflection shows them, then
//!   the luminance they add above the threshold there ([`rank_objects`]);
//!   the glass area each covers at any luminance is a separate figure
//!   (`covered_pixels`, `coverage_share`). Fields carry their unit in their names
//!   (`mean_reflected_luminance_cd_m2`); ratios and shares have none.
//!
//! Areas are pixel counts; shares are fractions in [0, 1] (0 for an empty
//! area).
//!
//! # Defaults and their sources
//!
//! Every threshold travels with a source string that the study writes next
//! to it. The defaults: a minimum contrast of 3:1 ([`DEFAULT_MIN_CONTRAST`]),
//! the daytime minimum usually quoted from ISO 15008 for in-vehicle displays;
//! a daylight ambient condition of 45,000 lx ([`DEFAULT_AMBIENT_LUX`]) on a
//! glass of diffuse reflectance 0.005; and a glare threshold of 500 cd/m²
//! ([`DEFAULT_VEILING_LUMINANCE_CD_M2`]), a vtfarm engineering default. The
//! standard's text is not reproduced in vtfarm: a study that signs off a
//! design sets the values (and their sources) of the edition and clause it
//! follows.

use std::collections::BTreeMap;

use glam::Vec3;
use serde::Serialize;
use vtfarm_scene::NONE;
use vtfarm_vertex::Components;

mod font;
mod glint;
mod images;
mod ramp;

pub use font::{GLYPH_HEIGHT, GLYPH_WIDTH, draw_text, text_width};
pub use glint::{
    CIE_SOURCE, CIE_VALIDITY_DEG, DEFAULT_GLINT_LUMINANCE_CD_M2, DEFAULT_GLINT_SOURCE, Glint,
    GlintThreshold, Instrument, InstrumentVeil, cie_valid, cie_veiling_luminance,
    contrast_with_veil, measure_glint,
};
pub use images::{
    FONT_COLOR, LogRange, NO_OBJECT_COLOR, PALETTE, format_label, heat_map, heat_map_frame,
    object_color_srgb, object_map, object_map_frame,
};
pub use ramp::{BEYOND_SCALE_SRGB, INFERNO_SRGB, beyond_scale_color, ramp_color};

pub use vtfarm_scene::photometry::{CD_M2_PER_UNIT, luminance};

/// Default [`Params::luminance_floor_cd_m2`]: the smallest denominator used
/// in ratios. Far below any luminance that matters for glare, large enough
/// to keep ratios finite over black.
pub const DEFAULT_LUMINANCE_FLOOR_CD_M2: f32 = 0.01;

/// Default [`Thresholds::min_contrast`]: 3:1.
pub const DEFAULT_MIN_CONTRAST: f32 = 3.0;
/// The source recorded with the default minimum contrast.
pub const DEFAULT_MIN_CONTRAST_SOURCE: &str = "ISO 15008 (in-vehicle visual presentation), daytime minimum contrast ratio 3:1 as usually quoted; vtfarm default, check the edition you follow";

/// Default [`Thresholds::veiling_luminance_cd_m2`]: 500 cd/m².
pub const DEFAULT_VEILING_LUMINANCE_CD_M2: f32 = 500.0;
/// The source recorded with the default glare threshold.
pub const DEFAULT_VEILING_LUMINANCE_SOURCE: &str =
    "vtfarm engineering default (about the luminance of a day-mode display)";

/// Default [`AmbientCondition::illuminance_lux`]: daylight on the display.
pub const DEFAULT_AMBIENT_LUX: f32 = 45_000.0;
/// Default [`AmbientCondition::glass_diffuse_reflectance`]: a clean cover
/// glass (the cockpit glass's own diffuse reflectance).
pub const DEFAULT_GLASS_DIFFUSE_REFLECTANCE: f32 = 0.005;
/// The source recorded with the default ambient condition.
pub const DEFAULT_AMBIENT_SOURCE: &str = "daylight condition after ISO 15008's bright-ambient legibility test (45,000 lx diffuse on the display); vtfarm default, check the edition you follow";

/// The thresholds of the summary, each with where it comes from.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Thresholds {
    /// Minimum readable contrast ratio of markings against their background
    /// (dimensionless, `CR` as in [`contrast_ratio`]). Default
    /// [`DEFAULT_MIN_CONTRAST`] = 3:1.
    pub min_contrast: f32,
    pub min_contrast_source: String,
    /// Reflected luminance above which a glass pixel counts as glare, in
    /// cd/m². Default [`DEFAULT_VEILING_LUMINANCE_CD_M2`].
    pub veiling_luminance_cd_m2: f32,
    pub veiling_luminance_source: String,
}

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            min_contrast: DEFAULT_MIN_CONTRAST,
            min_contrast_source: DEFAULT_MIN_CONTRAST_SOURCE.to_owned(),
            veiling_luminance_cd_m2: DEFAULT_VEILING_LUMINANCE_CD_M2,
            veiling_luminance_source: DEFAULT_VEILING_LUMINANCE_SOURCE.to_owned(),
        }
    }
}

/// The ambient condition the contrast is judged under: diffuse illuminance
/// on the display, scattered back by the cover glass.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AmbientCondition {
    pub illuminance_lux: f32,
    /// Diffuse (Lambertian) reflectance of the cover glass, 0 to 1.
    pub glass_diffuse_reflectance: f32,
    pub source: String,
}

impl AmbientCondition {
    /// `ρ_d · E / π`: the uniform veil the glass adds over the instruments.
    pub fn veiling_luminance_cd_m2(&self) -> f32 {
        self.glass_diffuse_reflectance * self.illuminance_lux / std::f32::consts::PI
    }
}

impl Default for AmbientCondition {
    fn default() -> Self {
        AmbientCondition {
            illuminance_lux: DEFAULT_AMBIENT_LUX,
            glass_diffuse_reflectance: DEFAULT_GLASS_DIFFUSE_REFLECTANCE,
            source: DEFAULT_AMBIENT_SOURCE.to_owned(),
        }
    }
}

/// Photometric parameters, thresholds and the ambient condition.
#[derive(Clone, Debug, PartialEq)]
pub struct Params {
    /// cd/m² per unit of rendered radiance (default [`CD_M2_PER_UNIT`]).
    pub cd_m2_per_unit: f32,
    /// Floor on ratio denominators, in cd/m² (default
    /// [`DEFAULT_LUMINANCE_FLOOR_CD_M2`]).
    pub luminance_floor_cd_m2: f32,
    pub thresholds: Thresholds,
    pub ambient: AmbientCondition,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            cd_m2_per_unit: CD_M2_PER_UNIT,
            luminance_floor_cd_m2: DEFAULT_LUMINANCE_FLOOR_CD_M2,
            thresholds: Thresholds::default(),
            ambient: AmbientCondition::default(),
        }
    }
}

/// Inconsistent input.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GlareError {
    #[error("image size {width}x{height} is too large")]
    TooLarge { width: u32, height: u32 },
    #[error("{name} has {got} entries, expected width * height = {expected}")]
    Length {
        name: &'static str,
        got: usize,
        expected: usize,
    },
    #[error("invalid parameter {name} = {value}: {why}")]
    Param {
        name: &'static str,
        value: f32,
        why: &'static str,
    },
}

/// The per-pixel inputs of one frame (row-major, row 0 at the top, every
/// slice `width * height` long).
#[derive(Clone, Copy, Debug)]
pub struct GlareInput<'a> {
    pub width: u32,
    pub height: u32,
    /// The reflector (cover glass) mask.
    pub glass: &'a [bool],
    /// The reflected component, linear RGB.
    pub reflected: &'a [Vec3],
    /// The transmitted component (what is seen through the glass), linear RGB.
    pub transmitted: &'a [Vec3],
    /// The object each pixel's reflection shows ([`vtfarm_scene::NONE`] for
    /// nothing).
    pub reflected_object: &'a [u32],
    /// Pixels over the instruments.
    pub instrument: &'a [bool],
    /// Pixels of instrument markings; the rest of the instrument area is
    /// background. Marking pixels outside `instrument` are ignored.
    pub marking: &'a [bool],
    /// Object names, indexed by object id (ids without a name are called
    /// `OBJECT <id>`).
    pub object_names: &'a [String],
}

impl<'a> GlareInput<'a> {
    /// Takes the glass mask, reflected and transmitted components and the
    /// reflected-object map from a composited frame's full-frame components
    /// ([`vtfarm_vertex::FrameImage::components`]).
    pub fn from_components(
        frame: &'a Components,
        instrument: &'a [bool],
        marking: &'a [bool],
        object_names: &'a [String],
    ) -> Self {
        GlareInput {
            width: frame.reflected.width,
            height: frame.reflected.height,
            glass: &frame.mask,
            reflected: &frame.reflected.pixels,
            transmitted: &frame.transmitted.pixels,
            reflected_object: &frame.reflected_object,
            instrument,
            marking,
            object_names,
        }
    }

    /// The number of pixels, `width * height`.
    pub fn pixel_count(&self) -> Result<usize, GlareError> {
        (self.width as usize)
            .checked_mul(self.height as usize)
            .ok_or(GlareError::TooLarge {
                width: self.width,
                height: self.height,
            })
    }

    /// Checks that every buffer has `width * height` entries.
    pub fn validate(&self) -> Result<usize, GlareError> {
        let n = self.pixel_count()?;
        let lens = [
            ("glass", self.glass.len()),
            ("reflected", self.reflected.len()),
            ("transmitted", self.transmitted.len()),
            ("reflected_object", self.reflected_object.len()),
            ("instrument", self.instrument.len()),
            ("marking", self.marking.len()),
        ];
        for (name, got) in lens {
            if got != n {
                return Err(GlareError::Length {
                    name,
                    got,
                    expected: n,
                });
            }
        }
        Ok(n)
    }

    /// The name of object `id`.
    pub fn object_name(&self, id: u32) -> String {
        self.object_names
            .get(id as usize)
            .cloned()
            .unwrap_or_else(|| format!("OBJECT {id}"))
    }
}

/// A parameter's name, value, rule and test.
type ParamCheck = (&'static str, f32, &'static str, fn(f32) -> bool);

impl Params {
    /// Checks that the parameters are finite and in range.
    pub fn validate(&self) -> Result<(), GlareError> {
        let (t, a) = (&self.thresholds, &self.ambient);
        let checks: [ParamCheck; 6] = [
            (
                "cd_m2_per_unit",
                self.cd_m2_per_unit,
                "must be positive",
                |v| v > 0.0,
            ),
            (
                "luminance_floor_cd_m2",
                self.luminance_floor_cd_m2,
                "must be positive",
                |v| v > 0.0,
            ),
            ("min_contrast", t.min_contrast, "must be finite", |_| true),
            (
                "veiling_luminance_cd_m2",
                t.veiling_luminance_cd_m2,
                "must be finite",
                |_| true,
            ),
            (
                "ambient illuminance_lux",
                a.illuminance_lux,
                "must not be negative",
                |v| v >= 0.0,
            ),
            (
                "glass_diffuse_reflectance",
                a.glass_diffuse_reflectance,
                "must be 0 to 1",
                |v| (0.0..=1.0).contains(&v),
            ),
        ];
        for (name, value, why, ok) in checks {
            if !value.is_finite() {
                return Err(GlareError::Param {
                    name,
                    value,
                    why: "must be finite",
                });
            }
            if !ok(value) {
                return Err(GlareError::Param { name, value, why });
            }
        }
        Ok(())
    }

    /// `cd_m2_per_unit · Y(c)`, with non-finite or negative results as 0.
    pub fn scaled_luminance(&self, c: Vec3) -> f32 {
        finite_non_negative(self.cd_m2_per_unit * luminance(c))
    }
}

fn finite_non_negative(v: f32) -> f32 {
    if v.is_finite() { v.max(0.0) } else { 0.0 }
}

fn check(input: &GlareInput<'_>, params: &Params) -> Result<usize, GlareError> {
    params.validate()?;
    input.validate()
}

fn masked_luminance(mask: &[bool], colors: &[Vec3], params: &Params) -> Vec<f32> {
    mask.iter()
        .zip(colors)
        .map(|(&m, &c)| if m { params.scaled_luminance(c) } else { 0.0 })
        .collect()
}

/// `L_r = s · Y(reflected)` per glass pixel, 0 outside the glass.
pub fn reflected_luminance(
    input: &GlareInput<'_>,
    params: &Params,
) -> Result<Vec<f32>, GlareError> {
    check(input, params)?;
    Ok(masked_luminance(input.glass, input.reflected, params))
}

/// `L_t = s · Y(transmitted)` per glass pixel, 0 outside the glass.
pub fn transmitted_luminance(
    input: &GlareInput<'_>,
    params: &Params,
) -> Result<Vec<f32>, GlareError> {
    check(input, params)?;
    Ok(masked_luminance(input.glass, input.transmitted, params))
}

/// The veiling ratio `V = L_r / max(L_t, f)` per glass pixel (dimensionless,
/// 0 outside the glass), `f` = [`Params::luminance_floor_cd_m2`].
pub fn veiling_ratio(input: &GlareInput<'_>, params: &Params) -> Result<Vec<f32>, GlareError> {
    check(input, params)?;
    Ok(veiling_from(
        input.glass,
        &masked_luminance(input.glass, input.reflected, params),
        &masked_luminance(input.glass, input.transmitted, params),
        params.luminance_floor_cd_m2,
    ))
}

fn veiling_from(glass: &[bool], lr: &[f32], lt: &[f32], floor: f32) -> Vec<f32> {
    glass
        .iter()
        .zip(lr.iter().zip(lt))
        .map(|(&g, (&r, &t))| {
            if g {
                finite_non_negative(r / t.max(floor))
            } else {
                0.0
            }
        })
        .collect()
}

/// The contrast ratio of a marking against its background under a veiling
/// luminance `l_reflected` (the reflection plus the ambient veil):
/// `(L_hi + L_r) / (L_lo + L_r)`, `L_hi`/`L_lo` the brighter and
/// darker of `l_marking` and `l_background`; numerator and denominator are
/// floored at `floor`. Dimensionless, ≥ 1, finite for finite inputs; with
/// `l_reflected = 0` and `l_background ≥ floor` it is exactly
/// `l_marking / l_background` for a bright marking, and it decreases towards
/// 1 as `l_reflected` grows (while the denominator is above the floor).
pub fn contrast_ratio(l_marking: f32, l_background: f32, l_reflected: f32, floor: f32) -> f32 {
    let (hi, lo) = if l_marking >= l_background {
        (l_marking, l_background)
    } else {
        (l_background, l_marking)
    };
    let r = finite_non_negative(l_reflected);
    finite_non_negative((hi + r).max(floor) / (lo + r).max(floor))
}

/// Marking contrast over the instrument area.
#[derive(Clone, Debug, PartialEq)]
pub struct ContrastMap {
    /// `CR` per pixel; `Some` at the evaluated instrument pixels, `None`
    /// elsewhere.
    pub per_pixel: Vec<Option<f32>>,
    /// Mean transmitted luminance `L̄_b` of the instrument background
    /// (instrument, not marking); 0 when there is none.
    pub mean_background_luminance_cd_m2: f32,
    /// Mean transmitted luminance `L̄_m` of the marking pixels; 0 when there
    /// are none.
    pub mean_marking_luminance_cd_m2: f32,
    pub instrument_pixels: usize,
    pub marking_pixels: usize,
    /// Pixels where `CR` was evaluated.
    pub evaluated_pixels: usize,
    /// Evaluated pixels with `CR` below [`Thresholds::min_contrast`].
    pub low_contrast_pixels: usize,
    /// `low_contrast_pixels / evaluated_pixels` (0 when none was evaluated).
    pub low_contrast_share: f32,
    /// The smallest evaluated `CR`, if any.
    pub min_contrast: Option<f32>,
}

/// The contrast of the instrument markings under the veiling reflection.
///
/// Transmitted luminance `L_t` is taken over the whole frame here (not only
/// the glass), reflected luminance `L_r` is 0 outside the glass.
///
/// * The background luminance is one number for the frame: the mean `L̄_b`
///   of `L_t` over the background pixels (instrument and not marking). A
///   marking is read against the dial around it, and the mean over the
///   instrument area is a robust stand-in for "around it" that does not
///   depend on a neighbourhood size; dials with very different background
///   zones should be passed as separate instrument masks.
/// * At a **marking pixel** `CR = contrast_ratio(L_t(p), L̄_b, L_r(p) + L_a)`
///   with `L_a` the ambient veil ([`AmbientCondition::veiling_luminance_cd_m2`]).
/// * At a **background pixel** `CR = contrast_ratio(L̄_m, L̄_b, L_r(p) + L_a)`
///   with `L̄_m` the mean marking luminance: the contrast a typical marking
///   would have under the reflection there. This makes the low-contrast share
///   a share of the whole instrument area, as glare moving over the dial
///   makes any marking that passes under it unreadable.
/// * Without marking pixels nothing can be read: no pixel is evaluated and
///   the share is 0. Without background pixels `L̄_b = 0`.
pub fn contrast(input: &GlareInput<'_>, params: &Params) -> Result<ContrastMap, GlareError> {
    check(input, params)?;
    let lr = masked_luminance(input.glass, input.reflected, params);
    Ok(contrast_from(input, params, &lr))
}

fn contrast_from(input: &GlareInput<'_>, params: &Params, lr: &[f32]) -> ContrastMap {
    let n = input.instrument.len();
    let lt = |i: usize| params.scaled_luminance(input.transmitted[i]);
    let is_marking = |i: usize| input.instrument[i] && input.marking[i];
    let (mut sum_b, mut count_b, mut sum_m, mut count_m) = (0.0f64, 0usize, 0.0f64, 0usize);
    for i in 0..n {
        if !input.instrument[i] {
            continue;
        }
        if is_marking(i) {
            sum_m += lt(i) as f64;
            count_m += 1;
        } else {
            sum_b += lt(i) as f64;
            count_b += 1;
        }
    }
    let mean = |s: f64, c: usize| if c == 0 { 0.0 } else { (s / c as f64) as f32 };
    let lb = mean(sum_b, count_b);
    let lm = mean(sum_m, count_m);
    let floor = params.luminance_floor_cd_m2;
    let veil = params.ambient.veiling_luminance_cd_m2();
    let threshold = params.thresholds.min_contrast;
    let mut per_pixel = vec![None; n];
    let (mut evaluated, mut low) = (0usize, 0usize);
    let mut min_cr: Option<f32> = None;
    if count_m > 0 {
        for (i, out) in per_pixel.iter_mut().enumerate() {
            if !input.instrument[i] {
                continue;
            }
            let l_mark = if is_marking(i) { lt(i) } else { lm };
            let cr = contrast_ratio(l_mark, lb, lr[i] + veil, floor);
            *out = Some(cr);
            evaluated += 1;
            if cr < threshold {
                low += 1;
            }
            min_cr = Some(min_cr.map_or(cr, |m| m.min(cr)));
        }
    }
    ContrastMap {
        per_pixel,
        mean_background_luminance_cd_m2: lb,
        mean_marking_luminance_cd_m2: lm,
        instrument_pixels: count_b + count_m,
        marking_pixels: count_m,
        evaluated_pixels: evaluated,
        low_contrast_pixels: low,
        low_contrast_share: share(low, evaluated),
        min_contrast: min_cr,
    }
}

fn share(part: usize, whole: usize) -> f32 {
    if whole == 0 {
        0.0
    } else {
        (part as f64 / whole as f64) as f32
    }
}

/// One object seen in the reflections, with the glare it causes.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ObjectGlare {
    /// Object id (index into the scene's objects).
    pub object: u32,
    pub name: String,
    /// Glass pixels over the glare threshold (`L_r >
    /// veiling_luminance_cd_m2`) whose reflection shows this object: the
    /// glare area it causes.
    pub glare_pixels: usize,
    /// `glare_pixels` / every glare pixel of the frame (0 without glare):
    /// its share of the glare.
    pub glare_share: f32,
    /// `Σ (L_r − threshold)` over its glare pixels (cd/m² × pixels): how
    /// far above the threshold it takes the glass.
    pub excess_luminance_cd_m2: f32,
    /// Glass pixels whose reflection shows this object, at any luminance:
    /// the area it covers, not the glare it causes.
    pub covered_pixels: usize,
    /// `covered_pixels` / glass pixels.
    pub coverage_share: f32,
    /// `Σ L_r` over the covered pixels (cd/m² × pixels).
    pub summed_reflected_luminance_cd_m2: f32,
    /// `summed_reflected_luminance_cd_m2 / covered_pixels`.
    pub mean_reflected_luminance_cd_m2: f32,
}

/// The objects in the reflected-object map over the glass, ranked by the
/// glare they cause: the glass area over `threshold_cd_m2` they cause
/// (descending), then the luminance they add above it (descending), then
/// the glass area they cover (descending), then object id (ascending). The
/// first is the frame's culprit, when it causes any glare. `lr` is the
/// reflected luminance map. Pixels showing [`NONE`] are not counted.
pub fn rank_objects(input: &GlareInput<'_>, lr: &[f32], threshold_cd_m2: f32) -> Vec<ObjectGlare> {
    #[derive(Default)]
    struct Tally {
        covered: usize,
        summed: f64,
        glare: usize,
        excess: f64,
    }
    let mut per: BTreeMap<u32, Tally> = BTreeMap::new();
    let (mut glass_pixels, mut all_glare) = (0usize, 0usize);
    for (i, &g) in input.glass.iter().enumerate() {
        if !g {
            continue;
        }
        glass_pixels += 1;
        let l = lr.get(i).copied().unwrap_or(0.0);
        let over = l > threshold_cd_m2;
        all_glare += usize::from(over);
        let id = input.reflected_object.get(i).copied().unwrap_or(NONE);
        if id == NONE {
            continue;
        }
        let e = per.entry(id).or_default();
        e.covered += 1;
        e.summed += l as f64;
        if over {
            e.glare += 1;
            e.excess += (l - threshold_cd_m2) as f64;
        }
    }
    let mut out: Vec<ObjectGlare> = per
        .into_iter()
        .map(|(object, t)| ObjectGlare {
            object,
            name: input.object_name(object),
            glare_pixels: t.glare,
            glare_share: share(t.glare, all_glare),
            excess_luminance_cd_m2: t.excess as f32,
            covered_pixels: t.covered,
            coverage_share: share(t.covered, glass_pixels),
            summed_reflected_luminance_cd_m2: t.summed as f32,
            mean_reflected_luminance_cd_m2: (t.summed / t.covered as f64) as f32,
        })
        .collect();
    out.sort_by(|a, b| {
        (b.glare_pixels.cmp(&a.glare_pixels))
            .then(
                b.excess_luminance_cd_m2
                    .total_cmp(&a.excess_luminance_cd_m2),
            )
            .then(b.covered_pixels.cmp(&a.covered_pixels))
            .then(a.object.cmp(&b.object))
    });
    out
}

/// The glare summary of one frame (serializable, e.g. to JSON).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Summary {
    pub cd_m2_per_unit: f32,
    pub luminance_floor_cd_m2: f32,
    pub thresholds: Thresholds,
    pub ambient: AmbientCondition,
    /// Pixels of the glass mask.
    pub glass_pixels: usize,
    /// `max L_r` over the glass (0 for no glass).
    pub peak_reflected_luminance_cd_m2: f32,
    /// `mean L_r` over the glass (0 for no glass).
    pub mean_reflected_luminance_cd_m2: f32,
    /// `mean L_t` over the glass (0 for no glass).
    pub mean_transmitted_luminance_cd_m2: f32,
    /// The ambient veil `L_a` added to every contrast.
    pub ambient_veiling_luminance_cd_m2: f32,
    /// `max V` over the glass.
    pub peak_veiling_ratio: f32,
    /// `mean V` over the glass.
    pub mean_veiling_ratio: f32,
    /// Glass pixels with `L_r > veiling_luminance_cd_m2`.
    pub glare_pixels: usize,
    /// Glare pixels whose reflection shows no object: the background (the
    /// rays that leave the scene, [`vtfarm_scene::Lighting::background`]),
    /// a glare source beside the objects of [`Summary::objects`].
    pub background_glare_pixels: usize,
    /// `Σ (L_r − threshold)` over those pixels (cd/m² × pixels).
    pub background_excess_luminance_cd_m2: f32,
    /// `glare_pixels / glass_pixels`.
    pub glare_area_share: f32,
    pub instrument_pixels: usize,
    pub marking_pixels: usize,
    pub mean_marking_luminance_cd_m2: f32,
    pub mean_background_luminance_cd_m2: f32,
    /// Smallest `CR` over the evaluated instrument area (`None` without
    /// markings).
    pub min_contrast: Option<f32>,
    /// Evaluated instrument pixels with `CR < min_contrast` threshold.
    pub low_contrast_pixels: usize,
    /// `low_contrast_pixels / evaluated instrument pixels`.
    pub low_contrast_share: f32,
    /// Objects seen in the reflections, the culprit of the glare first: see
    /// [`rank_objects`].
    pub objects: Vec<ObjectGlare>,
}

/// All metrics of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Analysis {
    pub reflected_luminance: Vec<f32>,
    pub transmitted_luminance: Vec<f32>,
    pub veiling_ratio: Vec<f32>,
    pub contrast: ContrastMap,
    pub summary: Summary,
}

/// Computes every map and the summary.
pub fn analyze(input: &GlareInput<'_>, params: &Params) -> Result<Analysis, GlareError> {
    check(input, params)?;
    let lr = masked_luminance(input.glass, input.reflected, params);
    let lt = masked_luminance(input.glass, input.transmitted, params);
    let v = veiling_from(input.glass, &lr, &lt, params.luminance_floor_cd_m2);
    let contrast = contrast_from(input, params, &lr);

    let mut glass_pixels = 0usize;
    let (mut peak_r, mut sum_r, mut sum_t, mut peak_v, mut sum_v) =
        (0.0f32, 0.0f64, 0.0f64, 0.0f32, 0.0f64);
    let mut glare_pixels = 0usize;
    let (mut background_glare, mut background_excess) = (0usize, 0.0f64);
    let threshold = params.thresholds.veiling_luminance_cd_m2;
    for i in 0..input.glass.len() {
        if !input.glass[i] {
            continue;
        }
        glass_pixels += 1;
        peak_r = peak_r.max(lr[i]);
        sum_r += lr[i] as f64;
        sum_t += lt[i] as f64;
        peak_v = peak_v.max(v[i]);
        sum_v += v[i] as f64;
        if lr[i] > threshold {
            glare_pixels += 1;
            if input.reflected_object.get(i).is_none_or(|&o| o == NONE) {
                background_glare += 1;
                background_excess += f64::from(lr[i] - threshold);
            }
        }
    }
    let mean = |s: f64| {
        if glass_pixels == 0 {
            0.0
        } else {
            (s / glass_pixels as f64) as f32
        }
    };
    let summary = Summary {
        cd_m2_per_unit: params.cd_m2_per_unit,
        luminance_floor_cd_m2: params.luminance_floor_cd_m2,
        thresholds: params.thresholds.clone(),
        ambient: params.ambient.clone(),
        glass_pixels,
        peak_reflected_luminance_cd_m2: peak_r,
        mean_reflected_luminance_cd_m2: mean(sum_r),
        mean_transmitted_luminance_cd_m2: mean(sum_t),
        ambient_veiling_luminance_cd_m2: params.ambient.veiling_luminance_cd_m2(),
        peak_veiling_ratio: peak_v,
        mean_veiling_ratio: mean(sum_v),
        glare_pixels,
        glare_area_share: share(glare_pixels, glass_pixels),
        background_glare_pixels: background_glare,
        background_excess_luminance_cd_m2: background_excess as f32,
        instrument_pixels: contrast.instrument_pixels,
        marking_pixels: contrast.marking_pixels,
        mean_marking_luminance_cd_m2: contrast.mean_marking_luminance_cd_m2,
        mean_background_luminance_cd_m2: contrast.mean_background_luminance_cd_m2,
        min_contrast: contrast.min_contrast,
        low_contrast_pixels: contrast.low_contrast_pixels,
        low_contrast_share: contrast.low_contrast_share,
        objects: rank_objects(input, &lr, params.thresholds.veiling_luminance_cd_m2),
    };
    Ok(Analysis {
        reflected_luminance: lr,
        transmitted_luminance: lt,
        veiling_ratio: v,
        contrast,
        summary,
    })
}

/// The [`Summary`] alone.
pub fn summarize(input: &GlareInput<'_>, params: &Params) -> Result<Summary, GlareError> {
    analyze(input, params).map(|a| a.summary)
}
