//! The methods on the cockpit's cover glass against the ray-traced
//! reference: both cube-map variants must be closer than the environment
//! map on the reflected component.

use std::time::Instant;

use glam::Vec3;
use vtfarm_method::{MethodFrame, MethodOutput, OwnedFrame, ReflectionMethod, VertexTracing};
use vtfarm_vertex::SparseBitmap;

use crate::{CubeMapMethod, EnvironmentMap, ReflectorShape, Region, SearchSettings, search};

fn small_cockpit() -> OwnedFrame {
    OwnedFrame::cockpit(0.3, 320, 180)
}

/// Mean absolute error per channel over the reflector's pixels.
fn mean_absolute_error(a: &[Vec3], b: &[Vec3]) -> f32 {
    assert_eq!(a.len(), b.len());
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| f64::from((*x - *y).abs().element_sum()) / 3.0)
        .sum();
    (sum / a.len() as f64) as f32
}

struct Errors {
    reflected: f32,
    color: f32,
}

fn errors(output: &SparseBitmap, reference: &SparseBitmap) -> Errors {
    assert_eq!(output.mask, reference.mask);
    Errors {
        reflected: mean_absolute_error(&output.reflected, &reference.reflected),
        color: mean_absolute_error(&output.color, &reference.color),
    }
}

fn timed(method: &dyn ReflectionMethod, frame: &MethodFrame<'_>) -> MethodOutput {
    let start = Instant::now();
    let out = method.render(frame);
    println!(
        "{:>13}: {:>7.1} ms (setup {:.1} ms), {} searches, {} rays",
        method.name(),
        start.elapsed().as_secs_f64() * 1e3,
        out.counters.setup_time.as_secs_f64() * 1e3,
        out.counters.searches,
        out.counters.rays
    );
    out
}

#[test]
fn cube_maps_are_closer_to_the_reference_than_the_environment_map() {
    let setup = small_cockpit();
    let frame = setup.frame();
    let reference = VertexTracing::reference();
    let reference = timed(&reference, &frame).bitmap;
    let envmap = errors(
        &timed(&EnvironmentMap::default(), &frame).bitmap,
        &reference,
    );
    println!(
        "envmap: reflected MAE {:.5}, colour MAE {:.5}",
        envmap.reflected, envmap.color
    );
    for method in [CubeMapMethod::full(), CubeMapMethod::grid()] {
        let out = timed(&method, &frame);
        assert!(out.counters.searches > 0);
        assert_eq!(
            out.counters.pixels,
            reference.mask.iter().filter(|m| **m).count() as u64
        );
        let e = errors(&out.bitmap, &reference);
        println!(
            "{}: reflected MAE {:.5}, colour MAE {:.5}",
            method.name(),
            e.reflected,
            e.color
        );
        assert!(
            e.reflected < envmap.reflected,
            "{}: {} vs envmap {}",
            method.name(),
            e.reflected,
            envmap.reflected
        );
        assert!(
            e.color <= envmap.color,
            "{}: {} vs envmap {}",
            method.name(),
            e.color,
            envmap.color
        );
    }
}

#[test]
fn the_cover_glass_is_concave() {
    let setup = small_cockpit();
    let prepared = CubeMapMethod::full().prepare(&setup.frame());
    assert_eq!(prepared.maps.shape, ReflectorShape::Concave);
}

#[test]
fn the_search_finds_the_ray_traced_reflection_points_on_the_glass() {
    let setup = small_cockpit();
    let frame = setup.frame();
    let prepared = CubeMapMethod::full().prepare(&frame);
    let mut worst = 0.0f32;
    let mut checked = 0;
    for pixel in frame.pixels().iter().step_by(37) {
        let terms = frame.tracer.surface_terms(&pixel.point, pixel.incoming);
        let Some(ray) = terms.reflection else {
            continue;
        };
        let Some(hit) = setup.bvh.closest_hit(&ray, f32::INFINITY) else {
            continue;
        };
        let seen = setup.bvh.surface_point(&hit).position;
        let found = search(
            &prepared.maps,
            frame.camera.eye,
            seen,
            &SearchSettings::default(),
        );
        assert_eq!(found.region, Region::Reflected, "{seen}: {found:?}");
        worst = worst.max((found.reflection_point - pixel.point.position).length());
        checked += 1;
    }
    assert!(checked > 100, "{checked} pixels checked");
    println!(
        "worst reflection-point error on the glass {:.2} mm over {checked} pixels",
        worst * 1e3
    );
    assert!(worst < 2e-3, "reflection points up to {worst} m off");
}

#[test]
fn the_output_does_not_depend_on_the_thread_count() {
    let setup = small_cockpit();
    let frame = setup.frame();
    let render = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool");
        pool.install(|| CubeMapMethod::grid().render(&frame).bitmap)
    };
    let (one, three) = (render(1), render(3));
    assert_eq!(one.mask, three.mask);
    assert_eq!(one.reflected_object, three.reflected_object);
    let bits = |v: &[Vec3]| {
        v.iter()
            .flat_map(|c| c.to_array().map(f32::to_bits))
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&one.color), bits(&three.color));
}

#[test]
fn the_cube_map_methods_honour_the_packages_stop() {
    let setup = OwnedFrame::cockpit(0.3, 160, 90);
    let methods: [&dyn ReflectionMethod; 3] = [
        &CubeMapMethod::full(),
        &CubeMapMethod::grid(),
        &EnvironmentMap::default(),
    ];
    for method in methods {
        vtfarm_method::check_honours_stop(method, &setup.frame());
    }
}
