//! Structural invariants of a BVH, at two strengths:
//!
//! * [`check_bvh2_indices`] and [`check_bvh8_indices`]: what the traversals index with. Every
//!   child, block and primitive reference is in range, each node is reached once, the depth
//!   stays within [`MAX_DEPTH`], empty slots can never be hit and a BVH8 node's inner children
//!   are where [`crate::bvh::Bvh8Node::inner_child`] says, so that even a forged tree
//!   cannot make a query panic. One linear pass, cheap enough for every start from the BVH
//!   cache (`scene::cache`), which runs it on each file it loads.
//! * [`validate_bvh2`] and [`validate_bvh8`]: those, plus the geometry. Every box holds its
//!   children's boxes; every primitive is referenced, never twice by one leaf, and the boxes
//!   of the leaves that reference it together hold its box (once, in a tree without spatial
//!   splits, whose leaf box then holds it whole; with them, each leaf holds a part); each
//!   used lane of a block belongs to exactly one leaf (small leaves may share a block); padding
//!   lanes are inert. For tests and `raypack info --validate`.
//!
//! Both builders store children after their parent (depth-first order), which the index checks
//! require: one pass in index order then sees each node's depth before its children's, so the
//! check is linear and cache-friendly (a depth-first walk with a stack was a large part of
//! a cached start; PERFORMANCE.md, "Smaller measured choices").

use crate::bvh::Bvh2;
use crate::bvh::bvh8::Bvh8;
use crate::bvh::limits::MAX_DEPTH;
use crate::bvh::node::{LeafKind, NodeRef};
use crate::geometry::{Sphere4, TriBlock};
use crate::math::{Aabb, Vec3};

/// Checks that a binary BVH over `num_prims` primitives can be traversed without indexing out
/// of range (see the module docs). Returns a description of the first violation.
pub fn check_bvh2_indices(bvh2: &Bvh2, num_prims: usize) -> Result<(), String> {
    let n2 = &bvh2.nodes;
    if n2.is_empty() {
        return Err("no root".into());
    }
    if !bvh2.prim_ids.iter().all(|&p| (p as usize) < num_prims) {
        return Err("refers to a primitive that does not exist".into());
    }
    // depth[i]: 0 while node i is unreached, else its depth (root = 1). An empty tree is a
    // root with `count == 0` that the traversal never enters.
    let mut depth = vec![0u8; n2.len()];
    depth[0] = u8::from(!bvh2.prim_ids.is_empty());
    for (i, n) in n2.iter().enumerate() {
        let d = depth[i];
        if d == 0 {
            continue;
        }
        let (start, count) = (n.start as usize, n.count as usize);
        if n.is_leaf() {
            if start + count > bvh2.prim_ids.len() {
                return Err(format!("leaf {i} out of range"));
            }
        } else if start <= i || start + 1 >= n2.len() || d as usize >= MAX_DEPTH {
            return Err(format!("node {i} has children out of range or too deep"));
        } else {
            for c in [start, start + 1] {
                if std::mem::replace(&mut depth[c], d + 1) != 0 {
                    return Err(format!("node {c} reached twice"));
                }
            }
        }
    }
    Ok(())
}

