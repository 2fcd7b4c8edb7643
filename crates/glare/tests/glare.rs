//! Analytic checks of the glare metrics and images.

use glam::Vec3;
use vtfarm_glare::*;
use vtfarm_imaging::Image;
use vtfarm_scene::NONE;

/// Owned buffers behind a [`GlareInput`].
struct Frame {
    w: u32,
    h: u32,
    glass: Vec<bool>,
    reflected: Vec<Vec3>,
    transmitted: Vec<Vec3>,
    objects: Vec<u32>,
    instrument: Vec<bool>,
    marking: Vec<bool>,
    names: Vec<String>,
}

impl Frame {
    fn new(w: u32, h: u32) -> Self {
        let n = (w * h) as usize;
        Frame {
            w,
            h,
            glass: vec![false; n],
            reflected: vec![Vec3::ZERO; n],
            transmitted: vec![Vec3::ZERO; n],
            objects: vec![NONE; n],
            instrument: vec![false; n],
            marking: vec![false; n],
            names: Vec::new(),
        }
    }

    fn input(&self) -> GlareInput<'_> {
        GlareInput {
            width: self.w,
            height: self.h,
            glass: &self.glass,
            reflected: &self.reflected,
            transmitted: &self.transmitted,
            reflected_object: &self.objects,
            instrument: &self.instrument,
            marking: &self.marking,
            object_names: &self.names,
        }
    }
}

/// Parameters that read rendered values as cd/m² (scale 1), so the
/// hand-made cases below state luminances directly.
fn relative() -> Params {
    Params {
        cd_m2_per_unit: 1.0,
        luminance_floor_cd_m2: 1e-4,
        thresholds: Thresholds {
            veiling_luminance_cd_m2: 0.05,
            ..Thresholds::default()
        },
        ambient: AmbientCondition {
            glass_diffuse_reflectance: 0.0,
            ..AmbientCondition::default()
        },
    }
}

fn gray(v: f32) -> Vec3 {
    Vec3::splat(v)
}

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= 1e-6 * b.abs().max(1.0)
}

/// A dial: the whole frame is glass and instrument; the left column is
/// marking (transmitted `lm`), the rest background (`lb`); uniform reflection
/// `lr`.
fn dial(lm: f32, lb: f32, lr: f32) -> Frame {
    let mut f = Frame::new(4, 4);
    for i in 0..16 {
        f.glass[i] = true;
        f.instrument[i] = true;
        f.marking[i] = i % 4 == 0;
        f.transmitted[i] = gray(if f.marking[i] { lm } else { lb });
        f.reflected[i] = gray(lr);
    }
    f
}

#[test]
fn luminance_uses_rec709_weights() {
    assert_eq!(luminance(Vec3::new(1.0, 0.0, 0.0)), 0.2126);
    assert_eq!(luminance(Vec3::new(0.0, 1.0, 0.0)), 0.7152);
    assert_eq!(luminance(Vec3::new(0.0, 0.0, 1.0)), 0.0722);
    assert!(close(luminance(Vec3::ONE), 1.0));
}

#[test]
fn uniform_reflected_field_gives_peak_equal_mean() {
    let mut f = Frame::new(8, 6);
    for i in 0..48 {
        // Glass on the upper half only; the lower half reflects too but is
        // not glass and must not count.
        f.glass[i] = i < 24;
        f.reflected[i] = gray(if i < 24 { 0.4 } else { 9.0 });
    }
    let mut params = relative();
    let s = summarize(&f.input(), &params).unwrap();
    assert_eq!(s.glass_pixels, 24);
    assert!(close(s.peak_reflected_luminance_cd_m2, 0.4));
    assert!(close(s.mean_reflected_luminance_cd_m2, 0.4));

    params.thresholds.veiling_luminance_cd_m2 = 0.0;
    let s = summarize(&f.input(), &params).unwrap();
    assert_eq!(s.glare_pixels, 24);
    assert_eq!(s.glare_area_share, 1.0);

    params.thresholds.veiling_luminance_cd_m2 = 0.5;
    let s = summarize(&f.input(), &params).unwrap();
    assert_eq!(s.glare_pixels, 0);
    assert_eq!(s.glare_area_share, 0.0);

    // The scale turns rendered radiance into cd/m².
    params.cd_m2_per_unit = 250.0;
    let s = summarize(&f.input(), &params).unwrap();
    assert!((s.peak_reflected_luminance_cd_m2 - 100.0).abs() < 1e-3);
    assert!((s.mean_reflected_luminance_cd_m2 - 100.0).abs() < 1e-3);
    assert_eq!(s.glare_area_share, 1.0);
}

