//! Whitted shading of a batch of samples generation by generation, so that
//! each generation's rays are traced together in packets
//! ([`SceneBvh::closest_hits`](crate::SceneBvh::closest_hits)).
//!
//! Two passes. The first walks the ray trees breadth first: it shades every
//! surface of one depth ([`Tracer::surface_of`]: local Phong with shadow
//! rays, kr, kt, the secondary rays), then traces all the reflection rays of
//! that depth as one batch and all the refraction rays as another (each in
//! sample order, so neighbouring samples' rays share packets), and records
//! each tree node. The second is [`Tracer::shade_tree`], the depth-first walk
//! every sample takes, reading the recorded nodes ([`Recorded`]) instead of
//! tracing on demand; so the samples are the one-at-a-time samples, bit for
//! bit (`scenarios::shade_points_*` checks this).

use std::ops::Range;

use glam::Vec3;
use vtfarm_scene::NONE;

use super::{Rays, Tracer, TreeSource, Visited, VisitedSurface};
use crate::{Ray, Sample, SurfacePoint};

/// One node of a sample's ray tree: a surface, or a ray that hit nothing.
struct Node {
    /// The object the ray into this node hit (`NONE` for a miss).
    object: u32,
    surface: Option<Surface>,
    /// The direction a ray that hit nothing left the scene along.
    escape: Vec3,
}

/// What the first pass found at a surface.
struct Surface {
    see_through: bool,
    local: Vec3,
    kr: Vec3,
    kt: Vec3,
    /// Its light words, in `Recorded::lit_words`.
    lit: Range<usize>,
    /// The nodes its reflection and refraction rays lead to.
    reflection: Option<usize>,
    refraction: Option<usize>,
}

/// A surface waiting to be shaded in the first pass.
struct Pending {
    node: usize,
    point: SurfacePoint,
    incoming: Vec3,
    /// The path length from the eye ([`super::PixelCone`]).
    path: f32,
    rays: Rays,
}

/// See the module docs.
pub(super) fn shade_points(
    tracer: &Tracer<'_>,
    points: &[(SurfacePoint, Vec3)],
    rays: Rays,
) -> Vec<Sample> {
    let scene = tracer.bvh.scene();
    let mut recorded = Recorded {
        nodes: Vec::with_capacity(points.len() * 2),
        lit_words: Vec::new(),
    };
    recorded.nodes.extend(points.iter().map(|(point, _)| Node {
        object: scene.triangles[point.triangle.index()].object.raw(),
        surface: None,
        escape: Vec3::ZERO,
    }));
    let mut pending: Vec<Pending> = points
        .iter()
        .enumerate()
        .map(|(node, &(point, incoming))| Pending {
            node,
            point,
            incoming,
            path: tracer.cone.distance(point.position),
            rays,
        })
        .collect();
    let mut depth = 1;
    while !pending.is_empty() {
        // (parent node, ray, path to the parent) of the next generation, by kind.
        let mut reflections: Vec<(usize, Ray, f32)> = Vec::new();
        let mut refractions: Vec<(usize, Ray, f32)> = Vec::new();
        for p in &pending {
            let start = recorded.lit_words.len();
            let (terms, reflection, refraction) = tracer.surface_of(
                &p.point,
                p.incoming,
                p.path,
                depth,
                p.rays,
                &mut recorded.lit_words,
            );
            reflections.extend(reflection.map(|ray| (p.node, ray, p.path)));
            refractions.extend(refraction.map(|ray| (p.node, ray, p.path)));
            recorded.nodes[p.node].surface = Some(Surface {
                see_through: tracer.bvh.see_through(p.point.triangle),
                local: terms.local,
                kr: terms.kr,
                kt: terms.kt,
                lit: start..recorded.lit_words.len(),
                reflection: None,
                refraction: None,
            });
        }
        pending.clear();
        for (spawned, is_reflection) in [(reflections, true), (refractions, false)] {
            let batch: Vec<Ray> = spawned.iter().map(|&(_, ray, _)| ray).collect();
            let hits = tracer.bvh.closest_hits(&batch, f32::INFINITY);
            for (&(parent, ray, path), hit) in spawned.iter().zip(hits) {
                let node = recorded.nodes.len();
                let parent = recorded.nodes[parent].surface.as_mut();
                let parent = parent.expect("a node spawns rays once shaded");
                if is_reflection {
                    parent.reflection = Some(node);
                } else {
                    parent.refraction = Some(node);
                }
                let object = match hit {
                    None => NONE,
                    Some(hit) => {
                        pending.push(Pending {
                            node,
                            point: tracer.bvh.surface_point(&hit),
                            incoming: ray.direction,
                            path: path + hit.t,
                            rays: Rays::Both,
                        });
                        scene.triangles[hit.triangle.index()].object.raw()
                    }
                };
                recorded.nodes.push(Node {
                    object,
                    surface: None,
                    escape: ray.direction,
                });
            }
        }
        depth += 1;
    }
    (0..points.len())
        .map(|root| tracer.sample_of(&mut recorded, root, rays))
        .collect()
}

/// The first pass's trees, for [`Tracer::shade_tree`].
struct Recorded {
    nodes: Vec<Node>,
    lit_words: Vec<u64>,
}

impl TreeSource for Recorded {
    type Link = usize;

    fn visit(&mut self, index: usize, _: u32, _: Rays, lit: &mut Vec<u64>) -> Visited<usize> {
        let node = &self.nodes[index];
        let Some(surface) = &node.surface else {
            return Visited::Miss(node.escape);
        };
        lit.extend_from_slice(&self.lit_words[surface.lit.clone()]);
        Visited::Surface(VisitedSurface {
            object: node.object,
            see_through: surface.see_through,
            local: surface.local,
            kr: surface.kr,
            kt: surface.kt,
            reflection: surface.reflection,
            refraction: surface.refraction,
        })
    }
}
