//! Ray queries on a committed [`Scene`] beyond single rays: 8- and 16-ray packets and
//! streams of any length, run over rayon.
//!
//! All of them use the hybrid packet kernels of [`crate::bvh::traverse_packet`], which adapt
//! to the rays they are given: a frustum prefilter when the packet's direction signs agree
//! (camera and shadow rays), per-lane box tests always, and single-ray traversal for subtrees
//! that only a few of the rays want (incoherent rays).
//!
//! Streams therefore trace every batch as 16-ray packets, coherent or not (single rays for
//! incoherent batches, and tiles of 4 packets under one frustum, were slower: PERFORMANCE.md,
//! "Streams"), but in a tree larger than the last-level cache ([`crate::bvh::Bvh8::interleaves`]):
//! there the rays of incoherent packets are traced as single rays, several in flight at once
//! so that their cache misses overlap ([`crate::bvh::traverse_interleaved`];
//! [`Scene::intersect_interleaved`] and [`Scene::occluded_interleaved`] trace that way
//! whatever the tree). Shadow-ray streams also carry an
//! [`OccluderCache`](crate::bvh::traverse_packet::OccluderCache) from packet to packet.

use crate::bvh::{Counter, NoCount};
use crate::math::Vec3;
use crate::ray::{Hit, Ray, RayPacket8, RayPacket16};
use crate::scene::Scene;
use rayon::prelude::*;

/// Rays per rayon task of the stream queries (64 packets of 16). Every chunk is a task of
/// its own (`with_max_len(1)`): rayon's default split stops at about two tasks per thread
/// and does not split a task once it runs, so a thread could finish its share of a batch and
/// wait for the other's last large task (PERFORMANCE.md, "Work split over threads").
const STREAM_CHUNK: usize = 1024;

macro_rules! packet_queries {
    ($intersect:ident, $occluded:ident, $packet:ty, $mask:ty, $doc_k:expr) => {
        #[doc = concat!("Closest hits of the ", $doc_k, " rays in the lanes set in `valid` (see the packet type for the")]
        /// layout). Hit lanes get `tfar = t`, `u`, `v`, `prim`; missed lanes get
        /// `prim = Hit::NONE`; invalid rays ([`Ray::is_valid`]) miss; lanes outside `valid`
        /// are left as they are.
        ///
        /// ```
        /// # use raypack::{BuildOptions, Material, Ray, RayPacket8, RayPacket16, SceneBuilder, Vec3};
        /// let mut b = SceneBuilder::new();
        /// let m = b.add_material(Material::default());
        /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
        /// let (scene, _) = b.commit(&BuildOptions::default());
        /// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(i as f32 * 0.2, 0.0, 5.0), -Vec3::Z)).collect();
        #[doc = concat!("let (mut packet, valid) = ", stringify!($packet), "::from_rays(&rays);")]
        #[doc = concat!("scene.", stringify!($intersect), "(&mut packet, valid);")]
        /// assert_eq!(packet.hit(0).t, 4.0); // straight at the centre
        /// assert!(packet.hit(4).is_hit() && !packet.hit(6).is_hit()); // x = 0.8 hits, x = 1.2 misses
        /// # Ok::<(), raypack::SceneError>(())
        /// ```
        pub fn $intersect(&self, packet: &mut $packet, valid: $mask) {
            let before = self.has_spheres().then(|| *packet);
            self.bvh8.intersect_packet_with(self.isa, packet, valid as u32, &mut NoCount);
            if let Some(before) = before {
                for i in crate::simd::bits(valid as u32) {
                    let mut h = packet.hit(i);
                    self.finish_hit(&before.ray(i), &mut h);
                    (packet.u[i], packet.v[i]) = (h.u, h.v);
                }
            }
        }

        #[doc = concat!("Which of the ", $doc_k, " rays in the lanes set in `valid` are blocked over `[tnear, tfar]`: bit")]
        /// `i` of the result is set for lane `i`. The packet is not modified; invalid rays are
        /// never blocked.
        ///
        /// ```
        /// # use raypack::{BuildOptions, Material, Ray, RayPacket8, RayPacket16, SceneBuilder, Vec3};
        /// let mut b = SceneBuilder::new();
        /// let m = b.add_material(Material::default());
        /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
        /// let (scene, _) = b.commit(&BuildOptions::default());
        /// // Two shadow rays from z = 5 toward z = -5: one through the sphere, one beside it.
        /// let rays = [Ray::segment(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z, 0.0, 10.0), Ray::segment(Vec3::new(2.0, 0.0, 5.0), -Vec3::Z, 0.0, 10.0)];
        #[doc = concat!("let (packet, valid) = ", stringify!($packet), "::from_rays(&rays);")]
        #[doc = concat!("assert_eq!(scene.", stringify!($occluded), "(&packet, valid), 0b01);")]
        /// # Ok::<(), raypack::SceneError>(())
        /// ```
        pub fn $occluded(&self, packet: &$packet, valid: $mask) -> $mask {
            self.bvh8.occluded_packet_with(self.isa, packet, valid as u32, &mut NoCount) as $mask
        }
    };
}

