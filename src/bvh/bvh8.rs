//! The 8-wide BVH: nodes, triangle blocks and sphere blocks in flat arrays.

use crate::bvh::BvhArray;
use crate::bvh::node::{Bvh8Node, LeafKind, NodeRef};
use crate::geometry::{PrimIds8, Sphere4, Tri8, TriBlock, TriangleTest};
use crate::math::Vec3;
use std::borrow::Borrow;
use std::ops::Range;

/// The triangle block the scene uses: M = 8.
///
/// M = 8 tests one ray against a whole leaf with one AVX2 register operation where M = 4
/// needs two for leaves of 5 to 8 triangles, and halves the leaf count; it fills blocks less
/// well, which the collapse costs keep in check ([`crate::bvh::CollapseOptions`]). It is the
/// faster of the two on every ray set measured (PERFORMANCE.md, "Leaf block width").
pub type DefaultTriBlock = Tri8;

/// An 8-wide BVH with leaf blocks of `T`. `nodes[0]` is the root (always an inner node; an
/// empty tree is a root with eight empty slots).
#[derive(Clone, Debug)]
pub struct Bvh8<T: TriBlock = DefaultTriBlock> {
    /// Inner nodes; the inner children of a node are stored consecutively, in its first slots
    /// ([`Bvh8Node`]).
    pub nodes: BvhArray<Bvh8Node>,
    /// Triangle blocks; a leaf's blocks are consecutive. Empty in a compact tree.
    pub tris: BvhArray<T>,
    /// The compact layout's leaf blocks ([`TreeLayout::Compact`]): the primitive ids of the
    /// triangle blocks, in their place (leaves index them as they index `tris`). Empty in the
    /// default layout.
    pub ids: BvhArray<PrimIds8>,
    /// Sphere blocks.
    pub spheres: BvhArray<Sphere4>,
    /// The triangle test the blocks are laid out for (the kernels dispatch on it once per
    /// query).
    pub test: TriangleTest,
}

impl<T: TriBlock> Default for Bvh8<T> {
    fn default() -> Self {
        Self {
            nodes: vec![Bvh8Node::EMPTY].into(),
            tris: BvhArray::default(),
            ids: BvhArray::default(),
            spheres: BvhArray::default(),
            test: TriangleTest::default(),
        }
    }
}

/// How a BVH8's triangle blocks are stored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum TreeLayout {
    /// [`Tri8`] blocks holding each triangle's vectors (40 bytes per triangle lane).
    #[default]
    Default,
    /// Blocks of primitive ids ([`PrimIds8`], 4 bytes per triangle lane); the kernels build
    /// each block they reach from the scene store's indices and positions. The smallest tree,
    /// with the same hits.
    Compact,
}

impl TreeLayout {
    /// Every layout, in the order of [`TreeLayout::name`]'s list.
    pub const ALL: [TreeLayout; 2] = [TreeLayout::Default, TreeLayout::Compact];

    /// The layout's name (`default`, `compact`), as [`TreeLayout::parse`] reads it.
    pub fn name(self) -> &'static str {
        match self {
            TreeLayout::Default => "default",
            TreeLayout::Compact => "compact",
        }
    }

    /// The layout named `s` ([`TreeLayout::name`]).
    pub fn parse(s: &str) -> Result<Self, TreeLayoutError> {
        Self::ALL.into_iter().find(|l| l.name() == s).ok_or_else(|| TreeLayoutError(s.to_string()))
    }
}

impl std::fmt::Display for TreeLayout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// An unknown tree layout name.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown tree layout '{0}' (expected default or compact)")]
pub struct TreeLayoutError(pub String);

/// Where the traversal kernels read a BVH8's triangle blocks: stored blocks (`&[T]`), or
/// blocks built from primitive ids on the fly ([`CompactLeaves`]). The kernels are written
/// once over this trait and instantiated per layout, so neither pays for the other.
pub trait LeafBlocks<T: TriBlock>: Copy {
    /// A block as the kernels test it: a reference into the array, or a block built on the
    /// stack.
    type Block: Borrow<T>;
    /// The blocks of a range.
    type Iter: Iterator<Item = Self::Block>;
    /// The blocks `range` (a leaf's).
    fn blocks(self, range: Range<usize>) -> Self::Iter;
    /// Block `i`.
    fn block(self, i: usize) -> Self::Block;
    /// Number of blocks.
    fn len(self) -> usize;
    /// True when there are no blocks.
    fn is_empty(self) -> bool {
        self.len() == 0
    }
    /// Bytes the kernels read for the blocks: the stored blocks, or the id blocks and the
    /// scene store's arrays they are built from.
    fn bytes(self) -> usize;
    /// Asks the cache for the stored data of block `first` and, when `two`, of the block after
    /// it.
    fn prefetch(self, first: usize, two: bool);
}

