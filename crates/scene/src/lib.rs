//! The scene model every other crate shares: indexed triangles with per-vertex
//! normals, named objects, Phong materials with mirror and transparency terms,
//! lights, and the pinhole camera with vtfarm's pixel convention.
//!
//! Architecture invariant: this crate knows nothing of ray tracing, rasterizing
//! or networking; it is plain data plus file import and export.

pub mod bounds;
mod camera;
pub mod file;
pub mod gltf;
mod light;
mod material;
pub mod normals;
pub mod obj;
pub mod photometry;
pub mod shading;
pub mod shapes;
pub mod texture;

pub use bounds::{MAX_COORDINATE, OutOfBounds};
pub use camera::{Camera, MAX_IMAGE_SIDE, MAX_PIXELS, NEAR, Projector, ScreenPoint};
pub use light::{
    DAYLIGHT_SKY_CD_M2, DAYLIGHT_SUN_DIRECTION, DAYLIGHT_SUN_LUX, Light, LightKind, Lighting,
    MAX_ANGULAR_DIAMETER_DEG, SUN_ANGULAR_DIAMETER_DEG, SunDisc, solid_angle_of_cone,
};
pub use material::{
    GLASS_IOR, Material, MtlOptics, MtlTerms, fresnel_reflectance, mtl_reflectance,
};
pub use texture::{Texture, TextureId};

use std::borrow::Cow;

use glam::{Vec2, Vec3};

/// An index into one of the scene's lists, as its own type: `index()` into
/// the list, `raw()` the bare number that maps and the wire hold, printed
/// as that number.
macro_rules! scene_index {
    ($(#[$doc:meta])* $name:ident, $list:literal) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
        pub struct $name(pub u32);

        impl $name {
            #[doc = concat!("Its index in [`Scene::", $list, "`].")]
            pub fn index(self) -> usize {
                self.0 as usize
            }

            /// The bare number, as maps and the wire hold it.
            pub fn raw(self) -> u32 {
                self.0
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                self.0.fmt(f)
            }
        }
    };
}

scene_index!(
    /// Index of an object (a named OBJ object or group) in [`Scene::objects`].
    /// Per-pixel and per-sample object maps hold the bare number, with
    /// [`NONE`] for no object ([`ObjectId::raw`]).
    ObjectId,
    "objects"
);

scene_index!(
    /// Index of a triangle in [`Scene::triangles`]. Per-pixel and per-sample
    /// triangle maps (ID buffers, sample records) hold the bare number, with
    /// [`NONE`] for no triangle ([`TriangleId::raw`]).
    TriangleId,
    "triangles"
);

scene_index!(
    /// Index of a material in [`Scene::materials`].
    MaterialId,
    "materials"
);

impl TriangleId {
    /// The triangle a map's bare number names: none for [`NONE`].
    pub fn from_raw(raw: u32) -> Option<TriangleId> {
        (raw != NONE).then_some(TriangleId(raw))
    }

    /// The ids of the first `n` triangles, in order.
    pub fn range(n: usize) -> impl DoubleEndedIterator<Item = TriangleId> + ExactSizeIterator {
        (0..n as u32).map(TriangleId)
    }
}

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
    /// The texture coordinates of each triangle's corners (see
    /// [`texture`]), or empty when nothing is textured.
    pub corner_uvs: Vec<[Vec2; 3]>,
    /// The textures the materials name.
    pub textures: Vec<Texture>,
}

/// A broken invariant of a [`Scene`] (see [`Scene::validate`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SceneError {
    #[error("{positions} positions but {normals} normals")]
    NormalCount { positions: usize, normals: usize },
    #[error("{triangles} triangles but {uvs} sets of corner texture coordinates")]
    UvCount { triangles: usize, uvs: usize },
    #[error("triangle {0} indexes a missing vertex")]
    MissingVertex(usize),
    #[error("triangle {triangle} names missing object {object}")]
    MissingObject { triangle: usize, object: ObjectId },
    #[error("triangle {triangle} names missing material {material}")]
    MissingMaterial {
        triangle: usize,
        material: MaterialId,
    },
    #[error("material {material:?} names missing texture {texture}")]
    MissingTexture {
        material: String,
        texture: TextureId,
    },
    #[error("texture coordinates of triangle {0} are not finite")]
    UvNotFinite(usize),
    #[error("the textures take {0} bytes, more than the {max} a scene may hold", max = texture::MAX_TEXTURE_BYTES)]
    TextureBytes(usize),
    #[error("normal {0} is not unit length")]
    NormalNotUnit(usize),
    #[error("vertex {vertex}: {bound}")]
    OutOfBounds { vertex: usize, bound: OutOfBounds },
}

impl Scene {
    /// The three corner positions of triangle `id`.
    pub fn triangle_positions(&self, id: TriangleId) -> [Vec3; 3] {
        let t = &self.triangles[id.index()];
        t.vertices.map(|v| self.positions[v as usize])
    }

