//! [`Lanes`] for the `wide` crate's `f32x4`, `f32x8` and `f32x16`: the baseline ISA's lanes.
//!
//! `wide` compiles them for the build's own target features (SSE2 in a default x86-64
//! build, NEON on AArch64, scalar arrays elsewhere), so these lanes run on any CPU the
//! binary runs on.

use super::Lanes;
use wide::{f32x4, f32x8, f32x16};

/// Horizontal min (or max) by halving: the lanes' array folded in log2(N) steps, which LLVM
/// turns into shuffles and `minps` / `maxps` (no NaN handling).
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

macro_rules! impl_lanes {
    ($t:ty, $n:expr) => {
        impl Lanes for $t {
            const LANES: usize = $n;
            const INT_ORDER: bool = false;
            #[inline(always)]
            fn splat(x: f32) -> Self {
                <$t>::splat(x)
            }
            #[inline(always)]
            fn load(s: &[f32]) -> Self {
                <$t>::new(s[..$n].try_into().expect("LANES floats"))
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
                <$t>::new(std::array::from_fn(|i| f32::from_bits(((bits >> i) & 1).wrapping_neg())))
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
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn reduce_min(self) -> f32 {
                halving::<$n>(self.to_array(), true)
            }
            #[inline(always)]
            fn reduce_max(self) -> f32 {
                halving::<$n>(self.to_array(), false)
            }
            #[inline(always)]
            fn add_ulps(self, k: Self) -> Self {
                let (a, k) = (self.as_array(), k.as_array());
                <$t>::new(std::array::from_fn(|i| {
                    f32::from_bits((a[i].to_bits() as i32).wrapping_add(k[i] as i32) as u32)
                }))
            }
            #[inline(always)]
            fn max_bits(self, o: Self) -> Self {
                let (a, b) = (self.as_array(), o.as_array());
                <$t>::new(std::array::from_fn(|i| {
                    if (b[i].to_bits() as i32) > (a[i].to_bits() as i32) { b[i] } else { a[i] }
                }))
            }
            #[inline(always)]
            fn min_bits(self, o: Self) -> Self {
                let (a, b) = (self.as_array(), o.as_array());
                <$t>::new(std::array::from_fn(|i| {
                    if (b[i].to_bits() as i32) < (a[i].to_bits() as i32) { b[i] } else { a[i] }
                }))
            }
            #[inline(always)]
            fn gt_bits(self, o: Self) -> Self {
                let (a, b) = (self.as_array(), o.as_array());
                <$t>::new(std::array::from_fn(|i| {
                    f32::from_bits((((a[i].to_bits() as i32) > (b[i].to_bits() as i32)) as u32).wrapping_neg())
                }))
            }
        }
    };
}

impl_lanes!(f32x4, 4);
impl_lanes!(f32x8, 8);
impl_lanes!(f32x16, 16);
