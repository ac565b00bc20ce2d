//! SoA leaf blocks of M triangles and the SIMD Möller–Trumbore test (Möller & Trumbore,
//! "Fast, Minimum Storage Ray/Triangle Intersection", JGT 1997) on them.
//!
//! A block stores, per lane, the first vertex `v0` and the edges `e1 = v1 - v0`,
//! `e2 = v2 - v0` as rows of M floats (Embree's `TriangleM` without the precomputed normal:
//! the normal costs 3 more rows of memory and is 9 cheap lane operations to recompute).
//! Padding lanes have zero edges, so their determinant is exactly 0 and they never hit.
//!
//! One routine, [`moller_trumbore`], serves both directions of SIMD: one ray (broadcast)
//! against the M triangles of a block, and K rays of a packet against one triangle
//! (broadcast). It performs the scalar reference's operations in the scalar reference's
//! order with a true division, so every lane is bit-identical to
//! [`intersect_triangle_edges`] — the scalar twin — and hit distances (and thus checksums)
//! agree exactly with the reference BVH whatever order the traversal visits primitives in.
//!
//! M = 4 and M = 8 are both provided; see `DefaultTriBlock` in [`crate::bvh`] for which one
//! the scene uses and the measurement that chose it.

use crate::geometry::triangle::intersect_triangle_edges;
use crate::math::Vec3;
use crate::simd::{F32x4, F32x8, Lanes, Vec3x};

/// Intersects rays with triangles lane by lane: ray lane `i` against triangle lane `i`
/// (either side may be a broadcast). Returns `(hit mask, t, u, v)`; a lane hits when
/// `t` lies in `(tnear, tfar]`, `u, v >= 0`, `u + v <= 1` and the determinant is finite and
/// non-zero — exactly the conditions of [`intersect_triangle_edges`].
///
/// The division is skipped when no lane can pass: Embree's division-free comparisons of the
/// unscaled `U, V, T` against `|det|` (with their signs flipped by `det`'s) decide, with a
/// relative slack of 2^-16, which lanes might hit; only if one might is `1 / det` computed and
/// the reference's exact tests applied. The slack exceeds the two roundings that separate
/// `u = U * (1/det)` from `U / det` (and the one of `U + V`), so the filter never rejects a
/// lane the exact test would accept; lanes whose `|det|` is below 2^-100 (where `u` could
/// round to `-0.0`) or whose `U, V, T` are not finite always pass it.
#[inline(always)]
pub fn moller_trumbore<V: Lanes>(
    origin: &Vec3x<V>,
    dir: &Vec3x<V>,
    tnear: V,
    tfar: V,
    v0: &Vec3x<V>,
    e1: &Vec3x<V>,
    e2: &Vec3x<V>,
) -> (V, V, V, V) {
    const SLACK: f32 = 1.0 / 65536.0;
    const TINY_DET: f32 = 7.888_609e-31; // 2^-100
    let zero = V::splat(0.0);
    let one = V::splat(1.0);
    let p = dir.cross(*e2);
    let det = e1.dot(p);
    let det_ok = !det.eq(zero) & det.is_finite();
    let s = *origin - *v0;
    let uu = s.dot(p);
    let q = s.cross(*e1);
    let vv = dir.dot(q);
    let tt = e2.dot(q);
    // Division-free necessary conditions (see above).
    let sign = one.copysign(det);
    let a = det & !V::splat(-0.0);
    let (u1, v1, t1) = (uu * sign, vv * sign, tt * sign);
    let lo = -(a * V::splat(SLACK));
    let hi = a * V::splat(1.0 + SLACK);
    let maybe = u1.ge(lo)
        & u1.le(hi)
        & v1.ge(lo)
        & (u1 + v1).le(hi)
        & t1.gt(tnear * a * V::splat(1.0 - SLACK))
        & t1.le(tfar * a * V::splat(1.0 + SLACK));
    let doubtful = a.lt(V::splat(TINY_DET)) | !(uu.is_finite() & vv.is_finite() & tt.is_finite());
    if (det_ok & (maybe | doubtful)).bitmask() == 0 {
        return (zero, zero, zero, zero);
    }
    // The reference's arithmetic, bit for bit.
    let inv_det = one / det;
    let u = uu * inv_det;
    let v = vv * inv_det;
    let t = tt * inv_det;
    let inside = u.ge(zero) & u.le(one) & !v.lt(zero) & !(u + v).gt(one);
    let valid = det_ok & inside & t.gt(tnear) & t.le(tfar);
    (valid, t, u, v)
}