#[test]
fn veiling_ratio_on_a_hand_made_4x4_case() {
    // Glass: the centre 2x2 plus the top-left corner.
    //   (0,0): L_r 0.2, L_t 0.4 -> 0.5
    //   (1,1): L_r 0.3, L_t 0.1 -> 3
    //   (2,1): L_r 0,   L_t 0.5 -> 0
    //   (1,2): L_r 0.5, L_t 0.5 -> 1
    //   (2,2): L_r 0.1, L_t 0   -> 0.1 / floor
    // Everything else is not glass (its colours must be ignored) -> 0.
    let mut f = Frame::new(4, 4);
    f.reflected = vec![gray(7.0); 16];
    f.transmitted = vec![gray(3.0); 16];
    let cases = [
        (0, 0, 0.2, 0.4),
        (1, 1, 0.3, 0.1),
        (2, 1, 0.0, 0.5),
        (1, 2, 0.5, 0.5),
        (2, 2, 0.1, 0.0),
    ];
    for (x, y, r, t) in cases {
        let i = y * 4 + x;
        f.glass[i] = true;
        f.reflected[i] = gray(r);
        f.transmitted[i] = gray(t);
    }
    let params = relative();
    let v = veiling_ratio(&f.input(), &params).unwrap();
    let mut expected = [0.0f32; 16];
    expected[0] = 0.5;
    expected[5] = 3.0;
    expected[6] = 0.0;
    expected[9] = 1.0;
    expected[10] = 0.1 / params.luminance_floor_cd_m2;
    for i in 0..16 {
        assert!(
            (v[i] - expected[i]).abs() <= 1e-5 * expected[i].max(1.0),
            "pixel {i}: {} vs {}",
            v[i],
            expected[i]
        );
    }
    let lr = reflected_luminance(&f.input(), &params).unwrap();
    let lt = transmitted_luminance(&f.input(), &params).unwrap();
    assert!(close(lr[5], 0.3) && close(lt[5], 0.1));
    assert_eq!(lr[15], 0.0);
    assert_eq!(lt[15], 0.0);
    let s = summarize(&f.input(), &params).unwrap();
    assert!(close(s.peak_veiling_ratio, expected[10]));
    let mean: f32 = expected.iter().sum::<f32>() / 5.0;
    assert!((s.mean_veiling_ratio - mean).abs() <= 1e-5 * mean);
}

#[test]
fn contrast_without_reflection_is_marking_over_background() {
    let f = dial(0.8, 0.1, 0.0);
    let c = contrast(&f.input(), &relative()).unwrap();
    assert_eq!(c.instrument_pixels, 16);
    assert_eq!(c.marking_pixels, 4);
    assert_eq!(c.evaluated_pixels, 16);
    let (lm, lb) = (
        c.mean_marking_luminance_cd_m2,
        c.mean_background_luminance_cd_m2,
    );
    assert!(close(lm, 0.8) && close(lb, 0.1));
    for cr in &c.per_pixel {
        // Exactly L_m / L_b of the computed luminances.
        assert_eq!(cr.unwrap(), lm / lb);
        assert!((cr.unwrap() - 8.0).abs() < 1e-4);
    }
    assert_eq!(c.low_contrast_pixels, 0);
    assert_eq!(c.min_contrast, Some(lm / lb));
    assert_eq!(contrast_ratio(0.8, 0.1, 0.0, 1e-4), 0.8 / 0.1);
    // Dark markings on a light dial: brighter over darker.
    assert_eq!(contrast_ratio(0.1, 0.8, 0.0, 1e-4), 0.8 / 0.1);
}

