//! Prints the triangle count of every cockpit object at the default and the
//! large detail (a debug aid; renders nothing).
//!
//! `cargo run -p vtfarm-cockpit --example object_counts [detail...]`

use vtfarm_cockpit::{CockpitConfig, cockpit};

fn main() {
    let details: Vec<f32> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let details = if details.is_empty() {
        vec![CockpitConfig::DEFAULT_DETAIL, CockpitConfig::LARGE_DETAIL]
    } else {
        details
    };
    for detail in details {
        let scene = cockpit(&CockpitConfig {
            detail,
            ..CockpitConfig::default()
        })
        .scene;
        println!(
            "detail {detail}: {} triangles, {} vertices",
            scene.triangles.len(),
            scene.positions.len()
        );
        let mut counts = vec![0usize; scene.objects.len()];
        for t in &scene.triangles {
            counts[t.object.index()] += 1;
        }
        for (object, count) in scene.objects.iter().zip(counts) {
            println!("  {:<20} {count:>7}", object.name);
        }
    }
}
