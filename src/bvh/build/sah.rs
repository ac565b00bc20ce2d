//! The binned SAH build of a binary BVH.
//!
//! Centroids are binned into `bins` equal intervals per axis; the split minimising
//! `A_left N_left + A_right N_right` is taken when it beats making a leaf. When the binning
//! cannot separate the primitives (all centroids in one bin, or all equal), the builder
//! falls back to an object-median split so that no node ever keeps all its primitives on
//! one side (the classic infinite-recursion bug). Below [`MAX_DEPTH`]`- 40` it forces
//! median splits too, which bounds the depth of any tree.
//!
//! The build is deterministic and parallel: every subtree of `n` primitives owns a reserved
//! range of `2n - 1` node slots, so subtrees built on different threads never race for node
//! indices, and a final pass compacts the slots in depth-first order. Binning and
//! partitioning of large nodes run in parallel chunks of fixed sizes whose reductions
//! (min/max and integer counts) are exact, so the tree is bit-identical whatever the thread
//! count.

use super::binning::{Bin, Scratch, bin_mappings, bin_prims};
use super::partition::{median_split, partition, partition_node};
use super::spatial::{self, Splitter};
use super::{Box4, BuildOptions, BuildPrim, BuildQuality, MAX_BINS, PrimInfo, SplitMethod, pad_outward};
use crate::bvh::limits::MAX_DEPTH;
use crate::bvh::{Bvh2, Bvh2Node};
use crate::math::{Aabb, Vec3};

/// Subtrees with more primitives than this are built on another rayon task (smaller ones
/// were slower; PERFORMANCE.md, "Builder").
const PARALLEL_SUBTREE_THRESHOLD: usize = 1 << 14;
/// From this depth on the builder only does median splits, bounding the final depth.
const FORCE_MEDIAN_DEPTH: usize = MAX_DEPTH - 40;

/// Builds a binary BVH over `prims` (reordered in place). Primitive ids in the leaves refer
/// to `BuildPrim::id`. An empty input gives a tree with one empty leaf.
pub fn build_bvh2(prims: &mut [BuildPrim], opts: &BuildOptions) -> Bvh2 {
    build_bvh2_kinds(prims, opts, u32::MAX).0
}

/// [`build_bvh2`] for a mix of two primitive kinds: ids below `first_of_second_kind` are
/// the first kind (triangles), the rest the second (spheres). No leaf mixes the kinds: a
/// leaf that would is split into one leaf per kind under an inner node, so that leaf blocks,
/// which hold one kind, can be filled straight from the binary leaves.
///
/// Also returns the union of the primitives' boxes, exactly (the root's box is padded:
/// [`pad_outward`]), which the builder finds on its way ([`Aabb::EMPTY`] for no primitive).
pub fn build_bvh2_kinds(prims: &mut [BuildPrim], opts: &BuildOptions, first_of_second_kind: u32) -> (Bvh2, Aabb) {
    if prims.is_empty() {
        return (Bvh2 { nodes: compact(&[], 0, prims), prim_ids: Vec::new() }, Aabb::EMPTY);
    }
    let info = PrimInfo::of_par(prims);
    let (slots, leaves) = build_slots(prims, prims.len(), info, opts, first_of_second_kind, None);
    let nodes = compact(&slots, leaves, prims);
    (Bvh2 { nodes, prim_ids: prim_ids(prims) }, info.bounds.aabb())
}

