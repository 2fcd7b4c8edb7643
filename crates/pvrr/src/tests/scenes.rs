//! Hand-built test scenes: a lit room of coloured walls, spherical mirror
//! caps, a biconvex lens and an emissive colour-gradient backdrop.

use glam::Vec3;
use vtfarm_scene::{
    Camera, Light, LightKind, Lighting, Material, MaterialId, Object, ObjectId, Scene, Triangle,
    TriangleId,
};

/// A scene under construction.
#[derive(Default)]
pub(super) struct Builder {
    pub(super) scene: Scene,
}

impl Builder {
    /// Adds an object; triangles are rewound so that their geometric normal
    /// agrees with the vertex normals (the tracer's outside).
    pub(super) fn add(
        &mut self,
        name: &str,
        material: Material,
        vertices: &[(Vec3, Vec3)],
        triangles: &[[u32; 3]],
    ) -> Vec<TriangleId> {
        let scene = &mut self.scene;
        let object = ObjectId(scene.objects.len() as u32);
        scene.objects.push(Object {
            name: name.to_owned(),
        });
        let material_id = MaterialId(scene.materials.len() as u32);
        scene.materials.push(material);
        let base = scene.positions.len() as u32;
        for &(p, n) in vertices {
            scene.positions.push(p);
            scene.normals.push(n.normalize());
        }
        let first = scene.triangles.len();
        for &[a, b, c] in triangles {
            let [pa, pb, pc] = [a, b, c].map(|i| vertices[i as usize].0);
            let normal = vertices[a as usize].1 + vertices[b as usize].1 + vertices[c as usize].1;
            let wound = if (pb - pa).cross(pc - pa).dot(normal) >= 0.0 {
                [a, b, c]
            } else {
                [a, c, b]
            };
            scene.triangles.push(Triangle {
                vertices: wound.map(|i| i + base),
                object,
                material: material_id,
            });
        }
        scene.triangle_ids().skip(first).collect()
    }

    /// A square `size` wide centred at `center` with normal `normal`, split
    /// into `n` × `n` cells; `material_of(u, v)` colours cell (u, v) in
    /// [0, 1)² (cells with equal materials still get their own).
    pub(super) fn panel(
        &mut self,
        name: &str,
        center: Vec3,
        normal: Vec3,
        size: f32,
        n: u32,
        material_of: &dyn Fn(f32, f32) -> Material,
    ) {
        let normal = normal.normalize();
        let helper = if normal.y.abs() < 0.9 {
            Vec3::Y
        } else {
            Vec3::X
        };
        let u_axis = helper.cross(normal).normalize();
        let v_axis = normal.cross(u_axis);
        let cell = size / n as f32;
        for i in 0..n {
            for j in 0..n {
                let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
                let corner =
                    center + u_axis * (u * size - size * 0.5) + v_axis * (v * size - size * 0.5);
                let quad = [
                    corner,
                    corner + u_axis * cell,
                    corner + u_axis * cell + v_axis * cell,
                    corner + v_axis * cell,
                ]
                .map(|p| (p, normal));
                let material = material_of(u + 0.5 / n as f32, v + 0.5 / n as f32);
                self.add(name, material, &quad, &[[0, 1, 2], [0, 2, 3]]);
            }
        }
    }

    /// A height field over the square [-half, half]² of the xy plane,
    /// `n` × `n` quads; `surface(x, y)` gives the position and normal.
    pub(super) fn grid(
        &mut self,
        name: &str,
        material: Material,
        n: u32,
        half: f32,
        surface: &dyn Fn(f32, f32) -> (Vec3, Vec3),
    ) -> Vec<TriangleId> {
        let mut vertices = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let x = -half + 2.0 * half * i as f32 / n as f32;
                let y = -half + 2.0 * half * j as f32 / n as f32;
                vertices.push(surface(x, y));
            }
        }
        let mut triangles = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                let (b, c, d) = (a + 1, a + n + 2, a + n + 1);
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
        self.add(name, material, &vertices, &triangles)
    }

    pub(super) fn build(self) -> Scene {
        self.scene.validate().expect("test scenes are valid");
        self.scene
    }
}

/// A sphere of `radius` as a height field over the xy plane: `z(x, y)`
/// measured from the sphere's pole at z = 0 facing `facing` (+1: the pole is
/// the highest point, a convex cap seen from +z; -1: the lowest, concave),
/// with the normal on the +z side.
pub(super) fn spherical(radius: f32, facing: f32) -> impl Fn(f32, f32) -> (Vec3, Vec3) {
    move |x, y| {
        let h = (radius * radius - x * x - y * y).sqrt();
        let z = facing * (h - radius);
        let center = Vec3::new(0.0, 0.0, -facing * radius);
        let p = Vec3::new(x, y, z);
        (p, ((p - center) * facing).normalize())
    }
}

/// A mirror: all reflection, nothing local.
pub(super) fn mirror() -> Material {
    Material {
        name: "mirror".to_owned(),
        reflectance: Vec3::splat(0.9),
        ..Material::diffuse("mirror", Vec3::ZERO)
    }
}

/// Clear glass: all transmission, nothing local or reflected.
pub(super) fn glass(ior: f32) -> Material {
    Material {
        name: "glass".to_owned(),
        transmittance: Vec3::ONE,
        ior,
        ..Material::diffuse("glass", Vec3::ZERO)
    }
}

pub(super) fn emissive(color: Vec3) -> Material {
    Material {
        emission: color,
        ..Material::diffuse("emissive", Vec3::ZERO)
    }
}

/// A closed room [-3, 3]³ of six differently coloured diffuse walls, each
/// split into cells, lit by one point light.
pub(super) fn room(builder: &mut Builder) -> Lighting {
    let walls = [
        (Vec3::X, Vec3::new(0.9, 0.2, 0.2)),
        (Vec3::NEG_X, Vec3::new(0.2, 0.9, 0.2)),
        (Vec3::Y, Vec3::new(0.9, 0.9, 0.9)),
        (Vec3::NEG_Y, Vec3::new(0.5, 0.4, 0.2)),
        (Vec3::Z, Vec3::new(0.2, 0.3, 0.9)),
        (Vec3::NEG_Z, Vec3::new(0.9, 0.8, 0.2)),
    ];
    for (side, color) in walls {
        builder.panel("wall", side * 3.0, -side, 6.0, 6, &|_, _| {
            Material::diffuse("wall", color)
        });
    }
    Lighting {
        lights: vec![Light {
            kind: LightKind::Point {
                position: Vec3::new(1.0, 2.5, 2.0),
            },
            color: Vec3::ONE,
            intensity: 1.0,
        }],
        ambient: Vec3::splat(0.1),
        background: Vec3::ZERO,
    }
}

/// A colour gradient (red along u, green along v) of emissive cells.
pub(super) fn gradient(u: f32, v: f32) -> Material {
    emissive(Vec3::new(u, v, 0.5))
}

pub(super) fn camera(eye: Vec3, target: Vec3, fov_y_deg: f32, size: u32) -> Camera {
    Camera {
        eye,
        target,
        up: Vec3::Y,
        fov_y_deg,
        width: size,
        height: size,
    }
}
