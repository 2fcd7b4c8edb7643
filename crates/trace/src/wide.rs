//! Closest-hit traversal of obvhs' compressed 8-wide BVH, tuned for the CPU:
//! each node's children are tested at once, hit children are visited nearest
//! first and a popped node is skipped when the closest hit so far already lies
//! before it. obvhs' own traversal (GPU style) orders children by the ray's
//! octant only, so it visits more nodes behind the hit.
//!
//! The box test is obvhs' (`t = q * (extent / d) + (p - o) / d` on the
//! quantised child bounds), with 0 instead of obvhs' 1e-4 as the lower bound:
//! it culls exactly the boxes obvhs culls, never one with a hit in `(0, tmax)`.

use std::mem::MaybeUninit;

use glam::Vec3A;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::ray::Ray as BvhRay;

use crate::leaf::bits;

/// Traversal stack entries: a popped node pushes at most 8 inner children,
/// so a tree of at most [`crate::bvh::CW_STACK_LIMIT`] inner levels holds at
/// most 1 + 7 per level (the depth is checked when the tree is built).
const STACK: usize = 1 + 7 * crate::bvh::CW_STACK_LIMIT + 8;

/// What a walk does at a leaf whose box a ray enters.
///
/// A trait rather than a closure: closures are compiled apart from the AVX2
/// build of the query that calls the walk, and left out of line they cost a
/// call per leaf in baseline code.
pub(crate) trait LeafTest {
    /// Tests the primitive slots `first..first + count` for ray `ray` of the
    /// walk (0 for a single-ray walk); returns that ray's new `tmax`
    /// (`f32::INFINITY` when nothing closer was found; for [`any`], any
    /// finite value means a hit).
    fn test(&mut self, ray: usize, first: u32, count: u32) -> f32;
}

/// Walks `bvh` for `ray`, calling `leaf.test` for every leaf whose box the
/// ray enters before `tmax`.
///
/// `Isa` says which box test to run; the AVX2 one only from code compiled
/// for AVX2 on a CPU that has it.
///
/// Per node: the entered leaves are tested nearest first, then the walk goes
/// on into the nearest inner child that still starts before `tmax`, the
/// others pushed farthest first (a node with one such child pushes nothing).
/// A popped node is skipped when the closest hit so far lies before it.
///
/// The stack is left uninitialised: zeroing its 1.8 kB per ray cost a fifth
/// of an incoherent ray, and a thread-local stack kept the walk out of the
/// caller's AVX2 build (the box test became a call per node).
#[inline(always)]
pub(crate) fn closest(isa: Isa, bvh: &CwBvh, ray: &BvhRay, leaf: &mut impl LeafTest) {
    let mut stack = [MaybeUninit::<(u32, f32)>::uninit(); STACK];
    let mut pending = 0;
    let mut tmax = ray.tmax;
    let mut index = 0u32;
    'walk: loop {
        let node = &bvh.nodes[index as usize];
        let (near, entered) = entry_distances(isa, node, ray, tmax);
        let tmax_at_node = tmax;
        let mut leaves = entered & !node.imask;
        while leaves != 0 {
            let child = nearest(&near, leaves);
            if near[child] > tmax {
                break; // and so are the farther ones
            }
            leaves &= !(1 << child);
            let (first, count) = node.child_primitives(child);
            tmax = tmax.min(leaf.test(0, first, count));
        }
        let mut inner = entered & node.imask;
        if tmax < tmax_at_node {
            // A leaf brought the hit closer: drop the children now behind it.
            for child in bits(inner) {
                if near[child] > tmax {
                    inner &= !(1 << child);
                }
            }
        }
        match inner.count_ones() {
            0 => {
                while pending > 0 {
                    pending -= 1;
                    // SAFETY: entries below `pending` were written (pushes
                    // write first).
                    let (next, entry) = unsafe { stack[pending].assume_init() };
                    if entry <= tmax {
                        index = next;
                        continue 'walk;
                    }
                }
                return;
            }
            1 => index = node.child_node_index(inner.trailing_zeros() as usize),
            count => {
                let order = sorted(&near, inner);
                for &(t, child) in order[1..count as usize].iter().rev() {
                    stack[pending].write((node.child_node_index(child as usize), t));
                    pending += 1;
                }
                index = node.child_node_index(order[0].1 as usize);
            }
        }
    }
}