/// [`build_bvh2_kinds`] with the spatial splits of [`spatial`]: where
/// triangles make the two sides of an object split overlap, the builder may cut them along a
/// plane instead, so that a triangle can be referenced by several leaves, each holding the
/// part of it inside its box. `triangle(id)` gives the corners of triangle `id` (ids below
/// `first_of_second_kind`); at most `budget * prims.len()` references are added (Embree
/// allows 0.2). No subtree of at most `opts.collapse.max_leaf_prims` references holds a
/// triangle twice, so no leaf of the collapsed tree does.
pub fn build_bvh2_spatial(
    mut prims: Vec<BuildPrim>,
    opts: &BuildOptions,
    first_of_second_kind: u32,
    budget: f32,
    triangle: &(dyn Fn(u32) -> [Vec3; 3] + Sync),
) -> (Bvh2, Aabb) {
    let n = prims.len();
    if n == 0 {
        return build_bvh2_kinds(&mut prims, opts, first_of_second_kind);
    }
    spatial::init_budgets(&mut prims, first_of_second_kind);
    let info = PrimInfo::of_par(&prims);
    let splitter = Splitter {
        triangle,
        first_sphere: first_of_second_kind,
        root_half_area: info.bounds.half_area(),
        min_refs: opts.collapse.max_leaf_prims.max(opts.max_leaf_size),
    };
    let extra = (f64::from(budget.max(0.0)) * n as f64) as usize;
    prims.reserve_exact(extra);
    crate::system::advise_huge_pages(&prims);
    prims.resize(n + extra, BuildPrim::new(Aabb::EMPTY, 0));
    let (mut slots, leaves) = build_slots(&mut prims, n, info, opts, first_of_second_kind, Some(&splitter));
    let prims = squeeze(&mut slots, &prims);
    let nodes = compact(&slots, leaves, &prims);
    (Bvh2 { nodes, prim_ids: prim_ids(&prims) }, info.bounds.aabb())
}

/// Gathers the references of the leaves of `slots` in depth-first order, left first,
/// leaving out the free space a spatial build did not use, and points each leaf at its new
/// range: afterwards every subtree's references are contiguous, as [`compact`] and the
/// collapse require.
fn squeeze(slots: &mut [Slot], prims: &[BuildPrim]) -> Vec<BuildPrim> {
    let mut out = crate::system::huge_page_vec(prims.len());
    let mut stack = vec![0usize];
    while let Some(s) = stack.pop() {
        let slot = slots[s];
        if slot.count & INNER == 0 {
            let (a, n) = (slot.a as usize, slot.count as usize);
            slots[s].a = out.len() as u32;
            out.extend_from_slice(&prims[a..a + n]);
        } else {
            stack.push(slot.a as usize);
            stack.push(s + 1);
        }
    }
    out
}

/// The primitives' ids in their final (leaf) order (in parallel: for large meshes the first
/// writes to fresh memory, page faults included, are a large part of the cost).
fn prim_ids(prims: &[BuildPrim]) -> Vec<u32> {
    use rayon::prelude::*;
    let mut ids = crate::system::huge_page_vec(prims.len());
    prims.par_iter().map(|p| p.id()).collect_into_vec(&mut ids);
    ids
}

/// A node in the reserved-range build array: a leaf's first primitive and count (`1 ..
/// INNER`), or an inner node's right child slot and `INNER |` the number of leaves below
/// its left child (its left child is the next slot), which tells [`compact`] where the
/// right subtree's nodes start so that it can renumber both subtrees in parallel. Boxes are
/// not stored: [`compact`] recomputes them from the primitives, which keeps the array, two
/// slots per primitive, at 8 bytes a slot (with boxes, 32: the largest allocation of the
/// build; PERFORMANCE.md, "Builder").
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Slot {
    a: u32,
    count: u32,
}

/// The flag of an inner [`Slot`]'s `count`.
const INNER: u32 = 1 << 31;

/// The binned SAH build into the reserved-range slots that [`compact`] renumbers, over the
/// first `n` (at least one) of `prims` (bounds `info`), the rest being free space for the
/// references spatial splits add (with `splitter`). Returns the slots and the number of
/// leaves.
fn build_slots(
    prims: &mut [BuildPrim],
    n: usize,
    info: PrimInfo,
    opts: &BuildOptions,
    first_of_second_kind: u32,
    splitter: Option<&Splitter>,
) -> (Vec<Slot>, usize) {
    // Reserved-range slots (see the module docs and `Slot`), two per reference the
    // subtree may end up holding. Zero-filled memory costs nothing until touched, and only
    // used slots are ever read.
    let mut slots: Vec<Slot> = bytemuck::zeroed_vec(2 * prims.len() - 1);
    crate::system::advise_huge_pages(&slots);
    let max_leaf = opts.max_leaf_size.clamp(1, INNER as usize - 1);
    // See `BuildQuality`: below High, every node of at most `max_leaf` primitives is a leaf.
    let leaf_at_most = if opts.quality == BuildQuality::High { 1 } else { max_leaf };
    let ctx = Ctx { opts, bins: opts.bin_count(), max_leaf, leaf_at_most, first_of_second_kind, splitter };
    let leaves = build_rec(&ctx, prims, n, 0, &mut slots, 0, info, 0, &mut Scratch::new());
    (slots, leaves)
}

