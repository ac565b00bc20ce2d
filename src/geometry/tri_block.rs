// Not split: the block layout and the two triangle tests on it, with their scalar twins and unit tests.
//! SoA leaf blocks of M triangles and the SIMD Möller–Trumbore test (Möller & Trumbore,
//! "Fast, Minimum Storage Ray/Triangle Intersection", JGT 1997) on them.
//!
//! (One file past 600 lines with its unit tests: the block layout, the two triangle tests on
//! it and their kernels are one concept, and the tests check every lane against the scalar twin.)
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
//! One routine, [`moller_trumbore`] (its body `moller_trumbore_with`, which leaves the rare
//! overflow path to the caller), serves both directions of SIMD: one ray (broadcast) against
//! the M triangles of a block, and K rays of a packet against one triangle (broadcast). It performs the scalar reference's operations in the scalar reference's
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
use crate::simd::{IsaLanes, Lanes, Vec3x};

/// Intersects rays with triangles lane by lane: ray lane `i` against triangle lane `i`
/// (either side may be a broadcast). Returns `(hit mask, t, u, v)`; a lane hits when
/// `t` lies in `[tnear, tfar]`, `u, v >= 0`, `u + v <= 1` and the determinant is finite and
/// non-zero — exactly the conditions of [`intersect_triangle_edges`] (and, like it, a hit at
/// the origin is `t = +0.0`).
///
/// The division is skipped when no lane can pass: Embree's division-free comparisons of the
/// unscaled `U, V, T` against `|det|` (with their signs flipped by `det`'s) decide, with a
/// relative slack of 2^-16, which lanes might hit; only if one might is `1 / det` computed and
/// the reference's exact tests applied. The slack exceeds the two roundings that separate
/// `u = U * (1/det)` from `U / det` (and the one of `U + V`), so the filter never rejects a
/// lane the exact test would accept; lanes whose `|det|` is below 2^-100 (where `u` could
/// round to `-0.0`) or whose `T` is not finite always pass it (a non-finite `U` or `V` fails the
/// exact test as well). The filter leaves out what rarely rejects a lane (`U <= |det|`, which
/// `U + V <= |det|` and `V >= 0` nearly imply; a finite `det`): a lane it lets through is
/// decided by the exact tests, so fewer conditions only cost a division now and then.
// PERFORMANCE.md, "Fewer instructions per ray in small trees".
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
    let redo = |t, lanes, inv_det, e2: &Vec3x<V>, q: &Vec3x<V>, _: &Vec3x<V>| {
        redo_t_f64(t, lanes, inv_det, |i| (e2.lane(i), q.lane(i)))
    };
    moller_trumbore_with(origin, dir, tnear, tfar, v0, e1, e2, redo)
}

