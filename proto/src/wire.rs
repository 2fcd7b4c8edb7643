//! Wire mirrors of the domain types and the conversions between them.
//!
//! `From<&Domain> for Wire*` is infallible. `TryFrom<Wire*> for Domain`
//! validates what a peer could get wrong and returns a [`WireError`] naming
//! the field: non-finite floats, indices out of range, sizes that disagree,
//! values outside the ranges the renderer relies on. It never panics, so the
//! receiving side can convert hostile data without further checks.
//!
//! Vectors travel as `[f32; 3]` (glam's types do not derive serde here).

use std::cell::RefCell;
use std::time::Duration;

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use vtfarm_method::{FrameSetup, MethodKind};
use vtfarm_scene::{
    Camera, Light, LightKind, Lighting, MAX_IMAGE_SIDE, Material, Object, OutOfBounds, Scene,
    Texture, Triangle,
};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{
    Components, FrameImage, PackageStats, Quality, SparseBitmap, Transmission, VertexSettings,
};

/// Why wire data does not make a valid domain value.
#[derive(Debug, thiserror::Error)]
pub enum WireError {
    /// A float that must be finite is NaN or infinite.
    #[error("{field} is not finite")]
    NotFinite { field: String },
    /// A domain value outside the bound its type's `validate` documents;
    /// `what` names the value (`camera`, `vertex`).
    #[error("{what} {source}")]
    Bounds {
        what: &'static str,
        source: OutOfBounds,
    },
    /// A value outside its allowed range.
    #[error("{field} = {value}: must be {rule}")]
    OutOfRange {
        field: String,
        value: String,
        rule: &'static str,
    },
    /// An index that names nothing.
    #[error("{field} = {index} is out of range (there are {len})")]
    IndexOutOfRange { field: String, index: u64, len: u64 },
    /// Two sizes that must agree do not.
    #[error("{field} has {actual} entries, expected {expected}")]
    SizeMismatch {
        field: String,
        expected: u64,
        actual: u64,
    },
    /// The same index appears twice where each must be unique.
    #[error("{field} lists {index} twice")]
    Duplicate { field: String, index: u64 },
    /// The scene breaks one of [`Scene::validate`]'s invariants.
    #[error("invalid scene: {0}")]
    InvalidScene(String),
    /// Scene bytes whose SHA-256 is not the announced hash.
    #[error("scene data hash mismatch: announced {announced}, content hashes to {actual}")]
    HashMismatch { announced: String, actual: String },
    /// Nested bincode (scene bytes) that does not decode.
    #[error("cannot decode {what}: {message}")]
    Decode { what: &'static str, message: String },
}

fn vec3(v: Vec3) -> [f32; 3] {
    v.to_array()
}

/// A finite vector, or the error naming `field`.
fn finite3(field: impl FnOnce() -> String, v: [f32; 3]) -> Result<Vec3, WireError> {
    if v.iter().all(|c| c.is_finite()) {
        Ok(Vec3::from_array(v))
    } else {
        Err(WireError::NotFinite { field: field() })
    }
}

fn finite(field: &str, v: f32) -> Result<f32, WireError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(WireError::NotFinite {
            field: field.to_owned(),
        })
    }
}

fn index(field: impl FnOnce() -> String, index: u32, len: usize) -> Result<u32, WireError> {
    if (index as usize) < len {
        Ok(index)
    } else {
        Err(WireError::IndexOutOfRange {
            field: field(),
            index: index.into(),
            len: len as u64,
        })
    }
}

/// Checks a list of triangle ids (reflectors, a package) against a scene of
/// `triangle_count` triangles: every id in range, none twice.
pub fn check_triangle_ids(
    field: &str,
    ids: &[u32],
    triangle_count: usize,
) -> Result<(), WireError> {
    let mut seen = vec![false; triangle_count];
    for (i, &id) in ids.iter().enumerate() {
        index(|| format!("{field}[{i}]"), id, triangle_count)?;
        let slot = &mut seen[id as usize];
        if *slot {
            return Err(WireError::Duplicate {
                field: field.to_owned(),
                index: id.into(),
            });
        }
        *slot = true;
    }
    Ok(())
}

// ---------------------------------------------------------------- scene

/// [`Triangle`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct WireTriangle {
    pub vertices: [u32; 3],
    pub object: u32,
    pub material: u32,
}

/// [`Material`] on the wire.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireMaterial {
    pub name: String,
    pub ambient: [f32; 3],
    pub diffuse: [f32; 3],
    pub specular: [f32; 3],
    pub shininess: f32,
    pub emission: [f32; 3],
    pub reflectance: [f32; 3],
    pub transmittance: [f32; 3],
    pub ior: f32,
    pub diffuse_texture: Option<u32>,
    pub alpha_texture: Option<u32>,
}

impl From<&Material> for WireMaterial {
    fn from(m: &Material) -> Self {
        WireMaterial {
            name: m.name.clone(),
            ambient: vec3(m.ambient),
            diffuse: vec3(m.diffuse),
            specular: vec3(m.specular),
            shininess: m.shininess,
            emission: vec3(m.emission),
            reflectance: vec3(m.reflectance),
            transmittance: vec3(m.transmittance),
            ior: m.ior,
            diffuse_texture: m.diffuse_texture,
            alpha_texture: m.alpha_texture,
        }
    }
}

impl TryFrom<WireMaterial> for Material {
    type Error = WireError;

    fn try_from(m: WireMaterial) -> Result<Self, WireError> {
        let field = |key: &str| format!("material {:?} {key}", m.name);
        Ok(Material {
            ambient: finite3(|| field("ambient"), m.ambient)?,
            diffuse: finite3(|| field("diffuse"), m.diffuse)?,
            specular: finite3(|| field("specular"), m.specular)?,
            shininess: finite(&field("shininess"), m.shininess)?,
            emission: finite3(|| field("emission"), m.emission)?,
            reflectance: finite3(|| field("reflectance"), m.reflectance)?,
            transmittance: finite3(|| field("transmittance"), m.transmittance)?,
            ior: finite(&field("ior"), m.ior)?,
            // Checked against the scene's textures by `Scene::validate`.
            diffuse_texture: m.diffuse_texture,
            alpha_texture: m.alpha_texture,
            name: m.name,
        })
    }
}

/// [`Scene`] on the wire; its bincode encoding is the canonical form that
/// [`crate::scene_hash`] hashes.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WireScene {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub triangles: Vec<WireTriangle>,
    pub objects: Vec<String>,
    pub materials: Vec<WireMaterial>,
    /// Per triangle, its corners' texture coordinates (or none at all).
    pub corner_uvs: Vec<[[f32; 2]; 3]>,
    pub textures: Vec<WireTexture>,
}

/// [`Texture`] on the wire: its level-0 RGBA bytes (the mip levels are
/// rebuilt from them).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct WireTexture {
    pub name: String,
    pub width: u32,
    pub height: u32,
    #[serde(with = "crate::message::bytes")]
    pub rgba8: Vec<u8>,
}

impl From<&Scene> for WireScene {
    fn from(s: &Scene) -> Self {
        WireScene {
            positions: s.positions.iter().map(|&p| vec3(p)).collect(),
            normals: s.normals.iter().map(|&n| vec3(n)).collect(),
            triangles: s
                .triangles
                .iter()
                .map(|t| WireTriangle {
                    vertices: t.vertices,
                    object: t.object,
                    material: t.material,
                })
                .collect(),
            objects: s.objects.iter().map(|o| o.name.clone()).collect(),
            materials: s.materials.iter().map(WireMaterial::from).collect(),
            corner_uvs: (s.corner_uvs.iter())
                .map(|c| c.map(|uv| uv.to_array()))
                .collect(),
            textures: (s.textures.iter())
                .map(|t| WireTexture {
                    name: t.name().to_owned(),
                    width: t.width(),
                    height: t.height(),
                    rgba8: t.rgba8().to_vec(),
                })
                .collect(),
        }
    }
}

