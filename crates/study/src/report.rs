//! `summary.csv`, `summary.json` and `report.html` of a finished study.

use std::fmt::Write as _;
use std::path::Path;

use plotters::prelude::*;
use serde::Serialize;

use crate::{FrameRow, StudyError, StudyPlan, StudyReport, VariantScore, WorstCase};

/// Worst cases listed per variant.
const WORST_CASES: usize = 3;

/// One flat CSV row (the JSON keeps the full summary per frame).
#[derive(Serialize)]
struct CsvRow<'a> {
    variant: &'a str,
    eye: usize,
    eye_x: f32,
    eye_y: f32,
    eye_z: f32,
    sun_index: Option<usize>,
    sun_time: Option<&'a str>,
    sun_azimuth_deg: Option<f32>,
    sun_elevation_deg: Option<f32>,
    glass_pixels: usize,
    peak_reflected_luminance_cd_m2: f32,
    mean_reflected_luminance_cd_m2: f32,
    mean_transmitted_luminance_cd_m2: f32,
    mean_marking_luminance_cd_m2: f32,
    mean_background_luminance_cd_m2: f32,
    mean_veiling_ratio: f32,
    glare_area_share: f32,
    instrument_pixels: usize,
    min_contrast: Option<f32>,
    low_contrast_share: f32,
    main_glare_source: &'a str,
    main_glare_source_area_share: f32,
}

#[derive(Serialize)]
struct JsonSummary<'a> {
    study: &'a str,
    cd_m2_per_unit: f32,
    thresholds: &'a vtfarm_glare::Thresholds,
    ambient: &'a vtfarm_glare::AmbientCondition,
    heat_min_cd_m2: f32,
    heat_max_cd_m2: f32,
    eyes: Vec<[f32; 3]>,
    /// Sun times of the sweep with the sun below the horizon (not rendered).
    suns_below_horizon: Vec<String>,
    frames: &'a [FrameRow],
    ranking: &'a [VariantScore],
}

pub(crate) fn write_all(
    plan: &StudyPlan,
    dir: &Path,
    frames: Vec<FrameRow>,
) -> Result<StudyReport, StudyError> {
    let ranking = rank_variants(plan, &frames);
    write_file(&dir.join("summary.csv"), &csv_text(&frames)?)?;
    let json = JsonSummary {
        study: &plan.name,
        cd_m2_per_unit: plan.params.cd_m2_per_unit,
        thresholds: &plan.params.thresholds,
        ambient: &plan.params.ambient,
        heat_min_cd_m2: plan.heat_range.min_cd_m2,
        heat_max_cd_m2: plan.heat_range.max_cd_m2,
        eyes: plan.eyes.iter().map(|e| e.to_array()).collect(),
        suns_below_horizon: plan
            .suns_below_horizon
            .iter()
            .map(|t| t.to_string())
            .collect(),
        frames: &frames,
        ranking: &ranking,
    };
    let json = serde_json::to_string_pretty(&json).expect("summaries serialize");
    write_file(&dir.join("summary.json"), &json)?;
    write_file(&dir.join("report.html"), &html(plan, &frames, &ranking)?)?;
    Ok(StudyReport { frames, ranking })
}

fn write_file(path: &Path, text: &str) -> Result<(), StudyError> {
    std::fs::write(path, text).map_err(|source| StudyError::Io {
        path: path.to_owned(),
        source,
    })
}