    /// The three corner normals of triangle `id`.
    pub fn triangle_normals(&self, id: TriangleId) -> [Vec3; 3] {
        let t = &self.triangles[id.index()];
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
        &self.materials[self.triangles[id.index()].material.index()]
    }

    /// The material of triangle `id` at the point with barycentric
    /// `weights` (of its corners), with its textures applied: the base
    /// colour multiplies `diffuse` and `ambient`, the alpha map the opacity
    /// `1 - transmittance`. `footprint` is the width in metres of one pixel
    /// on the surface there (0: the finest mip level); the mip level is
    /// where one footprint covers one texel. An untextured material is
    /// borrowed as it is.
    ///
    /// Every shading path (rasterized base frame, thin-glass transmission,
    /// traced shading) textures through this one function.
    pub fn textured_material(
        &self,
        id: TriangleId,
        weights: Vec3,
        footprint: f32,
    ) -> Cow<'_, Material> {
        let material = self.material_of(id);
        let Some(corners) = self.corner_uvs.get(id.index()) else {
            return Cow::Borrowed(material);
        };
        if !material.is_textured() {
            return Cow::Borrowed(material);
        }
        let uv = corners[0] * weights.x + corners[1] * weights.y + corners[2] * weights.z;
        let lod = |texture: &Texture| {
            if footprint <= 0.0 {
                return 0.0;
            }
            let [a, b, c] = self.triangle_positions(id);
            let world_area = (b - a).cross(c - a).length() * 0.5;
            let [p, q, r] = *corners;
            let uv_area = ((q - p).perp_dot(r - p) * 0.5).abs();
            Texture::lod(footprint * texture::texel_scale(uv_area, world_area, texture))
        };
        let mut textured = material.clone();
        if let Some(texture) = material
            .diffuse_texture
            .and_then(|t| self.textures.get(t as usize))
        {
            let colour = texture.sample(uv, lod(texture)).truncate();
            textured.diffuse *= colour;
            textured.ambient *= colour;
        }
        if let Some(texture) = material
            .alpha_texture
            .and_then(|t| self.textures.get(t as usize))
        {
            let alpha = texture.sample_alpha(uv, lod(texture));
            textured.transmittance = Vec3::ONE - (Vec3::ONE - material.transmittance) * alpha;
        }
        Cow::Owned(textured)
    }

    /// The barycentric weights of `point` (on or near the plane of triangle
    /// `id`) with respect to its corners; the centroid's for a degenerate
    /// triangle.
    pub fn barycentrics(&self, id: TriangleId, point: Vec3) -> Vec3 {
        let [a, b, c] = self.triangle_positions(id);
        let normal = (b - a).cross(c - a);
        let area2 = normal.length_squared();
        if area2.is_nan() || area2 <= 0.0 {
            return Vec3::splat(1.0 / 3.0);
        }
        let wb = (point - a).cross(c - a).dot(normal) / area2;
        let wc = (b - a).cross(point - a).dot(normal) / area2;
        Vec3::new(1.0 - wb - wc, wb, wc)
    }

    /// The ids of all triangles, in order.
    pub fn triangle_ids(&self) -> impl DoubleEndedIterator<Item = TriangleId> + ExactSizeIterator {
        TriangleId::range(self.triangles.len())
    }

    /// The ids of the triangles of `object`, in order.
    pub fn triangles_of(&self, object: ObjectId) -> impl Iterator<Item = TriangleId> + '_ {
        self.triangle_ids()
            .filter(move |t| self.triangles[t.index()].object == object)
    }

    /// Looks up an object by name.
    pub fn object_id(&self, name: &str) -> Option<ObjectId> {
        self.objects
            .iter()
            .position(|o| o.name == name)
            .map(|i| ObjectId(i as u32))
    }

    /// Looks up a material by name.
    pub fn material_id(&self, name: &str) -> Option<MaterialId> {
        self.materials
            .iter()
            .position(|m| m.name == name)
            .map(|i| MaterialId(i as u32))
    }

    /// The axis-aligned bounds (min, max) of all vertices.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        )
    }

    /// Appends the parallelogram `corner + s·u + t·v` (s, t in 0..1) as a
    /// new object named `name` with `material` of its own: two triangles
    /// with the flat normal `u × v`. For scenes built in code (tests,
    /// examples). Returns the two triangles' ids.
    pub fn append_quad(
        &mut self,
        name: &str,
        material: Material,
        corner: Vec3,
        u: Vec3,
        v: Vec3,
    ) -> [TriangleId; 2] {
        let first = TriangleId(self.triangles.len() as u32);
        let n = u.cross(v).normalize();
        let triangle = |vertices| Triangle {
            vertices,
            object: ObjectId(0),
            material: MaterialId(0),
        };
        self.append(&Scene {
            positions: vec![corner, corner + u, corner + u + v, corner + v],
            normals: vec![n; 4],
            triangles: vec![triangle([0, 1, 2]), triangle([0, 2, 3])],
            objects: vec![Object { name: name.into() }],
            materials: vec![material],
            ..Default::default()
        });
        [first, TriangleId(first.0 + 1)]
    }

    /// Appends another scene's content, remapping its indices.
    pub fn append(&mut self, other: &Scene) {
        let v0 = self.positions.len() as u32;
        let o0 = self.objects.len() as u32;
        let m0 = self.materials.len() as u32;
        let t0 = self.textures.len() as TextureId;
        if !(self.corner_uvs.is_empty() && other.corner_uvs.is_empty()) {
            self.corner_uvs
                .resize(self.triangles.len(), [Vec2::ZERO; 3]);
            self.corner_uvs.extend_from_slice(&other.corner_uvs);
            self.corner_uvs.resize(
                self.triangles.len() + other.triangles.len(),
                [Vec2::ZERO; 3],
            );
        }
        self.textures.extend(other.textures.iter().cloned());
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.objects.extend(other.objects.iter().cloned());
        self.materials
            .extend(other.materials.iter().map(|m| Material {
                diffuse_texture: m.diffuse_texture.map(|t| t + t0),
                alpha_texture: m.alpha_texture.map(|t| t + t0),
                ..m.clone()
            }));
        self.triangles
            .extend(other.triangles.iter().map(|t| Triangle {
                vertices: t.vertices.map(|v| v + v0),
                object: ObjectId(t.object.0 + o0),
                material: MaterialId(t.material.0 + m0),
            }));
    }

    /// Checks the structural invariants: indices in range, one normal per
    /// position, unit normals, every position within [`MAX_COORDINATE`]
    /// (the BVH build relies on it), corner texture coordinates for every
    /// triangle or none, and the textures within
    /// [`texture::MAX_TEXTURE_BYTES`]. Returns the first violation.
    pub fn validate(&self) -> Result<(), SceneError> {
        if self.positions.len() != self.normals.len() {
            return Err(SceneError::NormalCount {
                positions: self.positions.len(),
                normals: self.normals.len(),
            });
        }
        if !self.corner_uvs.is_empty() && self.corner_uvs.len() != self.triangles.len() {
            return Err(SceneError::UvCount {
                triangles: self.triangles.len(),
                uvs: self.corner_uvs.len(),
            });
        }
        for (i, t) in self.triangles.iter().enumerate() {
            if t.vertices
                .iter()
                .any(|&v| v as usize >= self.positions.len())
            {
                return Err(SceneError::MissingVertex(i));
            }
            if t.object.index() >= self.objects.len() {
                return Err(SceneError::MissingObject {
                    triangle: i,
                    object: t.object,
                });
            }
            if t.material.index() >= self.materials.len() {
                return Err(SceneError::MissingMaterial {
                    triangle: i,
                    material: t.material,
                });
            }
        }
        if let Some(i) = (self.corner_uvs.iter()).position(|c| !c.iter().all(|uv| uv.is_finite())) {
            return Err(SceneError::UvNotFinite(i));
        }
        for m in &self.materials {
            for texture in [m.diffuse_texture, m.alpha_texture].into_iter().flatten() {
                if texture as usize >= self.textures.len() {
                    return Err(SceneError::MissingTexture {
                        material: m.name.clone(),
                        texture,
                    });
                }
            }
        }
        let bytes: usize = self.textures.iter().map(|t| t.rgba8().len()).sum();
        if bytes > texture::MAX_TEXTURE_BYTES {
            return Err(SceneError::TextureBytes(bytes));
        }
        if let Some(i) = self
            .normals
            .iter()
            .position(|n| (n.length() - 1.0).abs().is_nan() || (n.length() - 1.0).abs() > 1e-3)
        {
            return Err(SceneError::NormalNotUnit(i));
        }
        for (i, &p) in self.positions.iter().enumerate() {
            bounds::point("position", p)
                .map_err(|bound| SceneError::OutOfBounds { vertex: i, bound })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_triangle_prints_as_its_number_and_indexes_its_scene() {
        let mut scene = Scene::default();
        let white = Material::default();
        let first = scene.append_quad("floor", white.clone(), Vec3::ZERO, Vec3::X, Vec3::Z);
        let second = scene.append_quad("wall", white, Vec3::ZERO, Vec3::X, Vec3::Y);
        assert_eq!(first, [TriangleId(0), TriangleId(1)]);
        assert_eq!(second, [TriangleId(2), TriangleId(3)]);
        assert_eq!(second[1].to_string(), "3");
        assert_eq!(second[1].raw(), 3);
        assert!(scene.triangle_ids().eq(first.into_iter().chain(second)));
        let wall = scene.object_id("wall").unwrap();
        assert_eq!(scene.triangles[second[0].index()].object, wall);
        assert!(scene.triangles_of(wall).eq(second));
        assert_eq!(scene.triangle_positions(second[1])[2], Vec3::Y);
        assert_eq!(TriangleId::from_raw(3), Some(second[1]));
        assert_eq!(TriangleId::from_raw(NONE), None);
        // Each quad brings its own material, numbered after the scene's.
        assert_eq!(scene.triangles[second[0].index()].material, MaterialId(1));
        assert_eq!(MaterialId(1).to_string(), "1");
    }
}
