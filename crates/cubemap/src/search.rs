//! The reflection-point search in the reflector cube maps (paper §4.2–4.3,
//! hidden vertices §6.1).
//!
//! The search runs in a gnomonic chart of directions from the maps' centre,
//! tangent at the start direction (a cube face centred on the start, so the
//! search never meets a seam). At a chart point x the maps give the surface
//! point P and normal N; B is the bisector of P→eye and P→V, and the
//! projected bisector direction b(x) is the chart image of the move from
//! the tip of N to the tip of B at P (§4.2, Fig. 3), taken through the
//! projection's differential. The reflection point is the sink b = 0.
//!
//! Steps follow the midpoint method (second-order Runge–Kutta): b at x,
//! then at half a step along it, then a full step along the midpoint's
//! direction; the step grows when the two directions agree and shrinks
//! when they do not (§4.3). A step that does not lower the error is
//! rejected and retried at half the length.
//!
//! Deviation: on concave pieces the field b is not attracting when the eye
//! and the vertex lie beyond the mirror's focal distance (R is then a
//! saddle or maximum of the path length), which is the cockpit glass's case
//! up its 0.45 m radius. The field is therefore preconditioned with the
//! inverse of its Jacobian (two extra lookups at the start and after a
//! rejected step), which leaves the sink where it is, makes it attracting
//! for convex and concave pieces alike, and turns |b| into an estimate of
//! the distance to it (the step never exceeds that estimate).
//!
//! A vertex behind the tangent plane at P (the hidden region, §6.1) uses
//! its mirror image about that plane in the bisector, so its search ends
//! where the eye ray towards it crosses the reflector.

use glam::{Mat2, Vec2, Vec3};

use crate::maps::{ReflectorMaps, SurfaceSample};

/// When a search stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SearchSettings {
    /// Converged when E = (1 - B·N)/2 is below this (evaluated as
    /// |B - N|²/4, which is the same for unit vectors but keeps precision
    /// near zero).
    pub epsilon: f32,
    /// Midpoint steps at most (each costs two map lookups).
    pub max_iterations: u32,
}

impl Default for SearchSettings {
    fn default() -> Self {
        SearchSettings {
            epsilon: 1e-9,
            max_iterations: 40,
        }
    }
}

/// Where a vertex lies with respect to the reflector and the eye (§6.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Region {
    /// Seen in the reflector.
    Reflected,
    /// Behind the reflector as seen from the eye; the reflection point is
    /// where the eye ray towards the vertex crosses the reflector.
    Hidden,
    /// The reflection point lies on the extension beyond an open
    /// reflector's rim (in front of or behind it).
    Unreflected,
    /// The search did not converge.
    Failed,
}

/// The search's result for one vertex.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VirtualVertex {
    pub region: Region,
    /// The reflection point R on the maps' surface.
    pub reflection_point: Vec3,
    /// V': behind R along the eye ray at |V - R| for a vertex in front of
    /// the tangent plane at R; the mirror image of V about that plane (in
    /// front of the reflector, so the depth test clips it) for one behind.
    pub virtual_position: Vec3,
    /// Whether V lies in front of the tangent plane at R (seen from the eye).
    pub in_front: bool,
    pub error: f32,
    pub iterations: u32,
}

impl VirtualVertex {
    pub const FAILED: VirtualVertex = VirtualVertex {
        region: Region::Failed,
        reflection_point: Vec3::ZERO,
        virtual_position: Vec3::ZERO,
        in_front: false,
        error: f32::INFINITY,
        iterations: 0,
    };
}

/// Searches the reflection point of `vertex` seen from `eye`.
pub fn search(
    maps: &ReflectorMaps,
    eye: Vec3,
    vertex: Vec3,
    settings: &SearchSettings,
) -> VirtualVertex {
    let centre = maps.layout.centre;
    let to_eye = (eye - centre).normalize_or_zero();
    let to_vertex = (vertex - centre).normalize_or_zero();
    // The bisector at the centre is near R on a closed reflector; an open
    // one starts in its middle. A start must lie on the reflector itself
    // (not its continuation) and face the eye.
    let starts = [
        (to_eye + to_vertex).normalize_or_zero(),
        (maps.centroid - centre).normalize_or_zero(),
        to_eye,
    ];
    let field = |start: Vec3| Field {
        maps,
        eye,
        vertex,
        chart: Chart::new(centre, start),
    };
    let first = starts
        .into_iter()
        .filter(|start| *start != Vec3::ZERO)
        .map(field)
        .find_map(|field| {
            let first = field.eval(Vec2::ZERO)?;
            first.surface.on_reflector.then_some((field, first))
        });
    match first {
        Some((field, first)) => field.run(first, settings),
        None => VirtualVertex::FAILED,
    }
}

/// A gnomonic chart of directions from `centre`, tangent at `axis`.
#[derive(Clone, Copy, Debug)]
struct Chart {
    centre: Vec3,
    axis: Vec3,
    e1: Vec3,
    e2: Vec3,
}

impl Chart {
    fn new(centre: Vec3, axis: Vec3) -> Self {
        let (e1, e2) = axis.any_orthonormal_pair();
        Chart {
            centre,
            axis,
            e1,
            e2,
        }
    }

