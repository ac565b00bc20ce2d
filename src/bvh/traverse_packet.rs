//! Packet traversal of the 8-wide BVH: K = 8 or 16 rays at once, with active masks.
//!
//! Two schemes, both from Embree (Wald et al. 2014; Benthin et al., "Combining Single and
//! Packet-Ray Tracing for Arbitrary Ray Distributions on the Intel MIC Architecture",
//! IEEE TVCG 2012):
//!
//! * **Hybrid** ([`intersect_hybrid`], [`occluded_hybrid`]): each child box is tested against
//!   all K rays (one ray per lane); a child is visited when any active ray hits it, and the
//!   per-lane entry distances travel on the stack. When the rays still interested in a
//!   subtree drop to `threshold` or fewer, each finishes that subtree alone with the
//!   single-ray kernel ([`crate::bvh::traverse1`]).
//! * **Frustum** ([`intersect_frustum`], [`occluded_frustum`]): for coherent rays whose
//!   direction signs agree (camera rays of a tile, shadow rays toward one light), the whole
//!   tile — P packets of K rays — is bounded by interval arithmetic on origins and reciprocal
//!   directions, and each node costs one 8-wide box test for all of them, exactly as cheap as
//!   one single ray's (Embree's "coherent" mode, Reshetov et al.'s "Multi-level ray tracing
//!   algorithm", SIGGRAPH 2005). Leaves test each packet's lanes against the leaf box, then
//!   the surviving lanes against each triangle (K rays vs one broadcast triangle).
//!
//! Every lane gets exactly the hit the single-ray kernel gives it: the box tests are
//! conservative and the triangle test is the same bit-exact Möller–Trumbore.