/// Whether `leaf.test` finds a hit in any leaf whose box the ray enters;
/// stops at the first (shadow rays). Order does not matter here: the first
/// hit ends the walk.
#[inline(always)]
pub(crate) fn any(isa: Isa, bvh: &CwBvh, ray: &BvhRay, leaf: &mut impl LeafTest) -> bool {
    // Uninitialised, as in `closest`.
    let mut stack = [MaybeUninit::<u32>::uninit(); STACK];
    stack[0].write(0);
    let mut pending = 1;
    while pending > 0 {
        pending -= 1;
        // SAFETY: entries below `pending` were written (pushes write first).
        let index = unsafe { stack[pending].assume_init() };
        let node = &bvh.nodes[index as usize];
        let (_, entered) = entry_distances(isa, node, ray, ray.tmax);
        for child in bits(entered & !node.imask) {
            let (first, count) = node.child_primitives(child);
            if leaf.test(0, first, count) < f32::INFINITY {
                return true;
            }
        }
        for child in bits(entered & node.imask) {
            stack[pending].write(node.child_node_index(child));
            pending += 1;
        }
    }
    false
}

/// Which build of the 8-child box test a walk uses (both give the same
/// entry distances, bit for bit: the same operations, no fused multiply-add).
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Isa {
    /// Plain Rust.
    Portable,
    /// `std::arch` AVX2 intrinsics: all 8 children in one register. Only
    /// for code compiled with AVX2 enabled, on a CPU that has it.
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

/// The child in `mask` with the smallest entry distance (the lowest index
/// among equals).
#[inline(always)]
fn nearest(near: &[f32; 8], mask: u8) -> usize {
    let mut best = mask.trailing_zeros() as usize;
    for child in bits(mask & (mask - 1)) {
        if near[child] < near[best] {
            best = child;
        }
    }
    best
}

/// The children in `mask` as (entry distance, child), nearest first
/// (insertion sort of at most 8); entries past `mask.count_ones()` are unused.
#[inline(always)]
fn sorted(near: &[f32; 8], mask: u8) -> [(f32, u8); 8] {
    let mut order = [(0f32, 0u8); 8];
    for (count, child) in bits(mask).enumerate() {
        let t = near[child];
        let mut at = count;
        while at > 0 && order[at - 1].0 > t {
            order[at] = order[at - 1];
            at -= 1;
        }
        order[at] = (t, child as u8);
    }
    order
}

/// The distance at which `ray` enters each child box of `node` before
/// `tmax`, `f32::INFINITY` for a child it misses or an empty slot, and the
/// mask of the entered children (bit `i` for child `i`).
#[inline(always)]
fn entry_distances(isa: Isa, node: &CwBvhNode, ray: &BvhRay, tmax: f32) -> ([f32; 8], u8) {
    match isa {
        Isa::Portable => entry_distances_portable(node, ray, tmax),
        // SAFETY: `Isa::Avx2` is only passed where the CPU has AVX2.
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 => unsafe { entry_distances_avx2(node, ray, tmax) },
    }
}

#[inline(always)]
fn entry_distances_portable(node: &CwBvhNode, ray: &BvhRay, tmax: f32) -> ([f32; 8], u8) {
    let extent = node.compute_extent();
    let scale = extent * ray.inv_direction;
    let offset = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
    let mut near = [0f32; 8];
    let mut far = [tmax; 8];
    // One call per axis with the scalars picked out (a loop over the axes
    // indexing `scale[axis]` kept the compiler from vectorising the lanes).
    slab(
        &node.child_min_x,
        &node.child_max_x,
        scale.x,
        offset.x,
        &mut near,
        &mut far,
    );
    slab(
        &node.child_min_y,
        &node.child_max_y,
        scale.y,
        offset.y,
        &mut near,
        &mut far,
    );
    slab(
        &node.child_min_z,
        &node.child_max_z,
        scale.z,
        offset.z,
        &mut near,
        &mut far,
    );
    let mut entries = [f32::INFINITY; 8];
    let mut entered = 0;
    for i in 0..8 {
        if node.child_meta[i] != 0 && near[i] <= far[i] {
            entries[i] = near[i];
            entered |= 1 << i;
        }
    }
    (entries, entered)
}

/// [`entry_distances`] with AVX2: the same operations on 8 lanes at once
/// (`_mm256_min_ps` is [`min`], `_mm256_max_ps` is [`max`]).
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn entry_distances_avx2(node: &CwBvhNode, ray: &BvhRay, tmax: f32) -> ([f32; 8], u8) {
    use std::arch::x86_64::*;
    let extent = node.compute_extent();
    let scale = extent * ray.inv_direction;
    let offset = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
    // SAFETY: each load reads the 8 bytes of one `[u8; 8]` field; the store
    // writes the 8 lanes of `entries`.
    unsafe {
        let lanes = |bytes: &[u8; 8]| _mm256_cvtepu8_epi32(_mm_loadl_epi64(bytes.as_ptr().cast()));
        let mut near = _mm256_setzero_ps();
        let mut far = _mm256_set1_ps(tmax);
        for (lo, hi, scale, offset) in [
            (&node.child_min_x, &node.child_max_x, scale.x, offset.x),
            (&node.child_min_y, &node.child_max_y, scale.y, offset.y),
            (&node.child_min_z, &node.child_max_z, scale.z, offset.z),
        ] {
            let (entry, exit) = near_far(lo, hi, scale);
            let (scale, offset) = (_mm256_set1_ps(scale), _mm256_set1_ps(offset));
            let a = _mm256_add_ps(
                _mm256_mul_ps(_mm256_cvtepi32_ps(lanes(entry)), scale),
                offset,
            );
            let b = _mm256_add_ps(
                _mm256_mul_ps(_mm256_cvtepi32_ps(lanes(exit)), scale),
                offset,
            );
            near = _mm256_max_ps(near, a);
            far = _mm256_min_ps(far, b);
        }
        let nonempty = _mm256_cmpgt_epi32(lanes(&node.child_meta), _mm256_setzero_si256());
        let enters = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_LE_OQ>(near, far),
            _mm256_castsi256_ps(nonempty),
        );
        let entries = _mm256_blendv_ps(_mm256_set1_ps(f32::INFINITY), near, enters);
        let mut out = [0f32; 8];
        _mm256_storeu_ps(out.as_mut_ptr(), entries);
        (out, _mm256_movemask_ps(enters) as u8)
    }
}

