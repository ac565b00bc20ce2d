// Not split: the closest-hit and any-hit packet kernels share their node step, leaf culling and fallback.
//! Packet traversal of the 8-wide BVH: K = 8 or 16 rays at once, with active masks.
//!
//! (One file past 600 lines: the closest-hit and any-hit packet kernels share their node
//! step, leaf culling and single-ray fallback, and read best side by side.)
//!
//! The scheme is Embree's hybrid one (Benthin, Wald, Woop, Ernst, Mark, "Combining Single
//! and Packet-Ray Tracing for Arbitrary Ray Distributions on the Intel MIC Architecture",
//! IEEE TVCG 2012) with the frustum prefilter of Embree's coherent mode (Reshetov, Soupikov,
//! Hurley, "Multi-Level Ray Tracing Algorithm", SIGGRAPH 2005, for the interval bounds):
//!
//! * When the packet's direction signs agree on every axis, its rays are bounded by interval
//!   arithmetic on origins and reciprocal directions ([`Frustum`]); one 8-wide test per node
//!   picks the children any ray could hit and bounds their entry distance.
//! * Only those children are tested against all K rays (one ray per lane); a child is visited
//!   when any active ray hits it. The stack holds the lanes that want each subtree (a bit mask)
//!   and, for closest hits, a lower bound of their entry distances; children are visited
//!   nearest first.
//! * When `threshold` or fewer rays still want a subtree, each finishes it alone with the
//!   single-ray kernel ([`crate::bvh::traverse1`]), so incoherent packets degrade to single
//!   rays instead of dragging empty lanes along.
//! * Leaves test all wanted rays against one broadcast triangle at a time, skipping the
//!   triangles whose bounding boxes the frustum ([`Frustum`]) misses (8 boxes per test, built from the
//!   block's `v0`, `e1`, `e2` and padded like node boxes).
// The leaf culling pays most where a leaf's box is much larger than its triangles'
// (PERFORMANCE.md, "Smaller measured choices").
//!
//! Every lane gets exactly the hit the single-ray kernel gives it: the box tests are
//! conservative and the triangle test is the same bit-exact one (Möller–Trumbore or
//! watertight, the BVH's [`TriangleKernel`] `P`, chosen once per packet).
//!
//! The kernels are generic over the packet's lanes `V` (K = `V::LANES` rays), the ISA's lanes
//! `I` (8-lane node and frustum tests, the single-ray fallback) and a work [`Counter`] `C`;
//! [`crate::bvh::queries`] instantiates them per ISA tier.
//!
// Tried and replaced by the hybrid with the frustum prefilter: frustum-only traversal of
// one packet or of tiles of packets (the larger frustum visits more leaves than it saves in
// node tests), per-ray leaf tests (the per-lane broadcast and extraction cost more than the
// wasted lanes), no prefilter, no prefetching of hit children (PERFORMANCE.md, "Smaller
// measured choices").

use crate::bvh::BVH8_STACK;
use crate::bvh::bvh2::SLAB_WIDEN;
use crate::bvh::bvh8::{Bvh8Ref, LeafBlocks};
use crate::bvh::counters::{Counter, Work};
use crate::bvh::frustum::Frustum;
use crate::bvh::node::{Bvh8Node, LeafKind, NodeRef};
use crate::bvh::traverse1::{Ray1, safe_recip_lanes};
use crate::geometry::sphere_block::sphere_lanes;
use crate::geometry::{TriBlock, TriangleKernel, TriangleTest};
use crate::ray::{Hit, Ray};
use crate::simd::{IsaLanes, Lanes, Transpose8, Vec3x};
use std::borrow::Borrow;
use std::mem::MaybeUninit;

