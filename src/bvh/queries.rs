// Not split: one IsaOp per query, each a few lines, listed together so the public entry points of the kernels are in one place.
//! The entry points of the BVH8 kernels: each query is an `IsaOp` that `dispatch`
//! instantiates per ISA tier, and that picks the triangle kernel `P` of the BVH's layout
//! ([`TriangleTest`]) once per call.
//!
//! (One file past 600 lines with its unit tests: the entry points are one table of `IsaOp`s
//! that share the dispatch and the choice of triangle kernel, and the tests compare them.)
//!
//! | query | kernel | rays per call |
//! |---|---|---|
//! | [`Bvh8::intersect1_with`], [`Bvh8::occluded1_with`] | [`crate::bvh::traverse1`] | one |
//! | [`Bvh8::intersect_packet_with`], [`Bvh8::occluded_packet_with`] | [`crate::bvh::traverse_packet`] | 8 or 16 (a [`RayPacket`]) |
//! | [`Bvh8::intersect_stream_with`], [`Bvh8::occluded_stream_with`] | as [`StreamKernel`] says: the packet kernels on consecutive packets of the ISA's stream width, the interleaved kernels ([`crate::bvh::traverse_interleaved`]) on every ray, or the packets with their incoherent rays interleaved (by default in trees larger than the last-level cache) | any number, on the calling thread |
//! | [`Bvh8::cone_may_hit_with`] | [`crate::bvh::frustum`] (a cone of rays as one interval frustum) | a cone of them |
//!
//! Every query takes the ISA to run on (normally the scene's, [`crate::Scene::isa`]) and a
//! work [`Counter`] ([`NoCount`] compiles away). The stream loop is written once for both
//! queries (`StreamQuery`: what a packet and a single ray of each compute).

use crate::bvh::Bvh8;
use crate::bvh::bvh8::{Bvh8Ref, LeafBlocks};
use crate::bvh::counters::{Counter, NoCount};
use crate::bvh::frustum::Frustum;
use crate::bvh::traverse_packet::{OccluderCache, PacketRays, intersect_hybrid, occluded_hybrid};
use crate::bvh::traverse1::Ray1;
use crate::geometry::{MollerTrumboreKernel, TriBlock, TriangleKernel, TriangleTest, WatertightKernel};
use crate::math::Vec3;
use crate::ray::{Hit, Ray, RayPacket};
use crate::simd::isa::{IsaOp, dispatch};
use crate::simd::{Isa, IsaLanes, Lanes};

/// A packet finishes a subtree as single rays once this many or fewer of its rays still
/// want it (Embree's hybrid switch threshold; the value is measured, PERFORMANCE.md,
/// "Hybrid threshold").
pub const HYBRID_THRESHOLD: usize = 1;

/// Inner nodes a cone query ([`Bvh8::cone_may_hit_with`]) visits at most before it answers
/// "may hit": a small budget already culls nearly the pixels an unlimited one does
/// (PERFORMANCE.md, "Pixels whose camera rays cannot hit the scene"), and the budget bounds
/// the cost of cones that brush many boxes and no triangle.
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

/// The single-ray closest-hit query speculates its descents (`traverse1::speculated_slot`)
/// in BVH8s of at most this many bytes ([`Bvh8::speculates`]), not in larger ones; in the
/// same small trees it does not prefetch the children it will visit (they sit in the cache).
///
/// A guess pays where the branch predictor has seen the rays' paths: in small trees, and on
/// camera rays. On the diffuse rays of larger trees the guesses fail at the deep levels, and
/// each wrong one costs a flush and starts a load the ray does not need. The bound is a
/// property of the tree, not of the machine, and hits are the same bit for bit either way.
/// The bound lies between the smallest tree where speculation lost and the largest where it
/// did not (PERFORMANCE.md, "Descent slots as predicted branches").
pub const SPECULATION_MAX_BYTES: usize = 5 << 19;

struct Intersect1<'a, T: TriBlock, L, C> {
    bvh: Bvh8Ref<'a, T, L>,
    ray: &'a Ray,
    counter: &'a mut C,
}