struct Ctx<'a> {
    opts: &'a BuildOptions,
    bins: usize,
    max_leaf: usize,
    first_of_second_kind: u32,
    /// Nodes of at most this many primitives become leaves without weighing a split.
    leaf_at_most: usize,
    /// Present when spatial splits are allowed.
    splitter: Option<&'a Splitter<'a>>,
}

/// Builds the subtree over the first `n` of `prims` (which start at `first` in the global
/// array, and whose bounds are `info`; the rest of `prims` is free space for spatial splits)
/// into `slots`, whose slot 0 is the subtree root and whose global index is `base`; returns
/// the number of leaves.
#[allow(clippy::too_many_arguments)]
fn build_rec(
    ctx: &Ctx,
    prims: &mut [BuildPrim],
    n: usize,
    first: usize,
    slots: &mut [Slot],
    base: u32,
    info: PrimInfo,
    depth: usize,
    scratch: &mut Scratch,
) -> usize {
    debug_assert!(n >= 1 && n <= prims.len());
    debug_assert_eq!(slots.len(), 2 * prims.len() - 1);
    let split = if n <= ctx.leaf_at_most { None } else { choose_split(ctx, prims, n, &info, depth, scratch) };
    let Some((mid, total, li, ri)) = split else {
        return make_leaf(ctx, &mut prims[..n], first, slots, base);
    };
    debug_assert!(mid > 0 && mid < total && total <= prims.len());
    // The free space left goes to the children in proportion to their references: the right
    // child's move up to make room for the left one's share.
    let free = prims.len() - total;
    let left_free = (free as u64 * mid as u64 / total as u64) as usize;
    if left_free > 0 {
        prims.copy_within(mid..total, mid + left_free);
    }
    let (lp, rp) = prims.split_at_mut(mid + left_free);
    let (nl, nr) = (mid, total - mid);
    let cl = lp.len();
    let (_, rest) = slots.split_at_mut(1);
    let (ls, rs) = rest.split_at_mut(2 * cl - 1);
    let left = base + 1;
    let right = base + 2 * cl as u32;
    let (ll, rl) = if n > PARALLEL_SUBTREE_THRESHOLD {
        rayon::join(
            || build_rec(ctx, lp, nl, first, ls, left, li, depth + 1, scratch),
            || build_rec(ctx, rp, nr, first + cl, rs, right, ri, depth + 1, &mut Scratch::new()),
        )
    } else {
        (
            build_rec(ctx, lp, nl, first, ls, left, li, depth + 1, scratch),
            build_rec(ctx, rp, nr, first + cl, rs, right, ri, depth + 1, scratch),
        )
    };
    slots[0] = Slot { a: right, count: INNER | ll as u32 };
    ll + rl
}

/// Writes a leaf over `prims`, or, when they mix the two kinds, an inner node over one
/// leaf per kind (a subtree of `n >= 2` primitives has the 3 slots this needs); returns the
/// number of leaves.
fn make_leaf(ctx: &Ctx, prims: &mut [BuildPrim], first: usize, slots: &mut [Slot], base: u32) -> usize {
    let n = prims.len();
    let k = ctx.first_of_second_kind;
    let nl = partition(prims, |p| p.id() < k);
    if nl == 0 || nl == n {
        slots[0] = Slot { a: first as u32, count: n as u32 };
        return 1;
    }
    let right = 2 * nl;
    slots[0] = Slot { a: base + right as u32, count: INNER | 1 };
    slots[1] = Slot { a: first as u32, count: nl as u32 };
    slots[right] = Slot { a: (first + nl) as u32, count: (n - nl) as u32 };
    2
}

