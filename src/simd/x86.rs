//! [`Lanes`] over `core::arch` for the AVX2 and AVX-512 tiers: [`M256`] (8 lanes in one
//! `__m256`), [`M512`] (16 lanes in one `__m512`) and [`Pair`] (two registers as one).
//!
//! # Safety
//! Every operation here executes AVX (`M256`) or AVX-512 F/DQ (`M512`) instructions. The
//! types are private to the crate and used only as the lanes of [`super::isa::Avx2`] and
//! [`super::isa::Avx512`], whose kernels run only through [`super::isa::dispatch`], which
//! enters them only on CPUs that have the tier's features (it clamps the requested tier to
//! the detected one). All operations are `#[inline(always)]`, so inside those
//! `#[target_feature]` entry points the intrinsics compile to single instructions.

use super::{Lanes, Transpose8};
use std::arch::x86_64::*;
use std::ops::{Add, BitAnd, BitOr, BitXor, Div, Mul, Neg, Not, Sub};

/// Eight `f32` lanes in one AVX register.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub(crate) struct M256(__m256);

/// Sixteen `f32` lanes in one AVX-512 register.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub(crate) struct M512(__m512);

/// Runs `$e`, which uses AVX or AVX-512 intrinsics.
macro_rules! simd {
    ($e:expr) => {
        // SAFETY: these lanes exist only inside kernels that `isa::dispatch` enters on CPUs
        // with the tier's features (see the module docs); the intrinsic only reads and
        // writes registers.
        unsafe { $e }
    };
}

macro_rules! binary_ops {
    ($t:ident, $add:ident, $sub:ident, $mul:ident, $div:ident, $and:ident, $or:ident, $xor:ident) => {
        impl Add for $t {
            type Output = Self;
            #[inline(always)]
            fn add(self, o: Self) -> Self {
                $t(simd!($add(self.0, o.0)))
            }
        }
        impl Sub for $t {
            type Output = Self;
            #[inline(always)]
            fn sub(self, o: Self) -> Self {
                $t(simd!($sub(self.0, o.0)))
            }
        }
        impl Mul for $t {
            type Output = Self;
            #[inline(always)]
            fn mul(self, o: Self) -> Self {
                $t(simd!($mul(self.0, o.0)))
            }
        }
        impl Div for $t {
            type Output = Self;
            #[inline(always)]
            fn div(self, o: Self) -> Self {
                $t(simd!($div(self.0, o.0)))
            }
        }
        impl BitAnd for $t {
            type Output = Self;
            #[inline(always)]
            fn bitand(self, o: Self) -> Self {
                $t(simd!($and(self.0, o.0)))
            }
        }
        impl BitOr for $t {
            type Output = Self;
            #[inline(always)]
            fn bitor(self, o: Self) -> Self {
                $t(simd!($or(self.0, o.0)))
            }
        }
        impl BitXor for $t {
            type Output = Self;
            #[inline(always)]
            fn bitxor(self, o: Self) -> Self {
                $t(simd!($xor(self.0, o.0)))
            }
        }
        impl Neg for $t {
            type Output = Self;
            #[inline(always)]
            fn neg(self) -> Self {
                $t(simd!($xor(self.0, <$t as Lanes>::splat(-0.0).0)))
            }
        }
        impl Not for $t {
            type Output = Self;
            #[inline(always)]
            fn not(self) -> Self {
                $t(simd!($xor(self.0, <$t as Lanes>::from_bitmask(u32::MAX).0)))
            }
        }
    };
}

binary_ops!(
    M256,
    _mm256_add_ps,
    _mm256_sub_ps,
    _mm256_mul_ps,
    _mm256_div_ps,
    _mm256_and_ps,
    _mm256_or_ps,
    _mm256_xor_ps
);
binary_ops!(
    M512,
    _mm512_add_ps,
    _mm512_sub_ps,
    _mm512_mul_ps,
    _mm512_div_ps,
    _mm512_and_ps,
    _mm512_or_ps,
    _mm512_xor_ps
);

