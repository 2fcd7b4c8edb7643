//! Triangle setup. Every vertex is projected once with the shared
//! [`Projector`], so triangles sharing a vertex get the very same screen
//! point. Triangles fully in front of the eye and near the image go straight
//! to scan conversion; the rest are clipped in view space (in `f64`) against
//! the near plane and a guard band around the image, which bounds snapped
//! coordinates so the integer edge functions cannot overflow.
//!
//! The near plane's view depth is a parameter: `vtfarm_scene::NEAR` for the
//! base frame and ID buffers (whose vertices then project exactly as the shared
//! [`Projector`] projects them), or a caller's plane, e.g. one placed at a
//! reflector for a map rendered from a virtual viewpoint behind it.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use vtfarm_scene::{Camera, NEAR, Projector, Scene, Triangle, TriangleId};

use crate::PixelRect;
use crate::triangle::{RasterTriangle, ScreenVertex};

/// How far beyond the image (in pixels) a corner may project before its
/// triangle is clipped against the guard band.
const GUARD: f64 = 16384.0;

// Clip planes as bits of a vertex's outside mask, in clipping order: the
// near plane first, so the guard planes only ever see points in front of the eye.
const NEAR_PLANE: u8 = 1;
const LEFT: u8 = 2;
const RIGHT: u8 = 4;
const TOP: u8 = 8;
const BOTTOM: u8 = 16;
const PLANES: [u8; 5] = [NEAR_PLANE, LEFT, RIGHT, TOP, BOTTOM];
/// A non-finite vertex: its triangles are dropped.
const INVALID: u8 = 128;

/// Clipping a triangle by five planes leaves at most 3 + 5 corners; the
/// slack absorbs rounding that makes a polygon look slightly non-convex.
const MAX_CORNERS: usize = 12;

/// A polygon corner during clipping.
#[derive(Clone, Copy, Debug, Default)]
struct ClipVertex {
    /// View-space position: (right, up, forward) relative to the eye.
    view: DVec3,
    /// Where it projects; meaningless when outside the near plane.
    screen: ScreenVertex,
    /// The planes it lies outside of.
    outside: u8,
}

#[derive(Clone, Copy, Debug, Default)]
struct Polygon {
    corners: [ClipVertex; MAX_CORNERS],
    len: usize,
}

impl Polygon {
    fn push(&mut self, v: ClipVertex) {
        // Only a degenerate, numerically non-convex polygon could overflow;
        // dropping a corner then merely changes a sliver.
        if self.len < MAX_CORNERS {
            self.corners[self.len] = v;
            self.len += 1;
        }
    }

    fn corners(&self) -> &[ClipVertex] {
        &self.corners[..self.len]
    }
}

/// The camera frame in the two forms setup needs: the shared `f32`
/// projector for vertices and an `f64` view transform for clipping.
struct View {
    projector: Projector,
    /// The near plane's view depth.
    near: f32,
    eye: DVec3,
    right: DVec3,
    up: DVec3,
    forward: DVec3,
    inv_pixel: f64,
    half_width: f64,
    half_height: f64,
    width: u32,
    height: u32,
    /// The pixels being rasterized: triangles outside are dropped.
    within: PixelRect,
}

/// Scene triangles set up per rayon task: each task's raster triangles go
/// into one vector sized for them up front (most triangles make at most one).
const TRIANGLES_PER_TASK: usize = 4096;

/// Projects, clips (at view depth `near`) and snaps the triangles of `scene`
/// that `keep` accepts and that may cover pixels of `within` (a non-empty
/// rectangle inside the image): in triangle order, in runs (one per
/// [`TRIANGLES_PER_TASK`] scene triangles), which are not copied together
/// here as [`crate::bands::nearest_first`] reorders them anyway.
pub(crate) fn setup(
    scene: &Scene,
    camera: &Camera,
    near: f32,
    within: PixelRect,
    keep: &(dyn Fn(TriangleId) -> bool + Sync),
) -> Vec<Vec<RasterTriangle>> {
    let view = View::new(camera, near, within);
    let corners: Vec<Corner> = scene
        .positions
        .par_iter()
        .map(|&p| view.corner(p))
        .collect();
    // Apart from the corners: the one byte per vertex that most triangles
    // (those wholly beside a small rectangle) are dropped by.
    let beyond: Vec<u8> = corners.par_iter().map(|c| view.beyond(c)).collect();
    scene
        .triangles
        .par_chunks(TRIANGLES_PER_TASK)
        .enumerate()
        .map(|(task, triangles)| {
            let first = task * TRIANGLES_PER_TASK;
            let mut out = Vec::with_capacity(triangles.len());
            for (id, t) in (first as u32..).map(TriangleId).zip(triangles) {
                let [a, b, c] = t.vertices.map(|v| beyond[v as usize]);
                if a & b & c == 0 && keep(id) {
                    view.triangle_into(scene, &corners, id, t, &mut out);
                }
            }
            out
        })
        .collect()
}

