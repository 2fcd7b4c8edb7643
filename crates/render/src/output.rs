//! The files a render writes: the image as 8-bit sRGB PNG (or linear `.npy`),
//! and on request the auxiliary outputs that other tools check:
//!
//! - `mask.png`: 8-bit gray, 255 on reflector pixels, 0 elsewhere;
//! - `reflected.png` (sRGB) and `reflected.npy` (linear float32, height x width x 3):
//!   the reflected component;
//! - `transmitted.png` (sRGB) and `transmitted.npy` (linear float32): the
//!   transmitted component (what is seen through the reflectors);
//! - `reflected_objects.png`: 16-bit gray, the index of the object each reflector
//!   pixel mirrors plus one (0 = nothing), with `objects.json` naming each value;
//! - `reflected_objects_map.png`: the same map for the eye, coloured with a
//!   legend (`vtfarm_glare::object_map`, as a study's `objects.png`);
//! - `wireframe.png`: the image with the refined triangles' edges drawn (Figure 13),
//!   when the frame was rendered in this process.

use std::path::{Path, PathBuf};

use glam::Vec3;
use vtfarm_imaging::{Image, ImageError, write_gray8_png, write_gray16_png};
use vtfarm_scene::{NONE, Scene};
use vtfarm_vertex::{FinishedFace, FrameImage, draw_wireframe};

/// Errors while writing outputs.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error("the reflected-object map: {0}")]
    ObjectMap(#[from] vtfarm_glare::GlareError),
    #[error("cannot write {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// One entry of `objects.json`.
#[derive(serde::Serialize)]
struct ObjectEntry<'a> {
    /// The pixel value in `reflected_objects.png`.
    value: u32,
    name: &'a str,
}

/// Writes an image: `.npy` writes linear floats, anything else PNG.
pub fn write_image(path: &Path, image: &Image) -> Result<(), OutputError> {
    if path.extension().is_some_and(|e| e == "npy") {
        image.write_npy(path)?;
    } else {
        image.write_png(path)?;
    }
    Ok(())
}

/// Writes the auxiliary outputs into `dir` (created if missing).
/// `faces` are the refined triangles for `wireframe.png`, which is written
/// only when there are some (a frame from the farm has none).
pub fn write_aux(
    dir: &Path,
    image: &FrameImage,
    faces: &[FinishedFace],
    scene: &Scene,
) -> Result<(), OutputError> {
    let io = |path: &Path| {
        let path = path.to_owned();
        move |source| OutputError::Io { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let (w, h) = (image.color.width, image.color.height);
    let components = image.components();
    let mask: Vec<u8> = components
        .mask
        .iter()
        .map(|&m| if m { 255 } else { 0 })
        .collect();
    write_gray8_png(&dir.join("mask.png"), w, h, &mask)?;
    components.reflected.write_png(&dir.join("reflected.png"))?;
    components.reflected.write_npy(&dir.join("reflected.npy"))?;
    components
        .transmitted
        .write_png(&dir.join("transmitted.png"))?;
    components
        .transmitted
        .write_npy(&dir.join("transmitted.npy"))?;
    let objects: Vec<u16> = components
        .reflected_object
        .iter()
        .map(|&o| {
            if o == NONE {
                0
            } else {
                (o + 1).min(u16::MAX as u32) as u16
            }
        })
        .collect();
    write_gray16_png(&dir.join("reflected_objects.png"), w, h, &objects)?;
    let names: Vec<String> = scene.objects.iter().map(|o| o.name.clone()).collect();
    // Only the glass, its reflection and the object names are read: no
    // instrument or marking masks without a study.
    let none = vec![false; components.mask.len()];
    let input = vtfarm_glare::GlareInput::from_components(&components, &none, &none, &names);
    vtfarm_glare::object_map(&input, &vtfarm_glare::Params::default())?
        .write_png(&dir.join("reflected_objects_map.png"))?;
    let entries: Vec<ObjectEntry<'_>> = scene
        .objects
        .iter()
        .enumerate()
        .map(|(i, o)| ObjectEntry {
            value: i as u32 + 1,
            name: &o.name,
        })
        .collect();
    let json_path = dir.join("objects.json");
    let json = serde_json::to_string_pretty(&entries).expect("plain structs serialize");
    std::fs::write(&json_path, json).map_err(io(&json_path))?;
    if !faces.is_empty() {
        let mut wire = image.color.clone();
        draw_wireframe(&mut wire, faces, Vec3::new(1.0, 0.1, 0.1));
        wire.write_png(&dir.join("wireframe.png"))?;
    }
    Ok(())
}