/// Smallest (or largest) lane of four, by two shuffles.
#[inline(always)]
fn reduce4(v: __m128, min: bool) -> f32 {
    simd!({
        let pick = |a, b| if min { _mm_min_ps(a, b) } else { _mm_max_ps(a, b) };
        let m = pick(v, _mm_movehl_ps(v, v));
        _mm_cvtss_f32(pick(m, _mm_movehdup_ps(m)))
    })
}

impl M256 {
    #[inline(always)]
    fn cmp<const P: i32>(self, o: Self) -> Self {
        M256(simd!(_mm256_cmp_ps::<P>(self.0, o.0)))
    }

    #[inline(always)]
    fn reduce(self, min: bool) -> f32 {
        let (lo, hi) = simd!((_mm256_castps256_ps128(self.0), _mm256_extractf128_ps::<1>(self.0)));
        reduce4(simd!(if min { _mm_min_ps(lo, hi) } else { _mm_max_ps(lo, hi) }), min)
    }
}

impl Lanes for M256 {
    const LANES: usize = 8;
    const INT_ORDER: bool = true;
    #[inline(always)]
    fn splat(x: f32) -> Self {
        M256(simd!(_mm256_set1_ps(x)))
    }
    #[inline(always)]
    fn load(s: &[f32]) -> Self {
        let s = &s[..8];
        M256(simd!(_mm256_loadu_ps(s.as_ptr())))
    }
    #[inline(always)]
    fn store(self, s: &mut [f32]) {
        let s = &mut s[..8];
        simd!(_mm256_storeu_ps(s.as_mut_ptr(), self.0))
    }
    #[inline(always)]
    fn lane(self, i: usize) -> f32 {
        self.to_array()[i]
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Self {
        self.cmp::<_CMP_LT_OQ>(o)
    }
    #[inline(always)]
    fn le(self, o: Self) -> Self {
        self.cmp::<_CMP_LE_OQ>(o)
    }
    #[inline(always)]
    fn gt(self, o: Self) -> Self {
        self.cmp::<_CMP_GT_OQ>(o)
    }
    #[inline(always)]
    fn ge(self, o: Self) -> Self {
        self.cmp::<_CMP_GE_OQ>(o)
    }
    #[inline(always)]
    fn eq(self, o: Self) -> Self {
        self.cmp::<_CMP_EQ_OQ>(o)
    }
    #[inline(always)]
    fn select(self, t: Self, f: Self) -> Self {
        M256(simd!(_mm256_blendv_ps(f.0, t.0, self.0)))
    }
    #[inline(always)]
    fn bitmask(self) -> u32 {
        simd!(_mm256_movemask_ps(self.0)) as u32
    }
    #[inline(always)]
    fn from_bitmask(bits: u32) -> Self {
        simd!({
            let lanes = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            let set = _mm256_and_si256(_mm256_set1_epi32(bits as i32), lanes);
            M256(_mm256_castsi256_ps(_mm256_cmpeq_epi32(set, lanes)))
        })
    }
    #[inline(always)]
    fn vmin(self, o: Self) -> Self {
        M256(simd!(_mm256_min_ps(self.0, o.0)))
    }
    #[inline(always)]
    fn vmax(self, o: Self) -> Self {
        M256(simd!(_mm256_max_ps(self.0, o.0)))
    }
    #[inline(always)]
    fn is_finite(self) -> Self {
        self.abs().lt(Self::splat(f32::INFINITY))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        M256(simd!(_mm256_sqrt_ps(self.0)))
    }
    #[inline(always)]
    fn reduce_min(self) -> f32 {
        self.reduce(true)
    }
    #[inline(always)]
    fn reduce_max(self) -> f32 {
        self.reduce(false)
    }
    #[inline(always)]
    fn add_ulps(self, k: Self) -> Self {
        // `vpaddd` is AVX2, which both tiers using `M256` have.
        M256(simd!(_mm256_castsi256_ps(_mm256_add_epi32(_mm256_castps_si256(self.0), _mm256_cvttps_epi32(k.0)))))
    }
    #[inline(always)]
    fn max_bits(self, o: Self) -> Self {
        M256(simd!(_mm256_castsi256_ps(_mm256_max_epi32(_mm256_castps_si256(self.0), _mm256_castps_si256(o.0)))))
    }
    #[inline(always)]
    fn min_bits(self, o: Self) -> Self {
        M256(simd!(_mm256_castsi256_ps(_mm256_min_epi32(_mm256_castps_si256(self.0), _mm256_castps_si256(o.0)))))
    }
    #[inline(always)]
    fn gt_bits(self, o: Self) -> Self {
        M256(simd!(_mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_castps_si256(self.0), _mm256_castps_si256(o.0)))))
    }
}

