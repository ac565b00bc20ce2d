//! Binned SAH construction of a binary BVH: Wald, "On fast Construction of SAH-based Bounding
//! Volume Hierarchies", IEEE Symposium on Interactive Ray Tracing 2007.
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
//!
//! (One file past 600 lines: binning, split choice, partitioning and compaction are the steps
//! of one algorithm over the same primitive, bin and slot types, read top to bottom.)

use crate::bvh::limits::MAX_DEPTH;
use crate::bvh::spatial::{self, Splitter};
use crate::bvh::{Bvh2, Bvh2Node};
use crate::math::{Aabb, Vec3, Vec4};

/// How much effort the builder spends on tree quality.
///
/// Below `High`, every node of at most [`BuildOptions::max_leaf_size`] primitives is a leaf;
/// `High` also weighs splitting those by the SAH. The binary tree is an intermediate for the
/// 8-wide one, whose leaf blocks hold 8 triangles, so splitting such small nodes rarely
/// pays: on the Stanford dragon it moved the BVH8's SAH cost from 15.04 to 15.03 (2% more
/// blocks) for a fifth of the binary build's time (its nodes of at most 4 primitives are
/// more than half of all nodes, and each costs a full binning and sweep).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BuildQuality {
    /// Fewer bins; for interactive use.
    Fast,
    /// The default trade-off.
    #[default]
    Medium,
    /// More bins, small nodes split by the SAH, and spatial splits where triangles overlap
    /// ([`BuildOptions::spatial_split_budget`]); for final renders and large scenes traced
    /// many times.
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
    /// Most primitives in a leaf (at least 1). Larger nodes are always split; smaller ones
    /// are leaves below [`BuildQuality::High`].
    pub max_leaf_size: usize,
    /// SAH bins per axis of the largest nodes (clamped to `16 ..= 256`; smaller nodes use
    /// fewer, see [`BuildOptions::bin_count`]); `None` picks from `quality`.
    pub bins: Option<usize>,
    /// Effort knob.
    pub quality: BuildQuality,
    /// At [`BuildQuality::High`], the references spatial splits may add
    /// ([`crate::bvh::spatial`]), as a fraction of the primitives; 0 turns them off. Embree's
    /// high-quality builder allows 0.2; the default 0.5 is measured (PERFORMANCE.md, "Spatial
    /// splits").
    pub spatial_split_budget: f32,
    /// Split rule.
    pub split: SplitMethod,
    /// Cost of one traversal step relative to one primitive test.
    pub traversal_cost: f32,
    /// Use the watertight triangle test (Woop, Benthin, Wald 2013) instead of Möller–Trumbore.
    pub watertight: bool,
    /// How the binary tree is collapsed into the 8-wide BVH the kernels traverse (costs and
    /// leaf limits; see [`crate::bvh::CollapseOptions`]).
    pub collapse: crate::bvh::CollapseOptions,
    /// Keep the binary BVH after the collapse, for the scalar reference queries
    /// ([`crate::Scene::intersect1_reference`]) and its statistics. Off by default: the
    /// kernels only traverse the 8-wide BVH, and the binary one costs another 39 bytes per
    /// triangle (Stanford dragon: 34.1 MB beside the BVH8's 59.0 MB).
    pub keep_bvh2: bool,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            max_leaf_size: 4,
            bins: None,
            quality: BuildQuality::Medium,
            spatial_split_budget: 0.5,
            split: SplitMethod::Sah,
            traversal_cost: 1.0,
            watertight: false,
            collapse: crate::bvh::CollapseOptions::default(),
            keep_bvh2: false,
        }
    }
}