/// Narrows each child's entry/exit interval by its slab on one axis
/// (quantised bounds `lo`, `hi`; `t = q * scale + offset`).
#[inline(always)]
fn slab(
    lo: &[u8; 8],
    hi: &[u8; 8],
    scale: f32,
    offset: f32,
    near: &mut [f32; 8],
    far: &mut [f32; 8],
) {
    let (entry, exit) = near_far(lo, hi, scale);
    for i in 0..8 {
        let a = entry[i] as f32 * scale + offset;
        let b = exit[i] as f32 * scale + offset;
        near[i] = max(near[i], a);
        far[i] = min(far[i], b);
    }
}

/// The quantised planes a ray crosses first and last on one axis: `lo`
/// then `hi` when `scale` (the axis's `extent / d`) is positive, else the
/// other way round. `q * scale + offset` is monotonic in `q` and
/// `lo <= hi` in every child, so this picks exactly what a per-lane min and
/// max of the two distances would (the same values, without the min and max).
#[inline(always)]
fn near_far<'a>(lo: &'a [u8; 8], hi: &'a [u8; 8], scale: f32) -> (&'a [u8; 8], &'a [u8; 8]) {
    if scale < 0.0 { (hi, lo) } else { (lo, hi) }
}

/// `a.min(b)` for numbers that are not NaN, as one SIMD instruction:
/// `f32::min`'s NaN rule costs a compare and a blend per lane. Nothing here
/// is NaN: obvhs' `inv_direction` is finite (its `safe_inverse`), and so are
/// node bounds and ray origins (`bvh_ray` refuses others).
#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// `a.max(b)` for numbers that are not NaN (see [`min`]).
#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// Rays per packet of [`closest_packet`]: one bit each in a `u8` mask.
pub(crate) const PACKET: usize = 8;

