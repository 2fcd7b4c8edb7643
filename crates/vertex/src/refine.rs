//! The per-triangle refinement mesh (paper section 3.1 and 3.2).
//!
//! Each original reflector triangle is refined on its own: its sub-mesh starts
//! as the triangle, and the edge list (longest projected edge first) splits
//! edges whose end samples differ in colour or ray tree. Splitting an edge
//! inserts one vertex at its midpoint and splits both faces that share it, so
//! one new sample serves up to four new faces. Because nothing here looks
//! beyond the triangle, its result cannot depend on the package it came in.
//!
//! Refinement runs in passes, one per level, each continuing on the mesh
//! the last left (the paper's `Refine()` going on after `TimeToBreak`):
//! `refine` splits edges whose samples disagree; `full` then also splits
//! agreeing edges longer than [`crate::VertexSettings::max_edge`]. A mesh
//! refined to `full` at once runs both passes, so a progressive frame and a
//! frame rendered from scratch are one algorithm and give the same mesh.

use std::collections::{BinaryHeap, HashMap};

use glam::Vec3;
use vtfarm_imaging::linear_to_srgb;
use vtfarm_scene::{Projector, ScreenPoint, TriangleId};
use vtfarm_trace::Sample;

use crate::{Frame, Quality};

/// A vertex of the refinement mesh with its traced sample.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MeshVertex {
    pub(crate) position: Vec3,
    pub(crate) normal: Vec3,
    pub(crate) screen: Option<ScreenPoint>,
    pub(crate) visible: bool,
    pub(crate) sample: Sample,
    /// The sample's colour in display (sRGB) units, for the epsilon test.
    srgb: Vec3,
}

impl MeshVertex {
    pub(crate) fn new(
        frame: &Frame<'_>,
        projector: &Projector,
        triangle: TriangleId,
        position: Vec3,
        normal: Vec3,
        sample: Sample,
    ) -> Self {
        let screen = projector.project(position);
        let visible = screen.is_some_and(|s| frame.vertex_visible(triangle, s));
        let srgb = Vec3::from_array(sample.color.to_array().map(linear_to_srgb));
        MeshVertex {
            position,
            normal,
            screen,
            visible,
            sample,
            srgb,
        }
    }
}

/// A face of the refinement mesh: three vertex indices (winding kept from the
/// original triangle) and its refinement depth.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Face {
    pub(crate) vertices: [u32; 3],
    depth: u32,
    alive: bool,
}

/// An edge waiting in the edge list. Ordered by projected length, then by the
/// vertex indices so the order is total and reproducible.
#[derive(Clone, Copy, Debug, PartialEq)]
struct QueuedEdge {
    length: f32,
    a: u32,
    b: u32,
    /// Queued by the flatness test: refine regardless of the samples.
    forced: bool,
}

impl Eq for QueuedEdge {}

impl Ord for QueuedEdge {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.length
            .total_cmp(&other.length)
            .then(other.a.cmp(&self.a))
            .then(other.b.cmp(&self.b))
            .then(self.forced.cmp(&other.forced))
    }
}

impl PartialOrd for QueuedEdge {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

fn edge_key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// The refined mesh of one original triangle.
pub(crate) struct TriangleMesh {
    pub(crate) triangle: TriangleId,
    pub(crate) vertices: Vec<MeshVertex>,
    faces: Vec<Face>,
    /// The (up to two) live faces on each edge.
    edge_faces: HashMap<(u32, u32), [u32; 2]>,
    pub(crate) refined_edges: u64,
    /// The last level whose pass ran to its end (`Preview`: none yet).
    pub(crate) level: Quality,
}

const NO_FACE: u32 = u32::MAX;

impl TriangleMesh {
    /// The unrefined mesh: the original triangle with its three traced corners.
    pub(crate) fn new(triangle: TriangleId, corners: [MeshVertex; 3]) -> Self {
        let mut edge_faces = HashMap::new();
        for (a, b) in [(0, 1), (1, 2), (2, 0)] {
            edge_faces.insert(edge_key(a, b), [0, NO_FACE]);
        }
        TriangleMesh {
            triangle,
            vertices: corners.to_vec(),
            faces: vec![Face {
                vertices: [0, 1, 2],
                depth: 0,
                alive: true,
            }],
            edge_faces,
            refined_edges: 0,
            level: Quality::Preview,
        }
    }

    /// The live faces.
    pub(crate) fn faces(&self) -> impl Iterator<Item = &Face> {
        self.faces.iter().filter(|f| f.alive)
    }

