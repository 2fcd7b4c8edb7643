//! The triangles of each leaf of the 8-wide BVH, laid out for one 4-lane
//! test of the whole leaf (a leaf holds at most 3): the same watertight test
//! as [`crate::bvh`]'s per-triangle one, lane by lane, with the same
//! operations in the same order, so every lane gives the scalar result bit
//! for bit (the brute-force agreement tests hold for both).

use glam::Vec4;
use obvhs::cwbvh::CwBvh;
use vtfarm_scene::TriangleId;

use crate::bvh::{PrimTriangle, ShearedRay};

/// Lanes per leaf block: at least the most triangles a leaf holds.
pub(crate) const LANES: usize = 4;

/// Every leaf's block, found by the leaf's first primitive slot.
#[derive(Default)]
pub(crate) struct Leaves {
    blocks: Vec<LeafBlock>,
    /// The block of the leaf starting at each slot (slots inside a leaf:
    /// unused).
    block_of_slot: Vec<u32>,
}

impl Leaves {
    /// The blocks of every leaf of `bvh`, whose slot `s` holds `prims[s]`,
    /// triangle `ids[s]` of the scene.
    pub(crate) fn new(bvh: &CwBvh, prims: &[PrimTriangle], ids: &[TriangleId]) -> Leaves {
        let mut leaves = Leaves {
            blocks: Vec::new(),
            block_of_slot: vec![0; prims.len()],
        };
        for node in &bvh.nodes {
            for child in 0..8 {
                if node.is_child_empty(child) || !node.is_leaf(child) {
                    continue;
                }
                let (first, count) = node.child_primitives(child);
                let slots = first as usize..(first + count) as usize;
                leaves.block_of_slot[slots.start] = leaves.blocks.len() as u32;
                leaves
                    .blocks
                    .push(LeafBlock::new(&prims[slots.clone()], &ids[slots]));
            }
        }
        leaves
    }

    /// The block of the leaf whose first slot is `first`.
    #[inline(always)]
    pub(crate) fn block(&self, first: u32) -> &LeafBlock {
        &self.blocks[self.block_of_slot[first as usize] as usize]
    }

    /// The hits of `ray` (axis order `[KX, KY, KZ]`) in that leaf.
    #[inline(always)]
    pub(crate) fn hits<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        first: u32,
        ray: &ShearedRay,
    ) -> LaneHits {
        self.block(first).intersect_in::<KX, KY, KZ>(ray)
    }
}

/// Up to [`LANES`] triangles, coordinate by coordinate:
/// `corners[vertex][axis]` holds that coordinate of every lane's triangle.
#[derive(Clone, Copy)]
pub(crate) struct LeafBlock {
    corners: [[Vec4; 3]; 3],
    /// Each lane's scene triangle (here rather than looked up by slot: one
    /// cache line fewer per hit).
    pub(crate) ids: [TriangleId; LANES],
    /// The lanes that hold a triangle that can be hit (present and not
    /// degenerate, as [`PrimTriangle::is_solid`] says).
    live: u8,
}

/// What a [`LeafBlock`] test found: lane `i` hit triangle `ids[i]` at
/// `t[i]` with weights `u[i]`, `v[i]` where bit `i` of `hits` is set.
pub(crate) struct LaneHits {
    pub(crate) ids: [TriangleId; LANES],
    pub(crate) hits: u8,
    pub(crate) t: [f32; LANES],
    pub(crate) u: [f32; LANES],
    pub(crate) v: [f32; LANES],
}

impl LeafBlock {
    fn new(prims: &[PrimTriangle], ids: &[TriangleId]) -> LeafBlock {
        assert!(
            prims.len() <= LANES,
            "a leaf holds at most {LANES} triangles"
        );
        let mut corners = [[[0f32; LANES]; 3]; 3];
        let mut lane_ids = [TriangleId::default(); LANES];
        lane_ids[..ids.len()].copy_from_slice(ids);
        let mut live = 0;
        for (lane, prim) in prims.iter().enumerate() {
            for (vertex, corner) in prim.corners().into_iter().enumerate() {
                for axis in 0..3 {
                    corners[vertex][axis][lane] = corner[axis];
                }
            }
            if prim.is_solid() {
                live |= 1 << lane;
            }
        }
        LeafBlock {
            corners: corners.map(|vertex| vertex.map(Vec4::from_array)),
            ids: lane_ids,
            live,
        }
    }