impl<'a, T: TriBlock> LeafBlocks<T> for &'a [T] {
    type Block = &'a T;
    type Iter = std::slice::Iter<'a, T>;

    #[inline(always)]
    fn blocks(self, range: Range<usize>) -> Self::Iter {
        self[range].iter()
    }

    #[inline(always)]
    fn block(self, i: usize) -> &'a T {
        &self[i]
    }

    #[inline(always)]
    fn len(self) -> usize {
        <[T]>::len(self)
    }

    #[inline(always)]
    fn bytes(self) -> usize {
        std::mem::size_of_val(self)
    }

    #[inline(always)]
    fn prefetch(self, first: usize, two: bool) {
        let lines = std::mem::size_of::<T>().div_ceil(64);
        let p = self.as_ptr().wrapping_add(first) as *const u8;
        for line in 0..lines {
            prefetch_line(p.wrapping_add(64 * line));
        }
        if two {
            let p = p.wrapping_add(std::mem::size_of::<T>());
            for line in 0..lines {
                prefetch_line(p.wrapping_add(64 * line));
            }
        }
    }
}

/// The compact layout's leaves ([`TreeLayout::Compact`]): blocks of primitive ids, and the
/// scene store's vertex indices and positions that each [`Tri8`] is built from when a kernel
/// reaches it ([`PrimIds8::tri8`]).
#[derive(Clone, Copy, Debug)]
pub struct CompactLeaves<'a> {
    /// The id blocks.
    pub ids: &'a [PrimIds8],
    /// Vertex positions of the scene store.
    pub positions: &'a [Vec3],
    /// Vertex indices of each triangle of the scene store.
    pub indices: &'a [[u32; 3]],
    /// The triangle test the built blocks are laid out for.
    pub test: TriangleTest,
}

/// The blocks of a range of [`CompactLeaves`], built one by one.
#[derive(Clone, Debug)]
pub struct CompactBlocks<'a> {
    ids: std::slice::Iter<'a, PrimIds8>,
    leaves: CompactLeaves<'a>,
}

impl Iterator for CompactBlocks<'_> {
    type Item = Tri8;

    #[inline(always)]
    fn next(&mut self) -> Option<Tri8> {
        let ids = self.ids.next()?;
        Some(ids.tri8(self.leaves.positions, self.leaves.indices, self.leaves.test))
    }
}

impl<'a> LeafBlocks<Tri8> for CompactLeaves<'a> {
    type Block = Tri8;
    type Iter = CompactBlocks<'a>;

    #[inline(always)]
    fn blocks(self, range: Range<usize>) -> CompactBlocks<'a> {
        CompactBlocks { ids: self.ids[range].iter(), leaves: self }
    }

    #[inline(always)]
    fn block(self, i: usize) -> Tri8 {
        self.ids[i].tri8(self.positions, self.indices, self.test)
    }

    #[inline(always)]
    fn len(self) -> usize {
        self.ids.len()
    }

    #[inline(always)]
    fn bytes(self) -> usize {
        std::mem::size_of_val(self.ids) + std::mem::size_of_val(self.positions) + std::mem::size_of_val(self.indices)
    }

    #[inline(always)]
    fn prefetch(self, first: usize, two: bool) {
        // One line holds two id blocks (32 bytes each, aligned to 32).
        let p = self.ids.as_ptr().wrapping_add(first) as *const u8;
        prefetch_line(p);
        if two {
            prefetch_line(p.wrapping_add(std::mem::size_of::<PrimIds8>()));
        }
    }
}

/// A [`Bvh8`]'s arrays as plain slices: what the traversal kernels read. (A [`BvhArray`] may
/// be a section of a memory-mapped file, whose dereference costs a match and a cast: done once
/// per query here instead of once per node.) `L` is where its triangle blocks come from: the
/// stored blocks of the default layout, or [`CompactLeaves`].
#[derive(Clone, Copy, Debug)]
pub struct Bvh8Ref<'a, T, L = &'a [T]> {
    /// Inner nodes; `nodes[0]` is the root.
    pub nodes: &'a [Bvh8Node],
    /// Triangle blocks.
    pub tris: L,
    /// Sphere blocks.
    pub spheres: &'a [Sphere4],
    /// The triangle test the blocks are laid out for.
    pub test: TriangleTest,
    /// The block type.
    pub block: std::marker::PhantomData<T>,
}