    /// Whether two vertices' samples differ enough to refine between them.
    fn disagree(&self, a: u32, b: u32, epsilon: f32) -> bool {
        let (va, vb) = (&self.vertices[a as usize], &self.vertices[b as usize]);
        va.sample.signature != vb.sample.signature
            || (va.srgb - vb.srgb).abs().max_element() > epsilon
    }

    /// Whether a face's three samples still disagree (the face needs filling).
    pub(crate) fn face_disagrees(&self, face: &Face, epsilon: f32) -> bool {
        let [a, b, c] = face.vertices;
        self.disagree(a, b, epsilon) || self.disagree(b, c, epsilon) || self.disagree(c, a, epsilon)
    }

    fn screen_length(&self, a: u32, b: u32) -> Option<f32> {
        let sa = self.vertices[a as usize].screen?;
        let sb = self.vertices[b as usize].screen?;
        Some(((sa.x - sb.x).powi(2) + (sa.y - sb.y).powi(2)).sqrt())
    }

    fn queue_edge(&self, queue: &mut BinaryHeap<QueuedEdge>, a: u32, b: u32, forced: bool) {
        // Edges with an end behind the eye cannot be measured on screen: they
        // stay as they are and their pixels are traced directly.
        if let Some(length) = self.screen_length(a, b) {
            let (a, b) = edge_key(a, b);
            queue.push(QueuedEdge {
                length,
                a,
                b,
                forced,
            });
        }
    }

    /// Refines the mesh on to `quality` (`Preview`, `Refine` or `Full`):
    /// each level's pass after the last one run, in order. A stopped pass
    /// leaves the level where it was.
    pub(crate) fn refine_to(&mut self, frame: &Frame<'_>, projector: &Projector, quality: Quality) {
        let level = self.level;
        let passes = [Quality::Refine, Quality::Full].into_iter();
        for pass in passes.filter(|&p| p > level && p <= quality) {
            self.run_pass(frame, projector, pass);
            if frame.stopped() {
                return;
            }
            self.level = pass;
        }
    }

    /// One level's pass: the edge list, seeded with every live edge (the
    /// original triangle's three at first), run to exhaustion (the paper's
    /// Refine()). The list is ordered totally, so the order the seeds go in
    /// does not matter.
    fn run_pass(&mut self, frame: &Frame<'_>, projector: &Projector, pass: Quality) {
        let settings = frame.settings;
        let mut queue = BinaryHeap::new();
        let mut seeds: Vec<(u32, u32)> = self.edge_faces.keys().copied().collect();
        seeds.sort_unstable();
        for (a, b) in seeds {
            self.queue_edge(&mut queue, a, b, false);
        }
        let captured: Vec<(u32, u32)> = (self.faces())
            .filter_map(|f| self.capture_edge(frame, f))
            .collect();
        for (a, b) in captured {
            self.queue_edge(&mut queue, a, b, true);
        }
        while let Some(edge) = queue.pop() {
            if frame.stopped() {
                return;
            }
            let Some(&faces) = self.edge_faces.get(&(edge.a, edge.b)) else {
                continue; // Split already (queued twice, or forced after queueing).
            };
            if !self.check_refinement(frame, &edge, faces, pass) {
                continue;
            }
            let new_faces = self.split(frame, projector, edge.a, edge.b, faces);
            let m = self.vertices.len() as u32 - 1;
            self.queue_edge(&mut queue, edge.a, m, false);
            self.queue_edge(&mut queue, m, edge.b, false);
            for &f in new_faces.iter().filter(|&&f| f != NO_FACE) {
                let face = self.faces[f as usize];
                let opposite = face
                    .vertices
                    .into_iter()
                    .find(|&v| v != edge.a && v != edge.b && v != m);
                if let Some(c) = opposite {
                    // Each opposite vertex appears in two new faces; the second push is dropped at pop.
                    self.queue_edge(&mut queue, m, c, false);
                }
                if let Some((a, b)) = self.flat_long_edge(
                    &face,
                    settings.flatness,
                    settings.pixel_floor,
                    settings.epsilon,
                ) {
                    self.queue_edge(&mut queue, a, b, true);
                }
                if let Some((a, b)) = self.capture_edge(frame, &face) {
                    self.queue_edge(&mut queue, a, b, true);
                }
            }
        }
    }