/// Checks that an 8-wide BVH over `num_prims` primitives can be traversed without indexing
/// out of range (see the module docs). Returns a description of the first violation.
pub fn check_bvh8_indices<T: TriBlock>(b8: &Bvh8<T>, num_prims: usize) -> Result<(), String> {
    if b8.nodes.is_empty() {
        return Err("no root".into());
    }
    let prim_ok = |p: u32| p == u32::MAX || (p as usize) < num_prims;
    if !(0..b8.tri_block_count()).all(|k| (0..b8.tri_lanes()).all(|lane| prim_ok(b8.tri_prim(k, lane))))
        || !b8.spheres.iter().all(|b| b.prim.iter().all(|&p| prim_ok(p)))
    {
        return Err("a block refers to a primitive that does not exist".into());
    }
    let mut depth = vec![0u8; b8.nodes.len()];
    depth[0] = 1;
    for (i, n) in b8.nodes.iter().enumerate() {
        let d = depth[i];
        if d == 0 {
            continue;
        }
        for (k, &c) in n.children.iter().enumerate() {
            if c.is_empty() {
                if n.child_bounds(k) != Aabb::EMPTY {
                    return Err(format!("node {i} has an empty slot {k} that can be hit"));
                }
            } else if !c.is_leaf() {
                let j = c.node_index();
                if j <= i || j >= b8.nodes.len() || d as usize >= MAX_DEPTH {
                    return Err(format!("node {i} has child {k} out of range or too deep"));
                }
                if n.inner_child(k) != c {
                    return Err(format!(
                        "node {i} has inner child {k} out of place (inner children first, consecutive)"
                    ));
                }
                if std::mem::replace(&mut depth[j], d + 1) != 0 {
                    return Err(format!("node {j} reached twice"));
                }
            } else {
                let (len, m) = match c.kind() {
                    LeafKind::Triangles => (b8.tri_block_count(), b8.tri_lanes()),
                    LeafKind::Spheres => (b8.spheres.len(), Sphere4::M),
                };
                let last = c.lanes_of_block(c.block_count().saturating_sub(1), m);
                let lanes_ok = if c.block_count() == 1 { c.first_lane() + last <= m } else { c.first_lane() == 0 };
                if c.block_count() == 0 || c.first_block() + c.block_count() > len || last == 0 || last > m || !lanes_ok
                {
                    return Err(format!("node {i} has leaf {k} out of range"));
                }
            }
        }
    }
    Ok(())
}

/// Checks [`check_bvh2_indices`], then that every child box lies inside its parent's and
/// that the leaves cover every primitive (see the module docs). Returns a description of the first
/// violation.
pub fn validate_bvh2(bvh: &Bvh2, prim_bounds: &[Aabb]) -> Result<(), String> {
    if bvh.is_empty() {
        return if prim_bounds.is_empty() { Ok(()) } else { Err("empty tree over non-empty input".into()) };
    }
    check_bvh2_indices(bvh, prim_bounds.len())?;
    // Every index below is in range, and every node is reached once.
    let mut cover = Coverage::new(prim_bounds);
    let mut stack = vec![0usize];
    while let Some(i) = stack.pop() {
        let n = &bvh.nodes[i];
        if n.is_leaf() {
            let ids = &bvh.prim_ids[n.start as usize..(n.start + n.count) as usize];
            cover.leaf(&n.bounds, ids.iter().copied()).map_err(|e| format!("leaf {i}: {e}"))?;
        } else {
            for c in [n.start as usize, n.start as usize + 1] {
                if !n.bounds.contains_box(&bvh.nodes[c].bounds) {
                    return Err(format!("node {i} does not contain child {c}"));
                }
                stack.push(c);
            }
        }
    }
    cover.finish()
}

