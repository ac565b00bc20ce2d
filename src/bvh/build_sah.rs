//! Binned SAH construction of a binary BVH: Wald, "On fast Construction of SAH-based Bounding
//! Volume Hierarchies", IEEE Symposium on Interactive Ray Tracing 2007.
//!
//! Centroids are binned into `bins` equal intervals per axis; the split minimising
//! `A_left N_left + A_right N_right` is taken when it beats making a leaf. When the binning
//! cannot separate the primitives (all centroids in one bin, or all equal), the builder
//! falls back to an object-median split so that no node ever keeps all its primitives on
//! one side (the classic infinite-recursion bug). Below [`super::MAX_DEPTH`]`- 40` it forces
//! median splits too, which bounds the depth of any tree.
//!
//! The build is deterministic and parallel: every subtree of `n` primitives owns a reserved
//! range of `2n - 1` node slots, so subtrees built on different threads never race for node
//! indices, and a final pass compacts the slots in depth-first order. Binning of large nodes
//! runs in parallel chunks whose reduction (min/max and integer counts) is exact, so the
//! tree is bit-identical whatever the thread count.

use crate::bvh::{Bvh2, Bvh2Node, MAX_DEPTH};
use crate::math::{Aabb, Vec3, Vec3A};

/// How much effort the builder spends on tree quality.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BuildQuality {
    /// Fewer bins; for interactive use.
    Fast,
    /// The default trade-off.
    #[default]
    Medium,
    /// More bins; for final renders of large scenes.
    High,
}

/// The splitting rule.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SplitMethod {
    /// Binned surface area heuristic.
    #[default]
    Sah,
    /// Object median on the largest centroid axis (for comparison only).
    Median,
}

/// Parameters of the BVH build.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildOptions {
    /// Most primitives in a leaf (at least 1). Larger nodes are always split.
    pub max_leaf_size: usize,
    /// SAH bins per axis (clamped to `16 ..= 256`); `None` picks from `quality`.
    pub bins: Option<usize>,
    /// Effort knob.
    pub quality: BuildQuality,
    /// Split rule.
    pub split: SplitMethod,
    /// Cost of one traversal step relative to one primitive test.
    pub traversal_cost: f32,
    /// Use the watertight triangle test (Woop, Benthin, Wald 2013) instead of Möller–Trumbore.
    pub watertight: bool,
    /// How the binary tree is collapsed into the 8-wide BVH the kernels traverse (costs and
    /// leaf limits; see [`crate::bvh::CollapseOptions`]).
    pub collapse: crate::bvh::CollapseOptions,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            max_leaf_size: 4,
            bins: None,
            quality: BuildQuality::Medium,
            split: SplitMethod::Sah,
            traversal_cost: 1.0,
            watertight: false,
            collapse: crate::bvh::CollapseOptions::default(),
        }
    }
}

impl BuildOptions {
    /// The number of bins actually used.
    pub fn bin_count(&self) -> usize {
        let b = self.bins.unwrap_or(match self.quality {
            BuildQuality::Fast => 16,
            BuildQuality::Medium => 32,
            BuildQuality::High => 64,
        });
        b.clamp(16, MAX_BINS)
    }
}

const MAX_BINS: usize = 256;
/// Nodes with more primitives than this bin in parallel chunks.
const PARALLEL_BIN_THRESHOLD: usize = 1 << 16;
/// Subtrees with more primitives than this are built on another rayon task.
const PARALLEL_SUBTREE_THRESHOLD: usize = 4096;
/// From this depth on the builder only does median splits, bounding the final depth.
const FORCE_MEDIAN_DEPTH: usize = MAX_DEPTH - 40;

/// One primitive as the builder sees it: its bounds and its id. 28 bytes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildPrim {
    /// Bounds of the primitive (must be valid and finite).
    pub bounds: Aabb,
    /// The id stored in the leaf.
    pub id: u32,
}

impl BuildPrim {
    #[inline]
    fn centroid(&self) -> Vec3 {
        self.bounds.center()
    }
}

/// A node slot in the reserved-range build array.
#[derive(Clone, Copy, Debug)]
enum Slot {
    Unused,
    Leaf { bounds: Aabb, start: u32, count: u32 },
    Inner { bounds: Aabb, left: u32, right: u32 },
}

