//! The 8-wide BVH node and its child references: the layout every BVH8 kernel reads.
//!
//! Layout follows Embree's `AABBNode` for N = 8 (Wald et al., "Embree: A Kernel Framework for
//! Efficient CPU Ray Tracing", SIGGRAPH 2014): the eight child boxes are stored as structure
//! of arrays, one 32-byte row of eight `f32` per box plane, so that one AVX2 load fetches a
//! plane of all eight children and the slab test runs on all of them at once.

use crate::math::Aabb;

/// Row of [`Bvh8Node::bounds`] holding the children's lower x planes.
pub const LOWER_X: usize = 0;
/// Row holding the upper x planes.
pub const UPPER_X: usize = 1;
/// Row holding the lower y planes.
pub const LOWER_Y: usize = 2;
/// Row holding the upper y planes.
pub const UPPER_Y: usize = 3;
/// Row holding the lower z planes.
pub const LOWER_Z: usize = 4;
/// Row holding the upper z planes.
pub const UPPER_Z: usize = 5;

/// What a leaf's blocks hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LeafKind {
    /// Triangle blocks (`Bvh8::tris`).
    Triangles,
    /// Sphere blocks (`Bvh8::spheres`).
    Spheres,
}

/// A tagged reference to a child: an inner node, a leaf (a run of consecutive primitive
/// blocks of one kind), or an empty slot. 8 bytes.
///
/// Bit layout, from the most significant bit:
/// * bit 63: leaf flag;
/// * inner: bits 0..32 hold the node index into `Bvh8::nodes`;
/// * leaf: bit 62 is set for sphere blocks, bits 53..58 hold the lane the leaf starts at in
///   its first block, bits 48..53 the number of lanes it uses in its last block, bits 32..48
///   the number of blocks (at least 1), bits 0..32 the index of the first block. A leaf of
///   one block uses lanes `first_lane .. first_lane + last lanes` of it, so that the small
///   leaves of a node can share a block (see [`mod@crate::bvh::collapse`]); a leaf of several
///   blocks starts at lane 0 and fills all blocks but its last;
/// * empty: all bits set ([`NodeRef::EMPTY`]); never dereferenced because the slot's box can
///   never be hit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(transparent)]
pub struct NodeRef(pub u64);

const LEAF_BIT: u64 = 1 << 63;
const SPHERE_BIT: u64 = 1 << 62;
const FIRST_LANE_SHIFT: u32 = 53;

impl NodeRef {
    /// An unused child slot.
    pub const EMPTY: NodeRef = NodeRef(u64::MAX);
    /// Largest number of blocks one leaf can reference.
    pub const MAX_LEAF_BLOCKS: usize = u16::MAX as usize;

    /// A reference to inner node `index`.
    #[inline]
    pub fn inner(index: u32) -> Self {
        NodeRef(index as u64)
    }

    /// A leaf of `count` blocks starting at block `first`, whose last block uses
    /// `last_lanes` lanes (`1 ..= 16`).
    #[inline]
    pub fn leaf(kind: LeafKind, first: u32, count: usize, last_lanes: usize) -> Self {
        assert!((1..=Self::MAX_LEAF_BLOCKS).contains(&count), "leaf of {count} blocks");
        assert!((1..=16).contains(&last_lanes), "{last_lanes} lanes");
        let kind = if kind == LeafKind::Spheres { SPHERE_BIT } else { 0 };
        NodeRef(LEAF_BIT | kind | ((last_lanes as u64) << 48) | ((count as u64) << 32) | first as u64)
    }

    /// A leaf of `lanes` primitives in lanes `first_lane .. first_lane + lanes` of block
    /// `block` (the other lanes may belong to other leaves).
    #[inline]
    pub fn leaf_in_block(kind: LeafKind, block: u32, first_lane: usize, lanes: usize) -> Self {
        assert!(first_lane + lanes <= 16, "lanes {first_lane}..{} of a block", first_lane + lanes);
        let r = Self::leaf(kind, block, 1, lanes);
        NodeRef(r.0 | (first_lane as u64) << FIRST_LANE_SHIFT)
    }

    /// True for leaves (and for [`NodeRef::EMPTY`]).
    #[inline(always)]
    pub fn is_leaf(self) -> bool {
        self.0 & LEAF_BIT != 0
    }

    /// True for the empty slot.
    #[inline(always)]
    pub fn is_empty(self) -> bool {
        self == Self::EMPTY
    }