impl Scene {
    packet_queries!(intersect8, occluded8, RayPacket8, u8, "8");
    packet_queries!(intersect16, occluded16, RayPacket16, u16, "16");

    /// Closest hits of `rays` into `hits` (same length), over all rayon threads: the rays are
    /// traced as 16-ray packets in the order given, so consecutive rays should be coherent when
    /// they can be (camera rays in small pixel tiles, shadow rays of neighbouring pixels). The
    /// packet kernel adapts to incoherent rays by itself (see [`crate::bvh::traverse_packet`]);
    /// in a scene whose BVH is larger than the last-level cache, the rays of incoherent packets
    /// are traced as single rays several at a time instead ([`Scene::intersect_interleaved`]).
    ///
    /// ```
    /// # use raypack::{BuildOptions, Hit, Material, Ray, SceneBuilder, Vec3};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
    /// let (scene, _) = b.commit(&BuildOptions::default());
    /// let rays: Vec<Ray> = (0..100).map(|i| Ray::new(Vec3::new(i as f32 * 0.01, 0.0, 5.0), -Vec3::Z)).collect();
    /// let mut hits = vec![Hit::MISS; rays.len()];
    /// scene.intersect_stream(&rays, &mut hits);
    /// assert!(hits.iter().all(|h| h.prim == 0 && h.t < 5.0));
    /// # Ok::<(), raypack::SceneError>(())
    /// ```
    pub fn intersect_stream(&self, rays: &[Ray], hits: &mut [Hit]) {
        assert_eq!(rays.len(), hits.len(), "one hit per ray");
        rays.par_chunks(STREAM_CHUNK)
            .zip(hits.par_chunks_mut(STREAM_CHUNK))
            .with_max_len(1)
            .for_each(|(r, h)| self.intersect_batch(r, h));
    }

    /// Could any ray from `origin` along a positive multiple of a vector in the box
    /// `[dir_lo, dir_hi]` hit the scene (a cone of rays, such as the camera rays through one
    /// pixel)? `false` is exact: none of those rays hits anything, whatever its length or
    /// interval. `true` may be conservative (a primitive's bounding box meets the cone), and
    /// is the answer whenever some component of the box can be 0.
    ///
    /// ```
    /// # use raypack::{BuildOptions, Material, SceneBuilder, Vec3};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
    /// let (scene, _) = b.commit(&BuildOptions::default());
    /// let eye = Vec3::new(0.0, 0.0, 5.0);
    /// // Towards the sphere, and well to its side.
    /// assert!(scene.cone_may_hit(eye, Vec3::new(0.01, 0.01, -1.0), Vec3::new(0.02, 0.02, -1.0)));
    /// assert!(!scene.cone_may_hit(eye, Vec3::new(0.5, 0.5, -1.0), Vec3::new(0.6, 0.6, -1.0)));
    /// # Ok::<(), raypack::SceneError>(())
    /// ```
    pub fn cone_may_hit(&self, origin: Vec3, dir_lo: Vec3, dir_hi: Vec3) -> bool {
        self.bvh8.cone_may_hit_with(self.isa, origin, dir_lo, dir_hi)
    }

    /// [`Scene::intersect_stream`] on the calling thread only.
    pub fn intersect_batch(&self, rays: &[Ray], hits: &mut [Hit]) {
        self.intersect_batch_counted(rays, hits, &mut NoCount);
    }

    /// [`Scene::intersect_batch`], adding the kernels' work to `counter`.
    pub fn intersect_batch_counted<C: Counter>(&self, rays: &[Ray], hits: &mut [Hit], counter: &mut C) {
        self.intersect_batch_as(rays, hits, counter, self.bvh8.interleaves());
    }

    /// [`Scene::intersect_batch_counted`], interleaving the rays of incoherent packets when
    /// `interleave` is set and as packets otherwise, whatever the BVH's size (the renderer's
    /// choice, [`crate::render::trace`]).
    pub(crate) fn intersect_batch_as<C: Counter>(
        &self,
        rays: &[Ray],
        hits: &mut [Hit],
        counter: &mut C,
        interleave: bool,
    ) {
        self.bvh8.intersect_stream_as(self.isa, rays, hits, counter, interleave);
        if self.has_spheres() {
            for (ray, out) in rays.iter().zip(hits.iter_mut()) {
                self.finish_hit(ray, out);
            }
        }
    }

