//! Triangle-mesh building blocks shared by the part builders: a parametric
//! grid and the primitives made from it (flat rectangles with openings,
//! boxes, discs, tubes, a torus, swept profiles with rounded corners), each
//! built in a local frame and placed with [`Frame`].
//!
//! Curved primitives carry their exact analytic normals; flat faces get their
//! own vertices so hard edges stay hard. [`Mesh::triangle`] winds every
//! triangle counter-clockwise as seen from the side its vertex normals point
//! to, so builders only have to get the normals right.

use std::f32::consts::TAU;

use glam::{Vec2, Vec3};

/// Triangles smaller than this (in m²) are dropped: they come from grid
/// cells that collapse to a line or a point.
const MIN_AREA: f32 = 1e-10;

/// A rigid placement: an origin plus a right-handed orthonormal basis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Frame {
    pub(crate) origin: Vec3,
    pub(crate) x: Vec3,
    pub(crate) y: Vec3,
    pub(crate) z: Vec3,
}

impl Frame {
    /// The world axes translated to `origin`.
    pub(crate) fn at(origin: Vec3) -> Self {
        Frame {
            origin,
            x: Vec3::X,
            y: Vec3::Y,
            z: Vec3::Z,
        }
    }

    /// The frame with x along `x`, y as close to `y` as possible and
    /// z = x × y (so it is always right-handed).
    pub(crate) fn from_axes(origin: Vec3, x: Vec3, y: Vec3) -> Self {
        let x = x.normalize();
        let z = x.cross(y).normalize();
        Frame {
            origin,
            x,
            y: z.cross(x),
            z,
        }
    }

    /// The frame whose z axis is `z` and whose y axis leans towards `up`.
    pub(crate) fn facing(origin: Vec3, z: Vec3, up: Vec3) -> Self {
        let z = z.normalize();
        let x = up.cross(z).normalize();
        Frame {
            origin,
            x,
            y: z.cross(x),
            z,
        }
    }

    /// A point given in this frame, in world coordinates.
    pub(crate) fn point(&self, p: Vec3) -> Vec3 {
        self.origin + self.vector(p)
    }

    /// A direction given in this frame, in world coordinates.
    pub(crate) fn vector(&self, v: Vec3) -> Vec3 {
        self.x * v.x + self.y * v.y + self.z * v.z
    }

    /// `child`, given in this frame's coordinates, in world coordinates.
    pub(crate) fn compose(&self, child: &Frame) -> Frame {
        Frame {
            origin: self.point(child.origin),
            x: self.vector(child.x),
            y: self.vector(child.y),
            z: self.vector(child.z),
        }
    }
}