use crate::bvh::bvh2::SLAB_WIDEN;
use crate::bvh::counters::*;
use crate::bvh::node::{Bvh8Node, LeafKind, NodeRef};
use crate::bvh::traverse1::{Ray1, Stack, order_children};
use crate::bvh::{BVH8_STACK, Bvh8};
use crate::geometry::TriBlock;
use crate::geometry::sphere_block::sphere_lanes;
use crate::geometry::tri_block::moller_trumbore;
use crate::ray::{Hit, Ray};
use crate::simd::{F32x8, Lanes, Vec3x};
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
    /// Lane form of `rays` (K = `V::LANES` entries); lanes whose bit is clear in `mask`, and
    /// invalid rays, are inactive.
    #[inline(always)]
    pub fn new(rays: &[Ray], mask: u32) -> Self {
        let mut rows = [[0.0f32; 16]; 8];
        for (i, r) in rays.iter().take(V::LANES).enumerate() {
            let vals = [r.origin.x, r.origin.y, r.origin.z, r.dir.x, r.dir.y, r.dir.z, r.tnear, r.tfar];
            for (row, x) in rows.iter_mut().zip(vals) {
                row[i] = x;
            }
        }
        let valid = if rays.len() >= V::LANES { mask } else { mask & ((1u32 << rays.len()) - 1) };
        let [ox, oy, oz, dx, dy, dz, tn, tf] = &rows;
        Self::from_rows([ox, oy, oz], [dx, dy, dz], tn, tf, valid)
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
        let nonzero = !(dir.x.eq(zero) & dir.y.eq(zero) & dir.z.eq(zero));
        let interval = tnear.ge(zero) & tnear.le(tfar);
        let mut bits = [0.0f32; 16];
        for (i, b) in bits.iter_mut().enumerate().take(V::LANES) {
            *b = f32::from_bits(if mask >> i & 1 != 0 { u32::MAX } else { 0 });
        }
        let active = V::load(&bits) & finite & nonzero & interval;
        // `safe_recip` lane-wise: tiny components map to a huge value of the same sign.
        let recip = |x: V| {
            let tiny = V::splat(1e-18);
            let abs = x & !V::splat(-0.0);
            abs.lt(tiny).select(V::splat(1.0 / 1e-18f32).copysign(x), V::splat(1.0) / x)
        };
        Self {
            org,
            dir,
            inv: Vec3x { x: recip(dir.x), y: recip(dir.y), z: recip(dir.z) },
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
    fn set_lane(&mut self, i: usize, tfar: f32, hit: &Hit) {
        let mut a = [[0.0f32; 16]; 4];
        self.tfar.store(&mut a[0]);
        self.u.store(&mut a[1]);
        self.v.store(&mut a[2]);
        self.prim.store(&mut a[3]);
        a[0][i] = tfar;
        if hit.is_hit() {
            a[1][i] = hit.u;
            a[2][i] = hit.v;
            a[3][i] = f32::from_bits(hit.prim);
        }
        self.tfar = V::load(&a[0]);
        self.u = V::load(&a[1]);
        self.v = V::load(&a[2]);
        self.prim = V::load(&a[3]);
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

    /// The rays of the lanes in `bits`, one at a time, against all triangles of `block`.
    #[inline(always)]
    fn intersect_block_per_ray<B: TriBlock>(&mut self, block: &B, bits: u32) {
        let mut rows = [[0.0f32; 16]; 8];
        for (row, x) in rows
            .iter_mut()
            .zip([self.org.x, self.org.y, self.org.z, self.dir.x, self.dir.y, self.dir.z, self.tnear, self.tfar])
        {
            x.store(row);
        }
        let mut hit = false;
        let (mut uu, mut vv, mut pp) = ([0.0f32; 16], [0.0f32; 16], [0.0f32; 16]);
        for i in crate::simd::bits(bits) {
            let o = Vec3x { x: B::V::splat(rows[0][i]), y: B::V::splat(rows[1][i]), z: B::V::splat(rows[2][i]) };
            let d = Vec3x { x: B::V::splat(rows[3][i]), y: B::V::splat(rows[4][i]), z: B::V::splat(rows[5][i]) };
            let h = block.intersect1(&o, &d, B::V::splat(rows[6][i]), B::V::splat(rows[7][i]));
            if let Some(l) = h.closest() {
                if !hit {
                    hit = true;
                    self.u.store(&mut uu);
                    self.v.store(&mut vv);
                    self.prim.store(&mut pp);
                }
                rows[7][i] = h.t.lane(l);
                uu[i] = h.u.lane(l);
                vv[i] = h.v.lane(l);
                pp[i] = f32::from_bits(block.prim(l));
            }
        }
        if hit {
            self.tfar = V::load(&rows[7]);
            self.u = V::load(&uu);
            self.v = V::load(&vv);
            self.prim = V::load(&pp);
        }
    }

    /// Tests the `active` lanes against the primitives of `leaf`, keeping the closest hits.
    #[inline(always)]
    fn intersect_leaf<T: TriBlock>(&mut self, bvh: &Bvh8<T>, leaf: NodeRef, active: V) {
        let range = leaf.first_block()..leaf.first_block() + leaf.block_count();
        match leaf.kind() {
            LeafKind::Triangles => {
                let bits = active.bitmask();
                let n_active = bits.count_ones() as usize;
                for (k, block) in bvh.tris[range].iter().enumerate() {
                    let lanes = leaf.lanes_of_block(k, T::M);
                    if n_active < (crate::bvh::tune::knob(crate::bvh::tune::PER_RAY_LEAF) as usize).min(lanes) {
                        count!(PER_RAY_BLOCKS, n_active);
                        // Fewer rays than triangles: each ray against the whole block at once.
                        self.intersect_block_per_ray(block, bits);
                        continue;
                    }
                    count!(PACKET_TRI_TESTS, lanes);
                    for lane in 0..lanes {
                        let prim = block.prim(lane);
                        let [v0, e1, e2] = block.lane_edges(lane);
                        let (m, t, u, v) = moller_trumbore(
                            &self.org,
                            &self.dir,
                            self.tnear,
                            self.tfar,
                            &Vec3x::splat(v0),
                            &Vec3x::splat(e1),
                            &Vec3x::splat(e2),
                        );
                        let m = m & active;
                        if m.bitmask() != 0 {
                            self.tfar = m.select(t, self.tfar);
                            self.u = m.select(u, self.u);
                            self.v = m.select(v, self.v);
                            self.prim = m.select(V::splat(f32::from_bits(prim)), self.prim);
                        }
                    }
                }
            }
            LeafKind::Spheres => {
                for (k, block) in bvh.spheres[range].iter().enumerate() {
                    for lane in 0..leaf.lanes_of_block(k, 4) {
                        let prim = block.prim[lane];
                        let c = Vec3x::splat(block.center(lane));
                        let (m, t) =
                            sphere_lanes(&self.org, &self.dir, self.tnear, self.tfar, &c, V::splat(block.radius[lane]));
                        let m = m & active;
                        if m.bitmask() != 0 {
                            self.tfar = m.select(t, self.tfar);
                            self.u = m.select(V::splat(0.0), self.u);
                            self.v = m.select(V::splat(0.0), self.v);
                            self.prim = m.select(V::splat(f32::from_bits(prim)), self.prim);
                        }
                    }
                }
            }
        }
    }

    /// The `active` lanes that hit anything in `leaf` over their interval.
    #[inline(always)]
    fn occluded_leaf<T: TriBlock>(&self, bvh: &Bvh8<T>, leaf: NodeRef, active: V) -> V {
        let mut occ = V::splat(0.0);
        let range = leaf.first_block()..leaf.first_block() + leaf.block_count();
        match leaf.kind() {
            LeafKind::Triangles => {
                for (k, block) in bvh.tris[range].iter().enumerate() {
                    for lane in 0..leaf.lanes_of_block(k, T::M) {
                        let [v0, e1, e2] = block.lane_edges(lane);
                        let (m, ..) = moller_trumbore(
                            &self.org,
                            &self.dir,
                            self.tnear,
                            self.tfar,
                            &Vec3x::splat(v0),
                            &Vec3x::splat(e1),
                            &Vec3x::splat(e2),
                        );
                        occ = occ | (m & active);
                        if (active & !occ).bitmask() == 0 {
                            return occ;
                        }
                    }
                }
            }
            LeafKind::Spheres => {
                for (k, block) in bvh.spheres[range].iter().enumerate() {
                    for lane in 0..leaf.lanes_of_block(k, 4) {
                        let c = Vec3x::splat(block.center(lane));
                        let (m, _) =
                            sphere_lanes(&self.org, &self.dir, self.tnear, self.tfar, &c, V::splat(block.radius[lane]));
                        occ = occ | (m & active);
                    }
                }
            }
        }
        occ
    }
}

/// A stack of node references with per-lane entry distances.
struct PacketStack<V> {
    refs: [MaybeUninit<NodeRef>; BVH8_STACK],
    dist: [MaybeUninit<V>; BVH8_STACK],
    len: usize,
}

impl<V: Lanes> PacketStack<V> {
    #[inline(always)]
    fn new() -> Self {
        Self {
            refs: [const { MaybeUninit::uninit() }; BVH8_STACK],
            dist: [const { MaybeUninit::uninit() }; BVH8_STACK],
            len: 0,
        }
    }
    #[inline(always)]
    fn push(&mut self, r: NodeRef, d: V) {
        self.refs[self.len] = MaybeUninit::new(r);
        self.dist[self.len] = MaybeUninit::new(d);
        self.len += 1;
    }
    #[inline(always)]
    fn pop(&mut self) -> Option<(NodeRef, V)> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: entries below `len` were all written by `push`.
        unsafe { Some((self.refs[self.len].assume_init(), self.dist[self.len].assume_init())) }
    }
}

/// Hybrid closest-hit traversal of the active lanes of `rays`. Subtrees wanted by at most
/// `threshold` lanes are finished lane by lane with the single-ray kernel.
pub fn intersect_hybrid<V: Lanes, T: TriBlock>(bvh: &Bvh8<T>, rays: &mut PacketRays<V>, threshold: usize) {
    let inf = V::splat(f32::INFINITY);
    let mut stack = PacketStack::<V>::new();
    stack.push(bvh.root(), rays.active.select(rays.tnear, inf));
    'pop: while let Some((mut cur, mut cur_dist)) = stack.pop() {
        let mut active = cur_dist.le(rays.tfar) & rays.active;
        loop {
            let bits = active.bitmask();
            if bits == 0 {
                continue 'pop;
            }
            if (bits.count_ones() as usize) <= threshold {
                for i in crate::simd::bits(bits) {
                    let r = rays.ray(i);
                    let mut tfar = r.tfar;
                    let mut hit = Hit::MISS;
                    bvh.intersect1_from(&Ray1::new(&r), cur, &mut tfar, &mut hit);
                    if hit.is_hit() {
                        rays.set_lane(i, tfar, &hit);
                    }
                }
                continue 'pop;
            }
            if cur.is_leaf() {
                break;
            }
            let node = &bvh.nodes[cur.node_index()];
            let mut next = NodeRef::EMPTY;
            let mut next_dist = inf;
            for i in 0..8 {
                let child = node.children[i];
                if child.is_empty() {
                    break;
                }
                let (m, tn) = rays.intersect_box(node, i);
                let m = m & active;
                if m.bitmask() == 0 {
                    continue;
                }
                let d = m.select(tn, inf);
                if next.is_empty() {
                    (next, next_dist) = (child, d);
                } else if d.lt(next_dist).bitmask() != 0 {
                    stack.push(next, next_dist);
                    (next, next_dist) = (child, d);
                } else {
                    stack.push(child, d);
                }
            }
            if next.is_empty() {
                continue 'pop;
            }
            cur = next;
            cur_dist = next_dist;
            active = cur_dist.le(rays.tfar) & rays.active;
        }
        rays.intersect_leaf(bvh, cur, active);
    }
}

