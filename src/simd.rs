//! SIMD lanes: aliases over the `wide` crate and the few helpers the kernels share.
//!
//! Masks follow `wide`'s convention: a lane is "true" when all its bits are one (the result
//! of a comparison), "false" when all are zero. [`Lanes`] lets one kernel be written once
//! for 4, 8 and 16 lanes (SSE, AVX2 and AVX-512 registers under `target-cpu=native`).
//!
//! Comparisons are IEEE ordered: any NaN operand gives "false", exactly as the scalar `<`,
//! `<=` of the reference kernels do, which keeps every SIMD kernel bit-compatible with its
//! scalar twin.

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

pub use wide::{f32x4, f32x8, f32x16, i32x4, i32x8, i32x16};

/// 4 lanes of `f32` (one SSE register).
pub type F32x4 = f32x4;
/// 8 lanes of `f32` (one AVX2 register): the width of a BVH8 node.
pub type F32x8 = f32x8;
/// 16 lanes of `f32` (one AVX-512 register): the width of [`crate::RayPacket16`].
pub type F32x16 = f32x16;

/// A vector of `f32` lanes with the operations the kernels use. Implemented for
/// [`F32x4`], [`F32x8`] and [`F32x16`].
pub trait Lanes:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + BitAnd<Output = Self>
    + BitOr<Output = Self>
    + Not<Output = Self>
    + std::fmt::Debug
{
    /// Number of lanes.
    const LANES: usize;
    /// Every lane `x`.
    fn splat(x: f32) -> Self;
    /// Loads `LANES` values from the start of `s` (panics when `s` is shorter).
    fn load(s: &[f32]) -> Self;
    /// Stores into the first `LANES` elements of `s`.
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
    /// `min` with `minps` semantics (`self < o ? self : o`; no NaN handling). Named apart
    /// from `wide`'s inherent `min`, which handles NaN at the cost of three instructions.
    fn vmin(self, o: Self) -> Self;
    /// `max` with `maxps` semantics (`self > o ? self : o`; no NaN handling).
    fn vmax(self, o: Self) -> Self;
    /// True lanes where the value is finite.
    fn is_finite(self) -> Self;
    /// `self * a - b` with one rounding (FMA) where the target has it.
    fn mul_sub(self, a: Self, b: Self) -> Self;
    /// Correctly rounded square root.
    fn sqrt(self) -> Self;
    /// Magnitude of `self` with the sign of `sign`.
    fn copysign(self, sign: Self) -> Self;
    /// Smallest lane (lanes must not be NaN).
    fn reduce_min(self) -> f32;
    /// Largest lane (lanes must not be NaN).
    fn reduce_max(self) -> f32;
}

