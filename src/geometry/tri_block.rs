//! SoA leaf blocks of M triangles and the SIMD Möller–Trumbore test (Möller & Trumbore,
//! "Fast, Minimum Storage Ray/Triangle Intersection", JGT 1997) on them.
//!
//! A block stores, per lane, the first vertex `v0` and the edges `e1 = v1 - v0`,
//! `e2 = v2 - v0` as rows of M floats (Embree's `TriangleM` without the precomputed normal:
//! the normal costs 3 more rows of memory and is 9 cheap lane operations to recompute).
//! Padding lanes have zero edges, so their determinant is exactly 0 and they never hit.
//!
//! For the watertight test ([`crate::geometry::watertight`]) the same blocks store the exact
//! vertices `v0, v1, v2` in those rows instead ([`TriangleTest::Watertight`]): the same 40
//! bytes per triangle, so the layout costs no memory; padding lanes are three zero vertices
//! (a degenerate triangle, never hit). The traversal kernels are generic over a
//! [`TriangleKernel`], which knows the layout, its per-ray constants and its tests (one ray
//! against a block, K rays against one triangle, and the scalar twin).
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
use crate::geometry::watertight::{ShearLanes, intersect_triangle_watertight, shear_frame, watertight};
use crate::math::Vec3;
use crate::ray::Ray;
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
    let mut t = tt * inv_det;
    let inside = u.ge(zero) & u.le(one) & v.ge(zero) & !(u + v).gt(one);
    let overflow = (det_ok & inside & !t.is_finite()).bitmask();
    if overflow != 0 {
        // Rare: the dot product overflowed (origin ~1e13 or more away); redo it in f64.
        t = redo_t_f64(t, overflow, e2, &q, inv_det);
    }
    let valid = det_ok & inside & t.gt(tnear) & t.le(tfar) & t.lt(V::splat(f32::INFINITY));
    (valid, t, u, v)
}

/// `t` with the lanes of `lanes` recomputed by [`crate::geometry::triangle::t_f64`].
#[cold]
#[inline(never)]
fn redo_t_f64<V: Lanes>(t: V, lanes: u32, e2: &Vec3x<V>, q: &Vec3x<V>, inv_det: V) -> V {
    let mut out = [0.0f32; 16];
    t.store(&mut out);
    for i in crate::simd::bits(lanes) {
        out[i] = crate::geometry::triangle::t_f64(e2.lane(i), q.lane(i), inv_det.lane(i));
    }
    V::load(&out)
}

/// A block of M triangles in structure-of-arrays form. Implemented by [`Tri4`] and [`Tri8`].
pub trait TriBlock: bytemuck::Pod + Send + Sync + std::fmt::Debug + 'static {
    /// Lane vector of width M.
    type V: Lanes;
    /// Triangles per block.
    const M: usize;
    /// A block whose lanes are all padding.
    const EMPTY: Self;
    /// Stores triangle `(v0, v1, v2)` with primitive id `prim` in `lane` as `v0` and edges
    /// (the layout of [`TriangleTest::MollerTrumbore`]).
    fn set(&mut self, lane: usize, v0: Vec3, v1: Vec3, v2: Vec3, prim: u32);
    /// Stores triangle `(v0, v1, v2)` with primitive id `prim` in `lane` as its three exact
    /// vertices (the layout of [`TriangleTest::Watertight`]).
    fn set_vertices(&mut self, lane: usize, v0: Vec3, v1: Vec3, v2: Vec3, prim: u32);
    /// Stores a triangle in the layout of `test`.
    #[inline]
    fn set_for(&mut self, test: TriangleTest, lane: usize, v0: Vec3, v1: Vec3, v2: Vec3, prim: u32) {
        match test {
            TriangleTest::MollerTrumbore => self.set(lane, v0, v1, v2, prim),
            TriangleTest::Watertight => self.set_vertices(lane, v0, v1, v2, prim),
        }
    }
    /// Row `axis` (0 = x, 1 = y, 2 = z) of stored vector `r` (0 = `v0`, 1 = `e1` or `v1`,
    /// 2 = `e2` or `v2`).
    fn row(&self, r: usize, axis: usize) -> Self::V;
    /// First vertices.
    fn v0(&self) -> Vec3x<Self::V>;
    /// First edges.
    fn e1(&self) -> Vec3x<Self::V>;
    /// Second edges.
    fn e2(&self) -> Vec3x<Self::V>;
    /// Primitive id of `lane` (`u32::MAX` for padding).
    fn prim(&self, lane: usize) -> u32;
    /// The three stored vectors of `lane` as scalars: `v0`, `e1`, `e2` in the
    /// Möller–Trumbore layout, `v0`, `v1`, `v2` in the watertight one.
    fn lane_rows(&self, lane: usize) -> [Vec3; 3];
    /// Bit `i` set when lane `i` holds a triangle (not padding).
    #[inline]
    fn live_lanes(&self) -> u32 {
        (0..Self::M).filter(|&l| self.prim(l) != u32::MAX).fold(0, |m, l| m | 1 << l)
    }

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
            let [v0, e1, e2] = self.lane_rows(lane);
            *o = intersect_triangle_edges(origin, dir, tnear, tfar, v0, e1, e2);
        }
        out
    }
}

