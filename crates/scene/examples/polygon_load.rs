//! Times loading one OBJ face with many vertices (a disc as a single
//! polygon), to show that import time grows about linearly with the face size.
//!
//! `cargo run --release -p vtfarm-scene --example polygon_load [sizes...]`

use std::time::Instant;

use vtfarm_scene::obj::{ObjOptions, load_obj};

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
        let mut obj = String::new();
        for i in 0..n {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            obj.push_str(&format!("v {} 0 {}\n", a.cos(), -a.sin()));
        }
        obj.push('f');
        for i in 1..=n {
            obj.push_str(&format!(" {i}"));
        }
        obj.push('\n');
        let path = dir.path().join(format!("disc{n}.obj"));
        std::fs::write(&path, obj).expect("the OBJ file is written");
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