impl<T: TriBlock, L: LeafBlocks<T>, C: Counter> IsaOp for Intersect1<'_, T, L, C> {
    type Output = Hit;
    #[inline(always)]
    fn run<I: IsaLanes>(self) -> Hit {
        let mut hit = Hit::MISS;
        if let Some(r) = Ray1::<I::F8>::try_new(self.ray) {
            let (bvh, mut tfar) = (self.bvh, r.ray.tfar);
            let root = bvh.root();
            if self.bvh.speculates() {
                with_kernel!(bvh.test, P => bvh.intersect1_from::<I, P, C, true>(&r, root, &mut tfar, &mut hit, self.counter));
            } else {
                with_kernel!(bvh.test, P => bvh.intersect1_from::<I, P, C, false>(&r, root, &mut tfar, &mut hit, self.counter));
            }
        }
        hit
    }
}

struct Occluded1<'a, T: TriBlock, L, C> {
    bvh: Bvh8Ref<'a, T, L>,
    ray: &'a Ray,
    counter: &'a mut C,
}

impl<T: TriBlock, L: LeafBlocks<T>, C: Counter> IsaOp for Occluded1<'_, T, L, C> {
    type Output = bool;
    #[inline(always)]
    fn run<I: IsaLanes>(self) -> bool {
        // A `match`, not `Option::is_some_and`: a closure does not inherit the ISA's target
        // features, and this one, too large to inline, ran the kernel's intrinsics as calls.
        match Ray1::<I::F8>::try_new(self.ray) {
            Some(r) => {
                let bvh = self.bvh;
                with_kernel!(bvh.test, P => bvh.occluded1_from::<I, P, C, true>(&r, bvh.root(), self.counter))
            }
            None => false,
        }
    }
}

struct ConeMayHit<'a, T: TriBlock, L> {
    bvh: Bvh8Ref<'a, T, L>,
    cone: (Vec3, Vec3, Vec3),
}

impl<T: TriBlock, L: LeafBlocks<T>> IsaOp for ConeMayHit<'_, T, L> {
    type Output = bool;
    #[inline(always)]
    fn run<I: IsaLanes>(self) -> bool {
        let (origin, lo, hi) = self.cone;
        match Frustum::<I::F8>::cone(origin, lo, hi) {
            Some(f) => self.bvh.frustum_may_hit::<I>(&f, CONE_NODE_BUDGET),
            None => true,
        }
    }
}

struct IntersectPacket<'a, T: TriBlock, L, R, C> {
    bvh: Bvh8Ref<'a, T, L>,
    packet: &'a mut R,
    valid: u32,
    counter: &'a mut C,
}

impl<T: TriBlock, L: LeafBlocks<T>, R: RayPacket, C: Counter> IsaOp for IntersectPacket<'_, T, L, R, C> {
    type Output = ();
    #[inline(always)]
    fn run<I: IsaLanes>(self) {
        let (org, dir, tnear, tfar) = self.packet.ray_rows();
        let mut rays = PacketRays::<R::Lanes<I>>::from_rows(org, dir, tnear, tfar, self.valid);
        let bvh = self.bvh;
        with_kernel!(bvh.test, P => intersect_hybrid::<_, I, T, L, P, C>(&bvh, &mut rays, HYBRID_THRESHOLD, self.counter));
        for i in crate::simd::bits(self.valid & ((1u32 << R::K) - 1)) {
            self.packet.set_result(i, &rays.hit(i));
        }
    }
}

struct OccludedPacket<'a, T: TriBlock, L, R, C> {
    bvh: Bvh8Ref<'a, T, L>,
    packet: &'a R,
    valid: u32,
    counter: &'a mut C,
}

impl<T: TriBlock, L: LeafBlocks<T>, R: RayPacket, C: Counter> IsaOp for OccludedPacket<'_, T, L, R, C> {
    type Output = u32;
    #[inline(always)]
    fn run<I: IsaLanes>(self) -> u32 {
        let (org, dir, tnear, tfar) = self.packet.ray_rows();
        let rays = PacketRays::<R::Lanes<I>>::from_rows(org, dir, tnear, tfar, self.valid);
        let mut cache = OccluderCache::default();
        let bvh = self.bvh;
        with_kernel!(bvh.test, P => occluded_hybrid::<_, I, T, L, P, C>(&bvh, &rays, HYBRID_THRESHOLD, &mut cache, self.counter))
    }
}

