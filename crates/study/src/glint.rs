//! The sun's glint in a study's frames: measured per frame from its
//! reflected luminance ([`vtfarm_glare::measure_glint`]) and the sun
//! positions whose glint reaches the eye.

use std::collections::BTreeSet;

use vtfarm_glare::{Glint, GlintThreshold, Instrument, Summary};
use vtfarm_scene::{Camera, Scene};

use crate::{FrameRow, InstrumentMasks};

/// The glint of a frame and the marking contrast it leaves: the mean
/// marking and background luminances of the instruments with the mean
/// reflection there, the ambient veil and the glint's worst veil added
/// (`None` without a glint or without markings).
pub(crate) fn frame_glint(
    scene: &Scene,
    camera: &Camera,
    masks: &InstrumentMasks,
    reflected_cd_m2: &[f32],
    summary: &Summary,
    threshold: &GlintThreshold,
) -> (Glint, Option<f32>) {
    let instruments: Vec<Instrument> = (masks.centres.iter())
        .map(|&(object, pixel)| Instrument {
            name: scene.objects[object.index()].name.clone(),
            pixel,
        })
        .collect();
    let glint = vtfarm_glare::measure_glint(reflected_cd_m2, camera, threshold, &instruments);
    let instrument_lr = {
        let (sum, n) = (reflected_cd_m2.iter().zip(&masks.instrument))
            .filter(|(_, i)| **i)
            .fold((0f64, 0usize), |(s, n), (l, _)| (s + f64::from(*l), n + 1));
        (sum / n.max(1) as f64) as f32
    };
    let contrast = match (glint.worst_instrument(), summary.marking_pixels) {
        (Some(worst), 1..) => Some(vtfarm_glare::contrast_with_veil(
            summary.mean_marking_luminance_cd_m2,
            summary.mean_background_luminance_cd_m2,
            instrument_lr + summary.ambient_veiling_luminance_cd_m2 + worst.veiling_luminance_cd_m2,
        )),
        _ => None,
    };
    (glint, contrast)
}

/// The sun positions (indices into [`crate::StudyPlan::suns`]) at which a frame of
/// `variant` has a glint reaching the eye.
pub(crate) fn suns_with_glint(frames: &[FrameRow], variant: &str) -> BTreeSet<usize> {
    (frames.iter())
        .filter(|f| f.variant == variant && f.glint.reaches_eye())
        .filter_map(|f| f.sun_index)
        .collect()
}

/// A frame's glint for the report's figures (HTML), empty without one.
pub(crate) fn glint_html(f: &FrameRow) -> String {
    let g = &f.glint;
    if !g.reaches_eye() {
        return String::new();
    }
    let mut h = format!(
        "<br><b class=\"glint\">sun glint at the eye</b>: peak {:.3e} cd/m², E {:.1} lx",
        g.peak_luminance_cd_m2, g.eye_illuminance_lux
    );
    if let Some(w) = g.worst_instrument() {
        h.push_str(&format!(
            "<br>L<sub>v</sub> {:.0} cd/m² on {} at {:.1}&deg;{}",
            w.veiling_luminance_cd_m2,
            vtfarm_imaging::escape_html(&w.name),
            w.angle_deg,
            if w.within_validity {
                ""
            } else {
                " (outside the formula's 1&ndash;30&deg;)"
            }
        ));
    }
    if let Some(cr) = f.direct_sun_contrast {
        h.push_str(&format!("<br>contrast with L<sub>v</sub> {cr:.2}"));
    }
    h
}
