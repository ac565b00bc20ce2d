//! Limits every tree and traversal of the BVH layer shares, in a leaf module so that the
//! builders, the kernels, the validators and the cache import them without importing their
//! parent.

/// No tree built here is deeper than this (the builder switches to median splits before
/// reaching it), so fixed-size traversal stacks of `MAX_DEPTH` entries cannot overflow.
pub const MAX_DEPTH: usize = 96;

/// Entries of a BVH8 traversal stack: each level pushes at most 7 siblings.
pub const BVH8_STACK: usize = 7 * MAX_DEPTH + 8;
