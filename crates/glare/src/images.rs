//! The heat map of reflected luminance and the reflected-object map: the
//! frame alone (`*_frame`, with what a legend beside it needs: a report
//! draws its legends as text), or with a legend panel to the right of the
//! frame drawn with the built-in bitmap font.
//!
//! Layout of the images with a panel: the frame occupies columns `0..width` and rows
//! `0..height` at the same pixel positions as the input; the legend panel
//! occupies the columns from `width` on. If the legend needs more rows than
//! the frame has, the image is taller and the rows below the frame are black.

use std::collections::BTreeMap;

use glam::Vec3;
use vtfarm_imaging::{Image, srgb_to_linear};

use crate::font::{GLYPH_HEIGHT, draw_text, text_width};
use crate::ramp::ramp_color;
use crate::{GlareError, GlareInput, ObjectGlare, Params, check, masked_luminance, rank_objects};

/// The colour of legend text (linear white; nothing else in the images is
/// pure white).
pub const FONT_COLOR: Vec3 = Vec3::ONE;
/// Glass pixels whose reflection shows no object, in the object map (linear).
pub const NO_OBJECT_COLOR: Vec3 = Vec3::splat(0.02);
/// Grey of the colour-bar frame and ticks (linear).
const TICK_COLOR: Vec3 = Vec3::splat(0.3);

/// The object-map palette (sRGB, Tableau 10), assigned by rank: the object
/// covering the most glass gets the first colour; it repeats after 10.
pub const PALETTE: [[u8; 3]; 10] = [
    [0x4e, 0x79, 0xa7],
    [0xf2, 0x8e, 0x2b],
    [0xe1, 0x57, 0x59],
    [0x76, 0xb7, 0xb2],
    [0x59, 0xa1, 0x4f],
    [0xed, 0xc9, 0x48],
    [0xb0, 0x7a, 0xa1],
    [0xff, 0x9d, 0xa7],
    [0x9c, 0x75, 0x5f],
    [0xba, 0xb0, 0xac],
];

/// Scale of the bitmap font (image pixels per font pixel).
const SCALE: u32 = 2;
const MARGIN: u32 = 8;
const BAR_WIDTH: u32 = 12;
const LABELS: usize = 5;
const MIN_LEGEND_HEIGHT: u32 = 120;
const TEXT_HEIGHT: u32 = GLYPH_HEIGHT * SCALE;
const ROW_HEIGHT: u32 = 14;
const MAX_ENTRIES: usize = 20;
const MAX_NAME_CHARS: usize = 16;

fn palette_color(rank: usize) -> Vec3 {
    let c = PALETTE[rank % PALETTE.len()];
    Vec3::new(
        srgb_to_linear(c[0] as f32 / 255.0),
        srgb_to_linear(c[1] as f32 / 255.0),
        srgb_to_linear(c[2] as f32 / 255.0),
    )
}