impl TryFrom<WireScene> for Scene {
    type Error = WireError;

    fn try_from(w: WireScene) -> Result<Self, WireError> {
        if w.normals.len() != w.positions.len() {
            return Err(WireError::SizeMismatch {
                field: "scene normals".to_owned(),
                expected: w.positions.len() as u64,
                actual: w.normals.len() as u64,
            });
        }
        let positions = (w.positions.iter().enumerate())
            .map(|(i, &p)| finite3(|| format!("scene position {i}"), p))
            .collect::<Result<Vec<_>, _>>()?;
        let normals = (w.normals.iter().enumerate())
            .map(|(i, &n)| finite3(|| format!("scene normal {i}"), n))
            .collect::<Result<Vec<_>, _>>()?;
        let (vertex_count, object_count, material_count) =
            (positions.len(), w.objects.len(), w.materials.len());
        let triangles = (w.triangles.iter().enumerate())
            .map(|(i, t)| {
                for (k, &v) in t.vertices.iter().enumerate() {
                    index(|| format!("triangle {i} vertex {k}"), v, vertex_count)?;
                }
                index(|| format!("triangle {i} object"), t.object, object_count)?;
                index(
                    || format!("triangle {i} material"),
                    t.material,
                    material_count,
                )?;
                Ok(Triangle {
                    vertices: t.vertices,
                    object: t.object,
                    material: t.material,
                })
            })
            .collect::<Result<Vec<_>, WireError>>()?;
        let scene = Scene {
            positions,
            normals,
            triangles,
            objects: w.objects.into_iter().map(|name| Object { name }).collect(),
            materials: (w.materials.into_iter())
                .map(Material::try_from)
                .collect::<Result<_, _>>()?,
            corner_uvs: (w.corner_uvs.iter())
                .map(|c| c.map(Vec2::from_array))
                .collect(),
            textures: (w.textures.into_iter())
                .map(|t| Texture::from_rgba8(&t.name, t.width, t.height, t.rgba8))
                .collect::<Result<_, _>>()
                .map_err(|e| WireError::InvalidScene(e.to_string()))?,
        };
        // Indices and finiteness are checked above; this adds unit normals.
        scene
            .validate()
            .map_err(|e| WireError::InvalidScene(e.to_string()))?;
        Ok(scene)
    }
}

// ---------------------------------------------------------------- camera and lighting

/// [`Camera`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireCamera {
    pub eye: [f32; 3],
    pub target: [f32; 3],
    pub up: [f32; 3],
    pub fov_y_deg: f32,
    pub width: u32,
    pub height: u32,
}

impl From<&Camera> for WireCamera {
    fn from(c: &Camera) -> Self {
        WireCamera {
            eye: vec3(c.eye),
            target: vec3(c.target),
            up: vec3(c.up),
            fov_y_deg: c.fov_y_deg,
            width: c.width,
            height: c.height,
        }
    }
}

impl TryFrom<WireCamera> for Camera {
    type Error = WireError;

    fn try_from(w: WireCamera) -> Result<Self, WireError> {
        let camera = Camera {
            eye: Vec3::from_array(w.eye),
            target: Vec3::from_array(w.target),
            up: Vec3::from_array(w.up),
            fov_y_deg: w.fov_y_deg,
            width: w.width,
            height: w.height,
        };
        camera.validate().map_err(bounds("camera"))?;
        Ok(camera)
    }
}

/// Wraps a domain bound error, naming the value it is about.
fn bounds(what: &'static str) -> impl FnOnce(OutOfBounds) -> WireError {
    move |source| WireError::Bounds { what, source }
}

fn out_of_range(field: &str, value: impl ToString, rule: &'static str) -> WireError {
    WireError::OutOfRange {
        field: field.to_owned(),
        value: value.to_string(),
        rule,
    }
}

/// [`LightKind`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum WireLightKind {
    Point { position: [f32; 3] },
    Directional { direction: [f32; 3] },
}

/// [`Light`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireLight {
    pub kind: WireLightKind,
    pub color: [f32; 3],
    pub intensity: f32,
}

impl From<&Light> for WireLight {
    fn from(l: &Light) -> Self {
        WireLight {
            kind: match l.kind {
                LightKind::Point { position } => WireLightKind::Point {
                    position: vec3(position),
                },
                LightKind::Directional { direction } => WireLightKind::Directional {
                    direction: vec3(direction),
                },
            },
            color: vec3(l.color),
            intensity: l.intensity,
        }
    }
}

impl TryFrom<WireLight> for Light {
    type Error = WireError;

    fn try_from(w: WireLight) -> Result<Self, WireError> {
        let light = Light {
            kind: match w.kind {
                WireLightKind::Point { position } => LightKind::Point {
                    position: Vec3::from_array(position),
                },
                WireLightKind::Directional { direction } => LightKind::Directional {
                    direction: Vec3::from_array(direction),
                },
            },
            color: Vec3::from_array(w.color),
            intensity: w.intensity,
        };
        light.validate().map_err(bounds("light"))?;
        Ok(light)
    }
}

/// [`Lighting`] on the wire.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireLighting {
    pub lights: Vec<WireLight>,
    pub ambient: [f32; 3],
    pub background: [f32; 3],
}

impl From<&Lighting> for WireLighting {
    fn from(l: &Lighting) -> Self {
        WireLighting {
            lights: l.lights.iter().map(WireLight::from).collect(),
            ambient: vec3(l.ambient),
            background: vec3(l.background),
        }
    }
}

impl TryFrom<WireLighting> for Lighting {
    type Error = WireError;

    fn try_from(w: WireLighting) -> Result<Self, WireError> {
        let lighting = Lighting {
            lights: (w.lights.into_iter())
                .map(Light::try_from)
                .collect::<Result<_, _>>()?,
            ambient: Vec3::from_array(w.ambient),
            background: Vec3::from_array(w.background),
        };
        lighting
            .validate()
            .map_err(|(_, e)| bounds("lighting")(e))?;
        Ok(lighting)
    }
}

// ---------------------------------------------------------------- settings

/// [`TraceSettings`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireTraceSettings {
    pub max_depth: u32,
    pub fresnel: bool,
    pub signature_min_weight: f32,
}

impl From<&TraceSettings> for WireTraceSettings {
    fn from(t: &TraceSettings) -> Self {
        WireTraceSettings {
            max_depth: t.max_depth,
            fresnel: t.fresnel,
            signature_min_weight: t.signature_min_weight,
        }
    }
}

impl TryFrom<WireTraceSettings> for TraceSettings {
    type Error = WireError;

    fn try_from(w: WireTraceSettings) -> Result<Self, WireError> {
        let trace = TraceSettings {
            max_depth: w.max_depth,
            fresnel: w.fresnel,
            signature_min_weight: w.signature_min_weight,
        };
        trace.validate().map_err(bounds("trace"))?;
        Ok(trace)
    }
}

/// [`Quality`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireQuality {
    Preview,
    Refine,
    Full,
    Reference,
}

impl From<Quality> for WireQuality {
    fn from(q: Quality) -> Self {
        match q {
            Quality::Preview => WireQuality::Preview,
            Quality::Refine => WireQuality::Refine,
            Quality::Full => WireQuality::Full,
            Quality::Reference => WireQuality::Reference,
        }
    }
}

impl From<WireQuality> for Quality {
    fn from(q: WireQuality) -> Self {
        match q {
            WireQuality::Preview => Quality::Preview,
            WireQuality::Refine => Quality::Refine,
            WireQuality::Full => Quality::Full,
            WireQuality::Reference => Quality::Reference,
        }
    }
}

/// [`Transmission`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireTransmission {
    Raster,
    Traced,
}

impl From<Transmission> for WireTransmission {
    fn from(t: Transmission) -> Self {
        match t {
            Transmission::Raster => WireTransmission::Raster,
            Transmission::Traced => WireTransmission::Traced,
        }
    }
}

