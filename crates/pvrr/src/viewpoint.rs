//! The virtual viewpoint (paper §3.2) and the view frustum of the first pass
//! (§3.3, with the reversed region of §4.2).

use glam::{DMat3, DVec3, Vec3};
use vtfarm_scene::{Camera, Projector};
use vtfarm_trace::Ray;

/// The widest half-angle a reflection map may span: beyond it a pinhole map
/// degenerates, and the vertices outside fall back on tracing.
const MAX_HALF_ANGLE_DEG: f32 = 80.0;

/// Texels of margin around the bounds, so bilinear lookups near the border
/// stay inside the map.
const MARGIN_TEXELS: f32 = 1.5;

/// The point closest, in the least-squares sense, to all lines (the extended
/// exit rays of the reflector's vertices): it minimises the sum of squared
/// distances `|(I - d dᵀ)(x - o)|²`, whose normal equations are
/// `Σ(I - d dᵀ) x = Σ(I - d dᵀ) o`. A tiny pull towards the rays' origins keeps
/// the system regular when all lines are parallel.
pub(crate) fn virtual_viewpoint(lines: &[Ray]) -> Vec3 {
    if lines.is_empty() {
        return Vec3::ZERO;
    }
    let mut a = DMat3::ZERO;
    let mut b = DVec3::ZERO;
    let mut centroid = DVec3::ZERO;
    for line in lines {
        let d = line.direction.as_dvec3().normalize_or_zero();
        let o = line.origin.as_dvec3();
        let projector = DMat3::IDENTITY - outer(d, d);
        a += projector;
        b += projector * o;
        centroid += o;
    }
    let n = lines.len() as f64;
    centroid /= n;
    let lambda = 1e-9 * n;
    a += DMat3::IDENTITY * lambda;
    b += centroid * lambda;
    let x = a.inverse() * b;
    if x.is_finite() {
        x.as_vec3()
    } else {
        centroid.as_vec3()
    }
}

fn outer(u: DVec3, v: DVec3) -> DMat3 {
    DMat3::from_cols(u * v.x, u * v.y, u * v.z)
}

/// The first-pass camera: a pinhole at the virtual viewpoint whose image
/// contains every exit ray between the near plane and the far end, and the
/// near clipping plane's view depth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct MapView {
    pub(crate) camera: Camera,
    /// Geometry nearer than this view depth is clipped (§3.3: the plane just
    /// in front of the reflector).
    pub(crate) near: f32,
}

/// What a frustum must contain besides the lines themselves.
pub(crate) struct FrustumInput<'a> {
    pub(crate) eye: Vec3,
    /// The exit rays (origins on the reflector).
    pub(crate) lines: &'a [Ray],
    /// Where each line meets the scene, where it does.
    pub(crate) hits: &'a [Option<Vec3>],
    /// The scene's bounding box, for the far plane.
    pub(crate) bounds: (Vec3, Vec3),
    /// The map's longer side in texels.
    pub(crate) resolution: u32,
}

/// §3.3: the viewing direction is the mean exit direction; the near plane
/// lies just in front of the reflector when the reflector is in front of the
/// virtual viewpoint (convex mirror, concave lens). When it lies behind
/// (concave mirror, convex lens: the rays cross near the viewpoint, §4.2),
/// the map looks into the reversed region beyond the crossing and the near
/// plane sits just past the viewpoint; the "zooming region" between reflector
/// and crossing is not in the map. The sides bound every line's crossing of
/// the far plane, every hit point and, in the first case, every line's
/// crossing of the near plane. The frustum is re-aimed at the centre of those
/// bounds so that the symmetric pinhole wastes no texels.
pub(crate) fn fit_frustum(input: &FrustumInput<'_>) -> MapView {
    let eye = input.eye;
    let mean = input
        .lines
        .iter()
        .fold(Vec3::ZERO, |s, l| s + l.direction)
        .normalize_or(Vec3::NEG_Z);
    let reflector_depth = input
        .lines
        .iter()
        .map(|l| (l.origin - eye).dot(mean))
        .fold(f32::NEG_INFINITY, f32::max);
    let scale = (input.bounds.1 - input.bounds.0).max_element().max(1e-3);
    // A near-plane clearance, not a ray offset: a small fraction of the scene.
    let margin = scale * 1e-4;
    let in_front = reflector_depth > margin;
    let near = if in_front {
        reflector_depth + margin
    } else {
        margin.max(scale * 1e-4)
    };
    let far = corners(input.bounds)
        .iter()
        .map(|&c| (c - eye).dot(mean))
        .fold(near * 2.0, f32::max);

    let mut points = Vec::with_capacity(input.lines.len() * 3);
    for (line, hit) in input.lines.iter().zip(input.hits) {
        let along = line.direction.dot(mean);
        let depth = (line.origin - eye).dot(mean);
        let at_depth = |plane: f32| line.origin + line.direction * ((plane - depth) / along);
        if along > 1e-6 {
            points.push(at_depth(far.max(depth)));
            if in_front {
                points.push(at_depth(near.max(depth)));
            }
        }
        if let Some(p) = hit {
            points.push(*p);
        }
    }

    let up = if mean.y.abs() < 0.9 { Vec3::Y } else { Vec3::Z };
    let aimed = |forward: Vec3| Camera {
        eye,
        target: eye + forward,
        up,
        fov_y_deg: 90.0,
        width: 2,
        height: 2,
    };
    let first = tangent_box(&aimed(mean), &points, near);
    let (forward, right, up_axis) = aimed(mean).basis();
    // Aim at the middle of the angular box (the middle of the tangent box
    // leans towards the wider side when the box is wide).
    let middle = |lo: f32, hi: f32| ((lo.atan() + hi.atan()) * 0.5).tan();
    let centred =
        (forward + right * middle(first.0.x, first.1.x) + up_axis * middle(first.0.y, first.1.y))
            .normalize_or(mean);
    let (lo, hi) = tangent_box(&aimed(centred), &points, near);
    let limit = MAX_HALF_ANGLE_DEG.to_radians().tan();
    let half = lo.abs().max(hi.abs()).min(glam::Vec2::splat(limit));
    let half = half.max(glam::Vec2::splat(1e-4));

    let resolution = input.resolution.max(2);
    let (width, height) = if half.x >= half.y {
        let h = (resolution as f32 * half.y / half.x).ceil() as u32;
        (resolution, h.max(2))
    } else {
        let w = (resolution as f32 * half.x / half.y).ceil() as u32;
        (w.max(2), resolution)
    };
    // The vertical half-extent that also covers the horizontal one, plus a
    // margin of texels for bilinear lookups.
    let tan_half = half.y.max(half.x * height as f32 / width as f32)
        * (1.0 + 2.0 * MARGIN_TEXELS / height.min(width) as f32);
    MapView {
        camera: Camera {
            fov_y_deg: (2.0 * tan_half.atan()).to_degrees(),
            width,
            height,
            ..aimed(centred)
        },
        near,
    }
}

