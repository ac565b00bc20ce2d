//! The scene: a structure-of-arrays store of geometry, materials, lights and camera, plus
//! the acceleration structure built over it at commit.

pub mod builder;
pub mod cache;
pub mod camera;
pub mod footprint;
pub mod light;
pub mod material;
pub mod query;
pub mod snapshot;
pub mod store;
pub mod surface;
pub mod verify;

pub use builder::{CommitReport, SceneBuilder, SceneError, bvh_builds};
pub use cache::{CacheError, CacheReport};
pub use camera::Camera;
pub use light::Light;
pub use material::{Bsdf, Material, MaterialId};
pub use query::{Counting, STREAM_CHUNK, StreamOptions, Threads, par_for_each_chunk, par_for_each_chunk_of};
pub use store::{Scene, SpheresSoa, SurfaceHit, TrianglesSoa};
pub use verify::AccelError;
