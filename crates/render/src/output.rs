//! The files a render writes: the image, by the output path's extension
//! ([`ImageFormat`]: 8-bit sRGB PNG under an [`Exposure`], linear OpenEXR in
//! cd/m², or linear `.npy` in render units), and on request the auxiliary
//! outputs that other tools check:
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
//!
//! An OpenEXR image holds the channels `R`, `G`, `B` (linear, cd/m²: the
//! render units times `vtfarm_scene::photometry::CD_M2_PER_UNIT`) and `Y`
//! (their luminance, [`vtfarm_scene::photometry::cd_m2`]); with the
//! components also `reflected.R` … `reflected.Y` and `transmitted.R` …
//! `transmitted.Y`, the same way.

use std::path::{Path, PathBuf};

use glam::Vec3;
use vtfarm_imaging::{Exposure, Image, ImageError, write_gray8_png, write_gray16_png};
use vtfarm_scene::photometry::{self, CD_M2_PER_UNIT};
use vtfarm_scene::{NONE, Scene};
use vtfarm_vertex::{Components, FinishedFace, FrameImage, draw_wireframe};

/// Errors while writing outputs. Each names the file and its cause once.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error("the reflected-object map: {0}")]
    ObjectMap(#[from] vtfarm_glare::GlareError),
    #[error("cannot write {path}: {cause}")]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("cannot write {path}: {why}; supported: {}", ImageFormat::SUPPORTED)]
    Extension { path: PathBuf, why: String },
}

/// The image formats an output path may name, by its extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// `.png`: 8-bit sRGB under the job's exposure.
    Png,
    /// `.exr`: OpenEXR, linear float32 in cd/m², RGB and luminance Y.
    Exr,
    /// `.npy`: linear float32 in render units (height × width × 3).
    Npy,
}

impl ImageFormat {
    /// The supported extensions, for messages.
    pub const SUPPORTED: &str =
        ".png (8-bit sRGB), .exr (OpenEXR, linear cd/m²), .npy (linear float32, render units)";

    /// The format `path`'s extension names; an error naming the supported
    /// ones for any other (checked before anything renders).
    pub fn of(path: &Path) -> Result<ImageFormat, OutputError> {
        let extension = path.extension().and_then(|e| e.to_str());
        match extension.map(str::to_ascii_lowercase).as_deref() {
            Some("png") => Ok(ImageFormat::Png),
            Some("exr") => Ok(ImageFormat::Exr),
            Some("npy") => Ok(ImageFormat::Npy),
            Some(other) => Err(OutputError::Extension {
                path: path.to_owned(),
                why: format!("unsupported extension .{other}"),
            }),
            None => Err(OutputError::Extension {
                path: path.to_owned(),
                why: "no extension".to_owned(),
            }),
        }
    }

    /// The extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            ImageFormat::Png => "png",
            ImageFormat::Exr => "exr",
            ImageFormat::Npy => "npy",
        }
    }
}

/// One entry of `objects.json`.
#[derive(serde::Serialize)]
struct ObjectEntry<'a> {
    /// The pixel value in `reflected_objects.png`.
    value: u32,
    name: &'a str,
}

/// Writes an image in the format its extension names ([`ImageFormat`]),
/// creating a missing directory: PNG under `exposure`, OpenEXR with the
/// `components` as layers when given.
pub fn write_image(
    path: &Path,
    image: &Image,
    exposure: &Exposure,
    components: Option<&Components>,
) -> Result<(), OutputError> {
    let format = ImageFormat::of(path)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|cause| OutputError::Io {
            path: dir.to_owned(),
            cause,
        })?;
    }
    match format {
        ImageFormat::Png => image.write_png_exposed(path, exposure)?,
        ImageFormat::Npy => image.write_npy(path)?,
        ImageFormat::Exr => write_exr(path, image, components)?,
    }
    Ok(())
}

/// The channels of an image in cd/m²: R, G, B and Y, named `prefix`R … .
fn cd_m2_channels(prefix: &str, image: &Image) -> [(String, Vec<f32>); 4] {
    let channel = |k: usize| -> Vec<f32> {
        (image.pixels.iter())
            .map(|c| c[k] * CD_M2_PER_UNIT)
            .collect()
    };
    let y = image.pixels.iter().map(|&c| photometry::cd_m2(c)).collect();
    [
        (format!("{prefix}R"), channel(0)),
        (format!("{prefix}G"), channel(1)),
        (format!("{prefix}B"), channel(2)),
        (format!("{prefix}Y"), y),
    ]
}

/// Writes `image` as OpenEXR in cd/m² (see the module docs), with the
/// reflected and transmitted components as layers when given.
pub fn write_exr(
    path: &Path,
    image: &Image,
    components: Option<&Components>,
) -> Result<(), ImageError> {
    let mut channels: Vec<(String, Vec<f32>)> = cd_m2_channels("", image).into();
    if let Some(c) = components {
        channels.extend(cd_m2_channels("reflected.", &c.reflected));
        channels.extend(cd_m2_channels("transmitted.", &c.transmitted));
    }
    let named: Vec<(&str, &[f32])> = (channels.iter())
        .map(|(name, values)| (name.as_str(), values.as_slice()))
        .collect();
    vtfarm_imaging::write_exr_f32(path, image.width, image.height, &named)
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
        move |cause| OutputError::Io { path, cause }
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