impl M512 {
    /// The vector mask of a comparison's mask register (AVX-512 DQ's `vpmovm2d`; LLVM folds
    /// it away when the mask only feeds selects, bit masks and other compares).
    #[inline(always)]
    fn from_k(k: __mmask16) -> Self {
        M512(simd!(_mm512_castsi512_ps(_mm512_movm_epi32(k))))
    }

    #[inline(always)]
    fn k(self) -> __mmask16 {
        simd!(_mm512_movepi32_mask(_mm512_castps_si512(self.0)))
    }

    #[inline(always)]
    fn cmp<const P: i32>(self, o: Self) -> Self {
        Self::from_k(simd!(_mm512_cmp_ps_mask::<P>(self.0, o.0)))
    }

    #[inline(always)]
    fn halves(self) -> (M256, M256) {
        simd!((
            M256(_mm512_castps512_ps256(self.0)),
            M256(_mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(_mm512_castps_pd(self.0))))
        ))
    }
}

impl Lanes for M512 {
    const LANES: usize = 16;
    const INT_ORDER: bool = true;
    #[inline(always)]
    fn splat(x: f32) -> Self {
        M512(simd!(_mm512_set1_ps(x)))
    }
    #[inline(always)]
    fn load(s: &[f32]) -> Self {
        let s = &s[..16];
        M512(simd!(_mm512_loadu_ps(s.as_ptr())))
    }
    #[inline(always)]
    fn store(self, s: &mut [f32]) {
        let s = &mut s[..16];
        simd!(_mm512_storeu_ps(s.as_mut_ptr(), self.0))
    }
    #[inline(always)]
    fn lane(self, i: usize) -> f32 {
        self.to_array()[i]
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Self {
        self.cmp::<_CMP_LT_OQ>(o)
    }
    #[inline(always)]
    fn le(self, o: Self) -> Self {
        self.cmp::<_CMP_LE_OQ>(o)
    }
    #[inline(always)]
    fn gt(self, o: Self) -> Self {
        self.cmp::<_CMP_GT_OQ>(o)
    }
    #[inline(always)]
    fn ge(self, o: Self) -> Self {
        self.cmp::<_CMP_GE_OQ>(o)
    }
    #[inline(always)]
    fn eq(self, o: Self) -> Self {
        self.cmp::<_CMP_EQ_OQ>(o)
    }
    #[inline(always)]
    fn select(self, t: Self, f: Self) -> Self {
        M512(simd!(_mm512_mask_blend_ps(self.k(), f.0, t.0)))
    }
    #[inline(always)]
    fn bitmask(self) -> u32 {
        self.k() as u32
    }
    #[inline(always)]
    fn from_bitmask(bits: u32) -> Self {
        Self::from_k(bits as __mmask16)
    }
    #[inline(always)]
    fn vmin(self, o: Self) -> Self {
        M512(simd!(_mm512_min_ps(self.0, o.0)))
    }
    #[inline(always)]
    fn vmax(self, o: Self) -> Self {
        M512(simd!(_mm512_max_ps(self.0, o.0)))
    }
    #[inline(always)]
    fn is_finite(self) -> Self {
        self.abs().lt(Self::splat(f32::INFINITY))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        M512(simd!(_mm512_sqrt_ps(self.0)))
    }
    #[inline(always)]
    fn reduce_min(self) -> f32 {
        let (lo, hi) = self.halves();
        lo.vmin(hi).reduce_min()
    }
    #[inline(always)]
    fn reduce_max(self) -> f32 {
        let (lo, hi) = self.halves();
        lo.vmax(hi).reduce_max()
    }
    #[inline(always)]
    fn add_ulps(self, k: Self) -> Self {
        M512(simd!(_mm512_castsi512_ps(_mm512_add_epi32(_mm512_castps_si512(self.0), _mm512_cvttps_epi32(k.0)))))
    }
    #[inline(always)]
    fn max_bits(self, o: Self) -> Self {
        M512(simd!(_mm512_castsi512_ps(_mm512_max_epi32(_mm512_castps_si512(self.0), _mm512_castps_si512(o.0)))))
    }
    #[inline(always)]
    fn min_bits(self, o: Self) -> Self {
        M512(simd!(_mm512_castsi512_ps(_mm512_min_epi32(_mm512_castps_si512(self.0), _mm512_castps_si512(o.0)))))
    }
    #[inline(always)]
    fn gt_bits(self, o: Self) -> Self {
        simd!({
            let gt = _mm512_cmpgt_epi32_mask(_mm512_castps_si512(self.0), _mm512_castps_si512(o.0));
            M512(_mm512_castsi512_ps(_mm512_maskz_set1_epi32(gt, -1)))
        })
    }
}

/// Two lane vectors used as one of twice the width (16 lanes from two `M256` on AVX2).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pair<V>(V, V);

macro_rules! pair_op {
    ($tr:ident, $f:ident) => {
        impl<V: Lanes> $tr for Pair<V> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                Pair(self.0.$f(o.0), self.1.$f(o.1))
            }
        }
    };
}
pair_op!(Add, add);
pair_op!(Sub, sub);
pair_op!(Mul, mul);
pair_op!(Div, div);
pair_op!(BitAnd, bitand);
pair_op!(BitOr, bitor);
pair_op!(BitXor, bitxor);

