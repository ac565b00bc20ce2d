//! Traversal choices that depend on the ISA tier a kernel runs on. They are the BVH's
//! tuning, measured on its kernels, so they live here and the SIMD layer's lanes
//! ([`crate::simd::IsaLanes`]) stay a description of the hardware. Each is a `const fn` of
//! the tier, which the kernels evaluate in `const` blocks: no branch is left at run time.

use crate::simd::Isa;

/// How few of a 16-ray packet's rays without a common direction octant still want a subtree
/// when they finish it one by one ([`crate::bvh::traverse_packet::incoherent_threshold`]).
//
// 4 on AVX-512, where it made diffuse streams faster than 6; on AVX2 4 was no better
// (PERFORMANCE.md, "Streams").
pub const fn incoherent_threshold_16(isa: Isa) -> usize {
    match isa {
        Isa::Avx512 => 4,
        Isa::Baseline | Isa::Avx2 => 6,
    }
}

/// Whether the single-ray kernels take the slot they descend to through predicted branches
/// ([`crate::bvh::traverse1`]; the closest-hit query only in small trees,
/// [`crate::bvh::queries::SPECULATION_MAX_BYTES`]). Not on the baseline tier, where a crate
/// that depends on raypack got less of the gain than the project's own build (PERFORMANCE.md,
/// "Descent slots as predicted branches").
pub const fn speculate_descent(isa: Isa) -> bool {
    match isa {
        Isa::Baseline => false,
        Isa::Avx2 | Isa::Avx512 => true,
    }
}