/// Hybrid any-hit traversal; returns the mask of occluded lanes (all-ones lanes).
pub fn occluded_hybrid<V: Lanes, T: TriBlock>(bvh: &Bvh8<T>, rays: &PacketRays<V>, threshold: usize) -> V {
    let inf = V::splat(f32::INFINITY);
    let mut occluded = V::splat(0.0);
    let mut stack = PacketStack::<V>::new();
    stack.push(bvh.root(), rays.active.select(rays.tnear, inf));
    'pop: while let Some((mut cur, cur_dist)) = stack.pop() {
        let mut active = cur_dist.le(rays.tfar) & rays.active & !occluded;
        loop {
            let bits = active.bitmask();
            if bits == 0 {
                continue 'pop;
            }
            if (bits.count_ones() as usize) <= threshold {
                let mut occ = [0.0f32; 16];
                occluded.store(&mut occ);
                for i in crate::simd::bits(bits) {
                    if bvh.occluded1_from(&Ray1::new(&rays.ray(i)), cur) {
                        occ[i] = f32::from_bits(u32::MAX);
                    }
                }
                occluded = V::load(&occ);
                if (rays.active & !occluded).bitmask() == 0 {
                    return occluded;
                }
                continue 'pop;
            }
            if cur.is_leaf() {
                break;
            }
            let node = &bvh.nodes[cur.node_index()];
            let mut next = NodeRef::EMPTY;
            let mut next_active = active;
            for i in 0..8 {
                let child = node.children[i];
                if child.is_empty() {
                    break;
                }
                let (m, tn) = rays.intersect_box(node, i);
                let m = m & active;
                if m.bitmask() == 0 {
                    continue;
                }
                if next.is_empty() {
                    next = child;
                    next_active = m;
                } else {
                    stack.push(child, m.select(tn, inf));
                }
            }
            if next.is_empty() {
                continue 'pop;
            }
            cur = next;
            active = next_active;
        }
        occluded = occluded | rays.occluded_leaf(bvh, cur, active);
        if (rays.active & !occluded).bitmask() == 0 {
            return occluded;
        }
    }
    occluded
}