/// The two stream queries, closest hit ([`Closest`]) and any hit ([`AnyHit`]): what one
/// packet of a stream computes and where its answers go, so that [`Stream`] is written once.
trait StreamQuery {
    /// One answer per ray: a [`Hit`] or whether the ray is blocked.
    type Out;
    /// What the query carries from packet to packet (the any-hit query's [`OccluderCache`]).
    type Carry: Default;

    /// Traces packet `p` and writes its answers into `out` (one per ray of `p`).
    fn packet<I: IsaLanes, T: TriBlock, L: LeafBlocks<T>, P: TriangleKernel, C: Counter>(
        bvh: &Bvh8Ref<'_, T, L>,
        p: &mut PacketRays<I::Stream>,
        carry: &mut Self::Carry,
        out: &mut [Self::Out],
        counter: &mut C,
    );

    /// Traces the rays `rays[i]` for `i` in `ids` as interleaved single rays into `out[i]`.
    fn interleaved<I: IsaLanes, T: TriBlock, L: LeafBlocks<T>, P: TriangleKernel, C: Counter>(
        bvh: &Bvh8Ref<'_, T, L>,
        rays: &[Ray],
        ids: impl Iterator<Item = usize>,
        out: &mut [Self::Out],
        counter: &mut C,
    );
}

/// The closest-hit stream.
struct Closest;

impl StreamQuery for Closest {
    type Out = Hit;
    type Carry = ();

    #[inline(always)]
    fn packet<I: IsaLanes, T: TriBlock, L: LeafBlocks<T>, P: TriangleKernel, C: Counter>(
        bvh: &Bvh8Ref<'_, T, L>,
        p: &mut PacketRays<I::Stream>,
        _: &mut (),
        out: &mut [Hit],
        counter: &mut C,
    ) {
        intersect_hybrid::<_, I, T, L, P, C>(bvh, p, HYBRID_THRESHOLD, counter);
        store_stream_hits(p, out);
    }

    #[inline(always)]
    fn interleaved<I: IsaLanes, T: TriBlock, L: LeafBlocks<T>, P: TriangleKernel, C: Counter>(
        bvh: &Bvh8Ref<'_, T, L>,
        rays: &[Ray],
        ids: impl Iterator<Item = usize>,
        out: &mut [Hit],
        counter: &mut C,
    ) {
        bvh.intersect_interleaved::<I, P, C>(rays, ids, out, counter)
    }
}

/// The any-hit stream, carrying an [`OccluderCache`] from packet to packet.
struct AnyHit;

impl StreamQuery for AnyHit {
    type Out = bool;
    type Carry = OccluderCache;

    #[inline(always)]
    fn packet<I: IsaLanes, T: TriBlock, L: LeafBlocks<T>, P: TriangleKernel, C: Counter>(
        bvh: &Bvh8Ref<'_, T, L>,
        p: &mut PacketRays<I::Stream>,
        cache: &mut OccluderCache,
        out: &mut [bool],
        counter: &mut C,
    ) {
        let bits = occluded_hybrid::<_, I, T, L, P, C>(bvh, p, HYBRID_THRESHOLD, cache, counter);
        for (i, x) in out.iter_mut().enumerate() {
            *x = bits >> i & 1 != 0;
        }
    }

    #[inline(always)]
    fn interleaved<I: IsaLanes, T: TriBlock, L: LeafBlocks<T>, P: TriangleKernel, C: Counter>(
        bvh: &Bvh8Ref<'_, T, L>,
        rays: &[Ray],
        ids: impl Iterator<Item = usize>,
        out: &mut [bool],
        counter: &mut C,
    ) {
        bvh.occluded_interleaved::<I, P, C>(rays, ids, out, counter)
    }
}