    /// [`PrimTriangle::intersect_in`] for every lane at once (axis order
    /// `[KX, KY, KZ]`, see there). `Vec4` operations are lane-wise IEEE
    /// operations without fused multiply-adds, so each lane rounds exactly
    /// as the scalar test does.
    #[inline(always)]
    pub(crate) fn intersect_in<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        ray: &ShearedRay,
    ) -> LaneHits {
        let origin = ray.origin;
        let (sx, sy) = (Vec4::splat(ray.shear.x), Vec4::splat(ray.shear.y));
        // A vertex in the ray's sheared frame: x, y and the unsheared z.
        let sheared = |c: &[Vec4; 3]| {
            let dx = c[KX] - Vec4::splat(origin[KX]);
            let dy = c[KY] - Vec4::splat(origin[KY]);
            let dz = c[KZ] - Vec4::splat(origin[KZ]);
            (dx - sx * dz, dy - sy * dz, dz)
        };
        let (ax, ay, az) = sheared(&self.corners[0]);
        let (bx, by, bz) = sheared(&self.corners[1]);
        let (cx, cy, cz) = sheared(&self.corners[2]);
        let mut w0 = cx * by - cy * bx;
        let mut w1 = ax * cy - ay * cx;
        let mut w2 = bx * ay - by * ax;
        let zero = (w0.cmpeq(Vec4::ZERO) | w1.cmpeq(Vec4::ZERO) | w2.cmpeq(Vec4::ZERO)).bitmask()
            as u8
            & self.live;
        if zero != 0 {
            // The exact signs, as in the scalar test.
            let cross = |x0: f32, y0: f32, x1: f32, y1: f32| {
                (f64::from(x0) * f64::from(y1) - f64::from(y0) * f64::from(x1)) as f32
            };
            let (mut l0, mut l1, mut l2) = (w0.to_array(), w1.to_array(), w2.to_array());
            for lane in bits(zero) {
                l0[lane] = cross(cx[lane], cy[lane], bx[lane], by[lane]);
                l1[lane] = cross(ax[lane], ay[lane], cx[lane], cy[lane]);
                l2[lane] = cross(bx[lane], by[lane], ax[lane], ay[lane]);
            }
            (w0, w1, w2) = (Vec4::from(l0), Vec4::from(l1), Vec4::from(l2));
        }
        let ge = |w: Vec4| w.cmpge(Vec4::ZERO);
        let le = |w: Vec4| w.cmple(Vec4::ZERO);
        let inside = (ge(w0) & ge(w1) & ge(w2)) | (le(w0) & le(w1) & le(w2));
        let det = w0 + w1 + w2;
        let hits = (inside & det.cmpne(Vec4::ZERO)).bitmask() as u8 & self.live;
        let mut out = LaneHits {
            ids: self.ids,
            hits,
            t: [0.0; LANES],
            u: [0.0; LANES],
            v: [0.0; LANES],
        };
        if hits != 0 {
            let z = Vec4::splat(ray.shear.z);
            out.t = ((w0 * (z * az) + w1 * (z * bz) + w2 * (z * cz)) / det).to_array();
            let inv_det = Vec4::ONE / det;
            // `+ 0.0` turns a -0.0 weight (on an edge) into +0.0.
            out.u = (w1 * inv_det + Vec4::ZERO).to_array();
            out.v = (w2 * inv_det + Vec4::ZERO).to_array();
        }
        out
    }
}

/// The set bits of `mask`, lowest first.
#[inline(always)]
pub(crate) fn bits(mut mask: u8) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let bit = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            bit
        })
    })
}