/// The bounds, by interval arithmetic, of a tile of coherent rays whose direction signs
/// agree on every axis: one 8-wide box test then answers "could any ray of the tile hit this
/// child" for all of them (conservatively: see [`Frustum::new`]).
#[derive(Clone, Copy, Debug)]
pub struct Frustum {
    near: [usize; 3],
    near_org: Vec3x<F32x8>,
    far_org: Vec3x<F32x8>,
    near_rdir: Vec3x<F32x8>,
    far_rdir: Vec3x<F32x8>,
    tnear: F32x8,
    /// Largest `tfar` of the tile's active rays.
    pub tfar: f32,
}

impl Frustum {
    /// The frustum of the active lanes of `packets`, or `None` when no lane is active or the
    /// direction signs differ on some axis.
    ///
    /// Per axis with reciprocal directions in `[i_lo, i_hi]` (same sign) and origins in
    /// `[o_lo, o_hi]`: the near plane `n` is entered no earlier than `(n - o') · i'` where
    /// `o'` is the origin bound on the far side (`o_hi` for positive directions) and `i'` the
    /// reciprocal of smallest magnitude; the far plane `f` is left no later than
    /// `(f - o'') · i''` with the other bounds. Rounding is monotone in each operand, so these
    /// bound the per-ray values computed by [`PacketRays::intersect_box`] and
    /// [`Ray1::intersect_node`] in floating point too. A negative bound is not tight, but the
    /// interval starts at `tnear >= 0`, which makes it harmless.
    pub fn new<V: Lanes>(packets: &[PacketRays<V>]) -> Option<Self> {
        let (pinf, ninf) = (V::splat(f32::INFINITY), V::splat(f32::NEG_INFINITY));
        let mut lo = [pinf; 7];
        let mut hi = [ninf; 7];
        let mut any = false;
        for p in packets {
            if p.active.bitmask() == 0 {
                continue;
            }
            any = true;
            let rows = [p.org.x, p.org.y, p.org.z, p.inv.x, p.inv.y, p.inv.z];
            for (k, row) in rows.iter().enumerate() {
                lo[k] = lo[k].vmin(p.active.select(*row, pinf));
                hi[k] = hi[k].vmax(p.active.select(*row, ninf));
            }
            lo[6] = lo[6].vmin(p.active.select(p.tnear, pinf));
            hi[6] = hi[6].vmax(p.active.select(p.tfar, ninf));
        }
        if !any {
            return None;
        }
        let lo: [f32; 7] = std::array::from_fn(|k| lo[k].reduce_min());
        let hi: [f32; 7] = std::array::from_fn(|k| hi[k].reduce_max());
        let (tn, tf) = (lo[6], hi[6]);
        let mut near = [0; 3];
        let mut near_org = [0.0; 3];
        let mut far_org = [0.0; 3];
        let mut near_rdir = [0.0; 3];
        let mut far_rdir = [0.0; 3];
        for a in 0..3 {
            let (ilo, ihi) = (lo[3 + a], hi[3 + a]);
            let (olo, ohi) = (lo[a], hi[a]);
            if ilo >= 0.0 {
                near[a] = 2 * a;
                (near_org[a], far_org[a]) = (ohi, olo);
                (near_rdir[a], far_rdir[a]) = (ilo, ihi);
            } else if ihi < 0.0 {
                near[a] = 2 * a + 1;
                (near_org[a], far_org[a]) = (olo, ohi);
                (near_rdir[a], far_rdir[a]) = (ihi, ilo);
            } else {
                return None;
            }
        }
        let v = |x: [f32; 3]| Vec3x { x: F32x8::splat(x[0]), y: F32x8::splat(x[1]), z: F32x8::splat(x[2]) };
        Some(Self {
            near,
            near_org: v(near_org),
            far_org: v(far_org),
            near_rdir: v(near_rdir),
            far_rdir: v(far_rdir),
            tnear: F32x8::splat(tn),
            tfar: tf,
        })
    }