impl BuildOptions {
    /// The most bins per axis a node is binned into. Smaller nodes use fewer: `4 + n/20` for
    /// a node of `n` primitives below [`BuildQuality::High`] (Embree's rule), `max(n, 8)` at
    /// High.
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
/// Nodes with more primitives than this are partitioned in parallel
/// ([`partition_with_info_par`]), in chunks of `PARALLEL_PARTITION_CHUNK`.
const PARALLEL_PARTITION_THRESHOLD: usize = 1 << 18;
const PARALLEL_PARTITION_CHUNK: usize = 1 << 16;
/// Nodes of fewer primitives than this bin into one set of bins, not two ([`bin_prims`]).
const SMALL_NODE: usize = 32;
/// Subtrees with more primitives than this are built on another rayon task (4096 was
/// slower: dragon, 2 threads, medians of 10 runs 0.235–0.252 s against 0.214–0.227 s).
const PARALLEL_SUBTREE_THRESHOLD: usize = 1 << 14;
/// From this depth on the builder only does median splits, bounding the final depth.
const FORCE_MEDIAN_DEPTH: usize = MAX_DEPTH - 40;

/// One primitive as the builder sees it: its box and its id, as two 16-byte SIMD lanes
/// (`lower.w` holds the id's bits XOR `ID_BITS_BIAS`; `upper.w` is 0). 32 bytes, so two
/// fill a cache line.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct BuildPrim {
    lower: Vec4,
    upper: Vec4,
}
const _: () = assert!(std::mem::size_of::<BuildPrim>() == 32);

/// Makes the id's bits in `lower.w` a normal float (exponent 127 for ids below 2^23): the
/// builder's SIMD arithmetic also runs on the w lane, and a denormal there (a plain small
/// id) costs a microcode assist per operation (PERFORMANCE.md, "Builder").
const ID_BITS_BIAS: u32 = 0x3f80_0000;

impl BuildPrim {
    /// A primitive with box `bounds` (valid and finite) and id `id`.
    #[inline]
    pub fn new(bounds: Aabb, id: u32) -> Self {
        Self { lower: bounds.min.extend(f32::from_bits(id ^ ID_BITS_BIAS)), upper: bounds.max.extend(0.0) }
    }

    /// The id stored in the leaf.
    #[inline]
    pub fn id(&self) -> u32 {
        self.lower.w.to_bits() ^ ID_BITS_BIAS
    }

    /// A reference to primitive `id` with box `bounds` that may be cut `budget` more times
    /// ([`crate::bvh::spatial`]).
    #[inline]
    pub(super) fn with_budget(bounds: Aabb, id: u32, budget: u32) -> Self {
        let mut p = Self::new(bounds, id);
        p.set_budget(budget);
        p
    }

    /// How many more times spatial splits may cut this reference (held in `upper.w` as a
    /// small whole float; 0 for a plain build).
    #[inline]
    pub(super) fn budget(&self) -> u32 {
        self.upper.w as u32
    }

    #[inline]
    pub(super) fn set_budget(&mut self, budget: u32) {
        self.upper.w = budget as f32;
    }

    /// The primitive's box.
    #[inline]
    pub fn bounds(&self) -> Aabb {
        Aabb { min: self.lower.truncate(), max: self.upper.truncate() }
    }

    /// Twice the centroid (the builder bins `lower + upper`, saving a multiply; the w lane
    /// is meaningless).
    #[inline]
    fn centroid2(&self) -> Vec4 {
        self.lower + self.upper
    }
}

/// A box in SIMD lanes (the w lanes are meaningless).
#[derive(Clone, Copy, Debug)]
struct Box4 {
    lower: Vec4,
    upper: Vec4,
}

impl Box4 {
    const EMPTY: Box4 = Box4 { lower: Vec4::splat(f32::INFINITY), upper: Vec4::splat(f32::NEG_INFINITY) };

    #[inline]
    fn grow(&mut self, lower: Vec4, upper: Vec4) {
        self.lower = self.lower.min(lower);
        self.upper = self.upper.max(upper);
    }

    #[inline]
    fn union(&self, o: &Box4) -> Box4 {
        Box4 { lower: self.lower.min(o.lower), upper: self.upper.max(o.upper) }
    }

    #[inline]
    fn extent(&self) -> Vec3 {
        (self.upper - self.lower).truncate()
    }