/// What set-up keeps of a scene vertex for its triangles: where it
/// projects and the clip planes it lies outside of (a [`ClipVertex`]
/// without its view-space position, which only clipping needs).
#[derive(Clone, Copy, Debug, Default)]
struct Corner {
    screen: ScreenVertex,
    outside: u8,
}

impl View {
    fn new(camera: &Camera, near: f32, within: PixelRect) -> Self {
        let (forward, right, up) = camera.basis();
        View {
            projector: Projector::new(camera),
            near,
            eye: camera.eye.as_dvec3(),
            right: right.as_dvec3(),
            up: up.as_dvec3(),
            forward: forward.as_dvec3(),
            inv_pixel: 1.0 / f64::from(camera.pixel_size_at_unit_depth()),
            half_width: f64::from(camera.width) * 0.5,
            half_height: f64::from(camera.height) * 0.5,
            width: camera.width,
            height: camera.height,
            within,
        }
    }

    /// The guard planes a projected point lies outside of.
    fn guard_outside(&self, x: f64, y: f64) -> u8 {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        [
            (x < -GUARD, LEFT),
            (x > w + GUARD, RIGHT),
            (y < -GUARD, TOP),
            (y > h + GUARD, BOTTOM),
        ]
        .into_iter()
        .filter(|&(out, _)| out)
        .fold(0, |mask, (_, plane)| mask | plane)
    }

    /// A scene vertex. Beyond [`NEAR`] it projects with the shared projector
    /// (so the default near plane gives exactly its screen points); between a
    /// nearer plane and `NEAR`, where the projector declines, it projects in
    /// `f64` like the corners clipping makes.
    fn corner(&self, p: Vec3) -> Corner {
        if !p.is_finite() {
            return Corner {
                outside: INVALID,
                ..Corner::default()
            };
        }
        match self.projector.project(p) {
            Some(s) if s.depth >= self.near => {
                let (x, y) = (f64::from(s.x), f64::from(s.y));
                Corner {
                    screen: ScreenVertex {
                        x,
                        y,
                        inv_depth: 1.0 / f64::from(s.depth),
                    },
                    outside: self.guard_outside(x, y),
                }
            }
            None if self.near < NEAR => {
                let view = self.view_of(p);
                if view.z >= f64::from(self.near) {
                    let v = self.clipped_vertex(view);
                    Corner {
                        screen: v.screen,
                        outside: v.outside,
                    }
                } else {
                    Corner {
                        outside: NEAR_PLANE,
                        ..Corner::default()
                    }
                }
            }
            _ => Corner {
                outside: NEAR_PLANE,
                ..Corner::default()
            },
        }
    }

    /// [`Self::corner`] with its view-space position, for clipping.
    fn vertex(&self, p: Vec3) -> ClipVertex {
        let Corner { screen, outside } = self.corner(p);
        let view = if outside & INVALID == 0 {
            self.view_of(p)
        } else {
            DVec3::ZERO
        };
        ClipVertex {
            view,
            screen,
            outside,
        }
    }

    /// A point's view-space position: (right, up, forward) relative to the eye.
    fn view_of(&self, p: Vec3) -> DVec3 {
        let d = p.as_dvec3() - self.eye;
        DVec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }

    /// The sides of the rectangle being rasterized that a corner lies
    /// wholly beyond, by more than a pixel (as [`LEFT`] .. [`BOTTOM`]): a
    /// triangle whose three corners share a side covers no pixel of it.
    /// Corners off the near plane (or invalid) are beyond none: their
    /// triangles are clipped first. A triangle of three corners in front
    /// of the near plane projects inside their screen points' hull, and the
    /// guard band only moves corners inwards along its edges; the pixel of
    /// slack covers snapping and the `f64` projection of clipped corners.
    fn beyond(&self, corner: &Corner) -> u8 {
        if corner.outside & (NEAR_PLANE | INVALID) != 0 {
            return 0;
        }
        let ScreenVertex { x, y, .. } = corner.screen;
        let w = self.within;
        let slack = 1.0;
        [
            (x < f64::from(w.x0) - slack, LEFT),
            (x > f64::from(w.x1) + slack, RIGHT),
            (y < f64::from(w.y0) - slack, TOP),
            (y > f64::from(w.y1) + slack, BOTTOM),
        ]
        .into_iter()
        .filter(|&(out, _)| out)
        .fold(0, |mask, (_, side)| mask | side)
    }

    /// A new corner made by clipping, projected in `f64`.
    fn clipped_vertex(&self, view: DVec3) -> ClipVertex {
        let k = self.inv_pixel / view.z;
        let (x, y) = (self.half_width + view.x * k, self.half_height - view.y * k);
        ClipVertex {
            view,
            screen: ScreenVertex {
                x,
                y,
                inv_depth: 1.0 / view.z,
            },
            outside: self.guard_outside(x, y),
        }
    }

    /// Signed distance-like value of a view-space point to a clip plane,
    /// positive inside. The guard planes are the screen lines x = -GUARD,
    /// x = width + GUARD, ... multiplied through by the (positive) depth.
    fn plane_value(&self, plane: u8, v: DVec3) -> f64 {
        let (gx, gy) = (self.half_width + GUARD, self.half_height + GUARD);
        match plane {
            NEAR_PLANE => v.z - f64::from(self.near),
            LEFT => gx * v.z + v.x * self.inv_pixel,
            RIGHT => gx * v.z - v.x * self.inv_pixel,
            TOP => gy * v.z - v.y * self.inv_pixel,
            _ => gy * v.z + v.y * self.inv_pixel,
        }
    }