    /// Could any ray of the tile hit the children of `n` before `self.tfar`? Returns the mask
    /// of such children and lower bounds of their entry distances.
    #[inline(always)]
    pub fn intersect_node(&self, n: &Bvh8Node) -> (u32, F32x8) {
        let b = &n.bounds;
        let tnx = (F32x8::load(&b[self.near[0]]) - self.near_org.x) * self.near_rdir.x;
        let tny = (F32x8::load(&b[self.near[1]]) - self.near_org.y) * self.near_rdir.y;
        let tnz = (F32x8::load(&b[self.near[2]]) - self.near_org.z) * self.near_rdir.z;
        let tfx = (F32x8::load(&b[self.near[0] ^ 1]) - self.far_org.x) * self.far_rdir.x;
        let tfy = (F32x8::load(&b[self.near[1] ^ 1]) - self.far_org.y) * self.far_rdir.y;
        let tfz = (F32x8::load(&b[self.near[2] ^ 1]) - self.far_org.z) * self.far_rdir.z;
        let tn = tnx.vmax(tny).vmax(tnz.vmax(self.tnear));
        let tf = (tfx.vmin(tfy).vmin(tfz) * F32x8::splat(SLAB_WIDEN)).vmin(F32x8::splat(self.tfar));
        (tn.le(tf).bitmask(), tn)
    }
}

/// A stack entry of the frustum traversal: the reference and where its box lives (parent
/// node and slot), for the per-lane box test at leaves.
#[derive(Clone, Copy)]
struct TileEntry {
    node: NodeRef,
    parent: u32,
    slot: u32,
}

