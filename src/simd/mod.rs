//! SIMD lanes: the [`Lanes`] trait every kernel is written against, its implementations per
//! instruction set, and the run-time choice of instruction set ([`Isa`]).
//!
//! Kernels are written once, generic over a set of lane types ([`IsaLanes`]: 4, 8 and 16
//! lanes of `f32`), and instantiated per instruction set behind `#[target_feature]` entry
//! points ([`isa`]), as Embree compiles its kernels once per ISA and picks one at run time.
//! A plain build (no `-C target-cpu`) therefore carries SSE2, AVX2 and AVX-512 kernels and
//! uses the best the CPU has.
//!
//! | ISA ([`Isa`]) | 4 lanes | 8 lanes | 16 lanes |
//! |---|---|---|---|
//! | `Baseline` (SSE2 on x86-64) | `wide::f32x4` | `wide::f32x8` | `wide::f32x16` |
//! | `Avx2` (AVX2, FMA, BMI) | `wide::f32x4` (VEX) | one `__m256` | two `__m256` |
//! | `Avx512` (F, VL, DQ, BW, CD) | `wide::f32x4` (VEX) | one `__m256` (EVEX) | one `__m512` |
//!
//! The baseline uses the `wide` crate, which compiles for the build's own target features
//! (SSE2 by default, NEON on AArch64); the higher tiers wrap `core::arch` intrinsics
//! (module `x86`), because `wide` picks its implementation when it is compiled, not at run time.
//!
//! Masks follow `wide`'s convention: a lane is "true" when all its bits are one (the result
//! of a comparison), "false" when all are zero. Comparisons are IEEE ordered: any NaN operand
//! gives "false", exactly as the scalar `<`, `<=` of the reference kernels do, which keeps
//! every SIMD kernel bit-compatible with its scalar twin whatever the ISA. No kernel uses
//! fused multiply-adds, for the same reason.

use std::ops::{Add, BitAnd, BitOr, BitXor, Div, Mul, Neg, Not, Sub};

pub mod isa;
mod portable;
#[cfg(target_arch = "x86_64")]
pub(crate) mod x86;

pub use isa::{Baseline, Isa, IsaError, IsaLanes};
pub use portable::F32x1;
pub use wide::{f32x4, f32x8, f32x16, i32x4, i32x8, i32x16};

/// 4 lanes of `f32` of the baseline ISA (an SSE register in a default x86-64 build).
pub type F32x4 = f32x4;
/// 8 lanes of `f32` of the baseline ISA: the width N of a BVH8 node.
pub type F32x8 = f32x8;
/// 16 lanes of `f32` of the baseline ISA: the width K of a [`crate::RayPacket16`].
pub type F32x16 = f32x16;

/// A vector of `f32` lanes with the operations the kernels use. Implemented by the lane
/// types of every ISA (see the module docs); kernels never assume which.
pub trait Lanes:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + BitAnd<Output = Self>
    + BitOr<Output = Self>
    + BitXor<Output = Self>
    + Not<Output = Self>
    + std::fmt::Debug
{
    /// Number of lanes.
    const LANES: usize;
    /// True where [`Lanes::max_bits`], [`Lanes::min_bits`] and [`Lanes::gt_bits`] are one
    /// instruction each (AVX2 and above); on SSE2 each is three or four, against one for the
    /// float forms, so kernels that could use either use the float forms there.
    const INT_ORDER: bool;
    /// Every lane `x`.
    fn splat(x: f32) -> Self;
    /// Loads `LANES` values from the start of `s` (panics when `s` is shorter).
    fn load(s: &[f32]) -> Self;
    /// Stores into the first `LANES` elements of `s` (panics when `s` is shorter).
    fn store(self, s: &mut [f32]);
    /// Lane `i`.
    fn lane(self, i: usize) -> f32;
    /// `self < o` per lane.
    fn lt(self, o: Self) -> Self;
    /// `self <= o` per lane.
    fn le(self, o: Self) -> Self;
    /// `self > o` per lane.
    fn gt(self, o: Self) -> Self;
    /// `self >= o` per lane.
    fn ge(self, o: Self) -> Self;
    /// `self == o` per lane.
    fn eq(self, o: Self) -> Self;
    /// Lanes of `t` where `self` is true, of `f` elsewhere.
    fn select(self, t: Self, f: Self) -> Self;
    /// Bit `i` set when lane `i` of the mask is true.
    fn bitmask(self) -> u32;
    /// The mask whose lane `i` is true when bit `i` of `bits` is set.
    fn from_bitmask(bits: u32) -> Self;
    /// `min` with `minps` semantics (`self < o ? self : o`; no NaN handling).
    fn vmin(self, o: Self) -> Self;
    /// `max` with `maxps` semantics (`self > o ? self : o`; no NaN handling).
    fn vmax(self, o: Self) -> Self;
    /// True lanes where the value is finite.
    fn is_finite(self) -> Self;
    /// Correctly rounded square root.
    fn sqrt(self) -> Self;
    /// Smallest lane (lanes must not be NaN).
    fn reduce_min(self) -> f32;
    /// Largest lane (lanes must not be NaN).
    fn reduce_max(self) -> f32;
    /// `self` stepped by `k` units in the last place: the bits of each lane, read as an
    /// `i32`, plus `k` truncated toward zero (`cvttps2dq`). `k` must be finite and within
    /// `i32`'s range, where Rust's `k as i32` agrees.
    fn add_ulps(self, k: Self) -> Self;
    /// Lane-wise maximum of the lanes' bits read as `i32`: the float maximum where one of the
    /// two is `+0.0` or above (a negative float reads as a negative integer), with no NaN
    /// (a NaN reads as an integer too). One cycle of latency where the float maximum takes up
    /// to four.
    fn max_bits(self, o: Self) -> Self;
    /// Lane-wise minimum of the lanes' bits read as `i32` (see [`Lanes::max_bits`]).
    fn min_bits(self, o: Self) -> Self;
    /// True in the lanes where `self` is greater than `o`, both read as `i32`: the float `>`
    /// where `self` is `+0.0` or above, except that `+0.0 > -0.0` is true.
    fn gt_bits(self, o: Self) -> Self;

    /// Magnitude of each lane (the sign bit cleared).
    #[inline(always)]
    fn abs(self) -> Self {
        self & !Self::splat(-0.0)
    }

    /// Magnitude of `self` with the sign of `sign`.
    #[inline(always)]
    fn copysign(self, sign: Self) -> Self {
        let s = Self::splat(-0.0);
        (self & !s) | (sign & s)
    }

    /// The lanes as an array (only the first `LANES` entries are meaningful).
    #[inline(always)]
    fn to_array(self) -> [f32; 16] {
        let mut a = [0.0f32; 16];
        self.store(&mut a);
        a
    }
}