/// Which ray/triangle test a BVH's leaf blocks are built for, and so what they store.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum TriangleTest {
    /// Möller–Trumbore ([`moller_trumbore`]): blocks store `v0`, `e1 = v1 - v0`, `e2 = v2 - v0`.
    /// Fast, but a ray through a shared edge can slip between the two triangles.
    #[default]
    MollerTrumbore,
    /// Woop, Benthin and Wald's watertight test ([`crate::geometry::watertight`]): blocks
    /// store the exact vertices `v0`, `v1`, `v2`. No ray slips through a shared edge or vertex.
    ///
    /// Cost, measured with `examples/triangle_test_cost.rs` under callgrind (Stanford dragon,
    /// 871k triangles, `raypack bench`'s primary, diffuse and shadow rays at 512 x 384, 265k
    /// rays, one thread, AVX2 build): single-ray kernels 196.0M against 174.2M instructions
    /// (+12.5%), 16-ray packet streams 267.1M against 255.3M (+4.6%). Memory: none (the same
    /// 40 bytes per triangle). The per-ray shear is computed once per ray (packets: per lane,
    /// with lane selects for the axis permutation). Wall clock on the native AVX-512 build
    /// (`raypack bench` on the dragon, 1 thread, two interleaved runs of each): camera rays in
    /// 16-ray packets 27% slower (37.8 / 37.1 against 25.7 / 28.8 Mrays/s), single camera rays
    /// 8%, shadow streams even: the per-lane permutation of each broadcast triangle costs more
    /// there than the instruction count shows. Untried: permuting by scalar index when all
    /// lanes share `kz` and the swap, as coherent packets do.
    Watertight,
}

impl TriangleTest {
    /// The test `BuildOptions::watertight` asks for.
    pub fn from_watertight(watertight: bool) -> Self {
        if watertight { Self::Watertight } else { Self::MollerTrumbore }
    }

    /// Short name, as printed by the CLI.
    pub fn name(self) -> &'static str {
        match self {
            Self::MollerTrumbore => "moller-trumbore",
            Self::Watertight => "watertight",
        }
    }
}

/// A ray/triangle test as the traversal kernels use it: per-ray constants, one ray against
/// the M lanes of a block, K rays against one triangle, and the scalar twin, all on the rows
/// a block stores in the kernel's layout. Implemented by [`MollerTrumboreKernel`] and
/// [`WatertightKernel`]; all three tests of one kernel are bit-identical lane by lane.
pub trait TriangleKernel: 'static {
    /// The test (and block layout) this kernel implements.
    const TEST: TriangleTest;
    /// Per-ray constants of one ray, in lanes of width `W`.
    type Ray1<W: Lanes>: Copy;
    /// The constants of `ray` (which must be valid).
    fn ray1<W: Lanes>(ray: &Ray) -> Self::Ray1<W>;
    /// One ray against the M triangles of `block`: `(hit mask, t, u, v)` per lane.
    fn block<B: TriBlock>(block: &B, ray: &Self::Ray1<B::V>, tnear: B::V, tfar: B::V) -> BlockHits<B::V>;
    /// Per-ray constants of K rays (one per lane).
    type RayK<W: Lanes>: Copy;
    /// The constants of the rays `org + t dir` (inactive lanes may hold anything).
    fn ray_k<W: Lanes>(org: &Vec3x<W>, dir: &Vec3x<W>) -> Self::RayK<W>;
    /// K rays against one triangle given by its stored rows ([`TriBlock::lane_rows`]):
    /// `(hit mask, t, u, v)`.
    fn broadcast<W: Lanes>(rows: &[Vec3; 3], rays: &Self::RayK<W>, tnear: W, tfar: W) -> (W, W, W, W);
    /// The scalar twin, on a triangle's vertices.
    fn scalar(ray: &Ray, tfar: f32, v0: Vec3, v1: Vec3, v2: Vec3) -> Option<(f32, f32, f32)>;
}

/// Origins and directions in lanes: the per-ray constants of Möller–Trumbore.
#[derive(Clone, Copy, Debug)]
pub struct RayLanes<W> {
    /// Origins.
    pub org: Vec3x<W>,
    /// Directions.
    pub dir: Vec3x<W>,
}

/// [`moller_trumbore`] on blocks of `v0`, `e1`, `e2`.
#[derive(Clone, Copy, Debug)]
pub struct MollerTrumboreKernel;

impl TriangleKernel for MollerTrumboreKernel {
    const TEST: TriangleTest = TriangleTest::MollerTrumbore;
    type Ray1<W: Lanes> = RayLanes<W>;
    type RayK<W: Lanes> = RayLanes<W>;