/// [`moller_trumbore`] with the rare path that redoes an overflowing `t` in `f64` given as
/// `redo(t, lanes, inv_det, e2, q, origin)`. The block test ([`TriBlock::intersect1`]) reads
/// `e2` from the block, which stays in memory, and recomputes `q` there from `origin`: with
/// `e2` and `q` alive past the filter for that path, the single-ray kernel, short of
/// registers, stored both to the stack on every block, rejected or not. The packet kernels'
/// broadcast test keeps the lanes.
// PERFORMANCE.md, "Spills of the single-ray kernel" and "The single-ray kernel's set-up".
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn moller_trumbore_with<V: Lanes>(
    origin: &Vec3x<V>,
    dir: &Vec3x<V>,
    tnear: V,
    tfar: V,
    v0: &Vec3x<V>,
    e1: &Vec3x<V>,
    e2: &Vec3x<V>,
    redo: impl FnOnce(V, u32, V, &Vec3x<V>, &Vec3x<V>, &Vec3x<V>) -> V,
) -> (V, V, V, V) {
    const SLACK: f32 = 1.0 / 65536.0;
    const TINY_DET: f32 = 7.888_609e-31; // 2^-100
    let zero = V::splat(0.0);
    let one = V::splat(1.0);
    let p = dir.cross(*e2);
    let det = e1.dot(p);
    let sign = det & V::splat(-0.0); // the sign bit of det
    let a = det ^ sign; // |det|
    let det_nonzero = a.gt(zero); // NaN fails
    let s = *origin - *v0;
    let uu = s.dot(p);
    let q = s.cross(*e1);
    let vv = dir.dot(q);
    let tt = e2.dot(q);
    // Division-free necessary conditions (see above), on U, V, T times the sign of det (a
    // flip of the sign bit: exact).
    let (u1, v1, t1) = (uu ^ sign, vv ^ sign, tt ^ sign);
    let lo = -(a * V::splat(SLACK));
    let hi = a * V::splat(1.0 + SLACK);
    // `tnear * (1 - SLACK)` is the same for every block of a ray (computed once where the
    // caller's loop allows); its rounding, like the products', is far inside the slack.
    let maybe = u1.ge(lo)
        & v1.ge(lo)
        & (u1 + v1).le(hi)
        & t1.ge(tnear * V::splat(1.0 - SLACK) * a)
        & t1.le(tfar * a * V::splat(1.0 + SLACK));
    // A non-finite U or V fails the exact test too (u or v is then infinite or NaN), so only
    // T needs the exact path when it is not finite (its f64 redo below).
    let doubtful = a.lt(V::splat(TINY_DET)) | !tt.is_finite();
    if (det_nonzero & (maybe | doubtful)).bitmask() == 0 {
        return (zero, zero, zero, zero);
    }
    let det_ok = det_nonzero & a.lt(V::splat(f32::INFINITY)); // and finite
    // The reference's arithmetic, bit for bit.
    let inv_det = one / det;
    let u = uu * inv_det;
    let v = vv * inv_det;
    let mut t = tt * inv_det;
    let inside = u.ge(zero) & u.le(one) & v.ge(zero) & !(u + v).gt(one);
    let overflow = (det_ok & inside & !t.is_finite()).bitmask();
    if overflow != 0 {
        // Rare: the dot product overflowed (origin ~1e13 or more away); redo it in f64.
        // The origin goes to `redo` as a copy made here: a reference to the caller's would
        // keep the caller's lanes in memory on every path.
        let origin = *origin;
        t = redo(t, overflow, inv_det, e2, &q, &origin);
    }
    let t = t + zero; // `-0.0` made `+0.0`, as the reference does
    let valid = det_ok & inside & t.ge(tnear) & t.le(tfar) & t.lt(V::splat(f32::INFINITY));
    (valid, t, u, v)
}

/// `t` with the lanes of `lanes` recomputed by [`crate::geometry::triangle::t_f64`] from
/// each lane's `(e2, q)`.
#[cold]
#[inline(never)]
fn redo_t_f64<V: Lanes>(t: V, lanes: u32, inv_det: V, e2_q: impl Fn(usize) -> (Vec3, Vec3)) -> V {
    let mut out = [0.0f32; 16];
    t.store(&mut out);
    for i in crate::simd::bits(lanes) {
        let (e2, q) = e2_q(i);
        out[i] = crate::geometry::triangle::t_f64(e2, q, inv_det.lane(i));
    }
    V::load(&out)
}