    /// The point where edge (`inside`, `outside`) crosses `plane`. Always
    /// called with the inside end first, so the two triangles sharing an edge
    /// create bit-identical corners and stay watertight.
    fn intersect(&self, plane: u8, inside: ClipVertex, outside: ClipVertex) -> ClipVertex {
        let a = self.plane_value(plane, inside.view);
        let b = self.plane_value(plane, outside.view);
        // The masks come from the f32 projection, the values from f64: where
        // they disagree (a corner within rounding of the plane) stay on the edge.
        let t = a / (a - b);
        let t = if t.is_finite() {
            t.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let mut view = inside.view.lerp(outside.view, t);
        if plane == NEAR_PLANE {
            view.z = f64::from(self.near);
        }
        self.clipped_vertex(view)
    }

    /// Sutherland-Hodgman against every plane some corner lies outside of.
    fn clip(&self, mut polygon: Polygon) -> Polygon {
        for plane in PLANES {
            if polygon.corners().iter().all(|v| v.outside & plane == 0) {
                continue;
            }
            let mut clipped = Polygon::default();
            let corners = polygon.corners();
            for (i, &a) in corners.iter().enumerate() {
                let b = corners[(i + 1) % corners.len()];
                let (a_in, b_in) = (a.outside & plane == 0, b.outside & plane == 0);
                if a_in {
                    clipped.push(a);
                }
                if a_in && !b_in {
                    clipped.push(self.intersect(plane, a, b));
                } else if b_in && !a_in {
                    clipped.push(self.intersect(plane, b, a));
                }
            }
            polygon = clipped;
        }
        polygon
    }

    /// Pushes the raster triangles of scene triangle `id` onto `out`: none,
    /// one, or a fan over its clipped polygon.
    fn triangle_into(
        &self,
        scene: &Scene,
        vertices: &[Corner],
        id: TriangleId,
        triangle: &Triangle,
        out: &mut Vec<RasterTriangle>,
    ) {
        let corners = triangle.vertices.map(|v| vertices[v as usize]);
        let any_outside = corners.iter().fold(0, |m, c| m | c.outside);
        let all_outside = corners.iter().fold(u8::MAX, |m, c| m & c.outside);
        if any_outside == 0 {
            // The common case: in front of the eye and near the image.
            let screen = corners.map(|c| c.screen);
            out.extend(RasterTriangle::new(id, screen, self.within));
            return;
        }
        // Entirely beyond one plane (or invalid): nothing to draw.
        if all_outside != 0 || any_outside & INVALID != 0 {
            return;
        }
        let mut polygon = Polygon::default();
        (triangle.vertices)
            .map(|v| self.vertex(scene.positions[v as usize]))
            .into_iter()
            .for_each(|c| polygon.push(c));
        let polygon = self.clip(polygon);
        out.extend((1..polygon.len.saturating_sub(1)).filter_map(|i| {
            let [a, b, c] = [0, i, i + 1].map(|j| polygon.corners[j].screen);
            RasterTriangle::new(id, [a, b, c], self.within)
        }));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng as _, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;
    use vtfarm_scene::MaterialId;

    fn camera() -> Camera {
        Camera {
            eye: Vec3::ZERO,
            target: -Vec3::Z,
            up: Vec3::Y,
            fov_y_deg: 60.0,
            width: 64,
            height: 48,
        }
    }

    #[test]
    fn near_plane_corners_land_on_the_near_plane_and_on_the_edge() {
        let view = View::new(&camera(), NEAR, PixelRect::full(64, 48));
        let front = view.vertex(Vec3::new(0.5, -1.0, -2.0));
        let behind = view.vertex(Vec3::new(0.5, -1.0, 2.0));
        assert_eq!(behind.outside, NEAR_PLANE);
        let v = view.intersect(NEAR_PLANE, front, behind);
        assert_eq!(v.view.z, f64::from(NEAR));
        assert!((v.view.x - 0.5).abs() < 1e-12 && (v.view.y + 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_custom_near_plane_moves_the_clipped_corners_there() {
        let near = 1.25f32;
        let view = View::new(&camera(), near, PixelRect::full(64, 48));
        let front = view.vertex(Vec3::new(0.5, -1.0, -2.0));
        let between = view.vertex(Vec3::new(0.5, -1.0, -1.0));
        assert_eq!(between.outside, NEAR_PLANE);
        let v = view.intersect(NEAR_PLANE, front, between);
        assert_eq!(v.view.z, f64::from(near));
        assert!((v.view.x - 0.5).abs() < 1e-12 && (v.view.y + 1.0).abs() < 1e-12);
        // Nearer than the default: projected in f64 where the projector declines.
        let close = View::new(&camera(), NEAR * 0.1, PixelRect::full(64, 48)).vertex(Vec3::new(
            0.0,
            0.0,
            -NEAR * 0.5,
        ));
        assert_eq!(close.outside, 0);
        assert!((close.screen.x - 32.0).abs() < 1e-6 && (close.screen.y - 24.0).abs() < 1e-6);
    }

    #[test]
    fn guard_band_clipping_keeps_corners_near_the_guard() {
        let view = View::new(&camera(), NEAR, PixelRect::full(64, 48));
        // A sliver reaching far to the right, just in front of the eye.
        let t = Triangle {
            vertices: [0, 1, 2],
            object: vtfarm_scene::ObjectId(0),
            material: MaterialId(0),
        };
        let positions = [
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(1e3, 0.0, -0.01),
            Vec3::new(0.0, 0.1, -1.0),
        ];
        let vertices = positions.map(|p| view.vertex(p));
        assert_eq!(vertices[1].outside, RIGHT);
        let mut polygon = Polygon::default();
        vertices.into_iter().for_each(|v| polygon.push(v));
        let clipped = view.clip(polygon);
        assert_eq!(clipped.len, 4);
        let max_x = clipped
            .corners()
            .iter()
            .map(|c| c.screen.x)
            .fold(f64::MIN, f64::max);
        assert!((max_x - (64.0 + GUARD)).abs() < 1e-6, "{max_x}");
        let scene = Scene {
            positions: positions.to_vec(),
            ..Scene::default()
        };
        let corners = positions.map(|p| view.corner(p));
        let mut set_up = Vec::new();
        view.triangle_into(&scene, &corners, TriangleId(0), &t, &mut set_up);
        assert!(!set_up.is_empty());
    }

    /// Uniform in [lo, hi), from the workspace's one test generator.
    fn uniform(rng: &mut Xoshiro256PlusPlus, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * rng.random::<f32>()
    }

    #[test]
    fn a_triangle_dropped_beside_the_rectangle_covers_none_of_its_pixels() {
        // Brute force: triangles near a rectangle's sides (corners within a
        // few pixels of them, some far off-screen, some behind the eye), each
        // either dropped by its corners' `beyond` bits or set up as usual;
        // every dropped one must be one that set-up itself gives no raster
        // triangle reaching the rectangle.
        let camera = camera();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        let (mut dropped, mut close_calls) = (0, 0);
        for case in 0..20_000 {
            let r = &mut rng;
            let x0 = uniform(r, 0.0, 50.0) as u32;
            let y0 = uniform(r, 0.0, 36.0) as u32;
            let within = PixelRect {
                x0,
                y0,
                x1: x0 + 1 + uniform(r, 0.0, 14.0) as u32,
                y1: y0 + 1 + uniform(r, 0.0, 12.0) as u32,
            };
            let view = View::new(&camera, NEAR, within);
            // Screen points near the rectangle, at random depths, lifted
            // back into the scene; every eighth corner far off or behind.
            let positions: Vec<Vec3> = (0..3)
                .map(|_| {
                    let depth = uniform(r, 0.5, 20.0);
                    let (w, outside) = (within, uniform(r, 0.9, 2.5));
                    let sx = uniform(r, w.x0 as f32 - 3.0, w.x1 as f32 + 3.0);
                    let sy = uniform(r, w.y0 as f32 - 3.0, w.y1 as f32 + 3.0);
                    // Mostly just beyond one side, the case's.
                    let (sx, sy) = match (uniform(r, 0.0, 8.0) as u32, case % 4) {
                        (0, _) => (uniform(r, -4e5, 4e5), uniform(r, -4e5, 4e5)),
                        (1, _) => (sx, sy),
                        (_, 0) => (w.x0 as f32 - outside, sy),
                        (_, 1) => (w.x1 as f32 + outside, sy),
                        (_, 2) => (sx, w.y0 as f32 - outside),
                        _ => (sx, w.y1 as f32 + outside),
                    };
                    let pixel = camera.pixel_size_at_unit_depth();
                    let right = (sx - 32.0) * pixel * depth;
                    let up = (24.0 - sy) * pixel * depth;
                    let behind = case % 16 == 0;
                    Vec3::new(right, up, if behind { depth } else { -depth })
                })
                .collect();
            let scene = Scene {
                positions,
                ..Scene::default()
            };
            let corners: Vec<Corner> = scene.positions.iter().map(|&p| view.corner(p)).collect();
            let t = Triangle {
                vertices: [0, 1, 2],
                object: vtfarm_scene::ObjectId(0),
                material: MaterialId(0),
            };
            let [a, b, c] = [0, 1, 2].map(|i| view.beyond(&corners[i]));
            if a & b & c == 0 {
                continue;
            }
            dropped += 1;
            let near_side = corners.iter().any(|c| {
                let (x, y) = (c.screen.x, c.screen.y);
                let w = within;
                (x - f64::from(w.x0)).abs() < 1.5
                    || (x - f64::from(w.x1)).abs() < 1.5
                    || (y - f64::from(w.y0)).abs() < 1.5
                    || (y - f64::from(w.y1)).abs() < 1.5
            });
            close_calls += usize::from(near_side);
            let mut set_up = Vec::new();
            view.triangle_into(&scene, &corners, TriangleId(0), &t, &mut set_up);
            assert!(
                set_up.iter().all(|t| !t.reaches(within)),
                "case {case}: a dropped triangle reaches {within:?}"
            );
        }
        // Not vacuous: many were dropped, many with a corner within a pixel
        // and a half of the rectangle's side.
        assert!(
            dropped > 2_000 && close_calls > 1_000,
            "{dropped} {close_calls}"
        );
    }
}