/// Builds a binary BVH over `prims` (reordered in place). Primitive ids in the leaves refer
/// to `BuildPrim::id`. An empty input gives a tree with one empty leaf.
pub fn build_bvh2(prims: &mut [BuildPrim], opts: &BuildOptions) -> Bvh2 {
    let n = prims.len();
    if n == 0 {
        return Bvh2 { nodes: vec![Bvh2Node { bounds: Aabb::EMPTY, start: 0, count: 0 }], prim_ids: Vec::new() };
    }
    let mut slots = vec![Slot::Unused; 2 * n - 1];
    let ctx = Ctx { opts, bins: opts.bin_count(), max_leaf: opts.max_leaf_size.max(1) };
    let bounds = union_bounds(prims);
    build_rec(&ctx, prims, 0, &mut slots, 0, bounds, 0, &mut Scratch::new());
    let prim_ids = prims.iter().map(|p| p.id).collect();
    Bvh2 { nodes: compact(&slots), prim_ids }
}

struct Ctx<'a> {
    opts: &'a BuildOptions,
    bins: usize,
    max_leaf: usize,
}

fn union_bounds(prims: &[BuildPrim]) -> Aabb {
    prims.iter().fold(Aabb::EMPTY, |b, p| b.union(&p.bounds))
}

fn centroid_bounds(prims: &[BuildPrim]) -> Aabb {
    let mut b = Aabb::EMPTY;
    for p in prims {
        b.grow(p.centroid());
    }
    b
}

/// Builds the subtree over `prims` (which start at `first` in the global array) into
/// `slots`, whose slot 0 is the subtree root and whose global index is `base`.
#[allow(clippy::too_many_arguments)]
fn build_rec(
    ctx: &Ctx,
    prims: &mut [BuildPrim],
    first: usize,
    slots: &mut [Slot],
    base: u32,
    bounds: Aabb,
    depth: usize,
    scratch: &mut Scratch,
) {
    let n = prims.len();
    debug_assert_eq!(slots.len(), 2 * n - 1);
    let leaf = Slot::Leaf { bounds, start: first as u32, count: n as u32 };
    if n == 1 {
        slots[0] = leaf;
        return;
    }
    let mid = match choose_split(ctx, prims, bounds, depth, scratch) {
        Some(mid) => mid,
        None => {
            slots[0] = leaf;
            return;
        }
    };
    debug_assert!(mid > 0 && mid < n);
    let (lp, rp) = prims.split_at_mut(mid);
    let (nl, nr) = (lp.len(), rp.len());
    let (_, rest) = slots.split_at_mut(1);
    let (ls, rs) = rest.split_at_mut(2 * nl - 1);
    let (lb, rb) = (union_bounds(lp), union_bounds(rp));
    let left = base + 1;
    let right = base + 2 * nl as u32;
    if n > PARALLEL_SUBTREE_THRESHOLD {
        rayon::join(
            || build_rec(ctx, lp, first, ls, left, lb, depth + 1, scratch),
            || build_rec(ctx, rp, first + nl, rs, right, rb, depth + 1, &mut Scratch::new()),
        );
    } else {
        build_rec(ctx, lp, first, ls, left, lb, depth + 1, scratch);
        build_rec(ctx, rp, first + nl, rs, right, rb, depth + 1, scratch);
    }
    debug_assert_eq!(rs.len(), 2 * nr - 1);
    slots[0] = Slot::Inner { bounds, left, right };
}