/// A stream of query `Q` from ray `from` on, as packets of consecutive rays of the ISA's
/// stream width. With `SET_ASIDE`, the rays of incoherent packets ([`incoherent_packet`]) are
/// set aside in `pending` instead of traced, and the op returns where it stopped: the end of
/// the rays, or the ray after the packet that filled `pending`. (`SET_ASIDE` is a constant so
/// that the packet-only stream is an instantiation of its own, without the coherence test.)
struct Stream<'a, T: TriBlock, L, C, Q: StreamQuery, const SET_ASIDE: bool> {
    bvh: Bvh8Ref<'a, T, L>,
    rays: &'a [Ray],
    out: &'a mut [Q::Out],
    counter: &'a mut C,
    from: usize,
    pending: &'a mut Pending,
}

impl<T: TriBlock, L: LeafBlocks<T>, C: Counter, Q: StreamQuery, const SET_ASIDE: bool> IsaOp
    for Stream<'_, T, L, C, Q, SET_ASIDE>
{
    type Output = usize;
    #[inline(always)]
    fn run<I: IsaLanes>(self) -> usize {
        let k = I::Stream::LANES;
        let (bvh, rays) = (self.bvh, self.rays);
        let mut carry = Q::Carry::default();
        // One length check here, so that `out[batch]` below needs none.
        let out = &mut self.out[..rays.len()];
        with_kernel!(bvh.test, P => {
            if !SET_ASIDE {
                // The packet-only stream: chunks of the slices, without index checks.
                for (n, (r, o)) in rays[self.from..].chunks(k).zip(out[self.from..].chunks_mut(k)).enumerate() {
                    prefetch_rays(rays, self.from + (n + 2) * k, k);
                    let mut p = PacketRays::<I::Stream>::new_in::<I::F8>(r, u32::MAX);
                    Q::packet::<I, T, L, P, C>(&bvh, &mut p, &mut carry, o, self.counter);
                }
                return rays.len();
            }
            let mut at = self.from;
            while at < rays.len() {
                let batch = at..rays.len().min(at + k);
                at = batch.end;
                prefetch_rays(rays, at + k, k);
                let mut p = PacketRays::<I::Stream>::new_in::<I::F8>(&rays[batch.clone()], u32::MAX);
                if incoherent_packet(&p) {
                    if self.pending.add(batch) {
                        break;
                    }
                    continue;
                }
                Q::packet::<I, T, L, P, C>(&bvh, &mut p, &mut carry, &mut out[batch], self.counter);
            }
            at
        })
    }
}

/// Single rays of query `Q`, `rays[i]` for `i` in `ids`, interleaved
/// ([`crate::bvh::traverse_interleaved`]).
struct Interleaved<'a, T: TriBlock, L, C, Q: StreamQuery, R> {
    bvh: Bvh8Ref<'a, T, L>,
    rays: &'a [Ray],
    ids: R,
    out: &'a mut [Q::Out],
    counter: &'a mut C,
}

impl<T: TriBlock, L: LeafBlocks<T>, C: Counter, Q: StreamQuery, R: Iterator<Item = usize>> IsaOp
    for Interleaved<'_, T, L, C, Q, R>
{
    type Output = ();
    #[inline(always)]
    fn run<I: IsaLanes>(self) {
        let bvh = self.bvh;
        with_kernel!(bvh.test, P => Q::interleaved::<I, T, L, P, C>(&bvh, self.rays, self.ids, self.out, self.counter))
    }
}

/// The packet's hits into `h` (one per ray; misses as [`Hit::MISS`]).
#[inline(always)]
fn store_stream_hits<V: Lanes>(p: &PacketRays<V>, h: &mut [Hit]) {
    let (mut t, mut u, mut v, mut prim) = ([0.0f32; 16], [0.0f32; 16], [0.0f32; 16], [0u32; 16]);
    p.store_hits(&mut t, &mut u, &mut v, &mut prim);
    for (i, out) in h.iter_mut().enumerate() {
        let miss = prim[i] == Hit::NONE;
        *out = Hit { t: if miss { f32::INFINITY } else { t[i] }, u: u[i], v: v[i], prim: prim[i] };
    }
}