/// A block of M triangles in structure-of-arrays form. Implemented by [`Tri4`] and [`Tri8`].
///
/// A block stores three vectors per triangle, `a`, `b`, `c`, as rows of M floats per axis;
/// what they mean depends on the BVH's [`TriangleTest`]: `v0`, `e1 = v1 - v0`, `e2 = v2 - v0`
/// for Möller–Trumbore, the vertices `v0`, `v1`, `v2` for the watertight test.
pub trait TriBlock: bytemuck::Pod + Send + Sync + std::fmt::Debug + 'static {
    /// M lanes of the ISA `I` (`I::F4` or `I::F8`).
    type Lanes<I: IsaLanes>: Lanes;
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
    /// The M floats of stored vector `r` (0 = `a`, 1 = `b`, 2 = `c`) on `axis` (0 = x).
    fn row_array(&self, r: usize, axis: usize) -> &[f32];
    /// Primitive id of `lane` (`u32::MAX` for padding).
    fn prim(&self, lane: usize) -> u32;
    /// The three stored vectors `a`, `b`, `c` of `lane` as scalars.
    fn lane_rows(&self, lane: usize) -> [Vec3; 3];

    /// Stored vector `r` on `axis` as lanes (`V` must have M lanes).
    #[inline(always)]
    fn row<V: Lanes>(&self, r: usize, axis: usize) -> V {
        debug_assert_eq!(V::LANES, Self::M);
        V::load(self.row_array(r, axis))
    }
    /// Stored vector `r` as lanes.
    #[inline(always)]
    fn rows<V: Lanes>(&self, r: usize) -> Vec3x<V> {
        Vec3x { x: self.row(r, 0), y: self.row(r, 1), z: self.row(r, 2) }
    }
    /// Bit `i` set when lane `i` holds a triangle (not padding).
    #[inline]
    fn live_lanes(&self) -> u32 {
        (0..Self::M).filter(|&l| self.prim(l) != u32::MAX).fold(0, |m, l| m | 1 << l)
    }

    /// One ray against all M triangles of a Möller–Trumbore block: `(hit mask, t, u, v)`
    /// per lane (`V` must have M lanes).
    #[inline(always)]
    fn intersect1<V: Lanes>(&self, origin: &Vec3x<V>, dir: &Vec3x<V>, tnear: V, tfar: V) -> BlockHits<V> {
        let redo = |t, lanes, inv_det, _: &Vec3x<V>, _: &Vec3x<V>, origin: &Vec3x<V>| {
            redo_t_f64(t, lanes, inv_det, |i| {
                let [v0, e1, e2] = self.lane_rows(i);
                // `moller_trumbore`'s operations for `q`, in its order: the same bits.
                (e2, (origin.lane(i) - v0).cross(e1))
            })
        };
        let (mask, t, u, v) =
            moller_trumbore_with(origin, dir, tnear, tfar, &self.rows(0), &self.rows(1), &self.rows(2), redo);
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
    // It costs instructions and, in packets, more wall clock than the instructions show (the
    // per-lane permutation of each broadcast triangle); no memory (the same 40 bytes per
    // triangle). The per-ray shear is computed once per ray (packets: per lane, with lane
    // selects for the axis permutation). PERFORMANCE.md, "Smaller measured choices". Untried:
    // permuting by scalar index when all lanes share `kz` and the swap, as coherent packets do.
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

/// A ray/triangle test as the traversal kernels use it (Embree's primitive intersector):
/// per-ray constants, one ray against the M lanes of a block, K rays against one triangle,
/// and the scalar twin, all on the vectors a block stores in the test's layout. Implemented
/// by [`MollerTrumboreKernel`] and [`WatertightKernel`]; the three tests of one kernel are
/// bit-identical lane by lane. Kernels take it as the type parameter `P`.
pub trait TriangleKernel: 'static {
    /// The test (and block layout) this kernel implements.
    const TEST: TriangleTest;
    /// Per-ray constants of one ray, in lanes `V`.
    type Ray1<V: Lanes>: Copy;
    /// The constants of `ray` (which must be valid).
    fn ray1<V: Lanes>(ray: &Ray) -> Self::Ray1<V>;
    /// One ray against the M triangles of `block`: `(hit mask, t, u, v)` per lane (`V` must
    /// have M lanes).
    fn block<B: TriBlock, V: Lanes>(block: &B, ray: &Self::Ray1<V>, tnear: V, tfar: V) -> BlockHits<V>;
    /// Per-ray constants of K rays (one per lane).
    type RayK<V: Lanes>: Copy;
    /// The constants of the rays `org + t dir` (inactive lanes may hold anything).
    fn ray_k<V: Lanes>(org: &Vec3x<V>, dir: &Vec3x<V>) -> Self::RayK<V>;
    /// K rays against one triangle given by its stored vectors ([`TriBlock::lane_rows`]):
    /// `(hit mask, t, u, v)`.
    fn broadcast<V: Lanes>(rows: &[Vec3; 3], rays: &Self::RayK<V>, tnear: V, tfar: V) -> (V, V, V, V);
    /// The scalar twin, on a triangle's vertices.
    fn scalar(ray: &Ray, tfar: f32, v0: Vec3, v1: Vec3, v2: Vec3) -> Option<(f32, f32, f32)>;
}

/// Origins and directions in lanes: the per-ray constants of Möller–Trumbore.
#[derive(Clone, Copy, Debug)]
pub struct RayLanes<V> {
    /// Origins.
    pub org: Vec3x<V>,
    /// Directions.
    pub dir: Vec3x<V>,
}

/// [`moller_trumbore`] on blocks of `v0`, `e1`, `e2`.
#[derive(Clone, Copy, Debug)]
pub struct MollerTrumboreKernel;

impl TriangleKernel for MollerTrumboreKernel {
    const TEST: TriangleTest = TriangleTest::MollerTrumbore;
    type Ray1<V: Lanes> = RayLanes<V>;
    type RayK<V: Lanes> = RayLanes<V>;