/// 8 lanes that can be transposed as an 8 x 8 matrix (rays into packet rows).
pub trait Transpose8: Lanes {
    /// The transpose of the matrix whose rows are `rows`.
    fn transpose8(rows: [Self; 8]) -> [Self; 8];
}

impl Transpose8 for F32x8 {
    /// Four 4 × 4 transposes of the rows' halves (`wide`'s `f32x4::transpose`, SSE shuffles).
    /// `wide`'s own `f32x8::transpose` moves lane by lane through memory when AVX is not
    /// enabled at compile time, as in this baseline tier, and made `RayPacket16::from_rays`
    /// as slow as tracing the packet's camera rays (PERFORMANCE.md, "Packets from rays").
    #[inline(always)]
    fn transpose8(rows: [Self; 8]) -> [Self; 8] {
        let halves: [[F32x4; 2]; 8] = rows.map(bytemuck::cast);
        let block = |bi: usize, bj: usize| F32x4::transpose(std::array::from_fn(|k| halves[4 * bi + k][bj]));
        // Block (bi, bj) holds lanes 4 bj .. 4 bj + 4 of rows 4 bi .. 4 bi + 4; transposed,
        // lanes 4 bi .. 4 bi + 4 of rows 4 bj .. 4 bj + 4.
        let t = [[block(0, 0), block(0, 1)], [block(1, 0), block(1, 1)]];
        std::array::from_fn(|j| bytemuck::cast([t[0][j / 4][j % 4], t[1][j / 4][j % 4]]))
    }
}

/// A 3-vector of lanes (structure of arrays): lane `i` of `x`, `y`, `z` is one vector.
#[derive(Clone, Copy, Debug)]
pub struct Vec3x<V> {
    /// x components.
    pub x: V,
    /// y components.
    pub y: V,
    /// z components.
    pub z: V,
}

impl<V: Lanes> Vec3x<V> {
    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(v: crate::math::Vec3) -> Self {
        Self { x: V::splat(v.x), y: V::splat(v.y), z: V::splat(v.z) }
    }

    /// Lane-wise cross product, with the operation order of `glam::Vec3::cross` so that
    /// each lane is bit-identical to the scalar result.
    #[inline(always)]
    pub fn cross(self, o: Self) -> Self {
        Self { x: self.y * o.z - o.y * self.z, y: self.z * o.x - o.z * self.x, z: self.x * o.y - o.x * self.y }
    }