/// Rays of incoherent packets set aside for the interleaved kernels
/// ([`crate::bvh::traverse_interleaved`]), as runs of consecutive rays.
struct Pending {
    /// `(first ray, count)` of each run.
    runs: [(u32, u32); PENDING_RUNS],
    len: usize,
}

/// Packets set aside before they are traced: 64 packets of 16 rays (a stream batch), so that
/// the flights rarely drain before the batch ends.
const PENDING_RUNS: usize = 64;

impl Pending {
    fn new() -> Self {
        Self { runs: [(0, 0); PENDING_RUNS], len: 0 }
    }

    /// Sets aside the rays `run`; true when full (to be drained now).
    #[inline(always)]
    fn add(&mut self, run: std::ops::Range<usize>) -> bool {
        self.runs[self.len] = (run.start as u32, run.len() as u32);
        self.len += 1;
        self.len == PENDING_RUNS
    }

    fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The rays set aside, in order, leaving none.
    #[inline(always)]
    fn drain(&mut self) -> impl Iterator<Item = usize> + '_ {
        let len = std::mem::take(&mut self.len);
        self.runs[..len].iter().flat_map(|&(first, count)| first as usize..(first + count) as usize)
    }
}

/// True when the packet's valid rays have directions of both signs on two axes or three: a
/// packet of diffuse bounces, say, where camera rays have both signs on one axis at most (in
/// the tiles that straddle the image's middle row or column, or on two in the one at its
/// centre). Such packets' rays go to the interleaved kernels in trees larger than the caches.
#[inline(always)]
fn incoherent_packet<V: Lanes>(p: &PacketRays<V>) -> bool {
    let valid = p.active.bitmask();
    let zero = V::splat(0.0);
    let mixed = |d: V| {
        let neg = d.lt(zero).bitmask() & valid;
        (neg != 0 && neg != valid) as u32
    };
    mixed(p.dir.x) + mixed(p.dir.y) + mixed(p.dir.z) >= 2
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

impl<T: TriBlock, L: LeafBlocks<T>> Bvh8Ref<'_, T, L> {
    /// Could a ray from `origin` along a positive multiple of a vector in the box
    /// `[dir_lo, dir_hi]` hit a primitive, on ISA `isa`? `false` is exact; `true` may be
    /// conservative, and is the answer whenever the box touches a coordinate plane
    /// ([`Frustum::cone`], [`crate::bvh::bvh8::Bvh8Ref::frustum_may_hit`]).
    pub fn cone_may_hit_with(&self, isa: Isa, origin: Vec3, dir_lo: Vec3, dir_hi: Vec3) -> bool {
        dispatch(isa, ConeMayHit { bvh: *self, cone: (origin, dir_lo, dir_hi) })
    }

    /// [`Bvh8::intersect1`] on `isa`'s kernels (the CPU's best when it lacks `isa`), counting
    /// the work into `counter`.
    #[inline]
    pub fn intersect1_with<C: Counter>(&self, isa: Isa, ray: &Ray, counter: &mut C) -> Hit {
        dispatch(isa, Intersect1 { bvh: *self, ray, counter })
    }

    /// [`Bvh8::occluded1`] on `isa`'s kernels, counting the work into `counter`.
    #[inline]
    pub fn occluded1_with<C: Counter>(&self, isa: Isa, ray: &Ray, counter: &mut C) -> bool {
        dispatch(isa, Occluded1 { bvh: *self, ray, counter })
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
        dispatch(isa, IntersectPacket { bvh: *self, packet, valid, counter })
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
        dispatch(isa, OccludedPacket { bvh: *self, packet, valid, counter })
    }

    /// Closest hits of `rays` into `hits` (same length) on the calling thread, traced as
    /// `kernel` says, on `isa`'s kernels. Misses are [`Hit::MISS`].
    pub fn intersect_stream_with<C: Counter>(
        &self,
        isa: Isa,
        rays: &[Ray],
        hits: &mut [Hit],
        kernel: StreamKernel,
        counter: &mut C,
    ) {
        assert_eq!(rays.len(), hits.len(), "one hit per ray");
        self.stream::<Closest, C>(isa, rays, hits, kernel, counter);
    }

    /// Occlusion of `rays` into `occluded` (same length) on the calling thread, traced as
    /// `kernel` says (packets carry an [`OccluderCache`] from one to the next), on `isa`'s
    /// kernels.
    pub fn occluded_stream_with<C: Counter>(
        &self,
        isa: Isa,
        rays: &[Ray],
        occluded: &mut [bool],
        kernel: StreamKernel,
        counter: &mut C,
    ) {
        assert_eq!(rays.len(), occluded.len(), "one answer per ray");
        self.stream::<AnyHit, C>(isa, rays, occluded, kernel, counter);
    }

    /// The stream driver of both queries: packets, single rays, or packets whose incoherent
    /// rays are set aside and traced as interleaved single rays whenever
    /// [`PENDING_RUNS`] packets are waiting.
    fn stream<Q: StreamQuery, C: Counter>(
        &self,
        isa: Isa,
        rays: &[Ray],
        out: &mut [Q::Out],
        kernel: StreamKernel,
        counter: &mut C,
    ) {
        let mut pending = Pending::new();
        match kernel.resolve_for(self.interleaves()) {
            StreamKernel::Interleaved => {
                dispatch(isa, Interleaved::<T, L, C, Q, _> { bvh: *self, rays, ids: 0..rays.len(), out, counter });
            }
            StreamKernel::Packets => {
                let op = Stream::<T, L, C, Q, false> { bvh: *self, rays, out, counter, from: 0, pending: &mut pending };
                dispatch(isa, op);
            }
            StreamKernel::Auto | StreamKernel::Hybrid => {
                let mut at = 0;
                while at < rays.len() {
                    let op = Stream::<T, L, C, Q, true> {
                        bvh: *self,
                        rays,
                        out: &mut *out,
                        counter: &mut *counter,
                        from: at,
                        pending: &mut pending,
                    };
                    at = dispatch(isa, op);
                    if !pending.is_empty() {
                        let ids = pending.drain();
                        let op = Interleaved::<T, L, C, Q, _> {
                            bvh: *self,
                            rays,
                            ids,
                            out: &mut *out,
                            counter: &mut *counter,
                        };
                        dispatch(isa, op);
                    }
                }
            }
        }
    }

    /// True when the single-ray closest-hit query speculates its descents: in trees of at
    /// most [`SPECULATION_MAX_BYTES`].
    pub fn speculates(&self) -> bool {
        self.bytes() <= SPECULATION_MAX_BYTES
    }

    /// True when the streams interleave the single rays of incoherent packets
    /// ([`crate::bvh::traverse_interleaved`]): when the tree is larger than the last-level
    /// cache ([`crate::system::last_level_cache_bytes`]).
    pub fn interleaves(&self) -> bool {
        self.bytes() as u64 > crate::system::last_level_cache_bytes()
    }
}

