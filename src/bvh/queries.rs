//! The entry points of the BVH8 kernels: each query is an `IsaOp` that `dispatch`
//! instantiates per ISA tier, and that picks the triangle kernel `P` of the BVH's layout
//! ([`TriangleTest`]) once per call.
//!
//! | query | kernel | rays per call |
//! |---|---|---|
//! | [`Bvh8::intersect1_with`], [`Bvh8::occluded1_with`] | [`crate::bvh::traverse1`] | one |
//! | [`Bvh8::intersect_packet_with`], [`Bvh8::occluded_packet_with`] | [`crate::bvh::traverse_packet`] | 8 or 16 (a [`RayPacket`]) |
//! | [`Bvh8::intersect_stream_with`], [`Bvh8::occluded_stream_with`] | the packet kernels on consecutive packets of the ISA's stream width | any number, on the calling thread |
//! | [`Bvh8::cone_may_hit_with`] | [`crate::bvh::frustum`] (a cone of rays as one interval frustum) | a cone of them |
//!
//! Every query takes the ISA to run on (normally the scene's, [`crate::Scene::isa`]) and a
//! work [`Counter`] ([`NoCount`] compiles away).

use crate::bvh::Bvh8;
use crate::bvh::counters::{Counter, NoCount};
use crate::bvh::frustum::Frustum;
use crate::bvh::traverse_packet::{OccluderCache, PacketRays, intersect_hybrid, occluded_hybrid};
use crate::bvh::traverse1::Ray1;
use crate::geometry::{MollerTrumboreKernel, TriBlock, TriangleTest, WatertightKernel};
use crate::math::Vec3;
use crate::ray::{Hit, Ray, RayPacket};
use crate::simd::isa::{IsaOp, dispatch};
use crate::simd::{Isa, IsaLanes, Lanes};

/// A packet finishes a subtree as single rays once this many or fewer of its rays still
/// want it (Embree's hybrid switch threshold; the value is measured, PERFORMANCE.md,
/// "Hybrid threshold").
pub const HYBRID_THRESHOLD: usize = 1;

/// Inner nodes a cone query ([`Bvh8::cone_may_hit_with`]) visits at most before it answers
/// "may hit". On the Stanford dragon's camera (480 × 360 pixels, one cone per pixel) a budget
/// of 16 nodes already culls the same pixels as an unlimited one but for 0.02% of them, at the
/// same time; the budget bounds the cost of cones that brush many boxes and no triangle.
pub const CONE_NODE_BUDGET: usize = 64;

/// Runs `$body` with the type `$p` set to the triangle kernel of `$test`.
macro_rules! with_kernel {
    ($test:expr, $p:ident => $body:expr) => {
        match $test {
            TriangleTest::MollerTrumbore => {
                type $p = MollerTrumboreKernel;
                $body
            }
            TriangleTest::Watertight => {
                type $p = WatertightKernel;
                $body
            }
        }
    };
}

struct Intersect1<'a, T: TriBlock, C> {
    bvh: &'a Bvh8<T>,
    ray: &'a Ray,
    counter: &'a mut C,
}

impl<T: TriBlock, C: Counter> IsaOp for Intersect1<'_, T, C> {
    type Output = Hit;
    #[inline(always)]
    fn run<I: IsaLanes>(self) -> Hit {
        let mut hit = Hit::MISS;
        if self.ray.is_valid() {
            let (bvh, r, mut tfar) = (self.bvh.slices(), Ray1::<I::F8>::new(self.ray), self.ray.tfar);
            with_kernel!(bvh.test, P => bvh.intersect1_from::<I, P, C, true>(&r, bvh.root(), &mut tfar, &mut hit, self.counter));
        }
        hit
    }
}

struct Occluded1<'a, T: TriBlock, C> {
    bvh: &'a Bvh8<T>,
    ray: &'a Ray,
    counter: &'a mut C,
}

impl<T: TriBlock, C: Counter> IsaOp for Occluded1<'_, T, C> {
    type Output = bool;
    #[inline(always)]
    fn run<I: IsaLanes>(self) -> bool {
        self.ray.is_valid() && {
            let (bvh, r) = (self.bvh.slices(), Ray1::<I::F8>::new(self.ray));
            with_kernel!(bvh.test, P => bvh.occluded1_from::<I, P, C, true>(&r, bvh.root(), self.counter))
        }
    }
}

struct ConeMayHit<'a, T: TriBlock> {
    bvh: &'a Bvh8<T>,
    cone: (Vec3, Vec3, Vec3),
}

