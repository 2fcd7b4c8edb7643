//! `summary.csv`, `summary.json` and `report.html` of a finished study.

use std::fmt::Write as _;
use std::path::Path;

use plotters::prelude::*;
use serde::Serialize;
use vtfarm_imaging::escape_html as escape;

use std::collections::BTreeMap;

use crate::{
    CULPRITS, Coverage, Culprit, FrameRow, MissingFrame, Provenance, StudyError, StudyPlan,
    StudyReport, SunSetting, VariantScore, WorstCase,
};

/// Worst cases listed per variant.
const WORST_CASES: usize = 3;

/// One flat CSV row (the JSON keeps the full summary per frame). The sun
/// columns are empty without a sweep (see [`crate::SunSetting`]).
#[derive(Serialize)]
struct CsvRow<'a> {
    variant: &'a str,
    eye: usize,
    eye_x_m: f32,
    eye_y_m: f32,
    eye_z_m: f32,
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
    culprit_1: &'a str,
    culprit_1_glare_share: Option<f32>,
    culprit_1_excess_cd_m2_px: Option<f32>,
    culprit_2: &'a str,
    culprit_2_glare_share: Option<f32>,
    culprit_2_excess_cd_m2_px: Option<f32>,
    culprit_3: &'a str,
    culprit_3_glare_share: Option<f32>,
    culprit_3_excess_cd_m2_px: Option<f32>,
    most_covering_object: &'a str,
    most_covering_object_coverage_share: Option<f32>,
    glint_pixels: usize,
    glint_peak_luminance_cd_m2: f32,
    glint_eye_illuminance_lux: f32,
    glint_worst_instrument: &'a str,
    glint_worst_veiling_luminance_cd_m2: Option<f32>,
    glint_worst_angle_deg: Option<f32>,
    glint_worst_within_cie_validity: Option<bool>,
    direct_sun_contrast: Option<f32>,
}

#[derive(Serialize)]
struct JsonSummary<'a> {
    study: &'a str,
    /// How the report was made (inputs with hashes, quality, workers).
    provenance: &'a Provenance,
    /// Whether every frame of the study is in it.
    complete: bool,
    missing_frames: &'a [MissingFrame],
    cd_m2_per_unit: f32,
    thresholds: &'a vtfarm_glare::Thresholds,
    ambient: &'a vtfarm_glare::AmbientCondition,
    heat_min_cd_m2: f32,
    heat_max_cd_m2: f32,
    /// The sun glint's threshold and the veiling-luminance formula.
    glint_threshold: &'a vtfarm_glare::GlintThreshold,
    glint_veiling_formula: &'static str,
    /// Eye points, metres.
    eyes_m: Vec<[f32; 3]>,
    /// How the sun was set: a sweep, a fixed sun from the base job, or none.
    sun: crate::SunSetting,
    /// Sun times of the sweep with the sun below the horizon (not rendered).
    suns_below_horizon: Vec<String>,
    frames: &'a [FrameRow],
    ranking: &'a [VariantScore],
}