/// K rays in lane form with their running closest hits.
#[derive(Clone, Copy, Debug)]
pub struct PacketRays<V> {
    /// Origins.
    pub org: Vec3x<V>,
    /// Directions.
    pub dir: Vec3x<V>,
    /// Safe reciprocal directions.
    pub inv: Vec3x<V>,
    /// Interval starts.
    pub tnear: V,
    /// Interval ends, shrunk to the closest hit found so far.
    pub tfar: V,
    /// Hit coordinates.
    pub u: V,
    /// Hit coordinates.
    pub v: V,
    /// Hit primitive ids, as `f32` bit patterns (`u32::MAX` = none).
    pub prim: V,
    /// Lanes that are queried and valid (all-ones lanes).
    pub active: V,
}

#[inline(always)]
fn none_bits<V: Lanes>() -> V {
    V::splat(f32::from_bits(Hit::NONE))
}

impl<V: Lanes> PacketRays<V> {
    /// Lane form of `rays` (K = `V::LANES` entries), transposed with the 8 lanes `W`; lanes
    /// whose bit is clear in `mask`, and invalid rays, are inactive.
    #[inline(always)]
    pub fn new_in<W: Transpose8>(rays: &[Ray], mask: u32) -> Self {
        let rows = crate::ray::transpose_rays_in::<W>(&rays[..rays.len().min(V::LANES)]);
        let valid = if rays.len() >= V::LANES { mask } else { mask & ((1u32 << rays.len()) - 1) };
        let [ox, oy, oz, dx, dy, dz, tn, tf] = &rows;
        Self::from_rows([ox, oy, oz], [dx, dy, dz], tn, tf, valid)
    }

    /// [`PacketRays::new_in`] with the baseline ISA's transpose.
    #[inline(always)]
    pub fn new(rays: &[Ray], mask: u32) -> Self {
        Self::new_in::<crate::simd::F32x8>(rays, mask)
    }

    /// Stores the hit rows (`t` = current `tfar`, `u`, `v`, primitive id) of all lanes.
    #[inline(always)]
    pub fn store_hits(&self, t: &mut [f32], u: &mut [f32], v: &mut [f32], prim: &mut [u32]) {
        let mut p = [0.0f32; 16];
        self.tfar.store(t);
        self.u.store(u);
        self.v.store(v);
        self.prim.store(&mut p);
        for (o, x) in prim.iter_mut().zip(p.iter()).take(V::LANES) {
            *o = x.to_bits();
        }
    }

    /// Lane form of the rows of a `RayPacket8` / `RayPacket16` (each row at least K long);
    /// lanes whose bit is clear in `mask`, and invalid rays ([`Ray::is_valid`], evaluated
    /// lane-wise), are inactive.
    #[inline(always)]
    pub fn from_rows(org: [&[f32]; 3], dir: [&[f32]; 3], tnear: &[f32], tfar: &[f32], mask: u32) -> Self {
        let org = Vec3x { x: V::load(org[0]), y: V::load(org[1]), z: V::load(org[2]) };
        let dir = Vec3x { x: V::load(dir[0]), y: V::load(dir[1]), z: V::load(dir[2]) };
        let (tnear, tfar) = (V::load(tnear), V::load(tfar));
        let zero = V::splat(0.0);
        let finite = org.x.is_finite() & org.y.is_finite() & org.z.is_finite();
        let finite = finite & dir.x.is_finite() & dir.y.is_finite() & dir.z.is_finite();
        let nonzero = dir.x.abs().vmax(dir.y.abs()).vmax(dir.z.abs()).ge(V::splat(Ray::MIN_DIRECTION));
        let interval = tnear.ge(zero) & tnear.le(tfar);
        let active = V::from_bitmask(mask) & finite & nonzero & interval;
        Self {
            org,
            dir,
            inv: Vec3x { x: safe_recip_lanes(dir.x), y: safe_recip_lanes(dir.y), z: safe_recip_lanes(dir.z) },
            tnear,
            tfar,
            u: zero,
            v: zero,
            prim: none_bits(),
            active,
        }
    }

    /// Bit mask of the active lanes.
    #[inline(always)]
    pub fn active_mask(&self) -> u32 {
        self.active.bitmask()
    }