impl<T: TriBlock> IsaOp for ConeMayHit<'_, T> {
    type Output = bool;
    #[inline(always)]
    fn run<I: IsaLanes>(self) -> bool {
        let (origin, lo, hi) = self.cone;
        match Frustum::<I::F8>::cone(origin, lo, hi) {
            Some(f) => self.bvh.slices().frustum_may_hit::<I>(&f, CONE_NODE_BUDGET),
            None => true,
        }
    }
}

struct IntersectPacket<'a, T: TriBlock, R, C> {
    bvh: &'a Bvh8<T>,
    packet: &'a mut R,
    valid: u32,
    counter: &'a mut C,
}

impl<T: TriBlock, R: RayPacket, C: Counter> IsaOp for IntersectPacket<'_, T, R, C> {
    type Output = ();
    #[inline(always)]
    fn run<I: IsaLanes>(self) {
        let (org, dir, tnear, tfar) = self.packet.ray_rows();
        let mut rays = PacketRays::<R::Lanes<I>>::from_rows(org, dir, tnear, tfar, self.valid);
        let bvh = self.bvh.slices();
        with_kernel!(bvh.test, P => intersect_hybrid::<_, I, T, P, C>(&bvh, &mut rays, HYBRID_THRESHOLD, self.counter));
        for i in crate::simd::bits(self.valid & ((1u32 << R::K) - 1)) {
            self.packet.set_result(i, &rays.hit(i));
        }
    }
}

struct OccludedPacket<'a, T: TriBlock, R, C> {
    bvh: &'a Bvh8<T>,
    packet: &'a R,
    valid: u32,
    counter: &'a mut C,
}

impl<T: TriBlock, R: RayPacket, C: Counter> IsaOp for OccludedPacket<'_, T, R, C> {
    type Output = u32;
    #[inline(always)]
    fn run<I: IsaLanes>(self) -> u32 {
        let (org, dir, tnear, tfar) = self.packet.ray_rows();
        let rays = PacketRays::<R::Lanes<I>>::from_rows(org, dir, tnear, tfar, self.valid);
        let mut cache = OccluderCache::default();
        let bvh = self.bvh.slices();
        with_kernel!(bvh.test, P => occluded_hybrid::<_, I, T, P, C>(&bvh, &rays, HYBRID_THRESHOLD, &mut cache, self.counter))
    }
}

struct IntersectStream<'a, T: TriBlock, C> {
    bvh: &'a Bvh8<T>,
    rays: &'a [Ray],
    hits: &'a mut [Hit],
    counter: &'a mut C,
}

impl<T: TriBlock, C: Counter> IsaOp for IntersectStream<'_, T, C> {
    type Output = ();
    #[inline(always)]
    fn run<I: IsaLanes>(self) {
        type V<I> = <I as IsaLanes>::Stream;
        let k = V::<I>::LANES;
        let (bvh, rays) = (self.bvh.slices(), self.rays);
        with_kernel!(bvh.test, P => {
            for (n, (r, h)) in rays.chunks(k).zip(self.hits.chunks_mut(k)).enumerate() {
                prefetch_rays(rays, (n + 2) * k, k);
                let mut p = PacketRays::<V<I>>::new_in::<I::F8>(r, u32::MAX);
                intersect_hybrid::<_, I, T, P, C>(&bvh, &mut p, HYBRID_THRESHOLD, self.counter);
                let (mut t, mut u, mut v, mut prim) = ([0.0f32; 16], [0.0f32; 16], [0.0f32; 16], [0u32; 16]);
                p.store_hits(&mut t, &mut u, &mut v, &mut prim);
                for (i, out) in h.iter_mut().enumerate() {
                    let miss = prim[i] == Hit::NONE;
                    *out = Hit { t: if miss { f32::INFINITY } else { t[i] }, u: u[i], v: v[i], prim: prim[i] };
                }
            }
        })
    }
}

struct OccludedStream<'a, T: TriBlock, C> {
    bvh: &'a Bvh8<T>,
    rays: &'a [Ray],
    occluded: &'a mut [bool],
    counter: &'a mut C,
}

impl<T: TriBlock, C: Counter> IsaOp for OccludedStream<'_, T, C> {
    type Output = ();
    #[inline(always)]
    fn run<I: IsaLanes>(self) {
        type V<I> = <I as IsaLanes>::Stream;
        let k = V::<I>::LANES;
        let (bvh, rays) = (self.bvh.slices(), self.rays);
        let mut cache = OccluderCache::default();
        with_kernel!(bvh.test, P => {
            for (n, (r, o)) in rays.chunks(k).zip(self.occluded.chunks_mut(k)).enumerate() {
                prefetch_rays(rays, (n + 2) * k, k);
                let p = PacketRays::<V<I>>::new_in::<I::F8>(r, u32::MAX);
                let bits = occluded_hybrid::<_, I, T, P, C>(&bvh, &p, HYBRID_THRESHOLD, &mut cache, self.counter);
                for (i, x) in o.iter_mut().enumerate() {
                    *x = bits >> i & 1 != 0;
                }
            }
        })
    }
}

