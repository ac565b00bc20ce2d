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
//! instead of one. Each ray's traversal is the single-ray kernels' own, step for step (the
//! same node test, order of children, leaf tests and pops, [`crate::bvh::traverse1`]), so the
//! hits are those of [`crate::Scene::intersect1`] and [`crate::Scene::occluded1`] exactly.
//!
//! Where the tree fits the caches the prefetches cover nothing and the switching costs: each
//! step starts from its ray's state in memory, and the branch predictor sees the rays'
//! histories mixed. The streams therefore take this path only for the rays of incoherent
//! packets in trees larger than the last-level cache ([`crate::bvh::queries`]).
// Measured: PERFORMANCE.md, "Incoherent rays in large trees: several in flight".

use crate::bvh::BVH8_STACK;
use crate::bvh::bvh8::Bvh8Ref;
use crate::bvh::counters::{Counter, Work};
use crate::bvh::node::NodeRef;
use crate::bvh::traverse1::{Ray1, next_child, push_all_but_nearest, push_below_highest};
use crate::geometry::{TriBlock, TriangleKernel};
use crate::ray::{Hit, Ray};
use crate::simd::{IsaLanes, Lanes};
use std::mem::MaybeUninit;

/// Rays in flight at once. Stanford dragon and 2M knot diffuse rays, AVX2, 1 thread: 2 and 4
/// were slower than 8, 16 no faster (PERFORMANCE.md).
pub const FLIGHTS: usize = 8;

/// One ray's traversal stack: child references and (closest hit) their entry distances.
struct Stack {
    refs: [MaybeUninit<NodeRef>; BVH8_STACK],
    dists: [MaybeUninit<f32>; BVH8_STACK],
}