    #[inline(always)]
    fn ray1<V: Lanes>(ray: &Ray) -> RayLanes<V> {
        RayLanes { org: Vec3x::splat(ray.origin), dir: Vec3x::splat(ray.dir) }
    }

    #[inline(always)]
    fn block<B: TriBlock, V: Lanes>(block: &B, ray: &RayLanes<V>, tnear: V, tfar: V) -> BlockHits<V> {
        block.intersect1(&ray.org, &ray.dir, tnear, tfar)
    }

    #[inline(always)]
    fn ray_k<V: Lanes>(org: &Vec3x<V>, dir: &Vec3x<V>) -> RayLanes<V> {
        RayLanes { org: *org, dir: *dir }
    }

    #[inline(always)]
    fn broadcast<V: Lanes>(rows: &[Vec3; 3], rays: &RayLanes<V>, tnear: V, tfar: V) -> (V, V, V, V) {
        let (v0, e1, e2) = (Vec3x::splat(rows[0]), Vec3x::splat(rows[1]), Vec3x::splat(rows[2]));
        moller_trumbore(&rays.org, &rays.dir, tnear, tfar, &v0, &e1, &e2)
    }

    #[inline]
    fn scalar(ray: &Ray, tfar: f32, v0: Vec3, v1: Vec3, v2: Vec3) -> Option<(f32, f32, f32)> {
        crate::geometry::intersect_triangle(ray.origin, ray.dir, ray.tnear, tfar, v0, v1, v2)
    }
}

/// One ray's sheared frame, as lanes for the watertight block test.
#[derive(Clone, Copy, Debug)]
pub struct ShearRay<V> {
    /// `[kx, ky, kz]`.
    axes: [usize; 3],
    /// The origin's `[kx, ky, kz]` components.
    org: [V; 3],
    /// `[Sx, Sy, Sz]`.
    shear: [V; 3],
}

impl<V: Lanes> ShearRay<V> {
    /// Stored vertex `r` of `block`'s lanes relative to the origin, permuted to `[kx, ky, kz]`.
    #[inline(always)]
    fn relative<B: TriBlock>(&self, block: &B, r: usize) -> [V; 3] {
        let [kx, ky, kz] = self.axes;
        [block.row::<V>(r, kx) - self.org[0], block.row::<V>(r, ky) - self.org[1], block.row::<V>(r, kz) - self.org[2]]
    }
}

/// [`crate::geometry::watertight`] on blocks of `v0`, `v1`, `v2`.
#[derive(Clone, Copy, Debug)]
pub struct WatertightKernel;

impl TriangleKernel for WatertightKernel {
    const TEST: TriangleTest = TriangleTest::Watertight;
    type Ray1<V: Lanes> = ShearRay<V>;
    type RayK<V: Lanes> = ShearLanes<V>;

    #[inline(always)]
    fn ray1<V: Lanes>(ray: &Ray) -> ShearRay<V> {
        let (axes, shear) = shear_frame(ray.dir);
        let [kx, ky, kz] = axes;
        ShearRay {
            axes,
            org: [V::splat(ray.origin[kx]), V::splat(ray.origin[ky]), V::splat(ray.origin[kz])],
            shear: [V::splat(shear[0]), V::splat(shear[1]), V::splat(shear[2])],
        }
    }

    #[inline(always)]
    fn block<B: TriBlock, V: Lanes>(block: &B, ray: &ShearRay<V>, tnear: V, tfar: V) -> BlockHits<V> {
        let (a, b, c) = (ray.relative(block, 0), ray.relative(block, 1), ray.relative(block, 2));
        let (mask, t, u, v) = watertight(a, b, c, ray.shear, tnear, tfar, || block.live_lanes());
        BlockHits { mask: mask.bitmask(), t, u, v }
    }

    #[inline(always)]
    fn ray_k<V: Lanes>(org: &Vec3x<V>, dir: &Vec3x<V>) -> ShearLanes<V> {
        ShearLanes::new(org, dir)
    }