/// The box of `points`' image-plane tangents (x right, y up) as seen by
/// `camera`, over the points beyond the near plane.
fn tangent_box(camera: &Camera, points: &[Vec3], near: f32) -> (glam::Vec2, glam::Vec2) {
    let (forward, right, up) = camera.basis();
    let mut lo = glam::Vec2::splat(f32::INFINITY);
    let mut hi = glam::Vec2::splat(f32::NEG_INFINITY);
    for &p in points {
        let d = p - camera.eye;
        let z = d.dot(forward);
        if z < near * 0.5 {
            continue;
        }
        let t = glam::Vec2::new(d.dot(right) / z, d.dot(up) / z);
        lo = lo.min(t);
        hi = hi.max(t);
    }
    if lo.x > hi.x {
        (glam::Vec2::ZERO, glam::Vec2::ZERO)
    } else {
        (lo, hi)
    }
}

fn corners((lo, hi): (Vec3, Vec3)) -> [Vec3; 8] {
    std::array::from_fn(|i| {
        Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    })
}

impl MapView {
    /// Continuous map coordinates (pixel convention of `vtfarm_scene::Camera`)
    /// of a scene point, or `None` when it is clipped or outside the map.
    pub(crate) fn coords_of_point(&self, projector: &Projector, p: Vec3) -> Option<glam::Vec2> {
        let s = projector.project(p)?;
        (s.depth >= self.near).then_some(())?;
        self.inside(glam::Vec2::new(s.x, s.y))
    }

    /// Map coordinates of a direction (a point at infinity): a pinhole
    /// images it where it images `eye + direction`.
    pub(crate) fn coords_of_direction(
        &self,
        projector: &Projector,
        direction: Vec3,
    ) -> Option<glam::Vec2> {
        let s = projector.project(self.camera.eye + direction)?;
        self.inside(glam::Vec2::new(s.x, s.y))
    }

    fn inside(&self, c: glam::Vec2) -> Option<glam::Vec2> {
        let (w, h) = (self.camera.width as f32, self.camera.height as f32);
        (c.x >= 0.0 && c.y >= 0.0 && c.x <= w && c.y <= h).then_some(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(origin: Vec3, through: Vec3) -> Ray {
        Ray {
            origin,
            direction: (through - origin).normalize(),
        }
    }

    #[test]
    fn lines_through_one_point_give_that_point() {
        let focus = Vec3::new(0.3, -1.0, 2.0);
        let lines: Vec<Ray> = [Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 5.0), Vec3::NEG_Z]
            .iter()
            .map(|&o| line(o, focus))
            .collect();
        assert!(virtual_viewpoint(&lines).distance(focus) < 1e-4);
    }

    #[test]
    fn the_viewpoint_minimises_the_squared_distances() {
        let lines = [
            line(Vec3::ZERO, Vec3::X),
            line(Vec3::Y, Vec3::new(0.0, 1.0, 1.0)),
            line(Vec3::Z, Vec3::new(1.0, 1.0, 1.0)),
        ];
        let cost = |x: Vec3| -> f32 {
            lines
                .iter()
                .map(|l| {
                    let v = x - l.origin;
                    (v - l.direction * v.dot(l.direction)).length_squared()
                })
                .sum()
        };
        let best = virtual_viewpoint(&lines);
        for step in [Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE] {
            assert!(cost(best) <= cost(best + step * 0.01));
            assert!(cost(best) <= cost(best - step * 0.01));
        }
    }

    #[test]
    fn the_frustum_contains_every_hit_point() {
        let eye = Vec3::new(0.0, 0.0, -1.0);
        let origins = [Vec3::new(-0.2, 0.0, 0.0), Vec3::new(0.2, 0.1, 0.0)];
        let hits = [Vec3::new(-3.0, 1.0, 4.0), Vec3::new(2.0, -0.5, 5.0)];
        let lines: Vec<Ray> = origins
            .iter()
            .zip(&hits)
            .map(|(&o, &h)| line(o, h))
            .collect();
        let hit_points: Vec<Option<Vec3>> = hits.iter().map(|&h| Some(h)).collect();
        let view = fit_frustum(&FrustumInput {
            eye,
            lines: &lines,
            hits: &hit_points,
            bounds: (Vec3::splat(-5.0), Vec3::splat(5.0)),
            resolution: 64,
        });
        assert!(view.near > 1.0, "the near plane lies past the reflector");
        let projector = Projector::new(&view.camera);
        for h in hits {
            assert!(view.coords_of_point(&projector, h).is_some(), "{h}");
        }
    }
}