/// Closest-hit traversal of a tile of coherent packets with one frustum test per node
/// (falls back to [`intersect_hybrid`] per packet when the direction signs disagree).
pub fn intersect_frustum<V: Lanes, T: TriBlock>(bvh: &Bvh8<T>, packets: &mut [PacketRays<V>], threshold: usize) {
    let Some(mut fr) = Frustum::new(packets) else {
        for p in packets.iter_mut() {
            if p.active_mask() != 0 {
                intersect_hybrid(bvh, p, threshold);
            }
        }
        return;
    };
    let mut stack = Stack::<TileEntry>::new();
    let mut cur = TileEntry { node: bvh.root(), parent: u32::MAX, slot: 0 };
    loop {
        'descend: {
            while !cur.node.is_leaf() {
                let idx = cur.node.node_index();
                let node = &bvh.nodes[idx];
                count!(FRUSTUM_NODES, 1);
                let (mask, dist) = fr.intersect_node(node);
                if mask == 0 {
                    break 'descend;
                }
                if mask & (mask - 1) != 0 && crate::bvh::tune::knob(crate::bvh::tune::NO_PREFETCH) == 0 {
                    for i in crate::simd::bits(mask) {
                        bvh.prefetch(node.children[i]);
                    }
                }
                cur = order_children(mask, dist, &mut stack, |i| TileEntry {
                    node: node.children[i],
                    parent: idx as u32,
                    slot: i as u32,
                });
            }
            let parent = &bvh.nodes[cur.parent as usize];
            let mut tested = false;
            for p in packets.iter_mut() {
                let (m, _) = p.intersect_box(parent, cur.slot as usize);
                let m = m & p.active;
                count!(PACKET_LEAVES, 1);
                if m.bitmask() != 0 {
                    count!(PACKET_LEAF_LANES, m.bitmask().count_ones());
                    p.intersect_leaf(bvh, cur.node, m);
                    tested = true;
                }
            }
            if tested {
                // The farthest interval end of the tile shrinks as rays find hits.
                let ninf = V::splat(f32::NEG_INFINITY);
                let far = packets.iter().fold(ninf, |acc, p| acc.vmax(p.active.select(p.tfar, ninf)));
                fr.tfar = far.reduce_max();
            }
        }
        loop {
            match stack.pop() {
                None => return,
                Some((next, d)) if d <= fr.tfar => {
                    cur = next;
                    break;
                }
                Some(_) => {}
            }
        }
    }
}

/// Any-hit traversal of a tile of coherent packets with one frustum test per node; returns
/// the occluded lanes of each packet as bit masks.
pub fn occluded_frustum<V: Lanes, T: TriBlock>(
    bvh: &Bvh8<T>,
    packets: &[PacketRays<V>],
    threshold: usize,
    out: &mut [u32],
) {
    let Some(fr) = Frustum::new(packets) else {
        for (p, o) in packets.iter().zip(out.iter_mut()) {
            *o = if p.active_mask() != 0 { occluded_hybrid(bvh, p, threshold).bitmask() } else { 0 };
        }
        return;
    };
    let mut occluded: [V; 64] = [V::splat(0.0); 64];
    let n = packets.len();
    assert!(n <= 64, "at most 64 packets per tile");
    let mut stack = Stack::<TileEntry>::new();
    let mut remaining: u32 = packets.iter().map(|p| p.active_mask().count_ones()).sum();
    let mut cur = TileEntry { node: bvh.root(), parent: u32::MAX, slot: 0 };
    'outer: loop {
        'descend: {
            while !cur.node.is_leaf() {
                let idx = cur.node.node_index();
                let node = &bvh.nodes[idx];
                let (mut mask, _) = fr.intersect_node(node);
                if mask == 0 {
                    break 'descend;
                }
                let first = mask.trailing_zeros();
                mask &= mask - 1;
                while mask != 0 {
                    let i = 31 - mask.leading_zeros();
                    mask &= !(1 << i);
                    stack.push(TileEntry { node: node.children[i as usize], parent: idx as u32, slot: i }, 0.0);
                }
                cur = TileEntry { node: node.children[first as usize], parent: idx as u32, slot: first };
            }
            let parent = &bvh.nodes[cur.parent as usize];
            for (p, occ) in packets.iter().zip(occluded.iter_mut()) {
                let act = p.active & !*occ;
                if act.bitmask() == 0 {
                    continue;
                }
                let (m, _) = p.intersect_box(parent, cur.slot as usize);
                let m = m & act;
                if m.bitmask() != 0 {
                    let o = p.occluded_leaf(bvh, cur.node, m);
                    remaining -= o.bitmask().count_ones();
                    *occ = *occ | o;
                }
            }
            if remaining == 0 {
                break 'outer;
            }
        }
        match stack.pop() {
            None => break,
            Some((next, _)) => cur = next,
        }
    }
    for (o, occ) in out.iter_mut().zip(occluded.iter()).take(n) {
        *o = occ.bitmask();
    }
}