/// Prefetches the `k` rays from `rays[start]`, if there are any.
#[inline(always)]
fn prefetch_rays(rays: &[Ray], start: usize, k: usize) {
    if start + k <= rays.len() {
        let p = rays[start..].as_ptr() as *const u8;
        for line in 0..k * std::mem::size_of::<Ray>() / 64 {
            crate::bvh::bvh8::prefetch_line(p.wrapping_add(64 * line));
        }
    }
}

impl<T: TriBlock> Bvh8<T> {
    /// Could a ray from `origin` along a positive multiple of a vector in the box
    /// `[dir_lo, dir_hi]` hit a primitive, on ISA `isa`? `false` is exact; `true` may be
    /// conservative, and is the answer whenever the box touches a coordinate plane
    /// ([`Frustum::cone`], [`crate::bvh::bvh8::Bvh8Ref::frustum_may_hit`]).
    pub fn cone_may_hit_with(&self, isa: Isa, origin: Vec3, dir_lo: Vec3, dir_hi: Vec3) -> bool {
        dispatch(isa, ConeMayHit { bvh: self, cone: (origin, dir_lo, dir_hi) })
    }

    /// Closest hit along `ray` on the process's default ISA ([`Isa::default_for_process`]).
    /// Invalid rays miss; sphere hits carry `u = v = 0` (the scene fills them in).
    #[inline]
    pub fn intersect1(&self, ray: &Ray) -> Hit {
        self.intersect1_with(Isa::default_for_process(), ray, &mut NoCount)
    }

    /// True when anything lies in `(ray.tnear, ray.tfar]`, on the process's default ISA.
    /// Invalid rays are never occluded.
    #[inline]
    pub fn occluded1(&self, ray: &Ray) -> bool {
        self.occluded1_with(Isa::default_for_process(), ray, &mut NoCount)
    }

    /// [`Bvh8::intersect1`] on `isa`'s kernels (the CPU's best when it lacks `isa`), counting
    /// the work into `counter`.
    #[inline]
    pub fn intersect1_with<C: Counter>(&self, isa: Isa, ray: &Ray, counter: &mut C) -> Hit {
        dispatch(isa, Intersect1 { bvh: self, ray, counter })
    }

    /// [`Bvh8::occluded1`] on `isa`'s kernels, counting the work into `counter`.
    #[inline]
    pub fn occluded1_with<C: Counter>(&self, isa: Isa, ray: &Ray, counter: &mut C) -> bool {
        dispatch(isa, Occluded1 { bvh: self, ray, counter })
    }

    /// Closest hits of the packet's rays in the lanes set in `valid`, written back into the
    /// packet ([`RayPacket::set_result`]; other lanes are untouched), on `isa`'s kernels.
    #[inline]
    pub fn intersect_packet_with<R: RayPacket, C: Counter>(
        &self,
        isa: Isa,
        packet: &mut R,
        valid: u32,
        counter: &mut C,
    ) {
        dispatch(isa, IntersectPacket { bvh: self, packet, valid, counter })
    }

    /// Which of the packet's rays in the lanes set in `valid` are blocked (bit `i` for lane
    /// `i`), on `isa`'s kernels.
    #[inline]
    pub fn occluded_packet_with<R: RayPacket, C: Counter>(
        &self,
        isa: Isa,
        packet: &R,
        valid: u32,
        counter: &mut C,
    ) -> u32 {
        dispatch(isa, OccludedPacket { bvh: self, packet, valid, counter })
    }

    /// Closest hits of `rays` into `hits` (same length) on the calling thread, as packets of
    /// consecutive rays, on `isa`'s kernels. Misses are [`Hit::MISS`].
    pub fn intersect_stream_with<C: Counter>(&self, isa: Isa, rays: &[Ray], hits: &mut [Hit], counter: &mut C) {
        assert_eq!(rays.len(), hits.len(), "one hit per ray");
        dispatch(isa, IntersectStream { bvh: self, rays, hits, counter })
    }

    /// Occlusion of `rays` into `occluded` (same length) on the calling thread, as packets of
    /// consecutive rays carrying an [`OccluderCache`], on `isa`'s kernels.
    pub fn occluded_stream_with<C: Counter>(&self, isa: Isa, rays: &[Ray], occluded: &mut [bool], counter: &mut C) {
        assert_eq!(rays.len(), occluded.len(), "one answer per ray");
        dispatch(isa, OccludedStream { bvh: self, rays, occluded, counter })
    }
}