    /// The single ray of lane `i` (with its current `tfar`).
    #[inline(always)]
    pub fn ray(&self, i: usize) -> Ray {
        Ray { origin: self.org.lane(i), dir: self.dir.lane(i), tnear: self.tnear.lane(i), tfar: self.tfar.lane(i) }
    }

    /// The hit of lane `i` ([`Hit::MISS`] when none).
    #[inline(always)]
    pub fn hit(&self, i: usize) -> Hit {
        let prim = self.prim.lane(i).to_bits();
        if prim == Hit::NONE {
            Hit::MISS
        } else {
            Hit { t: self.tfar.lane(i), u: self.u.lane(i), v: self.v.lane(i), prim }
        }
    }

    /// Writes lane `i`'s hit (from a single-ray fallback).
    #[inline(always)]
    fn set_lane(&mut self, i: usize, hit: &Hit) {
        let m = V::from_bitmask(1 << i);
        self.tfar = m.select(V::splat(hit.t), self.tfar);
        self.u = m.select(V::splat(hit.u), self.u);
        self.v = m.select(V::splat(hit.v), self.v);
        self.prim = m.select(V::splat(f32::from_bits(hit.prim)), self.prim);
    }

    /// Keeps the hits `(t, u, v)` of triangle or sphere `prim` in the lanes of mask `m`.
    #[inline(always)]
    fn keep_hits(&mut self, m: V, t: V, u: V, v: V, prim: u32) {
        self.tfar = m.select(t, self.tfar);
        self.u = m.select(u, self.u);
        self.v = m.select(v, self.v);
        self.prim = m.select(V::splat(f32::from_bits(prim)), self.prim);
    }

    /// Per-lane slab test against box `i` of `node`: `(hit lanes, entry distances)`.
    #[inline(always)]
    pub fn intersect_box(&self, node: &Bvh8Node, i: usize) -> (V, V) {
        let b = &node.bounds;
        let t0x = (V::splat(b[0][i]) - self.org.x) * self.inv.x;
        let t1x = (V::splat(b[1][i]) - self.org.x) * self.inv.x;
        let t0y = (V::splat(b[2][i]) - self.org.y) * self.inv.y;
        let t1y = (V::splat(b[3][i]) - self.org.y) * self.inv.y;
        let t0z = (V::splat(b[4][i]) - self.org.z) * self.inv.z;
        let t1z = (V::splat(b[5][i]) - self.org.z) * self.inv.z;
        let tn = t0x.vmin(t1x).vmax(t0y.vmin(t1y)).vmax(t0z.vmin(t1z).vmax(self.tnear));
        let tf = (t0x.vmax(t1x).vmin(t0y.vmax(t1y)).vmin(t0z.vmax(t1z)) * V::splat(SLAB_WIDEN)).vmin(self.tfar);
        (tn.le(tf), tn)
    }