impl<V: Lanes> Neg for Pair<V> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Pair(-self.0, -self.1)
    }
}

impl<V: Lanes> Not for Pair<V> {
    type Output = Self;
    #[inline(always)]
    fn not(self) -> Self {
        Pair(!self.0, !self.1)
    }
}

impl<V: Lanes> Lanes for Pair<V> {
    const LANES: usize = 2 * V::LANES;
    const INT_ORDER: bool = V::INT_ORDER;
    #[inline(always)]
    fn splat(x: f32) -> Self {
        Pair(V::splat(x), V::splat(x))
    }
    #[inline(always)]
    fn load(s: &[f32]) -> Self {
        Pair(V::load(s), V::load(&s[V::LANES..]))
    }
    #[inline(always)]
    fn store(self, s: &mut [f32]) {
        self.0.store(s);
        self.1.store(&mut s[V::LANES..]);
    }
    #[inline(always)]
    fn lane(self, i: usize) -> f32 {
        if i < V::LANES { self.0.lane(i) } else { self.1.lane(i - V::LANES) }
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Self {
        Pair(self.0.lt(o.0), self.1.lt(o.1))
    }
    #[inline(always)]
    fn le(self, o: Self) -> Self {
        Pair(self.0.le(o.0), self.1.le(o.1))
    }
    #[inline(always)]
    fn gt(self, o: Self) -> Self {
        Pair(self.0.gt(o.0), self.1.gt(o.1))
    }
    #[inline(always)]
    fn ge(self, o: Self) -> Self {
        Pair(self.0.ge(o.0), self.1.ge(o.1))
    }
    #[inline(always)]
    fn eq(self, o: Self) -> Self {
        Pair(self.0.eq(o.0), self.1.eq(o.1))
    }
    #[inline(always)]
    fn select(self, t: Self, f: Self) -> Self {
        Pair(self.0.select(t.0, f.0), self.1.select(t.1, f.1))
    }
    #[inline(always)]
    fn bitmask(self) -> u32 {
        self.0.bitmask() | self.1.bitmask() << V::LANES
    }
    #[inline(always)]
    fn from_bitmask(bits: u32) -> Self {
        Pair(V::from_bitmask(bits), V::from_bitmask(bits >> V::LANES))
    }
    #[inline(always)]
    fn vmin(self, o: Self) -> Self {
        Pair(self.0.vmin(o.0), self.1.vmin(o.1))
    }
    #[inline(always)]
    fn vmax(self, o: Self) -> Self {
        Pair(self.0.vmax(o.0), self.1.vmax(o.1))
    }
    #[inline(always)]
    fn is_finite(self) -> Self {
        Pair(self.0.is_finite(), self.1.is_finite())
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Pair(self.0.sqrt(), self.1.sqrt())
    }
    #[inline(always)]
    fn reduce_min(self) -> f32 {
        self.0.vmin(self.1).reduce_min()
    }
    #[inline(always)]
    fn reduce_max(self) -> f32 {
        self.0.vmax(self.1).reduce_max()
    }
    #[inline(always)]
    fn add_ulps(self, k: Self) -> Self {
        Pair(self.0.add_ulps(k.0), self.1.add_ulps(k.1))
    }
    #[inline(always)]
    fn max_bits(self, o: Self) -> Self {
        Pair(self.0.max_bits(o.0), self.1.max_bits(o.1))
    }
    #[inline(always)]
    fn min_bits(self, o: Self) -> Self {
        Pair(self.0.min_bits(o.0), self.1.min_bits(o.1))
    }
    #[inline(always)]
    fn gt_bits(self, o: Self) -> Self {
        Pair(self.0.gt_bits(o.0), self.1.gt_bits(o.1))
    }
}

impl Transpose8 for M256 {
    /// Unpacks, 64-bit shuffles and 128-bit lane permutes: 24 shuffles for 64 floats.
    #[inline(always)]
    fn transpose8(r: [Self; 8]) -> [Self; 8] {
        simd!({
            let t0 = _mm256_unpacklo_ps(r[0].0, r[1].0);
            let t1 = _mm256_unpackhi_ps(r[0].0, r[1].0);
            let t2 = _mm256_unpacklo_ps(r[2].0, r[3].0);
            let t3 = _mm256_unpackhi_ps(r[2].0, r[3].0);
            let t4 = _mm256_unpacklo_ps(r[4].0, r[5].0);
            let t5 = _mm256_unpackhi_ps(r[4].0, r[5].0);
            let t6 = _mm256_unpacklo_ps(r[6].0, r[7].0);
            let t7 = _mm256_unpackhi_ps(r[6].0, r[7].0);
            let s0 = _mm256_shuffle_ps::<0x44>(t0, t2);
            let s1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
            let s2 = _mm256_shuffle_ps::<0x44>(t1, t3);
            let s3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
            let s4 = _mm256_shuffle_ps::<0x44>(t4, t6);
            let s5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
            let s6 = _mm256_shuffle_ps::<0x44>(t5, t7);
            let s7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
            [
                M256(_mm256_permute2f128_ps::<0x20>(s0, s4)),
                M256(_mm256_permute2f128_ps::<0x20>(s1, s5)),
                M256(_mm256_permute2f128_ps::<0x20>(s2, s6)),
                M256(_mm256_permute2f128_ps::<0x20>(s3, s7)),
                M256(_mm256_permute2f128_ps::<0x31>(s0, s4)),
                M256(_mm256_permute2f128_ps::<0x31>(s1, s5)),
                M256(_mm256_permute2f128_ps::<0x31>(s2, s6)),
                M256(_mm256_permute2f128_ps::<0x31>(s3, s7)),
            ]
        })
    }
}
