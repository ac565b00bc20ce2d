//! The bounds of a packet of coherent rays, by interval arithmetic (Reshetov, Soupikov and
//! Hurley, "Multi-Level Ray Tracing Algorithm", SIGGRAPH 2005; Embree's coherent mode): one
//! 8-wide box test answers "could any ray of the packet hit this child" for all of them. The
//! frustum of a cone of rays ([`Frustum::cone`]: a pixel's camera rays, say) answers the same
//! down the whole tree ([`Bvh8Ref::frustum_may_hit`]), which the renderer uses to skip pixels
//! that cannot hit anything.

use crate::bvh::bvh2::SLAB_WIDEN;
use crate::bvh::bvh8::{Bvh8Ref, LeafBlocks};
use crate::bvh::node::Bvh8Node;
use crate::bvh::node::{LeafKind, NodeRef};
use crate::bvh::stack::{TraversalStack, stack_storage};
use crate::geometry::{TriBlock, TriangleTest};
use crate::math::Vec3;
use crate::simd::{IsaLanes, Lanes, Vec3x};
use std::borrow::Borrow;

/// The interval bounds of a packet of rays whose direction signs agree on every axis, in
/// lanes `V` of 8 (one per child slot of a node).
#[derive(Clone, Copy, Debug)]
pub struct Frustum<V> {
    near: [usize; 3],
    near_org: Vec3x<V>,
    far_org: Vec3x<V>,
    near_rdir: Vec3x<V>,
    far_rdir: Vec3x<V>,
    tnear: V,
    /// Largest `tfar` of the packet's active rays.
    pub tfar: f32,
    /// The same bounds as scalars `[near_org, far_org, near_rdir, far_rdir]` per axis, and
    /// `tnear`, for tests at other widths.
    scalars: [[f32; 3]; 4],
    tnear1: f32,
}

impl<V: Lanes> Frustum<V> {
    /// The frustum of the rays in the `active` (all-ones) lanes of a packet given as rows:
    /// origins `org`, safe reciprocal directions `inv` and the interval `[tnear, tfar]`; `None`
    /// when no lane is active or the direction signs differ on some axis.
    ///
    /// Per axis with reciprocal directions in `[i_lo, i_hi]` (same sign) and origins in
    /// `[o_lo, o_hi]`: the near plane `n` is entered no earlier than `(n - o') · i'` where
    /// `o'` is the origin bound on the far side (`o_hi` for positive directions) and `i'` the
    /// reciprocal of smallest magnitude; the far plane `f` is left no later than
    /// `(f - o'') · i''` with the other bounds. Rounding is monotone in each operand, so these
    /// bound the per-ray values computed by the packet kernels' box test
    /// ([`crate::bvh::traverse_packet`]) and [`crate::bvh::traverse1::Ray1::intersect_node`]
    /// in floating point too. A negative bound is not tight, but the interval starts at
    /// `tnear >= 0`, which makes it harmless.
    #[inline(always)]
    pub fn new<W: Lanes>(org: &Vec3x<W>, inv: &Vec3x<W>, tnear: W, tfar: W, active: W) -> Option<Self> {
        debug_assert_eq!(V::LANES, 8, "one lane per child slot");
        if active.bitmask() == 0 {
            return None;
        }
        let (pinf, ninf) = (W::splat(f32::INFINITY), W::splat(f32::NEG_INFINITY));
        let mut lo = [pinf; 7];
        let mut hi = [ninf; 7];
        let rows = [org.x, org.y, org.z, inv.x, inv.y, inv.z];
        for (k, row) in rows.iter().enumerate() {
            lo[k] = lo[k].vmin(active.select(*row, pinf));
            hi[k] = hi[k].vmax(active.select(*row, ninf));
        }
        lo[6] = lo[6].vmin(active.select(tnear, pinf));
        hi[6] = hi[6].vmax(active.select(tfar, ninf));
        let (mut lo1, mut hi1) = ([0.0f32; 7], [0.0f32; 7]);
        for k in 0..7 {
            (lo1[k], hi1[k]) = (lo[k].reduce_min(), hi[k].reduce_max());
        }
        Self::from_bounds(lo1, hi1)
    }