/// The queries of a tree in the default layout (a compact tree's read the scene store: its
/// [`crate::Scene`] queries it, or [`Bvh8::compact_slices`]); each is the query of
/// [`Bvh8::slices`].
impl<T: TriBlock> Bvh8<T> {
    /// Could a ray from `origin` along a positive multiple of a vector in the box
    /// `[dir_lo, dir_hi]` hit a primitive, on ISA `isa`? ([`Bvh8Ref::cone_may_hit_with`].)
    pub fn cone_may_hit_with(&self, isa: Isa, origin: Vec3, dir_lo: Vec3, dir_hi: Vec3) -> bool {
        self.slices().cone_may_hit_with(isa, origin, dir_lo, dir_hi)
    }

    /// Closest hit along `ray` on the process's default ISA ([`Isa::default_for_process`]).
    /// Invalid rays miss; sphere hits carry `u = v = 0` (the scene fills them in).
    #[inline]
    pub fn intersect1(&self, ray: &Ray) -> Hit {
        self.intersect1_with(Isa::default_for_process(), ray, &mut NoCount)
    }

    /// True when anything lies in `[ray.tnear, ray.tfar]`, on the process's default ISA.
    /// Invalid rays are never occluded.
    #[inline]
    pub fn occluded1(&self, ray: &Ray) -> bool {
        self.occluded1_with(Isa::default_for_process(), ray, &mut NoCount)
    }