/// An indexed triangle mesh with one unit normal per vertex.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Mesh {
    pub(crate) positions: Vec<Vec3>,
    pub(crate) normals: Vec<Vec3>,
    pub(crate) triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// Adds a vertex and returns its index.
    pub(crate) fn vertex(&mut self, position: Vec3, normal: Vec3) -> u32 {
        self.positions.push(position);
        self.normals.push(normal.normalize());
        (self.positions.len() - 1) as u32
    }

    /// Adds a triangle wound counter-clockwise as seen from the side its
    /// vertex normals point to; degenerate triangles are dropped.
    pub(crate) fn triangle(&mut self, a: u32, b: u32, c: u32) {
        let [pa, pb, pc] = [a, b, c].map(|v| self.positions[v as usize]);
        let cross = (pb - pa).cross(pc - pa);
        if cross.length() * 0.5 <= MIN_AREA {
            return;
        }
        let mean = [a, b, c]
            .iter()
            .map(|&v| self.normals[v as usize])
            .sum::<Vec3>();
        self.triangles.push(if cross.dot(mean) >= 0.0 {
            [a, b, c]
        } else {
            [a, c, b]
        });
    }

    /// Adds the quad `a b c d` (corners in order around it) as two triangles.
    pub(crate) fn quad(&mut self, a: u32, b: u32, c: u32, d: u32) {
        self.triangle(a, b, c);
        self.triangle(a, c, d);
    }

    /// Appends `other`, given in `frame`'s coordinates.
    pub(crate) fn append(&mut self, other: &Mesh, frame: &Frame) {
        let base = self.positions.len() as u32;
        self.positions
            .extend(other.positions.iter().map(|&p| frame.point(p)));
        self.normals
            .extend(other.normals.iter().map(|&n| frame.vector(n).normalize()));
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|v| v + base)));
    }

    /// Appends `other` as it is.
    pub(crate) fn merge(&mut self, other: &Mesh) {
        self.append(other, &Frame::at(Vec3::ZERO));
    }

    /// `self` placed with `frame`.
    pub(crate) fn placed(&self, frame: &Frame) -> Mesh {
        let mut mesh = Mesh::default();
        mesh.append(self, frame);
        mesh
    }

    /// A grid of `nu` × `nv` cells over the vertices `vertex(i, j)`
    /// (0 ≤ i ≤ nu, 0 ≤ j ≤ nv), each returning a position and normal.
    pub(crate) fn grid(nu: u32, nv: u32, vertex: impl FnMut(u32, u32) -> (Vec3, Vec3)) -> Mesh {
        Self::grid_where(nu, nv, vertex, |_, _| true)
    }

    /// [`Mesh::grid`] with only the cells (i, j) that `keep` accepts; vertices
    /// of skipped cells are not created.
    pub(crate) fn grid_where(
        nu: u32,
        nv: u32,
        mut vertex: impl FnMut(u32, u32) -> (Vec3, Vec3),
        keep: impl Fn(u32, u32) -> bool,
    ) -> Mesh {
        let mut mesh = Mesh::default();
        let mut index = vec![u32::MAX; ((nu + 1) * (nv + 1)) as usize];
        let mut id = |mesh: &mut Mesh, i: u32, j: u32| {
            let slot = &mut index[(j * (nu + 1) + i) as usize];
            if *slot == u32::MAX {
                let (p, n) = vertex(i, j);
                *slot = mesh.vertex(p, n);
            }
            *slot
        };
        for j in 0..nv {
            for i in 0..nu {
                if keep(i, j) {
                    let a = id(&mut mesh, i, j);
                    let b = id(&mut mesh, i + 1, j);
                    let c = id(&mut mesh, i + 1, j + 1);
                    let d = id(&mut mesh, i, j + 1);
                    mesh.quad(a, b, c, d);
                }
            }
        }
        mesh
    }

    /// The flat rectangle [0, size.x] × [0, size.y] in the local xy plane,
    /// facing +z, in cells of at most `cell` metres. `hole` (min, max corner)
    /// is left open; grid lines run along its edges so no T-junctions appear.
    pub(crate) fn rect(size: Vec2, hole: Option<[Vec2; 2]>, cell: f32) -> Mesh {
        let (xs, ys) = match hole {
            Some([lo, hi]) => (
                subdivide(&[0.0, lo.x, hi.x, size.x], cell),
                subdivide(&[0.0, lo.y, hi.y, size.y], cell),
            ),
            None => (
                subdivide(&[0.0, size.x], cell),
                subdivide(&[0.0, size.y], cell),
            ),
        };
        let open = |i: u32, j: u32| {
            let (i, j) = (i as usize, j as usize);
            hole.is_some_and(|[lo, hi]| {
                xs[i] >= lo.x && xs[i + 1] <= hi.x && ys[j] >= lo.y && ys[j + 1] <= hi.y
            })
        };
        Mesh::grid_where(
            xs.len() as u32 - 1,
            ys.len() as u32 - 1,
            |i, j| (Vec3::new(xs[i as usize], ys[j as usize], 0.0), Vec3::Z),
            |i, j| !open(i, j),
        )
    }

    /// An axis-aligned box centred at the origin with half extents `half`,
    /// each face its own flat grid of cells of at most `cell` metres.
    pub(crate) fn cuboid(half: Vec3, cell: f32) -> Mesh {
        let axes = [Vec3::X, Vec3::Y, Vec3::Z];
        let mut mesh = Mesh::default();
        for k in 0..3 {
            let (n, u, v) = (axes[k], axes[(k + 1) % 3], axes[(k + 2) % 3]);
            let (hn, hu, hv) = (half.dot(n), half.dot(u), half.dot(v));
            // +face: x = u, y = v (u × v = n); -face: x = v, y = u (v × u = -n).
            let faces = [
                (
                    n * hn - u * hu - v * hv,
                    u,
                    v,
                    Vec2::new(2.0 * hu, 2.0 * hv),
                ),
                (
                    -n * hn - u * hu - v * hv,
                    v,
                    u,
                    Vec2::new(2.0 * hv, 2.0 * hu),
                ),
            ];
            for (origin, x, y, size) in faces {
                mesh.append(
                    &Mesh::rect(size, None, cell),
                    &Frame::from_axes(origin, x, y),
                );
            }
        }
        mesh
    }

    /// A disc of `radius` in the local xy plane facing +z, as a fan.
    pub(crate) fn disc(radius: f32, segments: u32) -> Mesh {
        let mut mesh = Mesh::default();
        let centre = mesh.vertex(Vec3::ZERO, Vec3::Z);
        let ring: Vec<u32> = (0..segments)
            .map(|i| mesh.vertex(circle(i, segments).extend(0.0) * radius, Vec3::Z))
            .collect();
        for i in 0..segments as usize {
            mesh.triangle(centre, ring[i], ring[(i + 1) % ring.len()]);
        }
        mesh
    }

    /// The open side of a cylinder of `radius` along local +z from 0 to
    /// `length`, normals pointing outwards.
    pub(crate) fn tube(radius: f32, length: f32, segments: u32, rings: u32) -> Mesh {
        Mesh::grid(segments, rings, |i, j| {
            let dir = circle(i % segments, segments).extend(0.0);
            (
                dir * radius + Vec3::Z * (length * j as f32 / rings as f32),
                dir,
            )
        })
    }

    /// A closed cylinder: [`Mesh::tube`] plus flat end discs.
    pub(crate) fn cylinder(radius: f32, length: f32, segments: u32, rings: u32) -> Mesh {
        let mut mesh = Mesh::tube(radius, length, segments, rings);
        let disc = Mesh::disc(radius, segments);
        mesh.append(&disc, &Frame::from_axes(Vec3::ZERO, Vec3::X, -Vec3::Y));
        mesh.append(&disc, &Frame::at(Vec3::Z * length));
        mesh
    }

    /// A torus around the local z axis: ring radius `major`, tube radius
    /// `minor`, `nu` segments around the ring and `nv` around the tube.
    pub(crate) fn torus(major: f32, minor: f32, nu: u32, nv: u32) -> Mesh {
        Mesh::grid(nu, nv, |i, j| {
            let around = circle(i % nu, nu);
            let tube = circle(j % nv, nv);
            let normal = (around * tube.x).extend(tube.y);
            ((around * major).extend(0.0) + normal * minor, normal)
        })
    }

    /// Sweeps a section (points with their normals, perpendicular to
    /// `offset`) along `offset` in `steps` segments; a `closed` section joins
    /// its last point back to its first.
    pub(crate) fn sweep(section: &[(Vec3, Vec3)], offset: Vec3, steps: u32, closed: bool) -> Mesh {
        let n = section.len() as u32;
        let columns = if closed { n } else { n - 1 };
        Mesh::grid(columns, steps, |i, j| {
            let (p, normal) = section[(i % n) as usize];
            (p + offset * (j as f32 / steps as f32), normal)
        })
    }

    /// A prism: the closed convex `profile` (local xy, with its outward
    /// normals) swept along local +z over `length`, with flat end caps.
    pub(crate) fn prism(profile: &[(Vec2, Vec2)], length: f32, steps: u32) -> Mesh {
        let section: Vec<(Vec3, Vec3)> = profile
            .iter()
            .map(|&(p, n)| (p.extend(0.0), n.extend(0.0)))
            .collect();
        let mut mesh = Mesh::sweep(&section, Vec3::Z * length, steps, true);
        for (z, normal) in [(0.0, -Vec3::Z), (length, Vec3::Z)] {
            let outline: Vec<Vec3> = profile.iter().map(|&(p, _)| p.extend(z)).collect();
            mesh.fan(&outline, normal);
        }
        mesh
    }

    /// Closes the convex polygon `outline` with a fan from its centroid,
    /// all vertices getting the flat `normal`.
    pub(crate) fn fan(&mut self, outline: &[Vec3], normal: Vec3) {
        let centroid = outline.iter().sum::<Vec3>() / outline.len() as f32;
        let centre = self.vertex(centroid, normal);
        let ring: Vec<u32> = outline.iter().map(|&p| self.vertex(p, normal)).collect();
        for i in 0..ring.len() {
            self.triangle(centre, ring[i], ring[(i + 1) % ring.len()]);
        }
    }
}

