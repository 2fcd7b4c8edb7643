//! Assembles part meshes into a [`Scene`]: named objects, their materials
//! and the material constructors the parts use.

use glam::Vec3;
use vtfarm_scene::{Material, MaterialId, Object, ObjectId, Scene, Triangle, photometry};

use crate::mesh::Mesh;

/// Collects objects into a scene.
#[derive(Debug, Default)]
pub(crate) struct SceneBuilder {
    scene: Scene,
}

impl SceneBuilder {
    /// Registers `material`, or finds the one already registered under its name.
    pub(crate) fn material(&mut self, material: Material) -> MaterialId {
        if let Some(id) = self.scene.material_id(&material.name) {
            debug_assert_eq!(
                self.scene.materials[id.index()],
                material,
                "two materials named {}",
                material.name
            );
            return id;
        }
        self.scene.materials.push(material);
        MaterialId(self.scene.materials.len() as u32 - 1)
    }

    /// Starts a new object; names must be unique.
    pub(crate) fn object(&mut self, name: &str) -> ObjectId {
        assert!(
            self.scene.object_id(name).is_none(),
            "object {name} added twice"
        );
        self.scene.objects.push(Object {
            name: name.to_owned(),
        });
        ObjectId(self.scene.objects.len() as u32 - 1)
    }

    /// Adds `mesh` to `object` with `material`.
    pub(crate) fn push(&mut self, object: ObjectId, material: MaterialId, mesh: &Mesh) {
        let base = self.scene.positions.len() as u32;
        self.scene.positions.extend_from_slice(&mesh.positions);
        self.scene.normals.extend_from_slice(&mesh.normals);
        self.scene
            .triangles
            .extend(mesh.triangles.iter().map(|t| Triangle {
                vertices: t.map(|v| v + base),
                object,
                material,
            }));
    }

    /// Adds a whole object made of one mesh and one material.
    pub(crate) fn add(&mut self, name: &str, material: Material, mesh: &Mesh) {
        let material = self.material(material);
        let object = self.object(name);
        self.push(object, material, mesh);
    }

    pub(crate) fn finish(self) -> Scene {
        self.scene
    }
}

/// A plain diffuse material.
pub(crate) fn matte(name: &str, color: Vec3) -> Material {
    Material::diffuse(name, color)
}

/// A diffuse material with a Phong highlight (plastics, leather).
pub(crate) fn glossy(name: &str, color: Vec3, specular: f32, shininess: f32) -> Material {
    Material {
        specular: Vec3::splat(specular),
        shininess,
        ..Material::diffuse(name, color)
    }
}

/// A surface that only emits, with the hue of `color` and the luminance
/// `cd_m2` (windows' outside panels and lamps), unaffected by the lights.
pub(crate) fn emitter(name: &str, color: Vec3, cd_m2: f32) -> Material {
    backlit(name, Vec3::ZERO, color, cd_m2)
}

/// A diffuse surface of reflectance `diffuse` that also emits `cd_m2` in the
/// hue of `color` (backlit dial faces and markings: lit from behind, and
/// reflecting the cab's light like any print).
pub(crate) fn backlit(name: &str, diffuse: Vec3, color: Vec3, cd_m2: f32) -> Material {
    Material {
        emission: photometry::emission(color, cd_m2)
            .expect("the cockpit's emitters have colours with luminance"),
        ..Material::diffuse(name, diffuse)
    }
}
