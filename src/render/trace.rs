//! The renderer's only door to ray queries. Every kind of ray is traced in streams: a batch
//! of rays on the calling thread, as 16-ray packets through the hybrid packet kernels
//! ([`Scene::intersect_stream`], [`Scene::occluded_stream`] with [`RENDER_STREAMS`]), or
//! (`brute_force`) ray by ray against every primitive.
//!
//! Always as packets: the streams of the library's API trace incoherent packets as
//! interleaved single rays in a BVH larger than the last-level cache
//! ([`crate::bvh::traverse_interleaved`]), but the renderer's bounce streams lost by it
//! (PERFORMANCE.md, "Incoherent rays in large trees: several in flight").

use crate::bvh::StreamKernel;
use crate::ray::{Hit, Ray};
use crate::scene::{Scene, StreamOptions};

/// How the renderer's streams run: on the calling thread (the tiles are the parallel work),
/// always as packets, without sphere hits' surface coordinates (shading reads none).
pub const RENDER_STREAMS: StreamOptions = StreamOptions::CALLER.with_kernel(StreamKernel::Packets).without_sphere_uv();

/// Ray queries against a scene, through the BVH or (`brute_force`) against every primitive.
#[derive(Clone, Copy, Debug)]
pub struct Tracer<'a> {
    scene: &'a Scene,
    brute_force: bool,
}

impl<'a> Tracer<'a> {
    /// A tracer for `scene`.
    pub fn new(scene: &'a Scene, brute_force: bool) -> Self {
        Self { scene, brute_force }
    }

    /// The scene traced.
    pub fn scene(&self) -> &'a Scene {
        self.scene
    }

    /// Closest hits of a batch of rays: `hits[i]` for `rays[i]` (same length), on the calling
    /// thread. The packet kernel adapts to coherent rays (a frustum prefilter) and incoherent
    /// ones (single rays for subtrees few lanes want); consecutive rays should travel alike
    /// when they can (see [`super::order`]).
    pub fn intersect_stream(&self, rays: &[Ray], hits: &mut [Hit]) {
        debug_assert_eq!(rays.len(), hits.len());
        if self.brute_force {
            for (r, h) in rays.iter().zip(hits.iter_mut()) {
                *h = self.scene.intersect1_brute_force(r);
            }
        } else {
            self.scene.intersect_stream(rays, hits, &RENDER_STREAMS);
        }
    }

    /// Occlusion of a batch of rays over `[tnear, tfar]`: `occluded[i]` for `rays[i]` (same
    /// length), on the calling thread, with the packets' occluder cache carried along.
    pub fn occluded_stream(&self, rays: &[Ray], occluded: &mut [bool]) {
        debug_assert_eq!(rays.len(), occluded.len());
        if self.brute_force {
            for (r, o) in rays.iter().zip(occluded.iter_mut()) {
                *o = self.scene.intersect1_brute_force(r).is_hit();
            }
        } else {
            self.scene.occluded_stream(rays, occluded, &RENDER_STREAMS);
        }
    }
}
