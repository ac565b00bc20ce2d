//! Bounding volume hierarchies. The BVH layer knows boxes and primitive ids, never
//! materials or shading.
//!
//! * [`build_sah`] builds a binary BVH ([`Bvh2`]) with a binned surface area heuristic.
//! * [`Bvh2`] is also the scalar reference traversal that faster kernels are tested against.

pub mod build_sah;
pub mod bvh2;
pub mod stats;
pub mod validate;

pub use build_sah::{BuildOptions, BuildPrim, BuildQuality, SplitMethod, build_bvh2};
pub use bvh2::{Bvh2, Bvh2Node};
pub use stats::BvhStats;

/// No tree built here is deeper than this (the builder switches to median splits before
/// reaching it), so fixed-size traversal stacks of `MAX_DEPTH` entries cannot overflow.
pub const MAX_DEPTH: usize = 96;
