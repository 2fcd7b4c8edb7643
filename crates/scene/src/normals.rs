//! Vertex normals: angle-weighted smoothing with a crease angle.
//!
//! [`compute_normals`] gives every triangle corner the normal of the faces
//! around that corner's position that lie within the crease angle of the
//! corner's own face, each weighted by its corner angle (so a normal does not
//! depend on how a flat region happens to be tessellated). Corners whose
//! normals come out equal share one output vertex; corners on hard edges get
//! their own copies. A cube therefore ends up with 24 vertices carrying face
//! normals, while a finely tessellated sphere stays smooth.
//!
//! Vertices are identified by *position*, not by index, so meshes whose
//! vertices were duplicated for other reasons (UV seams, per-material splits in
//! an OBJ file) still smooth across those seams.
//!
//! No output normal is ever NaN: a degenerate (zero-area) face takes the
//! smoothed normal of its neighbours, and a corner with no usable face at all
//! falls back to +Y.

use std::collections::{BTreeMap, HashMap};

use glam::Vec3;

use crate::{ObjectId, Scene};

/// Crease angle used when the caller has no preference: faces meeting at more
/// than 40 degrees form a hard edge.
pub const DEFAULT_CREASE_ANGLE_DEG: f32 = 40.0;

/// Normal given to corners that have no non-degenerate face to take one from.
const FALLBACK_NORMAL: Vec3 = Vec3::Y;

/// Slack on the crease test so that coplanar faces, whose computed normals
/// differ by rounding, still smooth together at a crease angle of 0.
const CREASE_COS_SLACK: f32 = 1e-6;

/// Computes angle-weighted vertex normals with a crease angle.
///
/// `triangles` index `positions` (counter-clockwise winding gives the normal
/// direction). Returns `(positions, normals, triangles)`: new vertex arrays of
/// equal length, with unit normals, and the triangles re-indexed into them, in
/// the same order and number as the input. Output vertices appear in order of
/// first use by the triangles; unused input vertices are dropped.
///
/// A corner's normal averages the faces around its position whose normals
/// differ from its own face's by at most `crease_angle_deg` (clamped to
/// 0..=180): 0 gives flat shading, 180 smooths everything.
///
/// # Panics
///
/// If a triangle indexes past the end of `positions`.
pub fn compute_normals(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    crease_angle_deg: f32,
) -> (Vec<Vec3>, Vec<Vec3>, Vec<[u32; 3]>) {
    let corners: Vec<[Vec3; 3]> = triangles
        .iter()
        .map(|t| t.map(|v| positions[v as usize]))
        .collect();
    let faces: Vec<Vec3> = corners.iter().map(|&c| face_normal(c)).collect();

    // Weld corners by position: `welded[3 * face + corner]` is a position id.
    let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
    let welded: Vec<u32> = corners
        .iter()
        .flatten()
        .map(|&p| {
            let next = ids.len() as u32;
            *ids.entry(position_key(p)).or_insert(next)
        })
        .collect();

    // The non-degenerate faces around each position, with their corner angle
    // there. A non-degenerate face has three distinct positions, so it is
    // listed at most once per position.
    let mut around: Vec<Vec<(usize, f32)>> = vec![Vec::new(); ids.len()];
    for (f, c) in corners.iter().enumerate() {
        if faces[f] != Vec3::ZERO {
            let angles = corner_angles(*c);
            for k in 0..3 {
                around[welded[3 * f + k] as usize].push((f, angles[k]));
            }
        }
    }

    let crease = crease_angle_deg.clamp(0.0, 180.0).to_radians();
    let cos_crease = crease.cos() - CREASE_COS_SLACK;
    let cores = Cores::new(&around, &faces, crease);
    let mut out_positions = Vec::new();
    let mut out_normals = Vec::new();
    let mut out_ids: HashMap<(u32, [u32; 3]), u32> = HashMap::new();
    let out_triangles = corners
        .iter()
        .enumerate()
        .map(|(f, c)| {
            let own = faces[f];
            std::array::from_fn(|k| {
                let w = welded[3 * f + k];
                // A degenerate face has no direction of its own: it takes
                // all its neighbours.
                let sum = cores.sum(w as usize, own, &faces, cos_crease);
                let sum: Vec3 = sum.unwrap_or_else(|| {
                    around[w as usize]
                        .iter()
                        .filter(|&&(g, _)| own == Vec3::ZERO || own.dot(faces[g]) >= cos_crease)
                        .map(|&(g, angle)| faces[g] * angle)
                        .sum()
                });
                let fallback = if own == Vec3::ZERO {
                    FALLBACK_NORMAL
                } else {
                    own
                };
                let normal = sum.normalize_or(fallback);
                *out_ids
                    .entry((w, normal.to_array().map(f32::to_bits)))
                    .or_insert_with(|| {
                        out_positions.push(c[k]);
                        out_normals.push(normal);
                        out_normals.len() as u32 - 1
                    })
            })
        })
        .collect();
    (out_positions, out_normals, out_triangles)
}