    #[inline]
    fn half_area(&self) -> f32 {
        let e = self.extent().max(Vec3::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }

    fn aabb(&self) -> Aabb {
        Aabb { min: self.lower.truncate(), max: self.upper.truncate() }
    }
}

/// What a node's builder knows of its primitives before splitting them: their bounds and
/// the bounds of their doubled centroids. Splitting computes both children's right after
/// partitioning, while the primitives are in cache.
#[derive(Clone, Copy, Debug)]
struct PrimInfo {
    bounds: Box4,
    centroids: Box4,
}

impl PrimInfo {
    const EMPTY: PrimInfo = PrimInfo { bounds: Box4::EMPTY, centroids: Box4::EMPTY };

    #[inline]
    fn add(&mut self, p: &BuildPrim, c2: Vec4) {
        self.bounds.grow(p.lower, p.upper);
        self.centroids.grow(c2, c2);
    }

    fn merge(&self, o: &PrimInfo) -> PrimInfo {
        PrimInfo { bounds: self.bounds.union(&o.bounds), centroids: self.centroids.union(&o.centroids) }
    }

    fn of(prims: &[BuildPrim]) -> PrimInfo {
        let mut info = PrimInfo::EMPTY;
        for p in prims {
            info.add(p, p.centroid2());
        }
        info
    }

    /// [`PrimInfo::of`] in parallel chunks (min/max reductions are exact, so the result does
    /// not depend on the thread count).
    fn of_par(prims: &[BuildPrim]) -> PrimInfo {
        use rayon::prelude::*;
        prims.par_chunks(PARALLEL_BIN_THRESHOLD / 4).map(PrimInfo::of).reduce(|| PrimInfo::EMPTY, |a, b| a.merge(&b))
    }
}

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

/// [`build_bvh2_kinds`] with the spatial splits of [`crate::bvh::spatial`]: where
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
/// slots per primitive, at 8 bytes a slot (with boxes it was 32, and the largest
/// allocation of the build: 56 MB of its 118 MB peak on the Stanford dragon).
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

/// One SAH bin: bounds of the primitives in it and their count.
#[derive(Clone, Copy, Debug)]
struct Bin {
    bounds: Box4,
    count: u32,
}

impl Bin {
    const EMPTY: Bin = Bin { bounds: Box4::EMPTY, count: 0 };

