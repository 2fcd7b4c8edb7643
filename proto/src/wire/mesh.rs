//! A progressive frame's reflector meshes after a stage (`WireMesh`): what
//! a worker sends with its `preview` and `refine` results so that the
//! dashboard's view can draw the reflection as the meshes' vertex colours.

use glam::Vec3;
use serde::{Deserialize, Serialize};
use vtfarm_vertex::{PixelValue, SlabWeights, StageMesh};

use crate::wire::WireError;

/// The refinement meshes of a package's triangles after one stage, one
/// part per triangle that owns pixels (a frame's corner mesh: one per
/// reflector triangle).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WireMesh {
    pub parts: Vec<WireMeshPart>,
}

/// One reflector triangle's mesh ([`StageMesh`]): per vertex its world
/// position and traced sample, then the faces.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WireMeshPart {
    pub triangle: u32,
    pub positions: Vec<[f32; 3]>,
    pub colors: Vec<[f32; 3]>,
    pub reflected: Vec<[f32; 3]>,
    pub transmitted: Vec<[f32; 3]>,
    pub objects: Vec<u32>,
    /// Per vertex, its [`SlabWeights`]: what of the scene behind shows
    /// through, and the factor on the reflection.
    pub behind: Vec<[f32; 3]>,
    pub reflection_scale: Vec<f32>,
    pub faces: Vec<[u32; 3]>,
}

impl From<&[StageMesh]> for WireMesh {
    fn from(meshes: &[StageMesh]) -> Self {
        let parts = meshes.iter().map(|m| {
            let per_vertex = |f: fn(&PixelValue) -> Vec3| -> Vec<[f32; 3]> {
                m.samples.iter().map(|s| f(s).to_array()).collect()
            };
            WireMeshPart {
                triangle: m.triangle.raw(),
                positions: m.positions.iter().map(|p| p.to_array()).collect(),
                colors: per_vertex(|s| s.color),
                reflected: per_vertex(|s| s.reflected),
                transmitted: per_vertex(|s| s.transmitted),
                objects: m.samples.iter().map(|s| s.object).collect(),
                behind: m.slabs.iter().map(|s| s.behind.to_array()).collect(),
                reflection_scale: m.slabs.iter().map(|s| s.reflection_scale).collect(),
                faces: m.faces.clone(),
            }
        });
        WireMesh {
            parts: parts.collect(),
        }
    }
}

impl WireMesh {
    /// The meshes, checked: every per-vertex list as long as the
    /// positions, every face's indices among them, positions finite.
    pub fn decode(&self) -> Result<Vec<StageMesh>, WireError> {
        self.parts.iter().map(WireMeshPart::decode).collect()
    }
}

impl WireMeshPart {
    fn decode(&self) -> Result<StageMesh, WireError> {
        let n = self.positions.len();
        let lists = [
            ("mesh colors", self.colors.len()),
            ("mesh reflected", self.reflected.len()),
            ("mesh transmitted", self.transmitted.len()),
            ("mesh objects", self.objects.len()),
            ("mesh behind", self.behind.len()),
            ("mesh reflection_scale", self.reflection_scale.len()),
        ];
        for (field, actual) in lists {
            if actual != n {
                return Err(WireError::SizeMismatch {
                    field: field.to_owned(),
                    expected: n as u64,
                    actual: actual as u64,
                });
            }
        }
        let finite = [
            (
                "mesh positions",
                self.positions.iter().flatten().all(|v| v.is_finite()),
            ),
            (
                "mesh behind",
                self.behind.iter().flatten().all(|v| v.is_finite()),
            ),
            (
                "mesh reflection_scale",
                self.reflection_scale.iter().all(|v| v.is_finite()),
            ),
        ];
        if let Some((field, _)) = finite.iter().find(|(_, finite)| !finite) {
            return Err(WireError::NotFinite {
                field: (*field).to_owned(),
            });
        }
        if let Some(&index) = self.faces.iter().flatten().find(|&&v| v as usize >= n) {
            return Err(WireError::IndexOutOfRange {
                field: "mesh faces".to_owned(),
                index: index.into(),
                len: n as u64,
            });
        }
        let samples = (0..n).map(|k| PixelValue {
            index: 0,
            color: Vec3::from(self.colors[k]),
            reflected: Vec3::from(self.reflected[k]),
            transmitted: Vec3::from(self.transmitted[k]),
            object: self.objects[k],
        });
        let slabs = (0..n).map(|k| SlabWeights {
            behind: Vec3::from(self.behind[k]),
            reflection_scale: self.reflection_scale[k],
        });
        Ok(StageMesh {
            triangle: vtfarm_scene::TriangleId(self.triangle),
            positions: self.positions.iter().map(|&p| Vec3::from(p)).collect(),
            samples: samples.collect(),
            slabs: slabs.collect(),
            faces: self.faces.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part() -> WireMeshPart {
        WireMeshPart {
            triangle: 7,
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            colors: vec![[0.5; 3]; 3],
            reflected: vec![[0.25; 3]; 3],
            transmitted: vec![[0.0; 3]; 3],
            objects: vec![1, 2, u32::MAX],
            behind: vec![[0.7; 3], [0.6; 3], [0.0; 3]],
            reflection_scale: vec![1.5, 1.25, 1.0],
            faces: vec![[0, 1, 2]],
        }
    }

    #[test]
    fn a_mesh_decodes_to_the_meshes_it_was_made_of() {
        let mesh = WireMesh {
            parts: vec![part()],
        };
        let decoded = mesh.decode().unwrap();
        assert_eq!(WireMesh::from(&decoded[..]), mesh);
    }

    #[test]
    fn a_mesh_with_short_lists_or_faces_out_of_range_is_refused() {
        let short = WireMesh {
            parts: vec![WireMeshPart {
                objects: vec![1],
                ..part()
            }],
        };
        assert!(matches!(
            short.decode(),
            Err(WireError::SizeMismatch {
                expected: 3,
                actual: 1,
                ..
            })
        ));
        let outside = WireMesh {
            parts: vec![WireMeshPart {
                faces: vec![[0, 1, 3]],
                ..part()
            }],
        };
        assert!(matches!(
            outside.decode(),
            Err(WireError::IndexOutOfRange {
                index: 3,
                len: 3,
                ..
            })
        ));
        let infinite = WireMesh {
            parts: vec![WireMeshPart {
                positions: vec![[f32::INFINITY, 0.0, 0.0], [0.0; 3], [0.0; 3]],
                ..part()
            }],
        };
        assert!(matches!(
            infinite.decode(),
            Err(WireError::NotFinite { .. })
        ));
        let not_a_number = WireMesh {
            parts: vec![WireMeshPart {
                reflection_scale: vec![1.0, f32::NAN, 1.0],
                ..part()
            }],
        };
        assert!(matches!(
            not_a_number.decode(),
            Err(WireError::NotFinite { field }) if field == "mesh reflection_scale"
        ));
    }
}