/// Angle (radians) kept clear of the half crease angle in [`Cores::new`]:
/// covers the rounding of a dot product near 1 seen through `acos`.
const CORE_MARGIN: f32 = 1e-3;

/// The faces around each position split into a *core*, all within half the
/// crease angle of their mean direction (so any two of them are within the
/// crease angle of each other), and the outliers. A corner whose own face is
/// in the core takes the core's sum, computed once, plus the outliers within
/// its crease angle: a position shared by `k` faces (the centre of a big
/// polygon's fan, slivers included) costs O(k · outliers) instead of O(k²).
struct Cores {
    cos_half: f32,
    /// Per position: the core's mean direction and weighted sum (none when
    /// the crease angle is too small for a core).
    core: Vec<Option<(Vec3, Vec3)>>,
    outliers: Vec<Vec<(usize, f32)>>,
}

impl Cores {
    fn new(around: &[Vec<(usize, f32)>], faces: &[Vec3], crease: f32) -> Cores {
        let cos_half = (crease * 0.5 - CORE_MARGIN).cos();
        let mut core = Vec::with_capacity(around.len());
        let mut outliers = Vec::with_capacity(around.len());
        for here in around {
            let mean = here
                .iter()
                .map(|&(g, _)| faces[g])
                .sum::<Vec3>()
                .normalize_or_zero();
            if crease * 0.5 <= CORE_MARGIN || mean == Vec3::ZERO {
                core.push(None);
                outliers.push(Vec::new());
                continue;
            }
            let (inside, outside): (Vec<_>, Vec<_>) = here
                .iter()
                .partition(|&&(g, _)| mean.dot(faces[g]) >= cos_half);
            let sum = inside.iter().map(|&(g, angle)| faces[g] * angle).sum();
            core.push(Some((mean, sum)));
            outliers.push(outside);
        }
        Cores {
            cos_half,
            core,
            outliers,
        }
    }

    /// The sum for a corner at position `w` whose own face has normal `own`
    /// (zero: degenerate, takes every face), if its face is in the core.
    fn sum(&self, w: usize, own: Vec3, faces: &[Vec3], cos_crease: f32) -> Option<Vec3> {
        let (mean, sum) = self.core[w]?;
        if own != Vec3::ZERO && mean.dot(own) < self.cos_half {
            return None;
        }
        let extra: Vec3 = self.outliers[w]
            .iter()
            .filter(|&&(g, _)| own == Vec3::ZERO || own.dot(faces[g]) >= cos_crease)
            .map(|&(g, angle)| faces[g] * angle)
            .sum();
        Some(sum + extra)
    }
}