/// The unit vector at angle `i / n` of a full turn.
fn circle(i: u32, n: u32) -> Vec2 {
    let (sin, cos) = (TAU * i as f32 / n as f32).sin_cos();
    Vec2::new(cos, sin)
}

/// Splits each interval between consecutive `stops` into equal pieces of at
/// most `cell`; empty intervals are skipped.
fn subdivide(stops: &[f32], cell: f32) -> Vec<f32> {
    let mut out = vec![stops[0]];
    for pair in stops.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        if b - a <= 0.0 {
            continue;
        }
        let pieces = ((b - a) / cell).ceil().max(1.0) as u32;
        out.extend((1..pieces).map(|k| a + (b - a) * k as f32 / pieces as f32));
        out.push(b);
    }
    out
}

/// The outline of a convex polygon whose corners are rounded with arcs of
/// the given radii (all > 0), as points with exact outward normals, in
/// counter-clockwise order. Arcs get `arc_segments` segments; straight
/// edges are split into pieces of at most `edge_cell`.
pub(crate) fn rounded_polygon(
    corners: &[(Vec2, f32)],
    arc_segments: u32,
    edge_cell: f32,
) -> Vec<(Vec2, Vec2)> {
    let twice_area: f32 = (0..corners.len())
        .map(|k| corners[k].0.perp_dot(corners[(k + 1) % corners.len()].0))
        .sum();
    let mut corners = corners.to_vec();
    if twice_area < 0.0 {
        corners.reverse();
    }
    let n = corners.len();
    // Outward normal of the edge from corner k to corner k + 1.
    let edge_normal = |k: usize| {
        let d = (corners[(k + 1) % n].0 - corners[k].0).normalize();
        Vec2::new(d.y, -d.x)
    };
    let mut outline = Vec::new();
    for k in 0..n {
        let (corner, radius) = corners[k];
        debug_assert!(radius > 0.0, "sharp corners need duplicated vertices");
        let (n0, n1) = (edge_normal((k + n - 1) % n), edge_normal(k));
        let centre = corner - (n0 + n1) * (radius / (1.0 + n0.dot(n1)));
        let a0 = n0.to_angle();
        let mut a1 = n1.to_angle();
        if a1 < a0 {
            a1 += TAU;
        }
        for s in 0..=arc_segments {
            let normal = Vec2::from_angle(a0 + (a1 - a0) * s as f32 / arc_segments as f32);
            outline.push((centre + normal * radius, normal));
        }
        // The straight part up to the next corner's arc.
        let (next, next_radius) = corners[(k + 1) % n];
        let n2 = edge_normal((k + 1) % n);
        let next_centre = next - (n1 + n2) * (next_radius / (1.0 + n1.dot(n2)));
        let start = centre + n1 * radius;
        let end = next_centre + n1 * next_radius;
        let pieces = (start.distance(end) / edge_cell).ceil().max(1.0) as u32;
        outline.extend((1..pieces).map(|s| (start.lerp(end, s as f32 / pieces as f32), n1)));
    }
    outline
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_consistent(mesh: &Mesh) {
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            let geometric = (b - a).cross(c - a);
            let mean: Vec3 = t.iter().map(|&v| mesh.normals[v as usize]).sum();
            assert!(
                geometric.dot(mean) > 0.0,
                "{t:?} is wound against its normals"
            );
        }
        assert!(mesh.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-5));
    }

    #[test]
    fn rect_leaves_the_hole_open_without_t_junctions() {
        let mesh = Mesh::rect(
            Vec2::new(2.0, 1.0),
            Some([Vec2::new(0.5, 0.25), Vec2::new(1.5, 0.75)]),
            0.25,
        );
        assert_consistent(&mesh);
        let area: f32 = mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
                (b - a).cross(c - a).length() * 0.5
            })
            .sum();
        assert!((area - (2.0 - 0.5)).abs() < 1e-4, "{area}");
        assert!(mesh.normals.iter().all(|&n| n == Vec3::Z));
    }

    #[test]
    fn cuboid_faces_point_outwards() {
        let mesh = Mesh::cuboid(Vec3::new(0.5, 1.0, 2.0), 0.5);
        assert_consistent(&mesh);
        for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
            // Every vertex lies on the face its normal belongs to.
            assert!((p.dot(*n) - Vec3::new(0.5, 1.0, 2.0).dot(n.abs())).abs() < 1e-5);
        }
    }

    #[test]
    fn torus_normals_are_exact() {
        let mesh = Mesh::torus(1.0, 0.25, 24, 8);
        assert_consistent(&mesh);
        for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
            let ring = (p.truncate().normalize()).extend(0.0);
            assert!(((*p - ring) - *n * 0.25).length() < 1e-5);
        }
    }

    #[test]
    fn cylinder_and_disc_are_consistent() {
        assert_consistent(&Mesh::cylinder(0.1, 0.5, 16, 2));
        assert_eq!(Mesh::disc(1.0, 12).triangles.len(), 12);
    }

    #[test]
    fn rounded_polygon_outline_is_on_the_rounded_shape() {
        let square = [
            (Vec2::ZERO, 0.2),
            (Vec2::new(0.0, 1.0), 0.2),
            (Vec2::ONE, 0.2),
            (Vec2::new(1.0, 0.0), 0.2),
        ];
        let outline = rounded_polygon(&square, 4, 0.1);
        let centre = Vec2::splat(0.5);
        for &(p, n) in &outline {
            assert!((n.length() - 1.0).abs() < 1e-5);
            assert!(n.dot(p - centre) > 0.0, "normal {n} at {p} points inwards");
            // Distance to the shrunk square equals the radius.
            let q = (p - centre).abs() - Vec2::splat(0.3);
            assert!((q.max(Vec2::ZERO).length() - 0.2).abs() < 1e-4, "{p}");
        }
        let prism = Mesh::prism(&outline, 1.0, 3);
        assert_consistent(&prism);
    }
}
