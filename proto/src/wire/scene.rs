//! The scene, its camera and its lights on the wire ([`WireScene`],
//! [`WireCamera`], [`WireLighting`]): mirrors of `vtfarm-scene`'s types.

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use vtfarm_scene::{
    Camera, Light, LightKind, Lighting, Material, Object, Scene, Texture, Triangle,
};

use super::{WireError, bounds, finite, finite3, index, vec3};

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
    pub thin: bool,
    pub fresnel: bool,
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
            thin: m.thin,
            fresnel: m.fresnel,
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
            thin: m.thin,
            fresnel: m.fresnel,
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
                    object: t.object.raw(),
                    material: t.material.raw(),
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
                    object: vtfarm_scene::ObjectId(t.object),
                    material: vtfarm_scene::MaterialId(t.material),
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

/// [`LightKind`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum WireLightKind {
    Point {
        position: [f32; 3],
    },
    Directional {
        direction: [f32; 3],
        angular_diameter_deg: f32,
    },
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
                LightKind::Directional {
                    direction,
                    angular_diameter_deg,
                } => WireLightKind::Directional {
                    direction: vec3(direction),
                    angular_diameter_deg,
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
                WireLightKind::Directional {
                    direction,
                    angular_diameter_deg,
                } => LightKind::Directional {
                    direction: Vec3::from_array(direction),
                    angular_diameter_deg,
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

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use vtfarm_scene::{Camera, Light, Lighting, MAX_IMAGE_SIDE, Material, Scene};

    use super::*;
    use crate::wire::tests::{
        any_f32, camera, check_rejects, lighting, material, round_trip, scene,
    };

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
        // Finite but absurd: obvhs' build overflows on it.
        check(
            |s| s.positions[3][0] = 1e22,
            "vertex 3: position = [10000000000000000000000, 1, -0.5]: must be finite and within ±1e6 m",
        );
    }

    #[test]
    fn hostile_cameras_and_lights_are_rejected() {
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
                    angular_diameter_deg: 0.53,
                }
            },
            "light direction",
        );
        check_rejects::<WireLight, Light>(
            &light,
            |l| {
                l.kind = WireLightKind::Directional {
                    direction: [0.0, -1.0, 0.0],
                    angular_diameter_deg: f32::NAN,
                }
            },
            "light angular_diameter_deg",
        );
        check_rejects::<WireLight, Light>(&light, |l| l.intensity = f32::NAN, "light intensity");
        check_rejects::<WireLighting, Lighting>(
            &WireLighting::from(&lighting()),
            |l| l.lights = vec![light; Lighting::MAX_LIGHTS + 1],
            "lights = 65",
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

    proptest! {
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
                materials: vec![WireMaterial::from(&Material::default())],
                ..Default::default()
            };
            if let Ok(scene) = Scene::try_from(wire) {
                prop_assert!(scene.validate().is_ok());
            }
        }
    }
}