/// Recomputes all of `scene`'s normals with [`compute_normals`], smoothing
/// within each object only (separate objects never smooth together, even
/// where they touch). Triangles keep their order, object and material;
/// vertices are renumbered and unused ones dropped.
///
/// # Panics
///
/// If a triangle indexes a missing vertex.
pub fn compute_scene_normals(scene: &mut Scene, crease_angle_deg: f32) {
    scene.normals.resize(scene.positions.len(), FALLBACK_NORMAL);
    let all = vec![true; scene.triangles.len()];
    smooth_selected(scene, &all, crease_angle_deg);
    compact_vertices(scene);
}

/// Builds normals for a scene that has none (`normals` empty or not one per
/// position) with [`compute_scene_normals`]; returns whether it did.
pub fn ensure_normals(scene: &mut Scene, crease_angle_deg: f32) -> bool {
    if scene.normals.len() == scene.positions.len() {
        return false;
    }
    compute_scene_normals(scene, crease_angle_deg);
    true
}

/// Gives the triangles with `selected[i]` set freshly computed normals, per
/// object, appending the new vertices; the vertices they used before are left
/// in place (call [`compact_vertices`] to drop them). `scene.normals` must
/// have one entry per position.
pub(crate) fn smooth_selected(scene: &mut Scene, selected: &[bool], crease_angle_deg: f32) {
    let mut by_object: BTreeMap<ObjectId, Vec<usize>> = BTreeMap::new();
    for (i, t) in scene.triangles.iter().enumerate() {
        if selected.get(i).copied().unwrap_or(false) {
            by_object.entry(t.object).or_default().push(i);
        }
    }
    for ids in by_object.values() {
        let triangles: Vec<[u32; 3]> = ids.iter().map(|&i| scene.triangles[i].vertices).collect();
        let (positions, normals, triangles) =
            compute_normals(&scene.positions, &triangles, crease_angle_deg);
        let base = scene.positions.len() as u32;
        scene.positions.extend(positions);
        scene.normals.extend(normals);
        for (&i, t) in ids.iter().zip(triangles) {
            scene.triangles[i].vertices = t.map(|v| v + base);
        }
    }
}

/// Makes every normal unit length. Normals that are already unit length (to
/// rounding) are kept bit for bit, so that writing a scene and reading it back
/// is exact; zero or non-finite ones take the geometric normal of a triangle
/// using them, or +Y.
pub(crate) fn repair_normals(positions: &[Vec3], triangles: &[[u32; 3]], normals: &mut [Vec3]) {
    for n in normals.iter_mut() {
        // Written so that NaN counts as not unit.
        let unit = (n.length_squared() - 1.0).abs() <= 1e-6;
        if !unit {
            *n = n.normalize_or_zero();
        }
    }
    for t in triangles {
        let g = face_normal(t.map(|v| positions[v as usize]));
        for &v in t {
            let n = &mut normals[v as usize];
            if *n == Vec3::ZERO {
                *n = g;
            }
        }
    }
    for n in normals.iter_mut().filter(|n| **n == Vec3::ZERO) {
        *n = FALLBACK_NORMAL;
    }
}

/// Renumbers vertices into a canonical layout: for each run of consecutive
/// triangles with the same object and material, the vertices in order of first
/// use, vertices with bit-identical position and normal merged, unused ones
/// dropped. This is the layout tobj produces for an OBJ model with normals, so
/// a scene in this layout survives an OBJ round trip unchanged.
pub(crate) fn compact_vertices(scene: &mut Scene) {
    let Scene {
        positions,
        normals,
        triangles,
        ..
    } = scene;
    let mut new_positions = Vec::new();
    let mut new_normals = Vec::new();
    let mut ids: HashMap<([u32; 3], [u32; 3]), u32> = HashMap::new();
    let mut run = None;
    for t in triangles.iter_mut() {
        if run != Some((t.object, t.material)) {
            run = Some((t.object, t.material));
            ids.clear();
        }
        t.vertices = t.vertices.map(|v| {
            let (p, n) = (positions[v as usize], normals[v as usize]);
            *ids.entry((
                p.to_array().map(f32::to_bits),
                n.to_array().map(f32::to_bits),
            ))
            .or_insert_with(|| {
                new_positions.push(p);
                new_normals.push(n);
                new_normals.len() as u32 - 1
            })
        });
    }
    *positions = new_positions;
    *normals = new_normals;
}