/// Chooses where to split the first `n` of `prims` and partitions them; returns the size of
/// the left part, the number of references after the split (more than `n` when a spatial
/// split cut some, their second parts taken from the free space after `n`) and both parts'
/// [`PrimInfo`], or `None` to make a leaf.
fn choose_split(
    ctx: &Ctx,
    all: &mut [BuildPrim],
    n: usize,
    info: &PrimInfo,
    depth: usize,
    scratch: &mut Scratch,
) -> Option<(usize, usize, PrimInfo, PrimInfo)> {
    let with_total = |(mid, li, ri)| (mid, n, li, ri);
    let prims = &mut all[..n];
    let cb = &info.centroids;
    let must_split = n > ctx.max_leaf;
    let ext = cb.extent();
    if ctx.opts.split == SplitMethod::Median || depth >= FORCE_MEDIAN_DEPTH || ext.cmple(Vec3::ZERO).all() {
        // (All centroids equal: no plane separates them.)
        return must_split.then(|| with_total(median_split(prims, cb)));
    }
    let k = bins_for(ctx, n);
    let maps = bin_mappings(cb, k);
    bin_prims(prims, &maps, k, &mut scratch.bins, &mut scratch.bins2);
    let mut best = (f32::INFINITY, 0usize, 0usize); // (cost, axis, split bin)
    for axis in (0..3).filter(|&a| ext[a] > 0.0) {
        let b = &scratch.bins[axis * MAX_BINS..axis * MAX_BINS + k];
        // Branch-free sweeps: the bins of small nodes are mostly empty, in no predictable
        // pattern. An empty bin's box is the identity of `union` (and has no area), and a
        // split with nothing on one side costs infinity.
        let (mut acc, mut cnt) = (Box4::EMPTY, 0u32);
        for i in (1..k).rev() {
            acc = acc.union(&b[i].bounds);
            cnt += b[i].count;
            scratch.right_area[i] = acc.half_area();
            scratch.right_count[i] = cnt;
        }
        let (mut acc, mut cnt) = (Box4::EMPTY, 0u32);
        #[allow(clippy::needless_range_loop)] // bins i and i + 1 of two arrays
        for i in 0..k - 1 {
            acc = acc.union(&b[i].bounds);
            cnt += b[i].count;
            let right = scratch.right_count[i + 1];
            let cost = acc.half_area() * cnt as f32 + scratch.right_area[i + 1] * right as f32;
            let cost = if cnt == 0 || right == 0 { f32::INFINITY } else { cost };
            if cost < best.0 {
                best = (cost, axis, i + 1);
            }
        }
    }
    if !best.0.is_finite() {
        // All centroids fell into one bin (extremely clustered data).
        return must_split.then(|| with_total(median_split(prims, cb)));
    }
    let area = info.bounds.half_area();
    if !must_split {
        let leaf_cost = n as f32;
        let split_cost = if area > 0.0 { ctx.opts.traversal_cost + best.0 / area } else { f32::INFINITY };
        if !(split_cost < leaf_cost) {
            return None;
        }
    }
    let (axis, split_bin) = (best.1, best.2);
    if let Some(sp) = ctx.splitter.filter(|sp| all.len() > n && n > sp.min_refs && must_split) {
        let b = &scratch.bins[axis * MAX_BINS..axis * MAX_BINS + k];
        let side = |bins: &[Bin]| bins.iter().fold(Box4::EMPTY, |acc, b| acc.union(&b.bounds)).aabb();
        let node = info.bounds.aabb();
        if spatial::worth_trying(sp, &node, &side(&b[..split_bin]), &side(&b[split_bin..]))
            && let Some(s) = spatial::find(sp, &all[..n], &node)
                .filter(|s| spatial::better(s.cost, best.0) && s.left + s.right <= all.len())
        {
            let total = spatial::split_refs(sp, all, n, s.axis, s.pos);
            let prims = &mut all[..total];
            let pos2 = 2.0 * s.pos;
            let mut split = partition_node(prims, |c2| c2[s.axis] < pos2);
            if split.0 == 0 || split.0 == total {
                split = median_split(prims, &PrimInfo::of(prims).centroids);
            }
            let (mid, li, ri) = split;
            return Some((mid, total, li, ri));
        }
    }
    let prims = &mut all[..n];
    let (lo, scale) = maps[axis];
    // `min(trunc(x), k-1) < s` is `x < s` for the integer `s <= k-1`: the same arithmetic
    // as binning, without the float-to-int conversion.
    let split = split_bin as f32;
    let (mid, li, ri) = partition_node(prims, |c2| (c2[axis] - lo) * scale < split);
    if mid == 0 || mid == n {
        // Cannot happen with exact arithmetic; guard against rounding anyway.
        return Some(with_total(median_split(prims, cb)));
    }
    Some((mid, n, li, ri))
}