    /// CheckRefinement(): long enough on screen, not too deep, at least one
    /// end visible, and the samples disagree (or the flatness test forced it,
    /// or, in the `full` pass, the edge is longer than the maximum edge,
    /// below which agreeing ends are trusted).
    fn check_refinement(
        &self,
        frame: &Frame<'_>,
        edge: &QueuedEdge,
        faces: [u32; 2],
        pass: Quality,
    ) -> bool {
        let settings = &frame.settings;
        let deep = faces
            .iter()
            .filter(|&&f| f != NO_FACE)
            .any(|&f| self.faces[f as usize].depth >= settings.max_depth);
        let visible =
            self.vertices[edge.a as usize].visible || self.vertices[edge.b as usize].visible;
        edge.length > settings.pixel_floor
            && !deep
            && visible
            && (edge.forced
                || (pass == Quality::Full && edge.length > settings.max_edge)
                || self.disagree(edge.a, edge.b, settings.epsilon)
                || self.crosses_hidden_edge(frame, edge))
    }

    /// Whether the opaque scene seen through a transparent reflector changes
    /// along the edge: a marking thinner than the edge between two samples
    /// that both see the dial would otherwise be missed.
    fn crosses_hidden_edge(&self, frame: &Frame<'_>, edge: &QueuedEdge) -> bool {
        let (Some(a), Some(b)) = (
            self.vertices[edge.a as usize].screen,
            self.vertices[edge.b as usize].screen,
        ) else {
            return false;
        };
        frame.behind_hints(self.triangle) && frame.behind_changes_along(a, b)
    }

    /// RefineEdge(): inserts the midpoint vertex (position interpolated,
    /// normal interpolated and normalised), traces it, and splits each face on
    /// the edge in two. Returns the new faces.
    fn split(
        &mut self,
        frame: &Frame<'_>,
        projector: &Projector,
        a: u32,
        b: u32,
        faces: [u32; 2],
    ) -> [u32; 4] {
        let (va, vb) = (self.vertices[a as usize], self.vertices[b as usize]);
        // a + b is commutative in floating point, so the shared edge of two
        // neighbouring original triangles gets the same midpoint from both.
        let position = (va.position + vb.position) * 0.5;
        let normal = (va.normal + vb.normal).normalize_or(va.normal);
        let sample = frame.shade_vertex(self.triangle, position, normal);
        let m = self.vertices.len() as u32;
        self.vertices.push(MeshVertex::new(
            frame,
            projector,
            self.triangle,
            position,
            normal,
            sample,
        ));
        self.refined_edges += 1;
        self.edge_faces.remove(&edge_key(a, b));
        let mut new_faces = [NO_FACE; 4];
        for (i, &f) in faces.iter().enumerate().filter(|(_, f)| **f != NO_FACE) {
            let face = self.faces[f as usize];
            let v = face.vertices;
            let k = (0..3)
                .find(|&k| edge_key(v[k], v[(k + 1) % 3]) == edge_key(a, b))
                .expect("a face listed on an edge has that edge");
            let (p, q, r) = (v[k], v[(k + 1) % 3], v[(k + 2) % 3]);
            self.faces[f as usize].alive = false;
            let first = self.push_face([p, m, r], face.depth + 1);
            let second = self.push_face([m, q, r], face.depth + 1);
            self.replace_face_on_edge(r, p, f, first);
            self.replace_face_on_edge(q, r, f, second);
            self.add_face_to_edge(p, m, first);
            self.add_face_to_edge(m, q, second);
            self.add_face_to_edge(m, r, first);
            self.add_face_to_edge(m, r, second);
            new_faces[2 * i] = first;
            new_faces[2 * i + 1] = second;
        }
        new_faces
    }

    /// Whether `face` may mirror a bright source (`capture.rs`).
    pub(crate) fn face_captures(&self, frame: &Frame<'_>, face: &Face) -> bool {
        let corners = face.vertices.map(|i| &self.vertices[i as usize]);
        frame.captures(
            corners.map(|v| (v.position, v.normal)),
            corners.map(|v| v.sample.reflected_object),
        )
    }

    /// The longest screen edge of a captured face, split whatever its
    /// samples say (`capture.rs`); `None` for a face that captures nothing
    /// or has a corner behind the eye.
    fn capture_edge(&self, frame: &Frame<'_>, face: &Face) -> Option<(u32, u32)> {
        if !self.face_captures(frame, face) {
            return None;
        }
        let [a, b, c] = face.vertices;
        [(a, b), (b, c), (c, a)]
            .into_iter()
            .filter_map(|(p, q)| Some((self.screen_length(p, q)?, p, q)))
            .max_by(|x, y| x.0.total_cmp(&y.0))
            .map(|(_, p, q)| (p, q))
    }

    fn push_face(&mut self, vertices: [u32; 3], depth: u32) -> u32 {
        self.faces.push(Face {
            vertices,
            depth,
            alive: true,
        });
        self.faces.len() as u32 - 1
    }

    fn replace_face_on_edge(&mut self, a: u32, b: u32, old: u32, new: u32) {
        if let Some(slots) = self.edge_faces.get_mut(&edge_key(a, b)) {
            for slot in slots.iter_mut().filter(|s| **s == old) {
                *slot = new;
            }
        }
    }

