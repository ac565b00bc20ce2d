//! Single rays traced several at a time, for incoherent rays in trees larger than the caches.
//!
//! A single ray's traversal is one chain of dependent loads: a node's address is known only
//! when its parent's box test is done, and a leaf's blocks only when its node's is. In a tree
//! that fits the caches each load takes a few cycles; in one that does not (the Stanford
//! dragon's, a 2M-triangle mesh's) the ray waits on the L3 and on memory at
//! nearly every step, one miss after another. Here [`FLIGHTS`] rays are in flight at once,
//! each advanced by one step (a node, or a leaf and the pops after it) in turn, and every
//! step ends by prefetching what its ray visits next: by the time the ray's turn comes again,
//! the other rays' steps have covered the miss, and several misses are outstanding at once
//! instead of one. Each ray's traversal is the single-ray kernels' own: the same skeleton
//! and queries ([`crate::bvh::traverse1`]) taking one step per turn, so the hits are those of
//! [`crate::Scene::intersect1`] and [`crate::Scene::occluded1`] exactly.
//!
//! Where the tree fits the caches the prefetches cover nothing and the switching costs: each
//! step starts from its ray's state in memory, and the branch predictor sees the rays'
//! histories mixed. The streams therefore take this path only for the rays of incoherent
//! packets in trees larger than the last-level cache ([`crate::bvh::queries`]).
// Measured: PERFORMANCE.md, "Incoherent rays in large trees: several in flight".

use crate::bvh::BVH8_STACK;
use crate::bvh::bvh8::{Bvh8Ref, LeafBlocks};
use crate::bvh::counters::Counter;
use crate::bvh::node::NodeRef;
use crate::bvh::stack::{TraversalStack, stack_storage};
use crate::bvh::traverse1::{Any, Closest, Ray1, SingleRayQuery};
use crate::geometry::{TriBlock, TriangleKernel};
use crate::ray::{Hit, Ray};
use crate::simd::IsaLanes;

/// Rays in flight at once. Stanford dragon and 2M knot diffuse rays, AVX2, 1 thread: 2 and 4
/// were slower than 8, 16 no faster (PERFORMANCE.md).
pub const FLIGHTS: usize = 8;

/// A single-ray query whose rays can be in flight: the skeleton's query
/// ([`SingleRayQuery`]) holding its ray's constants and answer itself.
trait Flight<I: IsaLanes, T: TriBlock>: SingleRayQuery<I, T, Out: Copy> {
    /// The answer for a ray that is not valid ([`Ray::is_valid`]).
    const INVALID: Self::Out;
    /// The query of `ray` (valid) before its first step.
    fn start(ray: &Ray) -> Self;
}

impl<I: IsaLanes, T: TriBlock, P: TriangleKernel> Flight<I, T> for Closest<I, T, P, Ray1<I::F8>, Hit> {
    const INVALID: Hit = Hit::MISS;

    #[inline(always)]
    fn start(ray: &Ray) -> Self {
        let r = Ray1::new(ray);
        Closest::new(r, r.ray.tfar, Hit::MISS)
    }
}

impl<I: IsaLanes, T: TriBlock, P: TriangleKernel> Flight<I, T> for Any<I, T, P, Ray1<I::F8>> {
    const INVALID: bool = false;

    #[inline(always)]
    fn start(ray: &Ray) -> Self {
        Any::new(Ray1::new(ray))
    }
}