    #[inline(always)]
    fn broadcast<V: Lanes>(rows: &[Vec3; 3], rays: &ShearLanes<V>, tnear: V, tfar: V) -> (V, V, V, V) {
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
    ($(#[$doc:meta])* $name:ident, $m:expr, $lanes:ident, $align:expr, $size:expr) => {
        $(#[$doc])*
        #[repr(C, align($align))]
        #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $name {
            /// First stored vector (`v0`) as rows `[x; M], [y; M], [z; M]`.
            pub a: [[f32; $m]; 3],
            /// Second stored vector: `e1 = v1 - v0`, or `v1` in the watertight layout.
            pub b: [[f32; $m]; 3],
            /// Third stored vector: `e2 = v2 - v0`, or `v2` in the watertight layout.
            pub c: [[f32; $m]; 3],
            /// Scene primitive ids; `u32::MAX` in padding lanes.
            pub prim: [u32; $m],
        }
        const _: () = assert!(std::mem::size_of::<$name>() == $size);
        const _: () = assert!(std::mem::align_of::<$name>() == $align);

        impl TriBlock for $name {
            type Lanes<I: IsaLanes> = I::$lanes;
            const M: usize = $m;
            const EMPTY: Self = Self {
                a: [[0.0; $m]; 3],
                b: [[0.0; $m]; 3],
                c: [[0.0; $m]; 3],
                prim: [u32::MAX; $m],
            };

            fn set(&mut self, lane: usize, v0: Vec3, v1: Vec3, v2: Vec3, prim: u32) {
                self.set_vertices(lane, v0, v1 - v0, v2 - v0, prim);
            }

            fn set_vertices(&mut self, lane: usize, v0: Vec3, v1: Vec3, v2: Vec3, prim: u32) {
                for k in 0..3 {
                    self.a[k][lane] = v0[k];
                    self.b[k][lane] = v1[k];
                    self.c[k][lane] = v2[k];
                }
                self.prim[lane] = prim;
            }

            #[inline(always)]
            fn row_array(&self, r: usize, axis: usize) -> &[f32] {
                let rows = match r {
                    0 => &self.a,
                    1 => &self.b,
                    _ => &self.c,
                };
                &rows[axis]
            }

            #[inline(always)]
            fn prim(&self, lane: usize) -> u32 {
                self.prim[lane]
            }

            fn lane_rows(&self, lane: usize) -> [Vec3; 3] {
                let row = |r: &[[f32; $m]; 3]| Vec3::new(r[0][lane], r[1][lane], r[2][lane]);
                [row(&self.a), row(&self.b), row(&self.c)]
            }
        }
    };
}

tri_block!(
    /// Four triangles, structure of arrays: 160 bytes (40 per triangle).
    Tri4,
    4,
    F4,
    32,
    160
);
tri_block!(
    /// Eight triangles, structure of arrays: 320 bytes (40 per triangle), five cache lines.
    Tri8,
    8,
    F8,
    64,
    320
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simd::F32x4;

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

    /// Random triangles (some degenerate, some sharing vertices) and rays aimed at them.
    fn cases(seed: u64) -> Vec<(Ray, [[Vec3; 3]; 8])> {
        let mut rng = crate::rng::Rng::new(seed, 3);
        let mut r3 = move || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0;
        (0..3000)
            .map(|k| {
                let tris: [[Vec3; 3]; 8] = std::array::from_fn(|i| {
                    let (a, b, c) = (r3(), r3(), r3());
                    match (k + i) % 9 {
                        0 => [a, a, c],
                        1 => [a, b, a + (b - a) * 0.5],
                        _ => [a, b * 0.5, c * 0.5],
                    }
                });
                let target = match k % 3 {
                    0 => tris[k % 8][0],
                    1 => (tris[k % 8][1] + tris[k % 8][2]) * 0.5,
                    _ => r3() * 0.5,
                };
                let origin = r3() * 2.0;
                let tn = if k % 5 == 0 { 0.5 } else { 0.0 };
                let tf = if k % 7 == 0 { 1.0 } else { f32::INFINITY };
                (Ray::segment(origin, target - origin, tn, tf), tris)
            })
            .collect()
    }

    /// The block kernels of every ISA tier against their scalar twins, bit for bit: one ray
    /// against blocks of 4 and 8 triangles (both layouts), 16 and 8 rays against one triangle.
    struct BlocksMatchScalar(u64);
    impl crate::simd::isa::IsaOp for BlocksMatchScalar {
        type Output = usize;
        #[inline(always)]
        fn run<I: IsaLanes>(self) -> usize {
            let bits = |h: Option<(f32, f32, f32)>| h.map(|(t, u, v)| (t.to_bits(), u.to_bits(), v.to_bits()));
            let mut hits = 0;
            for (ray, tris) in cases(self.0) {
                let (mut b8, mut w8, mut b4) = (Tri8::EMPTY, Tri8::EMPTY, Tri4::EMPTY);
                for (i, t) in tris.iter().enumerate() {
                    b8.set(i, t[0], t[1], t[2], i as u32);
                    w8.set_vertices(i, t[0], t[1], t[2], i as u32);
                    if i < 4 {
                        b4.set(i, t[0], t[1], t[2], i as u32);
                    }
                }
                let (tn8, tf8) = (I::F8::splat(ray.tnear), I::F8::splat(ray.tfar));
                let mt = MollerTrumboreKernel::block(&b8, &MollerTrumboreKernel::ray1::<I::F8>(&ray), tn8, tf8);
                let wt = WatertightKernel::block(&w8, &WatertightKernel::ray1::<I::F8>(&ray), tn8, tf8);
                let (tn4, tf4) = (I::F4::splat(ray.tnear), I::F4::splat(ray.tfar));
                let m4 = MollerTrumboreKernel::block(&b4, &MollerTrumboreKernel::ray1::<I::F4>(&ray), tn4, tf4);
                for (i, t) in tris.iter().enumerate() {
                    fn lane<V: Lanes>(h: &BlockHits<V>, i: usize) -> Option<(f32, f32, f32)> {
                        (h.mask >> i & 1 != 0).then(|| (h.t.lane(i), h.u.lane(i), h.v.lane(i)))
                    }
                    let want = MollerTrumboreKernel::scalar(&ray, ray.tfar, t[0], t[1], t[2]);
                    hits += want.is_some() as usize;
                    assert_eq!(bits(lane(&mt, i)), bits(want), "{}: M-T lane {i} of {ray:?}", I::ISA);
                    if i < 4 {
                        assert_eq!(bits(lane(&m4, i)), bits(want), "{}: M-T M=4 lane {i} of {ray:?}", I::ISA);
                    }
                    let want = WatertightKernel::scalar(&ray, ray.tfar, t[0], t[1], t[2]);
                    assert_eq!(bits(lane(&wt, i)), bits(want), "{}: watertight lane {i} of {ray:?}", I::ISA);
                }
                // The other direction: K rays (the same ray, shifted per lane) against one triangle.
                let rays: [Ray; 16] =
                    std::array::from_fn(|k| Ray { origin: ray.origin + Vec3::splat(k as f32 * 0.01), ..ray });
                let rows = crate::ray::transpose_rays_in::<I::F8>(&rays);
                let row = |k: usize| Vec3x {
                    x: I::F16::load(&rows[k]),
                    y: I::F16::load(&rows[k + 1]),
                    z: I::F16::load(&rows[k + 2]),
                };
                let (org, dir) = (row(0), row(3));
                let (tn, tf) = (I::F16::load(&rows[6]), I::F16::load(&rows[7]));
                let tri = &tris[0];
                let (m, t, u, v) = MollerTrumboreKernel::broadcast(
                    &[tri[0], tri[1] - tri[0], tri[2] - tri[0]],
                    &MollerTrumboreKernel::ray_k(&org, &dir),
                    tn,
                    tf,
                );
                let (wm, wt, wu, wv) = WatertightKernel::broadcast(tri, &WatertightKernel::ray_k(&org, &dir), tn, tf);
                for (k, r) in rays.iter().enumerate() {
                    let got = (m.bitmask() >> k & 1 != 0).then(|| (t.lane(k), u.lane(k), v.lane(k)));
                    assert_eq!(
                        bits(got),
                        bits(MollerTrumboreKernel::scalar(r, r.tfar, tri[0], tri[1], tri[2])),
                        "{}: M-T packet lane {k}",
                        I::ISA
                    );
                    let got = (wm.bitmask() >> k & 1 != 0).then(|| (wt.lane(k), wu.lane(k), wv.lane(k)));
                    assert_eq!(
                        bits(got),
                        bits(WatertightKernel::scalar(r, r.tfar, tri[0], tri[1], tri[2])),
                        "{}: watertight packet lane {k}",
                        I::ISA
                    );
                }
            }
            hits
        }
    }

    #[test]
    fn block_kernels_match_scalar_on_every_isa() {
        for isa in crate::simd::Isa::available() {
            let hits = crate::simd::isa::dispatch(isa, BlocksMatchScalar(11));
            assert!(hits > 2000, "{isa}: the cases must hit ({hits} hits)");
        }
    }
}
