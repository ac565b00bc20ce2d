// Not split: the node test, the one single-ray skeleton and its two queries inline into each other, with their unit tests.
//! Single-ray traversal of the 8-wide BVH: one ray against the eight child boxes of a node
//! per step, closest hit (`intersect1`) and any hit (`occluded1`).
//!
//! One skeleton (`Bvh8Ref::walk1`) walks the tree for every single-ray kernel: the fused
//! closest-hit and any-hit kernels below and the interleaved ones
//! ([`crate::bvh::traverse_interleaved`]). The query it is instantiated with
//! (`SingleRayQuery`: `Closest` or `Any`) supplies the order of a node's hit children, the
//! leaf test and which stack entries still matter, as Embree's and pbrt-v4's traversal loops
//! are one loop with the query's parts plugged in.
//!
//! The node test is Embree's (Wald et al., "Embree: A Kernel Framework for Efficient CPU Ray
//! Tracing", 2014; for 8 lanes Fuetterling et al., "Accelerated Single Ray Tracing for Wide
//! Vector Units", HPG 2017): the ray's direction signs pick, once per ray, which row of the
//! node holds each axis' near plane, so the branch-free slab test is
//! `t_near = max((near - o) · 1/d)`, `t_far = min((far - o) · 1/d)` over the axes with no
//! per-lane min/max of the two planes. Hit children are visited nearest first: with one hit
//! child the traversal just descends, with two it compares, with more it descends to the
//! nearest and pushes the others sorted by distance (popped entries farther than the closest
//! hit so far are skipped). On the AVX2 and AVX-512 tiers the slot a step descends to is
//! chosen through predicted branches (`speculated_slot`), so that the child's loads need not
//! wait for the box test that picks it. The any-hit kernel does not sort: it visits hit
//! children from the highest slot down, which tests a node's leaves before its subtrees.
//!
// Nearest first beat visiting hit children in slot order (PERFORMANCE.md, "Smaller measured
// choices"). The static per-octant child order of Fuetterling et al. (no sorting at run
// time, an order table per node) was not tried: the 256-byte node has no room for the
// tables without narrowing the child references.
//
// The any-hit kernel's order (leaves first, from the highest slot down) against the lowest
// slot first (inner subtrees first), nearest first and farthest first: PERFORMANCE.md, "Any
// hit: leaves first".
//
//! Leaves are runs of SoA blocks tested one ray against all M triangles at once
//! ([`crate::geometry::tri_block`]) with the BVH's [`TriangleKernel`] `P` (Möller–Trumbore
//! or watertight), chosen once per query. A block may hold the triangles of several small
//! leaves of one node ([`NodeRef::lane_mask`]); the single-ray kernels test all its lanes
//! whichever leaf they enter by, which costs nothing (one test either way) and is exact: every
//! lane is a triangle of the scene, so a hit found there is a true hit, found early.
//!
//! The kernels are generic over the ISA's lanes `I` ([`IsaLanes`]) and a work [`Counter`]
//! `C`, and `#[inline(always)]`: the entry points of [`crate::bvh::queries`] instantiate
//! them per ISA tier, triangle test and counter.

use crate::bvh::bvh2::SLAB_WIDEN;
use crate::bvh::bvh8::{Bvh8Ref, LeafBlocks};
use crate::bvh::counters::{Counter, Work};
use crate::bvh::node::{Bvh8Node, LeafKind, NodeRef};
use crate::bvh::stack::{NearEntry, TraversalStack, stack_storage};
use crate::geometry::sphere_block::sphere_lanes;
use crate::geometry::{TriBlock, TriangleKernel};
use crate::math::{SAFE_RECIP_TINY, Vec3};
use crate::ray::{Hit, Ray};
use crate::simd::{IsaLanes, Lanes, Vec3x};
use std::borrow::{Borrow, BorrowMut};

/// `crate::math::safe_recip` in every lane: magnitudes below `SAFE_RECIP_TINY` map to its
/// reciprocal with the lane's sign. (Kernels use small functions, not closures: a closure is
/// compiled without the ISA's target features and, holding SIMD code, is not inlined into the
/// kernel.)
#[inline(always)]
pub(crate) fn safe_recip_lanes<V: Lanes>(x: V) -> V {
    let tiny = V::splat(SAFE_RECIP_TINY);
    x.abs().lt(tiny).select(V::splat(1.0 / SAFE_RECIP_TINY).copysign(x), V::splat(1.0) / x)
}

/// Per-ray constants of the single-ray kernels, in lanes `V` of 8 (one per child slot).
#[derive(Clone, Copy, Debug)]
pub struct Ray1<V> {
    /// The ray.
    pub ray: Ray,
    org: Vec3x<V>,
    inv: Vec3x<V>,
    /// `inv * SLAB_WIDEN` per axis: the far planes' factor (see [`Ray1::intersect_node`]).
    inv_far: Vec3x<V>,
    tnear: V,
    /// Where the near plane of each axis starts in the node's bounds read as one array of 48
    /// floats (`Bvh8Node::bounds` flattened): 0 or 8, 16 or 24, 32 or 40; the far plane's
    /// row is the other one (`^ 8`). In floats rather than rows so that the loads index with
    /// the address's scale factor and need no shift per node.
    near: [usize; 3],
}