impl<T: TriBlock, L: LeafBlocks<T>> Bvh8Ref<'_, T, L> {
    /// Closest hits of the rays `rays[i]` for `i` in `ids`, into `hits[i]`, [`FLIGHTS`] rays
    /// in flight (see the module docs); a ray that is not valid gets [`Hit::MISS`]. Sphere
    /// hits carry `u = v = 0`, as in [`Bvh8Ref::intersect1_from`].
    #[inline(always)]
    pub fn intersect_interleaved<I: IsaLanes, P: TriangleKernel, C: Counter>(
        &self,
        rays: &[Ray],
        ids: impl Iterator<Item = usize>,
        hits: &mut [Hit],
        counter: &mut C,
    ) {
        self.interleave::<I, P, C, Closest<I, T, P, Ray1<I::F8>, Hit>>(rays, ids, hits, counter);
    }

    /// Whether anything blocks the rays `rays[i]` for `i` in `ids`, into `occluded[i]`,
    /// [`FLIGHTS`] rays in flight (see the module docs); a ray that is not valid is not
    /// blocked.
    #[inline(always)]
    pub fn occluded_interleaved<I: IsaLanes, P: TriangleKernel, C: Counter>(
        &self,
        rays: &[Ray],
        ids: impl Iterator<Item = usize>,
        occluded: &mut [bool],
        counter: &mut C,
    ) {
        self.interleave::<I, P, C, Any<I, T, P, Ray1<I::F8>>>(rays, ids, occluded, counter);
    }

    /// The driver: starts a ray in every free flight, steps the flights in turn, and writes
    /// each ray's answer when it is done.
    #[inline(always)]
    fn interleave<I: IsaLanes, P: TriangleKernel, C: Counter, F: Flight<I, T>>(
        &self,
        rays: &[Ray],
        mut ids: impl Iterator<Item = usize>,
        out: &mut [F::Out],
        counter: &mut C,
    ) {
        debug_assert_eq!(P::TEST, self.test, "kernel of the block layout");
        // Each flight: its query, its current node or leaf, and its ray's index.
        let mut flights: [Option<(F, NodeRef, usize)>; FLIGHTS] = [const { None }; FLIGHTS];
        let mut items = [const { stack_storage::<F::Entry, BVH8_STACK>() }; FLIGHTS];
        let mut stacks = items.each_mut().map(TraversalStack::new);
        // The next valid ray, answering the invalid ones on the way.
        let mut next_ray = |out: &mut [F::Out]| {
            for i in ids.by_ref() {
                if rays[i].is_valid() {
                    return Some(i);
                }
                out[i] = F::INVALID;
            }
            None
        };
        let mut live = 0u32;
        for (g, f) in flights.iter_mut().enumerate() {
            if let Some(i) = next_ray(out) {
                *f = Some((F::start(&rays[i]), self.root(), i));
                live |= 1 << g;
            }
        }
        while live != 0 {
            let mut m = live;
            while m != 0 {
                let g = m.trailing_zeros() as usize;
                m &= m - 1;
                let Some((f, cur, i)) = &mut flights[g] else { continue };
                if let Some(answer) = self.walk1::<I, F, C, false, true>(f, cur, &mut stacks[g], counter) {
                    out[*i] = answer;
                    match next_ray(out) {
                        Some(j) => {
                            *f = F::start(&rays[j]);
                            *cur = self.root();
                            *i = j;
                            // An any-hit query ends at its first hit, with entries left.
                            stacks[g].clear();
                        }
                        None => {
                            flights[g] = None;
                            live &= !(1 << g);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::bvh::StreamKernel;
    use crate::bvh::TraversalCounts;
    use crate::rng::Rng;
    use crate::{Isa, Ray, Vec3};

    /// The interleaved kernels take each ray through the single-ray kernels' steps, whatever
    /// the other flights do: the same answers and the same work (nodes, leaves, blocks) as
    /// the single-ray queries ray by ray, on every ISA tier. Short segments make many any-hit
    /// queries end at a hit with entries left on their stack, which the flight's next ray
    /// must not pop.
    #[test]
    fn interleaved_kernels_take_the_single_ray_kernels_steps() {
        let scene = crate::testing::soup_and_sphere(5);
        let bvh = scene.bvh8();
        let mut rng = Rng::new(8, 2);
        let mut r3 = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
        let mut rays: Vec<Ray> = (0..4000)
            .map(|i| Ray::segment(r3() * 1.5, r3(), 0.0, if i % 2 == 0 { 0.3 } else { f32::INFINITY }))
            .collect();
        rays[7] = Ray { tnear: f32::NAN, ..rays[7] }; // not valid: misses, not blocked
        for isa in Isa::available() {
            let (mut single, mut flights) = (TraversalCounts::default(), TraversalCounts::default());
            let mut blocked = vec![true; rays.len()];
            bvh.occluded_stream_with(isa, &rays, &mut blocked, StreamKernel::Interleaved, &mut flights);
            let want: Vec<bool> = rays.iter().map(|r| bvh.occluded1_with(isa, r, &mut single)).collect();
            assert_eq!(blocked, want, "{isa}");
            assert_eq!(flights, single, "{isa}: occlusion work");
            let blocked_count = want.iter().filter(|&&b| b).count();
            assert!(blocked_count > rays.len() / 8 && blocked_count < rays.len() / 2, "{isa}: {blocked_count}");

            let (mut single, mut flights) = (TraversalCounts::default(), TraversalCounts::default());
            let mut hits = vec![crate::Hit::MISS; rays.len()];
            bvh.intersect_stream_with(isa, &rays, &mut hits, StreamKernel::Interleaved, &mut flights);
            for (i, r) in rays.iter().enumerate() {
                let want = bvh.intersect1_with(isa, r, &mut single);
                assert_eq!((hits[i].t.to_bits(), hits[i].prim), (want.t.to_bits(), want.prim), "{isa} ray {i}");
            }
            assert_eq!(flights, single, "{isa}: closest-hit work");
        }
    }
}