pub(crate) fn write_all(
    plan: &StudyPlan,
    dir: &Path,
    frames: Vec<FrameRow>,
    provenance: &Provenance,
    missing_frames: Vec<MissingFrame>,
) -> Result<StudyReport, StudyError> {
    let ranking = rank_variants(plan, &frames);
    write_file(&dir.join("summary.csv"), &csv_text(&frames)?)?;
    let json = JsonSummary {
        study: &plan.name,
        provenance,
        complete: missing_frames.is_empty(),
        missing_frames: &missing_frames,
        cd_m2_per_unit: plan.params.cd_m2_per_unit,
        thresholds: &plan.params.thresholds,
        ambient: &plan.params.ambient,
        heat_min_cd_m2: plan.heat_range.min_cd_m2,
        heat_max_cd_m2: plan.heat_range.max_cd_m2,
        glint_threshold: &plan.glint,
        glint_veiling_formula: vtfarm_glare::CIE_SOURCE,
        eyes_m: plan.eyes.iter().map(|e| e.to_array()).collect(),
        sun: plan.sun_setting(),
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
    let html = html(plan, &frames, &ranking, provenance, &missing_frames)?;
    write_file(&dir.join("report.html"), &html)?;
    Ok(StudyReport {
        frames,
        missing_frames,
        ranking,
    })
}

fn write_file(path: &Path, text: &str) -> Result<(), StudyError> {
    std::fs::write(path, text).map_err(|cause| StudyError::Io {
        path: path.to_owned(),
        cause,
    })
}

fn csv_text(frames: &[FrameRow]) -> Result<String, StudyError> {
    let mut writer = csv::Writer::from_writer(Vec::new());
    for f in frames {
        let s = &f.summary;
        let culprits = Culprit::of_frame(s);
        let covering = Coverage::of_frame(s);
        let culprit = |k: usize| culprits.get(k);
        let name = |k: usize| culprit(k).map_or("", |c| c.name.as_str());
        let glare_share = |k: usize| culprit(k).map(|c| c.glare_share);
        let excess = |k: usize| culprit(k).map(|c| c.excess_luminance_cd_m2);
        let worst = f.glint.worst_instrument();
        writer
            .serialize(CsvRow {
                variant: &f.variant,
                eye: f.eye_index,
                eye_x_m: f.eye[0],
                eye_y_m: f.eye[1],
                eye_z_m: f.eye[2],
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
                culprit_1: name(0),
                culprit_1_glare_share: glare_share(0),
                culprit_1_excess_cd_m2_px: excess(0),
                culprit_2: name(1),
                culprit_2_glare_share: glare_share(1),
                culprit_2_excess_cd_m2_px: excess(1),
                culprit_3: name(2),
                culprit_3_glare_share: glare_share(2),
                culprit_3_excess_cd_m2_px: excess(2),
                most_covering_object: covering.as_ref().map_or("", |c| c.name.as_str()),
                most_covering_object_coverage_share: covering.as_ref().map(|c| c.coverage_share),
                glint_pixels: f.glint.pixels,
                glint_peak_luminance_cd_m2: f.glint.peak_luminance_cd_m2,
                glint_eye_illuminance_lux: f.glint.eye_illuminance_lux,
                glint_worst_instrument: worst.map_or("", |w| w.name.as_str()),
                glint_worst_veiling_luminance_cd_m2: worst.map(|w| w.veiling_luminance_cd_m2),
                glint_worst_angle_deg: worst.map(|w| w.angle_deg),
                glint_worst_within_cie_validity: worst.map(|w| w.within_validity),
                direct_sun_contrast: f.direct_sun_contrast,
            })
            .map_err(|e| StudyError::Plot(format!("CSV: {e}")))?;
    }
    let bytes = writer
        .into_inner()
        .map_err(|e| StudyError::Plot(format!("CSV: {e}")))?;
    Ok(String::from_utf8(bytes).expect("CSV of UTF-8 fields is UTF-8"))
}

/// The culprits of a set of frames' glare, summed over them (see
/// [`VariantScore::glare_culprits`]), and the object covering the most of
/// their glass.
fn culprits_over(rows: &[&FrameRow]) -> (Vec<Culprit>, Option<Coverage>) {
    #[derive(Default)]
    struct Tally {
        glare: usize,
        excess: f64,
        covered: usize,
    }
    let mut per: BTreeMap<&str, Tally> = BTreeMap::new();
    let (mut glare, mut glass) = (0usize, 0usize);
    for r in rows {
        glare += r.summary.glare_pixels;
        glass += r.summary.glass_pixels;
        for o in &r.summary.objects {
            let t = per.entry(o.name.as_str()).or_default();
            t.glare += o.glare_pixels;
            t.excess += f64::from(o.excess_luminance_cd_m2);
            t.covered += o.covered_pixels;
        }
        if r.summary.background_glare_pixels > 0 {
            let t = per.entry(crate::BACKGROUND_CULPRIT).or_default();
            t.glare += r.summary.background_glare_pixels;
            t.excess += f64::from(r.summary.background_excess_luminance_cd_m2);
        }
    }
    let share = |part: usize, whole: usize| {
        if whole == 0 {
            0.0
        } else {
            (part as f64 / whole as f64) as f32
        }
    };
    let mut ranked: Vec<(&str, &Tally)> = per.iter().map(|(n, t)| (*n, t)).collect();
    ranked.sort_by(|a, b| {
        (b.1.glare.cmp(&a.1.glare))
            .then(b.1.excess.total_cmp(&a.1.excess))
            .then(b.1.covered.cmp(&a.1.covered))
            .then(a.0.cmp(b.0))
    });
    let culprits = (ranked.iter())
        .filter(|(_, t)| t.glare > 0)
        .take(CULPRITS)
        .map(|(name, t)| Culprit {
            name: (*name).to_owned(),
            glare_pixels: t.glare,
            glare_share: share(t.glare, glare),
            excess_luminance_cd_m2: t.excess as f32,
        })
        .collect();
    let covering = (ranked.iter())
        .filter(|(_, t)| t.covered > 0)
        .max_by(|a, b| a.1.covered.cmp(&b.1.covered).then(b.0.cmp(a.0)))
        .map(|(name, t)| Coverage {
            name: (*name).to_owned(),
            coverage_share: share(t.covered, glass),
        });
    (culprits, covering)
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
            let (glare_culprits, most_covering_object) = culprits_over(&rows);
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
                        glare_culprits: Culprit::of_frame(&f.summary),
                        most_covering_object: Coverage::of_frame(&f.summary),
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
                glare_culprits,
                most_covering_object,
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

/// A metric plotted over the eye points.
struct Plot {
    title: &'static str,
    axis: &'static str,
    value: fn(&FrameRow) -> f32,
    /// Draw the glare threshold (a luminance in cd/m²).
    threshold_line: bool,
}

const PLOTS: [Plot; 4] = [
    Plot {
        title: "Peak reflected luminance on the glass",
        axis: "peak Lr (cd/m²)",
        value: |r| r.summary.peak_reflected_luminance_cd_m2,
        threshold_line: true,
    },
    Plot {
        title: "Mean reflected luminance on the glass",
        axis: "mean Lr (cd/m²)",
        value: |r| r.summary.mean_reflected_luminance_cd_m2,
        threshold_line: true,
    },
    Plot {
        title: "Glass area over the glare threshold",
        axis: "% of the glass",
        value: |r| r.summary.glare_area_share * 100.0,
        threshold_line: false,
    },
    Plot {
        title: "Instrument area under the contrast threshold",
        axis: "% of the instrument area",
        value: |r| r.summary.low_contrast_share * 100.0,
        threshold_line: false,
    },
];

fn mean(values: &[f32]) -> f32 {
    values.iter().sum::<f32>() / values.len().max(1) as f32
}

/// The sRGB colour of variant `k` in the plots and their legend.
fn variant_color(k: usize) -> RGBColor {
    let (r, g, b) = Palette99::pick(k).rgb();
    RGBColor(r, g, b)
}

/// The variants' markers and names, as HTML above the plots (a legend
/// outside the charts covers no point).
fn plot_legend(plan: &StudyPlan) -> String {
    let mut h = String::from("<p class=\"legend\">");
    for (k, variant) in plan.variants.iter().enumerate() {
        let RGBColor(r, g, b) = variant_color(k);
        let _ = write!(
            h,
            "<span><svg width=\"14\" height=\"14\"><circle cx=\"7\" cy=\"7\" r=\"5\" fill=\"rgb({r},{g},{b})\"/></svg> {}</span>",
            escape(&variant.name)
        );
    }
    h.push_str("<span><svg width=\"26\" height=\"14\"><line x1=\"0\" y1=\"7\" x2=\"26\" y2=\"7\" stroke=\"#c00\" stroke-width=\"2\" stroke-dasharray=\"5,3\"/></svg> glare threshold</span></p>\n");
    h
}

/// One SVG chart: the metric at each eye point (its mean over the sun
/// positions), a point per variant, side by side; eye points are not
/// joined (they are points on an ellipse, not a series).
fn plot_svg(plan: &StudyPlan, frames: &[FrameRow], plot: &Plot) -> Result<String, StudyError> {
    let err = |e: &dyn std::fmt::Display| StudyError::Plot(e.to_string());
    let eyes = plan.eyes.len();
    let threshold = plan.params.thresholds.veiling_luminance_cd_m2;
    let data_top = frames.iter().map(plot.value).fold(0.0f32, f32::max);
    let top = if plot.threshold_line {
        data_top.max(threshold)
    } else {
        data_top
    }
    .max(1e-6)
        * 1.12;
    let variants = plan.variants.len().max(1);
    // Each variant's points sit beside the others' at an eye point.
    let offset = |k: usize| (k as f32 + 0.5) / variants as f32 * 0.6 - 0.3;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (640, 320)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(plot.title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(72)
            .build_cartesian_2d(-0.5f32..(eyes.max(1) as f32 - 0.5), 0f32..top)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("eye point (0 = nominal eye; see the table of eye points)")
            .y_desc(plot.axis)
            .x_labels(eyes.clamp(1, 20))
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_labels(6)
            .y_label_formatter(&|y| {
                if top >= 20.0 {
                    format!("{y:.0}")
                } else {
                    format!("{y:.1}")
                }
            })
            .light_line_style(WHITE)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 14))
            .disable_x_mesh()
            .draw()
            .map_err(|e| err(&e))?;
        if plot.threshold_line {
            chart
                .draw_series(DashedLineSeries::new(
                    [(-0.5, threshold), (eyes as f32 - 0.5, threshold)],
                    6,
                    4,
                    RGBColor(0xcc, 0, 0).stroke_width(2),
                ))
                .map_err(|e| err(&e))?;
        }
        for (k, variant) in plan.variants.iter().enumerate() {
            let color = variant_color(k);
            // The mean over the sun positions at each eye.
            let points: Vec<(f32, f32)> = (0..eyes)
                .map(|eye| {
                    let values: Vec<f32> = frames
                        .iter()
                        .filter(|f| f.variant == variant.name && f.eye_index == eye)
                        .map(plot.value)
                        .collect();
                    (eye as f32 + offset(k), mean(&values))
                })
                .collect();
            chart
                .draw_series(
                    points
                        .into_iter()
                        .map(|p| Circle::new(p, 4, color.filled())),
                )
                .map_err(|e| err(&e))?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    Ok(svg)
}

/// How the sun was set, in a sentence for the report's introduction.
fn sun_sentence(setting: &SunSetting) -> String {
    match setting {
        SunSetting::Sweep { positions } => format!(
            "Sun: swept over {positions} position(s) above the horizon (each frame names its own)."
        ),
        SunSetting::FixedFromJob {
            azimuth_deg,
            elevation_deg,
        } => format!(
            "Sun: fixed, the base job's directional light, the same in every frame (azimuth {azimuth_deg:.1}&deg; and elevation {elevation_deg:.1}&deg; relative to the vehicle, 0&deg; = ahead, clockwise)."
        ),
        SunSetting::None => "Sun: none (the base job has no directional light).".to_owned(),
    }
}

/// A luminance for a legend: 3 significant digits at most, no exponent,
/// no trailing zeros (`10000`, `12.5`, `1`, `0.25`).
fn luminance_label(v: f32) -> String {
    let decimals = if v >= 100.0 {
        0
    } else if v >= 10.0 {
        1
    } else if v >= 1.0 {
        2
    } else {
        3
    };
    let text = format!("{v:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        text
    }
}

/// The heat maps' legend (SVG): the colour bar of the shared logarithmic
/// scale with its luminances, and the glare threshold marked on it.
fn heat_legend(plan: &StudyPlan) -> String {
    const BAR_TOP: f32 = 44.0;
    const BAR_HEIGHT: f32 = 150.0;
    const STEPS: usize = 30;
    let range = plan.heat_range;
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg class="legend-bar" xmlns="http://www.w3.org/2000/svg" width="112" height="{h}" font-family="sans-serif" font-size="12"><text x="0" y="14">cd/m², log</text>"#,
        h = BAR_TOP + BAR_HEIGHT + 12.0
    );
    for k in 0..STEPS {
        let t = 1.0 - (k as f32 + 0.5) / STEPS as f32;
        let [r, g, b] = vtfarm_imaging::encode_srgb8(vtfarm_glare::ramp_color(t));
        let _ = writeln!(
            svg,
            r#"<rect x="0" y="{y:.1}" width="16" height="{h:.2}" fill="rgb({r},{g},{b})"/>"#,
            y = BAR_TOP + BAR_HEIGHT * k as f32 / STEPS as f32,
            h = BAR_HEIGHT / STEPS as f32 + 0.3
        );
    }
    for (t, value) in range.ticks(5) {
        let y = BAR_TOP + BAR_HEIGHT * (1.0 - t);
        let _ = writeln!(
            svg,
            r##"<line x1="16" y1="{y:.1}" x2="21" y2="{y:.1}" stroke="#333"/><text x="24" y="{ty:.1}">{label}</text>"##,
            ty = y + 4.0,
            label = luminance_label(value)
        );
    }
    let [r, g, b] = vtfarm_glare::BEYOND_SCALE_SRGB;
    let _ = writeln!(
        svg,
        r##"<rect x="0" y="{y}" width="16" height="8" fill="rgb({r},{g},{b})" stroke="#333"/><text x="24" y="{ty}">&gt; {top}</text>"##,
        y = BAR_TOP - 24.0,
        ty = BAR_TOP - 16.0,
        top = luminance_label(range.max_cd_m2)
    );
    let threshold = plan.params.thresholds.veiling_luminance_cd_m2;
    let t = range.position(threshold);
    if threshold > range.min_cd_m2 && threshold < range.max_cd_m2 {
        let y = BAR_TOP + BAR_HEIGHT * (1.0 - t);
        let _ = writeln!(
            svg,
            r##"<line x1="0" y1="{y:.1}" x2="16" y2="{y:.1}" stroke="#0c0" stroke-width="2"/><text x="62" y="{ty:.1}" fill="#080">&#8592; glare</text>"##,
            ty = y + 4.0
        );
    }
    svg.push_str("</svg>");
    svg
}

/// A frame's object map legend (HTML): each object's swatch, the share of
/// the glare area it causes and the share of the glass it covers.
fn object_legend(f: &FrameRow) -> String {
    const SHOWN: usize = 8;
    let objects = &f.summary.objects;
    let mut h = String::from(
        "<table class=\"objects\"><tr><th></th><th>object</th><th>glare</th><th>glass</th></tr>",
    );
    for (rank, o) in objects.iter().enumerate().take(SHOWN) {
        let [r, g, b] = vtfarm_glare::object_color_srgb(rank);
        let _ = write!(
            h,
            "<tr><td><span class=\"swatch\" style=\"background:rgb({r},{g},{b})\"></span></td><td>{}</td><td>{:.1}%</td><td>{:.1}%</td></tr>",
            escape(&o.name),
            o.glare_share * 100.0,
            o.coverage_share * 100.0
        );
    }
    if objects.len() > SHOWN {
        let _ = write!(
            h,
            "<tr><td></td><td colspan=\"3\">and {} more</td></tr>",
            objects.len() - SHOWN
        );
    }
    let [r, g, b] = vtfarm_imaging::encode_srgb8(vtfarm_glare::NO_OBJECT_COLOR);
    let s = &f.summary;
    let background = if s.glare_pixels == 0 {
        0.0
    } else {
        s.background_glare_pixels as f64 / s.glare_pixels as f64
    };
    let _ = write!(
        h,
        "<tr><td><span class=\"swatch\" style=\"background:rgb({r},{g},{b})\"></span></td><td>background</td><td>{:.1}%</td><td></td></tr></table>",
        background * 100.0
    );
    h
}

/// Culprits as "name 98.1%, name 1.9%" (shares of the glare area), or
/// "none (no glare)".
fn culprits_text(culprits: &[Culprit]) -> String {
    if culprits.is_empty() {
        return "none (no glare)".to_owned();
    }
    (culprits.iter())
        .map(|c| format!("{} {:.1}%", escape(&c.name), c.glare_share * 100.0))
        .collect::<Vec<_>>()
        .join("<br>")
}

fn coverage_text(coverage: &Option<Coverage>) -> String {
    coverage.as_ref().map_or("nothing".to_owned(), |c| {
        format!("{} {:.1}%", escape(&c.name), c.coverage_share * 100.0)
    })
}

fn html(
    plan: &StudyPlan,
    frames: &[FrameRow],
    ranking: &[VariantScore],
    provenance: &Provenance,
    missing: &[MissingFrame],
) -> Result<String, StudyError> {
    let mut h = String::new();
    let t = &plan.params.thresholds;
    let setting = plan.sun_setting();
    let swept = matches!(setting, SunSetting::Sweep { .. });
    let _ = write!(
        h,
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; color: #222; font-size: 15px; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
th, td {{ border: 1px solid #bbb; padding: 4px 8px; text-align: right; }}
th:first-child, td:first-child {{ text-align: left; }}
img {{ width: 216px; image-rendering: auto; }}
table.frames {{ table-layout: fixed; }}
.frames th {{ text-align: left; }}
.frames td {{ vertical-align: top; font-size: 13px; overflow-wrap: anywhere; }}
.frames td:last-child {{ text-align: left; }}
.map {{ display: flex; gap: 4px; align-items: flex-start; }}
table.objects {{ margin: 0; font-size: 12px; }}
table.objects td, table.objects th {{ border: none; padding: 1px 4px; text-align: left; white-space: nowrap; }}
.swatch {{ display: inline-block; width: 12px; height: 12px; border: 1px solid #555; }}
.legend span {{ margin-right: 1.5em; white-space: nowrap; }}
figure {{ display: inline-block; margin: 0 1em 1em 0; }}
.warning {{ background: #fff3cd; border: 1px solid #c9a227; padding: 6px 10px; }}
table.provenance td {{ text-align: left; }}
</style></head><body>
<h1>{title}</h1>
{made}<p>{variants} design variant(s) &times; {eyes} eye point(s){suns} = {frames} frames. Study file <code>{file}</code>.</p>
<p>{sun}</p>
<p>Luminances in cd/m² ({scale} cd/m² per unit of rendered radiance). The reflected luminance L<sub>r</sub> is the light the glass reflects toward the eye, its back surface's ghost image included.
Thresholds: glare where L<sub>r</sub> &gt; {veil} cd/m² ({veil_source});
markings hard to read where CR = (L<sub>m</sub> + L<sub>r</sub> + L<sub>a</sub>) / (L<sub>b</sub> + L<sub>r</sub> + L<sub>a</sub>) &lt; {cr} ({cr_source}),
under {lux} lx ambient on a glass of diffuse reflectance {rho}, L<sub>a</sub> = {la:.1} cd/m² ({ambient_source}).
Heat maps share one logarithmic scale, {heat_min} to {heat_max} cd/m².
The sun's glint is the glass pixels with L<sub>r</sub> &ge; {glint} cd/m² ({glint_source}); its illuminance at the eye E is &Sigma; L&middot;&Omega; over them, and its veiling luminance on each instrument L<sub>v</sub> = 10&middot;E/&theta;² ({cie}); a &theta; outside 1&ndash;30&deg; is flagged. The contrast with L<sub>v</sub> adds it to both luminances (the direct-sun case).
The culprits of the glare are the objects whose reflections cause it: ranked by the glass area over the threshold they cause, then the luminance they add above it; each share is of the glare area.</p>
"#,
        title = escape(&plan.name),
        made = provenance_html(provenance, missing, plan.frames()),
        variants = plan.variants.len(),
        eyes = plan.eyes.len(),
        suns = if plan.suns.is_empty() {
            String::new()
        } else {
            format!(" &times; {} sun position(s)", plan.suns.len())
        },
        frames = frames.len(),
        file = escape(&plan.file.display().to_string()),
        sun = sun_sentence(&setting),
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
        glint = plan.glint.luminance_cd_m2,
        glint_source = escape(&plan.glint.source),
        cie = escape(vtfarm_glare::CIE_SOURCE),
    );

    h.push_str("<h2>Ranking of the variants</h2>\n<p>Best first: by the mean glass area over the glare threshold, then the worst share of the instruments under the contrast threshold, then the mean reflected luminance.</p>\n<table><tr><th>variant</th><th>mean glare area<br>(% of glass)</th><th>worst glare area<br>(% of glass)</th><th>worst low-contrast area<br>(% of instruments)</th><th>mean L<sub>r</sub><br>(cd/m²)</th><th>peak L<sub>r</sub><br>(cd/m²)</th><th>glare culprits<br>(% of the glare area)</th><th>covers most glass<br>(% of glass, any luminance)</th></tr>\n");
    for s in ranking {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.1}</td><td>{:.1}</td><td>{}</td><td>{}</td></tr>",
            escape(&s.variant),
            s.mean_glare_area_share * 100.0,
            s.worst_glare_area_share * 100.0,
            s.worst_low_contrast_share * 100.0,
            s.mean_reflected_luminance_cd_m2,
            s.peak_reflected_luminance_cd_m2,
            culprits_text(&s.glare_culprits),
            coverage_text(&s.most_covering_object),
        );
    }
    h.push_str("</table>\n<h2>Metrics over the eye points</h2>\n");
    if swept {
        h.push_str("<p>Each point is the mean over the sun positions.</p>\n");
    }
    h.push_str(&plot_legend(plan));
    for plot in &PLOTS {
        let _ = writeln!(h, "<figure>{}</figure>", plot_svg(plan, frames, plot)?);
    }
    h.push_str("<h2>Eye points</h2>\n<table><tr><th>eye</th><th>x (m)</th><th>y (m)</th><th>z (m)</th></tr>\n");
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
    // The polar plots of all variants share their colour scales: each
    // covers every variant's values.
    let polar_tops: Vec<f32> = POLAR_PLOTS
        .iter()
        .map(|plot| {
            (plan.variants.iter())
                .flat_map(|v| per_sun(plan, frames, &v.name, plot.value))
                .flatten()
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
            // In a sweep the case names its sun (one column fewer keeps the
            // table within 1400 px).
            let (case_width, case_header) = if swept {
                (80, "case and sun")
            } else {
                (44, "case")
            };
            let _ = writeln!(
                h,
                "<h3>Worst cases</h3>\n<p>The frames with the highest mean reflected luminance.</p>\n<table class=\"frames worst\">{cols}<tr><th>{case_header}</th><th>eye</th>{FRAME_HEADERS}</tr>",
                cols = frame_columns(case_width),
            );
            for (k, case) in score.worst_cases.iter().enumerate() {
                let f = &frames[case.frame];
                let sun = if swept {
                    format!("<br>sun {}", sun_text(f))
                } else {
                    String::new()
                };
                let _ = writeln!(
                    h,
                    "<tr><td>{n}{sun}</td><td>{eye}</td>{cells}</tr>",
                    n = k + 1,
                    eye = f.eye_index,
                    cells = frame_cells(plan, f),
                );
            }
            h.push_str("</table>\n");
        }
        if !swept {
            let _ = writeln!(
                h,
                "<h3>Every eye point</h3>\n<table class=\"frames\">{cols}<tr><th>eye</th>{FRAME_HEADERS}</tr>",
                cols = frame_columns(0),
            );
            for f in frames.iter().filter(|f| f.variant == variant.name) {
                let _ = writeln!(
                    h,
                    "<tr><td>{}</td>{}</tr>",
                    f.eye_index,
                    frame_cells(plan, f)
                );
            }
            h.push_str("</table>\n");
        }
    }
    h.push_str("</body></html>\n");
    Ok(h)
}

/// The report's header block: a warning for a quality below `full`, the
/// frames a partial report lacks, and how the report was made.
fn provenance_html(p: &Provenance, missing: &[MissingFrame], frames: usize) -> String {
    let mut h = String::new();
    if let Some(w) = &p.quality_warning {
        let _ = writeln!(h, "<p class=\"warning\">Warning: {}.</p>", escape(w));
    }
    if !missing.is_empty() {
        let list: Vec<String> = (missing.iter())
            .map(|m| {
                let sun = m.sun_index.map_or(String::new(), |s| format!(" sun {s}"));
                format!("{}{sun} eye {}", escape(&m.variant), m.eye_index)
            })
            .collect();
        let _ = writeln!(
            h,
            "<p class=\"warning\">Partial report: {} of {frames} frames rendered; every figure below is over those only. Missing ({}): {}.</p>",
            frames - missing.len(),
            missing.len(),
            list.join(", ")
        );
    }
    let inputs: String = (p.inputs.iter())
        .map(|f| {
            format!(
                "<tr><th>{}</th><td><code>{}</code><br>{} {}</td></tr>",
                escape(&f.role),
                escape(&f.path),
                p.hash,
                f.sha256
            )
        })
        .collect();
    let _ = writeln!(
        h,
        "<section id=\"provenance\"><table class=\"provenance\"><tr><th>made by</th><td>vtfarm {version}</td></tr><tr><th>date</th><td>{date}</td></tr><tr><th>quality, method</th><td>{quality}, {method}</td></tr><tr><th>resolution</th><td>{w} &times; {h} px</td></tr>{inputs}<tr><th>rendered by</th><td>{workers}</td></tr><tr><th>command</th><td><code>{command}</code></td></tr></table></section>",
        version = escape(&p.vtfarm_version),
        date = escape(&p.date),
        quality = p.quality,
        method = p.method,
        w = p.width,
        h = p.height,
        workers = escape(&p.workers),
        command = escape(&p.command),
    );
    h
}

/// The column widths of a frame table (px): a first column of
/// `first_width` (none for 0), the eye, then [`frame_cells`]' columns, so
/// that every legend sits beside its map within 1400 px.
fn frame_columns(first_width: u32) -> String {
    let mut widths = Vec::new();
    if first_width > 0 {
        widths.push(first_width);
    }
    widths.extend([40, 228, 340, 470, 176]);
    let cols: String = (widths.iter())
        .map(|w| format!("<col style=\"width:{w}px\">"))
        .collect();
    format!("<colgroup>{cols}</colgroup>")
}

/// The column headers of [`frame_cells`].
const FRAME_HEADERS: &str = "<th>rendered image</th><th>reflected luminance L<sub>r</sub><br>(cd/m², log scale;<br>green: glare threshold)</th><th>reflected objects<br>(glare: % of the glare area;<br>glass: % of the glass covered)</th><th>figures</th>";

/// A frame's images, their legends and figures as table cells.
fn frame_cells(plan: &StudyPlan, f: &FrameRow) -> String {
    let s = &f.summary;
    format!(
        "<td><a href=\"{img}\"><img src=\"{img}\" alt=\"image\"></a></td><td><div class=\"map\"><a href=\"{heat}\"><img src=\"{heat}\" alt=\"heat map\"></a>{heat_legend}</div></td><td><div class=\"map\"><a href=\"{obj}\"><img src=\"{obj}\" alt=\"object map\"></a>{object_legend}</div></td><td>mean L<sub>r</sub> {mean:.1} cd/m²<br>peak L<sub>r</sub> {peak:.1} cd/m²<br>glare area {area:.2}% of glass<br>low contrast {low:.2}% of instruments<br>glare culprits:<br>{culprits}<br>covers most glass:<br>{covering}{glint}</td>",
        img = escape(&f.image),
        heat = escape(&f.heat_map),
        obj = escape(&f.object_map),
        heat_legend = heat_legend(plan),
        object_legend = object_legend(f),
        mean = s.mean_reflected_luminance_cd_m2,
        peak = s.peak_reflected_luminance_cd_m2,
        area = s.glare_area_share * 100.0,
        low = s.low_contrast_share * 100.0,
        culprits = culprits_text(&Culprit::of_frame(s)),
        covering = coverage_text(&Coverage::of_frame(s)),
        glint = crate::glint::glint_html(f),
    )
}

/// Where a swept frame's sun stands, for the tables.
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
    /// The colour scale's top, with its unit.
    label: fn(f32) -> String,
}

const POLAR_PLOTS: [PolarPlot; 2] = [
    PolarPlot {
        title: "Mean reflected luminance (cd/m²) over the sun positions",
        value: |r| r.summary.mean_reflected_luminance_cd_m2,
        label: |v| format!("{v:.0} cd/m²"),
    },
    PolarPlot {
        title: "Instrument area under the contrast threshold over the sun positions",
        value: |r| r.summary.low_contrast_share,
        label: |v| format!("{:.1}% of instruments", v * 100.0),
    },
];

/// Per sun position, the mean of `value` over the rendered eye points of
/// `variant`; `None` where none is rendered (a partial report).
fn per_sun(
    plan: &StudyPlan,
    frames: &[FrameRow],
    variant: &str,
    value: fn(&FrameRow) -> f32,
) -> Vec<Option<f32>> {
    let mut sums = vec![(0.0f32, 0usize); plan.suns.len()];
    for f in frames {
        if let (Some(s), true) = (f.sun_index, variant == f.variant) {
            sums[s].0 += value(f);
            sums[s].1 += 1;
        }
    }
    sums.into_iter()
        .map(|(sum, n)| (n > 0).then(|| sum / n as f32))
        .collect()
}

/// A polar plot (SVG) of a metric over the sun's azimuth (relative to the
/// vehicle, ahead at the top, clockwise) and elevation (the horizon at the
/// rim, the zenith in the centre): one disc per sun position, coloured from
/// 0 to `top` (the mean over the eye points), in the beyond-scale colour
/// above it, hollow where not rendered; a ring marks the sun positions
/// whose glint reaches the eye. Every disc carries its value and the
/// scale's top (`data-value`, `data-top`).
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
        r#"<svg class="polar" xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="11">"#,
        w = SIZE + 170.0,
        h = SIZE + 50.0
    );
    let _ = writeln!(
        svg,
        r#"<text x="{x}" y="14" text-anchor="middle" font-size="12">{}</text>"#,
        escape(plot.title),
        x = (SIZE + 170.0) / 2.0
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
    let values = per_sun(plan, frames, variant, plot.value);
    let glints = crate::glint::suns_with_glint(frames, variant);
    for (s, (sun, value)) in plan.suns.iter().zip(&values).enumerate() {
        let (x, y) = polar_point(cx, cy, RIM, sun.azimuth_deg, sun.elevation_deg);
        let (a, e) = (sun.azimuth_deg, sun.elevation_deg);
        if glints.contains(&s) {
            let _ = writeln!(
                svg,
                r##"<circle cx="{x:.1}" cy="{y:.1}" r="11" fill="none" stroke="#d00" stroke-width="2.5"/>"##
            );
        }
        let Some(value) = *value else {
            let _ = writeln!(
                svg,
                r##"<circle cx="{x:.1}" cy="{y:.1}" r="7" fill="none" stroke="#999" stroke-dasharray="2,2"><title>azimuth {a:.1}, elevation {e:.1}: not rendered</title></circle>"##
            );
            continue;
        };
        let beyond = value > top;
        let [r, g, b] = if beyond {
            vtfarm_glare::BEYOND_SCALE_SRGB
        } else {
            let t = if top > 0.0 { value / top } else { 0.0 };
            vtfarm_imaging::encode_srgb8(vtfarm_glare::ramp_color(t))
        };
        let _ = writeln!(
            svg,
            r##"<circle cx="{x:.1}" cy="{y:.1}" r="7" fill="rgb({r},{g},{b})" stroke="#333" data-value="{value}" data-top="{top}" data-beyond="{beyond}"><title>azimuth {a:.1}, elevation {e:.1}: {label}</title></circle>"##,
            label = (plot.label)(value),
        );
    }
    // The colour scale, shared by the variants' plots.
    let (x0, y0, height) = (SIZE + 30.0, 80.0, 200.0);
    let [r, g, b] = vtfarm_glare::BEYOND_SCALE_SRGB;
    let _ = writeln!(
        svg,
        r##"<text x="{x0}" y="{t0}">scale shared by all variants</text><rect x="{x0}" y="{y:.1}" width="14" height="8" fill="rgb({r},{g},{b})" stroke="#333"/><text x="{tx}" y="{ty:.1}">above the scale</text>"##,
        t0 = y0 - 34.0,
        y = y0 - 26.0,
        tx = x0 + 18.0,
        ty = y0 - 18.5,
    );
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
        r##"<text x="{tx}" y="{y1}">{top}</text><text x="{tx}" y="{y2}">0</text><circle cx="{cx2}" cy="{y3}" r="7" fill="none" stroke="#999" stroke-dasharray="2,2"/><text x="{tx}" y="{y4}">not rendered</text><circle cx="{cx2}" cy="{y5}" r="9" fill="none" stroke="#d00" stroke-width="2.5"/><text x="{tx}" y="{y6}">sun glint at the eye</text></svg>"##,
        top = (plot.label)(top),
        tx = x0 + 18.0,
        y1 = y0 + 8.0,
        y2 = y0 + height,
        cx2 = x0 + 7.0,
        y3 = y0 + height + 22.0,
        y4 = y0 + height + 26.0,
        y5 = y0 + height + 44.0,
        y6 = y0 + height + 48.0,
    );
    svg
}

/// The plot position of a sun direction.
fn polar_point(cx: f32, cy: f32, rim: f32, azimuth_deg: f32, elevation_deg: f32) -> (f32, f32) {
    let r = rim * (90.0 - elevation_deg) / 90.0;
    let (sin, cos) = azimuth_deg.to_radians().sin_cos();
    (cx + r * sin, cy - r * cos)
}