/// Chooses where to split `prims` and partitions them; returns the size of the left part,
/// or `None` to make a leaf.
fn choose_split(
    ctx: &Ctx,
    prims: &mut [BuildPrim],
    bounds: Aabb,
    depth: usize,
    scratch: &mut Scratch,
) -> Option<usize> {
    let n = prims.len();
    let cb = centroid_bounds(prims);
    let must_split = n > ctx.max_leaf;
    if ctx.opts.split == SplitMethod::Median || depth >= FORCE_MEDIAN_DEPTH {
        return must_split.then(|| median_split(prims, &cb));
    }
    let ext = cb.extent();
    if ext.cmple(Vec3::ZERO).all() {
        // Every centroid is the same point: no plane separates them.
        return must_split.then(|| median_split(prims, &cb));
    }
    // Small nodes use fewer bins: more bins than primitives only cost time.
    let k = ctx.bins.min(n.max(8));
    let maps: [(f32, f32); 3] =
        std::array::from_fn(|a| if ext[a] > 0.0 { bin_mapping(&cb, a, k) } else { (cb.min[a], 0.0) });
    bin_prims(prims, &maps, k, &mut scratch.bins);
    let mut best = (f32::INFINITY, 0usize, 0usize); // (cost, axis, split bin)
    for axis in (0..3).filter(|&a| ext[a] > 0.0) {
        let b = &scratch.bins[axis * MAX_BINS..axis * MAX_BINS + k];
        let (mut acc, mut cnt) = (Bin::EMPTY, 0u32);
        for i in (1..k).rev() {
            acc.union(&b[i]);
            cnt += b[i].count;
            scratch.right_area[i] = acc.half_area();
            scratch.right_count[i] = cnt;
        }
        let (mut acc, mut cnt) = (Bin::EMPTY, 0u32);
        for i in 0..k - 1 {
            acc.union(&b[i]);
            cnt += b[i].count;
            let right = scratch.right_count[i + 1];
            if cnt == 0 || right == 0 {
                continue;
            }
            let cost = acc.half_area() * cnt as f32 + scratch.right_area[i + 1] * right as f32;
            if cost < best.0 {
                best = (cost, axis, i + 1);
            }
        }
    }
    if !best.0.is_finite() {
        // All centroids fell into one bin (extremely clustered data).
        return must_split.then(|| median_split(prims, &cb));
    }
    let area = bounds.half_area();
    if !must_split {
        let leaf_cost = n as f32;
        let split_cost = if area > 0.0 { ctx.opts.traversal_cost + best.0 / area } else { f32::INFINITY };
        if !(split_cost < leaf_cost) {
            return None;
        }
    }
    let (axis, split_bin) = (best.1, best.2);
    let (lo, scale) = maps[axis];
    // `min(trunc(x), k-1) < s` is `x < s` for the integer `s <= k-1`: the same arithmetic
    // as binning, without the float-to-int conversion.
    let split = split_bin as f32;
    let mid = partition(prims, |p| (p.centroid()[axis] - lo) * scale < split);
    if mid == 0 || mid == n {
        // Cannot happen with exact arithmetic; guard against rounding anyway.
        return Some(median_split(prims, &cb));
    }
    Some(mid)
}

/// One SAH bin: bounds of the primitives in it (16-byte lanes so unions are two SIMD
/// min/max operations) and their count.
#[derive(Clone, Copy, Debug)]
struct Bin {
    min: Vec3A,
    max: Vec3A,
    count: u32,
}

impl Bin {
    const EMPTY: Bin = Bin { min: Vec3A::splat(f32::INFINITY), max: Vec3A::splat(f32::NEG_INFINITY), count: 0 };

    #[inline]
    fn union(&mut self, o: &Bin) {
        self.min = self.min.min(o.min);
        self.max = self.max.max(o.max);
    }