/// A block of M triangles in structure-of-arrays form. Implemented by [`Tri4`] and [`Tri8`].
pub trait TriBlock: Copy + Send + Sync + std::fmt::Debug + 'static {
    /// Lane vector of width M.
    type V: Lanes;
    /// Triangles per block.
    const M: usize;
    /// A block whose lanes are all padding.
    const EMPTY: Self;
    /// Stores triangle `(v0, v1, v2)` with primitive id `prim` in `lane`.
    fn set(&mut self, lane: usize, v0: Vec3, v1: Vec3, v2: Vec3, prim: u32);
    /// First vertices.
    fn v0(&self) -> Vec3x<Self::V>;
    /// First edges.
    fn e1(&self) -> Vec3x<Self::V>;
    /// Second edges.
    fn e2(&self) -> Vec3x<Self::V>;
    /// Primitive id of `lane` (`u32::MAX` for padding).
    fn prim(&self, lane: usize) -> u32;
    /// `v0`, `e1`, `e2` of `lane` as scalars.
    fn lane_edges(&self, lane: usize) -> [Vec3; 3];

    /// One ray against all M triangles: `(hit mask, t, u, v)` per lane.
    #[inline(always)]
    fn intersect1(
        &self,
        origin: &Vec3x<Self::V>,
        dir: &Vec3x<Self::V>,
        tnear: Self::V,
        tfar: Self::V,
    ) -> BlockHits<Self::V> {
        let (mask, t, u, v) = moller_trumbore(origin, dir, tnear, tfar, &self.v0(), &self.e1(), &self.e2());
        BlockHits { mask: mask.bitmask(), t, u, v }
    }

    /// Scalar twin of [`TriBlock::intersect1`]: the reference test on each lane.
    fn intersect1_scalar(&self, origin: Vec3, dir: Vec3, tnear: f32, tfar: f32) -> [Option<(f32, f32, f32)>; 16] {
        let mut out = [None; 16];
        for (lane, o) in out.iter_mut().enumerate().take(Self::M) {
            let [v0, e1, e2] = self.lane_edges(lane);
            *o = intersect_triangle_edges(origin, dir, tnear, tfar, v0, e1, e2);
        }
        out
    }
}

/// Per-lane results of a block test.
#[derive(Clone, Copy, Debug)]
pub struct BlockHits<V> {
    /// Bit `i` set when lane `i` hits.
    pub mask: u32,
    /// Hit distances (meaningful in hit lanes).
    pub t: V,
    /// First barycentric coordinates.
    pub u: V,
    /// Second barycentric coordinates.
    pub v: V,
}

impl<V: Lanes> BlockHits<V> {
    /// The hit lane with the smallest `t` (lowest lane on ties), if any.
    #[inline(always)]
    pub fn closest(&self) -> Option<usize> {
        if self.mask == 0 {
            return None;
        }
        let mut best = self.mask.trailing_zeros() as usize;
        let mut rest = self.mask & (self.mask - 1);
        while rest != 0 {
            let i = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            if self.t.lane(i) < self.t.lane(best) {
                best = i;
            }
        }
        Some(best)
    }
}