    /// The frustum of every ray that leaves `origin` along a positive multiple of a vector
    /// in the box `[dir_lo, dir_hi]`, over `t` in `[0, inf)`: a cone of rays given by the
    /// range of their directions (a pixel's camera rays: [`crate::Scene::cone_may_hit`]).
    /// `None` when the box touches a coordinate plane (some component can be 0 or change sign).
    ///
    /// The test is scale-free (`t` is unbounded), so a ray is covered whatever its
    /// direction's length. The box and the reciprocals are widened by 2^-20 of their
    /// magnitude, more than the roundings of a ray's normalised direction and of the
    /// reciprocals: a ray whose exact direction lies in the box is covered as computed.
    #[inline(always)]
    pub fn cone(origin: Vec3, dir_lo: Vec3, dir_hi: Vec3) -> Option<Self> {
        const PAD: f32 = 1.0 / (1 << 20) as f32;
        let widen = |lo: f32, hi: f32| (lo - lo.abs() * PAD, hi + hi.abs() * PAD);
        let (mut lo, mut hi) = ([0.0f32; 7], [0.0f32; 7]);
        for a in 0..3 {
            let (dlo, dhi) = widen(dir_lo[a], dir_hi[a]);
            if !(dlo > 0.0 || dhi < 0.0) || !dlo.is_finite() || !dhi.is_finite() {
                return None;
            }
            // 1/x is decreasing on each side of 0: the reciprocals of [dlo, dhi] are [1/dhi, 1/dlo].
            (lo[3 + a], hi[3 + a]) = widen(1.0 / dhi, 1.0 / dlo);
            (lo[a], hi[a]) = (origin[a], origin[a]);
        }
        (lo[6], hi[6]) = (0.0, f32::INFINITY);
        Self::from_bounds(lo, hi)
    }

    /// The frustum of origins in `[lo, hi][0..3]`, reciprocal directions in
    /// `[lo, hi][3..6]` and `t` in `[lo[6], hi[6]]`.
    #[inline(always)]
    fn from_bounds(lo: [f32; 7], hi: [f32; 7]) -> Option<Self> {
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
        Some(Self {
            near,
            near_org: splat3(near_org),
            far_org: splat3(far_org),
            near_rdir: splat3(near_rdir),
            far_rdir: splat3(far_rdir),
            tnear: V::splat(tn),
            tfar: tf,
            scalars: [near_org, far_org, near_rdir, far_rdir],
            tnear1: tn,
        })
    }

    /// Could any ray of the packet hit the triangles of `block`, laid out for `test`? Bit `i`
    /// is set when lane `i`'s bounding box, grown by 2^-20 of its largest coordinate magnitude
    /// (the rounding of `v0 + e1` and `v0 + e2` is far smaller), passes the same interval
    /// test as [`Frustum::intersect_node`]. `B` must have the block's M lanes.
    #[inline(always)]
    pub fn intersect_triangles<T: TriBlock, B: Lanes>(&self, block: &T, test: TriangleTest) -> u32 {
        let (a, b, c) = (block.rows::<B>(0), block.rows::<B>(1), block.rows::<B>(2));
        let vertices = test == TriangleTest::Watertight;
        let (lx, hx) = triangle_extent(vertices, a.x, b.x, c.x);
        let (ly, hy) = triangle_extent(vertices, a.y, b.y, c.y);
        let (lz, hz) = triangle_extent(vertices, a.z, b.z, c.z);
        let mag = lx.abs().vmax(hx.abs()).vmax(ly.abs().vmax(hy.abs())).vmax(lz.abs().vmax(hz.abs()));
        let pad = mag * B::splat(1.0 / (1 << 20) as f32) + B::splat(f32::MIN_POSITIVE);
        let (lx, ly, lz) = (lx - pad, ly - pad, lz - pad);
        let (hx, hy, hz) = (hx + pad, hy + pad, hz + pad);
        let [no, fo, nr, fr] = self.scalars;
        let sp = B::splat;
        let (nx, fx) = if self.near[0] & 1 == 0 { (lx, hx) } else { (hx, lx) };
        let (ny, fy) = if self.near[1] & 1 == 0 { (ly, hy) } else { (hy, ly) };
        let (nz, fz) = if self.near[2] & 1 == 0 { (lz, hz) } else { (hz, lz) };
        let tn = ((nx - sp(no[0])) * sp(nr[0]))
            .vmax((ny - sp(no[1])) * sp(nr[1]))
            .vmax(((nz - sp(no[2])) * sp(nr[2])).vmax(sp(self.tnear1)));
        let tf = ((fx - sp(fo[0])) * sp(fr[0])).vmin((fy - sp(fo[1])) * sp(fr[1])).vmin((fz - sp(fo[2])) * sp(fr[2]));
        let tf = (tf * sp(SLAB_WIDEN)).vmin(sp(self.tfar));
        tn.le(tf).bitmask()
    }

