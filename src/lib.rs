//! # raypack
//!
//! A data-oriented SIMD ray tracer with a CS184-style path tracer on top.
//!
//! Layers, each depending only on the ones before it (the table in CONTRIBUTING.md, checked
//! by `tests/layers.rs`): [`fs`] / [`system`] → [`math`] / [`ray`] / [`rng`] / [`simd`] →
//! [`geometry`] → [`bvh`] → [`scene`] → [`render`], [`io`] and the other users of a scene.
//!
//! ```
//! use raypack::{BuildOptions, Material, Ray, SceneBuilder, Vec3};
//!
//! let mut b = SceneBuilder::new();
//! let mat = b.add_material(Material::diffuse(Vec3::splat(0.7)));
//! b.add_mesh(&[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]], mat)?;
//! b.add_sphere(Vec3::new(0.0, 0.0, -5.0), 1.0, mat)?;
//! let (scene, report) = b.commit(&BuildOptions::default());
//! assert_eq!(report.dropped(), 0);
//!
//! let hit = scene.intersect1(&Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z));
//! assert_eq!((hit.prim, hit.t), (0, 1.0)); // the triangle, one unit away
//! assert!(scene.occluded1(&Ray::new(Vec3::new(0.0, 0.0, -1.0), -Vec3::Z))); // the sphere
//! # Ok::<(), raypack::SceneError>(())
//! ```
//!
//! ## Queries
//!
//! In the style of Embree: `intersect*` finds the closest hit, `occluded*` answers whether
//! anything lies on a segment; the suffix says how many rays a call takes. A ray covers `t` in
//! `[tnear, tfar]`, both ends included: a ray that starts on a surface with `tnear = 0` hits
//! it at `t = 0` ([`ray`]).
//!
//! | call | rays | best for |
//! |---|---|---|
//! | [`Scene::intersect1`], [`Scene::occluded1`] | one [`Ray`] | anything; the simplest |
//! | [`Scene::intersect8`], [`Scene::occluded8`] | a [`RayPacket8`] | coherent rays, AVX2 |
//! | [`Scene::intersect16`], [`Scene::occluded16`] | a [`RayPacket16`] | coherent rays, AVX-512 |
//! | [`Scene::intersect_stream`], [`Scene::occluded_stream`] | any slice, over all threads | batches of any kind: camera rays in small tiles, bounces, shadow rays |
//!
//! All of them traverse the same 8-wide BVH ([`Bvh8Node`], SoA leaf blocks of 8 triangles)
//! and return bit-identical hit distances to the scalar reference
//! ([`Scene::intersect1_reference`]); invalid rays ([`Ray::is_valid`]) miss.
//!
//! ```
//! use raypack::{BuildOptions, Hit, Material, Ray, SceneBuilder, StreamOptions, Vec3};
//!
//! let mut b = SceneBuilder::new();
//! let mat = b.add_material(Material::default());
//! b.add_sphere(Vec3::ZERO, 1.0, mat)?;
//! let (scene, _) = b.commit(&BuildOptions::default());
//! let rays: Vec<Ray> = (0..64).map(|i| Ray::new(Vec3::new(0.0, i as f32 * 0.05 - 1.6, 5.0), -Vec3::Z)).collect();
//! let mut hits = vec![Hit::MISS; rays.len()];
//! scene.intersect_stream(&rays, &mut hits, &StreamOptions::POOL);
//! for (r, h) in rays.iter().zip(&hits) {
//!     assert_eq!(h.t, scene.intersect1_reference(r).t);
//! }
//! # Ok::<(), raypack::SceneError>(())
//! ```
#![deny(missing_docs)]

#[cfg(feature = "bench")]
pub mod bench;
pub mod bvh;
#[cfg(feature = "embree")]
pub mod embree;
pub mod fs;
pub mod generate;
pub mod geometry;
pub mod io;
pub mod kernels;
pub mod math;
pub mod ray;
pub mod raysets;
pub mod render;
pub mod rng;
pub mod scene;
pub mod simd;
pub mod system;
#[cfg(test)]
mod testing;

pub use bvh::{
    BuildOptions, BuildQuality, BuildQualityError, Bvh8Node, BvhStats, SplitMethod, StreamKernel, TraversalCounts,
    TreeLayout,
};
pub use math::{Aabb, Mat3, Mat4, Vec3};
pub use ray::{Hit, Ray, RayPacket, RayPacket8, RayPacket16};
pub use scene::{
    Bsdf, CacheError, CacheReport, Camera, CommitReport, Light, Material, MaterialId, Scene, SceneBuilder, SceneError,
    StreamOptions, SurfaceHit, Threads,
};
pub use simd::{Isa, IsaError};
