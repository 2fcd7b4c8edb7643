//! Which scene triangles a reflector can mirror: everything but the
//! reflector's triangles and the transparent back surfaces of their objects.
//!
//! A glass reflector's back surface (the cockpit's `cover_glass_back`, by
//! the convention `<object>_back`) lies millimetres behind the front: the
//! ray tracer's mirror rays never reach it, while for the cube-map search
//! it sits wholly in the hidden region and in the environment map it would
//! cover the view from the centroid. Leaving it out matches the reference.

use vtfarm_scene::{Scene, TriangleId};

/// Suffix of the object name of a reflector's back surface.
pub const BACK_SUFFIX: &str = "_back";

/// Per scene triangle: whether it belongs to a mesh the reflector mirrors.
pub fn reflected_triangle_flags(scene: &Scene, reflector: &[TriangleId]) -> Vec<bool> {
    // Objects whose triangles are all left out: the reflector objects' backs
    // (looked up by name once per reflector object, not per triangle).
    let mut is_reflector = vec![false; scene.objects.len()];
    for &t in reflector {
        is_reflector[scene.triangles[t.index()].object.index()] = true;
    }
    let mut excluded = vec![false; scene.objects.len()];
    for (object, _) in is_reflector.iter().enumerate().filter(|(_, r)| **r) {
        let back = format!("{}{BACK_SUFFIX}", scene.objects[object].name);
        if let Some(back) = scene.object_id(&back) {
            excluded[back.index()] = true;
        }
    }
    let mut flags: Vec<bool> = scene
        .triangles
        .iter()
        .map(|t| !excluded[t.object.index()])
        .collect();
    for &t in reflector {
        flags[t.index()] = false;
    }
    flags
}
