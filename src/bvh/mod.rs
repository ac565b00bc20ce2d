//! Bounding volume hierarchies. The BVH layer knows boxes and primitive ids, never
//! materials or shading.
//!
//! * [`build`] builds a binary BVH ([`Bvh2`]) with a binned surface area heuristic.
//! * [`Bvh2`] is also the scalar reference traversal that faster kernels are tested against.
//! * [`collapse()`] turns it into the 8-wide [`Bvh8`] ([`Bvh8Node`], SoA leaf blocks) that the
//!   SIMD kernels of [`traverse1`] (single rays), [`traverse_interleaved`] (single rays,
//!   several in flight at once) and [`traverse_packet`] (8/16-ray packets, with the
//!   [`frustum`] of coherent ones; the frustum of a cone of rays also answers whether any of
//!   them can hit) traverse; [`queries`] holds their entry points, instantiated per ISA tier
//!   and counting their work through [`counters`].

pub mod array;
pub mod build;
pub mod bvh2;
pub mod bvh8;
pub mod collapse;
pub mod counters;
pub mod frustum;
pub mod limits;
pub mod node;
pub mod queries;
mod stack;
pub mod stats;
pub mod traverse1;
pub mod traverse_interleaved;
pub mod traverse_packet;
pub mod tuning;
pub mod validate;

pub use array::BvhArray;
pub use build::{
    BuildOptions, BuildPrim, BuildQuality, BuildQualityError, SplitMethod, build_bvh2, build_bvh2_kinds,
    build_bvh2_spatial,
};
pub use bvh2::{Bvh2, Bvh2Node};
pub use bvh8::{Bvh8, Bvh8Ref, Bvh8Stats, CompactLeaves, DefaultTriBlock, LeafBlocks, TreeLayout, TreeLayoutError};
pub use collapse::{CollapseMethod, CollapseOptions, PrimShape, collapse, collapse_for};
pub use counters::{Counter, NoCount, TraversalCounts, Work};
pub use limits::{BVH8_STACK, MAX_DEPTH};
pub use node::{Bvh8Node, LeafKind, NodeRef};
pub use queries::StreamKernel;
pub use stats::BvhStats;
