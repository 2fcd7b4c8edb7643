//! Times loading one OBJ face with many vertices (a disc as a single
//! polygon), to show that import time grows about linearly with the face size.
//!
//! `cargo run --release -p vtfarm-scene --example polygon_load [sizes...]`

use std::time::Instant;

use vtfarm_scene::obj::{ObjOptions, load_obj};
use vtfarm_scene::shapes::disc_polygon_obj;

fn main() {
    let sizes: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("sizes are integers"))
        .collect();
    let sizes = if sizes.is_empty() {
        vec![1_000, 10_000, 40_000]
    } else {
        sizes
    };
    let dir = tempfile::tempdir().expect("a temporary directory");
    for n in sizes {
        let path = dir.path().join(format!("disc{n}.obj"));
        std::fs::write(&path, disc_polygon_obj(n)).expect("the OBJ file is written");
        let start = Instant::now();
        let result = load_obj(&path, &ObjOptions::default());
        let seconds = start.elapsed().as_secs_f64();
        match result {
            Ok(scene) => println!(
                "{n:>7} vertices: {seconds:8.3} s, {} triangles",
                scene.triangles.len()
            ),
            Err(e) => println!("{n:>7} vertices: {seconds:8.3} s, refused: {e}"),
        }
    }
}