impl<V: Lanes> Ray1<V> {
    /// Precomputes the slab-test constants of `ray` (which must be valid).
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        Self::from_lanes(ray, V::load(&ray.to_array()))
    }

    /// The constants of `ray` when it is valid ([`Ray::is_valid`]), `None` when it is not:
    /// the validity check and the reciprocal direction on the ray's eight floats as one
    /// vector of lanes (two comparisons and one division) instead of a branch and a division
    /// per component.
    #[inline(always)]
    pub fn try_new(ray: &Ray) -> Option<Self> {
        let v = V::load(&ray.to_array());
        let a = v.abs();
        // Lanes 0-5: origin and direction finite; lanes 3-5: some direction component of
        // magnitude at least `Ray::MIN_DIRECTION` (NaN fails both).
        let finite = a.le(V::splat(f32::MAX)).bitmask() & 0x3f == 0x3f;
        let moving = a.ge(V::splat(Ray::MIN_DIRECTION)).bitmask() & 0x38 != 0;
        // No closure (`bool::then`): closures do not inherit the ISA's target features.
        if finite & moving & (ray.tnear >= 0.0) & (ray.tnear <= ray.tfar) {
            Some(Self::from_lanes(ray, v))
        } else {
            None
        }
    }

    #[inline(always)]
    fn from_lanes(ray: &Ray, v: V) -> Self {
        debug_assert_eq!(V::LANES, 8, "one lane per child slot");
        let recip = safe_recip_lanes(v); // lanes 3-5 are the direction's
        let inv = Vec3::new(recip.lane(3), recip.lane(4), recip.lane(5));
        let neg = recip.lt(V::splat(0.0)).bitmask();
        // `+ 0.0` turns a `tnear` or `tfar` of `-0.0` into `+0.0` (see `intersect_node`), in
        // the ray itself so that the node and the triangle tests share one value; callers start
        // the closest-hit search from `ray.tfar` of the result.
        let ray = Ray { tnear: ray.tnear + 0.0, tfar: ray.tfar + 0.0, ..*ray };
        Self {
            ray,
            org: Vec3x::splat(ray.origin),
            inv: Vec3x::splat(inv),
            inv_far: Vec3x::splat(inv * SLAB_WIDEN),
            tnear: V::splat(ray.tnear),
            near: [(neg & 8) as usize, 16 + (neg >> 1 & 8) as usize, 32 + (neg >> 2 & 8) as usize],
        }
    }

    /// Slab test against the eight child boxes of `n` over `[tnear, tfar]`: bit `i` of the mask
    /// is set when child `i` is hit, and lane `i` of the result is its entry distance.
    ///
    /// The exit distances are widened by [`SLAB_WIDEN`] (Ize's robust traversal) through the
    /// far planes' factor `inv * SLAB_WIDEN`, not by a multiplication of their minimum: the
    /// same number of roundings (subtraction, reciprocal, the factor's product, the plane's
    /// product), so the same guarantee, and one dependent multiplication fewer per node. With
    /// the four-operand minimum and maximum as two levels each, the test's critical path is
    /// four dependent operations instead of six.
    ///
    /// On AVX2 and above ([`Lanes::INT_ORDER`]) the maximum, minimum and comparison read the
    /// distances' bits as integers ([`Lanes::max_bits`]: `vpmaxsd`, `vpminsd`, `vpcmpgtd`, one
    /// cycle each where the float forms take two to four), as Embree's kernels do; on SSE2,
    /// where those take three or four instructions each, they stay floats. Both give the
    /// same hits: `tnear` is `+0.0` or more (a `-0.0` is made `+0.0` in [`Ray1::new`], and
    /// so is a `tfar` of `-0.0`; hit distances are never `-0.0`) and the reciprocal is finite,
    /// so no lane is NaN, the entry distance `tn` is the float maximum, and a negative float
    /// reads as a negative integer, below every `tn`. The one difference, an exit distance of
    /// `-0.0` against an entry of `+0.0` (a miss for the integers, a hit for the floats), is a
    /// box the ray leaves exactly at its origin (the subtraction is exact when it gives zero),
    /// where no hit can lie, not even one at `t = 0`: node boxes are padded outward
    /// ([`crate::bvh::build::pad_outward`]), so every primitive lies strictly inside its
    /// box and no point of it on the box's boundary.
    // Tried and not kept: the fused form `t = plane * inv - org * inv` (one FMA per plane
    // instead of a subtraction and a multiplication, as Embree's non-robust kernel does). It
    // was a little faster, but the rounding of `org * inv` grows with the distance of the
    // origin from the scene and would eat the 2^-20 relative padding of the node boxes for
    // origins more than about 16 scene extents away, making hits near node faces go missing.
    // Tried three times since, and it never paid: robust with the per-ray `org * inv` moved
    // outward past its rounding; without that rounding, as the best case; robust with `org *
    // inv` computed exactly in f64 and rounded outward. Slower on the CS184 scenes, even or
    // slower on the Stanford dragon (PERFORMANCE.md: "Single-ray kernel against
    // `rtcIntersect1`", "the fused node test", and "Inner children computed, not loaded", its
    // two retries).
    #[inline(always)]
    pub fn intersect_node(&self, n: &Bvh8Node, tfar: f32) -> (u32, V) {
        let b = n.bounds.as_flattened();
        // The masks restate the offsets' ranges (see `near`) so that the loads need no bounds
        // checks where the compiler cannot see where the offsets came from: the interleaved
        // kernels keep their rays' constants in memory (in the single-ray kernels, which can,
        // they cost instructions; PERFORMANCE.md, "The single-ray kernel's set-up").
        let [nx, ny, nz] = [self.near[0] & 8, 16 | self.near[1] & 8, 32 | self.near[2] & 8];
        let tnx = (V::load(&b[nx..]) - self.org.x) * self.inv.x;
        let tny = (V::load(&b[ny..]) - self.org.y) * self.inv.y;
        let tnz = (V::load(&b[nz..]) - self.org.z) * self.inv.z;
        let tfx = (V::load(&b[nx ^ 8..]) - self.org.x) * self.inv_far.x;
        let tfy = (V::load(&b[ny ^ 8..]) - self.org.y) * self.inv_far.y;
        let tfz = (V::load(&b[nz ^ 8..]) - self.org.z) * self.inv_far.z;
        if V::INT_ORDER {
            let tn = tnx.max_bits(tny).max_bits(tnz.max_bits(self.tnear));
            let tf = tfx.min_bits(tfy).min_bits(tfz.min_bits(V::splat(tfar)));
            (!tn.gt_bits(tf).bitmask() & 0xff, tn)
        } else {
            let tn = tnx.vmax(tny).vmax(tnz.vmax(self.tnear));
            let tf = tfx.vmin(tfy).vmin(tfz.vmin(V::splat(tfar)));
            (tn.le(tf).bitmask(), tn)
        }
    }

    /// Scalar twin of [`Ray1::intersect_node`]: per slot, the near plane of each axis chosen
    /// by the direction's sign, then the same slab arithmetic (far planes through
    /// `inv * SLAB_WIDEN`; the maximum, minimum and comparison on the bits as `i32` where the
    /// lanes `V` use the integer order, on the floats elsewhere).
    pub fn intersect_node_scalar(&self, n: &Bvh8Node, tfar: f32) -> u32 {
        let (o, inv) = (self.ray.origin, self.ray.inv_dir());
        let inv_far = inv * SLAB_WIDEN;
        let mut mask = 0;
        for i in 0..8 {
            let b = n.child_bounds(i);
            let (mut tn, mut tf) = ([0.0f32; 3], [0.0f32; 3]);
            for a in 0..3 {
                let (near, far) = if inv[a] < 0.0 { (b.max[a], b.min[a]) } else { (b.min[a], b.max[a]) };
                tn[a] = (near - o[a]) * inv[a];
                tf[a] = (far - o[a]) * inv_far[a];
            }
            let hit = if V::INT_ORDER {
                let bits = |t: f32| t.to_bits() as i32;
                let near = tn.iter().fold(bits(self.ray.tnear), |m, &t| m.max(bits(t)));
                near <= tf.iter().fold(bits(tfar), |m, &t| m.min(bits(t)))
            } else {
                tn.iter().fold(self.ray.tnear, |m, &t| m.max(t)) <= tf.iter().fold(tfar, |m, &t| m.min(t))
            };
            if hit {
                mask |= 1 << i;
            }
        }
        mask
    }
}