impl From<WireTransmission> for Transmission {
    fn from(t: WireTransmission) -> Self {
        match t {
            WireTransmission::Raster => Transmission::Raster,
            WireTransmission::Traced => Transmission::Traced,
        }
    }
}

/// [`MethodKind`] on the wire.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireMethod {
    #[default]
    VertexTracing,
    CubeMap,
    CubeMapGrid,
    Pvrr,
    EnvironmentMap,
}

impl From<MethodKind> for WireMethod {
    fn from(m: MethodKind) -> Self {
        match m {
            MethodKind::VertexTracing => WireMethod::VertexTracing,
            MethodKind::CubeMap => WireMethod::CubeMap,
            MethodKind::CubeMapGrid => WireMethod::CubeMapGrid,
            MethodKind::Pvrr => WireMethod::Pvrr,
            MethodKind::EnvironmentMap => WireMethod::EnvironmentMap,
        }
    }
}

impl From<WireMethod> for MethodKind {
    fn from(m: WireMethod) -> Self {
        match m {
            WireMethod::VertexTracing => MethodKind::VertexTracing,
            WireMethod::CubeMap => MethodKind::CubeMap,
            WireMethod::CubeMapGrid => MethodKind::CubeMapGrid,
            WireMethod::Pvrr => MethodKind::Pvrr,
            WireMethod::EnvironmentMap => MethodKind::EnvironmentMap,
        }
    }
}

/// [`VertexSettings`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireVertexSettings {
    pub quality: WireQuality,
    pub epsilon: f32,
    pub pixel_floor: f32,
    pub flatness: f32,
    pub max_depth: u32,
    pub visibility_radius: u32,
    pub depth_tolerance: f32,
    pub max_edge: f32,
    pub transmission: WireTransmission,
}

impl From<&VertexSettings> for WireVertexSettings {
    fn from(v: &VertexSettings) -> Self {
        WireVertexSettings {
            quality: v.quality.into(),
            epsilon: v.epsilon,
            pixel_floor: v.pixel_floor,
            flatness: v.flatness,
            max_depth: v.max_depth,
            visibility_radius: v.visibility_radius,
            depth_tolerance: v.depth_tolerance,
            max_edge: v.max_edge,
            transmission: v.transmission.into(),
        }
    }
}

impl TryFrom<WireVertexSettings> for VertexSettings {
    type Error = WireError;

    fn try_from(w: WireVertexSettings) -> Result<Self, WireError> {
        let vertex = VertexSettings {
            quality: w.quality.into(),
            epsilon: w.epsilon,
            pixel_floor: w.pixel_floor,
            flatness: w.flatness,
            max_depth: w.max_depth,
            visibility_radius: w.visibility_radius,
            depth_tolerance: w.depth_tolerance,
            max_edge: w.max_edge,
            transmission: w.transmission.into(),
        };
        vertex.validate().map_err(bounds("vertex"))?;
        Ok(vertex)
    }
}

/// [`FrameSetup`] on the wire: everything that can change from one frame to
/// the next.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireFrameSetup {
    pub camera: WireCamera,
    pub lighting: WireLighting,
    pub trace: WireTraceSettings,
    pub vertex: WireVertexSettings,
}

impl From<&FrameSetup> for WireFrameSetup {
    fn from(f: &FrameSetup) -> Self {
        WireFrameSetup {
            camera: (&f.camera).into(),
            lighting: (&f.lighting).into(),
            trace: (&f.trace).into(),
            vertex: (&f.vertex).into(),
        }
    }
}

impl TryFrom<WireFrameSetup> for FrameSetup {
    type Error = WireError;

    fn try_from(w: WireFrameSetup) -> Result<Self, WireError> {
        Ok(FrameSetup {
            camera: w.camera.try_into()?,
            lighting: w.lighting.try_into()?,
            trace: w.trace.try_into()?,
            vertex: w.vertex.try_into()?,
        })
    }
}

// ---------------------------------------------------------------- results

/// Which per-pixel arrays of a [`SparseBitmap`] travel: the colour always,
/// the components (reflected, transmitted, reflected object) only when the
/// job asks for them (`FrameStart::aux`), since they triple the bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireBitmapParts {
    Color,
    #[default]
    All,
}

/// [`SparseBitmap`] on the wire, compact and lossless: the rectangle; the
/// coverage mask packed eight pixels a byte (row-major within the rectangle,
/// least significant bit first, unused high bits of the last byte zero), then
/// zstd-compressed; and the covered pixels' arrays (in [`WireBitmapParts`])
/// as little-endian byte planes — byte k of every value, then byte k + 1 …
/// — zstd-compressed. Byte planes put the slowly varying sign and exponent
/// bytes of neighbouring pixels side by side, which is what makes float
/// colours compress. Both decompress into exactly the size the rectangle and
/// the mask imply, so hostile input cannot make the receiver allocate more.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WireBitmap {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
    pub parts: WireBitmapParts,
    #[serde(with = "crate::message::bytes")]
    pub mask: Vec<u8>,
    #[serde(with = "crate::message::bytes")]
    pub pixels: Vec<u8>,
}

/// zstd's fastest level: results are encoded once per package on the
/// worker's critical path, finished frames once per frame on the master's,
/// and level 1 already gets most of the gain.
const ZSTD_LEVEL: i32 = 1;

impl From<&SparseBitmap> for WireBitmap {
    fn from(b: &SparseBitmap) -> Self {
        WireBitmap::encode(b, WireBitmapParts::All)
    }
}

impl WireBitmap {
    /// Encodes `parts` of a bitmap.
    pub fn encode(b: &SparseBitmap, parts: WireBitmapParts) -> Self {
        let mut mask = vec![0u8; b.mask.len().div_ceil(8)];
        for (i, _) in b.mask.iter().enumerate().filter(|(_, m)| **m) {
            mask[i / 8] |= 1 << (i % 8);
        }
        let mut values: Vec<[u8; 4]> = Vec::new();
        let mut colors = |v: &[Vec3]| {
            values.extend(v.iter().flat_map(|c| c.to_array()).map(f32::to_le_bytes));
        };
        colors(&b.color);
        if parts == WireBitmapParts::All {
            colors(&b.reflected);
            colors(&b.transmitted);
            values.extend(b.reflected_object.iter().map(|o| o.to_le_bytes()));
        }
        let planes = byte_planes(&values);
        WireBitmap {
            x0: b.x0,
            y0: b.y0,
            width: b.width,
            height: b.height,
            parts,
            mask: compress(&mask),
            pixels: compress(&planes),
        }
    }

    /// Converts like `TryFrom`, and also checks that the rectangle lies
    /// inside a `width` × `height` frame, as compositing requires.
    pub fn into_bitmap_within(self, width: u32, height: u32) -> Result<SparseBitmap, WireError> {
        self.check_within(width, height)?;
        self.try_into()
    }

    /// Whether the rectangle lies inside a `width` × `height` frame.
    fn check_within(&self, width: u32, height: u32) -> Result<(), WireError> {
        // u64: the sums cannot overflow.
        let (x_end, y_end) = (
            u64::from(self.x0) + u64::from(self.width),
            u64::from(self.y0) + u64::from(self.height),
        );
        if x_end > width.into() || y_end > height.into() {
            return Err(out_of_range(
                "bitmap rectangle",
                format!("({}, {}) {}x{}", self.x0, self.y0, self.width, self.height),
                "inside the frame",
            ));
        }
        Ok(())
    }
}

impl crate::WireFrameAux {
    /// The wire form of a frame's components (its colour travels apart, in
    /// `FrameDone::image`).
    pub fn encode(image: &FrameImage) -> Self {
        let image = image.components();
        let objects: Vec<[u8; 4]> = image
            .reflected_object
            .iter()
            .map(|o| o.to_le_bytes())
            .collect();
        let mask: Vec<u8> = image.mask.iter().map(|&m| u8::from(m)).collect();
        crate::WireFrameAux {
            reflected: WireImage::encode(&image.reflected, WireImageFormat::LinearF32),
            transmitted: WireImage::encode(&image.transmitted, WireImageFormat::LinearF32),
            reflected_object: compress(&byte_planes(&objects)),
            mask: compress(&mask),
        }
    }