    fn add_face_to_edge(&mut self, a: u32, b: u32, face: u32) {
        let slots = self
            .edge_faces
            .entry(edge_key(a, b))
            .or_insert([NO_FACE; 2]);
        if slots[0] == NO_FACE {
            slots[0] = face;
        } else {
            slots[1] = face;
        }
    }

    /// The convergence guard of section 3.2: a face that still disagrees and
    /// is flat (h / c < v) has its longest edge c refined, unless h is under
    /// the pixel floor (rounding on the raster would then loop forever).
    fn flat_long_edge(
        &self,
        face: &Face,
        flatness: f32,
        pixel_floor: f32,
        epsilon: f32,
    ) -> Option<(u32, u32)> {
        if !self.face_disagrees(face, epsilon) {
            return None;
        }
        let [a, b, c] = face.vertices;
        let s = [a, b, c].map(|v| self.vertices[v as usize].screen);
        let [Some(pa), Some(pb), Some(pc)] = s else {
            return None;
        };
        let edges = [(a, b, pa, pb, pc), (b, c, pb, pc, pa), (c, a, pc, pa, pb)];
        let (ea, eb, p, q, r) = edges
            .into_iter()
            .max_by(|x, y| dist(x.2, x.3).total_cmp(&dist(y.2, y.3)))
            .expect("three edges");
        let c_len = dist(p, q);
        if c_len <= 0.0 {
            return None;
        }
        let twice_area = ((q.x - p.x) * (r.y - p.y) - (q.y - p.y) * (r.x - p.x)).abs();
        let h = twice_area / c_len;
        (h / c_len < flatness && h >= pixel_floor).then_some((ea, eb))
    }
}

fn dist(a: ScreenPoint, b: ScreenPoint) -> f32 {
    ((a.x - b.x).powi(2) + (a.y - b.y).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vertex at screen point (x, y) whose sample is `color` (object 0).
    fn vertex((x, y): (f32, f32), color: f32) -> MeshVertex {
        MeshVertex {
            position: Vec3::ZERO,
            normal: Vec3::Z,
            screen: Some(ScreenPoint { x, y, depth: 1.0 }),
            visible: true,
            sample: Sample {
                color: Vec3::splat(color),
                reflected: Vec3::splat(color),
                transmitted: Vec3::ZERO,
                reflected_object: 0,
                signature: 0,
            },
            srgb: Vec3::splat(color),
        }
    }

    /// The flatness guard on one face with corners at `screen` and corner
    /// colours `colors` (floor 2 px, v = 0.2, epsilon 0.1): the edge it
    /// forces, as corner indices, or `None`.
    fn check(screen: [(f32, f32); 3], colors: [f32; 3], expect: Option<(u32, u32)>) {
        let mesh = TriangleMesh::new(
            TriangleId(0),
            [0, 1, 2].map(|k| vertex(screen[k], colors[k])),
        );
        let face = mesh.faces[0];
        let got = mesh
            .flat_long_edge(&face, 0.2, 2.0, 0.1)
            .map(|(a, b)| edge_key(a, b));
        assert_eq!(got, expect, "{screen:?} {colors:?}");
    }

    #[test]
    fn the_flatness_guard_splits_the_long_edge_of_flat_disagreeing_faces() {
        let differ = [0.0, 1.0, 0.0];
        // Right isosceles: h / c = 7.07 / 14.1 = 0.5, not flat.
        check([(0.0, 0.0), (10.0, 0.0), (0.0, 10.0)], differ, None);
        // A sliver: c = 20 (corners 0-1), h = 3, h / c = 0.15 < 0.2.
        check([(0.0, 0.0), (20.0, 0.0), (10.0, 3.0)], differ, Some((0, 1)));
        // The long edge is found whichever corners it joins (1-2 here).
        check([(10.0, 3.0), (0.0, 0.0), (20.0, 0.0)], differ, Some((1, 2)));
        // Just above v: h = 4.2, c = 20, h / c = 0.21.
        check([(0.0, 0.0), (20.0, 0.0), (5.0, 4.2)], differ, None);
        // Flat, but h = 1 is under the 2-px floor: splitting would not end.
        check([(0.0, 0.0), (20.0, 0.0), (10.0, 1.0)], differ, None);
        // Flat, but the corners agree: nothing to resolve.
        check([(0.0, 0.0), (20.0, 0.0), (10.0, 3.0)], [0.5; 3], None);
        // Degenerate (all corners on one point): no edge.
        check([(5.0, 5.0); 3], differ, None);
    }
}
