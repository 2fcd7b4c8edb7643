//! Closest-hit traversal of obvhs' compressed 8-wide BVH, tuned for the CPU:
//! each node's children are tested at once, hit children are visited nearest
//! first and a popped node is skipped when the closest hit so far already lies
//! before it. obvhs' own traversal (GPU style) orders children by the ray's
//! octant only, so it visits more nodes behind the hit.
//!
//! The box test is obvhs' (`t = q * (extent / d) + (p - o) / d` on the
//! quantised child bounds), with 0 instead of obvhs' 1e-4 as the lower bound:
//! it culls exactly the boxes obvhs culls, never one with a hit in `(0, tmax)`.

use std::cell::RefCell;

use glam::Vec3A;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::ray::Ray as BvhRay;

thread_local! {
    /// The traversal stack (node index, entry distance), kept per thread so
    /// that a query neither allocates nor clears a large array.
    static STACK: RefCell<Vec<(u32, f32)>> = RefCell::new(Vec::with_capacity(256));
}

/// Walks `bvh` for `ray`, calling `test(slot)` for every primitive slot whose
/// leaf box the ray enters before `tmax`; `test` returns the new `tmax`
/// (`f32::INFINITY` when it found nothing closer).
#[inline(always)]
pub(crate) fn closest<F: FnMut(usize) -> f32>(bvh: &CwBvh, ray: &BvhRay, test: F) {
    STACK.with_borrow_mut(|stack| {
        stack.clear();
        walk(bvh, ray, test, stack);
    });
}

#[inline(always)]
fn walk<F: FnMut(usize) -> f32>(
    bvh: &CwBvh,
    ray: &BvhRay,
    mut test: F,
    stack: &mut Vec<(u32, f32)>,
) {
    let mut tmax = ray.tmax;
    stack.push((0, 0.0));
    while let Some((index, entry)) = stack.pop() {
        if entry > tmax {
            continue;
        }
        let node = &bvh.nodes[index as usize];
        let extent = node.compute_extent();
        let scale = extent * ray.inv_direction;
        let offset = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
        let mut near = [0f32; 8];
        let mut far = [tmax; 8];
        for (axis, (lo, hi)) in [
            (&node.child_min_x, &node.child_max_x),
            (&node.child_min_y, &node.child_max_y),
            (&node.child_min_z, &node.child_max_z),
        ]
        .into_iter()
        .enumerate()
        {
            for i in 0..8 {
                let a = lo[i] as f32 * scale[axis] + offset[axis];
                let b = hi[i] as f32 * scale[axis] + offset[axis];
                near[i] = near[i].max(a.min(b));
                far[i] = far[i].min(a.max(b));
            }
        }
        let (order, hits) = nearest_first(node, &near, |i| near[i] <= far[i]);
        // Leaves now, nearest first; inner children onto the stack farthest
        // first so the nearest is popped next.
        let mut inner = [(0u32, 0f32); 8];
        let mut inner_count = 0;
        for &(t, child) in &order[..hits] {
            if t > tmax {
                break;
            }
            let child = child as usize;
            if node.is_leaf(child) {
                let (first, count) = node.child_primitives(child);
                for slot in first..first + count {
                    tmax = tmax.min(test(slot as usize));
                }
            } else {
                inner[inner_count] = (node.child_node_index(child), t);
                inner_count += 1;
            }
        }
        stack.extend(inner[..inner_count].iter().rev());
    }
}

/// The non-empty children that `hit` accepts as (entry distance, slot),
/// nearest first (insertion sort of at most 8), and their number.
#[inline(always)]
fn nearest_first(
    node: &CwBvhNode,
    near: &[f32; 8],
    hit: impl Fn(usize) -> bool,
) -> ([(f32, u8); 8], usize) {
    let mut order = [(0f32, 0u8); 8];
    let mut hits = 0;
    for (i, &t) in near.iter().enumerate() {
        if node.child_meta[i] != 0 && hit(i) {
            let mut at = hits;
            while at > 0 && order[at - 1].0 > t {
                order[at] = order[at - 1];
                at -= 1;
            }
            order[at] = (t, i as u8);
            hits += 1;
        }
    }
    (order, hits)
}

/// Rays per packet of [`closest_packet`]: one bit each in a `u8` mask.
pub(crate) const PACKET: usize = 8;

/// [`closest`] for up to [`PACKET`] rays at once (camera rays, a package's
/// reflection rays): a node's child bounds are decoded once for the packet,
/// each ray runs the same box test as alone and keeps its own `tmax`, so every
/// ray is offered every primitive it would be offered alone (results are
/// identical). `test(ray, slot)` returns that ray's new `tmax`.
pub(crate) fn closest_packet<F: FnMut(usize, usize) -> f32>(
    bvh: &CwBvh,
    rays: &[BvhRay],
    mut test: F,
) {
    debug_assert!(rays.len() <= PACKET);
    let mut tmax = [0f32; PACKET];
    for (t, ray) in tmax.iter_mut().zip(rays) {
        *t = ray.tmax;
    }
    let all = ((1u32 << rays.len()) - 1) as u8;
    let mut stack: Vec<(u32, u8)> = Vec::with_capacity(64);
    stack.push((0, all));
    while let Some((index, active)) = stack.pop() {
        let node = &bvh.nodes[index as usize];
        let extent = node.compute_extent();
        let p = Vec3A::from(node.p);
        let mut q = [[0f32; 8]; 6];
        for (q, bytes) in q.iter_mut().zip([
            &node.child_min_x,
            &node.child_max_x,
            &node.child_min_y,
            &node.child_max_y,
            &node.child_min_z,
            &node.child_max_z,
        ]) {
            for i in 0..8 {
                q[i] = bytes[i] as f32;
            }
        }
        // Per child: the rays that enter it, and the nearest entry among them.
        let mut child_rays = [0u8; 8];
        let mut child_near = [f32::INFINITY; 8];
        let mut remaining = active;
        while remaining != 0 {
            let r = remaining.trailing_zeros() as usize;
            remaining &= remaining - 1;
            let ray = &rays[r];
            let scale = extent * ray.inv_direction;
            let offset = (p - ray.origin) * ray.inv_direction;
            let mut near = [0f32; 8];
            let mut far = [tmax[r]; 8];
            for axis in 0..3 {
                for i in 0..8 {
                    let a = q[2 * axis][i] * scale[axis] + offset[axis];
                    let b = q[2 * axis + 1][i] * scale[axis] + offset[axis];
                    near[i] = near[i].max(a.min(b));
                    far[i] = far[i].min(a.max(b));
                }
            }
            for i in 0..8 {
                if near[i] <= far[i] {
                    child_rays[i] |= 1 << r;
                    child_near[i] = child_near[i].min(near[i]);
                }
            }
        }
        let (order, hits) = nearest_first(node, &child_near, |i| child_rays[i] != 0);
        let mut inner = [(0u32, 0u8); 8];
        let mut inner_count = 0;
        for &(_, child) in &order[..hits] {
            let child = child as usize;
            if node.is_leaf(child) {
                let (first, count) = node.child_primitives(child);
                for slot in first..first + count {
                    let mut remaining = child_rays[child];
                    while remaining != 0 {
                        let r = remaining.trailing_zeros() as usize;
                        remaining &= remaining - 1;
                        tmax[r] = tmax[r].min(test(r, slot as usize));
                    }
                }
            } else {
                inner[inner_count] = (node.child_node_index(child), child_rays[child]);
                inner_count += 1;
            }
        }
        stack.extend(inner[..inner_count].iter().rev());
    }
}
