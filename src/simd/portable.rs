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

/// One lane of `f32`: the scalar code's [`Lanes`], so that a function written once over lanes
/// serves one value at a time as well as the SIMD kernels (the renderer's shading helpers,
/// whose one-path callers and eight-path steps must agree bit for bit). A mask is an `f32`
/// whose bits are all one (true) or all zero (false), as in `wide`; every operation is the
/// scalar one (`add_ulps` truncates with Rust's `as i32`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(transparent)]
pub struct F32x1(pub f32);

impl F32x1 {
    /// The mask of `b`.
    #[inline(always)]
    fn mask(b: bool) -> Self {
        Self(f32::from_bits((b as u32).wrapping_neg()))
    }

    /// The lane's bits read as an `i32`.
    #[inline(always)]
    fn int(self) -> i32 {
        self.0.to_bits() as i32
    }
}

macro_rules! one_lane_op {
    ($trait:ident, $f:ident, $op:tt) => {
        impl std::ops::$trait for F32x1 {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                Self(self.0 $op o.0)
            }
        }
    };
}
one_lane_op!(Add, add, +);
one_lane_op!(Sub, sub, -);
one_lane_op!(Mul, mul, *);
one_lane_op!(Div, div, /);

macro_rules! one_lane_bits {
    ($trait:ident, $f:ident, $op:tt) => {
        impl std::ops::$trait for F32x1 {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                Self(f32::from_bits(self.0.to_bits() $op o.0.to_bits()))
            }
        }
    };
}
one_lane_bits!(BitAnd, bitand, &);
one_lane_bits!(BitOr, bitor, |);
one_lane_bits!(BitXor, bitxor, ^);

impl std::ops::Neg for F32x1 {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Self(-self.0)
    }
}

impl std::ops::Not for F32x1 {
    type Output = Self;
    #[inline(always)]
    fn not(self) -> Self {
        Self(f32::from_bits(!self.0.to_bits()))
    }
}

impl Lanes for F32x1 {
    const LANES: usize = 1;
    const INT_ORDER: bool = false;
    #[inline(always)]
    fn splat(x: f32) -> Self {
        Self(x)
    }
    #[inline(always)]
    fn load(s: &[f32]) -> Self {
        Self(s[0])
    }
    #[inline(always)]
    fn store(self, s: &mut [f32]) {
        s[0] = self.0;
    }
    #[inline(always)]
    fn lane(self, i: usize) -> f32 {
        [self.0][i]
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Self {
        Self::mask(self.0 < o.0)
    }
    #[inline(always)]
    fn le(self, o: Self) -> Self {
        Self::mask(self.0 <= o.0)
    }
    #[inline(always)]
    fn gt(self, o: Self) -> Self {
        Self::mask(self.0 > o.0)
    }
    #[inline(always)]
    fn ge(self, o: Self) -> Self {
        Self::mask(self.0 >= o.0)
    }
    #[inline(always)]
    fn eq(self, o: Self) -> Self {
        Self::mask(self.0 == o.0)
    }
    #[inline(always)]
    fn select(self, t: Self, f: Self) -> Self {
        if self.0.to_bits() != 0 { t } else { f }
    }
    #[inline(always)]
    fn bitmask(self) -> u32 {
        self.0.to_bits() >> 31
    }
    #[inline(always)]
    fn from_bitmask(bits: u32) -> Self {
        Self::mask(bits & 1 != 0)
    }
    #[inline(always)]
    fn vmin(self, o: Self) -> Self {
        if self.0 < o.0 { self } else { o }
    }
    #[inline(always)]
    fn vmax(self, o: Self) -> Self {
        if self.0 > o.0 { self } else { o }
    }
    #[inline(always)]
    fn is_finite(self) -> Self {
        Self::mask(self.0.is_finite())
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Self(self.0.sqrt())
    }
    #[inline(always)]
    fn reduce_min(self) -> f32 {
        self.0
    }
    #[inline(always)]
    fn reduce_max(self) -> f32 {
        self.0
    }
    #[inline(always)]
    fn add_ulps(self, k: Self) -> Self {
        Self(f32::from_bits(self.int().wrapping_add(k.0 as i32) as u32))
    }
    #[inline(always)]
    fn max_bits(self, o: Self) -> Self {
        if o.int() > self.int() { o } else { self }
    }
    #[inline(always)]
    fn min_bits(self, o: Self) -> Self {
        if o.int() < self.int() { o } else { self }
    }
    #[inline(always)]
    fn gt_bits(self, o: Self) -> Self {
        Self::mask(self.int() > o.int())
    }
    #[inline(always)]
    fn abs(self) -> Self {
        Self(self.0.abs())
    }
    #[inline(always)]
    fn copysign(self, sign: Self) -> Self {
        Self(self.0.copysign(sign.0))
    }
}