    /// The frame with its components, every array checked to hold one
    /// entry per pixel of `color`.
    pub fn into_components(self, color: vtfarm_imaging::Image) -> Result<FrameImage, WireError> {
        let n = color.pixels.len();
        let component = |field: &str, image: WireImage| {
            let (width, height, pixels) = image.into_pixels()?;
            if (width, height) != (color.width, color.height) {
                return Err(out_of_range(
                    field,
                    format!("{width}x{height}"),
                    "the frame's size",
                ));
            }
            Ok(vtfarm_imaging::Image {
                width,
                height,
                pixels,
            })
        };
        let reflected = component("reflected component", self.reflected)?;
        let transmitted = component("transmitted component", self.transmitted)?;
        let planes = decompress("reflected object bytes", &self.reflected_object, 4 * n)?;
        let reflected_object = (0..n)
            .map(|i| u32::from_le_bytes([0, 1, 2, 3].map(|k| planes[k * n + i])))
            .collect();
        let mask = decompress("mask bytes", &self.mask, n)?;
        if let Some(i) = mask.iter().position(|&m| m > 1) {
            return Err(out_of_range(
                "mask",
                format!("{} at pixel {i}", mask[i]),
                "0 or 1",
            ));
        }
        let components = Components {
            reflected,
            transmitted,
            reflected_object,
            mask: mask.into_iter().map(|m| m == 1).collect(),
        };
        Ok(FrameImage::from_components(color, components))
    }
}

/// The pixels' channels as little-endian byte planes ([`byte_planes_into`]
/// of every channel), into `planes` (whatever it held).
fn pixel_planes_into(pixels: &[Vec3], planes: &mut Vec<u8>) {
    let channels = pixels.iter().flat_map(|c| c.to_array());
    byte_planes_into(channels.map(f32::to_le_bytes), 3 * pixels.len(), planes);
}

/// Little-endian values as byte planes: byte 0 of every value, then byte 1 …
fn byte_planes(values: &[[u8; 4]]) -> Vec<u8> {
    let mut planes = Vec::new();
    byte_planes_into(values.iter().copied(), values.len(), &mut planes);
    planes
}

/// [`byte_planes`] of `count` values into `planes` (whatever it held).
fn byte_planes_into(values: impl Iterator<Item = [u8; 4]>, count: usize, planes: &mut Vec<u8>) {
    planes.clear();
    planes.resize(4 * count, 0);
    for (i, bytes) in values.take(count).enumerate() {
        for (k, byte) in bytes.into_iter().enumerate() {
            planes[k * count + i] = byte;
        }
    }
}

/// A [`WireBitmap`]'s checked and decompressed parts.
struct DecodedBitmap {
    /// The coverage bits, eight pixels a byte, padding checked to be zero.
    mask: Vec<u8>,
    /// Pixels of the rectangle.
    area: usize,
    /// Covered pixels.
    covered: usize,
    /// Values (each four bytes, one byte per plane) of the covered pixels.
    values: usize,
    planes: Vec<u8>,
}

impl DecodedBitmap {
    /// Whether pixel `i` of the rectangle is covered.
    fn is_covered(&self, i: usize) -> bool {
        self.mask[i / 8] >> (i % 8) & 1 == 1
    }

    /// Value `i`'s four bytes, one from each plane.
    fn value(&self, i: usize) -> [u8; 4] {
        [0, 1, 2, 3].map(|k| self.planes[k * self.values + i])
    }

    /// Covered pixel `p`'s colour of the component whose values start at
    /// `first`, checked finite.
    fn color(&self, field: &str, first: usize, p: usize) -> Result<Vec3, WireError> {
        let c = [0, 1, 2].map(|c| f32::from_le_bytes(self.value(first + 3 * p + c)));
        finite3(|| format!("{field}[{p}]"), c)
    }
}

impl WireBitmap {
    /// The rectangle checked to fit the coordinate type, the mask and the
    /// byte planes decompressed into exactly the sizes they imply.
    fn decode(&self) -> Result<DecodedBitmap, WireError> {
        // Both ends of the rectangle must fit the frame's coordinate type.
        for (field, start, size) in [
            ("bitmap x", self.x0, self.width),
            ("bitmap y", self.y0, self.height),
        ] {
            if start
                .checked_add(size)
                .is_none_or(|end| end > MAX_IMAGE_SIDE)
            {
                return Err(out_of_range(
                    field,
                    format!("{start} + {size}"),
                    "within 16384 pixels",
                ));
            }
        }
        let area = self.width as usize * self.height as usize;
        let mask = decompress("bitmap mask bytes", &self.mask, area.div_ceil(8))?;
        if area % 8 != 0 && mask.last().is_some_and(|&b| b >> (area % 8) != 0) {
            return Err(out_of_range(
                "bitmap mask padding",
                "set bits",
                "zero past the last pixel",
            ));
        }
        let covered: usize = mask.iter().map(|b| b.count_ones() as usize).sum();
        let values_per_pixel = match self.parts {
            WireBitmapParts::Color => 3,
            WireBitmapParts::All => 10,
        };
        let values = covered * values_per_pixel;
        let planes = decompress("bitmap pixel bytes", &self.pixels, values * 4)?;
        Ok(DecodedBitmap {
            mask,
            area,
            covered,
            values,
            planes,
        })
    }

    /// The covered pixels' colours with their indices in a `width`-wide
    /// frame (`y * width + x`), in the order of the mask, decoded straight
    /// from the wire for compositing the colour alone (the components, if
    /// sent, are skipped); the rectangle must lie inside the `width` ×
    /// `height` frame. The same checks as the conversion to
    /// [`SparseBitmap`], without building one.
    pub fn colors_within(&self, width: u32, height: u32) -> Result<Vec<(usize, Vec3)>, WireError> {
        self.check_within(width, height)?;
        let decoded = self.decode()?;
        let mut colors = Vec::with_capacity(decoded.covered);
        for i in (0..decoded.area).filter(|&i| decoded.is_covered(i)) {
            let p = colors.len();
            let (x, y) = (
                self.x0 as usize + i % self.width as usize,
                self.y0 as usize + i / self.width as usize,
            );
            colors.push((y * width as usize + x, decoded.color("bitmap color", 0, p)?));
        }
        Ok(colors)
    }
}

thread_local! {
    /// zstd's contexts, one of each per thread, kept from call to call: a
    /// fresh one allocates its tables again for every result and frame.
    static COMPRESSOR: RefCell<Option<zstd::bulk::Compressor<'static>>> =
        const { RefCell::new(None) };
    static DECOMPRESSOR: RefCell<Option<zstd::bulk::Decompressor<'static>>> =
        const { RefCell::new(None) };
}

fn compress(bytes: &[u8]) -> Vec<u8> {
    if bytes.is_empty() {
        return Vec::new();
    }
    // Compressing from memory into memory fails only on allocation failure.
    COMPRESSOR.with_borrow_mut(|compressor| {
        let compressor = compressor.get_or_insert_with(|| {
            zstd::bulk::Compressor::new(ZSTD_LEVEL).expect("zstd makes a context")
        });
        compressor
            .compress(bytes)
            .expect("zstd compresses in memory")
    })
}

/// Decompresses exactly `expected` bytes (no more may be allocated).
fn decompress(field: &str, bytes: &[u8], expected: usize) -> Result<Vec<u8>, WireError> {
    let data = if expected == 0 && bytes.is_empty() {
        Vec::new()
    } else {
        let decompressed = DECOMPRESSOR.with_borrow_mut(|decompressor| {
            let decompressor = match decompressor {
                Some(d) => d,
                None => decompressor.insert(zstd::bulk::Decompressor::new()?),
            };
            decompressor.decompress(bytes, expected)
        });
        decompressed.map_err(|e| WireError::Decode {
            what: "compressed data",
            message: format!("{field}: {e}"),
        })?
    };
    if data.len() != expected {
        return Err(WireError::SizeMismatch {
            field: field.to_owned(),
            expected: expected as u64,
            actual: data.len() as u64,
        });
    }
    Ok(data)
}