    fn direction(&self, x: Vec2) -> Vec3 {
        self.axis + self.e1 * x.x + self.e2 * x.y
    }

    /// The chart image of an infinitesimal move `delta` at `p` (the
    /// projection's differential: no cancellation between two nearby
    /// projected points).
    fn project_move(&self, p: Vec3, delta: Vec3) -> Vec2 {
        let d = p - self.centre;
        let depth = d.dot(self.axis).max(1e-6);
        let image = Vec2::new(d.dot(self.e1), d.dot(self.e2)) / depth;
        (Vec2::new(delta.dot(self.e1), delta.dot(self.e2)) - image * delta.dot(self.axis)) / depth
    }
}

/// The projected-bisector field for one eye and vertex.
struct Field<'a> {
    maps: &'a ReflectorMaps,
    eye: Vec3,
    vertex: Vec3,
    chart: Chart,
}

/// The field at one chart point.
#[derive(Clone, Copy, Debug)]
struct Eval {
    x: Vec2,
    surface: SurfaceSample,
    /// Unit normal, facing the eye.
    normal: Vec3,
    bisector: Vec2,
    error: f32,
    in_front: bool,
}

/// Chart points farther out than this are more than ~84° from the start.
const CHART_LIMIT: f32 = 10.0;

impl Field<'_> {
    fn eval(&self, x: Vec2) -> Option<Eval> {
        if x.length() > CHART_LIMIT {
            return None;
        }
        let surface = self.maps.sample(self.chart.direction(x))?;
        let p = surface.position;
        let normal = surface.normal;
        // The reflector mirrors on the side its normals face; points facing
        // away from the eye cannot reflect anything to it.
        if normal.dot(self.eye - p) <= 0.0 {
            return None;
        }
        let height = (self.vertex - p).dot(normal);
        let in_front = height >= 0.0;
        let seen = if in_front {
            self.vertex
        } else {
            self.vertex - 2.0 * height * normal
        };
        let b = ((self.eye - p).normalize_or_zero() + (seen - p).normalize_or_zero())
            .normalize_or(normal);
        let bisector = self.chart.project_move(p, b - normal);
        Some(Eval {
            x,
            surface,
            normal,
            bisector,
            error: (b - normal).length_squared() * 0.25,
            in_front,
        })
    }

    /// The preconditioner -J⁻¹ at `at` (forward differences of about two
    /// texels); the identity where J is singular.
    fn preconditioner(&self, at: &Eval) -> Mat2 {
        let h = 4.0 / self.maps.layout.resolution as f32;
        let column = |dx: Vec2| self.eval(at.x + dx).map(|e| (e.bisector - at.bisector) / h);
        match (column(Vec2::X * h), column(Vec2::Y * h)) {
            (Some(c0), Some(c1)) => {
                let j = Mat2::from_cols(c0, c1);
                if j.determinant().abs() > 1e-12 {
                    -j.inverse()
                } else {
                    Mat2::IDENTITY
                }
            }
            _ => Mat2::IDENTITY,
        }
    }

    fn run(&self, first: Eval, settings: &SearchSettings) -> VirtualVertex {
        let mut current = first;
        let mut m = self.preconditioner(&current);
        let mut step_cap = 0.5f32;
        let mut iterations = 0;
        while current.error >= settings.epsilon && iterations < settings.max_iterations {
            iterations += 1;
            let g_start = m * current.bisector;
            let distance = g_start.length().max(f32::MIN_POSITIVE);
            let step = distance.min(step_cap);
            let accepted = self
                .eval(current.x + g_start * (0.5 * step / distance))
                .and_then(|mid| {
                    let g_mid = m * mid.bisector;
                    let direction = g_mid.normalize_or_zero();
                    let next = self.eval(current.x + direction * step)?;
                    (next.error < current.error).then(|| (next, direction.dot(g_start / distance)))
                });
            match accepted {
                Some((next, agreement)) => {
                    current = next;
                    step_cap = if agreement > 0.99 {
                        step * 2.0
                    } else if agreement < 0.9 {
                        step * 0.5
                    } else {
                        step
                    };
                }
                None => {
                    step_cap = step * 0.5;
                    m = self.preconditioner(&current);
                }
            }
        }
        self.finish(&current, iterations, settings)
    }

    fn finish(&self, at: &Eval, iterations: u32, settings: &SearchSettings) -> VirtualVertex {
        let r = at.surface.position;
        let region = if at.error >= settings.epsilon {
            Region::Failed
        } else if !at.surface.on_reflector {
            Region::Unreflected
        } else if at.in_front {
            Region::Reflected
        } else {
            Region::Hidden
        };
        let virtual_position = if at.in_front {
            r + (r - self.eye).normalize_or_zero() * (self.vertex - r).length()
        } else {
            self.vertex - 2.0 * (self.vertex - r).dot(at.normal) * at.normal
        };
        VirtualVertex {
            region,
            reflection_point: r,
            virtual_position,
            in_front: at.in_front,
            error: at.error,
            iterations,
        }
    }
}