/// Checks [`check_bvh8_indices`], then that every node is reached; every child box lies
/// inside the parent's slot box; the leaves cover every primitive (see the module docs); padding
/// lanes of blocks are inert (zero edges, NaN radius). Returns a description of the first
/// violation.
pub fn validate_bvh8<T: TriBlock>(bvh: &Bvh8<T>, prim_bounds: &[Aabb]) -> Result<(), String> {
    check_bvh8_indices(bvh, prim_bounds.len())?;
    // Every index below is in range, every node is reached at most once and empty slots are
    // never hit.
    let mut cover = Coverage::new(prim_bounds);
    let mut reached = vec![false; bvh.nodes.len()];
    // The lanes each leaf claims, per block: no lane claimed twice, every used lane claimed.
    let mut claimed = (vec![0u32; bvh.tri_block_count()], vec![0u32; bvh.spheres.len()]);
    let mut stack = vec![0usize];
    while let Some(i) = stack.pop() {
        reached[i] = true;
        let n = &bvh.nodes[i];
        for (slot, &c) in n.children.iter().enumerate() {
            if c == NodeRef::EMPTY {
                continue;
            }
            let b = n.child_bounds(slot);
            if !b.is_valid() {
                return Err(format!("slot {slot} of node {i} has invalid box {b:?}"));
            }
            if !c.is_leaf() {
                let k = c.node_index();
                if !b.contains_box(&bvh.nodes[k].bounds()) {
                    return Err(format!("slot {slot} of node {i} does not contain node {k}"));
                }
                stack.push(k);
                continue;
            }
            let (claims, m) = match c.kind() {
                LeafKind::Triangles => (&mut claimed.0, bvh.tri_lanes()),
                LeafKind::Spheres => (&mut claimed.1, Sphere4::M),
            };
            for (k, block) in c.blocks().enumerate() {
                let lanes = c.lane_mask(k, m);
                if claims[block] & lanes != 0 {
                    return Err(format!(
                        "leaf in slot {slot} of node {i} claims lanes of block {block} another leaf holds"
                    ));
                }
                claims[block] |= lanes;
            }
            cover.leaf(&b, bvh.leaf_prims(c)).map_err(|e| format!("leaf in slot {slot} of node {i}: {e}"))?;
        }
    }
    let used_tri =
        |k: usize| (0..bvh.tri_lanes()).filter(|&l| bvh.tri_prim(k, l) != u32::MAX).fold(0u32, |m, l| m | 1 << l);
    let used_sphere = |b: &Sphere4| (0..Sphere4::M).filter(|&l| b.prim[l] != u32::MAX).fold(0u32, |m, l| m | 1 << l);
    if let Some(k) = (0..bvh.tri_block_count()).find(|&k| used_tri(k) & !claimed.0[k] != 0) {
        return Err(format!("triangle block {k} has lanes no leaf holds"));
    }
    if let Some(k) = (0..bvh.spheres.len()).find(|&k| used_sphere(&bvh.spheres[k]) & !claimed.1[k] != 0) {
        return Err(format!("sphere block {k} has lanes no leaf holds"));
    }
    if let Some(i) = reached.iter().position(|r| !r) {
        return Err(format!("node {i} unreachable"));
    }
    for (k, b) in bvh.tris.iter().enumerate() {
        for lane in 0..T::M {
            let [_, e1, e2] = b.lane_rows(lane);
            if b.prim(lane) == u32::MAX && (e1 != Vec3::ZERO || e2 != Vec3::ZERO) {
                return Err(format!("padding lane {lane} of triangle block {k} is not inert"));
            }
        }
    }
    for (k, b) in bvh.spheres.iter().enumerate() {
        for lane in 0..Sphere4::M {
            if b.prim[lane] == u32::MAX && !b.radius[lane].is_nan() {
                return Err(format!("padding lane {lane} of sphere block {k} is not inert"));
            }
        }
    }
    cover.finish()
}

/// What the leaves of a tree say about each primitive: how often they reference it and the
/// union of their boxes.
struct Coverage<'a> {
    prim_bounds: &'a [Aabb],
    boxes: Vec<Aabb>,
    refs: Vec<u32>,
}

impl<'a> Coverage<'a> {
    fn new(prim_bounds: &'a [Aabb]) -> Self {
        Self { prim_bounds, boxes: vec![Aabb::EMPTY; prim_bounds.len()], refs: vec![0; prim_bounds.len()] }
    }

    /// Records a leaf with box `b` referencing `ids` (in range): no id twice, and each
    /// primitive's box overlaps `b`.
    fn leaf(&mut self, b: &Aabb, ids: impl IntoIterator<Item = u32>) -> Result<(), String> {
        let mut seen = Vec::new();
        for id in ids {
            if seen.contains(&id) {
                return Err(format!("references prim {id} twice"));
            }
            seen.push(id);
            let p = &self.prim_bounds[id as usize];
            if !(Aabb { min: p.min.max(b.min), max: p.max.min(b.max) }).is_valid() {
                return Err(format!("does not overlap prim {id}"));
            }
            let i = id as usize;
            self.boxes[i] = self.boxes[i].union(b);
            self.refs[i] += 1;
        }
        Ok(())
    }

    /// Every primitive referenced, and held by its leaves' boxes together.
    fn finish(&self) -> Result<(), String> {
        for (id, p) in self.prim_bounds.iter().enumerate() {
            if self.refs[id] == 0 {
                return Err(format!("prim {id} not referenced"));
            }
            if !self.boxes[id].contains_box(p) {
                return Err(format!("the leaves referencing prim {id} do not contain it"));
            }
        }
        Ok(())
    }
}
