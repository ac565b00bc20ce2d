//! The 8-wide BVH: nodes, triangle blocks and sphere blocks in flat arrays.

use crate::bvh::BvhArray;
use crate::bvh::node::{Bvh8Node, LeafKind, NodeRef};
use crate::geometry::{Sphere4, Tri8, TriBlock, TriangleTest};

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
    /// Triangle blocks; a leaf's blocks are consecutive.
    pub tris: BvhArray<T>,
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
            spheres: BvhArray::default(),
            test: TriangleTest::default(),
        }
    }
}

/// A [`Bvh8`]'s arrays as plain slices: what the traversal kernels read. (A [`BvhArray`] may
/// be a section of a memory-mapped file, whose dereference costs a match and a cast: done once
/// per query here instead of once per node.)
#[derive(Clone, Copy, Debug)]
pub struct Bvh8Ref<'a, T> {
    /// Inner nodes; `nodes[0]` is the root.
    pub nodes: &'a [Bvh8Node],
    /// Triangle blocks.
    pub tris: &'a [T],
    /// Sphere blocks.
    pub spheres: &'a [Sphere4],
    /// The triangle test the blocks are laid out for.
    pub test: TriangleTest,
}

impl<T: TriBlock> Bvh8Ref<'_, T> {
    /// The root reference.
    #[inline(always)]
    pub fn root(&self) -> NodeRef {
        NodeRef::inner(0)
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
            let lines = std::mem::size_of::<T>().div_ceil(64);
            let p = self.tris.as_ptr().wrapping_add(r.first_block()) as *const u8;
            for line in 0..lines {
                prefetch_line(p.wrapping_add(64 * line));
            }
            if r.block_count() > 1 {
                let p = p.wrapping_add(std::mem::size_of::<T>());
                for line in 0..lines {
                    prefetch_line(p.wrapping_add(64 * line));
                }
            }
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
    #[inline(always)]
    pub fn slices(&self) -> Bvh8Ref<'_, T> {
        Bvh8Ref { nodes: &self.nodes, tris: &self.tris, spheres: &self.spheres, test: self.test }
    }

    /// Bytes of nodes and leaf blocks.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(&self.nodes[..])
            + std::mem::size_of_val(&self.tris[..])
            + std::mem::size_of_val(&self.spheres[..])
    }

    /// Structure statistics.
    pub fn stats(&self) -> Bvh8Stats {
        let mut s = Bvh8Stats {
            nodes: self.nodes.len(),
            tri_blocks: self.tris.len(),
            sphere_blocks: self.spheres.len(),
            bytes: self.bytes(),
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
        let lanes = self.tris.len() * T::M + self.spheres.len() * Sphere4::M;
        let full = self.tris.iter().map(|b| (0..T::M).filter(|&l| b.prim(l) != u32::MAX).count()).sum::<usize>()
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
            LeafKind::Triangles => self.tris[range]
                .iter()
                .enumerate()
                .flat_map(|(k, b)| crate::simd::bits(r.lane_mask(k, T::M)).map(|l| b.prim(l)))
                .filter(real)
                .collect(),
            LeafKind::Spheres => self.spheres[range]
                .iter()
                .enumerate()
                .flat_map(|(k, b)| crate::simd::bits(r.lane_mask(k, Sphere4::M)).map(|l| b.prim[l]))
                .filter(real)
                .collect(),
        }
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