macro_rules! impl_lanes {
    ($t:ty, $n:expr) => {
        impl Lanes for $t {
            const LANES: usize = $n;
            #[inline(always)]
            fn splat(x: f32) -> Self {
                <$t>::splat(x)
            }
            #[inline(always)]
            fn load(s: &[f32]) -> Self {
                assert!(s.len() >= $n, "slice of at least LANES floats");
                // SAFETY: `s` holds at least LANES floats (checked above; the check folds away
                // for fixed-size rows); the read is unaligned and `$t` is plain old data.
                unsafe { (s.as_ptr() as *const $t).read_unaligned() }
            }
            #[inline(always)]
            fn store(self, s: &mut [f32]) {
                s[..$n].copy_from_slice(self.as_array());
            }
            #[inline(always)]
            fn lane(self, i: usize) -> f32 {
                self.as_array()[i]
            }
            #[inline(always)]
            fn lt(self, o: Self) -> Self {
                self.simd_lt(o)
            }
            #[inline(always)]
            fn le(self, o: Self) -> Self {
                self.simd_le(o)
            }
            #[inline(always)]
            fn gt(self, o: Self) -> Self {
                self.simd_gt(o)
            }
            #[inline(always)]
            fn ge(self, o: Self) -> Self {
                self.simd_ge(o)
            }
            #[inline(always)]
            fn eq(self, o: Self) -> Self {
                self.simd_eq(o)
            }
            #[inline(always)]
            fn select(self, t: Self, f: Self) -> Self {
                <$t>::select(self, t, f)
            }
            #[inline(always)]
            fn bitmask(self) -> u32 {
                self.to_bitmask()
            }
            #[inline(always)]
            fn from_bitmask(bits: u32) -> Self {
                let mut a = [0.0f32; $n];
                for (i, x) in a.iter_mut().enumerate() {
                    *x = f32::from_bits(((bits >> i) & 1).wrapping_neg());
                }
                <$t>::new(a)
            }
            #[inline(always)]
            fn vmin(self, o: Self) -> Self {
                self.fast_min(o)
            }
            #[inline(always)]
            fn vmax(self, o: Self) -> Self {
                self.fast_max(o)
            }
            #[inline(always)]
            fn is_finite(self) -> Self {
                <$t>::is_finite(self)
            }
            #[inline(always)]
            fn mul_sub(self, a: Self, b: Self) -> Self {
                <$t>::mul_sub(self, a, b)
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn copysign(self, sign: Self) -> Self {
                let s = <$t>::splat(-0.0);
                (self & !s) | (sign & s)
            }
            #[inline(always)]
            fn reduce_min(self) -> f32 {
                reduce::min(self)
            }
            #[inline(always)]
            fn reduce_max(self) -> f32 {
                reduce::max(self)
            }
        }
    };
}
/// Horizontal min / max: a few shuffles and `minps` / `maxps` (no NaN handling). The
/// portable fallback halves an array, which LLVM vectorises less well.
mod reduce {
    use super::*;

    pub trait Reduce: Copy {
        fn min(self) -> f32;
        fn max(self) -> f32;
    }

    #[inline(always)]
    pub fn min<V: Reduce>(v: V) -> f32 {
        v.min()
    }

    #[inline(always)]
    pub fn max<V: Reduce>(v: V) -> f32 {
        v.max()
    }

    #[allow(dead_code)]
    #[inline(always)]
    fn halving<const N: usize>(mut m: [f32; N], take_min: bool) -> f32 {
        let mut n = N;
        while n > 1 {
            n /= 2;
            for i in 0..n {
                let (a, b) = (m[i], m[i + n]);
                m[i] = if (b < a) == take_min { b } else { a };
            }
        }
        m[0]
    }

    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    mod x86 {
        use std::arch::x86_64::*;

        #[inline(always)]
        pub fn min4(v: __m128) -> f32 {
            // SAFETY: compiled only when the target has these instructions (the cfg above);
            // they only read and write registers.
            unsafe {
                let m = _mm_min_ps(v, _mm_movehl_ps(v, v));
                _mm_cvtss_f32(_mm_min_ss(m, _mm_movehdup_ps(m)))
            }
        }

        #[inline(always)]
        pub fn max4(v: __m128) -> f32 {
            // SAFETY: as in `min4`.
            unsafe {
                let m = _mm_max_ps(v, _mm_movehl_ps(v, v));
                _mm_cvtss_f32(_mm_max_ss(m, _mm_movehdup_ps(m)))
            }
        }

        #[inline(always)]
        pub fn min8(v: __m256) -> f32 {
            // SAFETY: as in `min4`.
            min4(unsafe { _mm_min_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v)) })
        }

        #[inline(always)]
        pub fn max8(v: __m256) -> f32 {
            // SAFETY: as in `min4`.
            max4(unsafe { _mm_max_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v)) })
        }
    }

    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    impl Reduce for f32x4 {
        #[inline(always)]
        fn min(self) -> f32 {
            x86::min4(self.into())
        }
        #[inline(always)]
        fn max(self) -> f32 {
            x86::max4(self.into())
        }
    }

    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    impl Reduce for f32x8 {
        #[inline(always)]
        fn min(self) -> f32 {
            x86::min8(self.into())
        }
        #[inline(always)]
        fn max(self) -> f32 {
            x86::max8(self.into())
        }
    }

    /// 16 lanes: the two halves through 8-lane registers (LLVM turns the array split into
    /// one `vextractf64x4`; the AVX-512 intrinsics need a newer Rust than this crate's MSRV).
    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    impl Reduce for f32x16 {
        #[inline(always)]
        fn min(self) -> f32 {
            let (lo, hi) = halves(self);
            Reduce::min(lo.fast_min(hi))
        }
        #[inline(always)]
        fn max(self) -> f32 {
            let (lo, hi) = halves(self);
            Reduce::max(lo.fast_max(hi))
        }
    }

    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    #[inline(always)]
    fn halves(v: f32x16) -> (f32x8, f32x8) {
        let a = v.to_array();
        (f32x8::new(a[..8].try_into().expect("8 lanes")), f32x8::new(a[8..].try_into().expect("8 lanes")))
    }

    #[allow(unused_macros)]
    macro_rules! portable {
        ($t:ty, $n:expr) => {
            impl Reduce for $t {
                #[inline(always)]
                fn min(self) -> f32 {
                    halving::<$n>(self.to_array(), true)
                }
                #[inline(always)]
                fn max(self) -> f32 {
                    halving::<$n>(self.to_array(), false)
                }
            }
        };
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
    portable!(f32x4, 4);
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
    portable!(f32x8, 8);
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
    portable!(f32x16, 16);
}