#[test]
fn contrast_falls_towards_one_as_reflection_grows() {
    let mut previous = f32::INFINITY;
    for k in 0..60 {
        let lr = 1e-3 * 1.3f32.powi(k);
        let cr = contrast_ratio(0.8, 0.1, lr, 1e-4);
        assert!(cr < previous, "not falling at L_r = {lr}");
        assert!(cr > 1.0);
        previous = cr;
    }
    assert!(contrast_ratio(0.8, 0.1, 1e6, 1e-4) < 1.0001);

    // Through the whole pipeline: the low-contrast share goes from 0 to 1.
    let mut shares = Vec::new();
    for lr in [0.0, 0.1, 0.2, 0.3, 0.5, 1.0] {
        let f = dial(0.8, 0.1, lr);
        let s = summarize(&f.input(), &relative()).unwrap();
        let expected = (0.8 + lr) / (0.1 + lr);
        assert!((s.min_contrast.unwrap() - expected).abs() < 1e-4 * expected);
        shares.push(s.low_contrast_share);
    }
    // CR = 8, 4.5, 3.33, 2.75, 2.17, 1.64 against 3:1.
    assert_eq!(shares, vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
}

#[test]
fn low_contrast_share_covers_the_instrument_area_where_the_glare_is() {
    // Reflection only on the right half of the dial: the background pixels
    // there (with a typical marking) and no marking pixel fall under 3:1.
    let mut f = dial(0.8, 0.1, 0.0);
    for y in 0..4 {
        for x in 2..4 {
            f.reflected[y * 4 + x] = gray(1.0);
        }
    }
    let s = summarize(&f.input(), &relative()).unwrap();
    assert_eq!(s.low_contrast_pixels, 8);
    assert_eq!(s.low_contrast_share, 0.5);
}

#[test]
fn objects_over_the_threshold_everywhere_rank_by_their_area_and_are_named() {
    let mut f = Frame::new(8, 4);
    f.names = vec!["mirror".into(), "driver shirt".into(), "sun visor".into()];
    f.glass = vec![true; 32];
    // Object 0: 3 px, object 1: 7 px, object 2: 5 px, object 7 (no name): 1 px.
    let mut next = 0;
    for (id, count) in [(0u32, 3), (1, 7), (2, 5), (7, 1)] {
        for _ in 0..count {
            f.objects[next] = id;
            f.reflected[next] = gray(0.1);
            next += 1;
        }
    }
    // Object 0 also covers non-glass pixels: they do not count.
    for i in 28..32 {
        f.glass[i] = false;
        f.objects[i] = 0;
    }
    let s = summarize(&f.input(), &relative()).unwrap();
    let ranked: Vec<(u32, &str, usize)> = s
        .objects
        .iter()
        .map(|o| (o.object, o.name.as_str(), o.glare_pixels))
        .collect();
    assert_eq!(
        ranked,
        vec![
            (1, "driver shirt", 7),
            (2, "sun visor", 5),
            (0, "mirror", 3),
            (7, "OBJECT 7", 1)
        ]
    );
    assert!(close(s.objects[0].summed_reflected_luminance_cd_m2, 0.7));
    assert!(close(s.objects[0].mean_reflected_luminance_cd_m2, 0.1));
    assert!(close(s.objects[0].coverage_share, 7.0 / 28.0));
    assert_eq!(s.objects[0].covered_pixels, 7);
    // Every pixel showing an object is glare (0.1 > 0.05), 16 in all: the
    // shares are of the glare area.
    assert!(close(s.objects[0].glare_share, 7.0 / 16.0));
    assert!(close(s.objects[0].excess_luminance_cd_m2, 7.0 * 0.05));
}

#[test]
fn equal_glare_areas_rank_by_the_luminance_above_the_threshold() {
    let mut f = Frame::new(4, 1);
    f.glass = vec![true; 4];
    f.objects = vec![3, 3, 5, 5];
    f.reflected = vec![gray(0.1), gray(0.1), gray(0.9), gray(0.2)];
    let s = summarize(&f.input(), &relative()).unwrap();
    let order: Vec<u32> = s.objects.iter().map(|o| o.object).collect();
    assert_eq!(order, vec![5, 3]);
}

#[test]
fn the_culprit_is_the_small_bright_object_over_the_threshold_not_the_large_dim_one() {
    // The stock cockpit's case in miniature, at the default scale and
    // threshold (500 cd/m²): cab walls at 35 cd/m² over 90 % of the glass,
    // a side window at 5,000 cd/m² over 6 %, nothing over the rest.
    let mut f = Frame::new(10, 10);
    f.names = vec!["cab_walls".into(), "side_window_left".into()];
    f.glass = vec![true; 100];
    let unit = |cd_m2: f32| gray(cd_m2 / CD_M2_PER_UNIT);
    for i in 0..90 {
        f.objects[i] = 0;
        f.reflected[i] = unit(35.0);
    }
    for i in 90..96 {
        f.objects[i] = 1;
        f.reflected[i] = unit(5_000.0);
    }
    let s = summarize(&f.input(), &Params::default()).unwrap();
    assert_eq!(s.glare_pixels, 6);
    let culprit = &s.objects[0];
    assert_eq!(culprit.name, "side_window_left");
    assert_eq!(culprit.glare_pixels, 6);
    assert_eq!(culprit.glare_share, 1.0);
    assert!((culprit.excess_luminance_cd_m2 - 6.0 * 4_500.0).abs() < 1.0);
    assert!(close(culprit.coverage_share, 0.06));
    // The walls cover the most glass, a separate figure, and cause no glare.
    let walls = &s.objects[1];
    assert_eq!((walls.name.as_str(), walls.glare_pixels), ("cab_walls", 0));
    assert!(close(walls.coverage_share, 0.9));
    assert_eq!(walls.glare_share, 0.0);
    assert_eq!(s.background_glare_pixels, 0);
    // Glare where the glass mirrors no object is the background's.
    f.reflected[99] = unit(2_000.0);
    let s = summarize(&f.input(), &Params::default()).unwrap();
    assert_eq!((s.glare_pixels, s.background_glare_pixels), (7, 1));
    assert!((s.background_excess_luminance_cd_m2 - 1_500.0).abs() < 0.1);
    assert!(close(s.objects[0].glare_share, 6.0 / 7.0));
    // The object map colours by the same rank: the culprit takes the
    // palette's first colour.
    let (map, ranked) = object_map_frame(&f.input(), &Params::default()).unwrap();
    assert_eq!(ranked[0].name, "side_window_left");
    let [r, g, b] = object_color_srgb(0);
    let first = Vec3::new(r.into(), g.into(), b.into())
        .map(|c: f32| vtfarm_imaging::srgb_to_linear(c / 255.0));
    assert_eq!(map.get(0, 9), first);
    assert_eq!(
        (map.width, map.height),
        (10, 10),
        "the frame alone, no legend"
    );
}

#[test]
fn the_culprit_among_glare_sources_is_the_one_causing_more_glare_area() {
    // Two objects over the threshold: a larger patch just over it beats a
    // smaller, brighter one (area first), and at equal areas the brighter
    // one wins (luminance above the threshold second).
    let mut f = Frame::new(10, 1);
    f.names = vec!["lamp".into(), "window".into()];
    f.glass = vec![true; 10];
    let unit = |cd_m2: f32| gray(cd_m2 / CD_M2_PER_UNIT);
    for i in 0..3 {
        f.objects[i] = 0;
        f.reflected[i] = unit(9_000.0);
    }
    for i in 3..8 {
        f.objects[i] = 1;
        f.reflected[i] = unit(600.0);
    }
    let s = summarize(&f.input(), &Params::default()).unwrap();
    let order: Vec<&str> = s.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(order, ["window", "lamp"]);
    assert!(close(s.objects[0].glare_share, 5.0 / 8.0));
    f.objects[3..5].fill(NONE);
    f.objects[5..8].fill(1);
    let s = summarize(&f.input(), &Params::default()).unwrap();
    let order: Vec<&str> = s.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(order, ["lamp", "window"]);
}

/// A gradient strip: row 0 is glass with L_r rising 0..1 over 16 pixels,
/// row 1 is not glass (but has reflections that must not show).
fn gradient() -> Frame {
    let mut f = Frame::new(16, 2);
    for x in 0..16 {
        f.glass[x] = true;
        f.reflected[x] = gray(x as f32 / 15.0);
        f.reflected[16 + x] = gray(1.0);
    }
    f
}

#[test]
fn heat_map_is_black_outside_the_glass_and_rises_with_luminance() {
    let f = gradient();
    let img = heat_map(&f.input(), &relative(), None).unwrap();
    assert!(img.width > f.w, "legend panel to the right");
    assert!(img.height >= f.h);
    for y in 0..img.height {
        for x in 0..f.w {
            if y >= f.h || !f.glass[(y * f.w + x) as usize] {
                assert_eq!(img.get(x, y), Vec3::ZERO, "({x}, {y})");
            }
        }
    }
    let mut previous = -1.0;
    for x in 0..16 {
        let y = luminance(img.get(x, 0));
        assert!(y > previous, "heat map not rising at x = {x}");
        previous = y;
    }
    // The top of the ramp is the peak; above a fixed scale a pixel is
    // marked beyond it, not drawn as the scale's top.
    assert_eq!(img.get(15, 0), ramp_color(1.0));
    let fixed = LogRange {
        min_cd_m2: 0.05,
        max_cd_m2: 0.5,
    };
    let fixed_img = heat_map(&f.input(), &relative(), Some(fixed)).unwrap();
    assert_eq!(fixed_img.get(15, 0), beyond_scale_color());
    assert_eq!(fixed_img.get(8, 0), beyond_scale_color());
    assert!(luminance(fixed_img.get(7, 0)) < luminance(ramp_color(1.0)));
    assert_eq!(fixed_img.get(0, 0), ramp_color(0.0));
}

/// The colour scale is logarithmic: each decade of cd/m² takes the same
/// step of the ramp, and the automatic range spans four decades below the
/// peak.
#[test]
fn heat_map_scale_is_logarithmic_in_cd_m2() {
    let mut f = Frame::new(5, 1);
    for (x, l) in [1.0f32, 10.0, 100.0, 1000.0, 10_000.0]
        .into_iter()
        .enumerate()
    {
        f.glass[x] = true;
        f.reflected[x] = gray(l / CD_M2_PER_UNIT);
    }
    let params = Params::default();
    let img = heat_map(&f.input(), &params, None).unwrap();
    for x in 0..5 {
        assert_eq!(img.get(x, 0), ramp_color(x as f32 / 4.0), "decade {x}");
    }
    let range = LogRange::below_peak(10_000.0);
    assert!((range.min_cd_m2 - 1.0).abs() < 1e-4);
    assert!((range.position(100.0) - 0.5).abs() < 1e-6);
    assert_eq!(range.position(0.0), 0.0);
    assert_eq!(range.position(f32::NAN), 0.0);
    assert_eq!(range.position(1e9), 1.0);
}

#[test]
fn ramp_rises_monotonically_in_luminance() {
    let mut previous = -1.0;
    for k in 0..=1000 {
        let y = luminance(ramp_color(k as f32 / 1000.0));
        assert!(y > previous, "ramp not rising at t = {}", k as f32 / 1000.0);
        previous = y;
    }
    assert_eq!(ramp_color(-1.0), ramp_color(0.0));
    assert_eq!(ramp_color(2.0), ramp_color(1.0));
    assert_eq!(ramp_color(f32::NAN), ramp_color(0.0));
}

fn count_font_pixels(img: &Image, x_from: u32) -> usize {
    let mut n = 0;
    for y in 0..img.height {
        for x in x_from..img.width {
            if img.get(x, y) == FONT_COLOR {
                n += 1;
            }
        }
    }
    n
}

#[test]
fn legends_contain_text() {
    let f = gradient();
    let img = heat_map(&f.input(), &relative(), None).unwrap();
    assert!(count_font_pixels(&img, f.w) > 50);
    // Text only in the legend: the frame area has none.
    assert_eq!(count_font_pixels(&img, 0), count_font_pixels(&img, f.w));

    let mut o = gradient();
    o.names = vec!["mirror".into()];
    o.objects[..8].fill(0);
    let map = object_map(&o.input(), &relative()).unwrap();
    assert!(count_font_pixels(&map, o.w) > 50);
    assert_eq!(count_font_pixels(&map, 0), count_font_pixels(&map, o.w));
}

#[test]
fn object_map_colours_objects_distinctly() {
    let mut f = Frame::new(6, 2);
    f.names = vec!["a".into(), "b".into(), "c".into()];
    f.glass = vec![
        true, true, true, true, true, false, true, true, true, true, true, true,
    ];
    f.objects = vec![0, 0, 0, 1, 1, 1, 2, NONE, NONE, NONE, NONE, NONE];
    let img = object_map(&f.input(), &relative()).unwrap();
    let (c0, c1, c2) = (img.get(0, 0), img.get(3, 0), img.get(0, 1));
    assert_eq!(img.get(1, 0), c0);
    assert_eq!(img.get(4, 0), c1);
    assert!(c0 != c1 && c1 != c2 && c0 != c2);
    for c in [c0, c1, c2] {
        assert!(c != NO_OBJECT_COLOR && c != Vec3::ZERO && c != FONT_COLOR);
    }
    assert_eq!(img.get(5, 0), Vec3::ZERO, "not glass");
    assert_eq!(img.get(1, 1), NO_OBJECT_COLOR, "glass showing nothing");
    // The legend has a swatch of each object's colour.
    for c in [c0, c1, c2] {
        let n = (0..img.height)
            .flat_map(|y| (f.w..img.width).map(move |x| (x, y)))
            .filter(|&(x, y)| img.get(x, y) == c)
            .count();
        assert_eq!(n, 100, "a 10x10 swatch");
    }
}

#[test]
fn many_objects_fit_the_legend() {
    let mut f = Frame::new(30, 1);
    f.glass = vec![true; 30];
    f.objects = (0..30).collect();
    let img = object_map(&f.input(), &relative()).unwrap();
    assert!(img.height > 20 * 10);
}

fn assert_finite(s: &Summary) {
    let v = serde_json::to_value(s).unwrap();
    fn walk(v: &serde_json::Value) {
        match v {
            serde_json::Value::Number(n) => assert!(n.as_f64().unwrap().is_finite()),
            serde_json::Value::Array(a) => a.iter().for_each(walk),
            serde_json::Value::Object(o) => o.values().for_each(walk),
            _ => {}
        }
    }
    walk(&v);
    let floats = [
        s.peak_reflected_luminance_cd_m2,
        s.mean_reflected_luminance_cd_m2,
        s.mean_transmitted_luminance_cd_m2,
        s.peak_veiling_ratio,
        s.mean_veiling_ratio,
        s.glare_area_share,
        s.mean_marking_luminance_cd_m2,
        s.mean_background_luminance_cd_m2,
        s.low_contrast_share,
    ];
    assert!(floats.iter().all(|x| x.is_finite()), "{s:?}");
    assert!(s.min_contrast.is_none_or(f32::is_finite));
}

#[test]
fn empty_mask_gives_zeros() {
    let mut f = Frame::new(5, 3);
    f.reflected = vec![gray(1.0); 15];
    let a = analyze(&f.input(), &relative()).unwrap();
    let s = &a.summary;
    assert_finite(s);
    assert_eq!(s.glass_pixels, 0);
    assert_eq!(s.peak_reflected_luminance_cd_m2, 0.0);
    assert_eq!(s.mean_reflected_luminance_cd_m2, 0.0);
    assert_eq!(s.glare_area_share, 0.0);
    assert_eq!(s.low_contrast_share, 0.0);
    assert_eq!(s.min_contrast, None);
    assert!(s.objects.is_empty());
    assert!(a.reflected_luminance.iter().all(|&x| x == 0.0));
    let img = heat_map(&f.input(), &relative(), None).unwrap();
    assert!((0..3).all(|y| (0..5).all(|x| img.get(x, y) == Vec3::ZERO)));
    object_map(&f.input(), &relative()).unwrap();
}

#[test]
fn zero_sized_frame_works() {
    let f = Frame::new(0, 0);
    assert_finite(&summarize(&f.input(), &relative()).unwrap());
    let img = heat_map(&f.input(), &relative(), None).unwrap();
    assert!(count_font_pixels(&img, 0) > 0);
    object_map(&f.input(), &relative()).unwrap();
}

#[test]
fn all_none_object_map_ranks_nothing() {
    let mut f = gradient();
    f.objects = vec![NONE; 32];
    let s = summarize(&f.input(), &relative()).unwrap();
    assert!(s.objects.is_empty());
    assert_finite(&s);
    let img = object_map(&f.input(), &relative()).unwrap();
    assert_eq!(img.get(0, 0), NO_OBJECT_COLOR);
}

#[test]
fn zero_transmitted_luminance_stays_finite() {
    // Black dial, black markings, with and without reflection.
    for lr in [0.0, 0.5] {
        let f = dial(0.0, 0.0, lr);
        let a = analyze(&f.input(), &relative()).unwrap();
        assert_finite(&a.summary);
        assert!(a.veiling_ratio.iter().all(|v| v.is_finite()));
        for cr in a.contrast.per_pixel.iter().flatten() {
            assert_eq!(*cr, 1.0, "no contrast between two blacks");
        }
    }
    // Bright markings on a black background: large but finite.
    let f = dial(0.8, 0.0, 0.0);
    let c = contrast(&f.input(), &relative()).unwrap();
    assert!(
        c.per_pixel
            .iter()
            .flatten()
            .all(|cr| cr.is_finite() && *cr > 1.0)
    );
}

#[test]
fn non_finite_colours_count_as_black() {
    let mut f = dial(0.8, 0.1, 0.0);
    f.reflected[3] = Vec3::new(f32::NAN, 0.0, 0.0);
    f.reflected[4] = gray(f32::INFINITY);
    f.transmitted[5] = gray(-1.0);
    let a = analyze(&f.input(), &relative()).unwrap();
    assert_finite(&a.summary);
    assert!(a.reflected_luminance.iter().all(|x| x.is_finite()));
    heat_map(&f.input(), &relative(), None).unwrap();
}

#[test]
fn inconsistent_input_is_an_error() {
    let mut f = Frame::new(4, 4);
    f.marking.pop();
    let err = summarize(&f.input(), &relative()).unwrap_err();
    assert_eq!(
        err,
        GlareError::Length {
            name: "marking",
            got: 15,
            expected: 16
        }
    );
    assert!(heat_map(&f.input(), &relative(), None).is_err());
    let f = Frame::new(2, 2);
    let params = Params {
        luminance_floor_cd_m2: 0.0,
        ..relative()
    };
    assert!(matches!(
        summarize(&f.input(), &params),
        Err(GlareError::Param { .. })
    ));
}

#[test]
fn summary_serializes_to_json() {
    let f = dial(0.8, 0.1, 0.2);
    let s = summarize(&f.input(), &relative()).unwrap();
    let json = serde_json::to_value(&s).unwrap();
    assert_eq!(json["thresholds"]["min_contrast"], 3.0);
    assert!(
        json["thresholds"]["min_contrast_source"]
            .as_str()
            .unwrap()
            .contains("ISO 15008")
    );
    assert!(json["mean_reflected_luminance_cd_m2"].is_number());
    assert_eq!(json["glass_pixels"], 16);
    assert!(json["objects"].as_array().unwrap().is_empty());
    assert!(json["low_contrast_share"].is_number());
}

#[test]
fn input_from_a_composited_frame() {
    // Component planes over one pixel: the input still covers the frame.
    let bounds = vtfarm_vertex::PixelRect {
        x0: 1,
        y0: 0,
        x1: 2,
        y1: 1,
    };
    let frame = vtfarm_vertex::FrameImage::new(Image::new(3, 2, Vec3::ZERO), bounds);
    let components = frame.components();
    let instrument = vec![false; 6];
    let names = vec!["x".to_owned()];
    let input = GlareInput::from_components(&components, &instrument, &instrument, &names);
    assert_eq!(input.validate(), Ok(6));
    assert_eq!(input.object_name(0), "x");
}

#[test]
fn text_is_clipped_and_measured() {
    let mut img = Image::new(10, 10, Vec3::ZERO);
    draw_text(&mut img, -3, -4, "AB1", 2, FONT_COLOR);
    draw_text(&mut img, 8, 8, "XYZ", 3, FONT_COLOR);
    assert_eq!(text_width("", 2), 0);
    assert_eq!(text_width("12", 1), 7);
    assert_eq!(text_width("12", 2), 14);
    let mut one = Image::new(3, 5, Vec3::ZERO);
    draw_text(&mut one, 0, 0, "8", 1, FONT_COLOR);
    // "8" is a full box with two holes.
    assert_eq!(count_font_pixels(&one, 0), 13);
}

/// The ambient condition adds its veil `ρ_d · E / π` to both sides of the
/// contrast: bright markings (1000 cd/m² over 50) under 45,000 lx on a glass
/// of diffuse reflectance 0.01 keep `(1000 + L_a) / (50 + L_a)`.
#[test]
fn the_ambient_condition_veils_the_contrast() {
    let f = dial(1000.0, 50.0, 0.0);
    let mut params = relative();
    params.ambient = AmbientCondition {
        illuminance_lux: 45_000.0,
        glass_diffuse_reflectance: 0.01,
        source: "test".to_owned(),
    };
    let la = 0.01 * 45_000.0 / std::f32::consts::PI;
    let s = summarize(&f.input(), &params).unwrap();
    assert!((s.ambient_veiling_luminance_cd_m2 - la).abs() < 1e-3);
    let expected = (1000.0 + la) / (50.0 + la);
    assert!((s.min_contrast.unwrap() - expected).abs() < 1e-4 * expected);
    assert!(s.min_contrast.unwrap() < 20.0);
    params.ambient.glass_diffuse_reflectance = 1.5;
    assert!(matches!(
        summarize(&f.input(), &params),
        Err(GlareError::Param { .. })
    ));
}

/// A flat mirror of reflectance k_r in front of a panel of luminance L,
/// traced by the renderer and measured here: the reflected luminance on the
/// mirror is k_r · L cd/m² (and the object map names the panel).
#[test]
fn a_flat_mirror_reflecting_a_panel_returns_kr_times_its_luminance() {
    use std::sync::Arc;
    use vtfarm_scene::{Lighting, Material, Object, Scene, Triangle, photometry};
    use vtfarm_trace::{Ray, SceneBvh, TraceSettings, Tracer};

    let panel_cd_m2 = 8_000.0;
    let kr = 0.12;
    let mut scene = Scene::default();
    let mut quad = |name: &str, material: Material, corners: [Vec3; 4]| {
        let n = (corners[1] - corners[0])
            .cross(corners[2] - corners[0])
            .normalize();
        let base = scene.positions.len() as u32;
        scene.positions.extend(corners);
        scene.normals.extend([n; 4]);
        let object = scene.objects.len() as u32;
        scene.objects.push(Object {
            name: name.to_owned(),
        });
        scene.materials.push(material);
        for vertices in [[0, 1, 2], [0, 2, 3]] {
            scene.triangles.push(Triangle {
                vertices: vertices.map(|v| base + v),
                object: vtfarm_scene::ObjectId(object),
                material: vtfarm_scene::MaterialId(object),
            });
        }
    };
    // The mirror in the plane z = 0 facing +z; the panel at z = 2 facing it.
    quad(
        "mirror",
        Material {
            reflectance: Vec3::splat(kr),
            ..Material::diffuse("mirror", Vec3::ZERO)
        },
        [
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
    );
    quad(
        "panel",
        Material {
            emission: photometry::emission(Vec3::new(0.9, 1.0, 1.1), panel_cd_m2).unwrap(),
            ..Material::diffuse("panel", Vec3::ZERO)
        },
        [
            Vec3::new(-5.0, -5.0, 2.0),
            Vec3::new(-5.0, 5.0, 2.0),
            Vec3::new(5.0, 5.0, 2.0),
            Vec3::new(5.0, -5.0, 2.0),
        ],
    );
    assert_eq!(scene.validate(), Ok(()));
    // No lights and no ambient term: the panel's emission is all there is.
    let dark = Lighting {
        ambient: Vec3::ZERO,
        ..Lighting::default()
    };
    let bvh = SceneBvh::new(Arc::new(scene));
    let eye = Vec3::new(0.2, 0.1, 1.0);
    let sample = Tracer {
        bvh: &bvh,
        lighting: &dark,
        settings: TraceSettings::default(),
        cone: vtfarm_trace::PixelCone::FINEST,
    }
    .trace(&Ray {
        origin: eye,
        direction: (Vec3::new(0.0, 0.0, 0.0) - eye).normalize(),
    });

    let mut f = Frame::new(1, 1);
    f.glass[0] = true;
    f.reflected[0] = sample.reflected;
    f.transmitted[0] = sample.transmitted;
    f.objects[0] = sample.reflected_object;
    f.names = vec!["mirror".to_owned(), "panel".to_owned()];
    let s = summarize(&f.input(), &Params::default()).unwrap();
    let expected = kr * panel_cd_m2;
    assert!(
        (s.mean_reflected_luminance_cd_m2 - expected).abs() <= 1e-4 * expected,
        "{} cd/m² vs {expected}",
        s.mean_reflected_luminance_cd_m2
    );
    assert_eq!(s.objects[0].name, "panel");
}