/// [`closest`] for up to [`PACKET`] rays at once (camera rays, a package's
/// reflection rays): the rays walk the tree together, each running the same
/// box test as alone with its own `tmax`, so every ray is offered every
/// primitive it would be offered alone (results are identical).
/// `leaf.test(r, ..)` tests a leaf for ray `rays[r]`.
#[inline(always)]
pub(crate) fn closest_packet(isa: Isa, bvh: &CwBvh, rays: &[BvhRay], leaf: &mut impl LeafTest) {
    debug_assert!(rays.len() <= PACKET);
    let mut tmax = [0f32; PACKET];
    for (t, ray) in tmax.iter_mut().zip(rays) {
        *t = ray.tmax;
    }
    let all = ((1u32 << rays.len()) - 1) as u8;
    // (node, its rays, the nearest of their entries); uninitialised as in
    // `closest`.
    let mut stack = [MaybeUninit::<(u32, u8, f32)>::uninit(); STACK];
    stack[0].write((0, all, 0.0));
    let mut pending = 1;
    while pending > 0 {
        pending -= 1;
        // SAFETY: entries below `pending` were written (pushes write first).
        let (index, active, entry) = unsafe { stack[pending].assume_init() };
        // Skip a node every ray of it has a hit before (each ray's own box
        // test would cull it).
        if bits(active).all(|r| entry > tmax[r]) {
            continue;
        }
        let node = &bvh.nodes[index as usize];
        // Per ray its entries; per child the rays that enter it and the
        // nearest entry among them.
        let mut ray_near = [[f32::INFINITY; 8]; PACKET];
        let mut child_rays = [0u8; 8];
        let mut child_near = [f32::INFINITY; 8];
        let mut entered = 0u8;
        for r in bits(active) {
            let (near, ray_entered) = entry_distances(isa, node, &rays[r], tmax[r]);
            entered |= ray_entered;
            // Branch-free, so that it runs lane-parallel (a miss is +inf,
            // which leaves the minimum alone).
            for i in 0..8 {
                child_rays[i] |= u8::from(near[i] < f32::INFINITY) << r;
                child_near[i] = min(child_near[i], near[i]);
            }
            ray_near[r] = near;
        }
        let order = sorted(&child_near, entered);
        let mut inner = [(0u32, 0u8, 0f32); 8];
        let mut inner_count = 0;
        for &(near, child) in &order[..entered.count_ones() as usize] {
            let child = child as usize;
            if node.is_leaf(child) {
                let (first, count) = node.child_primitives(child);
                for r in bits(child_rays[child]) {
                    // A leaf of this node found a hit before this box.
                    if ray_near[r][child] <= tmax[r] {
                        tmax[r] = tmax[r].min(leaf.test(r, first, count));
                    }
                }
            } else {
                inner[inner_count] = (node.child_node_index(child), child_rays[child], near);
                inner_count += 1;
            }
        }
        for &entry in inner[..inner_count].iter().rev() {
            stack[pending].write(entry);
            pending += 1;
        }
    }
}