impl<T: TriBlock, L: LeafBlocks<T>> Bvh8Ref<'_, T, L> {
    /// The root reference.
    #[inline(always)]
    pub fn root(&self) -> NodeRef {
        NodeRef::inner(0)
    }

    /// Bytes the kernels read: nodes, leaf blocks ([`LeafBlocks::bytes`]: in a compact tree
    /// with the scene store's arrays the blocks are built from) and sphere blocks. The
    /// streams' and the single-ray query's choices by the tree's size go by it.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes) + self.tris.bytes() + std::mem::size_of_val(self.spheres)
    }

    /// Asks the cache for the data of child `r` (a node's four lines, or a leaf's first two
    /// blocks) so that several misses overlap instead of being paid one after another.
    #[inline(always)]
    pub fn prefetch(&self, r: NodeRef) {
        if !r.is_leaf() {
            let p = self.nodes.as_ptr().wrapping_add(r.node_index()) as *const u8;
            for line in 0..std::mem::size_of::<Bvh8Node>() / 64 {
                prefetch_line(p.wrapping_add(64 * line));
            }
        } else if r.kind() == LeafKind::Triangles {
            self.tris.prefetch(r.first_block(), r.block_count() > 1);
        } else {
            let p = self.spheres.as_ptr().wrapping_add(r.first_block()) as *const u8;
            prefetch_line(p);
            prefetch_line(p.wrapping_add(std::mem::size_of::<Sphere4>() - 1));
        }
    }
}

/// Size and shape figures of a [`Bvh8`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bvh8Stats {
    /// Inner nodes.
    pub nodes: usize,
    /// Leaves (child slots holding blocks).
    pub leaves: usize,
    /// Triangle blocks.
    pub tri_blocks: usize,
    /// Sphere blocks.
    pub sphere_blocks: usize,
    /// Mean used child slots per node (of 8).
    pub node_fill: f64,
    /// Fraction of block lanes holding a primitive.
    pub block_fill: f64,
    /// Bytes of nodes and blocks.
    pub bytes: usize,
    /// Bytes of the inner nodes (the rest of `bytes` is leaf blocks).
    pub node_bytes: usize,
    /// How the triangle blocks are stored.
    pub layout: TreeLayout,
    /// SAH cost (unit node and block costs, relative to the root's area).
    pub sah_cost: f64,
    /// Deepest level of inner nodes (root = 1).
    pub depth: usize,
}

impl std::fmt::Display for Bvh8Stats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "SAH cost {:.2}, {} nodes ({:.2}/8 full), {} leaves, {} triangle + {} sphere blocks ({:.0}% full), depth {}, {:.1} MB",
            self.sah_cost,
            self.nodes,
            self.node_fill,
            self.leaves,
            self.tri_blocks,
            self.sphere_blocks,
            self.block_fill * 100.0,
            self.depth,
            self.bytes as f64 / 1e6
        )
    }
}

impl<T: TriBlock> Bvh8<T> {
    /// The root reference.
    #[inline(always)]
    pub fn root(&self) -> NodeRef {
        NodeRef::inner(0)
    }