/// The bins of a node of `n` primitives. Small nodes use fewer: at `High`, as many as they
/// have primitives (at least 8); otherwise Embree's rule, `4 + n / 20` (its `BinMapping`),
/// so that a node of 100 primitives sweeps 9 bins instead of 32.
//
// Embree's rule, against `min(bins, max(n, 8))` at Medium: faster commits for a tree of the
// same SAH cost within a percent and traversal within the noise (PERFORMANCE.md, "Builder").
#[inline]
fn bins_for(ctx: &Ctx, n: usize) -> usize {
    let k = match ctx.opts.quality {
        BuildQuality::High => n.max(8),
        BuildQuality::Fast | BuildQuality::Medium => 4 + n / 20,
    };
    ctx.bins.min(k)
}

/// Renumbers the reserved-range slots depth first so that siblings are adjacent (see
/// [`Slot`]), computing every box from the primitives (`prims`, in their final order) and
/// padding it with [`pad_outward`]. Large subtrees are renumbered in parallel: an inner
/// slot's left leaf count says where its right subtree's nodes start.
fn compact(slots: &[Slot], leaves: usize, prims: &[BuildPrim]) -> Vec<Bvh2Node> {
    if slots.is_empty() {
        // The empty tree: one leaf with `count == 0` and empty bounds.
        return vec![Bvh2Node { bounds: Aabb::EMPTY, start: 0, count: 0 }];
    }
    // Zero-filled fresh memory that the parallel renumbering, which writes every node once,
    // touches first (on a 20M-triangle mesh the page faults of the array are a second or
    // more). A binary tree has one inner node fewer than leaves.
    let mut nodes: Vec<Bvh2Node> = bytemuck::zeroed_vec(2 * leaves - 1);
    crate::system::advise_huge_pages(&nodes);
    let (root, rest) = nodes.split_first_mut().expect("a root");
    let (node, _, used) = compact_rec(slots, prims, 0, rest, 1);
    debug_assert_eq!(used, rest.len());
    *root = node;
    nodes
}

/// Subtrees of more slots than this are renumbered in parallel.
const PARALLEL_COMPACT_SLOTS: usize = 1 << 13;

/// Renumbers the subtree at slot `s`: returns its root node (which the caller stores), its
/// exact box and the number of nodes below the root, written to the front of `out`, whose
/// first node has global index `at` (children pairs first, then the left subtree's, then
/// the right's).
fn compact_rec(
    slots: &[Slot],
    prims: &[BuildPrim],
    s: usize,
    out: &mut [Bvh2Node],
    at: usize,
) -> (Bvh2Node, Box4, usize) {
    let slot = slots[s];
    if slot.count & INNER == 0 {
        let (a, n) = (slot.a as usize, slot.count as usize);
        let b = prims[a..a + n].iter().fold(Box4::EMPTY, |b, p| b.union(&Box4 { lower: p.lower, upper: p.upper }));
        return (Bvh2Node { bounds: pad_outward(&b.aabb()), start: slot.a, count: slot.count }, b, 0);
    }
    let right = slot.a as usize;
    let (pair, rest) = out.split_at_mut(2);
    // The left subtree has 2 * left_leaves - 1 nodes, its root in `pair`.
    let left_below = 2 * (slot.count & !INNER) as usize - 2;
    let (lo, ro) = rest.split_at_mut(left_below);
    let ((ln, lb, lu), (rn, rb, ru)) = if right - s > PARALLEL_COMPACT_SLOTS {
        rayon::join(
            || compact_rec(slots, prims, s + 1, lo, at + 2),
            || compact_rec(slots, prims, right, ro, at + 2 + left_below),
        )
    } else {
        (compact_rec(slots, prims, s + 1, lo, at + 2), compact_rec(slots, prims, right, ro, at + 2 + left_below))
    };
    debug_assert_eq!(lu, left_below);
    (pair[0], pair[1]) = (ln, rn);
    let b = lb.union(&rb);
    (Bvh2Node { bounds: pad_outward(&b.aabb()), start: at as u32, count: 0 }, b, 2 + lu + ru)
}
