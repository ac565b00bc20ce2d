//! Primitive intersectors: the scalar reference tests for triangles and spheres, and the
//! SoA leaf blocks whose SIMD kernels are checked against them.
//!
//! The scalar tests are the ground truth: simple, branchy and obviously correct rather than
//! fast. Each SIMD kernel performs the same operations in the same order, lane by lane.

pub mod id_block;
pub mod sphere;
pub mod sphere_block;
pub mod tri_block;
pub mod triangle;
pub mod watertight;

pub use id_block::PrimIds8;
pub use sphere::intersect_sphere;
pub use sphere_block::Sphere4;
pub use tri_block::{MollerTrumboreKernel, Tri4, Tri8, TriBlock, TriangleKernel, TriangleTest, WatertightKernel};
pub use triangle::{intersect_triangle, intersect_triangle_edges};
pub use watertight::intersect_triangle_watertight;
