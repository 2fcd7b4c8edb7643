//! The scene model every other crate shares: indexed triangles with per-vertex
//! normals, named objects, Phong materials with mirror and transparency terms,
//! lights, and the pinhole camera with vtfarm's pixel convention.
//!
//! Architecture invariant: this crate knows nothing of ray tracing, rasterizing
//! or networking; it is plain data plus file import and export.

pub mod bounds;
mod camera;
mod light;
mod material;
pub mod normals;
pub mod obj;
pub mod photometry;
pub mod shading;
pub mod shapes;

pub use bounds::{MAX_COORDINATE, OutOfBounds};
pub use camera::{Camera, MAX_IMAGE_SIDE, MAX_PIXELS, NEAR, Projector, ScreenPoint};
pub use light::{
    DAYLIGHT_SKY_CD_M2, DAYLIGHT_SUN_DIRECTION, DAYLIGHT_SUN_LUX, Light, LightKind, Lighting,
};
pub use material::{GLASS_IOR, Material, MtlOptics, fresnel_reflectance, mtl_reflectance};

use glam::Vec3;

/// Index of an object (a named OBJ object or group) in [`Scene::objects`].
pub type ObjectId = u32;
/// Index of a triangle in [`Scene::triangles`].
pub type TriangleId = u32;
/// Index of a material in [`Scene::materials`].
pub type MaterialId = u32;
/// The "no object / no triangle" marker used in ID buffers and samples.
pub const NONE: u32 = u32::MAX;

/// One triangle: three indices into the vertex arrays (positions and normals
/// share one index), the object it belongs to and its material.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Triangle {
    pub vertices: [u32; 3],
    pub object: ObjectId,
    pub material: MaterialId,
}

/// A named object (OBJ `o` or `g`).
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    pub name: String,
}

/// A whole scene. Positions are in metres, +Y is up. `normals[i]` is the unit
/// shading normal of vertex `i`; vertices on hard edges are duplicated so each
/// copy has its own normal.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub triangles: Vec<Triangle>,
    pub objects: Vec<Object>,
    pub materials: Vec<Material>,
}

impl Scene {
    /// The three corner positions of triangle `id`.
    pub fn triangle_positions(&self, id: TriangleId) -> [Vec3; 3] {
        let t = &self.triangles[id as usize];
        t.vertices.map(|v| self.positions[v as usize])
    }

    /// The three corner normals of triangle `id`.
    pub fn triangle_normals(&self, id: TriangleId) -> [Vec3; 3] {
        let t = &self.triangles[id as usize];
        t.vertices.map(|v| self.normals[v as usize])
    }

    /// The unit geometric normal of triangle `id` (counter-clockwise winding),
    /// or zero for a degenerate triangle.
    pub fn geometric_normal(&self, id: TriangleId) -> Vec3 {
        let [a, b, c] = self.triangle_positions(id);
        (b - a).cross(c - a).normalize_or_zero()
    }

    /// The material of triangle `id`.
    pub fn material_of(&self, id: TriangleId) -> &Material {
        &self.materials[self.triangles[id as usize].material as usize]
    }

    /// Looks up an object by name.
    pub fn object_id(&self, name: &str) -> Option<ObjectId> {
        self.objects
            .iter()
            .position(|o| o.name == name)
            .map(|i| i as ObjectId)
    }

    /// Looks up a material by name.
    pub fn material_id(&self, name: &str) -> Option<MaterialId> {
        self.materials
            .iter()
            .position(|m| m.name == name)
            .map(|i| i as MaterialId)
    }

    /// The axis-aligned bounds (min, max) of all vertices.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        )
    }

    /// Appends another scene's content, remapping its indices.
    pub fn append(&mut self, other: &Scene) {
        let v0 = self.positions.len() as u32;
        let o0 = self.objects.len() as u32;
        let m0 = self.materials.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.objects.extend(other.objects.iter().cloned());
        self.materials.extend(other.materials.iter().cloned());
        self.triangles
            .extend(other.triangles.iter().map(|t| Triangle {
                vertices: t.vertices.map(|v| v + v0),
                object: t.object + o0,
                material: t.material + m0,
            }));
    }

    /// Checks the structural invariants: indices in range, one normal per
    /// position, unit normals, and every position within
    /// [`MAX_COORDINATE`] (the BVH build relies on it). Returns a description
    /// of the first violation.
    pub fn validate(&self) -> Result<(), String> {
        if self.positions.len() != self.normals.len() {
            return Err(format!(
                "{} positions but {} normals",
                self.positions.len(),
                self.normals.len()
            ));
        }
        for (i, t) in self.triangles.iter().enumerate() {
            if t.vertices
                .iter()
                .any(|&v| v as usize >= self.positions.len())
            {
                return Err(format!("triangle {i} indexes a missing vertex"));
            }
            if t.object as usize >= self.objects.len() {
                return Err(format!("triangle {i} names missing object {}", t.object));
            }
            if t.material as usize >= self.materials.len() {
                return Err(format!(
                    "triangle {i} names missing material {}",
                    t.material
                ));
            }
        }
        if let Some(i) = self
            .normals
            .iter()
            .position(|n| (n.length() - 1.0).abs().is_nan() || (n.length() - 1.0).abs() > 1e-3)
        {
            return Err(format!("normal {i} is not unit length"));
        }
        for (i, &p) in self.positions.iter().enumerate() {
            bounds::point("position", p).map_err(|e| format!("vertex {i}: {e}"))?;
        }
        Ok(())
    }
}
