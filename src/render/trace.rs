//! The renderer's only door to ray queries. Camera rays of a tile are traced in one call
//! ([`Tracer::closest_batch`]), shadow rays by occlusion queries and bounce rays by single-ray
//! closest-hit queries, so that switching a kind of ray to another kernel (packets, streams)
//! is a change in this file alone.

use crate::ray::{Hit, Ray};
use crate::scene::Scene;

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

    /// Closest hits of a batch of (coherent) camera rays: `hits[i]` for `rays[i]`, on the
    /// calling thread, as 16-ray packets through the hybrid packet kernel ([`Scene::intersect_batch`]:
    /// a frustum prefilter for coherent packets, single rays for subtrees few lanes want).
    pub fn closest_batch(&self, rays: &[Ray], hits: &mut [Hit]) {
        debug_assert_eq!(rays.len(), hits.len());
        if self.brute_force {
            for (r, h) in rays.iter().zip(hits.iter_mut()) {
                *h = self.closest(r);
            }
        } else {
            self.scene.intersect_batch(rays, hits);
        }
    }

    /// Closest hit of one (incoherent) ray.
    #[inline]
    pub fn closest(&self, ray: &Ray) -> Hit {
        if self.brute_force { self.scene.intersect1_brute_force(ray) } else { self.scene.intersect1(ray) }
    }

    /// True when anything blocks `ray` over `(tnear, tfar]`.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        if self.brute_force { self.scene.intersect1_brute_force(ray).is_hit() } else { self.scene.occluded1(ray) }
    }
}
