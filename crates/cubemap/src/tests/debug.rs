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
        let (v, _) = method.virtual_vertices(&frame, &prepared);
        let mut counts = std::collections::BTreeMap::new();
        let mut iters = 0u64;
        let mut n = 0u64;
        for x in v.iter().flatten() {
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
fn debug_trajectory() {
    let setup = small_cockpit();
    let frame = setup.frame();
    let method = CubeMapMethod::full();
    let prepared = method.prepare(&frame);
    let (v, _) = method.virtual_vertices(&frame, &prepared);
    let scene = setup.bvh.scene();
    let failed: Vec<usize> = v
        .iter()
        .enumerate()
        .filter(|(_, x)| x.is_some_and(|x| x.region == crate::Region::Failed))
        .map(|(i, _)| i)
        .step_by(1000)
        .collect();
    for &i in failed.iter().take(5) {
        let p = scene.positions[i];
        println!("vertex {i} at {p}");
        for cap in [0, 1, 2, 3, 5, 8, 12, 20, 40] {
            let s = crate::search(
                &prepared.maps,
                frame.camera.eye,
                p,
                &crate::SearchSettings {
                    epsilon: 1e-7,
                    max_iterations: cap,
                },
            );
            println!(
                "  cap {cap}: R {} err {:.3e} front {} region {:?} it {}",
                s.reflection_point, s.error, s.in_front, s.region, s.iterations
            );
        }
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
fn debug_relevant() {
    let setup = small_cockpit();
    let frame = setup.frame();
    let method = CubeMapMethod::full();
    let prepared = method.prepare(&frame);
    let (v, _) = method.virtual_vertices(&frame, &prepared);
    let scene = setup.bvh.scene();
    let pixels = frame.pixels();
    let mut counts = std::collections::BTreeMap::new();
    let mut shown = 0;
    for p in pixels.iter() {
        let terms = frame.tracer.surface_terms(&p.point, p.incoming);
        let Some(ray) = terms.reflection else {
            continue;
        };
        let Some(hit) = setup.bvh.closest_hit(&ray, f32::INFINITY) else {
            continue;
        };
        let t = &scene.triangles[hit.triangle as usize];
        let regions: Vec<String> = t
            .vertices
            .iter()
            .map(|&i| v[i as usize].map_or("none".to_owned(), |x| format!("{:?}", x.region)))
            .collect();
        let key = format!("{} {:?}", scene.objects[t.object as usize].name, regions);
        *counts.entry(key.clone()).or_insert(0) += 1;
        if shown < 4 && regions.iter().any(|r| r == "Failed") {
            shown += 1;
            let x = setup.bvh.surface_point(&hit).position;
            println!(
                "pixel R {} V {} tri {:?}",
                p.point.position,
                x,
                t.vertices.map(|i| scene.positions[i as usize])
            );
            for &i in &t.vertices {
                let s = v[i as usize].unwrap();
                println!(
                    "    {:?} R {} E {:.2e} it {}",
                    s.region, s.reflection_point, s.error, s.iterations
                );
            }
        }
    }
    let mut sorted: Vec<_> = counts.into_iter().collect();
    sorted.sort_by_key(|(_, n)| std::cmp::Reverse(*n));
    for (k, n) in sorted.iter().take(25) {
        println!("{n:6} {k}");
    }
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