    #[inline]
    fn half_area(&self) -> f32 {
        let e = (self.max - self.min).max(Vec3A::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }
}

/// Per-task scratch memory of the builder, reused for every node the task splits (only the
/// first `k` bins of each axis are touched per node), so splitting allocates nothing.
struct Scratch {
    /// `3 * MAX_BINS` bins, axis-major.
    bins: Vec<Bin>,
    right_area: Vec<f32>,
    right_count: Vec<u32>,
}

impl Scratch {
    fn new() -> Self {
        Self { bins: vec![Bin::EMPTY; 3 * MAX_BINS], right_area: vec![0.0; MAX_BINS], right_count: vec![0; MAX_BINS] }
    }
}

#[inline]
fn bin_mapping(cb: &Aabb, axis: usize, k: usize) -> (f32, f32) {
    let ext = cb.extent()[axis];
    (cb.min[axis], k as f32 * (1.0 - 1e-6) / ext)
}

/// Fills the first `k` bins of each axis of `bins` with `prims`; large inputs bin in
/// parallel chunks whose exact reduction keeps the result independent of the thread count.
fn bin_prims(prims: &[BuildPrim], maps: &[(f32, f32); 3], k: usize, bins: &mut [Bin]) {
    use wide::f32x4;
    // All three axes' bin indices in one SIMD step; clamping in the float domain makes the
    // truncating conversion exact (and maps the unused fourth lane to bin 0).
    let lo = f32x4::new([maps[0].0, maps[1].0, maps[2].0, 0.0]);
    let scale = f32x4::new([maps[0].1, maps[1].1, maps[2].1, 0.0]);
    let top = f32x4::splat((k - 1) as f32);
    let bin_chunk = |chunk: &[BuildPrim], bins: &mut [Bin]| {
        for a in 0..3 {
            bins[a * MAX_BINS..a * MAX_BINS + k].fill(Bin::EMPTY);
        }
        for p in chunk {
            let (min, max) = (Vec3A::from(p.bounds.min), Vec3A::from(p.bounds.max));
            let c = (min + max) * 0.5;
            let c = f32x4::new([c.x, c.y, c.z, 0.0]);
            let idx = ((c - lo) * scale).min(top).max(f32x4::ZERO).fast_trunc_int().to_array();
            for a in 0..3 {
                let bin = &mut bins[a * MAX_BINS + idx[a] as usize];
                bin.min = bin.min.min(min);
                bin.max = bin.max.max(max);
                bin.count += 1;
            }
        }
    };
    if prims.len() < PARALLEL_BIN_THRESHOLD {
        return bin_chunk(prims, bins);
    }
    use rayon::prelude::*;
    let partial = prims
        .par_chunks(PARALLEL_BIN_THRESHOLD / 4)
        .map(|chunk| {
            let mut b = vec![Bin::EMPTY; 3 * MAX_BINS];
            bin_chunk(chunk, &mut b);
            b
        })
        .reduce_with(|mut a, b| {
            for axis in 0..3 {
                for i in axis * MAX_BINS..axis * MAX_BINS + k {
                    a[i].union(&b[i]);
                    a[i].count += b[i].count;
                }
            }
            a
        })
        .expect("non-empty");
    bins.copy_from_slice(&partial);
}

/// Object-median split on the largest centroid axis (by index when all centroids agree).
fn median_split(prims: &mut [BuildPrim], cb: &Aabb) -> usize {
    let mid = prims.len() / 2;
    let axis = cb.largest_axis();
    if cb.extent()[axis] > 0.0 {
        prims.select_nth_unstable_by(mid, |a, b| {
            a.centroid()[axis].total_cmp(&b.centroid()[axis]).then(a.id.cmp(&b.id))
        });
    }
    mid
}

/// Moves the elements satisfying `pred` to the front; returns how many there are.
fn partition(prims: &mut [BuildPrim], pred: impl Fn(&BuildPrim) -> bool) -> usize {
    let mut i = 0;
    let mut j = prims.len();
    while i < j {
        if pred(&prims[i]) {
            i += 1;
        } else {
            j -= 1;
            prims.swap(i, j);
        }
    }
    i
}

/// Relative padding of node bounds; see [`pad_outward`].
pub const BOUNDS_PADDING: f32 = 1.0 / (1 << 20) as f32;

/// Grows a node box outward by `BOUNDS_PADDING` times its largest coordinate magnitude or
/// extent. Without it, a ray travelling exactly in a box's boundary plane (a zero direction
/// component, origin on the plane) gets an empty slab interval even though the triangle test
/// hits the primitive on that plane — rays aimed straight at the shared edges of an
/// axis-aligned grid do exactly that. The padding is monotone, so children stay inside
/// their parents.
#[inline]
pub fn pad_outward(b: &Aabb) -> Aabb {
    if !b.is_valid() {
        return *b;
    }
    let scale = b.min.abs().max(b.max.abs()).max(b.extent()).max_element() * BOUNDS_PADDING;
    let scale = scale.max(f32::MIN_POSITIVE);
    Aabb { min: b.min - Vec3::splat(scale), max: b.max + Vec3::splat(scale) }
}

/// Renumbers the reserved-range slots depth first so that siblings are adjacent.
fn compact(slots: &[Slot]) -> Vec<Bvh2Node> {
    let used = slots.iter().filter(|s| !matches!(s, Slot::Unused)).count();
    let mut nodes = Vec::with_capacity(used);
    nodes.push(Bvh2Node { bounds: Aabb::EMPTY, start: 0, count: 0 });
    // (slot index, final index)
    let mut stack = vec![(0u32, 0u32)];
    while let Some((s, f)) = stack.pop() {
        match slots[s as usize] {
            Slot::Leaf { bounds, start, count } => {
                nodes[f as usize] = Bvh2Node { bounds: pad_outward(&bounds), start, count }
            }
            Slot::Inner { bounds, left, right } => {
                let c = nodes.len() as u32;
                nodes[f as usize] = Bvh2Node { bounds: pad_outward(&bounds), start: c, count: 0 };
                nodes.push(Bvh2Node { bounds: Aabb::EMPTY, start: 0, count: 0 });
                nodes.push(Bvh2Node { bounds: Aabb::EMPTY, start: 0, count: 0 });
                stack.push((right, c + 1));
                stack.push((left, c));
            }
            Slot::Unused => unreachable!("compaction only follows child links"),
        }
    }
    debug_assert_eq!(nodes.len(), used);
    nodes
}