    /// The lanes of `active` (bit mask) against the primitives of `leaf`, keeping the closest
    /// hits: all wanted rays against one (broadcast) primitive at a time, skipping the
    /// triangles the frustum `fr` misses.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn intersect_leaf<I: IsaLanes, T: TriBlock, L: LeafBlocks<T>, P: TriangleKernel, C: Counter>(
        &mut self,
        bvh: &Bvh8Ref<'_, T, L>,
        leaf: NodeRef,
        active: u32,
        fr: Option<&Frustum<I::F8>>,
        pre: &P::RayK<V>,
        counter: &mut C,
    ) {
        let act = V::from_bitmask(active);
        let range = leaf.blocks();
        if leaf.kind() == LeafKind::Spheres {
            for (k, block) in bvh.spheres[range].iter().enumerate() {
                for lane in crate::simd::bits(leaf.lane_mask(k, 4)) {
                    let c = Vec3x::splat(block.center(lane));
                    let (m, t) =
                        sphere_lanes(&self.org, &self.dir, self.tnear, self.tfar, &c, V::splat(block.radius[lane]));
                    let m = m & act;
                    if m.bitmask() != 0 {
                        let zero = V::splat(0.0);
                        self.keep_hits(m, t, zero, zero, block.prim[lane]);
                    }
                }
            }
            return;
        }
        for (k, block) in bvh.tris.blocks(range).enumerate() {
            let block: &T = block.borrow();
            for lane in crate::simd::bits(lanes_to_test::<I, T, P, C>(leaf, k, block, fr, counter)) {
                let (m, t, u, v) = P::broadcast(&block.lane_rows(lane), pre, self.tnear, self.tfar);
                let m = m & act;
                if m.bitmask() != 0 {
                    self.keep_hits(m, t, u, v, block.prim(lane));
                }
            }
        }
    }

    /// The lanes of `active` (bit mask) blocked by anything in `leaf`, as a bit mask: all
    /// wanted rays against one (broadcast) primitive at a time, skipping the triangles the
    /// frustum `fr` misses, until every wanted ray is blocked.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn occluded_leaf<I: IsaLanes, T: TriBlock, L: LeafBlocks<T>, P: TriangleKernel, C: Counter>(
        &self,
        bvh: &Bvh8Ref<'_, T, L>,
        leaf: NodeRef,
        active: u32,
        cache: &mut OccluderCache,
        fr: Option<&Frustum<I::F8>>,
        pre: &P::RayK<V>,
        counter: &mut C,
    ) -> u32 {
        let mut occ = 0u32;
        let range = leaf.blocks();
        match leaf.kind() {
            LeafKind::Triangles => {
                for (k, block) in bvh.tris.blocks(range).enumerate() {
                    let block: &T = block.borrow();
                    for lane in crate::simd::bits(lanes_to_test::<I, T, P, C>(leaf, k, block, fr, counter)) {
                        let rows = block.lane_rows(lane);
                        let (m, ..) = P::broadcast(&rows, pre, self.tnear, self.tfar);
                        let blocked = m.bitmask() & active;
                        if blocked != 0 {
                            occ |= blocked;
                            cache.tri = Some((P::TEST, rows));
                            if active & !occ == 0 {
                                return occ;
                            }
                        }
                    }
                }
            }
            LeafKind::Spheres => {
                for (k, block) in bvh.spheres[range].iter().enumerate() {
                    for lane in crate::simd::bits(leaf.lane_mask(k, 4)) {
                        let c = Vec3x::splat(block.center(lane));
                        let (m, _) =
                            sphere_lanes(&self.org, &self.dir, self.tnear, self.tfar, &c, V::splat(block.radius[lane]));
                        occ |= m.bitmask() & active;
                    }
                }
            }
        }
        occ
    }
}

/// The switch threshold of packets without a frustum (direction signs that differ): `3K/8`
/// rays (6 of 16, 3 of 8), except 16-lane packets on AVX-512, which go on alone at 4
/// ([`crate::bvh::tuning::incoherent_threshold_16`]). Coherent packets keep
/// [`crate::bvh::queries::HYBRID_THRESHOLD`].
//
// The threshold is measured (PERFORMANCE.md, "Smaller measured choices").
#[inline(always)]
pub fn incoherent_threshold<V: Lanes, I: IsaLanes>() -> usize {
    if V::LANES == 16 { const { crate::bvh::tuning::incoherent_threshold_16(I::ISA) } } else { 3 * V::LANES / 8 }
}