    /// Occlusion of `rays` into `occluded` (same length), over all rayon threads, as 16-ray
    /// packets in the order given (see [`Scene::intersect_stream`]).
    ///
    /// ```
    /// # use raypack::{BuildOptions, Material, Ray, SceneBuilder, Vec3};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
    /// let (scene, _) = b.commit(&BuildOptions::default());
    /// let rays: Vec<Ray> = (0..40).map(|i| Ray::segment(Vec3::new(i as f32 * 0.05 + 0.025, 0.0, 5.0), -Vec3::Z, 0.0, 10.0)).collect();
    /// let mut blocked = vec![false; rays.len()];
    /// scene.occluded_stream(&rays, &mut blocked);
    /// assert_eq!(blocked.iter().filter(|&&b| b).count(), 20); // x < 1 passes through the sphere
    /// # Ok::<(), raypack::SceneError>(())
    /// ```
    pub fn occluded_stream(&self, rays: &[Ray], occluded: &mut [bool]) {
        assert_eq!(rays.len(), occluded.len(), "one answer per ray");
        rays.par_chunks(STREAM_CHUNK)
            .zip(occluded.par_chunks_mut(STREAM_CHUNK))
            .with_max_len(1)
            .for_each(|(r, o)| self.occluded_batch(r, o));
    }

    /// Closest hits of `rays` into `hits` (same length) on the calling thread, traced as single
    /// rays with several in flight at once, so that one ray's cache misses overlap the
    /// others' steps ([`crate::bvh::traverse_interleaved`]): for incoherent rays (diffuse
    /// bounces) in scenes whose BVH is larger than the last-level cache, where it is the
    /// fastest of the queries; where the BVH fits the caches it is the slowest. The streams
    /// ([`Scene::intersect_stream`]) trace the incoherent packets of such scenes this way by
    /// themselves. The hits are [`Scene::intersect1`]'s.
    ///
    /// ```
    /// # use raypack::{BuildOptions, Hit, Material, Ray, SceneBuilder, Vec3};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
    /// let (scene, _) = b.commit(&BuildOptions::default());
    /// let rays: Vec<Ray> = (0..100).map(|i| Ray::new(Vec3::ZERO, Vec3::new((i as f32).cos(), (i as f32).sin(), 0.3))).collect();
    /// let mut hits = vec![Hit::MISS; rays.len()];
    /// scene.intersect_interleaved(&rays, &mut hits);
    /// assert!(rays.iter().zip(&hits).all(|(r, h)| *h == scene.intersect1(r)));
    /// # Ok::<(), raypack::SceneError>(())
    /// ```
    pub fn intersect_interleaved(&self, rays: &[Ray], hits: &mut [Hit]) {
        self.bvh8.intersect_interleaved_with(self.isa, rays, hits, &mut NoCount);
        if self.has_spheres() {
            for (ray, out) in rays.iter().zip(hits.iter_mut()) {
                self.finish_hit(ray, out);
            }
        }
    }

    /// Which of `rays` are blocked over `[tnear, tfar]`, into `occluded` (same length), on the
    /// calling thread, as single rays with several in flight at once (see
    /// [`Scene::intersect_interleaved`]). The answers are [`Scene::occluded1`]'s.
    pub fn occluded_interleaved(&self, rays: &[Ray], occluded: &mut [bool]) {
        self.bvh8.occluded_interleaved_with(self.isa, rays, occluded, &mut NoCount);
    }

    /// [`Scene::occluded_stream`] on the calling thread only.
    pub fn occluded_batch(&self, rays: &[Ray], occluded: &mut [bool]) {
        self.occluded_batch_counted(rays, occluded, &mut NoCount);
    }

    /// [`Scene::occluded_batch`], adding the kernels' work to `counter`.
    pub fn occluded_batch_counted<C: Counter>(&self, rays: &[Ray], occluded: &mut [bool], counter: &mut C) {
        self.occluded_batch_as(rays, occluded, counter, self.bvh8.interleaves());
    }

    /// [`Scene::occluded_batch_counted`] with the choice of [`Scene::intersect_batch_as`].
    pub(crate) fn occluded_batch_as<C: Counter>(
        &self,
        rays: &[Ray],
        occluded: &mut [bool],
        counter: &mut C,
        interleave: bool,
    ) {
        self.bvh8.occluded_stream_as(self.isa, rays, occluded, counter, interleave);
    }
}
