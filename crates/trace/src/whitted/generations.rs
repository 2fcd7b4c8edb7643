//! Whitted shading of a batch of samples generation by generation, so that
//! each generation's rays are traced together in packets
//! ([`SceneBvh::closest_hits`](crate::SceneBvh::closest_hits)).
//!
//! Two passes. The first walks the ray trees breadth first: it shades every
//! surface of one depth (local Phong with shadow rays, kr, kt, the secondary
//! rays), then traces all the reflection rays of that depth as one batch and
//! all the refraction rays as another (each in sample order, so neighbouring
//! samples' rays share packets), and records each tree node. The second
//! walks each sample's tree depth first in the order of
//! [`Tracer::shade_surface`]'s recursion, adding the colours and feeding the
//! signature the same words in the same order. Each node's figures come from
//! the same expressions as in the recursion, so the samples are the
//! recursion's, bit for bit (`scenarios::shade_points_*` checks this).

use std::ops::Range;

use glam::Vec3;
use vtfarm_scene::{NONE, ObjectId};

use super::{Rays, Shaded, Signature, Tracer, light_index, sample, word};
use crate::{Ray, Sample, SurfacePoint};

/// One node of a sample's ray tree: a surface, or a ray that hit nothing.
struct Node {
    /// The object the ray into this node hit (`NONE` for a miss).
    object: ObjectId,
    surface: Option<Surface>,
}

/// What the first pass found at a surface.
struct Surface {
    local: Vec3,
    kr: Vec3,
    kt: Vec3,
    /// The `LIT` words of the lights that reach it, in `lit_words`.
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
    depth: u32,
    weight: f32,
    rays: Rays,
}

/// A secondary ray of the next generation and the node it leaves from.
struct Spawned {
    parent: usize,
    ray: Ray,
    weight: f32,
}

/// See the module docs.
pub(super) fn shade_points(
    tracer: &Tracer<'_>,
    points: &[(SurfacePoint, Vec3)],
    rays: Rays,
) -> Vec<Sample> {
    let settings = &tracer.settings;
    let max_depth = settings.max_depth.max(1);
    let mut nodes: Vec<Node> = Vec::with_capacity(points.len() * 2);
    let mut lit_words = Vec::new();
    let mut pending: Vec<Pending> = points
        .iter()
        .enumerate()
        .map(|(node, &(point, incoming))| Pending {
            node,
            point,
            incoming,
            depth: 1,
            weight: 1.0,
            rays,
        })
        .collect();
    nodes.extend(points.iter().map(|(point, _)| Node {
        object: tracer.bvh.scene().triangles[point.triangle as usize].object,
        surface: None,
    }));

    while !pending.is_empty() {
        let mut reflections = Vec::new();
        let mut refractions = Vec::new();
        let depth = pending[0].depth;
        for p in &pending {
            // As in `shade_surface`: which words the recursion adds.
            let tracked = p.weight >= settings.signature_min_weight;
            let lights_tracked = tracked && p.rays == Rays::Both;
            let start = lit_words.len();
            let terms = tracer.terms(&p.point, p.incoming, &mut |light| {
                if lights_tracked {
                    lit_words.push(word::LIT + light_index(tracer.lighting, light));
                }
            });
            if p.depth < max_depth {
                if let Some(ray) = terms.reflection {
                    let weight = p.weight * terms.kr.max_element();
                    reflections.push(Spawned {
                        parent: p.node,
                        ray,
                        weight,
                    });
                }
                if let Some(ray) = terms.refraction.filter(|_| p.rays == Rays::Both) {
                    let weight = p.weight * terms.kt.max_element();
                    refractions.push(Spawned {
                        parent: p.node,
                        ray,
                        weight,
                    });
                }
            }
            nodes[p.node].surface = Some(Surface {
                local: terms.local,
                kr: terms.kr,
                kt: terms.kt,
                lit: start..lit_words.len(),
                reflection: None,
                refraction: None,
            });
        }

        pending.clear();
        for (spawned, is_reflection) in [(reflections, true), (refractions, false)] {
            let batch: Vec<Ray> = spawned.iter().map(|s| s.ray).collect();
            let hits = tracer.bvh.closest_hits(&batch, f32::INFINITY);
            for (s, hit) in spawned.iter().zip(hits) {
                let node = nodes.len();
                let parent = nodes[s.parent].surface.as_mut();
                let parent = parent.expect("a spawning node was shaded");
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
                            incoming: s.ray.direction,
                            depth: depth + 1,
                            weight: s.weight,
                            rays: Rays::Both,
                        });
                        tracer.bvh.scene().triangles[hit.triangle as usize].object
                    }
                };
                nodes.push(Node {
                    object,
                    surface: None,
                });
            }
        }
    }

    let tree = Trees {
        tracer,
        nodes: &nodes,
        lit_words: &lit_words,
    };
    (0..points.len())
        .map(|root| {
            let mut signature = Signature::new();
            let shaded = tree.shade(root, 1, 1.0, rays, &mut signature);
            sample(shaded, signature)
        })
        .collect()
}

/// The second pass over the first pass's trees.
struct Trees<'a> {
    tracer: &'a Tracer<'a>,
    nodes: &'a [Node],
    lit_words: &'a [u64],
}

impl Trees<'_> {
    /// `shade_surface` (or `radiance_of`'s miss) of node `index`, from the
    /// recorded figures.
    fn shade(
        &self,
        index: usize,
        depth: u32,
        weight: f32,
        rays: Rays,
        signature: &mut Signature,
    ) -> Shaded {
        let settings = &self.tracer.settings;
        let tracked = weight >= settings.signature_min_weight;
        let node = &self.nodes[index];
        let Some(surface) = &node.surface else {
            if tracked {
                signature.add(word::MISS);
            }
            return Shaded {
                color: self.tracer.lighting.background,
                reflected: Vec3::ZERO,
                transmitted: Vec3::ZERO,
                reflected_object: NONE,
            };
        };
        if tracked {
            signature.add(u64::from(node.object));
        }
        if tracked && rays == Rays::Both {
            for &word in &self.lit_words[surface.lit.clone()] {
                signature.add(word);
            }
            signature.add(word::LIGHTS_END);
        }
        let mut shaded = Shaded {
            color: surface.local,
            reflected: Vec3::ZERO,
            transmitted: Vec3::ZERO,
            reflected_object: NONE,
        };
        if let Some(child) = surface.reflection {
            if tracked {
                signature.add(word::REFLECT);
            }
            let kr = surface.kr;
            let branch = weight * kr.max_element();
            let seen = self.shade(child, depth + 1, branch, Rays::Both, signature);
            let object = self.nodes[child].object;
            if depth == 1 && branch < settings.signature_min_weight {
                signature.add(u64::from(object));
            }
            shaded.reflected = kr * seen.color;
            shaded.reflected_object = object;
            shaded.color += shaded.reflected;
        }
        if let Some(child) = surface.refraction {
            if tracked {
                signature.add(word::REFRACT);
            }
            let kt = surface.kt;
            let seen = self.shade(
                child,
                depth + 1,
                weight * kt.max_element(),
                Rays::Both,
                signature,
            );
            shaded.transmitted = kt * seen.color;
            shaded.color += shaded.transmitted;
        }
        shaded
    }
}