/// Hybrid closest-hit traversal of the active lanes of `rays`, in ISA `I` with triangle
/// kernel `P` (which must be the kernel of `bvh.test`).
///
/// The stack holds, per entry, the lanes that hit the subtree's box and a lower bound of
/// their entry distances; a popped entry keeps only the lanes whose closest hit so far lies
/// beyond that bound. When the packet's direction signs agree, a frustum test first picks the
/// children any ray could hit (and gives the distance bound); only those get the per-lane
/// test. Hit children are visited nearest first (by that bound). Subtrees wanted by at most
/// `threshold` lanes are finished lane by lane with the single-ray kernel; leaves test all
/// wanted rays against one triangle at a time.
#[inline(always)]
pub fn intersect_hybrid<V: Lanes, I: IsaLanes, T: TriBlock, L: LeafBlocks<T>, P: TriangleKernel, C: Counter>(
    bvh: &Bvh8Ref<'_, T, L>,
    rays: &mut PacketRays<V>,
    threshold: usize,
    counter: &mut C,
) {
    debug_assert_eq!(P::TEST, bvh.test, "kernel of the block layout");
    let all = rays.active_mask();
    if all == 0 {
        return;
    }
    let pre = P::ray_k(&rays.org, &rays.dir);
    let frustum = Frustum::<I::F8>::new(&rays.org, &rays.inv, rays.tnear, rays.tfar, rays.active);
    // Rays whose direction signs differ (no frustum) are incoherent: they split up early, so
    // they go on alone sooner (Embree's incoherent switch threshold is higher too).
    let threshold = if frustum.is_none() { threshold.max(incoherent_threshold::<V, I>()) } else { threshold };
    let inf = V::splat(f32::INFINITY);
    // The one exception to `bvh::stack::TraversalStack`: the packet kernels keep three
    // parallel arrays (node, lane mask, distance), which the 16-lane streams trace faster
    // with (PERFORMANCE.md, "One single-ray skeleton and one stack").
    let mut refs = [const { MaybeUninit::<NodeRef>::uninit() }; BVH8_STACK];
    let mut masks = [const { MaybeUninit::<u32>::uninit() }; BVH8_STACK];
    let mut dists = [const { MaybeUninit::<f32>::uninit() }; BVH8_STACK];
    let mut sp = 0usize;
    let mut cur = bvh.root();
    let mut active = all;
    loop {
        'descend: loop {
            if active.count_ones() as usize <= threshold {
                counter.add(Work::FallbackRays, active.count_ones());
                for i in crate::simd::bits(active) {
                    let r = Ray1::new(&rays.ray(i));
                    let mut tfar = r.ray.tfar;
                    let mut hit = Hit::MISS;
                    bvh.intersect1_from::<I, P, C, false>(&r, cur, &mut tfar, &mut hit, counter);
                    if hit.is_hit() {
                        rays.set_lane(i, &hit);
                    }
                }
                break 'descend;
            }
            if cur.is_leaf() {
                rays.intersect_leaf::<I, T, L, P, C>(bvh, cur, active, frustum.as_ref(), &pre, counter);
                break 'descend;
            }
            let node = &bvh.nodes[cur.node_index()];
            counter.add(Work::PacketNodes, 1);
            let (candidates, fdist) = match &frustum {
                Some(f) => f.intersect_node(node),
                None => {
                    let used = node.children.iter().take_while(|c| !c.is_empty()).count();
                    ((1u32 << used) - 1, I::F8::splat(0.0))
                }
            };
            let fd = fdist.to_array();
            let mut next = NodeRef::EMPTY;
            let mut next_active = 0;
            let mut next_dist = f32::INFINITY;
            let base = sp;
            for i in crate::simd::bits(candidates) {
                let (m, tn) = rays.intersect_box(node, i);
                let mb = m.bitmask() & active;
                if mb == 0 {
                    continue;
                }
                let d = if frustum.is_some() { fd[i] } else { m.select(tn, inf).reduce_min() };
                let child = node.children[i];
                bvh.prefetch(child);
                let (push_ref, push_mask, push_dist) = if next.is_empty() {
                    next = child;
                    next_active = mb;
                    next_dist = d;
                    continue;
                } else if d < next_dist {
                    let old = (next, next_active, next_dist);
                    next = child;
                    next_active = mb;
                    next_dist = d;
                    old
                } else {
                    (child, mb, d)
                };
                refs[sp] = MaybeUninit::new(push_ref);
                masks[sp] = MaybeUninit::new(push_mask);
                dists[sp] = MaybeUninit::new(push_dist);
                sp += 1;
            }
            if next.is_empty() {
                break 'descend;
            }
            // Nearest of the pushed entries on top (insertion sort, at most 7 entries).
            for i in base + 1..sp {
                // SAFETY: entries base..sp were written above.
                let (r, m, d) = unsafe { (refs[i].assume_init(), masks[i].assume_init(), dists[i].assume_init()) };
                let mut j = i;
                // SAFETY: base <= j - 1 < sp, written above.
                while j > base && unsafe { dists[j - 1].assume_init() } < d {
                    refs[j] = refs[j - 1];
                    masks[j] = masks[j - 1];
                    dists[j] = dists[j - 1];
                    j -= 1;
                }
                refs[j] = MaybeUninit::new(r);
                masks[j] = MaybeUninit::new(m);
                dists[j] = MaybeUninit::new(d);
            }
            cur = next;
            active = next_active;
        }
        loop {
            if sp == 0 {
                return;
            }
            sp -= 1;
            // SAFETY: entries below sp were written by pushes.
            let (r, m, d) = unsafe { (refs[sp].assume_init(), masks[sp].assume_init(), dists[sp].assume_init()) };
            let m = m & V::splat(d).le(rays.tfar).bitmask();
            if m != 0 {
                cur = r;
                active = m;
                break;
            }
        }
    }
}