    /// Could any ray of the packet hit the children of `n` before `self.tfar`? Returns the
    /// mask of such children and lower bounds of their entry distances.
    #[inline(always)]
    pub fn intersect_node(&self, n: &Bvh8Node) -> (u32, V) {
        let b = &n.bounds;
        let tnx = (V::load(&b[self.near[0]]) - self.near_org.x) * self.near_rdir.x;
        let tny = (V::load(&b[self.near[1]]) - self.near_org.y) * self.near_rdir.y;
        let tnz = (V::load(&b[self.near[2]]) - self.near_org.z) * self.near_rdir.z;
        let tfx = (V::load(&b[self.near[0] ^ 1]) - self.far_org.x) * self.far_rdir.x;
        let tfy = (V::load(&b[self.near[1] ^ 1]) - self.far_org.y) * self.far_rdir.y;
        let tfz = (V::load(&b[self.near[2] ^ 1]) - self.far_org.z) * self.far_rdir.z;
        let tn = tnx.vmax(tny).vmax(tnz.vmax(self.tnear));
        let tf = (tfx.vmin(tfy).vmin(tfz) * V::splat(SLAB_WIDEN)).vmin(V::splat(self.tfar));
        (tn.le(tf).bitmask(), tn)
    }
}

impl<T: TriBlock, L: LeafBlocks<T>> Bvh8Ref<'_, T, L> {
    /// Could a ray of frustum `f` hit a primitive? `false` is exact: no ray of the frustum
    /// hits anything. `true` may be conservative: some triangle's bounding box (or some
    /// sphere leaf's box) meets the frustum, or `budget` inner nodes were visited without
    /// deciding. Depth first, stopping at the first such box.
    pub fn frustum_may_hit<I: IsaLanes>(&self, f: &Frustum<I::F8>, mut budget: usize) -> bool {
        let mut items = stack_storage();
        let mut stack = TraversalStack::<NodeRef>::new(&mut items);
        let mut cur = self.root();
        loop {
            if !cur.is_leaf() {
                if budget == 0 {
                    return true;
                }
                budget -= 1;
                let node = &self.nodes[cur.node_index()];
                let (mut mask, _) = f.intersect_node(node);
                while mask != 0 {
                    stack.push(node.children[mask.trailing_zeros() as usize]);
                    mask &= mask - 1;
                }
            } else if cur.kind() == LeafKind::Spheres {
                return true;
            } else {
                for (k, b) in cur.blocks().enumerate() {
                    let lanes = cur.lane_mask(k, T::M);
                    if lanes & f.intersect_triangles::<T, T::Lanes<I>>(self.tris.block(b).borrow(), self.test) != 0 {
                        return true;
                    }
                }
            }
            match stack.pop() {
                Some(next) => cur = next,
                None => return false,
            }
        }
    }
}

/// Every lane `x[axis]`, per axis.
#[inline(always)]
fn splat3<V: Lanes>(x: [f32; 3]) -> Vec3x<V> {
    Vec3x { x: V::splat(x[0]), y: V::splat(x[1]), z: V::splat(x[2]) }
}

/// The extent of triangles on one axis from a block's stored vectors `a, b, c` (the
/// vertices, or `v0` and the edges).
#[inline(always)]
fn triangle_extent<B: Lanes>(vertices: bool, a: B, b: B, c: B) -> (B, B) {
    let (p1, p2) = if vertices { (b, c) } else { (a + b, a + c) };
    (a.vmin(p1).vmin(p2), a.vmax(p1).vmax(p2))
}