impl TryFrom<WireBitmap> for SparseBitmap {
    type Error = WireError;

    fn try_from(w: WireBitmap) -> Result<Self, WireError> {
        let decoded = w.decode()?;
        let covered = decoded.covered;
        let colors = |field: &'static str, first: usize| {
            (0..covered)
                .map(|p| decoded.color(field, first, p))
                .collect::<Result<Vec<_>, _>>()
        };
        let color = colors("bitmap color", 0)?;
        let (reflected, transmitted, reflected_object) = match w.parts {
            WireBitmapParts::Color => (
                vec![Vec3::ZERO; covered],
                vec![Vec3::ZERO; covered],
                vec![vtfarm_scene::NONE; covered],
            ),
            WireBitmapParts::All => (
                colors("bitmap reflected", 3 * covered)?,
                colors("bitmap transmitted", 6 * covered)?,
                (0..covered)
                    .map(|p| u32::from_le_bytes(decoded.value(9 * covered + p)))
                    .collect(),
            ),
        };
        Ok(SparseBitmap {
            x0: w.x0,
            y0: w.y0,
            width: w.width,
            height: w.height,
            mask: (0..decoded.area).map(|i| decoded.is_covered(i)).collect(),
            color,
            reflected,
            transmitted,
            reflected_object,
        })
    }
}

/// [`PackageStats`] on the wire. Durations keep their full precision.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct WirePackageStats {
    pub triangles: u64,
    pub traced_triangles: u64,
    pub visible_vertices: u64,
    pub vertex_samples: u64,
    pub filled_pixels: u64,
    pub refined_edges: u64,
    pub faces: u64,
    pub pixels: u64,
    pub vertex_time: Duration,
    pub fill_time: Duration,
}

impl From<&PackageStats> for WirePackageStats {
    fn from(s: &PackageStats) -> Self {
        WirePackageStats {
            triangles: s.triangles,
            traced_triangles: s.traced_triangles,
            visible_vertices: s.visible_vertices,
            vertex_samples: s.vertex_samples,
            filled_pixels: s.filled_pixels,
            refined_edges: s.refined_edges,
            faces: s.faces,
            pixels: s.pixels,
            vertex_time: s.vertex_time,
            fill_time: s.fill_time,
        }
    }
}

// Counters cannot be invalid, and serde already rejects malformed durations.
impl From<WirePackageStats> for PackageStats {
    fn from(s: WirePackageStats) -> Self {
        PackageStats {
            triangles: s.triangles,
            traced_triangles: s.traced_triangles,
            visible_vertices: s.visible_vertices,
            vertex_samples: s.vertex_samples,
            filled_pixels: s.filled_pixels,
            refined_edges: s.refined_edges,
            faces: s.faces,
            pixels: s.pixels,
            vertex_time: s.vertex_time,
            fill_time: s.fill_time,
        }
    }
}

/// How a [`WireImage`] codes its pixels: what the job's outputs need
/// (`WireJob::image`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireImageFormat {
    /// Linear RGB f32, lossless: for `.npy` files, error figures and the
    /// components.
    #[default]
    LinearF32,
    /// 8-bit sRGB, [`vtfarm_imaging::encode_srgb8`] of every pixel: exactly
    /// what a PNG of the frame holds, for a job that writes only PNGs.
    Srgb8,
}

/// A finished frame (row 0 at the top, row-major) in a
/// [`WireImageFormat`]: linear f32 channels as little-endian byte planes
/// (as in [`WireBitmap`]), or sRGB bytes, RGB interleaved; zstd-compressed
/// either way. The master encodes a finished frame once and the same bytes
/// go to the submitter and the journal (a 1080p frame is 25 MB of floats
/// before compression, a few MB as sRGB after). The submitter decides on
/// PNG or NPY, since sRGB happens only in vtfarm-imaging. Decoding
/// decompresses into exactly the size the sides imply, so hostile input
/// cannot make the receiver allocate more.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WireImage {
    pub width: u32,
    pub height: u32,
    pub format: WireImageFormat,
    #[serde(with = "crate::message::bytes")]
    pub pixels: Vec<u8>,
}

impl WireImage {
    /// The wire form of a `width` × `height` linear image, lossless.
    pub fn from_pixels(width: u32, height: u32, pixels: &[Vec3]) -> Self {
        let mut planes = Vec::new();
        pixel_planes_into(pixels, &mut planes);
        WireImage {
            width,
            height,
            format: WireImageFormat::LinearF32,
            pixels: compress(&planes),
        }
    }

    /// The wire form of `image` in `format`.
    pub fn encode(image: &vtfarm_imaging::Image, format: WireImageFormat) -> Self {
        WireImage::encode_reusing(image, format, &mut Vec::new())
    }

    /// [`WireImage::encode`] with the uncompressed bytes in `scratch`
    /// (whatever it held): a buffer kept from frame to frame spares a
    /// fresh one's page faults (6 MB of sRGB, 25 MB of floats at 1080p).
    pub fn encode_reusing(
        image: &vtfarm_imaging::Image,
        format: WireImageFormat,
        scratch: &mut Vec<u8>,
    ) -> Self {
        match format {
            WireImageFormat::LinearF32 => pixel_planes_into(&image.pixels, scratch),
            WireImageFormat::Srgb8 => image.to_srgb8_into(scratch),
        }
        WireImage {
            width: image.width,
            height: image.height,
            format,
            pixels: compress(scratch),
        }
    }

    /// The pixel count, with the sides checked.
    fn pixel_count(&self) -> Result<usize, WireError> {
        for (field, side) in [("image width", self.width), ("image height", self.height)] {
            if side > MAX_IMAGE_SIDE {
                return Err(out_of_range(field, side, "0 to 16384"));
            }
        }
        Ok(self.width as usize * self.height as usize)
    }