    /// [`Bvh8::intersect1`] on `isa`'s kernels (the CPU's best when it lacks `isa`), counting
    /// the work into `counter`.
    #[inline]
    pub fn intersect1_with<C: Counter>(&self, isa: Isa, ray: &Ray, counter: &mut C) -> Hit {
        self.slices().intersect1_with(isa, ray, counter)
    }

    /// [`Bvh8::occluded1`] on `isa`'s kernels, counting the work into `counter`.
    #[inline]
    pub fn occluded1_with<C: Counter>(&self, isa: Isa, ray: &Ray, counter: &mut C) -> bool {
        self.slices().occluded1_with(isa, ray, counter)
    }

    /// [`Bvh8Ref::intersect_packet_with`].
    #[inline]
    pub fn intersect_packet_with<R: RayPacket, C: Counter>(
        &self,
        isa: Isa,
        packet: &mut R,
        valid: u32,
        counter: &mut C,
    ) {
        self.slices().intersect_packet_with(isa, packet, valid, counter)
    }

    /// [`Bvh8Ref::occluded_packet_with`].
    #[inline]
    pub fn occluded_packet_with<R: RayPacket, C: Counter>(
        &self,
        isa: Isa,
        packet: &R,
        valid: u32,
        counter: &mut C,
    ) -> u32 {
        self.slices().occluded_packet_with(isa, packet, valid, counter)
    }

    /// [`Bvh8Ref::intersect_stream_with`].
    pub fn intersect_stream_with<C: Counter>(
        &self,
        isa: Isa,
        rays: &[Ray],
        hits: &mut [Hit],
        kernel: StreamKernel,
        counter: &mut C,
    ) {
        self.slices().intersect_stream_with(isa, rays, hits, kernel, counter)
    }

    /// [`Bvh8Ref::occluded_stream_with`].
    pub fn occluded_stream_with<C: Counter>(
        &self,
        isa: Isa,
        rays: &[Ray],
        occluded: &mut [bool],
        kernel: StreamKernel,
        counter: &mut C,
    ) {
        self.slices().occluded_stream_with(isa, rays, occluded, kernel, counter)
    }

    /// True when the single-ray closest-hit query speculates its descents: in trees of at
    /// most [`SPECULATION_MAX_BYTES`] (nodes and leaf blocks as stored; a compact tree's
    /// kernels read the scene store as well: [`crate::Scene::speculates`]).
    pub fn speculates(&self) -> bool {
        self.bytes() <= SPECULATION_MAX_BYTES
    }

    /// True when the streams interleave the single rays of incoherent packets
    /// ([`crate::bvh::traverse_interleaved`]): when the tree is larger than the last-level
    /// cache ([`crate::system::last_level_cache_bytes`]); of a compact tree:
    /// [`crate::Scene::interleaves`].
    pub fn interleaves(&self) -> bool {
        self.bytes() as u64 > crate::system::last_level_cache_bytes()
    }
}

/// How a stream query traces its rays (every way gives the same answers).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StreamKernel {
    /// [`StreamKernel::Hybrid`] in a tree larger than the last-level cache
    /// ([`Bvh8::interleaves`]), [`StreamKernel::Packets`] otherwise.
    #[default]
    Auto,
    /// Packets of consecutive rays of the ISA's stream width through the hybrid packet
    /// kernels ([`crate::bvh::traverse_packet`]), whatever the tree.
    Packets,
    /// Packets, but the rays of incoherent packets (directions of both signs on two axes or
    /// more) as single rays several in flight at once ([`crate::bvh::traverse_interleaved`]),
    /// whatever the tree.
    Hybrid,
    /// Every ray as a single ray, several in flight at once
    /// ([`crate::bvh::traverse_interleaved`]).
    Interleaved,
}

impl StreamKernel {
    /// The kernel that runs on `bvh`: [`StreamKernel::Auto`] decided by the tree's size.
    pub fn resolve<T: TriBlock>(self, bvh: &Bvh8<T>) -> StreamKernel {
        self.resolve_for(bvh.interleaves())
    }

