//! The reflected meshes as the search sees them: every scene triangle the
//! reflector mirrors, split into a regular lattice of 4^k sub-triangles
//! when its longest edge exceeds a limit.
//!
//! Only vertices are reflected, so a long edge comes out as the straight
//! line between its reflected ends (the paper's §8 limitation), and a big
//! triangle whose corners lie outside the reflected region (a window panel
//! seen in the glass) would be dropped altogether. Splitting puts vertices
//! where the reflection is. A virtual vertex depends only on its position,
//! so lattice points shared by neighbours of the same level get the same
//! virtual position and the virtual mesh has no cracks there.

use glam::Vec3;
use vtfarm_scene::{ObjectId, Scene, TriangleId};

/// One triangle of the reflected meshes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct MeshTriangle {
    /// The scene triangle it is part of.
    pub(crate) original: TriangleId,
    /// Indices into [`ReflectedMesh::positions`].
    pub(crate) corners: [u32; 3],
    /// Barycentric coordinates of the corners in the original triangle.
    pub(crate) barycentric: [Vec3; 3],
}

/// Vertices (with the object they belong to) and triangles.
#[derive(Clone, Debug, Default)]
pub(crate) struct ReflectedMesh {
    pub(crate) positions: Vec<Vec3>,
    pub(crate) objects: Vec<ObjectId>,
    pub(crate) triangles: Vec<MeshTriangle>,
}

/// Splits stop here: 4^6 = 4096 sub-triangles per scene triangle.
const MAX_LEVEL: u32 = 6;

impl ReflectedMesh {
    /// The triangles `keep` accepts, split until no edge exceeds `max_edge`.
    /// Unsplit corners keep sharing their scene vertex.
    pub(crate) fn build(scene: &Scene, keep: &[bool], max_edge: f32) -> ReflectedMesh {
        let mut mesh = ReflectedMesh::default();
        // Scene vertex -> mesh vertex, assigned on first use.
        let mut shared = vec![u32::MAX; scene.positions.len()];
        for (t, triangle) in scene.triangle_ids().zip(&scene.triangles) {
            if !keep[t.index()] {
                continue;
            }
            let corners = scene.triangle_positions(t);
            let longest = (0..3)
                .map(|k| (corners[k] - corners[(k + 1) % 3]).length())
                .fold(0.0, f32::max);
            let level = if longest > max_edge && max_edge > 0.0 {
                ((longest / max_edge).log2().ceil() as u32).min(MAX_LEVEL)
            } else {
                0
            };
            let n = 1u32 << level;
            let mut lattice = Vec::with_capacity(((n + 1) * (n + 2) / 2) as usize);
            for j in 0..=n {
                for i in 0..=n - j {
                    let w = Vec3::new((n - i - j) as f32, i as f32, j as f32) / n as f32;
                    let corner = match (i, j) {
                        (0, 0) => Some(0),
                        (i, 0) if i == n => Some(1),
                        (0, j) if j == n => Some(2),
                        _ => None,
                    };
                    let index = match corner {
                        Some(k) => {
                            let v = triangle.vertices[k] as usize;
                            if shared[v] == u32::MAX {
                                shared[v] = mesh.push(scene.positions[v], triangle.object);
                            }
                            shared[v]
                        }
                        None => {
                            let p = corners[0] * w.x + corners[1] * w.y + corners[2] * w.z;
                            mesh.push(p, triangle.object)
                        }
                    };
                    lattice.push((index, w));
                }
            }
            // Row j starts after the rows above it, each one shorter.
            let at = |i: u32, j: u32| {
                lattice[(j * (n + 1) - j * (j.saturating_sub(1)) / 2 + i) as usize]
            };
            let mut emit = |a: (u32, Vec3), b: (u32, Vec3), c: (u32, Vec3)| {
                mesh.triangles.push(MeshTriangle {
                    original: t,
                    corners: [a.0, b.0, c.0],
                    barycentric: [a.1, b.1, c.1],
                });
            };
            for j in 0..n {
                for i in 0..n - j {
                    emit(at(i, j), at(i + 1, j), at(i, j + 1));
                    if i + j + 1 < n {
                        emit(at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                    }
                }
            }
        }
        mesh
    }

    fn push(&mut self, position: Vec3, object: ObjectId) -> u32 {
        self.positions.push(position);
        self.objects.push(object);
        self.positions.len() as u32 - 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tests::scenes::{add_object, push};
    use vtfarm_scene::Material;

    #[test]
    fn long_triangles_split_into_a_lattice_that_covers_them() {
        let mut scene = Scene::default();
        let object = add_object(&mut scene, "o", Material::diffuse("m", Vec3::ONE));
        push(
            &mut scene,
            object,
            &[Vec3::ZERO, Vec3::X * 4.0, Vec3::Y * 4.0, Vec3::Z * 0.5],
            &[Vec3::Z; 4],
            &[[0, 1, 2], [0, 3, 1]],
        );
        // Longest edge 5.66 with a limit of 1.5: 2 levels, 16 triangles.
        let mesh = ReflectedMesh::build(&scene, &[true, false], 1.5);
        assert_eq!(mesh.triangles.len(), 16);
        assert_eq!(mesh.positions.len(), 15);
        let area: f32 = mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.corners.map(|k| mesh.positions[k as usize]);
                0.5 * (b - a).cross(c - a).length()
            })
            .sum();
        assert!((area - 8.0).abs() < 1e-4, "{area}");
        for t in &mesh.triangles {
            for k in 0..3 {
                let w = t.barycentric[k];
                let p = Vec3::X * 4.0 * w.y + Vec3::Y * 4.0 * w.z;
                assert!((p - mesh.positions[t.corners[k] as usize]).length() < 1e-5);
            }
        }
        // Short triangles stay whole and share their vertices.
        let whole = ReflectedMesh::build(&scene, &[true, true], 10.0);
        assert_eq!((whole.triangles.len(), whole.positions.len()), (2, 4));
    }
}