/// A scale label: at most about 5 characters (`0`, `0.125`, `12.5`, `1.2E4`).
pub fn format_label(v: f32) -> String {
    if !v.is_finite() || v <= 0.0 {
        "0".to_owned()
    } else if !(0.01..10_000.0).contains(&v) {
        format!("{v:.1e}").to_uppercase()
    } else if v >= 100.0 {
        format!("{v:.0}")
    } else if v >= 10.0 {
        format!("{v:.1}")
    } else if v >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

fn fill_rect(image: &mut Image, x: u32, y: u32, w: u32, h: u32, color: Vec3) {
    for py in y..(y + h).min(image.height) {
        for px in x..(x + w).min(image.width) {
            image.set(px, py, color);
        }
    }
}

/// Colours each glass pixel of the frame area with `color(pixel index)`.
fn paint_glass(img: &mut Image, input: &GlareInput<'_>, color: impl Fn(usize) -> Vec3) {
    let w = input.width;
    for y in 0..input.height {
        for x in 0..w {
            let i = (y * w + x) as usize;
            if input.glass[i] {
                img.set(x, y, color(i));
            }
        }
    }
}

/// `frame` at the top left of a black canvas with room for a legend panel
/// on its right.
fn frame_canvas(frame: &Image, panel_width: u32, panel_height: u32) -> Image {
    let (w, h) = (frame.width, frame.height);
    let mut img = Image::new(w + panel_width, h.max(panel_height), Vec3::ZERO);
    for y in 0..h {
        for x in 0..w {
            img.set(x, y, frame.get(x, y));
        }
    }
    img
}

/// The luminance range of a heat map's logarithmic colour scale, in cd/m².
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogRange {
    /// The bottom of the scale: darker pixels take the ramp's first colour.
    pub min_cd_m2: f32,
    /// The top of the scale: brighter pixels saturate.
    pub max_cd_m2: f32,
}

impl LogRange {
    /// Decades a frame's own scale spans below its peak.
    pub const AUTO_DECADES: i32 = 4;

    /// The frame's own range: its peak (1 cd/m² for a black frame) and
    /// [`LogRange::AUTO_DECADES`] below.
    pub fn below_peak(peak_cd_m2: f32) -> Self {
        let max = if peak_cd_m2.is_finite() && peak_cd_m2 > 0.0 {
            peak_cd_m2
        } else {
            1.0
        };
        LogRange {
            min_cd_m2: max * 10f32.powi(-Self::AUTO_DECADES),
            max_cd_m2: max,
        }
    }

    /// Where `l` sits on the scale, 0 at or below the bottom, 1 at or above
    /// the top (0 for a range that is not positive and increasing).
    pub fn position(&self, l: f32) -> f32 {
        let span = (self.max_cd_m2 / self.min_cd_m2).ln();
        let valid = self.min_cd_m2 > 0.0 && span.is_finite() && span > 0.0;
        // A NaN luminance compares false and sits at the bottom.
        if valid && l > self.min_cd_m2 {
            ((l / self.min_cd_m2).ln() / span).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// The luminance at position `t` of the scale.
    pub fn at(&self, t: f32) -> f32 {
        self.min_cd_m2 * (self.max_cd_m2 / self.min_cd_m2).powf(t)
    }

    /// `count` (at least 2) labels of a legend, evenly spaced in the
    /// logarithm from the bottom to the top: (position on the scale,
    /// luminance in cd/m²).
    pub fn ticks(&self, count: usize) -> Vec<(f32, f32)> {
        let last = count.max(2) - 1;
        (0..=last)
            .map(|i| {
                let t = i as f32 / last as f32;
                (t, self.at(t))
            })
            .collect()
    }
}

/// The heat map of reflected luminance `L_r` in cd/m² on a logarithmic
/// colour scale, the frame alone (no legend: a report draws it beside the
/// image, from [`LogRange::ticks`] and [`ramp_color`]): glass pixels take
/// [`ramp_color`] of their [`LogRange::position`] ([`crate::beyond_scale_color`]
/// above its top), everything else is black.
/// `range` is `Some` for a fixed scale (to compare the frames of a study),
/// `None` for [`LogRange::below_peak`] of the frame's peak; the range used
/// comes back with the image.
pub fn heat_map_frame(
    input: &GlareInput<'_>,
    params: &Params,
    range: Option<LogRange>,
) -> Result<(Image, LogRange), GlareError> {
    check(input, params)?;
    let lr = masked_luminance(input.glass, input.reflected, params);
    let peak = lr.iter().copied().fold(0.0f32, f32::max);
    let range = range.unwrap_or_else(|| LogRange::below_peak(peak));
    let mut img = Image::new(input.width, input.height, Vec3::ZERO);
    paint_glass(&mut img, input, |i| {
        if lr[i] > range.max_cd_m2 {
            crate::beyond_scale_color()
        } else {
            ramp_color(range.position(lr[i]))
        }
    });
    Ok((img, range))
}

/// [`heat_map_frame`] with a legend panel baked in on the right, in the
/// built-in bitmap font (for quick looks, e.g. the dashboard; a report
/// draws its legends as text): the colour bar (top = the range's top),
/// five labels evenly spaced in the logarithm (decades for the automatic
/// range) and the title `CD/M2 LOG`.
pub fn heat_map(
    input: &GlareInput<'_>,
    params: &Params,
    range: Option<LogRange>,
) -> Result<Image, GlareError> {
    let (frame, range) = heat_map_frame(input, params, range)?;
    let labels: Vec<String> = (range.ticks(LABELS).into_iter())
        .map(|(_, value)| format_label(value))
        .collect();
    let title = "CD/M2 LOG";
    let label_width = labels
        .iter()
        .map(|l| text_width(l, SCALE))
        .max()
        .unwrap_or(0);
    let panel_width = (MARGIN + BAR_WIDTH + 6 + label_width + MARGIN)
        .max(MARGIN + text_width(title, SCALE) + MARGIN);
    let w = input.width;
    let mut img = frame_canvas(&frame, panel_width, MIN_LEGEND_HEIGHT);

    let x0 = w + MARGIN;
    draw_text(&mut img, x0 as i64, MARGIN as i64, title, SCALE, FONT_COLOR);
    let bar_top = MARGIN + TEXT_HEIGHT + MARGIN;
    let bar_bottom = img.height - MARGIN - TEXT_HEIGHT / 2; // exclusive
    let bar_height = bar_bottom - bar_top;
    fill_rect(
        &mut img,
        x0 - 1,
        bar_top - 1,
        BAR_WIDTH + 2,
        bar_height + 2,
        TICK_COLOR,
    );
    for k in 0..bar_height {
        let t = 1.0 - k as f32 / (bar_height - 1) as f32;
        fill_rect(&mut img, x0, bar_top + k, BAR_WIDTH, 1, ramp_color(t));
    }
    for (label, (t, _)) in labels.iter().zip(range.ticks(LABELS)) {
        let y = bar_top + ((1.0 - t) * (bar_height - 1) as f32).round() as u32;
        fill_rect(&mut img, x0 + BAR_WIDTH + 1, y, 3, 1, TICK_COLOR);
        draw_text(
            &mut img,
            (x0 + BAR_WIDTH + 6) as i64,
            y as i64 - (TEXT_HEIGHT / 2) as i64,
            label,
            SCALE,
            FONT_COLOR,
        );
    }
    Ok(img)
}

/// The colour of the object ranked `rank` in the object maps (sRGB):
/// [`PALETTE`], repeating after 10.
pub fn object_color_srgb(rank: usize) -> [u8; 3] {
    PALETTE[rank % PALETTE.len()]
}

/// The reflected-object map, the frame alone (no legend: a report draws
/// it beside the image): each glass pixel takes the colour of the object
/// its reflection shows ([`object_color_srgb`] of its rank in
/// [`crate::rank_objects`], the culprit of the glare first),
/// [`NO_OBJECT_COLOR`] where it shows nothing; pixels outside the glass are
/// black. The ranked objects come back with the image, in colour order.
pub fn object_map_frame(
    input: &GlareInput<'_>,
    params: &Params,
) -> Result<(Image, Vec<ObjectGlare>), GlareError> {
    check(input, params)?;
    let lr = masked_luminance(input.glass, input.reflected, params);
    let ranked = rank_objects(input, &lr, params.thresholds.veiling_luminance_cd_m2);
    let colors: BTreeMap<u32, Vec3> = ranked
        .iter()
        .enumerate()
        .map(|(rank, o)| (o.object, palette_color(rank)))
        .collect();
    let mut img = Image::new(input.width, input.height, Vec3::ZERO);
    paint_glass(&mut img, input, |i| {
        colors
            .get(&input.reflected_object[i])
            .copied()
            .unwrap_or(NO_OBJECT_COLOR)
    });
    Ok((img, ranked))
}

/// [`object_map_frame`] with a legend panel baked in on the right, in the
/// built-in bitmap font (for quick looks, e.g. the dashboard), titled
/// `OBJECTS`: one swatch per object with its name (upper-case, cut to 16
/// characters) and the glass pixels it covers, in rank order; beyond 20
/// objects a last line says `+N MORE`.
pub fn object_map(input: &GlareInput<'_>, params: &Params) -> Result<Image, GlareError> {
    let (frame, ranked) = object_map_frame(input, params)?;
    let shown = ranked.len().min(MAX_ENTRIES);
    let mut lines: Vec<String> = ranked[..shown]
        .iter()
        .map(|o| {
            let name: String = o.name.chars().take(MAX_NAME_CHARS).collect();
            format!("{name} {}", o.covered_pixels)
        })
        .collect();
    if ranked.len() > shown {
        lines.push(format!("+{} MORE", ranked.len() - shown));
    }
    let title = "OBJECTS";
    let text_w = lines
        .iter()
        .map(|l| text_width(l, SCALE))
        .max()
        .unwrap_or(0);
    let panel_width =
        (MARGIN + 10 + 6 + text_w + MARGIN).max(MARGIN + text_width(title, SCALE) + MARGIN);
    let panel_height = MARGIN + TEXT_HEIGHT + MARGIN + lines.len() as u32 * ROW_HEIGHT + MARGIN;
    let w = input.width;
    let mut img = frame_canvas(&frame, panel_width, panel_height);
    let x0 = w + MARGIN;
    draw_text(&mut img, x0 as i64, MARGIN as i64, title, SCALE, FONT_COLOR);
    let mut y = MARGIN + TEXT_HEIGHT + MARGIN;
    for (k, line) in lines.iter().enumerate() {
        if k < shown {
            fill_rect(&mut img, x0, y, 10, 10, palette_color(k));
        }
        draw_text(
            &mut img,
            (x0 + 16) as i64,
            y as i64,
            line,
            SCALE,
            FONT_COLOR,
        );
        y += ROW_HEIGHT;
    }
    Ok(img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_short_and_finite() {
        assert_eq!(format_label(0.0), "0");
        assert_eq!(format_label(f32::NAN), "0");
        assert_eq!(format_label(0.125), "0.125");
        assert_eq!(format_label(12.5), "12.5");
        assert_eq!(format_label(250.0), "250");
        assert_eq!(format_label(12_345.0), "1.2E4");
        assert_eq!(format_label(0.005), "5.0E-3");
        for v in [1e-9f32, 0.3, 3.0, 30.0, 300.0, 3000.0, 3e9] {
            assert!(format_label(v).len() <= 6, "{v}: {}", format_label(v));
        }
    }
}