/// The triangle that last blocked a ray of a packet, carried from packet to packet along a
/// shadow-ray stream and tested before traversal starts. Coherent shadow rays are mostly
/// blocked by the same few triangles, so the last occluder often settles a whole packet with
/// one test (the "shadow cache" of Haines and Greenberg, "The Light Buffer", IEEE CG&A 1986).
/// Any hit is as good as another for occlusion, so the answers do not change.
//
// It pays most where one occluder blocks most rays (the CS184 CBbunny's ceiling). The same
// cache for closest hits (a hit on the last hit triangle shrinks the rays' intervals before
// traversal) was tried on camera rays and did not pay (PERFORMANCE.md, "Smaller measured
// choices").
#[derive(Clone, Copy, Debug, Default)]
pub struct OccluderCache {
    /// The stored vectors of the last occluder, and the layout they are in.
    tri: Option<(TriangleTest, [crate::math::Vec3; 3])>,
}

/// Packet leaves: skip triangles whose (padded) boxes the frustum misses.
const TRIANGLE_CULL: bool = true;

/// Bit mask of the lanes of `block` (block `k` of `leaf`) a packet tests: the leaf's lanes,
/// less the triangles the frustum `fr` misses (when culling applies to a block this full).
#[inline(always)]
fn lanes_to_test<I: IsaLanes, T: TriBlock, P: TriangleKernel, C: Counter>(
    leaf: NodeRef,
    k: usize,
    block: &T,
    fr: Option<&Frustum<I::F8>>,
    counter: &mut C,
) -> u32 {
    let mut todo = leaf.lane_mask(k, T::M);
    if TRIANGLE_CULL
        && todo.count_ones() >= 4
        && let Some(f) = fr
    {
        todo &= f.intersect_triangles::<T, T::Lanes<I>>(block, P::TEST);
    }
    counter.add(Work::PacketTriangles, todo.count_ones());
    todo
}

/// Test a node's leaf children before descending into its inner children (any hit only).
const LEAVES_FIRST: bool = true;