    /// Lane-wise dot product, summed in the order of `glam::Vec3::dot`.
    #[inline(always)]
    pub fn dot(self, o: Self) -> V {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// The vectors whose `x`, `y` and `z` are rows 0, 1 and 2 of `rows` (each at least
    /// `V::LANES` long).
    #[inline(always)]
    pub fn load_rows<const N: usize>(rows: &[[f32; N]; 3]) -> Self {
        Self { x: V::load(&rows[0]), y: V::load(&rows[1]), z: V::load(&rows[2]) }
    }

    /// Stores `x`, `y` and `z` into rows 0, 1 and 2 of `rows`.
    #[inline(always)]
    pub fn store_rows<const N: usize>(self, rows: &mut [[f32; N]; 3]) {
        self.x.store(&mut rows[0]);
        self.y.store(&mut rows[1]);
        self.z.store(&mut rows[2]);
    }

    /// Lanes of `t` where `mask` is true, of `f` elsewhere.
    #[inline(always)]
    pub fn select(mask: V, t: Self, f: Self) -> Self {
        Self { x: mask.select(t.x, f.x), y: mask.select(t.y, f.y), z: mask.select(t.z, f.z) }
    }

    /// Lane `i` as a scalar vector.
    #[inline(always)]
    pub fn lane(self, i: usize) -> crate::math::Vec3 {
        crate::math::Vec3::new(self.x.lane(i), self.y.lane(i), self.z.lane(i))
    }
}

impl From<crate::math::Vec3> for Vec3x<F32x1> {
    /// The vector as one lane.
    #[inline(always)]
    fn from(v: crate::math::Vec3) -> Self {
        Self::splat(v)
    }
}

impl From<Vec3x<F32x1>> for crate::math::Vec3 {
    /// The vector of the one lane.
    #[inline(always)]
    fn from(v: Vec3x<F32x1>) -> Self {
        crate::math::Vec3::new(v.x.0, v.y.0, v.z.0)
    }
}

impl<V: Lanes> Neg for Vec3x<V> {
    type Output = Self;
    /// Lane-wise negation.
    #[inline(always)]
    fn neg(self) -> Self {
        Self { x: -self.x, y: -self.y, z: -self.z }
    }
}

impl<V: Lanes> Add for Vec3x<V> {
    type Output = Self;
    /// Lane-wise sum.
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self { x: self.x + o.x, y: self.y + o.y, z: self.z + o.z }
    }
}

impl<V: Lanes> Mul<V> for Vec3x<V> {
    type Output = Self;
    /// Each component times the lanes of `s` (`glam::Vec3 * f32` per lane).
    #[inline(always)]
    fn mul(self, s: V) -> Self {
        Self { x: self.x * s, y: self.y * s, z: self.z * s }
    }
}

impl<V: Lanes> Div<V> for Vec3x<V> {
    type Output = Self;
    /// Each component divided by the lanes of `s` (`glam::Vec3 / f32` per lane: three
    /// divisions, not a reciprocal).
    #[inline(always)]
    fn div(self, s: V) -> Self {
        Self { x: self.x / s, y: self.y / s, z: self.z / s }
    }
}

impl<V: Lanes> Sub for Vec3x<V> {
    type Output = Self;
    /// Lane-wise difference.
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Self { x: self.x - o.x, y: self.y - o.y, z: self.z - o.z }
    }
}

/// Iterates over the indices of the set bits of `mask`, lowest first.
#[inline(always)]
pub fn bits(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        if mask == 0 {
            None
        } else {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            Some(i)
        }
    })
}

/// `V::transpose8` checked on a matrix of distinct values (the unit tests of every ISA's
/// lanes call this).
#[cfg(test)]
pub(crate) fn check_transpose8<V: Transpose8>() {
    let rows: [V; 8] = std::array::from_fn(|i| V::load(&std::array::from_fn::<f32, 8, _>(|j| (8 * i + j) as f32)));
    for (j, column) in V::transpose8(rows).iter().enumerate() {
        for i in 0..8 {
            assert_eq!(column.lane(i), (8 * i + j) as f32, "row {j}, lane {i} of the transpose");
        }
    }
}