    /// Index of the inner node (meaningful for inner references only).
    #[inline(always)]
    pub fn node_index(self) -> usize {
        self.0 as u32 as usize
    }

    /// First block of a leaf.
    #[inline(always)]
    pub fn first_block(self) -> usize {
        self.0 as u32 as usize
    }

    /// Number of blocks of a leaf.
    #[inline(always)]
    pub fn block_count(self) -> usize {
        ((self.0 >> 32) & 0xFFFF) as usize
    }

    /// Indices of a leaf's blocks in the block array.
    #[inline(always)]
    pub fn blocks(self) -> std::ops::Range<usize> {
        self.first_block()..self.first_block() + self.block_count()
    }

    /// Lane the leaf starts at in its first block (0 for leaves of several blocks).
    #[inline(always)]
    pub fn first_lane(self) -> usize {
        ((self.0 >> FIRST_LANE_SHIFT) & 0x1F) as usize
    }

    /// Number of lanes the leaf uses in block `k` of its run (all `m` but in the last block).
    #[inline(always)]
    pub fn lanes_of_block(self, k: usize, m: usize) -> usize {
        if k + 1 == self.block_count() { ((self.0 >> 48) & 0x1F) as usize } else { m }
    }

    /// Bit mask of the lanes the leaf uses in block `k` of its run, blocks of `m` lanes.
    #[inline(always)]
    pub fn lane_mask(self, k: usize, m: usize) -> u32 {
        let start = if k == 0 { self.first_lane() } else { 0 };
        ((1u32 << self.lanes_of_block(k, m)) - 1) << start
    }

    /// What the blocks of a leaf hold.
    #[inline(always)]
    pub fn kind(self) -> LeafKind {
        if self.0 & SPHERE_BIT != 0 { LeafKind::Spheres } else { LeafKind::Triangles }
    }
}

/// A node of the 8-wide BVH: the boxes of up to eight children, structure of arrays, and
/// their references. 256 bytes, aligned to a cache line.
///
/// | bytes | field | content |
/// |---|---|---|
/// | 0..32 | `bounds[LOWER_X]` | lower x of children 0..8 |
/// | 32..64 | `bounds[UPPER_X]` | upper x |
/// | 64..96 | `bounds[LOWER_Y]` | lower y |
/// | 96..128 | `bounds[UPPER_Y]` | upper y |
/// | 128..160 | `bounds[LOWER_Z]` | lower z |
/// | 160..192 | `bounds[UPPER_Z]` | upper z |
/// | 192..256 | `children` | one [`NodeRef`] per child |
///
/// Lower and upper rows of an axis are adjacent, so a ray picks its near and far plane
/// rows by the sign of its direction (row `2 axis + (dir < 0)` is the near one) and the slab
/// test needs no per-lane min/max. An empty slot has lower `+inf` and upper `-inf`: whatever
/// the direction, its entry distance is `+inf` and its exit `-inf`, so it is never hit.
///
/// Inner children come first: a node with `k` inner children holds them in slots `0..k`, as
/// nodes `children[0].node_index() + 0..k` (the collapse allocates siblings consecutively),
/// then its leaves, then its empty slots. So the node of inner slot `i` is
/// [`Bvh8Node::inner_child`]`(i)`, which a single-ray kernel computes from `i` without waiting
/// for the load of `children[i]` (see [`crate::bvh::traverse1`]). The index checks of
/// [`crate::bvh::validate`] enforce it.
///
/// ```
/// use raypack::{BuildOptions, Bvh8Node, Material, SceneBuilder, Vec3};
///
/// let mut b = SceneBuilder::new();
/// let m = b.add_material(Material::default());
/// for i in 0..3 {
///     b.add_sphere(Vec3::new(i as f32 * 3.0, 0.0, 0.0), 1.0, m)?;
/// }
/// let (scene, _) = b.commit(&BuildOptions::default());
/// let root: &Bvh8Node = &scene.bvh8().nodes[0];
/// assert!(root.child_count() >= 1);
/// assert!(root.bounds().contains(Vec3::new(6.5, 0.0, 0.0)));
/// assert!(root.children[7].is_empty() && !root.child_bounds(7).is_valid()); // an unused slot
/// # Ok::<(), raypack::SceneError>(())
/// ```
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Bvh8Node {
    /// Child boxes, one row of eight lanes per plane: `LOWER_X, UPPER_X, LOWER_Y, UPPER_Y,
    /// LOWER_Z, UPPER_Z`.
    pub bounds: [[f32; 8]; 6],
    /// Child references; [`NodeRef::EMPTY`] for unused slots.
    pub children: [NodeRef; 8],
}
const _: () = assert!(std::mem::size_of::<Bvh8Node>() == 256);
const _: () = assert!(std::mem::align_of::<Bvh8Node>() == 64);
const _: () = assert!(std::mem::offset_of!(Bvh8Node, children) == 192);