    #[inline(always)]
    fn add(&mut self, p: &BuildPrim) {
        self.bounds.grow(p.lower, p.upper);
        self.count += 1;
    }
}

/// Adds the first `k` bins of each axis of `from` to those of `into` (exact: unions and sums).
fn merge_bins(into: &mut [Bin], from: &[Bin], k: usize) {
    for axis in 0..3 {
        for i in axis * MAX_BINS..axis * MAX_BINS + k {
            into[i].bounds = into[i].bounds.union(&from[i].bounds);
            into[i].count += from[i].count;
        }
    }
}

/// Per-task scratch memory of the builder, reused for every node the task splits (only the
/// first `k` bins of each axis are touched per node), so splitting allocates nothing.
struct Scratch {
    /// `3 * MAX_BINS` bins, axis-major.
    bins: Vec<Bin>,
    /// A second set of bins: odd primitives bin here (see [`bin_prims`]).
    bins2: Vec<Bin>,
    right_area: Vec<f32>,
    right_count: Vec<u32>,
}

impl Scratch {
    fn new() -> Self {
        Self {
            bins: vec![Bin::EMPTY; 3 * MAX_BINS],
            bins2: vec![Bin::EMPTY; 3 * MAX_BINS],
            right_area: vec![0.0; MAX_BINS],
            right_count: vec![0; MAX_BINS],
        }
    }
}

/// The bins of a node of `n` primitives. Small nodes use fewer: at `High`, as many as they
/// have primitives (at least 8); otherwise Embree's rule, `4 + n / 20` (its `BinMapping`),
/// so that a node of 100 primitives sweeps 9 bins instead of 32.
//
// Embree's rule against `min(bins, max(n, 8))` at Medium, Intel Xeon (model 167), AVX-512:
// the Stanford dragon's commit (`examples`-style loop of 9 builds, medians) 0.355 / 0.357 s
// → 0.320 / 0.320 s on one CPU, 0.186 / 0.194 → 0.166 / 0.171 s on two; SAH cost 15.04 →
// 15.13 (dragon), 3.47 → 3.50 (CS184 building), 6.68 → 6.74 (beetle), 4.97 → 4.96
// (CBbunny); `raypack bench` streams and single rays on those four scenes within the noise
// of three interleaved runs (±2%).
#[inline]
fn bins_for(ctx: &Ctx, n: usize) -> usize {
    let k = match ctx.opts.quality {
        BuildQuality::High => n.max(8),
        BuildQuality::Fast | BuildQuality::Medium => 4 + n / 20,
    };
    ctx.bins.min(k)
}

/// Maps doubled centroids on `axis` to `[0, k)`: `(c2 - lo) * scale`.
#[inline]
fn bin_mapping(cb: &Box4, axis: usize, k: usize) -> (f32, f32) {
    let ext = cb.extent()[axis];
    (cb.lower[axis], k as f32 * (1.0 - 1e-6) / ext)
}

/// [`bin_mapping`] of each axis of `cb` with an extent; the others map every centroid to bin 0.
#[inline]
fn bin_mappings(cb: &Box4, k: usize) -> [(f32, f32); 3] {
    let ext = cb.extent();
    std::array::from_fn(|a| if ext[a] > 0.0 { bin_mapping(cb, a, k) } else { (cb.lower[a], 0.0) })
}

/// Fills the first `k` bins of each axis of `bins` with `prims`; large inputs bin in
/// parallel chunks whose exact reduction keeps the result independent of the thread count.
fn bin_prims(prims: &[BuildPrim], maps: &[(f32, f32); 3], k: usize, bins: &mut [Bin], bins2: &mut [Bin]) {
    use wide::f32x4;
    // All three axes' bin indices in one SIMD step (one truncating conversion for the four
    // lanes); clamping in the float domain makes it exact and maps the unused fourth lane
    // to bin 0.
    let lo = f32x4::new([maps[0].0, maps[1].0, maps[2].0, 0.0]);
    let scale = f32x4::new([maps[0].1, maps[1].1, maps[2].1, 0.0]);
    let top = f32x4::splat((k - 1) as f32);
    // `fast_min`/`fast_max` (one instruction each; a NaN lane would take `top`, still a bin)
    // rather than the NaN-propagating forms: 3% of a commit on one CPU (2M knot 0.670-0.687
    // -> 0.648-0.665 s, dragon 0.305-0.313 -> 0.295-0.303 s, Intel Xeon model 167).
    let index = |p: &BuildPrim| {
        let c: f32x4 = bytemuck::cast(p.centroid2());
        ((c - lo) * scale).fast_min(top).fast_max(f32x4::ZERO).fast_trunc_int().to_array()
    };
    // Even and odd primitives go to two sets of bins, merged at the end: neighbours in a
    // mesh mostly fall into the same bins, and one set would chain every update to the
    // previous one through memory. (Unions and sums are exact, so the bins are the same.)
    // Nodes of fewer than SMALL_NODE primitives, the most numerous by far, use one set: for
    // them clearing and merging the second set costs more than the chain.
    let bin_chunk = |chunk: &[BuildPrim], bins: &mut [Bin], bins2: &mut [Bin]| {
        // As arrays, and with indices masked to `MAX_BINS - 1` (a no-op after the clamp),
        // the compiler sees every index in range and drops the bounds checks.
        let bins: &mut [Bin; 3 * MAX_BINS] = bins.try_into().expect("3 * MAX_BINS bins");
        let bins2: &mut [Bin; 3 * MAX_BINS] = bins2.try_into().expect("3 * MAX_BINS bins");
        // Primitive `p` into bin `idx[a]` of each axis `a` of `bins`.
        let add = |bins: &mut [Bin; 3 * MAX_BINS], idx: [i32; 4], p: &BuildPrim| {
            for a in 0..3 {
                bins[a * MAX_BINS + (idx[a] as usize & (MAX_BINS - 1))].add(p);
            }
        };
        for a in 0..3 {
            bins[a * MAX_BINS..a * MAX_BINS + k].fill(Bin::EMPTY);
        }
        if chunk.len() < SMALL_NODE {
            for p in chunk {
                add(bins, index(p), p);
            }
            return;
        }
        for a in 0..3 {
            bins2[a * MAX_BINS..a * MAX_BINS + k].fill(Bin::EMPTY);
        }
        let mut pairs = chunk.chunks_exact(2);
        for pair in &mut pairs {
            let (p, q) = (&pair[0], &pair[1]);
            let (ip, iq) = (index(p), index(q));
            add(bins, ip, p);
            add(bins2, iq, q);
        }
        for p in pairs.remainder() {
            add(bins, index(p), p);
        }
        merge_bins(bins, bins2, k);
    };
    if prims.len() < PARALLEL_BIN_THRESHOLD {
        return bin_chunk(prims, bins, bins2);
    }
    use rayon::prelude::*;
    let partial = prims
        .par_chunks(PARALLEL_BIN_THRESHOLD / 4)
        .map(|chunk| {
            let (mut b, mut b2) = (vec![Bin::EMPTY; 3 * MAX_BINS], vec![Bin::EMPTY; 3 * MAX_BINS]);
            bin_chunk(chunk, &mut b, &mut b2);
            b
        })
        .reduce_with(|mut a, b| {
            merge_bins(&mut a, &b, k);
            a
        })
        .expect("non-empty");
    bins.copy_from_slice(&partial);
}

/// Object-median split on the largest centroid axis (by id when centroids tie), with both
/// halves' [`PrimInfo`].
fn median_split(prims: &mut [BuildPrim], cb: &Box4) -> (usize, PrimInfo, PrimInfo) {
    let mid = prims.len() / 2;
    let axis = cb.aabb().largest_axis();
    if cb.extent()[axis] > 0.0 {
        prims.select_nth_unstable_by(mid, |a, b| {
            a.centroid2()[axis].total_cmp(&b.centroid2()[axis]).then(a.id().cmp(&b.id()))
        });
    }
    with_infos(prims, mid)
}

/// `mid` with the [`PrimInfo`] of `prims[..mid]` and of `prims[mid..]`.
#[inline]
fn with_infos(prims: &[BuildPrim], mid: usize) -> (usize, PrimInfo, PrimInfo) {
    let (l, r) = prims.split_at(mid);
    (mid, PrimInfo::of(l), PrimInfo::of(r))
}

/// Moves the primitives whose doubled centroid satisfies `left` to the front, and finds both
/// sides' [`PrimInfo`]; returns how many went left. Large nodes are partitioned in parallel.
fn partition_node(prims: &mut [BuildPrim], left: impl Fn(Vec4) -> bool + Sync) -> (usize, PrimInfo, PrimInfo) {
    if prims.len() > PARALLEL_PARTITION_THRESHOLD {
        partition_with_info_par(prims, left, PARALLEL_PARTITION_CHUNK)
    } else {
        partition_with_info(prims, left)
    }
}

/// [`partition_node`] on one thread: [`partition_blocks`], each side's infos gathered from
/// its blocks as they are finished, while they are in cache.
//
// The branchy one-pass partition that gathered the infos as it went mispredicted on every
// other primitive of a mixed node. Blocks, then the infos in a second pass over the (cached)
// primitives: Stanford dragon Medium commit on one CPU (`taskset -c 0 raypack bench
// --build-runs 7`, three interleaved rounds, medians) 0.334 / 0.338 / 0.318 s -> 0.302 /
// 0.306 / 0.298 s, AMD EPYC Zen 4. Gathering the infos in the classifying loop without
// branches (a select per lane) was slower than either: 0.341 / 0.352 / 0.351 s. Blocks of
// 16, 32 or 128: the same as 64. The infos of each finished block instead of the second
// pass, which for nodes larger than the caches was one more pass over memory: the 2M knot's
// partitions of nodes above 2^18 primitives, summed over 6 builds on 2 threads (Intel Xeon
// model 207, a timer around this call, three rounds) 356 / 351 / 322 ms -> 271 / 268 / 268 ms.
#[inline]
fn partition_with_info(prims: &mut [BuildPrim], left: impl Fn(Vec4) -> bool) -> (usize, PrimInfo, PrimInfo) {
    let (mut li, mut ri) = (PrimInfo::EMPTY, PrimInfo::EMPTY);
    let finished = |done: &[BuildPrim], on_left: bool| {
        let info = if on_left { &mut li } else { &mut ri };
        for p in done {
            info.add(p, p.centroid2());
        }
    };
    let mid = partition_blocks(prims, |p| left(p.centroid2()), finished);
    (mid, li, ri)
}

/// [`partition_node`] in parallel: fixed chunks of `chunk` primitives are partitioned on
/// their own ([`partition_with_info`]), then the chunks' right parts that lie before the
/// final boundary trade places with their left parts that lie after it, in pieces swapped in
/// parallel. The chunks do not depend on the thread count, so neither does the order of
/// the primitives.
//
// The 2M knot's root partition on 2 threads (Intel Xeon model 207): 17-20 ms -> 9 ms; its
// binary build (`build_slots`), summed over 6 builds, three rounds, 2226 / 2210 / 1880 ms
// before both changes, 2146 / 2149 / 2129 ms with the fused infos, 1976 / 2032 / 1919 ms with
// this too. (Round-robin commits against Embree MEDIUM could not tell the 3%: ratios 0.97-1.04
// before and 0.98-1.04 after, four rounds.)
fn partition_with_info_par(
    prims: &mut [BuildPrim],
    left: impl Fn(Vec4) -> bool + Sync,
    chunk: usize,
) -> (usize, PrimInfo, PrimInfo) {
    use rayon::prelude::*;
    let parts: Vec<(usize, PrimInfo, PrimInfo)> =
        prims.par_chunks_mut(chunk).map(|c| partition_with_info(c, &left)).collect();
    let mid: usize = parts.iter().map(|p| p.0).sum();
    let (li, ri) = parts.iter().fold((PrimInfo::EMPTY, PrimInfo::EMPTY), |(l, r), p| (l.merge(&p.1), r.merge(&p.2)));
    // The misplaced ranges, in increasing order: right-side primitives before `mid`, and
    // left-side ones from `mid` on (counted from `mid`). Both lists hold as many primitives.
    let (mut wrong_left, mut wrong_right) = (Vec::new(), Vec::new());
    for (c, p) in parts.iter().enumerate() {
        let start = c * chunk;
        let (split, end) = (start + p.0, (start + chunk).min(prims.len()));
        if split < mid {
            wrong_left.push(split..end.min(mid));
        }
        if split > mid {
            wrong_right.push(start.max(mid) - mid..split - mid);
        }
    }
    // Pairs of equal-length pieces (at most SWAP_PIECE, for balance), cut from both sides
    // in increasing order so that every piece is a disjoint slice.
    const SWAP_PIECE: usize = 1 << 14;
    let (mut before, mut after) = prims.split_at_mut(mid);
    let (mut before_at, mut after_at) = (0, 0);
    let mut swaps: Vec<(&mut [BuildPrim], &mut [BuildPrim])> = Vec::new();
    let (mut a, mut b) = (wrong_left.into_iter().peekable(), wrong_right.into_iter().peekable());
    while let (Some(ra), Some(rb)) = (a.peek_mut(), b.peek_mut()) {
        let len = ra.len().min(rb.len()).min(SWAP_PIECE);
        let (x, rest) = std::mem::take(&mut before)[ra.start - before_at..].split_at_mut(len);
        (before, before_at) = (rest, ra.start + len);
        let (y, rest) = std::mem::take(&mut after)[rb.start - after_at..].split_at_mut(len);
        (after, after_at) = (rest, rb.start + len);
        swaps.push((x, y));
        ra.start += len;
        rb.start += len;
        if ra.start == ra.end {
            a.next();
        }
        if rb.start == rb.end {
            b.next();
        }
    }
    swaps.into_par_iter().for_each(|(x, y)| x.swap_with_slice(y));
    (mid, li, ri)
}

/// [`partition`] in blocks, as BlockQuicksort does (Edelkamp and Weiß, "BlockQuicksort:
/// Avoiding Branch Mispredictions in Quicksort", ESA 2016): a block at each end is
/// classified without branches, recording where the elements on the wrong side are, and
/// those are then swapped pairwise. Whatever is left between the blocks (all of a node of
/// fewer than two blocks) is partitioned by [`partition_lomuto`], also without branches.
/// `finished(slice, on_left)` sees every primitive once, in slices that are already on
/// their final side.
#[inline]
fn partition_blocks(
    prims: &mut [BuildPrim],
    pred: impl Fn(&BuildPrim) -> bool,
    mut finished: impl FnMut(&[BuildPrim], bool),
) -> usize {
    const BLOCK: usize = 64;
    let (mut l, mut r) = (0, prims.len());
    // Offsets into the left block `[l, l + BLOCK)` of elements that belong right, and into
    // the right block `[r - BLOCK, r)` (counted from its end) of elements that belong left;
    // `off_l[sl..nl]` and `off_r[sr..nr]` are those not swapped yet.
    let (mut off_l, mut off_r) = ([0u8; BLOCK], [0u8; BLOCK]);
    let (mut sl, mut nl, mut sr, mut nr) = (0, 0, 0, 0);
    // Invariant: `[0, l)` all satisfy `pred`, `[r, len)` none does.
    while r - l >= 2 * BLOCK {
        if sl == nl {
            (sl, nl) = (0, 0);
            for (i, p) in prims[l..l + BLOCK].iter().enumerate() {
                off_l[nl] = i as u8;
                nl += !pred(p) as usize;
            }
        }
        if sr == nr {
            (sr, nr) = (0, 0);
            for (i, p) in prims[r - BLOCK..r].iter().rev().enumerate() {
                off_r[nr] = i as u8;
                nr += pred(p) as usize;
            }
        }
        let m = (nl - sl).min(nr - sr);
        for k in 0..m {
            prims.swap(l + off_l[sl + k] as usize, r - 1 - off_r[sr + k] as usize);
        }
        (sl, sr) = (sl + m, sr + m);
        if sl == nl {
            finished(&prims[l..l + BLOCK], true);
            l += BLOCK;
        }
        if sr == nr {
            finished(&prims[r - BLOCK..r], false);
            r -= BLOCK;
        }
    }
    // A block with unswapped elements stays inside `[l, r)`, fewer than 2 * BLOCK
    // elements: finish them without branches too.
    let m = partition_lomuto(&mut prims[l..r], pred);
    finished(&prims[l..l + m], true);
    finished(&prims[l + m..r], false);
    l + m
}

/// [`partition`] without data-dependent branches: Lomuto's scheme, each element swapped
/// with the first one of the right side whether it goes left or not (a swap with itself or
/// with another right-side element changes nothing that matters), the boundary moved by the
/// predicate. One swap per element, against a mispredicted branch for every other element
/// of a mixed run in the plain partition.
//
// Small nodes are most of a build's nodes: with this (and one set of bins below SMALL_NODE)
// splitting a node of 5-8 primitives took 375 instead of 545 cycles, of 9-16 470 instead of
// 770, of 17-64 910 instead of 1405, of 65-1024 4310 instead of 4900 (2M knot, one CPU,
// rdtsc around `choose_split`). Whole commits: PERFORMANCE.md, "Builder time against Embree".
#[inline]
fn partition_lomuto(prims: &mut [BuildPrim], pred: impl Fn(&BuildPrim) -> bool) -> usize {
    let mut j = 0;
    for i in 0..prims.len() {
        let go = pred(&prims[i]);
        prims.swap(i, j);
        j += go as usize;
    }
    j
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn bins_hold_every_primitive_whatever_the_node_size() {
        // Small nodes bin into one set of bins, larger ones into two that are merged: either
        // way each bin holds exactly the primitives whose centroid falls in it.
        let mut rng = Rng::new(3, 8);
        let mut r3 = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 10.0 - 5.0;
        let mut scratch = Scratch::new();
        for len in (1..80).chain([200, 1000]) {
            let prims: Vec<BuildPrim> = (0..len as u32)
                .map(|id| {
                    let c = r3();
                    BuildPrim::new(Aabb::new(c - r3().abs() * 0.1, c + r3().abs() * 0.1), id)
                })
                .collect();
            let cb = PrimInfo::of(&prims).centroids;
            let k = 4 + len / 20;
            let maps = bin_mappings(&cb, k);
            bin_prims(&prims, &maps, k, &mut scratch.bins, &mut scratch.bins2);
            for (a, &(lo, scale)) in maps.iter().enumerate() {
                let mut want = vec![Bin::EMPTY; k];
                for p in &prims {
                    let x = ((p.centroid2()[a] - lo) * scale).clamp(0.0, (k - 1) as f32) as usize;
                    want[x].add(p);
                }
                for (i, w) in want.iter().enumerate() {
                    let got = &scratch.bins[a * MAX_BINS + i];
                    assert_eq!(got.count, w.count, "len {len} axis {a} bin {i}");
                    if w.count > 0 {
                        assert_eq!(got.bounds.aabb(), w.bounds.aabb(), "len {len} axis {a} bin {i}");
                    }
                }
            }
        }
    }

    #[test]
    fn parallel_partition_splits_like_the_serial_one() {
        // Chunks of 64 (instead of 65536) so that small inputs have many chunks, partial last
        // chunks, chunks all on one side and boundaries inside or between chunks.
        let mut rng = Rng::new(7, 11);
        for len in (1..200).chain([640, 1000, 4097, 20000]) {
            let mut prims: Vec<BuildPrim> = (0..len as u32)
                .map(|id| {
                    let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                    BuildPrim::new(Aabb::new(c, c + Vec3::splat(rng.next_f32() * 0.01)), id)
                })
                .collect();
            let mut serial = prims.clone();
            let cut = 2.0 * rng.next_f32();
            let left = |c2: Vec4| c2.x < cut;
            let (mid, li, ri) = partition_with_info_par(&mut prims, left, 64);
            let (want, wl, wr) = partition_with_info(&mut serial, left);
            assert_eq!(mid, want, "len {len}");
            assert!(prims[..mid].iter().all(|p| left(p.centroid2())), "len {len}");
            assert!(!prims[mid..].iter().any(|p| left(p.centroid2())), "len {len}");
            let mut ids: Vec<u32> = prims.iter().map(|p| p.id()).collect();
            ids.sort_unstable();
            assert_eq!(ids, (0..len as u32).collect::<Vec<_>>(), "len {len}");
            for (got, want) in [(li, wl), (ri, wr)] {
                assert_eq!(got.bounds.aabb(), want.bounds.aabb(), "len {len}");
                assert_eq!(got.centroids.aabb(), want.centroids.aabb(), "len {len}");
            }
        }
    }

    #[test]
    fn block_partition_splits_like_the_plain_one() {
        // Below two blocks (128 elements) this is `partition_lomuto` alone; above, the
        // blocks and then `partition_lomuto` on the rest.
        let mut rng = Rng::new(5, 9);
        for len in (0..300).chain([511, 512, 513, 1000, 4099]) {
            // Runs of each side of random lengths, and uniformly mixed sides.
            for runs in [false, true] {
                let mut left = rng.next_f32() < 0.5;
                let mut prims: Vec<BuildPrim> = (0..len as u32)
                    .map(|id| {
                        left = if runs { left ^ (rng.next_f32() < 0.1) } else { rng.next_f32() < 0.5 };
                        let x = if left { -1.0 } else { 1.0 };
                        BuildPrim::new(Aabb::new(Vec3::new(x, 0.0, 0.0), Vec3::new(x, 1.0, 1.0)), id)
                    })
                    .collect();
                let mut plain = prims.clone();
                let pred = |p: &BuildPrim| p.lower.x < 0.0;
                let mid = partition_blocks(&mut prims, pred, |_, _| {});
                assert_eq!(mid, partition(&mut plain, pred), "len {len}");
                assert!(prims[..mid].iter().all(pred) && !prims[mid..].iter().any(pred), "len {len}");
                let ids = |v: &[BuildPrim]| {
                    let mut ids: Vec<u32> = v.iter().map(|p| p.id()).collect();
                    ids.sort_unstable();
                    ids
                };
                assert_eq!(ids(&prims), (0..len as u32).collect::<Vec<_>>());
            }
        }
    }
}