macro_rules! tri_block {
    ($(#[$doc:meta])* $name:ident, $m:expr, $v:ty, $align:expr, $size:expr) => {
        $(#[$doc])*
        #[repr(C, align($align))]
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct $name {
            /// `v0` as rows `[x; M], [y; M], [z; M]`.
            pub v0: [[f32; $m]; 3],
            /// `e1 = v1 - v0`, rows as `v0`.
            pub e1: [[f32; $m]; 3],
            /// `e2 = v2 - v0`, rows as `v0`.
            pub e2: [[f32; $m]; 3],
            /// Scene primitive ids; `u32::MAX` in padding lanes.
            pub prim: [u32; $m],
        }
        const _: () = assert!(std::mem::size_of::<$name>() == $size);
        const _: () = assert!(std::mem::align_of::<$name>() == $align);

        impl TriBlock for $name {
            type V = $v;
            const M: usize = $m;
            const EMPTY: Self = Self {
                v0: [[0.0; $m]; 3],
                e1: [[0.0; $m]; 3],
                e2: [[0.0; $m]; 3],
                prim: [u32::MAX; $m],
            };

            fn set(&mut self, lane: usize, v0: Vec3, v1: Vec3, v2: Vec3, prim: u32) {
                let (e1, e2) = (v1 - v0, v2 - v0);
                for a in 0..3 {
                    self.v0[a][lane] = v0[a];
                    self.e1[a][lane] = e1[a];
                    self.e2[a][lane] = e2[a];
                }
                self.prim[lane] = prim;
            }

            #[inline(always)]
            fn v0(&self) -> Vec3x<$v> {
                Vec3x { x: <$v>::load(&self.v0[0]), y: <$v>::load(&self.v0[1]), z: <$v>::load(&self.v0[2]) }
            }

            #[inline(always)]
            fn e1(&self) -> Vec3x<$v> {
                Vec3x { x: <$v>::load(&self.e1[0]), y: <$v>::load(&self.e1[1]), z: <$v>::load(&self.e1[2]) }
            }

            #[inline(always)]
            fn e2(&self) -> Vec3x<$v> {
                Vec3x { x: <$v>::load(&self.e2[0]), y: <$v>::load(&self.e2[1]), z: <$v>::load(&self.e2[2]) }
            }

            #[inline(always)]
            fn prim(&self, lane: usize) -> u32 {
                self.prim[lane]
            }

            fn lane_edges(&self, lane: usize) -> [Vec3; 3] {
                let row = |r: &[[f32; $m]; 3]| Vec3::new(r[0][lane], r[1][lane], r[2][lane]);
                [row(&self.v0), row(&self.e1), row(&self.e2)]
            }
        }
    };
}

tri_block!(
    /// Four triangles, structure of arrays: 160 bytes (40 per triangle).
    Tri4,
    4,
    F32x4,
    32,
    160
);
tri_block!(
    /// Eight triangles, structure of arrays: 320 bytes (40 per triangle), five cache lines.
    Tri8,
    8,
    F32x8,
    64,
    320
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn padding_lanes_never_hit() {
        let mut b = Tri4::EMPTY;
        b.set(1, Vec3::new(-1.0, -1.0, 0.0), Vec3::new(3.0, -1.0, 0.0), Vec3::new(-1.0, 3.0, 0.0), 7);
        let (o, d) = (Vec3::new(0.0, 0.0, 1.0), -Vec3::Z);
        let hits = b.intersect1(&Vec3x::splat(o), &Vec3x::splat(d), F32x4::splat(0.0), F32x4::splat(f32::INFINITY));
        assert_eq!(hits.mask, 0b10);
        assert_eq!(hits.closest(), Some(1));
        assert_eq!(hits.t.lane(1), 1.0);
        // A ray through the origin, where the padding lanes' zero-size triangles sit.
        let hits = b.intersect1(&Vec3x::splat(Vec3::Z), &Vec3x::splat(-Vec3::Z), F32x4::splat(0.0), F32x4::splat(9.0));
        assert_eq!(hits.mask, 0b10);
    }
}