    /// The validated linear pixels: sizes in range, `width * height` of
    /// them, all finite. An sRGB image is refused: its linear colours are
    /// lost (the job asked for sRGB).
    pub fn into_pixels(self) -> Result<(u32, u32, Vec<Vec3>), WireError> {
        let n = self.pixel_count()?;
        if self.format != WireImageFormat::LinearF32 {
            return Err(out_of_range(
                "image format",
                format!("{:?}", self.format),
                "LinearF32 where linear colours are needed",
            ));
        }
        let values = 3 * n;
        let planes = decompress("image pixel bytes", &self.pixels, 4 * values)?;
        let value = |i: usize| f32::from_le_bytes([0, 1, 2, 3].map(|k| planes[k * values + i]));
        let pixels = (0..n)
            .map(|i| {
                let p = [value(3 * i), value(3 * i + 1), value(3 * i + 2)];
                finite3(|| format!("image pixel {i}"), p)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok((self.width, self.height, pixels))
    }

    /// The 8-bit sRGB pixels (RGB interleaved), `width * height * 3` of
    /// them: as sent, or encoded here from linear ones.
    pub fn into_srgb8(self) -> Result<(u32, u32, Vec<u8>), WireError> {
        let n = self.pixel_count()?;
        match self.format {
            WireImageFormat::Srgb8 => {
                let bytes = decompress("image pixel bytes", &self.pixels, 3 * n)?;
                Ok((self.width, self.height, bytes))
            }
            WireImageFormat::LinearF32 => {
                let (width, height, pixels) = self.into_pixels()?;
                let image = vtfarm_imaging::Image {
                    width,
                    height,
                    pixels,
                };
                Ok((width, height, image.to_srgb8()))
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use proptest::prelude::*;

    pub(crate) fn material(name: &str) -> Material {
        Material {
            name: name.to_owned(),
            ambient: Vec3::new(0.1, 0.2, 0.3),
            diffuse: Vec3::new(0.4, 0.5, 0.6),
            specular: Vec3::splat(0.25),
            shininess: 32.0,
            emission: Vec3::new(0.0, 0.5, 0.0),
            reflectance: Vec3::splat(0.9),
            transmittance: Vec3::splat(0.1),
            ior: 1.5,
            ..Default::default()
        }
    }

    /// Two triangles in two objects with two materials.
    pub(crate) fn scene() -> Scene {
        Scene {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, -0.5)],
            normals: vec![Vec3::Z; 4],
            triangles: vec![
                Triangle {
                    vertices: [0, 1, 2],
                    object: 0,
                    material: 0,
                },
                Triangle {
                    vertices: [1, 3, 2],
                    object: 1,
                    material: 1,
                },
            ],
            objects: vec![
                Object {
                    name: "glass".to_owned(),
                },
                Object {
                    name: "dash".to_owned(),
                },
            ],
            materials: vec![material("mirror"), Material::default()],
            ..Default::default()
        }
    }

    pub(crate) fn camera() -> Camera {
        Camera {
            eye: Vec3::new(0.0, 1.0, 3.0),
            target: Vec3::new(0.2, 0.5, 0.0),
            up: Vec3::Y,
            fov_y_deg: 45.0,
            width: 64,
            height: 48,
        }
    }

    pub(crate) fn lighting() -> Lighting {
        Lighting {
            lights: vec![
                Light {
                    kind: LightKind::Point {
                        position: Vec3::new(1.0, 2.0, 3.0),
                    },
                    color: Vec3::ONE,
                    intensity: 0.8,
                },
                Light {
                    kind: LightKind::Directional {
                        direction: Vec3::new(0.0, -1.0, -1.0),
                    },
                    color: Vec3::new(1.0, 0.9, 0.8),
                    intensity: 0.5,
                },
            ],
            ambient: Vec3::splat(0.05),
            background: Vec3::new(0.2, 0.3, 0.9),
        }
    }

    /// A 5 × 3 rectangle (15 mask bits: not a multiple of 8) with 4 covered pixels.
    pub(crate) fn bitmap() -> SparseBitmap {
        let mut mask = vec![false; 15];
        for i in [0, 6, 7, 14] {
            mask[i] = true;
        }
        SparseBitmap {
            x0: 3,
            y0: 2,
            width: 5,
            height: 3,
            mask,
            color: vec![Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE],
            reflected: vec![Vec3::ZERO, Vec3::splat(0.5), Vec3::ZERO, Vec3::splat(0.25)],
            transmitted: vec![Vec3::ONE, Vec3::splat(0.125), Vec3::X, Vec3::ZERO],
            reflected_object: vec![0, vtfarm_scene::NONE, 1, 0],
        }
    }

    fn round_trip<D, W>(value: &D) -> D
    where
        for<'a> W: From<&'a D>,
        D: TryFrom<W, Error = WireError>,
    {
        D::try_from(W::from(value)).expect("a domain value converts back")
    }

    #[test]
    fn scene_round_trips() {
        let s = scene();
        assert_eq!(round_trip::<Scene, WireScene>(&s), s);
        assert_eq!(
            round_trip::<Scene, WireScene>(&Scene::default()),
            Scene::default()
        );
    }

    #[test]
    fn camera_lighting_and_material_round_trip() {
        assert_eq!(round_trip::<Camera, WireCamera>(&camera()), camera());
        assert_eq!(
            round_trip::<Lighting, WireLighting>(&lighting()),
            lighting()
        );
        for l in &lighting().lights {
            assert_eq!(round_trip::<Light, WireLight>(l), *l);
        }
        assert_eq!(
            round_trip::<Material, WireMaterial>(&material("m")),
            material("m")
        );
    }

    #[test]
    fn settings_round_trip() {
        let trace = TraceSettings {
            max_depth: 7,
            fresnel: true,
            signature_min_weight: 0.125,
        };
        assert_eq!(
            round_trip::<TraceSettings, WireTraceSettings>(&trace),
            trace
        );
        for method in MethodKind::ALL {
            assert_eq!(MethodKind::from(WireMethod::from(method)), method);
        }
        for quality in Quality::ALL {
            assert_eq!(Quality::from(WireQuality::from(quality)), quality);
            let vertex = VertexSettings {
                quality,
                max_depth: 9,
                visibility_radius: 2,
                ..VertexSettings::default()
            };
            assert_eq!(
                round_trip::<VertexSettings, WireVertexSettings>(&vertex),
                vertex
            );
        }
        let setup = FrameSetup {
            camera: camera(),
            lighting: lighting(),
            trace,
            vertex: VertexSettings::default(),
        };
        assert_eq!(round_trip::<FrameSetup, WireFrameSetup>(&setup), setup);
    }

    #[test]
    fn bitmaps_round_trip_with_packed_masks() {
        let b = bitmap();
        let wire = WireBitmap::from(&b);
        assert_eq!(
            zstd::bulk::decompress(&wire.mask, 2).expect("zstd"),
            vec![0b1100_0001, 0b0100_0000]
        );
        assert_eq!(round_trip::<SparseBitmap, WireBitmap>(&b), b);
        assert_eq!(
            wire.into_bitmap_within(8, 5).expect("fits exactly"),
            bitmap()
        );
        let empty = SparseBitmap::default();
        assert_eq!(round_trip::<SparseBitmap, WireBitmap>(&empty), empty);
    }

    #[test]
    fn color_only_bitmaps_leave_the_components_empty() {
        let b = bitmap();
        let wire = WireBitmap::encode(&b, WireBitmapParts::Color);
        assert!(wire.pixels.len() < WireBitmap::from(&b).pixels.len());
        let back = SparseBitmap::try_from(wire).expect("valid");
        assert_eq!((&back.mask, &back.color), (&b.mask, &b.color));
        assert_eq!(back.reflected, vec![Vec3::ZERO; 4]);
        assert_eq!(back.transmitted, vec![Vec3::ZERO; 4]);
        assert_eq!(back.reflected_object, vec![vtfarm_scene::NONE; 4]);
    }

    /// The colours alone, straight from the wire: each covered pixel's
    /// index in the frame with its colour, whichever parts were sent.
    #[test]
    fn colors_come_straight_from_the_wire_with_frame_indices() {
        let b = bitmap();
        let expected: Vec<(usize, Vec3)> = (b.covered())
            .map(|(x, y, k)| ((y * 9 + x) as usize, b.color[k]))
            .collect();
        assert_eq!(expected.len(), 4);
        for parts in [WireBitmapParts::Color, WireBitmapParts::All] {
            let wire = WireBitmap::encode(&b, parts);
            assert_eq!(wire.colors_within(9, 5).expect("inside"), expected);
            let error = wire.colors_within(7, 5).expect_err("one column short");
            assert!(error.to_string().contains("inside the frame"), "{error}");
        }
    }

    #[test]
    fn smooth_colors_compress() {
        // A 200 x 100 gradient, like a reflection: the byte planes compress.
        let (width, height) = (200u32, 100u32);
        let n = (width * height) as usize;
        let shade = |i: usize| Vec3::new(0.2 + i as f32 * 1e-5, 0.3, 0.4 - i as f32 * 1e-5);
        let b = SparseBitmap {
            x0: 0,
            y0: 0,
            width,
            height,
            mask: vec![true; n],
            color: (0..n).map(shade).collect(),
            reflected: (0..n).map(shade).collect(),
            transmitted: vec![Vec3::splat(0.1); n],
            reflected_object: vec![3; n],
        };
        let raw = n * 40;
        let wire = WireBitmap::from(&b);
        assert!(
            wire.pixels.len() * 2 < raw,
            "{} of {raw}",
            wire.pixels.len()
        );
        assert_eq!(SparseBitmap::try_from(wire).expect("valid"), b);
    }

    #[test]
    fn stats_and_images_round_trip() {
        let stats = PackageStats {
            triangles: 1,
            traced_triangles: 2,
            visible_vertices: 3,
            vertex_samples: 4,
            filled_pixels: 5,
            refined_edges: 6,
            faces: 7,
            pixels: 8,
            vertex_time: Duration::new(1, 234_567_891),
            fill_time: Duration::from_nanos(17),
        };
        assert_eq!(PackageStats::from(WirePackageStats::from(&stats)), stats);
        let pixels = vec![Vec3::new(0.5, 1.5, 2.5); 6];
        let image = WireImage::from_pixels(3, 2, &pixels);
        assert_eq!(image.into_pixels().expect("valid image"), (3, 2, pixels));
    }

    /// Applies `damage` to a valid wire value and expects the conversion to
    /// fail with a message containing `expected`.
    fn check_rejects<W: Clone, D: TryFrom<W, Error = WireError> + std::fmt::Debug>(
        valid: &W,
        damage: impl FnOnce(&mut W),
        expected: &str,
    ) {
        let mut w = valid.clone();
        damage(&mut w);
        let message = D::try_from(w).expect_err(expected).to_string();
        assert!(message.contains(expected), "{message:?} lacks {expected:?}");
    }

    #[test]
    fn hostile_scenes_are_rejected() {
        let valid = WireScene::from(&scene());
        let check = |damage: fn(&mut WireScene), expected| {
            check_rejects::<WireScene, Scene>(&valid, damage, expected)
        };
        check(
            |s| s.positions[1][2] = f32::NAN,
            "scene position 1 is not finite",
        );
        check(
            |s| s.normals.truncate(3),
            "scene normals has 3 entries, expected 4",
        );
        check(
            |s| s.triangles[1].vertices[2] = 4,
            "triangle 1 vertex 2 = 4 is out of range",
        );
        check(|s| s.triangles[0].object = 2, "triangle 0 object = 2");
        check(
            |s| s.triangles[0].material = u32::MAX,
            "triangle 0 material",
        );
        check(
            |s| s.normals[0] = [0.0, 0.0, 2.0],
            "normal 0 is not unit length",
        );
        check(
            |s| s.materials[1].ior = f32::INFINITY,
            "material \"default\" ior is not finite",
        );
        // Finite but absurd: obvhs' build overflowed on it (issue 13).
        check(
            |s| s.positions[3][0] = 1e22,
            "vertex 3: position = [10000000000000000000000, 1, -0.5]: must be finite and within ±1e6 m",
        );
    }

    #[test]
    fn hostile_cameras_lights_and_settings_are_rejected() {
        let cam = WireCamera::from(&camera());
        let check = |damage: fn(&mut WireCamera), expected| {
            check_rejects::<WireCamera, Camera>(&cam, damage, expected)
        };
        check(
            |c| c.eye[0] = f32::NAN,
            "camera eye = [NaN, 1, 3]: must be finite",
        );
        check(|c| c.width = 0, "camera width = 0");
        check(|c| c.height = MAX_IMAGE_SIDE + 1, "camera height = 16385");
        check(|c| c.fov_y_deg = 180.0, "camera fov_y_deg = 180");
        check(
            |c| c.target = c.eye,
            "camera eye = [0, 1, 3]: must be away from the target",
        );
        check(|c| c.up = [0.0; 3], "camera up");

        let light = WireLight::from(&lighting().lights[1]);
        check_rejects::<WireLight, Light>(
            &light,
            |l| {
                l.kind = WireLightKind::Directional {
                    direction: [0.0; 3],
                }
            },
            "light direction",
        );
        check_rejects::<WireLight, Light>(&light, |l| l.intensity = f32::NAN, "light intensity");
        check_rejects::<WireLighting, Lighting>(
            &WireLighting::from(&lighting()),
            |l| l.lights = vec![light; Lighting::MAX_LIGHTS + 1],
            "lights = 65",
        );

        let trace = WireTraceSettings::from(&TraceSettings::default());
        check_rejects::<_, TraceSettings>(&trace, |t| t.max_depth = 0, "trace max_depth = 0");
        check_rejects::<_, TraceSettings>(&trace, |t| t.max_depth = 65, "trace max_depth = 65");
        let vertex = WireVertexSettings::from(&VertexSettings::default());
        check_rejects::<_, VertexSettings>(&vertex, |v| v.epsilon = -1.0, "vertex epsilon = -1");
        check_rejects::<_, VertexSettings>(
            &vertex,
            |v| v.visibility_radius = 1000,
            "vertex visibility_radius = 1000",
        );
        // Issue 13's runaway values: the same `validate` as the job parser.
        check_rejects::<_, VertexSettings>(
            &vertex,
            |v| v.max_depth = u32::MAX,
            "vertex max_depth = 4294967295: must be 0 to 32",
        );
        check_rejects::<_, VertexSettings>(
            &vertex,
            |v| (v.pixel_floor, v.epsilon) = (0.0, 0.0),
            "vertex pixel_floor = 0: must be finite and at least 0.5",
        );
        check(
            |c| (c.width, c.height) = (16384, 16384),
            "camera width × height = 16384 × 16384: must be at most 16777216 pixels",
        );
        check(
            |c| c.eye[1] = 1e22,
            "camera eye = [0, 10000000000000000000000, 3]",
        );
        let far = WireLight::from(&lighting().lights[0]);
        check_rejects::<WireLight, Light>(
            &far,
            |l| {
                l.kind = WireLightKind::Point {
                    position: [0.0, 0.0, -1e22],
                }
            },
            "light position",
        );
    }

    #[test]
    fn hostile_bitmaps_are_rejected() {
        let valid = WireBitmap::from(&bitmap());
        let check = |damage: fn(&mut WireBitmap), expected| {
            check_rejects::<WireBitmap, SparseBitmap>(&valid, damage, expected)
        };
        check(
            |b| b.mask = zstd::bulk::compress(&[0b1100_0001, 0, 0], 1).expect("zstd"),
            "bitmap mask bytes",
        );
        check(
            |b| b.mask = zstd::bulk::compress(&[0b1100_0001, 0b1100_0000], 1).expect("zstd"),
            "bitmap mask padding",
        );
        check(
            |b| b.mask = zstd::bulk::compress(&[0b1100_0011, 0b0100_0000], 1).expect("zstd"),
            "bitmap pixel bytes",
        );
        check(|b| b.mask = vec![1, 2, 3], "bitmap mask bytes");
        check(|b| b.pixels.truncate(5), "bitmap pixel bytes");
        check(|b| b.parts = WireBitmapParts::Color, "bitmap pixel bytes");
        check(
            |b| {
                let mut bad = bitmap();
                bad.color[3].y = f32::NEG_INFINITY;
                *b = WireBitmap::from(&bad);
            },
            "bitmap color[3] is not finite",
        );
        check(|b| b.x0 = u32::MAX, "bitmap x");
        check(|b| (b.width, b.height) = (u32::MAX, u32::MAX), "bitmap x");
        let outside = valid
            .clone()
            .into_bitmap_within(7, 5)
            .expect_err("one column short");
        assert!(
            outside.to_string().contains("inside the frame"),
            "{outside}"
        );
        let mut image = WireImage::from_pixels(2, 1, &[Vec3::ZERO; 2]);
        image.height = 2;
        let error = image.into_pixels().expect_err("two pixels for four");
        assert!(error.to_string().contains("image pixel bytes"), "{error}");
    }

    /// A frame's image crosses the wire bit for bit (compressed byte
    /// planes); a non-finite pixel or damaged bytes are refused, naming what
    /// is wrong.
    #[test]
    fn wire_images_round_trip_bit_exact_and_refuse_bad_pixels() {
        let pixels = vec![
            Vec3::new(0.1, -0.0, 3.5e-39),
            Vec3::new(1e30, 0.5, 0.25),
            Vec3::splat(f32::MIN_POSITIVE),
            Vec3::new(7.0, 8.0, 9.0),
        ];
        let wire = WireImage::from_pixels(2, 2, &pixels);
        let message = crate::Message::FrameDone(crate::FrameDone {
            job: 1,
            frame: 2,
            image: wire,
            stats: Default::default(),
            aux: None,
        });
        let encoded = crate::encode_message(&message).unwrap();
        let crate::Message::FrameDone(done) = crate::decode_message(&encoded[4..]).unwrap() else {
            panic!("a FrameDone comes back");
        };
        let (w, h, back) = done.image.into_pixels().unwrap();
        assert_eq!((w, h), (2, 2));
        let bits = |p: &[Vec3]| -> Vec<u32> {
            p.iter()
                .flat_map(|v| v.to_array())
                .map(f32::to_bits)
                .collect()
        };
        assert_eq!(bits(&back), bits(&pixels));

        let mut nan = pixels.clone();
        nan[1].y = f32::NAN;
        let error = (WireImage::from_pixels(2, 2, &nan).into_pixels()).expect_err("a NaN pixel");
        assert!(error.to_string().contains("image pixel 1"), "{error}");
        let mut ragged = WireImage::from_pixels(2, 2, &pixels);
        ragged.pixels.pop();
        assert!(ragged.into_pixels().is_err());
    }

    /// A frame's components cross the wire bit for bit; arrays of another
    /// size than the frame's, or a mask that is not 0 or 1, are refused.
    #[test]
    fn frame_components_round_trip_and_refuse_bad_sizes() {
        let image = |pixels: Vec<Vec3>| vtfarm_imaging::Image {
            width: 3,
            height: 1,
            pixels,
        };
        let frame = FrameImage::from_components(
            image(vec![Vec3::ONE, Vec3::X, Vec3::Y]),
            Components {
                reflected: image(vec![Vec3::ZERO, Vec3::splat(0.25), Vec3::Z]),
                transmitted: image(vec![Vec3::ZERO, Vec3::splat(1e-30), Vec3::X]),
                reflected_object: vec![vtfarm_scene::NONE, 7, 0],
                mask: vec![false, true, true],
            },
        );
        let wire = crate::WireFrameAux::encode(&frame);
        assert_eq!(
            wire.clone().into_components(frame.color.clone()).unwrap(),
            frame
        );

        let wider = vtfarm_imaging::Image::black(4, 1);
        let error = wire
            .clone()
            .into_components(wider)
            .expect_err("a wider frame");
        assert!(
            error.to_string().contains("reflected component = 3x1"),
            "{error}"
        );
        let mut bad_mask = wire;
        bad_mask.mask = compress(&[0, 2, 1]);
        let error = (bad_mask.into_components(frame.color.clone())).expect_err("a mask of 2");
        assert!(error.to_string().contains("mask = 2 at pixel 1"), "{error}");
    }

    /// An sRGB frame carries exactly the bytes a PNG of the linear one
    /// holds; a linear frame gives the same bytes; linear colours are not
    /// made up from sRGB ones.
    #[test]
    fn srgb_wire_images_carry_the_png_bytes() {
        let image = vtfarm_imaging::Image {
            width: 3,
            height: 2,
            pixels: (0..6)
                .map(|i| Vec3::new(0.1 * i as f32, 0.5, 2.0))
                .collect(),
        };
        let srgb = WireImage::encode(&image, WireImageFormat::Srgb8);
        assert_eq!(srgb.clone().into_srgb8().unwrap(), (3, 2, image.to_srgb8()));
        let linear = WireImage::encode(&image, WireImageFormat::LinearF32);
        assert_eq!(linear.into_srgb8().unwrap(), (3, 2, image.to_srgb8()));
        let error = srgb.clone().into_pixels().expect_err("no linear colours");
        assert!(error.to_string().contains("image format"), "{error}");
        let mut short = srgb;
        short.width = 4;
        let error = short.into_srgb8().expect_err("six pixels for eight");
        assert!(error.to_string().contains("image pixel bytes"), "{error}");
        // Encoded in a buffer that held more or less, the same bytes.
        for format in [WireImageFormat::Srgb8, WireImageFormat::LinearF32] {
            for stale in [vec![0xab; 1000], vec![0xab; 1]] {
                let mut scratch = stale;
                let reused = WireImage::encode_reusing(&image, format, &mut scratch);
                assert_eq!(reused, WireImage::encode(&image, format), "{format:?}");
            }
        }
    }

    #[test]
    fn triangle_id_lists_are_checked_against_the_scene() {
        assert!(check_triangle_ids("reflectors", &[2, 0, 1], 3).is_ok());
        let error = check_triangle_ids("reflectors", &[0, 3], 3).expect_err("3 of 3");
        assert_eq!(
            error.to_string(),
            "reflectors[1] = 3 is out of range (there are 3)"
        );
        let error = check_triangle_ids("package", &[1, 1], 3).expect_err("duplicate");
        assert_eq!(error.to_string(), "package lists 1 twice");
    }

    fn any_f32() -> impl Strategy<Value = f32> {
        prop_oneof![
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(0.0f32),
            -2.0f32..2.0
        ]
    }

    prop_compose! {
        fn any_bitmap()(
            x0 in prop_oneof![0u32..20, Just(u32::MAX)],
            y0 in 0u32..20,
            width in prop_oneof![0u32..20, Just(u32::MAX)],
            height in 0u32..20,
            all in any::<bool>(),
            mask in proptest::collection::vec(any::<u8>(), 0..8),
            colors in proptest::collection::vec(any_f32(), 0..300),
            compressed in any::<bool>(),
        ) -> WireBitmap {
            let parts = if all { WireBitmapParts::All } else { WireBitmapParts::Color };
            let planes: Vec<u8> = colors.iter().flat_map(|c| c.to_le_bytes()).collect();
            // Well-formed zstd of arbitrary content, or arbitrary bytes.
            let pack = |b: &[u8]| if compressed { compress(b) } else { b.to_vec() };
            WireBitmap { x0, y0, width, height, parts, mask: pack(&mask), pixels: pack(&planes) }
        }
    }

    proptest! {
        #[test]
        fn hostile_bitmaps_never_panic(b in any_bitmap(), w in 0u32..40, h in 0u32..40) {
            let accepted = SparseBitmap::try_from(b.clone());
            if let Ok(bitmap) = &accepted {
                // Whatever is accepted is self-consistent.
                prop_assert_eq!(bitmap.mask.len(), (bitmap.width * bitmap.height) as usize);
                prop_assert_eq!(bitmap.covered().count(), bitmap.color.len());
            }
            // Compositing the colour straight from the wire accepts the
            // same results and gives the same pixels.
            let colors = b.colors_within(w, h);
            match b.into_bitmap_within(w, h) {
                Ok(bitmap) => {
                    let expected: Vec<(usize, Vec3)> = (bitmap.covered())
                        .map(|(x, y, k)| ((y * w + x) as usize, bitmap.color[k]))
                        .collect();
                    prop_assert_eq!(colors.expect("accepted as a bitmap"), expected);
                }
                Err(_) => prop_assert!(colors.is_err()),
            }
        }

        #[test]
        fn hostile_scenes_never_panic(
            positions in proptest::collection::vec([any_f32(), any_f32(), any_f32()], 0..6),
            normals in proptest::collection::vec([any_f32(), any_f32(), any_f32()], 0..6),
            triangles in proptest::collection::vec(
                ([0u32..8, 0u32..8, 0u32..8], 0u32..3, 0u32..3), 0..6),
        ) {
            let wire = WireScene {
                positions,
                normals,
                triangles: triangles
                    .into_iter()
                    .map(|(vertices, object, material)| WireTriangle { vertices, object, material })
                    .collect(),
                objects: vec!["a".to_owned(), "b".to_owned()],
                materials: vec![WireMaterial::from(&Material::default())], ..Default::default()
            };
            if let Ok(scene) = Scene::try_from(wire) {
                prop_assert!(scene.validate().is_ok());
            }
        }
    }
}
