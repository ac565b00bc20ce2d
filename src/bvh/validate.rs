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
