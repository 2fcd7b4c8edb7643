//! Conservative capture: what the per-pixel reference finds, `full` finds.
//!
//! Refinement reacts to the samples it has; a source smaller than the gap
//! between a face's samples (the sun's 0.53° disc mirrored in the middle
//! of a flat pane, a small lamp between the vertices of a coarse mirror)
//! leaves every sample agreeing and is interpolated away. So before
//! trusting a face, the vertex tracer bounds what the face can mirror: the
//! cone of directions its points reflect the eye's rays into, from the
//! cone of its eye directions and the cone of its normals (a reflection
//! turns by at most the first's angle plus twice the second's). The rule:
//!
//! * a face whose cone may reach a directional light's disc (its radius
//!   and a pixel's footprint added), or the bounding sphere of an emitter at
//!   least [`crate::VertexSettings::capture_cd_m2`] bright that none of its
//!   corner samples mirrors (once one does, the samples disagree where the
//!   emitter's image ends and refinement follows that edge), is *captured*;
//! * refinement splits a captured face's longest edge whatever its samples
//!   say (down to the pixel floor and the depth limit, at one visible end
//!   as every split), so the split faces narrow onto the source;
//! * at `full` a captured face's pixels are traced, not interpolated.
//!
//! Every test is a function of the face, the frame's lights and the
//! scene's emitters alone, so package independence holds.

use glam::Vec3;
use vtfarm_scene::photometry;

use crate::Frame;

/// A cone of directions: a unit axis and a half-angle in radians.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Cone {
    axis: Vec3,
    half_angle: f32,
}

/// The angle between two unit vectors.
fn angle(a: Vec3, b: Vec3) -> f32 {
    a.dot(b).clamp(-1.0, 1.0).acos()
}

/// A cone around three unit directions (the normalised sum as its axis),
/// which holds every direction between them while it is narrower than a
/// hemisphere; `None` when it is not (anything may lie between).
fn bounding_cone(directions: [Vec3; 3]) -> Option<Cone> {
    let axis = (directions[0] + directions[1] + directions[2]).try_normalize()?;
    let half_angle = directions
        .iter()
        .map(|&d| angle(axis, d))
        .fold(0.0, f32::max);
    (half_angle < std::f32::consts::FRAC_PI_2).then_some(Cone { axis, half_angle })
}

/// The cone of the directions a face with `corners` (position, shading
/// normal) reflects the rays from `eye` into; `None` when it cannot be
/// bounded below a hemisphere.
fn reflection_cone(eye: Vec3, corners: [(Vec3, Vec3); 3]) -> Option<Cone> {
    let seen = bounding_cone(corners.map(|(p, _)| (p - eye).normalize_or_zero()))?;
    let normals = bounding_cone(corners.map(|(_, n)| n.normalize_or_zero()))?;
    let axis = vtfarm_trace::reflect(seen.axis, normals.axis);
    Some(Cone {
        axis,
        half_angle: seen.half_angle + 2.0 * normals.half_angle,
    })
}

impl Frame<'_> {
    /// Whether a face with `corners` (position, shading normal) may mirror
    /// a bright source (see the module docs).
    /// `seen`: the objects the corners' samples mirror.
    pub(crate) fn captures(&self, corners: [(Vec3, Vec3); 3], seen: [u32; 3]) -> bool {
        let threshold = self.settings.capture_cd_m2;
        let cone = reflection_cone(self.camera.eye, corners);
        let within = |toward: Vec3, reach: f32| {
            cone.is_none_or(|c| angle(c.axis, toward) <= c.half_angle + reach)
        };
        let footprint = self.tracer.cone.spread;
        let discs = (self.tracer.lighting.lights.iter()).filter_map(|l| l.disc());
        for disc in discs {
            if photometry::cd_m2(disc.radiance) >= threshold
                && within(disc.toward, disc.radius + footprint)
            {
                return true;
            }
        }
        let centre = (corners[0].0 + corners[1].0 + corners[2].0) / 3.0;
        let radius = corners
            .iter()
            .map(|(p, _)| p.distance(centre))
            .fold(0.0, f32::max);
        let bright = (self.tracer.bvh.emitters().iter())
            .filter(|e| e.luminance_cd_m2 >= threshold && !seen.contains(&e.object.raw()));
        for emitter in bright {
            let to = emitter.centre - centre;
            let distance = to.length();
            if distance <= emitter.radius + radius {
                // The face reaches into the source's bounds: any direction.
                return true;
            }
            let reach = ((emitter.radius + radius) / distance).min(1.0).asin();
            if within(to / distance, reach) {
                return true;
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flat_faces_reflection_cone_holds_the_mirror_direction_of_every_point() {
        let eye = Vec3::new(0.0, 0.5, 2.0);
        let corners = [
            (Vec3::new(-1.0, -1.0, 0.0), Vec3::Z),
            (Vec3::new(1.0, -1.0, 0.0), Vec3::Z),
            (Vec3::new(0.0, 1.0, 0.0), Vec3::Z),
        ];
        let cone = reflection_cone(eye, corners).unwrap();
        for (u, v) in [(0.2, 0.3), (0.33, 0.33), (0.9, 0.05), (0.0, 1.0)] {
            let p = corners[0].0 * (1.0 - u - v) + corners[1].0 * u + corners[2].0 * v;
            let r = vtfarm_trace::reflect((p - eye).normalize(), Vec3::Z);
            assert!(angle(cone.axis, r) <= cone.half_angle + 1e-5);
        }
    }

    #[test]
    fn a_curved_faces_cone_widens_by_twice_its_normals_spread() {
        let eye = Vec3::new(0.0, 0.0, 10.0);
        let tilt = |x: f32, y: f32| Vec3::new(x, y, 1.0).normalize();
        let corners = [
            (Vec3::new(-0.01, -0.01, 0.0), tilt(-0.1, -0.1)),
            (Vec3::new(0.01, -0.01, 0.0), tilt(0.1, -0.1)),
            (Vec3::new(0.0, 0.01, 0.0), tilt(0.0, 0.1)),
        ];
        let cone = reflection_cone(eye, corners).unwrap();
        let n = (tilt(-0.1, -0.1) * 0.2 + tilt(0.1, -0.1) * 0.3 + tilt(0.0, 0.1) * 0.5).normalize();
        let r = vtfarm_trace::reflect(-Vec3::Z, n);
        assert!(angle(cone.axis, r) <= cone.half_angle);
        assert!(cone.half_angle > 0.2);
    }
}