/// The child of slot `i` that the traversal descends to next. An inner child's reference is
/// computed ([`Bvh8Node::inner_child`]: slot 0's index, loaded with the node, plus `i`) rather
/// than loaded: the load of `children[i]`, which must wait for `i` and so for the whole box
/// test, then only decides the branch between node and leaf, which the processor predicts, and
/// the next node's address no longer waits for it. One L1 load less on the chain of dependent
/// latencies that a node step is.
// PERFORMANCE.md, "Inner children computed, not loaded".
#[inline(always)]
pub(crate) fn next_child(node: &Bvh8Node, i: usize) -> NodeRef {
    let c = node.children[i];
    if c.is_leaf() { c } else { node.inner_child(i) }
}

/// Slot `i` (below 8) as the outcome of branches: three branches on `i`'s bits lead to code
/// that sets the slot as a constant, so the result depends on the branches, which the
/// processor predicts, and not on `i`'s data. A node step is one chain of dependent
/// latencies (the node's rows, the slab test, the hit mask, its lowest bit, the child's
/// address, the child's rows); with the descent's slot coming from here, a correctly
/// predicted step starts loading the child as soon as the node's slot-0 reference is in,
/// while the box test that decides it is still running, and a mispredicted one costs what
/// the chain did plus the pipeline flush. The branch history of the descent so far (which
/// slots were taken above) is what lets the predictor guess the slot.
///
/// The constants are written by `asm!` because LLVM would otherwise fold the branches back
/// into `i`, which is the data dependency again. (A `match` on `i` became a jump table: one
/// indirect branch, which predicted worse than the three conditional ones.)
// PERFORMANCE.md, "Descent slots as predicted branches".
#[inline(always)]
fn speculated_slot(i: usize) -> usize {
    #[cfg(target_arch = "x86_64")]
    {
        macro_rules! slot {
            ($k:literal) => {{
                let k: usize;
                // SAFETY: moves a constant into a register: no memory, stack or flags touched.
                unsafe {
                    core::arch::asm!(
                        concat!("mov {0:e}, ", $k),
                        out(reg) k,
                        options(pure, nomem, nostack, preserves_flags)
                    )
                };
                k
            }};
        }
        debug_assert!(i < 8, "slot {i}");
        if i & 4 == 0 {
            if i & 2 == 0 {
                if i & 1 == 0 { slot!(0) } else { slot!(1) }
            } else if i & 1 == 0 {
                slot!(2)
            } else {
                slot!(3)
            }
        } else if i & 2 == 0 {
            if i & 1 == 0 { slot!(4) } else { slot!(5) }
        } else if i & 1 == 0 {
            slot!(6)
        } else {
            slot!(7)
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    i
}

/// The slot to descend to: through [`speculated_slot`]'s predicted branches when the caller
/// asks for it (`SPECULATE`) and the tier takes it ([`crate::bvh::tuning::speculate_descent`]:
/// not the baseline tier), else `i` as it is.
#[inline(always)]
fn descent_slot<I: IsaLanes, const SPECULATE: bool>(i: usize) -> usize {
    if SPECULATE && const { crate::bvh::tuning::speculate_descent(I::ISA) } { speculated_slot(i) } else { i }
}

/// What a single-ray query brings to the traversal skeleton ([`Bvh8Ref::walk1`]): the far
/// bound of its node tests, the order it visits a node's hit children in (which slot it
/// descends to, and what it pushes), what it does in a leaf, which stack entries it still
/// wants, and its answer. The closest-hit ([`Closest`]) and any-hit ([`Any`]) queries
/// implement it; [`Bvh8Ref::intersect1_from`], [`Bvh8Ref::occluded1_from`] and the
/// interleaved kernels ([`crate::bvh::traverse_interleaved`]) instantiate the skeleton with
/// them.
pub(crate) trait SingleRayQuery<I: IsaLanes, T: TriBlock> {
    /// A deferred subtree on the stack.
    type Entry: Copy;
    /// The answer for the ray.
    type Out;
    /// The ray's constants.
    fn ray(&self) -> &Ray1<I::F8>;
    /// The far end of the interval the node tests clip to.
    fn node_tfar(&self) -> f32;
    /// Of the hit children `mask` (not empty) of `node`, with entry distances `dist`, pushes
    /// the ones visited later onto `stack` and returns the child to descend to. `SPECULATE`
    /// and `IN_FLIGHT` as for [`Bvh8Ref::walk1`].
    fn order<L: LeafBlocks<T>, const SPECULATE: bool, const IN_FLIGHT: bool>(
        &self,
        bvh: &Bvh8Ref<'_, T, L>,
        node: &Bvh8Node,
        mask: u32,
        dist: I::F8,
        stack: &mut TraversalStack<'_, Self::Entry>,
    ) -> NodeRef;
    /// Tests the primitives of `leaf`; `Some` with the answer when the query is done.
    fn leaf<L: LeafBlocks<T>, C: Counter>(
        &mut self,
        bvh: &Bvh8Ref<'_, T, L>,
        leaf: NodeRef,
        counter: &mut C,
    ) -> Option<Self::Out>;
    /// The next deferred subtree to visit, dropping the entries that can no longer matter;
    /// `None` when none is left.
    fn pop(&self, stack: &mut TraversalStack<'_, Self::Entry>) -> Option<NodeRef>;
    /// The answer when the whole tree has been visited.
    fn finish(&self) -> Self::Out;
}

/// The closest-hit query: its leaves shrink `tfar` and update the hit `H` (`&mut Hit` in the
/// caller's memory, or a `Hit` of a ray in flight); hit children are visited nearest first
/// and popped entries farther than the closest hit so far are skipped. `R` holds the ray's
/// constants (a reference, or the constants of a ray in flight).
pub(crate) struct Closest<I: IsaLanes, T: TriBlock, P: TriangleKernel, R, H> {
    r: R,
    pre: P::Ray1<T::Lanes<I>>,
    tnear: T::Lanes<I>,
    /// The closest hit's distance so far (the ray's `tfar` before any).
    pub(crate) tfar: f32,
    hit: H,
}

impl<I: IsaLanes, T: TriBlock, P: TriangleKernel, R: Borrow<Ray1<I::F8>>, H: BorrowMut<Hit>> Closest<I, T, P, R, H> {
    /// The query of the ray `r`, searching `[r.ray.tnear, tfar]` with `hit` the closest hit
    /// so far.
    #[inline(always)]
    pub(crate) fn new(r: R, tfar: f32, hit: H) -> Self {
        let ray = &r.borrow().ray;
        Self { pre: P::ray1::<T::Lanes<I>>(ray), tnear: T::Lanes::<I>::splat(ray.tnear), tfar, hit, r }
    }
}

impl<I: IsaLanes, T: TriBlock, P: TriangleKernel, R: Borrow<Ray1<I::F8>>, H: BorrowMut<Hit>> SingleRayQuery<I, T>
    for Closest<I, T, P, R, H>
{
    type Entry = NearEntry;
    type Out = Hit;

    #[inline(always)]
    fn ray(&self) -> &Ray1<I::F8> {
        self.r.borrow()
    }

    #[inline(always)]
    fn node_tfar(&self) -> f32 {
        self.tfar
    }

    /// With one hit child the traversal just descends, with two it pushes the farther one,
    /// with more it pushes all but the nearest sorted by distance
    /// ([`push_all_but_nearest`]). When two or more children will be visited they are all
    /// prefetched, unless the tree is small enough to sit in the cache (`SPECULATE`).
    #[inline(always)]
    fn order<L: LeafBlocks<T>, const SPECULATE: bool, const IN_FLIGHT: bool>(
        &self,
        bvh: &Bvh8Ref<'_, T, L>,
        node: &Bvh8Node,
        mut mask: u32,
        dist: I::F8,
        stack: &mut TraversalStack<'_, NearEntry>,
    ) -> NodeRef {
        let i0 = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        if mask == 0 {
            let next = next_child(node, descent_slot::<I, SPECULATE>(i0));
            if IN_FLIGHT {
                bvh.prefetch(next);
            }
            return next;
        }
        let mut d = [0.0f32; 8];
        dist.store(&mut d);
        if !SPECULATE {
            bvh.prefetch_children(node, i0, mask);
        }
        let i1 = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        let near = if mask == 0 {
            let (near, far) = if d[i0] <= d[i1] { (i0, i1) } else { (i1, i0) };
            stack.push(NearEntry { node: node.children[far], dist: d[far] });
            near
        } else {
            push_all_but_nearest(node, i0, i1, mask, &d, stack)
        };
        next_child(node, descent_slot::<I, SPECULATE>(near))
    }

    #[inline(always)]
    fn leaf<L: LeafBlocks<T>, C: Counter>(
        &mut self,
        bvh: &Bvh8Ref<'_, T, L>,
        leaf: NodeRef,
        counter: &mut C,
    ) -> Option<Hit> {
        let (r, hit) = (self.r.borrow(), self.hit.borrow_mut());
        bvh.intersect_leaf1::<I, P, C>(leaf, r, &self.pre, self.tnear, &mut self.tfar, hit, counter);
        None
    }

    #[inline(always)]
    fn pop(&self, stack: &mut TraversalStack<'_, NearEntry>) -> Option<NodeRef> {
        // The empty stack first, the end of every ray: the loop's set-up is for the others.
        if stack.len() == 0 {
            return None;
        }
        while let Some(e) = stack.pop() {
            if e.dist <= self.tfar {
                return Some(e.node);
            }
        }
        None
    }

    #[inline(always)]
    fn finish(&self) -> Hit {
        *self.hit.borrow()
    }
}

/// The any-hit query: the first primitive found on the ray's interval ends it. Hit children
/// are visited from the highest slot down, without sorting: a node's leaves sit after its
/// inner children ([`Bvh8Node`]), so its leaves are tested before the traversal descends into
/// its subtrees, as the packet kernel does (`traverse_packet::LEAVES_FIRST`): a leaf costs a
/// block test where a subtree costs a walk, and an occluder found there ends the query.
pub(crate) struct Any<I: IsaLanes, T: TriBlock, P: TriangleKernel, R> {
    r: R,
    pre: P::Ray1<T::Lanes<I>>,
    tnear: T::Lanes<I>,
    tfar: T::Lanes<I>,
}

impl<I: IsaLanes, T: TriBlock, P: TriangleKernel, R: Borrow<Ray1<I::F8>>> Any<I, T, P, R> {
    /// The query of the ray `r` over its interval.
    #[inline(always)]
    pub(crate) fn new(r: R) -> Self {
        let ray = &r.borrow().ray;
        let (tnear, tfar) = (T::Lanes::<I>::splat(ray.tnear), T::Lanes::<I>::splat(ray.tfar));
        Self { pre: P::ray1::<T::Lanes<I>>(ray), tnear, tfar, r }
    }
}

impl<I: IsaLanes, T: TriBlock, P: TriangleKernel, R: Borrow<Ray1<I::F8>>> SingleRayQuery<I, T> for Any<I, T, P, R> {
    type Entry = NodeRef;
    type Out = bool;

    #[inline(always)]
    fn ray(&self) -> &Ray1<I::F8> {
        self.r.borrow()
    }

    #[inline(always)]
    fn node_tfar(&self) -> f32 {
        self.r.borrow().ray.tfar
    }

    #[inline(always)]
    fn order<L: LeafBlocks<T>, const SPECULATE: bool, const IN_FLIGHT: bool>(
        &self,
        bvh: &Bvh8Ref<'_, T, L>,
        node: &Bvh8Node,
        mask: u32,
        _dist: I::F8,
        stack: &mut TraversalStack<'_, NodeRef>,
    ) -> NodeRef {
        let first = push_below_highest(node, mask, stack);
        let next = next_child(node, descent_slot::<I, SPECULATE>(first));
        if IN_FLIGHT {
            bvh.prefetch(next);
        }
        next
    }

    #[inline(always)]
    fn leaf<L: LeafBlocks<T>, C: Counter>(
        &mut self,
        bvh: &Bvh8Ref<'_, T, L>,
        leaf: NodeRef,
        counter: &mut C,
    ) -> Option<bool> {
        let r = self.r.borrow();
        if bvh.occluded_leaf1::<I, P, C>(leaf, r, &self.pre, self.tnear, self.tfar, counter) {
            Some(true)
        } else {
            None
        }
    }

    #[inline(always)]
    fn pop(&self, stack: &mut TraversalStack<'_, NodeRef>) -> Option<NodeRef> {
        stack.pop()
    }

    #[inline(always)]
    fn finish(&self) -> bool {
        false
    }
}

impl<T: TriBlock, L: LeafBlocks<T>> Bvh8Ref<'_, T, L> {
    /// The single-ray traversal skeleton: query `q` from the subtree `cur` on. Each step is
    /// an inner node's box test and the query's choice of the child to descend to, or a
    /// leaf's test and the pops after it (or after a node none of whose children is hit).
    /// Returns the answer when the ray is done; `IN_FLIGHT` returns `None` after each step
    /// instead of going on, and prefetches the node or leaf the step ends on, for the ray's
    /// next turn: the interleaved kernels take one step of each ray in flight in turn.
    ///
    /// `SPECULATE` takes each descent's slot through predicted branches (`speculated_slot`)
    /// and skips the prefetches of hit children, which a tree this small holds in the cache.
    #[inline(always)]
    pub(crate) fn walk1<
        I: IsaLanes,
        Q: SingleRayQuery<I, T>,
        C: Counter,
        const SPECULATE: bool,
        const IN_FLIGHT: bool,
    >(
        &self,
        q: &mut Q,
        cur: &mut NodeRef,
        stack: &mut TraversalStack<'_, Q::Entry>,
        counter: &mut C,
    ) -> Option<Q::Out> {
        loop {
            if !cur.is_leaf() {
                let node = &self.nodes[cur.node_index()];
                counter.add(Work::Nodes, 1);
                let (mask, dist) = q.ray().intersect_node(node, q.node_tfar());
                if mask != 0 {
                    *cur = q.order::<L, SPECULATE, IN_FLIGHT>(self, node, mask, dist, stack);
                    if IN_FLIGHT {
                        return None;
                    }
                    continue;
                }
            } else if let Some(out) = q.leaf(self, *cur, counter) {
                return Some(out);
            }
            match q.pop(stack) {
                Some(next) => {
                    *cur = next;
                    if IN_FLIGHT {
                        self.prefetch(next);
                        return None;
                    }
                }
                None => return Some(q.finish()),
            }
        }
    }

    /// Closest-hit traversal of the subtree `start` in ISA `I` with triangle kernel `P`
    /// (which must be the kernel of `self.test`), shrinking `tfar` and updating `hit` as
    /// closer hits are found; the packet kernels' single-ray fallback enters here too.
    /// Sphere hits carry `u = v = 0`; the scene fills in their surface coordinates.
    ///
    /// `SPECULATE` takes each descent's slot through predicted branches (`speculated_slot`)
    /// and skips the prefetches of hit children, which a tree this small holds in the cache.
    /// The single-ray query sets it in small trees
    /// ([`crate::bvh::queries::SPECULATION_MAX_BYTES`]); the packet kernels' fallback does
    /// not: its rays enter subtrees part-way down, one after the other, where the branch
    /// history does not tell the slot, and the streams were slower with it (PERFORMANCE.md,
    /// "Descent slots as predicted branches"; the prefetches: "Fewer instructions per ray in
    /// small trees").
    #[inline(always)]
    pub fn intersect1_from<I: IsaLanes, P: TriangleKernel, C: Counter, const SPECULATE: bool>(
        &self,
        r: &Ray1<I::F8>,
        start: NodeRef,
        tfar_io: &mut f32,
        hit_io: &mut Hit,
        counter: &mut C,
    ) {
        debug_assert_eq!(P::TEST, self.test, "kernel of the block layout");
        // The closest hit so far stays in the caller's memory (`black_box` hides where the
        // reference points, so the compiler cannot keep its fields in registers): a hit writes
        // it, and the block test, which needs every vector register, no longer saves and
        // restores `t`, `u` and `v` around each block. `tfar` stays in a register: in memory
        // too it saved instructions but cost wall clock (PERFORMANCE.md, "Spills of the
        // single-ray kernel").
        let mut q = Closest::<I, T, P, _, _>::new(r, *tfar_io, std::hint::black_box(hit_io));
        let mut items = stack_storage();
        let mut stack = TraversalStack::new(&mut items);
        let mut cur = start;
        self.walk1::<I, _, C, SPECULATE, false>(&mut q, &mut cur, &mut stack, counter);
        *tfar_io = q.tfar;
    }

    /// Any-hit traversal of the subtree `start` in ISA `I` with triangle kernel `P` (which
    /// must be the kernel of `self.test`), visiting a node's hit children from the highest
    /// slot down (its leaves before its subtrees). `SPECULATE` as for
    /// [`Bvh8Ref::intersect1_from`].
    #[inline(always)]
    pub fn occluded1_from<I: IsaLanes, P: TriangleKernel, C: Counter, const SPECULATE: bool>(
        &self,
        r: &Ray1<I::F8>,
        start: NodeRef,
        counter: &mut C,
    ) -> bool {
        debug_assert_eq!(P::TEST, self.test, "kernel of the block layout");
        let mut q = Any::<I, T, P, _>::new(r);
        let mut items = stack_storage();
        let mut stack = TraversalStack::new(&mut items);
        let mut cur = start;
        // Without `IN_FLIGHT` the walk returns only with the answer.
        self.walk1::<I, _, C, SPECULATE, false>(&mut q, &mut cur, &mut stack, counter).unwrap_or(false)
    }

    /// Prefetches the children of `node` in the slots set in `rest` (from the lowest up), then
    /// the one in slot `i0`.
    #[inline(always)]
    fn prefetch_children(&self, node: &Bvh8Node, i0: usize, rest: u32) {
        let mut m = rest;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            self.prefetch(node.children[i]);
        }
        self.prefetch(node.children[i0]);
    }

    /// The closest hit in `leaf` nearer than `tfar` (which it shrinks), into `hit`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn intersect_leaf1<I: IsaLanes, P: TriangleKernel, C: Counter>(
        &self,
        leaf: NodeRef,
        r: &Ray1<I::F8>,
        pre: &P::Ray1<T::Lanes<I>>,
        tnear: T::Lanes<I>,
        tfar: &mut f32,
        hit: &mut Hit,
        counter: &mut C,
    ) {
        let range = leaf.blocks();
        counter.add(Work::Leaves, 1);
        counter.add(Work::Blocks, leaf.block_count() as u32);
        match leaf.kind() {
            LeafKind::Triangles => {
                for block in self.tris.blocks(range) {
                    let block: &T = block.borrow();
                    let h = P::block(block, pre, tnear, T::Lanes::<I>::splat(*tfar));
                    if let Some(lane) = h.closest() {
                        *tfar = h.t.lane(lane);
                        *hit = Hit { t: *tfar, u: h.u.lane(lane), v: h.v.lane(lane), prim: block.prim(lane) };
                    }
                }
            }
            LeafKind::Spheres => {
                // The ray through `black_box`, an optimisation barrier: without it the compiler
                // hoists the sphere test's constants (the origin, the direction, its square
                // length and `tnear` in four lanes) out of the traversal loop, and every ray
                // computes them also in scenes without spheres (PERFORMANCE.md, "Fewer
                // instructions per ray in small trees").
                let ray = std::hint::black_box(r.ray);
                for block in &self.spheres[range] {
                    let (m, t) = sphere_lanes(
                        &Vec3x::splat(ray.origin),
                        &Vec3x::splat(ray.dir),
                        I::F4::splat(ray.tnear),
                        I::F4::splat(*tfar),
                        &block.centers(),
                        I::F4::load(&block.radius),
                    );
                    for lane in crate::simd::bits(m.bitmask()) {
                        if t.lane(lane) <= *tfar {
                            *tfar = t.lane(lane);
                            *hit = Hit { t: *tfar, u: 0.0, v: 0.0, prim: block.prim[lane] };
                        }
                    }
                }
            }
        }
    }

    /// True when something in `leaf` blocks the ray `r` over `[tnear, tfar]` (`pre`, `tnear`,
    /// `tfar`: the triangle test's constants of `r` and its interval, in lanes).
    #[inline(always)]
    pub(crate) fn occluded_leaf1<I: IsaLanes, P: TriangleKernel, C: Counter>(
        &self,
        leaf: NodeRef,
        r: &Ray1<I::F8>,
        pre: &P::Ray1<T::Lanes<I>>,
        tnear: T::Lanes<I>,
        tfar: T::Lanes<I>,
        counter: &mut C,
    ) -> bool {
        let range = leaf.blocks();
        counter.add(Work::Leaves, 1);
        match leaf.kind() {
            LeafKind::Triangles => {
                for block in self.tris.blocks(range) {
                    counter.add(Work::Blocks, 1);
                    if P::block(block.borrow(), pre, tnear, tfar).mask != 0 {
                        return true;
                    }
                }
            }
            LeafKind::Spheres => {
                for block in &self.spheres[range] {
                    counter.add(Work::Blocks, 1);
                    let (m, _) = block.intersect1::<I::F4>(r.ray.origin, r.ray.dir, r.ray.tnear, r.ray.tfar);
                    if m != 0 {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// The closest-hit order when three or more children of `node` are hit (`i0` and `i1`, the
/// lowest two hit slots, and the others in `rest`, not empty; entry distances `d`): returns
/// the nearest slot, to descend to (of equal distances the last slot, where a stable sort by
/// decreasing distance would put it on top), and pushes the others onto `stack` sorted by
/// decreasing distance, so that the nearest pops first.
#[inline(always)]
fn push_all_but_nearest(
    node: &Bvh8Node,
    i0: usize,
    i1: usize,
    rest: u32,
    d: &[f32; 8],
    stack: &mut TraversalStack<'_, NearEntry>,
) -> usize {
    let mut near = if d[i1] <= d[i0] { i1 } else { i0 };
    let mut m = rest;
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        if d[i] <= d[near] {
            near = i;
        }
    }
    let base = stack.len();
    let mut m = (rest | 1 << i0 | 1 << i1) & !(1 << near);
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        stack.push(NearEntry { node: node.children[i], dist: d[i] });
    }
    stack.sort_from_by_decreasing_distance(base);
    near
}

/// The any-hit order: of the hit children `mask` (not empty) of `node`, returns the highest
/// slot (the one to descend to) and pushes the others onto `stack` from the lowest up, so
/// that they pop from the highest down: a node's leaves (its last slots) before its subtrees.
#[inline(always)]
fn push_below_highest(node: &Bvh8Node, mut mask: u32, stack: &mut TraversalStack<'_, NodeRef>) -> usize {
    let first = 31 - mask.leading_zeros() as usize;
    mask &= !(1 << first);
    while mask != 0 {
        let i = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        stack.push(node.children[i]);
    }
    first
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Sphere4;
    use crate::math::{Aabb, Vec3};
    use crate::simd::isa::{IsaOp, dispatch};

    /// The node and sphere-block tests of every ISA tier against their scalar twins.
    struct NodeAndSpheresMatchScalar;
    impl IsaOp for NodeAndSpheresMatchScalar {
        type Output = (u32, u32);
        #[inline(always)]
        fn run<I: IsaLanes>(self) -> (u32, u32) {
            let mut rng = crate::rng::Rng::new(5, 9);
            let mut r3 = move || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0;
            let (mut boxes_hit, mut spheres_hit) = (0, 0);
            for k in 0..4000 {
                let mut n = Bvh8Node::EMPTY;
                for i in 0..(k % 9) {
                    n.set_child(i, &Aabb::new(r3(), r3()), NodeRef::inner(i as u32));
                }
                let mut dir = r3();
                if k % 4 == 0 {
                    dir[k % 3] = if k % 8 == 0 { 0.0 } else { -0.0 };
                }
                // tnear 0, -0 (made +0 by `Ray1::new`), 0.25 and 0.5.
                let tnear = if k % 6 == 3 { -0.0 } else { (k % 3) as f32 * 0.25 };
                let ray = Ray::segment(r3() * 2.0, dir, tnear, if k % 5 == 0 { 2.0 } else { f32::INFINITY });
                if !ray.is_valid() {
                    continue;
                }
                let r = Ray1::<I::F8>::new(&ray);
                for tfar in [ray.tfar, 1.0f32.max(ray.tnear)] {
                    let (mask, _) = r.intersect_node(&n, tfar);
                    assert_eq!(mask, r.intersect_node_scalar(&n, tfar), "{}: {ray:?}", I::ISA);
                    boxes_hit += mask.count_ones();
                }
                let mut s = Sphere4::EMPTY;
                for i in 0..(k % 5) {
                    s.set(i, r3(), (k % 7) as f32 * 0.2, i as u32);
                }
                let (mask, t) = s.intersect1::<I::F4>(ray.origin, ray.dir, ray.tnear, ray.tfar);
                for (i, want) in s.intersect1_scalar(ray.origin, ray.dir, ray.tnear, ray.tfar).iter().enumerate() {
                    let got = (mask >> i & 1 != 0).then(|| t.lane(i));
                    assert_eq!(got.map(f32::to_bits), want.map(f32::to_bits), "{}: sphere {i} of {ray:?}", I::ISA);
                }
                spheres_hit += mask.count_ones();
            }
            (boxes_hit, spheres_hit)
        }
    }

    /// [`Ray1::try_new`]'s check and constants, in lanes, against [`Ray::is_valid`],
    /// [`crate::math::safe_recip3`] and the direction's signs, on rays whose floats are drawn
    /// from the edge cases (zeros of both signs, the smallest directions, the largest finite
    /// values, infinities, NaN, subnormals) as well as at random.
    struct RayConstantsMatchScalar;
    impl IsaOp for RayConstantsMatchScalar {
        type Output = (u32, u32);
        #[inline(always)]
        fn run<I: IsaLanes>(self) -> (u32, u32) {
            const EDGES: [f32; 16] = [
                0.0,
                -0.0,
                1e-19,
                -1e-19,
                Ray::MIN_DIRECTION,
                -Ray::MIN_DIRECTION,
                1e-40,
                1.5,
                -2.0,
                f32::MAX,
                -f32::MAX,
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::NAN,
                3.0,
                -0.75,
            ];
            let mut rng = crate::rng::Rng::new(7, 3);
            let (mut valid, mut invalid) = (0, 0);
            for _ in 0..20000 {
                let f: [f32; 8] = std::array::from_fn(|_| {
                    let k = (rng.next_f32() * 24.0) as usize;
                    if k < 16 { EDGES[k] } else { rng.next_f32() * 4.0 - 2.0 }
                });
                let ray = Ray::segment(Vec3::new(f[0], f[1], f[2]), Vec3::new(f[3], f[4], f[5]), f[6], f[7]);
                let got = Ray1::<I::F8>::try_new(&ray);
                assert_eq!(got.is_some(), ray.is_valid(), "{}: {ray:?}", I::ISA);
                let Some(r) = got else {
                    invalid += 1;
                    continue;
                };
                valid += 1;
                let inv = crate::math::safe_recip3(ray.dir);
                let lanes = |v: &Vec3x<I::F8>| [v.x.lane(7), v.y.lane(7), v.z.lane(7)].map(f32::to_bits);
                assert_eq!(lanes(&r.inv), inv.to_array().map(f32::to_bits), "{}: {ray:?}", I::ISA);
                assert_eq!(lanes(&r.inv_far), (inv * SLAB_WIDEN).to_array().map(f32::to_bits), "{}: {ray:?}", I::ISA);
                assert_eq!(lanes(&r.org), ray.origin.to_array().map(f32::to_bits), "{}: {ray:?}", I::ISA);
                let near =
                    [(inv.x < 0.0) as usize * 8, 16 + (inv.y < 0.0) as usize * 8, 32 + (inv.z < 0.0) as usize * 8];
                assert_eq!(r.near, near, "{}: {ray:?}", I::ISA);
                let tnear = (ray.tnear + 0.0).to_bits();
                assert_eq!((r.ray.tnear.to_bits(), r.tnear.lane(3).to_bits()), (tnear, tnear), "{}: {ray:?}", I::ISA);
                assert_eq!(r.ray.tfar.to_bits(), (ray.tfar + 0.0).to_bits(), "{}: {ray:?}", I::ISA);
                let n = Ray1::<I::F8>::new(&ray);
                assert_eq!((lanes(&n.inv), n.near), (lanes(&r.inv), r.near), "{}: {ray:?}", I::ISA);
            }
            (valid, invalid)
        }
    }

    #[test]
    fn ray_constants_in_lanes_match_the_scalar_ones_on_every_isa() {
        for isa in crate::simd::Isa::available() {
            let (valid, invalid) = dispatch(isa, RayConstantsMatchScalar);
            assert!(valid > 1000 && invalid > 1000, "{isa}: both kinds must occur ({valid} valid, {invalid} invalid)");
        }
    }

    #[test]
    fn node_and_sphere_tests_match_scalar_on_every_isa() {
        for isa in crate::simd::Isa::available() {
            let (boxes, spheres) = dispatch(isa, NodeAndSpheresMatchScalar);
            assert!(boxes > 300 && spheres > 50, "{isa}: the cases must hit ({boxes} boxes, {spheres} spheres)");
        }
    }
}