/// The lane operations checked on one lane type against scalar arithmetic (the unit tests of
/// every ISA's lanes call this).
#[cfg(test)]
pub(crate) fn check_lanes<V: Lanes>() {
    let n = V::LANES;
    let pattern =
        [1.0, 5.0, -2.0, f32::NAN, 0.0, 3.0, 3.0, 9.0, -0.0, f32::INFINITY, -7.5, 2.0, 3.0, 1e30, -1e-30, 4.0];
    let a = V::load(&pattern);
    let b = V::splat(3.0);
    let want = |f: &dyn Fn(f32) -> bool| (0..n).filter(|&i| f(pattern[i])).fold(0u32, |m, i| m | 1 << i);
    assert_eq!(a.lt(b).bitmask(), want(&|x| x < 3.0));
    assert_eq!(a.le(b).bitmask(), want(&|x| x <= 3.0));
    assert_eq!(a.gt(b).bitmask(), want(&|x| x > 3.0));
    assert_eq!(a.ge(b).bitmask(), want(&|x| x >= 3.0), "NaN compares false");
    assert_eq!(a.eq(b).bitmask(), want(&|x| x == 3.0));
    assert_eq!(a.is_finite().bitmask(), want(&|x| x.is_finite()));
    let all = if n == 32 { u32::MAX } else { (1u32 << n) - 1 };
    for bits in [0, 1, 0xA5C3 & all, all, 0x8000_0001 & all] {
        assert_eq!(V::from_bitmask(bits).bitmask(), bits);
        assert_eq!((!V::from_bitmask(bits)).bitmask(), !bits & all);
    }
    let m = a.gt(b);
    let s = m.select(a, b).to_array();
    let (arr, mn, mx) = (a.to_array(), a.vmin(b).to_array(), a.vmax(b).to_array());
    let (sum, quo, neg) = ((a + b).to_array(), (a / b).to_array(), (-a).to_array());
    let (sq, cs) = (a.abs().sqrt().to_array(), b.copysign(a).to_array());
    for i in 0..n {
        let x = pattern[i];
        assert_eq!(arr[i].to_bits(), x.to_bits());
        assert_eq!(a.lane(i).to_bits(), x.to_bits());
        assert_eq!(s[i].to_bits(), if x > 3.0 { x } else { 3.0f32 }.to_bits());
        assert_eq!(mn[i].to_bits(), if x < 3.0 { x } else { 3.0f32 }.to_bits(), "minps semantics");
        assert_eq!(mx[i].to_bits(), if x > 3.0 { x } else { 3.0f32 }.to_bits(), "maxps semantics");
        assert_eq!(sum[i].to_bits(), (x + 3.0).to_bits());
        assert_eq!(quo[i].to_bits(), (x / 3.0).to_bits());
        assert_eq!(neg[i].to_bits(), (-x).to_bits());
        assert_eq!(sq[i].to_bits(), x.abs().sqrt().to_bits());
        assert_eq!(cs[i].to_bits(), 3.0f32.copysign(x).to_bits());
    }
    let mut out = [0.0f32; 16];
    (a * b - b).store(&mut out);
    for i in 0..n {
        assert_eq!(out[i].to_bits(), (pattern[i] * 3.0 - 3.0).to_bits());
    }
    let finite: Vec<f32> = (0..n).map(|i| ((i * 7 + 3) % 11) as f32 - 4.5).collect();
    for k in 0..n {
        let mut v = finite.clone();
        v[k] = -50.0;
        v[n - 1 - k] = if n - 1 - k == k { -50.0 } else { 60.0 };
        let x = V::load(&v);
        let (lo, hi) = v.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
        assert_eq!((x.reduce_min(), x.reduce_max()), (lo, hi));
    }
    let steps = [3.7f32, -2.2, 0.0, -0.9, 256.0, -256.0, 1.0, 7.9, -3.5, 0.2, 12.0, -12.0, 99.0, -1.0, 2.0, 5.5];
    let ulps = a.add_ulps(V::load(&steps)).to_array();
    for i in 0..n {
        let want = (pattern[i].to_bits() as i32).wrapping_add(steps[i] as i32) as u32;
        assert_eq!(ulps[i].to_bits(), want, "lane {i}");
    }
    // The integer order of the bits, against each lane's neighbour (negative floats, -0.0,
    // infinities and NaN included).
    let mut rotated = pattern;
    rotated[..n].rotate_left(1);
    let c = V::load(&rotated);
    let (imax, imin, igt) = (a.max_bits(c).to_array(), a.min_bits(c).to_array(), a.gt_bits(c).to_array());
    for i in 0..n {
        let (x, y) = (pattern[i].to_bits() as i32, rotated[i].to_bits() as i32);
        assert_eq!(imax[i].to_bits() as i32, x.max(y), "max_bits, lane {i}");
        assert_eq!(imin[i].to_bits() as i32, x.min(y), "min_bits, lane {i}");
        assert_eq!(igt[i].to_bits(), if x > y { u32::MAX } else { 0 }, "gt_bits, lane {i}");
    }
    let bit_and = (V::from_bitmask(0b1010) & V::from_bitmask(0b0110)).bitmask();
    let bit_or = (V::from_bitmask(0b1010) | V::from_bitmask(0b0110)).bitmask();
    let bit_xor = (V::from_bitmask(0b1010) ^ V::from_bitmask(0b0110)).bitmask();
    assert_eq!((bit_and, bit_or, bit_xor), (0b0010 & all, 0b1110 & all, 0b1100 & all));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn portable_lanes() {
        check_lanes::<F32x4>();
        check_lanes::<F32x8>();
        check_lanes::<F32x16>();
        check_transpose8::<F32x8>();
        check_lanes::<F32x1>();
        assert_eq!(bits(0b1010_0001).collect::<Vec<_>>(), vec![0, 5, 7]);
    }
}