    #[inline(always)]
    fn ray1<W: Lanes>(ray: &Ray) -> RayLanes<W> {
        RayLanes { org: Vec3x::splat(ray.origin), dir: Vec3x::splat(ray.dir) }
    }

    #[inline(always)]
    fn block<B: TriBlock>(block: &B, ray: &RayLanes<B::V>, tnear: B::V, tfar: B::V) -> BlockHits<B::V> {
        block.intersect1(&ray.org, &ray.dir, tnear, tfar)
    }

    #[inline(always)]
    fn ray_k<W: Lanes>(org: &Vec3x<W>, dir: &Vec3x<W>) -> RayLanes<W> {
        RayLanes { org: *org, dir: *dir }
    }

    #[inline(always)]
    fn broadcast<W: Lanes>(rows: &[Vec3; 3], rays: &RayLanes<W>, tnear: W, tfar: W) -> (W, W, W, W) {
        let [v0, e1, e2] = rows.map(Vec3x::splat);
        moller_trumbore(&rays.org, &rays.dir, tnear, tfar, &v0, &e1, &e2)
    }

    #[inline]
    fn scalar(ray: &Ray, tfar: f32, v0: Vec3, v1: Vec3, v2: Vec3) -> Option<(f32, f32, f32)> {
        crate::geometry::intersect_triangle(ray.origin, ray.dir, ray.tnear, tfar, v0, v1, v2)
    }
}

/// One ray's sheared frame, as lanes for the watertight block test.
#[derive(Clone, Copy, Debug)]
pub struct ShearRay<W> {
    /// `[kx, ky, kz]`.
    axes: [usize; 3],
    /// The origin's `[kx, ky, kz]` components.
    org: [W; 3],
    /// `[Sx, Sy, Sz]`.
    shear: [W; 3],
}

/// [`crate::geometry::watertight`] on blocks of `v0`, `v1`, `v2`.
#[derive(Clone, Copy, Debug)]
pub struct WatertightKernel;

impl TriangleKernel for WatertightKernel {
    const TEST: TriangleTest = TriangleTest::Watertight;
    type Ray1<W: Lanes> = ShearRay<W>;
    type RayK<W: Lanes> = ShearLanes<W>;

    #[inline(always)]
    fn ray1<W: Lanes>(ray: &Ray) -> ShearRay<W> {
        let (axes, shear) = shear_frame(ray.dir);
        ShearRay { axes, org: axes.map(|k| W::splat(ray.origin[k])), shear: shear.map(W::splat) }
    }

    #[inline(always)]
    fn block<B: TriBlock>(block: &B, ray: &ShearRay<B::V>, tnear: B::V, tfar: B::V) -> BlockHits<B::V> {
        let [kx, ky, kz] = ray.axes;
        let rel =
            |r: usize| [block.row(r, kx) - ray.org[0], block.row(r, ky) - ray.org[1], block.row(r, kz) - ray.org[2]];
        let (mask, t, u, v) = watertight(rel(0), rel(1), rel(2), ray.shear, tnear, tfar, || block.live_lanes());
        BlockHits { mask: mask.bitmask(), t, u, v }
    }

    #[inline(always)]
    fn ray_k<W: Lanes>(org: &Vec3x<W>, dir: &Vec3x<W>) -> ShearLanes<W> {
        ShearLanes::new(org, dir)
    }

    #[inline(always)]
    fn broadcast<W: Lanes>(rows: &[Vec3; 3], rays: &ShearLanes<W>, tnear: W, tfar: W) -> (W, W, W, W) {
        rays.intersect(rows, tnear, tfar)
    }

    #[inline]
    fn scalar(ray: &Ray, tfar: f32, v0: Vec3, v1: Vec3, v2: Vec3) -> Option<(f32, f32, f32)> {
        intersect_triangle_watertight(ray.origin, ray.dir, ray.tnear, tfar, v0, v1, v2)
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
        #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $name {
            /// `v0` as rows `[x; M], [y; M], [z; M]`.
            pub v0: [[f32; $m]; 3],
            /// `e1 = v1 - v0` (or `v1` in the watertight layout), rows as `v0`.
            pub e1: [[f32; $m]; 3],
            /// `e2 = v2 - v0` (or `v2` in the watertight layout), rows as `v0`.
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

            fn set_vertices(&mut self, lane: usize, v0: Vec3, v1: Vec3, v2: Vec3, prim: u32) {
                for a in 0..3 {
                    self.v0[a][lane] = v0[a];
                    self.e1[a][lane] = v1[a];
                    self.e2[a][lane] = v2[a];
                }
                self.prim[lane] = prim;
            }

            #[inline(always)]
            fn row(&self, r: usize, axis: usize) -> $v {
                let rows = match r {
                    0 => &self.v0,
                    1 => &self.e1,
                    _ => &self.e2,
                };
                <$v>::load(&rows[axis])
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

            fn lane_rows(&self, lane: usize) -> [Vec3; 3] {
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
