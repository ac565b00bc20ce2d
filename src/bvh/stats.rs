//! Tree quality figures: SAH cost, node counts, leaf fill, depth.

use crate::bvh::Bvh2;

/// Summary statistics of a BVH.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BvhStats {
    /// Inner nodes.
    pub inner_nodes: usize,
    /// Leaves.
    pub leaves: usize,
    /// Primitives referenced by leaves.
    pub prims: usize,
    /// Mean primitives per leaf.
    pub mean_leaf_size: f64,
    /// Deepest leaf (root = 1).
    pub depth: usize,
    /// SAH cost with unit traversal and intersection costs, relative to the root's area:
    /// `sum_inner A(n)/A(root) + sum_leaves N(l) A(l)/A(root)`.
    pub sah_cost: f64,
}

impl BvhStats {
    /// Statistics of a binary BVH.
    pub fn of_bvh2(bvh: &Bvh2) -> Self {
        let mut s = BvhStats::default();
        if bvh.is_empty() {
            return s;
        }
        let root_area = bvh.nodes[0].bounds.half_area() as f64;
        let norm = if root_area > 0.0 { 1.0 / root_area } else { 0.0 };
        for n in &bvh.nodes {
            let a = n.bounds.half_area() as f64 * norm;
            if n.is_leaf() {
                s.leaves += 1;
                s.prims += n.count as usize;
                s.sah_cost += a * n.count as f64;
            } else {
                s.inner_nodes += 1;
                s.sah_cost += a;
            }
        }
        s.mean_leaf_size = s.prims as f64 / s.leaves.max(1) as f64;
        s.depth = bvh.depth();
        s
    }
}

impl std::fmt::Display for BvhStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "SAH cost {:.2}, {} inner nodes, {} leaves ({:.2} prims/leaf), depth {}",
            self.sah_cost, self.inner_nodes, self.leaves, self.mean_leaf_size, self.depth
        )
    }
}
