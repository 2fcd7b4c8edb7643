//! Classifies a reflector as convex, concave, flat or neither from how the
//! surface bends across its interior edges. The search supports convex and
//! concave pieces (the paper's §6.2 asks for the segmentation); saddles and
//! torus-like reflectors are neither and get a warning.
//!
//! An edge bends convexly when the far corner of each neighbouring triangle
//! lies below the other triangle's plane, "below" meaning against the
//! triangle's normal turned to agree with its vertex normals (the side the
//! reflector faces).

use std::collections::HashMap;

use glam::Vec3;
use vtfarm_scene::{Scene, TriangleId};

/// The reflector's shape as the search sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReflectorShape {
    /// Every bent edge bends away from the side the normals face (a sphere
    /// seen from outside).
    Convex,
    /// Every bent edge bends towards it (a sphere seen from inside, the
    /// cockpit's cover glass).
    Concave,
    /// No edge bends (a plane).
    Flat,
    /// Both kinds of edges: a saddle, a torus or several pieces; the
    /// search may converge to a wrong point or not at all.
    Neither,
}

impl ReflectorShape {
    /// The warning a front end should print, if any.
    pub fn warning(&self) -> Option<String> {
        (*self == ReflectorShape::Neither).then(|| {
            "the reflector is neither convex nor concave (saddle, torus-like or several \
             pieces): cube-map reflections may be wrong; split it into convex and concave pieces"
                .to_owned()
        })
    }
}

/// The warnings for a job of `method` whose reflectors are `reflectors`:
/// one per reflector object the cube-map search does not support (neither
/// convex nor concave), naming it; none for the other methods.
pub fn unsupported_reflector_warnings(
    method: vtfarm_method::MethodKind,
    scene: &Scene,
    reflectors: &[TriangleId],
) -> Vec<String> {
    use vtfarm_method::MethodKind;
    if !matches!(method, MethodKind::CubeMap | MethodKind::CubeMapGrid) {
        return Vec::new();
    }
    (vtfarm_method::reflector_groups(scene, reflectors).iter())
        .filter_map(|group| {
            let warning = classify(scene, group).warning()?;
            let object = scene.triangles[group[0].index()].object;
            let name = &scene.objects[object.index()].name;
            Some(format!("reflector {name:?}: {warning}"))
        })
        .collect()
}

/// Mean bends smaller than this fraction of the edge length count as flat.
const FLAT: f32 = 1e-5;
/// A kind of bend whose sum is below this share of all bends is noise.
const MINOR: f64 = 0.1;

/// Classifies the reflector `triangles` of `scene`.
pub fn classify(scene: &Scene, triangles: &[TriangleId]) -> ReflectorShape {
    // Corners are welded by exact position: meshes duplicate vertices
    // along hard edges, which still bound the same surface.
    let key = |p: Vec3| p.to_array().map(f32::to_bits);
    let mut edges: HashMap<([u32; 3], [u32; 3]), Vec<TriangleId>> = HashMap::new();
    for &t in triangles {
        let corners = scene.triangle_positions(t);
        for k in 0..3 {
            let (a, b) = (key(corners[k]), key(corners[(k + 1) % 3]));
            edges.entry((a.min(b), a.max(b))).or_default().push(t);
        }
    }
    let (mut convex, mut concave) = (0.0f64, 0.0f64);
    for (edge, owners) in &edges {
        let [t1, t2] = owners[..] else {
            continue;
        };
        let length = (Vec3::from_array(edge.0.map(f32::from_bits))
            - Vec3::from_array(edge.1.map(f32::from_bits)))
        .length();
        let bend = height_of_far_corner(scene, t1, t2) + height_of_far_corner(scene, t2, t1);
        let relative = f64::from(bend / length.max(f32::MIN_POSITIVE));
        if relative < 0.0 {
            convex -= relative;
        } else {
            concave += relative;
        }
    }
    // A quad's diagonal on a doubly curved patch may bend slightly against
    // the surface (twist): only a bend sum of comparable size counts.
    let total = convex + concave;
    let significant = |sum: f64| sum > f64::from(FLAT) * edges.len() as f64 && sum > MINOR * total;
    match (significant(convex), significant(concave)) {
        (false, false) => ReflectorShape::Flat,
        (true, false) => ReflectorShape::Convex,
        (false, true) => ReflectorShape::Concave,
        (true, true) => ReflectorShape::Neither,
    }
}

/// Height of `other`'s corners above `base`'s plane, the largest in
/// magnitude (the one not on the shared edge), along `base`'s facing normal.
fn height_of_far_corner(scene: &Scene, base: TriangleId, other: TriangleId) -> f32 {
    let [a, _, _] = scene.triangle_positions(base);
    let normal = facing(scene.geometric_normal(base), scene.triangle_normals(base));
    scene
        .triangle_positions(other)
        .iter()
        .map(|&p| (p - a).dot(normal))
        .fold(0.0, |best, h| if h.abs() > best.abs() { h } else { best })
}

/// A triangle's geometric `normal` (any length) turned to agree with its
/// vertex normals: towards the side the reflector faces.
pub(crate) fn facing(normal: Vec3, vertex_normals: [Vec3; 3]) -> Vec3 {
    let shading: Vec3 = vertex_normals.iter().sum();
    if normal.dot(shading) < 0.0 {
        -normal
    } else {
        normal
    }
}