impl Default for Bvh8Node {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Bvh8Node {
    /// A node with eight empty slots.
    pub const EMPTY: Bvh8Node = Bvh8Node {
        bounds: [
            [f32::INFINITY; 8],
            [f32::NEG_INFINITY; 8],
            [f32::INFINITY; 8],
            [f32::NEG_INFINITY; 8],
            [f32::INFINITY; 8],
            [f32::NEG_INFINITY; 8],
        ],
        children: [NodeRef::EMPTY; 8],
    };

    /// Sets slot `i` to `child` with box `b`.
    pub fn set_child(&mut self, i: usize, b: &Aabb, child: NodeRef) {
        for axis in 0..3 {
            self.bounds[2 * axis][i] = b.min[axis];
            self.bounds[2 * axis + 1][i] = b.max[axis];
        }
        self.children[i] = child;
    }

    /// The reference of slot `i` when it holds an inner node: `children[0]`'s index plus `i`,
    /// by the layout invariant (inner children first, at consecutive indices). Meaningless
    /// for the other slots.
    #[inline(always)]
    pub fn inner_child(&self, i: usize) -> NodeRef {
        NodeRef::inner((self.children[0].0 as u32).wrapping_add(i as u32))
    }

    /// The box of slot `i` ([`Aabb::EMPTY`] for empty slots).
    pub fn child_bounds(&self, i: usize) -> Aabb {
        let b = &self.bounds;
        Aabb {
            min: crate::math::Vec3::new(b[LOWER_X][i], b[LOWER_Y][i], b[LOWER_Z][i]),
            max: crate::math::Vec3::new(b[UPPER_X][i], b[UPPER_Y][i], b[UPPER_Z][i]),
        }
    }

    /// Number of used slots.
    pub fn child_count(&self) -> usize {
        self.children.iter().filter(|c| !c.is_empty()).count()
    }

    /// Union of the children's boxes.
    pub fn bounds(&self) -> Aabb {
        (0..8).fold(Aabb::EMPTY, |acc, i| acc.union(&self.child_bounds(i)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn references_round_trip() {
        let r = NodeRef::leaf(LeafKind::Spheres, 123_456, 7, 3);
        assert!(r.is_leaf() && !r.is_empty());
        assert_eq!((r.kind(), r.first_block(), r.block_count()), (LeafKind::Spheres, 123_456, 7));
        assert_eq!((r.lanes_of_block(0, 4), r.lanes_of_block(6, 4)), (4, 3));
        assert_eq!((r.lane_mask(0, 4), r.lane_mask(6, 4), r.first_lane()), (0b1111, 0b111, 0));
        let r = NodeRef::leaf(LeafKind::Triangles, u32::MAX - 1, 1, 16);
        assert_eq!(r.lanes_of_block(0, 16), 16);
        assert_eq!((r.kind(), r.first_block(), r.block_count()), (LeafKind::Triangles, u32::MAX as usize - 1, 1));
        let r = NodeRef::leaf_in_block(LeafKind::Triangles, 77, 5, 3);
        assert_eq!((r.first_block(), r.block_count(), r.first_lane()), (77, 1, 5));
        assert_eq!((r.lanes_of_block(0, 8), r.lane_mask(0, 8)), (3, 0b1110_0000));
        let n = NodeRef::inner(42);
        assert!(!n.is_leaf() && n.node_index() == 42);
        assert!(NodeRef::EMPTY.is_empty() && NodeRef::EMPTY.is_leaf());
    }

    #[test]
    fn empty_slots_have_empty_boxes() {
        let n = Bvh8Node::EMPTY;
        assert_eq!(n.child_count(), 0);
        assert!(!n.child_bounds(3).is_valid());
        assert_eq!(n.bounds(), Aabb::EMPTY);
    }
}
