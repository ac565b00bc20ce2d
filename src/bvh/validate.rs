//! Structural invariants of a BVH, checked by tests and by `raypack info --validate`.

use crate::bvh::{Bvh2, MAX_DEPTH};
use crate::math::Aabb;

/// Checks that every child box lies inside its parent's, every leaf box holds its
/// primitives' boxes (`prim_bounds[id]`), every primitive id appears exactly once, and the
/// depth stays within [`MAX_DEPTH`]. Returns a description of the first violation.
pub fn validate_bvh2(bvh: &Bvh2, prim_bounds: &[Aabb]) -> Result<(), String> {
    let mut seen = vec![false; prim_bounds.len()];
    if bvh.is_empty() {
        return if prim_bounds.is_empty() { Ok(()) } else { Err("empty tree over non-empty input".into()) };
    }
    let mut stack = vec![(0u32, 1usize)];
    while let Some((i, depth)) = stack.pop() {
        let n = bvh.nodes.get(i as usize).ok_or(format!("node index {i} out of range"))?;
        if depth > MAX_DEPTH {
            return Err(format!("depth {depth} exceeds {MAX_DEPTH}"));
        }
        if n.is_leaf() {
            let range = n.start as usize..(n.start + n.count) as usize;
            let ids = bvh.prim_ids.get(range).ok_or(format!("leaf {i} range out of bounds"))?;
            for &id in ids {
                let b = prim_bounds.get(id as usize).ok_or(format!("prim id {id} out of range"))?;
                if !n.bounds.contains_box(b) {
                    return Err(format!("leaf {i} does not contain prim {id}"));
                }
                if std::mem::replace(&mut seen[id as usize], true) {
                    return Err(format!("prim {id} referenced twice"));
                }
            }
        } else {
            for c in [n.start, n.start + 1] {
                let cb = bvh.nodes.get(c as usize).ok_or(format!("child {c} of node {i} out of range"))?;
                if !n.bounds.contains_box(&cb.bounds) {
                    return Err(format!("node {i} does not contain child {c}"));
                }
                stack.push((c, depth + 1));
            }
        }
    }
    match seen.iter().position(|s| !s) {
        Some(id) => Err(format!("prim {id} not referenced")),
        None => Ok(()),
    }
}

/// Checks the invariants of an 8-wide BVH: every node is reached exactly once; every child
/// box lies inside the parent's slot box; every leaf box holds its primitives' boxes
/// (`prim_bounds[id]`); every primitive id appears exactly once; empty slots have the
/// never-hit box (`+inf` lower, `-inf` upper); padding lanes of blocks are inert (zero
/// edges, NaN radius). Returns a description of the first violation.
pub fn validate_bvh8<T: crate::geometry::TriBlock>(
    bvh: &crate::bvh::Bvh8<T>,
    prim_bounds: &[Aabb],
) -> Result<(), String> {
    use crate::bvh::node::NodeRef;
    let mut seen = vec![false; prim_bounds.len()];
    let mut reached = vec![false; bvh.nodes.len()];
    let mut stack = vec![(0usize, 1usize)];
    while let Some((i, depth)) = stack.pop() {
        if std::mem::replace(&mut reached[i], true) {
            return Err(format!("node {i} reached twice"));
        }
        if depth > MAX_DEPTH {
            return Err(format!("depth {depth} exceeds {MAX_DEPTH}"));
        }
        let n = &bvh.nodes[i];
        for slot in 0..8 {
            let c = n.children[slot];
            let b = n.child_bounds(slot);
            if c == NodeRef::EMPTY {
                let inert = (0..3)
                    .all(|a| n.bounds[2 * a][slot] == f32::INFINITY && n.bounds[2 * a + 1][slot] == f32::NEG_INFINITY);
                if !inert {
                    return Err(format!("empty slot {slot} of node {i} has box {b:?}"));
                }
                continue;
            }
            if !b.is_valid() {
                return Err(format!("slot {slot} of node {i} has invalid box {b:?}"));
            }
            if !c.is_leaf() {
                let k = c.node_index();
                let child = bvh.nodes.get(k).ok_or(format!("child {k} of node {i} out of range"))?;
                if !b.contains_box(&child.bounds()) {
                    return Err(format!("slot {slot} of node {i} does not contain node {k}"));
                }
                stack.push((k, depth + 1));
                continue;
            }
            let end = c.blocks().end;
            let in_range = match c.kind() {
                crate::bvh::LeafKind::Triangles => end <= bvh.tris.len(),
                crate::bvh::LeafKind::Spheres => end <= bvh.spheres.len(),
            };
            if !in_range {
                return Err(format!("leaf in slot {slot} of node {i} out of range"));
            }
            for id in bvh.leaf_prims(c) {
                let pb = prim_bounds.get(id as usize).ok_or(format!("prim id {id} out of range"))?;
                if !b.contains_box(pb) {
                    return Err(format!("leaf in slot {slot} of node {i} does not contain prim {id}"));
                }
                if std::mem::replace(&mut seen[id as usize], true) {
                    return Err(format!("prim {id} referenced twice"));
                }
            }
        }
    }
    if let Some(i) = reached.iter().position(|r| !r) {
        return Err(format!("node {i} unreachable"));
    }
    for (k, b) in bvh.tris.iter().enumerate() {
        for lane in 0..T::M {
            let [_, e1, e2] = b.lane_rows(lane);
            if b.prim(lane) == u32::MAX && (e1 != crate::math::Vec3::ZERO || e2 != crate::math::Vec3::ZERO) {
                return Err(format!("padding lane {lane} of triangle block {k} is not inert"));
            }
        }
    }
    for (k, b) in bvh.spheres.iter().enumerate() {
        for lane in 0..4 {
            if b.prim[lane] == u32::MAX && !b.radius[lane].is_nan() {
                return Err(format!("padding lane {lane} of sphere block {k} is not inert"));
            }
        }
    }
    match seen.iter().position(|s| !s) {
        Some(id) => Err(format!("prim {id} not referenced")),
        None => Ok(()),
    }
}
