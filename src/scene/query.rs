//! Ray queries on a committed [`Scene`] beyond single rays: 8- and 16-ray packets, tiles of
//! coherent rays, and streams that pick a kernel per batch and run over rayon.

use crate::bvh::traverse_packet::{PacketRays, intersect_frustum, occluded_frustum};
use crate::ray::{Hit, Ray, RayPacket8, RayPacket16};
use crate::scene::Scene;
use crate::simd::{F32x8, F32x16};
use rayon::prelude::*;

/// A packet finishes a subtree as single rays once this many or fewer of its rays still
/// want it (Embree's hybrid switch threshold). See `benches/traverse.rs` for the
/// measurement that chose it.
pub const HYBRID_THRESHOLD: usize = 3;

/// Rays per tile of the stream kernels: 4 packets of 16 (an 8 x 8 pixel block of camera rays
/// when the rays come in 4 x 4 pixel tiles).
pub const STREAM_TILE: usize = 64;

/// A batch is traced as packets when its unit directions span at most this much in each
/// component (and share signs); otherwise ray by ray.
pub const COHERENT_SPREAD: f32 = 0.25;

/// Rays per rayon task of the stream kernels.
const STREAM_CHUNK: usize = 1024;

macro_rules! packet_queries {
    ($intersect:ident, $occluded:ident, $packet:ty, $mask:ty, $v:ty) => {
        /// Closest hits of the rays in the lanes set in `valid` (see the packet type for the
        /// layout). Hit lanes get `tfar = t`, `u`, `v`, `prim`; missed lanes get
        /// `prim = Hit::NONE`; invalid rays ([`Ray::is_valid`]) miss. Coherent packets (all
        /// directions of one sign per axis) take the frustum kernel, others the hybrid one.
        pub fn $intersect(&self, packet: &mut $packet, valid: $mask) {
            let p = packet;
            let mut rays = PacketRays::<$v>::from_rows(
                [&p.org_x, &p.org_y, &p.org_z],
                [&p.dir_x, &p.dir_y, &p.dir_z],
                &p.tnear,
                &p.tfar,
                valid as u32,
            );
            if rays.active_mask() != 0 {
                // The frustum kernel falls back to the hybrid one when direction signs differ.
                intersect_frustum(&self.bvh8, std::slice::from_mut(&mut rays), HYBRID_THRESHOLD);
            }
            for i in crate::simd::bits(valid as u32) {
                let mut h = rays.hit(i);
                p.prim[i] = h.prim;
                if h.is_hit() {
                    self.finish_hit(&p.ray(i), &mut h);
                    p.tfar[i] = h.t;
                    p.u[i] = h.u;
                    p.v[i] = h.v;
                }
            }
        }

        /// Which rays of the lanes set in `valid` are blocked over `(tnear, tfar]`: bit `i`
        /// of the result is set for lane `i`. The packet is not modified.
        pub fn $occluded(&self, packet: &$packet, valid: $mask) -> $mask {
            let p = packet;
            let rays = PacketRays::<$v>::from_rows(
                [&p.org_x, &p.org_y, &p.org_z],
                [&p.dir_x, &p.dir_y, &p.dir_z],
                &p.tnear,
                &p.tfar,
                valid as u32,
            );
            if rays.active_mask() == 0 {
                return 0;
            }
            let mut out = [0u32];
            occluded_frustum(&self.bvh8, std::slice::from_ref(&rays), HYBRID_THRESHOLD, &mut out);
            out[0] as $mask
        }
    };
}

impl Scene {
    packet_queries!(intersect8, occluded8, RayPacket8, u8, F32x8);
    packet_queries!(intersect16, occluded16, RayPacket16, u16, F32x16);

    /// Closest hits of `rays` into `hits` (same length), over all rayon threads. Each tile of
    /// [`STREAM_TILE`] consecutive rays whose directions are coherent is traced as packets
    /// with the frustum kernel, any other ray by the single-ray kernel.
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
            .for_each(|(r, h)| self.intersect_batch(r, h));
    }

    /// [`Scene::intersect_stream`] on the calling thread only.
    pub fn intersect_batch(&self, rays: &[Ray], hits: &mut [Hit]) {
        for (r, h) in rays.chunks(STREAM_TILE).zip(hits.chunks_mut(STREAM_TILE)) {
            if r.len() == STREAM_TILE && is_coherent(r) {
                self.intersect_tile(r, h);
            } else {
                for (ray, hit) in r.iter().zip(h.iter_mut()) {
                    *hit = self.intersect1(ray);
                }
            }
        }
    }

    /// Traces a tile of up to 64 coherent rays with the frustum kernel.
    pub fn intersect_tile(&self, rays: &[Ray], hits: &mut [Hit]) {
        const P: usize = STREAM_TILE / 16;
        assert!(rays.len() <= STREAM_TILE && rays.len() == hits.len());
        let mut packets: [PacketRays<F32x16>; P] = std::array::from_fn(|p| {
            let lo = (p * 16).min(rays.len());
            let hi = ((p + 1) * 16).min(rays.len());
            let mut buf = [Ray::new(crate::Vec3::ZERO, crate::Vec3::X); 16];
            buf[..hi - lo].copy_from_slice(&rays[lo..hi]);
            PacketRays::new(&buf, (1u32 << (hi - lo)) - 1)
        });
        intersect_frustum(&self.bvh8, &mut packets, HYBRID_THRESHOLD);
        for (i, h) in hits.iter_mut().enumerate() {
            let mut hit = packets[i / 16].hit(i % 16);
            self.finish_hit(&rays[i], &mut hit);
            *h = hit;
        }
    }

    /// Occlusion of `rays` into `occluded` (same length), over all rayon threads; kernels
    /// chosen per tile as in [`Scene::intersect_stream`].
    pub fn occluded_stream(&self, rays: &[Ray], occluded: &mut [bool]) {
        assert_eq!(rays.len(), occluded.len(), "one answer per ray");
        rays.par_chunks(STREAM_CHUNK)
            .zip(occluded.par_chunks_mut(STREAM_CHUNK))
            .for_each(|(r, o)| self.occluded_batch(r, o));
    }

    /// [`Scene::occluded_stream`] on the calling thread only.
    pub fn occluded_batch(&self, rays: &[Ray], occluded: &mut [bool]) {
        const P: usize = STREAM_TILE / 16;
        for (r, o) in rays.chunks(STREAM_TILE).zip(occluded.chunks_mut(STREAM_TILE)) {
            if r.len() == STREAM_TILE && is_coherent(r) {
                let packets: [PacketRays<F32x16>; P] = std::array::from_fn(|p| PacketRays::new(&r[p * 16..], 0xFFFF));
                let mut out = [0u32; P];
                occluded_frustum(&self.bvh8, &packets, HYBRID_THRESHOLD, &mut out);
                for (i, x) in o.iter_mut().enumerate() {
                    *x = out[i / 16] >> (i % 16) & 1 != 0;
                }
            } else {
                for (ray, x) in r.iter().zip(o.iter_mut()) {
                    *x = self.occluded1(ray);
                }
            }
        }
    }
}

/// True when the unit directions of `rays` share their signs and span at most
/// [`COHERENT_SPREAD`] per component.
pub fn is_coherent(rays: &[Ray]) -> bool {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for r in rays {
        let d = r.dir.normalize_or_zero();
        for a in 0..3 {
            lo[a] = lo[a].min(d[a]);
            hi[a] = hi[a].max(d[a]);
        }
    }
    (0..3).all(|a| (lo[a] > 0.0 || hi[a] < 0.0) && hi[a] - lo[a] <= COHERENT_SPREAD)
}
