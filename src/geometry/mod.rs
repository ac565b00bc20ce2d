//! Primitive intersectors: the scalar reference tests for triangles and spheres.
//!
//! These are the ground truth the SIMD kernels are checked against: simple, branchy and
//! obviously correct rather than fast.

pub mod sphere;
pub mod triangle;

pub use sphere::intersect_sphere;
pub use triangle::intersect_triangle;