/// The unit normal of a triangle (counter-clockwise winding), or zero when it
/// is degenerate or not finite.
fn face_normal([a, b, c]: [Vec3; 3]) -> Vec3 {
    (b - a).cross(c - a).normalize_or_zero()
}

/// The interior angle of a triangle at each corner; atan2 keeps it well
/// defined (zero) for zero-length edges.
fn corner_angles(p: [Vec3; 3]) -> [f32; 3] {
    std::array::from_fn(|k| {
        let e1 = p[(k + 1) % 3] - p[k];
        let e2 = p[(k + 2) % 3] - p[k];
        e1.cross(e2).length().atan2(e1.dot(e2))
    })
}

/// Hash key for welding: the position's bits, with -0.0 folded into 0.0.
fn position_key(p: Vec3) -> [u32; 3] {
    (p + Vec3::ZERO).to_array().map(f32::to_bits)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Material, MaterialId, Object, Triangle};
    use proptest::prelude::*;

    /// A unit cube with 8 shared corners and 12 outward-facing triangles.
    fn cube() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let positions = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
            .collect();
        let quads = [
            [0, 2, 3, 1], // z = 0, facing -z
            [4, 5, 7, 6], // z = 1
            [0, 1, 5, 4], // y = 0
            [2, 6, 7, 3], // y = 1
            [0, 4, 6, 2], // x = 0
            [1, 3, 7, 5], // x = 1
        ];
        let triangles = quads
            .iter()
            .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
            .collect();
        (positions, triangles)
    }

    /// A UV sphere of radius 1 with `rings` latitude bands and `segments`
    /// longitude slices; the poles are single shared vertices.
    fn sphere(rings: u32, segments: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut positions = vec![Vec3::Y, -Vec3::Y];
        for r in 1..rings {
            let theta = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..segments {
                let phi = std::f32::consts::TAU * s as f32 / segments as f32;
                positions.push(Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    -theta.sin() * phi.sin(),
                ));
            }
        }
        let ring = |r: u32, s: u32| 2 + (r - 1) * segments + s % segments;
        let mut triangles = Vec::new();
        for s in 0..segments {
            triangles.push([0, ring(1, s), ring(1, s + 1)]);
            triangles.push([1, ring(rings - 1, s + 1), ring(rings - 1, s)]);
            for r in 1..rings - 1 {
                let (a, b, c, d) = (
                    ring(r, s),
                    ring(r + 1, s),
                    ring(r + 1, s + 1),
                    ring(r, s + 1),
                );
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
        (positions, triangles)
    }

    fn assert_unit(normals: &[Vec3]) {
        for n in normals {
            assert!(n.is_finite() && (n.length() - 1.0).abs() < 1e-5, "{n}");
        }
    }

    #[test]
    fn a_cube_gets_24_vertices_with_face_normals() {
        let (positions, triangles) = cube();
        let (p, n, t) = compute_normals(&positions, &triangles, DEFAULT_CREASE_ANGLE_DEG);
        assert_eq!((p.len(), n.len(), t.len()), (24, 24, 12));
        assert_unit(&n);
        for (old, new) in triangles.iter().zip(&t) {
            let face = face_normal(new.map(|v| p[v as usize]));
            for k in 0..3 {
                assert_eq!(p[new[k] as usize], positions[old[k] as usize]);
                assert!((n[new[k] as usize] - face).length() < 1e-6);
            }
        }
    }

    #[test]
    fn a_cube_smoothed_past_90_degrees_has_diagonal_corner_normals() {
        let (positions, triangles) = cube();
        let (p, n, _) = compute_normals(&positions, &triangles, 100.0);
        assert_eq!(p.len(), 8);
        for (p, n) in p.iter().zip(&n) {
            let outward = (*p - Vec3::splat(0.5)).normalize();
            // Angle weighting makes the corner normal exactly diagonal even
            // though each face has a different number of triangles there.
            assert!((*n - outward).length() < 1e-5, "{p} {n}");
        }
    }

    #[test]
    fn a_tessellated_sphere_stays_smooth() {
        let (positions, triangles) = sphere(16, 32);
        let (p, n, t) = compute_normals(&positions, &triangles, DEFAULT_CREASE_ANGLE_DEG);
        assert_eq!(p.len(), positions.len());
        assert_eq!(t.len(), triangles.len());
        for (p, n) in p.iter().zip(&n) {
            assert!(n.dot(p.normalize()) > 0.999, "{p} {n}");
        }
    }

    #[test]
    fn duplicated_positions_are_welded_so_seams_stay_smooth() {
        let (mut positions, mut triangles) = sphere(8, 16);
        // Give half of the triangles private copies of their vertices, as an
        // OBJ file with a UV seam or a material split would.
        let base = positions.len() as u32;
        positions.extend_from_within(..);
        for t in triangles.iter_mut().step_by(2) {
            *t = t.map(|v| v + base);
        }
        let (p, n, _) = compute_normals(&positions, &triangles, DEFAULT_CREASE_ANGLE_DEG);
        assert_eq!(p.len(), positions.len() / 2);
        for (p, n) in p.iter().zip(&n) {
            assert!(n.dot(p.normalize()) > 0.99, "{p} {n}");
        }
    }

    #[test]
    fn degenerate_faces_get_a_neighbours_normal_or_plus_y() {
        let positions = [
            Vec3::ZERO,
            Vec3::X,
            Vec3::Z,
            Vec3::X * 2.0,
            Vec3::splat(5.0),
        ];
        // A proper triangle facing -y, a sliver along the x axis touching it,
        // and a triangle collapsed to a point.
        let triangles = [[0, 1, 2], [0, 1, 3], [4, 4, 4]];
        let (p, n, t) = compute_normals(&positions, &triangles, DEFAULT_CREASE_ANGLE_DEG);
        assert_unit(&n);
        assert_eq!(p.len(), n.len());
        for v in t[1] {
            // The sliver's far corner (x = 2) touches nothing and falls back.
            let expected = if p[v as usize].x == 2.0 {
                Vec3::Y
            } else {
                -Vec3::Y
            };
            assert!(
                (n[v as usize] - expected).length() < 1e-6,
                "{:?}",
                p[v as usize]
            );
        }
        assert_eq!(n[t[2][0] as usize], Vec3::Y);
    }

    #[test]
    fn non_finite_positions_and_crease_angles_give_no_nan() {
        let positions = [
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(f32::NAN, 0.0, 1.0),
            Vec3::INFINITY,
            Vec3::Z,
        ];
        let triangles = [[0, 1, 2], [0, 1, 3], [0, 3, 2], [0, 1, 4], [1, 0, 4]];
        for crease in [f32::NAN, -5.0, 0.0, 1e9, f32::INFINITY] {
            let (_, n, _) = compute_normals(&positions, &triangles, crease);
            assert_unit(&n);
        }
    }

    #[test]
    fn repair_keeps_unit_normals_and_fixes_zero_ones() {
        let positions = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let tilted = Vec3::new(0.3, 0.4, 0.5).normalize();
        let mut normals = [tilted, Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO, Vec3::NAN];
        repair_normals(&positions, &[[0, 1, 2]], &mut normals);
        assert_eq!(normals, [tilted, Vec3::Z, Vec3::Z, Vec3::Y]);
    }

    fn two_cube_scene() -> Scene {
        let (positions, triangles) = cube();
        let mut scene = Scene {
            positions: positions.clone(),
            normals: Vec::new(),
            triangles: triangles
                .iter()
                .enumerate()
                .map(|(i, &vertices)| Triangle {
                    vertices,
                    object: ObjectId(0),
                    material: MaterialId((i / 6) as u32),
                })
                .collect(),
            objects: vec![Object { name: "a".into() }, Object { name: "b".into() }],
            materials: vec![Material::default(), Material::diffuse("red", Vec3::X)],
            ..Default::default()
        };
        // The second cube shares the first one's vertex array but is its own
        // object; it must not smooth with the first where they coincide.
        scene
            .triangles
            .extend(triangles.iter().map(|&vertices| Triangle {
                vertices,
                object: ObjectId(1),
                material: MaterialId(0),
            }));
        scene
    }

    #[test]
    fn scene_normals_are_built_per_object_when_missing() {
        let mut scene = two_cube_scene();
        let before = scene.triangles.clone();
        assert!(ensure_normals(&mut scene, 100.0));
        assert!(!ensure_normals(&mut scene, 100.0));
        scene.validate().unwrap();
        // Each object smooths fully on its own, but the material switch inside
        // object 0 splits its vertex runs: 8 + 8 corners there, 8 for object 1.
        assert_eq!(scene.positions.len(), 8 + 8 + 8);
        for (old, new) in before.iter().zip(&scene.triangles) {
            assert_eq!((old.object, old.material), (new.object, new.material));
            for v in new.vertices {
                let (p, n) = (scene.positions[v as usize], scene.normals[v as usize]);
                assert!((n - (p - Vec3::splat(0.5)).normalize()).length() < 1e-5);
            }
        }
    }

    #[test]
    fn compacting_merges_identical_vertices_within_a_run_only() {
        let mut scene = two_cube_scene();
        scene.normals = vec![Vec3::Y; 8];
        // Duplicate every vertex and point one triangle of the first run at
        // the copies: identical values, so they merge back within the run.
        scene.positions.extend_from_within(..);
        scene.normals.extend_from_within(..);
        scene.triangles[1].vertices = scene.triangles[1].vertices.map(|v| v + 8);
        compact_vertices(&mut scene);
        scene.validate().unwrap();
        // Three runs (object, material): (0, 0), (0, 1), (1, 0), each using
        // all 8 corners, numbered in order of first use after the last run's.
        assert_eq!(scene.positions.len(), 3 * 8);
        let runs = [
            &scene.triangles[..6],
            &scene.triangles[6..12],
            &scene.triangles[12..],
        ];
        for (base, run) in (0..).step_by(8).zip(runs) {
            let mut first_use: Vec<u32> = Vec::new();
            for v in run.iter().flat_map(|t| t.vertices) {
                if !first_use.contains(&v) {
                    first_use.push(v);
                }
            }
            assert_eq!(first_use, (base..base + 8).collect::<Vec<u32>>());
        }
    }

    proptest! {
        /// Random meshes on a 3x3x3 grid: plenty of duplicate corners,
        /// degenerate and coincident faces.
        #[test]
        fn random_meshes_get_unit_normals_and_keep_their_corners(
            grid in prop::collection::vec((0u8..3, 0u8..3, 0u8..3), 1..12),
            corners in prop::collection::vec(any::<[u8; 3]>(), 0..40),
            crease in -10.0f32..200.0,
        ) {
            let positions: Vec<Vec3> =
                grid.iter().map(|&(x, y, z)| Vec3::new(x.into(), y.into(), z.into())).collect();
            let triangles: Vec<[u32; 3]> =
                corners.iter().map(|t| t.map(|v| u32::from(v) % positions.len() as u32)).collect();
            let (p, n, t) = compute_normals(&positions, &triangles, crease);
            prop_assert_eq!(p.len(), n.len());
            prop_assert_eq!(t.len(), triangles.len());
            assert_unit(&n);
            for (old, new) in triangles.iter().zip(&t) {
                for k in 0..3 {
                    prop_assert_eq!(p[new[k] as usize], positions[old[k] as usize]);
                }
            }
        }
    }
}