/// A query whose rays can be stepped: its per-ray state, its step and its answer.
trait Flight<I: IsaLanes, T: TriBlock, P: TriangleKernel>: Sized {
    /// The answer for one ray.
    type Out: Copy;
    /// The answer for a ray that is not valid ([`Ray::is_valid`]).
    const INVALID: Self::Out;
    /// The state of `ray` (valid) before its first step, at the root.
    fn start(bvh: &Bvh8Ref<'_, T>, ray: &Ray) -> Self;
    /// Visits the ray's current node, or its current leaf and the pops after it; ends with a
    /// prefetch of the next one. `Some` when the ray is done.
    fn step<C: Counter>(&mut self, bvh: &Bvh8Ref<'_, T>, stack: &mut Stack, counter: &mut C) -> Option<Self::Out>;
}

/// Closest hit of one ray in flight.
struct Closest<I: IsaLanes, T: TriBlock, P: TriangleKernel> {
    r: Ray1<I::F8>,
    pre: P::Ray1<T::Lanes<I>>,
    tfar: f32,
    hit: Hit,
    cur: NodeRef,
    sp: usize,
}

impl<I: IsaLanes, T: TriBlock, P: TriangleKernel> Flight<I, T, P> for Closest<I, T, P> {
    type Out = Hit;
    const INVALID: Hit = Hit::MISS;

    #[inline(always)]
    fn start(bvh: &Bvh8Ref<'_, T>, ray: &Ray) -> Self {
        let r = Ray1::new(ray);
        Self { tfar: r.ray.tfar, r, pre: P::ray1(ray), hit: Hit::MISS, cur: bvh.root(), sp: 0 }
    }

    #[inline(always)]
    fn step<C: Counter>(&mut self, bvh: &Bvh8Ref<'_, T>, s: &mut Stack, counter: &mut C) -> Option<Hit> {
        let cur = self.cur;
        if !cur.is_leaf() {
            let node = &bvh.nodes[cur.node_index()];
            counter.add(Work::Nodes, 1);
            let (mut mask, dist) = self.r.intersect_node(node, self.tfar);
            if mask != 0 {
                let i0 = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                if mask == 0 {
                    self.cur = next_child(node, i0);
                    bvh.prefetch(self.cur);
                    return None;
                }
                let mut d = [0.0f32; 8];
                dist.store(&mut d);
                bvh.prefetch_children(node, i0, mask);
                let i1 = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let near = if mask == 0 {
                    let (near, far) = if d[i0] <= d[i1] { (i0, i1) } else { (i1, i0) };
                    s.refs[self.sp] = MaybeUninit::new(node.children[far]);
                    s.dists[self.sp] = MaybeUninit::new(d[far]);
                    self.sp += 1;
                    near
                } else {
                    push_all_but_nearest(node, i0, i1, mask, &d, &mut s.refs, &mut s.dists, &mut self.sp)
                };
                self.cur = next_child(node, near);
                return None;
            }
        } else {
            let tnear = T::Lanes::<I>::splat(self.r.ray.tnear);
            bvh.intersect_leaf1::<I, P, C>(cur, &self.r, &self.pre, tnear, &mut self.tfar, &mut self.hit, counter);
        }
        while self.sp > 0 {
            self.sp -= 1;
            // SAFETY: entries below sp were written by pushes.
            let (next, d) = unsafe { (s.refs[self.sp].assume_init(), s.dists[self.sp].assume_init()) };
            if d <= self.tfar {
                self.cur = next;
                bvh.prefetch(next);
                return None;
            }
        }
        Some(self.hit)
    }
}

/// Any hit of one ray in flight.
struct Any<I: IsaLanes, T: TriBlock, P: TriangleKernel> {
    r: Ray1<I::F8>,
    pre: P::Ray1<T::Lanes<I>>,
    cur: NodeRef,
    sp: usize,
}

impl<I: IsaLanes, T: TriBlock, P: TriangleKernel> Flight<I, T, P> for Any<I, T, P> {
    type Out = bool;
    const INVALID: bool = false;

    #[inline(always)]
    fn start(bvh: &Bvh8Ref<'_, T>, ray: &Ray) -> Self {
        Self { r: Ray1::new(ray), pre: P::ray1(ray), cur: bvh.root(), sp: 0 }
    }

    #[inline(always)]
    fn step<C: Counter>(&mut self, bvh: &Bvh8Ref<'_, T>, s: &mut Stack, counter: &mut C) -> Option<bool> {
        let cur = self.cur;
        if !cur.is_leaf() {
            let node = &bvh.nodes[cur.node_index()];
            counter.add(Work::Nodes, 1);
            let (mask, _) = self.r.intersect_node(node, self.r.ray.tfar);
            if mask != 0 {
                let first = push_below_highest(node, mask, &mut s.refs, &mut self.sp);
                self.cur = next_child(node, first);
                bvh.prefetch(self.cur);
                return None;
            }
        } else {
            let (tnear, tfar) = (T::Lanes::<I>::splat(self.r.ray.tnear), T::Lanes::<I>::splat(self.r.ray.tfar));
            if bvh.occluded_leaf1::<I, P, C>(cur, &self.r, &self.pre, tnear, tfar, counter) {
                return Some(true);
            }
        }
        if self.sp == 0 {
            return Some(false);
        }
        self.sp -= 1;
        // SAFETY: entries below sp were written by pushes.
        self.cur = unsafe { s.refs[self.sp].assume_init() };
        bvh.prefetch(self.cur);
        None
    }
}

impl<T: TriBlock> Bvh8Ref<'_, T> {
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
        self.interleave::<I, P, C, Closest<I, T, P>>(rays, ids, hits, counter);
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
        self.interleave::<I, P, C, Any<I, T, P>>(rays, ids, occluded, counter);
    }

    /// The driver: starts a ray in every free flight, steps the flights in turn, and writes
    /// each ray's answer when it is done.
    #[inline(always)]
    fn interleave<I: IsaLanes, P: TriangleKernel, C: Counter, F: Flight<I, T, P>>(
        &self,
        rays: &[Ray],
        mut ids: impl Iterator<Item = usize>,
        out: &mut [F::Out],
        counter: &mut C,
    ) {
        debug_assert_eq!(P::TEST, self.test, "kernel of the block layout");
        let mut flights: [Option<(F, usize)>; FLIGHTS] = [const { None }; FLIGHTS];
        let mut stacks =
            [const { Stack { refs: [MaybeUninit::uninit(); BVH8_STACK], dists: [MaybeUninit::uninit(); BVH8_STACK] } };
                FLIGHTS];
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
                *f = Some((F::start(self, &rays[i]), i));
                live |= 1 << g;
            }
        }
        while live != 0 {
            let mut m = live;
            while m != 0 {
                let g = m.trailing_zeros() as usize;
                m &= m - 1;
                let Some((f, i)) = &mut flights[g] else { continue };
                if let Some(answer) = f.step(self, &mut stacks[g], counter) {
                    out[*i] = answer;
                    match next_ray(out) {
                        Some(j) => {
                            *f = F::start(self, &rays[j]);
                            *i = j;
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