impl_lanes!(f32x4, 4);
impl_lanes!(f32x8, 8);
impl_lanes!(f32x16, 16);

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

    /// Lane `i` as a scalar vector.
    #[inline(always)]
    pub fn lane(self, i: usize) -> crate::math::Vec3 {
        crate::math::Vec3::new(self.x.lane(i), self.y.lane(i), self.z.lane(i))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masks_and_reductions() {
        let a = F32x8::new([1.0, 5.0, -2.0, f32::NAN, 0.0, 3.0, 3.0, 9.0]);
        let b = F32x8::splat(3.0);
        assert_eq!(Lanes::lt(a, b).bitmask(), 0b0001_0101);
        assert_eq!(Lanes::le(a, b).bitmask(), 0b0111_0101);
        assert_eq!(Lanes::ge(a, b).bitmask(), 0b1110_0010, "NaN compares false");
        assert_eq!(F32x16::splat(1.0).lt(F32x16::splat(2.0)).bitmask(), 0xFFFF);
        assert_eq!(F32x16::from_bitmask(0xA5C3).bitmask(), 0xA5C3);
        assert_eq!(F32x8::from_bitmask(0x1FF).bitmask(), 0xFF);
        let m = Lanes::gt(a, b);
        assert_eq!(Lanes::select(m, a, b).lane(1), 5.0);
        assert_eq!(Lanes::select(m, a, b).lane(0), 3.0);
        assert_eq!(F32x4::new([4.0, -1.0, 2.0, 8.0]).reduce_min(), -1.0);
        assert_eq!(F32x4::new([4.0, -1.0, 2.0, 8.0]).reduce_max(), 8.0);
        for k in 0..16 {
            let v: [f32; 16] = std::array::from_fn(|i| {
                if i == k {
                    -5.0
                } else if i == 15 - k {
                    9.0
                } else {
                    i as f32 * 0.1
                }
            });
            let (x16, x8) = (F32x16::new(v), F32x8::new(v[..8].try_into().unwrap()));
            assert_eq!((x16.reduce_min(), x16.reduce_max()), (-5.0, 9.0));
            let (lo8, hi8) = v[..8].iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
            assert_eq!((x8.reduce_min(), x8.reduce_max()), (lo8, hi8));
        }
        assert_eq!(bits(0b1010_0001).collect::<Vec<_>>(), vec![0, 5, 7]);
    }
}