    /// The kernel that runs on a tree that interleaves ([`Bvh8::interleaves`]) or not.
    pub(crate) fn resolve_for(self, interleaves: bool) -> StreamKernel {
        match self {
            StreamKernel::Auto if interleaves => StreamKernel::Hybrid,
            StreamKernel::Auto => StreamKernel::Packets,
            k => k,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{StreamKernel, incoherent_packet};
    use crate::bvh::NoCount;
    use crate::bvh::traverse_packet::PacketRays;
    use crate::rng::Rng;
    use crate::simd::F32x16;
    use crate::{Hit, Isa, Ray, Vec3};

    /// Packets of 16 rays, alternately coherent (one origin, directions in a narrow cone, as
    /// camera rays) and incoherent (origins and directions at random, as diffuse bounces).
    fn mixed_packets(packets: usize) -> Vec<Ray> {
        let mut rng = Rng::new(3, 9);
        let mut r3 = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
        let mut rays = Vec::new();
        for p in 0..packets {
            let (origin, dir) = (Vec3::new(0.1, 0.2, 4.0), Vec3::new(0.3, -0.2, -1.0) + r3() * 0.3);
            for _ in 0..16 {
                rays.push(if p % 2 == 0 { Ray::new(origin, dir + r3() * 0.05) } else { Ray::new(r3() * 1.5, r3()) });
            }
        }
        rays
    }

    #[test]
    fn coherence_of_packets() {
        let incoherent = |rays: &[Ray]| incoherent_packet(&PacketRays::<F32x16>::new(rays, u32::MAX));
        let rays = mixed_packets(2);
        assert!(!incoherent(&rays[..16]) && incoherent(&rays[16..]));
        assert!(incoherent(&rays[16..24]), "a partial packet");
        let one_axis: Vec<Ray> = (0..16).map(|i| Ray::new(Vec3::ZERO, Vec3::new(i as f32 - 7.5, -1.0, -1.0))).collect();
        assert!(!incoherent(&one_axis), "camera rays straddling the middle column are coherent");
        // Only the valid lanes count: the packet's last ray is not valid.
        let mut two_axes = one_axis.clone();
        two_axes[15] = Ray { tnear: f32::NAN, ..Ray::new(Vec3::ZERO, Vec3::new(1.0, 1.0, -1.0)) };
        assert!(!incoherent(&two_axes));
        two_axes[15].tnear = 0.0;
        assert!(incoherent(&two_axes));
    }

    /// Streams that interleave the rays of their incoherent packets (forced here, in a tree
    /// that fits the caches) answer each ray as the single-ray kernels do, on every ISA tier,
    /// over more incoherent packets than are set aside at once.
    #[test]
    fn interleaving_streams_answer_as_single_rays() {
        let scene = crate::testing::soup_and_sphere(11);
        let bvh = scene.bvh8();
        let mut rays = mixed_packets(2 * super::PENDING_RUNS + 37);
        rays.truncate(rays.len() - 5);
        rays[20] = Ray { tnear: f32::NAN, ..rays[20] }; // not valid: misses, not blocked
        for isa in Isa::available() {
            let mut hits = vec![Hit { t: -1.0, ..Hit::MISS }; rays.len()];
            let mut blocked = vec![true; rays.len()];
            bvh.intersect_stream_with(isa, &rays, &mut hits, StreamKernel::Hybrid, &mut NoCount);
            bvh.occluded_stream_with(isa, &rays, &mut blocked, StreamKernel::Hybrid, &mut NoCount);
            let mut hit_count = 0;
            for (i, r) in rays.iter().enumerate() {
                let want = bvh.intersect1_with(isa, r, &mut NoCount);
                assert_eq!(hits[i].is_hit(), want.is_hit(), "{isa} ray {i}");
                assert_eq!(hits[i].t.to_bits(), want.t.to_bits(), "{isa} ray {i}");
                assert_eq!(blocked[i], bvh.occluded1_with(isa, r, &mut NoCount), "{isa} ray {i}");
                hit_count += want.is_hit() as usize;
            }
            assert!(hit_count > rays.len() / 4 && !hits[20].is_hit() && !blocked[20], "{isa}: {hit_count} hits");
        }
    }
}
