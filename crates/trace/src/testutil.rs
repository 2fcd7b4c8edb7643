//! Test helpers: the seeded test generator and a small scene builder.

use glam::Vec3;
use rand::{Rng, RngCore, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use vtfarm_scene::{Material, MaterialId, Object, ObjectId, Scene, Triangle};

/// Seeded test inputs: the workspace's one test generator
/// (`rand_xoshiro`'s xoshiro256++, a reproducible stream per seed) with the
/// shapes these tests draw.
pub(crate) struct TestRng(Xoshiro256PlusPlus);

impl TestRng {
    pub(crate) fn new(seed: u64) -> Self {
        TestRng(Xoshiro256PlusPlus::seed_from_u64(seed))
    }

    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// Uniform in [0, 1).
    pub(crate) fn unit(&mut self) -> f32 {
        self.0.random()
    }

    /// Uniform in [lo, hi).
    pub(crate) fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    pub(crate) fn vec3(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }

    /// A uniformly random unit vector.
    pub(crate) fn direction(&mut self) -> Vec3 {
        loop {
            let v = self.vec3(-1.0, 1.0);
            let len2 = v.length_squared();
            if len2 > 1e-4 && len2 <= 1.0 {
                return v / len2.sqrt();
            }
        }
    }
}

/// A material that only emits `color` (no ambient or diffuse response), so
/// whatever sees it sees exactly `color`.
pub(crate) fn emitter(name: &str, color: Vec3) -> Material {
    Material {
        emission: color,
        ..Material::diffuse(name, Vec3::ZERO)
    }
}

/// A perfect mirror: kr = 1, no local response.
pub(crate) fn mirror(name: &str) -> Material {
    Material {
        reflectance: Vec3::ONE,
        ..Material::diffuse(name, Vec3::ZERO)
    }
}

/// Clear glass: kt = 1, no local response, no mirror term.
pub(crate) fn glass(name: &str, ior: f32) -> Material {
    Material {
        transmittance: Vec3::ONE,
        ior,
        ..Material::diffuse(name, Vec3::ZERO)
    }
}

/// Builds scenes object by object; every object gets its own material.
#[derive(Default)]
pub(crate) struct SceneBuilder {
    pub(crate) scene: Scene,
}

impl SceneBuilder {
    /// Starts a new object with its own material; returns the object id.
    fn object(&mut self, material: Material) -> (ObjectId, MaterialId) {
        let object = ObjectId(self.scene.objects.len() as u32);
        self.scene.objects.push(Object {
            name: format!("{}#{object}", material.name),
        });
        let material_id = MaterialId(self.scene.materials.len() as u32);
        self.scene.materials.push(material);
        (object, material_id)
    }

    fn vertex(&mut self, position: Vec3, normal: Vec3) -> u32 {
        self.scene.positions.push(position);
        self.scene.normals.push(normal.normalize());
        self.scene.positions.len() as u32 - 1
    }

    /// Loose triangles (flat normals; degenerate ones get +Y).
    pub(crate) fn triangles(&mut self, material: Material, corners: &[[Vec3; 3]]) -> ObjectId {
        let (object, material) = self.object(material);
        for &[a, b, c] in corners {
            let n = (b - a).cross(c - a).try_normalize().unwrap_or(Vec3::Y);
            let vertices = [self.vertex(a, n), self.vertex(b, n), self.vertex(c, n)];
            self.scene.triangles.push(Triangle {
                vertices,
                object,
                material,
            });
        }
        object
    }

    /// A parallelogram `corner + s * edge_u + t * edge_v`, s, t in [0, 1],
    /// facing `edge_u x edge_v`.
    pub(crate) fn quad(
        &mut self,
        material: Material,
        corner: Vec3,
        edge_u: Vec3,
        edge_v: Vec3,
    ) -> ObjectId {
        let [a, b, c, d] = [
            corner,
            corner + edge_u,
            corner + edge_u + edge_v,
            corner + edge_v,
        ];
        self.triangles(material, &[[a, b, c], [a, c, d]])
    }

    /// A square of half size `half` centred at `centre`, facing `normal`.
    pub(crate) fn square(
        &mut self,
        material: Material,
        centre: Vec3,
        normal: Vec3,
        half: f32,
    ) -> ObjectId {
        let (u, v) = normal.normalize().any_orthonormal_pair();
        self.quad(
            material,
            centre - (u + v) * half,
            u * 2.0 * half,
            v * 2.0 * half,
        )
    }

    /// An icosphere with smooth (radial) vertex normals, `subdivisions` times
    /// split from the icosahedron, outward-facing.
    pub(crate) fn icosphere(
        &mut self,
        material: Material,
        centre: Vec3,
        radius: f32,
        subdivisions: u32,
    ) -> ObjectId {
        let (object, material) = self.object(material);
        let (points, faces) = vtfarm_scene::shapes::icosphere(subdivisions);
        let base = self.scene.positions.len() as u32;
        for &unit in &points {
            self.vertex(centre + unit * radius, unit);
        }
        for face in faces {
            let vertices = face.map(|i| base + i);
            self.scene.triangles.push(Triangle {
                vertices,
                object,
                material,
            });
        }
        object
    }
}