    /// The arrays as plain slices, for the kernels (one dereference per query, not per node).
    ///
    /// # Panics
    /// On a compact tree ([`TreeLayout::Compact`]), whose kernels read the scene store:
    /// query it through its [`crate::Scene`], or [`Bvh8::compact_slices`].
    #[inline(always)]
    pub fn slices(&self) -> Bvh8Ref<'_, T> {
        assert!(self.ids.is_empty(), "a compact BVH8 is queried through its scene, which holds the triangles");
        self.slices_with(&self.tris[..])
    }

    /// The arrays as plain slices with the triangle blocks `tris`.
    #[inline(always)]
    pub fn slices_with<L: LeafBlocks<T>>(&self, tris: L) -> Bvh8Ref<'_, T, L> {
        Bvh8Ref { nodes: &self.nodes, tris, spheres: &self.spheres, test: self.test, block: std::marker::PhantomData }
    }

    /// The layout of the triangle blocks (a tree without triangle blocks is in the default
    /// layout: there is nothing to store compactly).
    pub fn layout(&self) -> TreeLayout {
        if self.ids.is_empty() { TreeLayout::Default } else { TreeLayout::Compact }
    }

    /// Number of triangle blocks (stored blocks, or id blocks in a compact tree).
    pub fn tri_block_count(&self) -> usize {
        self.tris.len() + self.ids.len()
    }

    /// Lanes of a triangle block: `T::M`, or 8 in a compact tree ([`PrimIds8`]).
    pub fn tri_lanes(&self) -> usize {
        if self.ids.is_empty() { T::M } else { Tri8::M }
    }

    /// The primitive id in lane `lane` of triangle block `k` (stored or compact).
    pub fn tri_prim(&self, k: usize, lane: usize) -> u32 {
        if self.ids.is_empty() { self.tris[k].prim(lane) } else { self.ids[k].prim[lane] }
    }

    /// Bytes of nodes and leaf blocks (id blocks in a compact tree).
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(&self.nodes[..])
            + std::mem::size_of_val(&self.tris[..])
            + std::mem::size_of_val(&self.ids[..])
            + std::mem::size_of_val(&self.spheres[..])
    }

    /// Structure statistics.
    pub fn stats(&self) -> Bvh8Stats {
        let mut s = Bvh8Stats {
            nodes: self.nodes.len(),
            tri_blocks: self.tri_block_count(),
            sphere_blocks: self.spheres.len(),
            bytes: self.bytes(),
            node_bytes: std::mem::size_of_val(&self.nodes[..]),
            layout: self.layout(),
            ..Default::default()
        };
        let root_area = self.nodes[0].bounds().half_area() as f64;
        let norm = if root_area > 0.0 { 1.0 / root_area } else { 0.0 };
        let mut used = 0usize;
        let mut stack = vec![(0usize, 1usize)];
        s.sah_cost = 1.0;
        while let Some((i, d)) = stack.pop() {
            s.depth = s.depth.max(d);
            let n = &self.nodes[i];
            for k in 0..8 {
                let c = n.children[k];
                if c.is_empty() {
                    continue;
                }
                used += 1;
                let a = n.child_bounds(k).half_area() as f64 * norm;
                if c.is_leaf() {
                    s.leaves += 1;
                    s.sah_cost += a * c.block_count() as f64;
                } else {
                    s.sah_cost += a;
                    stack.push((c.node_index(), d + 1));
                }
            }
        }
        s.node_fill = used as f64 / s.nodes.max(1) as f64;
        let m = self.tri_lanes();
        let lanes = self.tri_block_count() * m + self.spheres.len() * Sphere4::M;
        let full = (0..self.tri_block_count())
            .map(|k| (0..m).filter(|&l| self.tri_prim(k, l) != u32::MAX).count())
            .sum::<usize>()
            + self.spheres.iter().map(|b| b.prim.iter().filter(|&&p| p != u32::MAX).count()).sum::<usize>();
        s.block_fill = if lanes > 0 { full as f64 / lanes as f64 } else { 1.0 };
        s
    }

    /// The primitive ids held by leaf `r`: its lanes of its blocks ([`NodeRef::lane_mask`]),
    /// padding lanes excluded.
    pub fn leaf_prims(&self, r: NodeRef) -> Vec<u32> {
        let range = r.blocks();
        let real = |p: &u32| *p != u32::MAX;
        match r.kind() {
            LeafKind::Triangles => {
                let m = self.tri_lanes();
                range
                    .enumerate()
                    .flat_map(|(k, b)| crate::simd::bits(r.lane_mask(k, m)).map(move |l| self.tri_prim(b, l)))
                    .filter(real)
                    .collect()
            }
            LeafKind::Spheres => self.spheres[range]
                .iter()
                .enumerate()
                .flat_map(|(k, b)| crate::simd::bits(r.lane_mask(k, Sphere4::M)).map(|l| b.prim[l]))
                .filter(real)
                .collect(),
        }
    }
}

impl Bvh8<Tri8> {
    /// The same tree in the compact layout ([`TreeLayout::Compact`]): each triangle block
    /// replaced by its primitive ids. Nodes and leaf references are unchanged.
    pub fn into_compact(mut self) -> Self {
        if self.ids.is_empty() {
            self.ids = self.tris.iter().map(PrimIds8::of).collect::<Vec<_>>().into();
            self.tris = BvhArray::default();
        }
        self
    }

    /// The arrays of a compact tree as the kernels read them, with the scene store's
    /// `positions` and `indices` (those the tree was built over) to build its blocks from.
    #[inline(always)]
    pub fn compact_slices<'a>(
        &'a self,
        positions: &'a [Vec3],
        indices: &'a [[u32; 3]],
    ) -> Bvh8Ref<'a, Tri8, CompactLeaves<'a>> {
        self.slices_with(CompactLeaves { ids: &self.ids, positions, indices, test: self.test })
    }
}

/// Prefetches the cache line holding `p` into all cache levels.
#[inline(always)]
pub fn prefetch_line(p: *const u8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is only a hint: it never faults and has no effect on program state,
    // whatever the address.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p as *const i8)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}