fn csv_text(frames: &[FrameRow]) -> Result<String, StudyError> {
    let mut writer = csv::Writer::from_writer(Vec::new());
    for f in frames {
        let s = &f.summary;
        let main = s.objects.first();
        writer
            .serialize(CsvRow {
                variant: &f.variant,
                eye: f.eye_index,
                eye_x: f.eye[0],
                eye_y: f.eye[1],
                eye_z: f.eye[2],
                sun_index: f.sun_index,
                sun_time: f.sun_time.as_deref(),
                sun_azimuth_deg: f.sun_azimuth_deg,
                sun_elevation_deg: f.sun_elevation_deg,
                glass_pixels: s.glass_pixels,
                peak_reflected_luminance_cd_m2: s.peak_reflected_luminance_cd_m2,
                mean_reflected_luminance_cd_m2: s.mean_reflected_luminance_cd_m2,
                mean_transmitted_luminance_cd_m2: s.mean_transmitted_luminance_cd_m2,
                mean_marking_luminance_cd_m2: s.mean_marking_luminance_cd_m2,
                mean_background_luminance_cd_m2: s.mean_background_luminance_cd_m2,
                mean_veiling_ratio: s.mean_veiling_ratio,
                glare_area_share: s.glare_area_share,
                instrument_pixels: s.instrument_pixels,
                min_contrast: s.min_contrast,
                low_contrast_share: s.low_contrast_share,
                main_glare_source: main.map_or("", |o| o.name.as_str()),
                main_glare_source_area_share: main.map_or(0.0, |o| o.area_share),
            })
            .map_err(|e| StudyError::Plot(format!("CSV: {e}")))?;
    }
    let bytes = writer
        .into_inner()
        .map_err(|e| StudyError::Plot(format!("CSV: {e}")))?;
    Ok(String::from_utf8(bytes).expect("CSV of UTF-8 fields is UTF-8"))
}

/// The variants best first (see [`VariantScore`]).
fn rank_variants(plan: &StudyPlan, frames: &[FrameRow]) -> Vec<VariantScore> {
    let mut scores: Vec<VariantScore> = plan
        .variants
        .iter()
        .map(|v| {
            let rows: Vec<&FrameRow> = frames.iter().filter(|f| f.variant == v.name).collect();
            let n = rows.len().max(1) as f32;
            let mean = |f: fn(&FrameRow) -> f32| rows.iter().map(|r| f(r)).sum::<f32>() / n;
            let worst = |f: fn(&FrameRow) -> f32| rows.iter().map(|r| f(r)).fold(0.0, f32::max);
            // The object that covers the most glass, summed over the eyes
            // (ties to the first name).
            let mut areas: std::collections::BTreeMap<&str, usize> = Default::default();
            for o in rows.iter().flat_map(|r| &r.summary.objects) {
                *areas.entry(o.name.as_str()).or_default() += o.pixels;
            }
            let main = areas
                .iter()
                .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
                .map(|(name, _)| (*name).to_owned());
            // Brightest first; ties keep the frame order.
            let mut brightest: Vec<usize> = (0..frames.len())
                .filter(|&i| frames[i].variant == v.name)
                .collect();
            brightest.sort_by(|&a, &b| {
                frames[b]
                    .summary
                    .mean_reflected_luminance_cd_m2
                    .total_cmp(&frames[a].summary.mean_reflected_luminance_cd_m2)
            });
            let worst_cases = brightest
                .into_iter()
                .take(WORST_CASES)
                .map(|i| {
                    let f = &frames[i];
                    WorstCase {
                        frame: i,
                        eye_index: f.eye_index,
                        sun_index: f.sun_index,
                        sun_azimuth_deg: f.sun_azimuth_deg,
                        sun_elevation_deg: f.sun_elevation_deg,
                        sun_time: f.sun_time.clone(),
                        mean_reflected_luminance_cd_m2: f.summary.mean_reflected_luminance_cd_m2,
                        low_contrast_share: f.summary.low_contrast_share,
                        mirrored_object: f.summary.objects.first().map(|o| o.name.clone()),
                    }
                })
                .collect();
            VariantScore {
                variant: v.name.clone(),
                mean_glare_area_share: mean(|r| r.summary.glare_area_share),
                worst_glare_area_share: worst(|r| r.summary.glare_area_share),
                worst_low_contrast_share: worst(|r| r.summary.low_contrast_share),
                mean_reflected_luminance_cd_m2: mean(|r| r.summary.mean_reflected_luminance_cd_m2),
                peak_reflected_luminance_cd_m2: worst(|r| r.summary.peak_reflected_luminance_cd_m2),
                main_glare_source: main,
                worst_cases,
            }
        })
        .collect();
    scores.sort_by(|a, b| {
        a.mean_glare_area_share
            .total_cmp(&b.mean_glare_area_share)
            .then(
                a.worst_low_contrast_share
                    .total_cmp(&b.worst_low_contrast_share),
            )
            .then(
                a.mean_reflected_luminance_cd_m2
                    .total_cmp(&b.mean_reflected_luminance_cd_m2),
            )
    });
    scores
}

fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A metric plotted over the eye points.
struct Plot {
    title: &'static str,
    axis: &'static str,
    value: fn(&FrameRow) -> f32,
}

const PLOTS: [Plot; 3] = [
    Plot {
        title: "Mean reflected luminance on the glass",
        axis: "mean Lr (cd/m²)",
        value: |r| r.summary.mean_reflected_luminance_cd_m2,
    },
    Plot {
        title: "Glass area over the glare threshold",
        axis: "share of glass",
        value: |r| r.summary.glare_area_share,
    },
    Plot {
        title: "Instrument area under the contrast threshold",
        axis: "share of instruments",
        value: |r| r.summary.low_contrast_share,
    },
];

fn mean(values: &[f32]) -> f32 {
    values.iter().sum::<f32>() / values.len().max(1) as f32
}

/// One SVG line chart: the metric over the eye index (its mean over the sun
/// positions), a line per variant.
fn plot_svg(plan: &StudyPlan, frames: &[FrameRow], plot: &Plot) -> Result<String, StudyError> {
    let err = |e: &dyn std::fmt::Display| StudyError::Plot(e.to_string());
    let eyes = plan.eyes.len();
    let top = frames
        .iter()
        .map(plot.value)
        .fold(0.0f32, f32::max)
        .max(1e-6)
        * 1.1;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (720, 340)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(plot.title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(64)
            .build_cartesian_2d(-0.2f32..(eyes.max(2) - 1) as f32 + 0.2, 0f32..top)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("eye point (0 = nominal eye)")
            .y_desc(plot.axis)
            .x_labels(eyes.clamp(2, 20))
            .x_label_formatter(&|x| format!("{x:.0}"))
            .draw()
            .map_err(|e| err(&e))?;
        for (k, variant) in plan.variants.iter().enumerate() {
            let color = Palette99::pick(k).to_rgba();
            // The mean over the sun positions at each eye.
            let points: Vec<(f32, f32)> = (0..eyes)
                .map(|eye| {
                    let values: Vec<f32> = frames
                        .iter()
                        .filter(|f| f.variant == variant.name && f.eye_index == eye)
                        .map(plot.value)
                        .collect();
                    (eye as f32, mean(&values))
                })
                .collect();
            chart
                .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))
                .map_err(|e| err(&e))?
                .label(variant.name.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
            chart
                .draw_series(
                    points
                        .into_iter()
                        .map(|p| Circle::new(p, 3, color.filled())),
                )
                .map_err(|e| err(&e))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    Ok(svg)
}

fn html(
    plan: &StudyPlan,
    frames: &[FrameRow],
    ranking: &[VariantScore],
) -> Result<String, StudyError> {
    let mut h = String::new();
    let t = &plan.params.thresholds;
    let _ = write!(
        h,
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; color: #222; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
th, td {{ border: 1px solid #bbb; padding: 4px 8px; text-align: right; }}
th:first-child, td:first-child {{ text-align: left; }}
img {{ width: 320px; image-rendering: auto; }}
.frames td {{ vertical-align: top; }}
figure {{ display: inline-block; margin: 0 1em 1em 0; }}
</style></head><body>
<h1>{title}</h1>
<p>{variants} design variant(s) &times; {eyes} eye point(s){suns} = {frames} frames. Study file <code>{file}</code>.</p>
<p>Luminances in cd/m² ({scale} cd/m² per unit of rendered radiance).
Thresholds: glare where the reflected luminance L<sub>r</sub> &gt; {veil} cd/m² ({veil_source});
markings hard to read where CR = (L<sub>m</sub> + L<sub>r</sub> + L<sub>a</sub>) / (L<sub>b</sub> + L<sub>r</sub> + L<sub>a</sub>) &lt; {cr} ({cr_source}),
under {lux} lx ambient on a glass of diffuse reflectance {rho}, L<sub>a</sub> = {la:.1} cd/m² ({ambient_source}).
Heat maps share one logarithmic scale, {heat_min} to {heat_max} cd/m².</p>
"#,
        title = escape(&plan.name),
        variants = plan.variants.len(),
        eyes = plan.eyes.len(),
        suns = if plan.suns.is_empty() {
            String::new()
        } else {
            format!(" &times; {} sun position(s)", plan.suns.len())
        },
        frames = frames.len(),
        file = escape(&plan.file.display().to_string()),
        veil = t.veiling_luminance_cd_m2,
        veil_source = escape(&t.veiling_luminance_source),
        scale = plan.params.cd_m2_per_unit,
        cr = t.min_contrast,
        cr_source = escape(&t.min_contrast_source),
        lux = plan.params.ambient.illuminance_lux,
        rho = plan.params.ambient.glass_diffuse_reflectance,
        la = plan.params.ambient.veiling_luminance_cd_m2(),
        ambient_source = escape(&plan.params.ambient.source),
        heat_min = plan.heat_range.min_cd_m2,
        heat_max = plan.heat_range.max_cd_m2,
    );

    h.push_str("<h2>Ranking of the variants</h2>\n<p>Best first: by the mean glass area over the glare threshold, then the worst share of the instruments under the contrast threshold, then the mean reflected luminance.</p>\n<table><tr><th>variant</th><th>mean glare area</th><th>worst glare area</th><th>worst low-contrast area</th><th>mean L<sub>r</sub> (cd/m²)</th><th>peak L<sub>r</sub> (cd/m²)</th><th>main glare source</th></tr>\n");
    for s in ranking {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{:.2}%</td><td>{:.2}%</td><td>{:.2}%</td><td>{:.1}</td><td>{:.1}</td><td>{}</td></tr>",
            escape(&s.variant),
            s.mean_glare_area_share * 100.0,
            s.worst_glare_area_share * 100.0,
            s.worst_low_contrast_share * 100.0,
            s.mean_reflected_luminance_cd_m2,
            s.peak_reflected_luminance_cd_m2,
            escape(s.main_glare_source.as_deref().unwrap_or("none")),
        );
    }
    h.push_str("</table>\n<h2>Metrics over the eye points</h2>\n");
    for plot in &PLOTS {
        let _ = writeln!(h, "<figure>{}</figure>", plot_svg(plan, frames, plot)?);
    }
    h.push_str("<h2>Eye points</h2>\n<table><tr><th>eye</th><th>x</th><th>y</th><th>z</th></tr>\n");
    for (i, e) in plan.eyes.iter().enumerate() {
        let _ = writeln!(
            h,
            "<tr><td>{i}{}</td><td>{:.3}</td><td>{:.3}</td><td>{:.3}</td></tr>",
            if i == 0 { " (nominal)" } else { "" },
            e.x,
            e.y,
            e.z
        );
    }
    h.push_str("</table>\n");
    if !plan.suns_below_horizon.is_empty() {
        let _ = writeln!(
            h,
            "<p>Not rendered: {} time(s) of the sweep with the sun below the horizon ({}).</p>",
            plan.suns_below_horizon.len(),
            plan.suns_below_horizon
                .iter()
                .map(|t| t.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    // The polar plots of all variants share their colour scales.
    let polar_tops: Vec<f32> = POLAR_PLOTS
        .iter()
        .map(|plot| {
            per_sun(plan, frames, None, plot.value)
                .into_iter()
                .fold(0.0f32, f32::max)
        })
        .collect();
    for variant in &plan.variants {
        let _ = writeln!(h, "<h2>Variant: {}</h2>", escape(&variant.name));
        if !plan.suns.is_empty() {
            for (plot, &top) in POLAR_PLOTS.iter().zip(&polar_tops) {
                let _ = writeln!(
                    h,
                    "<figure>{}</figure>",
                    polar_svg(plan, frames, &variant.name, plot, top)
                );
            }
        }
        if let Some(score) = ranking.iter().find(|s| s.variant == variant.name) {
            h.push_str("<h3>Worst cases</h3>\n<table class=\"frames worst\"><tr><th>case</th><th>sun</th><th>eye</th><th>rendered image</th><th>reflected luminance (cd/m², log)</th><th>reflected objects</th><th>figures</th></tr>\n");
            for (k, case) in score.worst_cases.iter().enumerate() {
                let f = &frames[case.frame];
                let _ = writeln!(
                    h,
                    "<tr><td>{n}</td><td>{sun}</td><td>{eye}</td>{cells}</tr>",
                    n = k + 1,
                    sun = sun_text(f),
                    eye = f.eye_index,
                    cells = frame_cells(f),
                );
            }
            h.push_str("</table>\n");
        }
        if plan.suns.is_empty() {
            h.push_str("<h3>Every eye point</h3>\n<table class=\"frames\"><tr><th>eye</th><th>rendered image</th><th>reflected luminance (cd/m², log)</th><th>reflected objects</th><th>figures</th></tr>\n");
            for f in frames.iter().filter(|f| f.variant == variant.name) {
                let _ = writeln!(h, "<tr><td>{}</td>{}</tr>", f.eye_index, frame_cells(f));
            }
            h.push_str("</table>\n");
        }
    }
    h.push_str("</body></html>\n");
    Ok(h)
}

/// A frame's images and figures as table cells.
fn frame_cells(f: &FrameRow) -> String {
    let s = &f.summary;
    format!(
        "<td><a href=\"{img}\"><img src=\"{img}\" alt=\"image\"></a></td><td><a href=\"{heat}\"><img src=\"{heat}\" alt=\"heat map\"></a></td><td><a href=\"{obj}\"><img src=\"{obj}\" alt=\"object map\"></a></td><td>mean L<sub>r</sub> {mean:.1} cd/m²<br>peak L<sub>r</sub> {peak:.1} cd/m²<br>glare area {area:.2}%<br>low contrast {low:.2}%<br>mirrored: {main}</td>",
        img = escape(&f.image),
        heat = escape(&f.heat_map),
        obj = escape(&f.object_map),
        mean = s.mean_reflected_luminance_cd_m2,
        peak = s.peak_reflected_luminance_cd_m2,
        area = s.glare_area_share * 100.0,
        low = s.low_contrast_share * 100.0,
        main = escape(s.objects.first().map_or("none", |o| o.name.as_str())),
    )
}

/// Where a frame's sun stands, for the tables.
fn sun_text(f: &FrameRow) -> String {
    let mut text = match (f.sun_azimuth_deg, f.sun_elevation_deg) {
        (Some(a), Some(e)) => format!("azimuth {a:.1}&deg;, elevation {e:.1}&deg;"),
        _ => "none".to_owned(),
    };
    if let Some(t) = &f.sun_time {
        let _ = write!(text, "<br>{}", escape(t));
    }
    text
}

/// A metric over the sun positions.
struct PolarPlot {
    title: &'static str,
    value: fn(&FrameRow) -> f32,
}

const POLAR_PLOTS: [PolarPlot; 2] = [
    PolarPlot {
        title: "Mean reflected luminance (cd/m²) over the sun positions",
        value: |r| r.summary.mean_reflected_luminance_cd_m2,
    },
    PolarPlot {
        title: "Instrument area under the contrast threshold over the sun positions",
        value: |r| r.summary.low_contrast_share,
    },
];

/// Per sun position, the mean of `value` over the eye points of `variant`
/// (of every variant for `None`).
fn per_sun(
    plan: &StudyPlan,
    frames: &[FrameRow],
    variant: Option<&str>,
    value: fn(&FrameRow) -> f32,
) -> Vec<f32> {
    let mut sums = vec![(0.0f32, 0usize); plan.suns.len()];
    for f in frames {
        if let (Some(s), true) = (f.sun_index, variant.is_none_or(|v| v == f.variant)) {
            sums[s].0 += value(f);
            sums[s].1 += 1;
        }
    }
    sums.into_iter()
        .map(|(sum, n)| sum / n.max(1) as f32)
        .collect()
}

/// A polar plot (SVG) of a metric over the sun's azimuth (relative to the
/// vehicle, ahead at the top, clockwise) and elevation (the horizon at the
/// rim, the zenith in the centre): one disc per sun position, coloured from
/// 0 to `top` (the mean over the eye points).
fn polar_svg(
    plan: &StudyPlan,
    frames: &[FrameRow],
    variant: &str,
    plot: &PolarPlot,
    top: f32,
) -> String {
    const SIZE: f32 = 360.0;
    const RIM: f32 = 140.0;
    let (cx, cy) = (SIZE / 2.0, SIZE / 2.0 + 10.0);
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="11">"#,
        w = SIZE + 90.0,
        h = SIZE + 30.0
    );
    let _ = writeln!(
        svg,
        r#"<text x="{x}" y="14" text-anchor="middle" font-size="12">{}</text>"#,
        escape(plot.title),
        x = (SIZE + 90.0) / 2.0
    );
    for elevation in [0.0f32, 30.0, 60.0] {
        let r = RIM * (90.0 - elevation) / 90.0;
        let _ = writeln!(
            svg,
            r##"<circle cx="{cx}" cy="{cy}" r="{r}" fill="none" stroke="#bbb"/><text x="{x}" y="{y}" fill="#777">{elevation:.0}&#176;</text>"##,
            x = cx + 3.0,
            y = cy - r + 11.0
        );
    }
    for (azimuth, label) in [
        (0.0f32, "ahead"),
        (90.0, "right"),
        (180.0, "behind"),
        (270.0, "left"),
    ] {
        let (x, y) = polar_point(cx, cy, RIM, azimuth, 0.0);
        let (lx, ly) = polar_point(cx, cy, RIM + 12.0, azimuth, 0.0);
        let _ = writeln!(
            svg,
            r##"<line x1="{cx}" y1="{cy}" x2="{x:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{lx:.1}" y="{ly:.1}" text-anchor="middle" dominant-baseline="middle">{label}</text>"##
        );
    }
    let values = per_sun(plan, frames, Some(variant), plot.value);
    for (sun, value) in plan.suns.iter().zip(&values) {
        let (x, y) = polar_point(cx, cy, RIM, sun.azimuth_deg, sun.elevation_deg);
        let t = if top > 0.0 { value / top } else { 0.0 };
        let [r, g, b] = vtfarm_imaging::encode_srgb8(vtfarm_glare::ramp_color(t));
        let _ = writeln!(
            svg,
            r##"<circle cx="{x:.1}" cy="{y:.1}" r="7" fill="rgb({r},{g},{b})" stroke="#333"><title>azimuth {a:.1}, elevation {e:.1}: {value:.5}</title></circle>"##,
            a = sun.azimuth_deg,
            e = sun.elevation_deg
        );
    }
    // The colour scale.
    let (x0, y0, height) = (SIZE + 30.0, 40.0, 200.0);
    for k in 0..20 {
        let t = 1.0 - k as f32 / 19.0;
        let [r, g, b] = vtfarm_imaging::encode_srgb8(vtfarm_glare::ramp_color(t));
        let _ = writeln!(
            svg,
            r#"<rect x="{x0}" y="{y:.1}" width="14" height="{h:.1}" fill="rgb({r},{g},{b})"/>"#,
            y = y0 + height * k as f32 / 20.0,
            h = height / 20.0 + 0.5
        );
    }
    let _ = writeln!(
        svg,
        r#"<text x="{x0}" y="{y1}">{top:.3}</text><text x="{x0}" y="{y2}">0</text></svg>"#,
        y1 = y0 - 4.0,
        y2 = y0 + height + 12.0
    );
    svg
}

/// The plot position of a sun direction.
fn polar_point(cx: f32, cy: f32, rim: f32, azimuth_deg: f32, elevation_deg: f32) -> (f32, f32) {
    let r = rim * (90.0 - elevation_deg) / 90.0;
    let (sin, cos) = azimuth_deg.to_radians().sin_cos();
    (cx + r * sin, cy - r * cos)
}