/// Hybrid any-hit traversal in ISA `I` with triangle kernel `P` (which must be the kernel of
/// `bvh.test`); returns the bit mask of occluded lanes.
///
/// Occlusion needs no distances, so the stack holds lane masks (which rays want a subtree)
/// rather than per-lane entry distances. When the packet's direction signs agree, a frustum
/// test first picks the children any ray could hit, and only those get the per-lane test.
/// Subtrees wanted by at most `threshold` rays are finished ray by ray; leaves test all
/// wanted rays against one triangle at a time, leaf children of a node before its inner ones.
#[inline(always)]
pub fn occluded_hybrid<V: Lanes, I: IsaLanes, T: TriBlock, L: LeafBlocks<T>, P: TriangleKernel, C: Counter>(
    bvh: &Bvh8Ref<'_, T, L>,
    rays: &PacketRays<V>,
    threshold: usize,
    cache: &mut OccluderCache,
    counter: &mut C,
) -> u32 {
    debug_assert_eq!(P::TEST, bvh.test, "kernel of the block layout");
    let all = rays.active_mask();
    let mut occluded = 0u32;
    if all == 0 {
        return 0;
    }
    let pre = P::ray_k(&rays.org, &rays.dir);
    if let Some((_, rows)) = cache.tri.filter(|c| c.0 == P::TEST) {
        let (m, ..) = P::broadcast(&rows, &pre, rays.tnear, rays.tfar);
        occluded = m.bitmask() & all;
        if occluded == all {
            return occluded;
        }
    }
    let frustum = Frustum::<I::F8>::new(&rays.org, &rays.inv, rays.tnear, rays.tfar, rays.active);
    let mut refs = [const { MaybeUninit::<NodeRef>::uninit() }; BVH8_STACK];
    let mut masks = [const { MaybeUninit::<u32>::uninit() }; BVH8_STACK];
    let mut sp = 0usize;
    let mut cur = bvh.root();
    let mut active = all & !occluded;
    loop {
        'descend: loop {
            if active.count_ones() as usize <= threshold {
                counter.add(Work::FallbackRays, active.count_ones());
                for i in crate::simd::bits(active) {
                    if bvh.occluded1_from::<I, P, C, false>(&Ray1::new(&rays.ray(i)), cur, counter) {
                        occluded |= 1 << i;
                    }
                }
                break 'descend;
            }
            if cur.is_leaf() {
                occluded |=
                    rays.occluded_leaf::<I, T, L, P, C>(bvh, cur, active, cache, frustum.as_ref(), &pre, counter);
                break 'descend;
            }
            let node = &bvh.nodes[cur.node_index()];
            counter.add(Work::PacketNodes, 1);
            let candidates = match &frustum {
                Some(f) => f.intersect_node(node).0,
                None => (1u32 << node.children.iter().take_while(|c| !c.is_empty()).count()) - 1,
            };
            let mut next = NodeRef::EMPTY;
            let mut next_active = 0;
            let mut leaves = 0u32;
            let mut leaf_masks = [0u32; 8];
            for i in crate::simd::bits(candidates) {
                let (m, _) = rays.intersect_box(node, i);
                let m = m.bitmask() & active;
                if m == 0 {
                    continue;
                }
                let child = node.children[i];
                bvh.prefetch(child);
                if child.is_leaf() && LEAVES_FIRST {
                    leaves |= 1 << i;
                    leaf_masks[i] = m;
                    continue;
                }
                if !next.is_empty() {
                    refs[sp] = MaybeUninit::new(next);
                    masks[sp] = MaybeUninit::new(next_active);
                    sp += 1;
                }
                next = child;
                next_active = m;
            }
            // Leaves first: they cost one test each, and the large ones near the root (walls,
            // floors) are the likeliest occluders.
            for i in crate::simd::bits(leaves) {
                let m = leaf_masks[i] & !occluded;
                if m != 0 {
                    occluded |= rays.occluded_leaf::<I, T, L, P, C>(
                        bvh,
                        node.children[i],
                        m,
                        cache,
                        frustum.as_ref(),
                        &pre,
                        counter,
                    );
                    if all & !occluded == 0 {
                        return occluded;
                    }
                }
            }
            next_active &= !occluded;
            if next.is_empty() || next_active == 0 {
                break 'descend;
            }
            cur = next;
            active = next_active;
        }
        if all & !occluded == 0 {
            return occluded;
        }
        loop {
            if sp == 0 {
                return occluded;
            }
            sp -= 1;
            // SAFETY: entries below sp were written by pushes.
            let (r, m) = unsafe { (refs[sp].assume_init(), masks[sp].assume_init()) };
            let m = m & !occluded;
            if m != 0 {
                cur = r;
                active = m;
                break;
            }
        }
    }
}
