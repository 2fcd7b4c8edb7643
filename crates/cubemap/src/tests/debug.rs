use super::cockpit::*;
use crate::CubeMapMethod;
use vtfarm_method::ReflectionMethod;

#[test]
fn debug_regions() {
    let setup = small_cockpit();
    let frame = setup.frame();
    for method in [CubeMapMethod::full(), CubeMapMethod::grid()] {
        let prepared = method.prepare(&frame);
        let kinds = &prepared.maps.kind;
        println!(
            "centre {} centroid {} surface {} ext {} empty {}",
            prepared.maps.layout.centre,
            prepared.maps.centroid,
            kinds
                .iter()
                .filter(|k| **k == crate::TexelKind::Surface)
                .count(),
            kinds
                .iter()
                .filter(|k| **k == crate::TexelKind::Extension)
                .count(),
            kinds
                .iter()
                .filter(|k| **k == crate::TexelKind::Empty)
                .count()
        );
        let (_, v, _) = method.virtual_vertices(&frame, &prepared);
        let mut counts = std::collections::BTreeMap::new();
        let mut iters = 0u64;
        let mut n = 0u64;
        for x in v.iter() {
            *counts
                .entry(format!("{:?}/{}", x.region, x.in_front))
                .or_insert(0) += 1;
            iters += x.iterations as u64;
            n += 1;
        }
        println!(
            "{} {:?} mean iterations {}",
            method.name(),
            counts,
            iters as f64 / n as f64
        );
    }
    let scene = setup.bvh.scene();
    let glass = &setup.reflector;
    println!("glass triangles {}", glass.len());
    for &t in glass.iter().take(4) {
        println!(
            "{:?} {:?} {:?}",
            scene.triangles[t as usize].vertices,
            scene.triangle_positions(t),
            scene.triangle_normals(t)
        );
    }
}

#[test]
fn debug_traced() {
    let setup = small_cockpit();
    let frame = setup.frame();
    let method = CubeMapMethod::full();
    let prepared = method.prepare(&frame);
    let pixels = frame.pixels();
    let mut ok = 0;
    let mut n = 0;
    for p in pixels.iter().step_by(97) {
        let terms = frame.tracer.surface_terms(&p.point, p.incoming);
        let Some(ray) = terms.reflection else {
            continue;
        };
        let Some(hit) = setup.bvh.closest_hit(&ray, f32::INFINITY) else {
            continue;
        };
        let x = setup.bvh.surface_point(&hit).position;
        n += 1;
        let s = crate::search(
            &prepared.maps,
            frame.camera.eye,
            x,
            &crate::SearchSettings::default(),
        );
        let err = (s.reflection_point - p.point.position).length();
        if err < 2e-3 && s.region == crate::Region::Reflected {
            ok += 1;
            continue;
        }
        if n - ok < 6 {
            println!(
                "pixel R {} V {}: found {} err {err:.4} E {:.2e} {:?} it {}",
                p.point.position, x, s.reflection_point, s.error, s.region, s.iterations
            );
            for cap in [0, 1, 2, 3, 5, 10, 20] {
                let s = crate::search(
                    &prepared.maps,
                    frame.camera.eye,
                    x,
                    &crate::SearchSettings {
                        epsilon: 1e-7,
                        max_iterations: cap,
                    },
                );
                println!("   cap {cap}: {} E {:.3e}", s.reflection_point, s.error);
            }
        }
    }
    println!("{ok} of {n} traced reflections found");
}

#[test]
fn debug_sphere_case() {
    let (scene, sphere) = super::scenes::sphere_scene(0.5);
    let maps = crate::ReflectorMaps::build(&scene, &sphere, 256, 1);
    let s = crate::search(
        &maps,
        glam::Vec3::new(0.3, 0.4, 2.0),
        glam::Vec3::new(0.80520606, -0.14700004, 0.65767324),
        &crate::SearchSettings::default(),
    );
    println!("{s:?}");
}
