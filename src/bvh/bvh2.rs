//! The binary BVH and its scalar traversal: the reference every faster kernel is tested
//! against. Simple on purpose: one box test per node, near child first, a fixed stack.

use crate::bvh::limits::MAX_DEPTH;
use crate::math::{Aabb, Vec3};
use crate::ray::{Hit, Ray};

/// A node of [`Bvh2`]. 32 bytes.
///
/// * Leaf (`count > 0`): primitives `prim_ids[start .. start + count]`.
/// * Inner (`count == 0`): children at `nodes[start]` and `nodes[start + 1]`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Bvh2Node {
    /// Bounds of everything below this node.
    pub bounds: Aabb,
    /// First primitive (leaf) or left child (inner).
    pub start: u32,
    /// Primitive count; 0 marks an inner node.
    pub count: u32,
}
const _: () = assert!(std::mem::size_of::<Bvh2Node>() == 32);

impl Bvh2Node {
    /// True for leaves.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }
}

/// A binary BVH: nodes in depth-first order with siblings adjacent, root at index 0.
/// An empty tree is one leaf with `count == 0` and empty bounds, which no ray hits.
#[derive(Clone, Debug, Default)]
pub struct Bvh2 {
    /// The nodes; `nodes[0]` is the root.
    pub nodes: Vec<Bvh2Node>,
    /// Primitive ids in leaf order.
    pub prim_ids: Vec<u32>,
}

/// Relative widening of the slab interval that makes the box test conservative under
/// floating-point rounding (Ize, "Robust BVH Ray Traversal", JCGT 2013: `1 + 2 gamma(3)`).
pub const SLAB_WIDEN: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// The entry distance of the ray into `b` clipped to `[tnear, tfar]`, or `None`.
#[inline]
pub fn slab_test(b: &Aabb, origin: Vec3, inv_dir: Vec3, tnear: f32, tfar: f32) -> Option<f32> {
    let t0 = (b.min - origin) * inv_dir;
    let t1 = (b.max - origin) * inv_dir;
    let tmin = t0.min(t1).max_element().max(tnear);
    let tmax = (t0.max(t1).min_element() * SLAB_WIDEN).min(tfar);
    (tmin <= tmax).then_some(tmin)
}

impl Bvh2 {
    /// True when the tree holds no primitives.
    pub fn is_empty(&self) -> bool {
        self.prim_ids.is_empty()
    }

    /// Bytes of nodes and primitive ids.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice()) + std::mem::size_of_val(self.prim_ids.as_slice())
    }

    /// Closest hit. `test(prim, tfar)` intersects one primitive over `[ray.tnear, tfar]` and
    /// returns `(t, u, v)`; the traversal keeps the nearest.
    pub fn intersect(&self, ray: &Ray, mut test: impl FnMut(u32, f32) -> Option<(f32, f32, f32)>) -> Hit {
        let mut hit = Hit::MISS;
        if !ray.is_valid() || self.is_empty() {
            return hit;
        }
        let inv = ray.inv_dir();
        let mut tfar = ray.tfar;
        let mut stack = [0u32; MAX_DEPTH + 1];
        let mut sp = 0usize;
        let mut node = 0u32;
        if slab_test(&self.nodes[0].bounds, ray.origin, inv, ray.tnear, tfar).is_none() {
            return hit;
        }
        loop {
            let n = &self.nodes[node as usize];
            if n.is_leaf() {
                for &prim in &self.prim_ids[n.start as usize..(n.start + n.count) as usize] {
                    if let Some((t, u, v)) = test(prim, tfar) {
                        tfar = t;
                        hit = Hit { t, u, v, prim };
                    }
                }
            } else {
                let (a, b) = (n.start, n.start + 1);
                let ta = slab_test(&self.nodes[a as usize].bounds, ray.origin, inv, ray.tnear, tfar);
                let tb = slab_test(&self.nodes[b as usize].bounds, ray.origin, inv, ray.tnear, tfar);
                match (ta, tb) {
                    (Some(x), Some(y)) => {
                        let (near, far) = if x <= y { (a, b) } else { (b, a) };
                        stack[sp] = far;
                        sp += 1;
                        node = near;
                        continue;
                    }
                    (Some(_), None) => {
                        node = a;
                        continue;
                    }
                    (None, Some(_)) => {
                        node = b;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Pop, skipping nodes that the shrunken interval no longer reaches.
            loop {
                if sp == 0 {
                    return hit;
                }
                sp -= 1;
                node = stack[sp];
                if slab_test(&self.nodes[node as usize].bounds, ray.origin, inv, ray.tnear, tfar).is_some() {
                    break;
                }
            }
        }
    }

    /// Any hit: true as soon as `test(prim)` reports a hit in `[ray.tnear, ray.tfar]`.
    pub fn occluded(&self, ray: &Ray, mut test: impl FnMut(u32) -> bool) -> bool {
        if !ray.is_valid() || self.is_empty() {
            return false;
        }
        let inv = ray.inv_dir();
        let mut stack = [0u32; MAX_DEPTH + 2];
        let mut sp = 1usize;
        stack[0] = 0;
        while sp > 0 {
            sp -= 1;
            let n = &self.nodes[stack[sp] as usize];
            if slab_test(&n.bounds, ray.origin, inv, ray.tnear, ray.tfar).is_none() {
                continue;
            }
            if n.is_leaf() {
                let prims = &self.prim_ids[n.start as usize..(n.start + n.count) as usize];
                if prims.iter().any(|&p| test(p)) {
                    return true;
                }
            } else {
                stack[sp] = n.start + 1;
                stack[sp + 1] = n.start;
                sp += 2;
            }
        }
        false
    }

    /// Depth of the tree (a single leaf has depth 1).
    pub fn depth(&self) -> usize {
        let mut max = 0;
        let mut stack = vec![(0u32, 1usize)];
        while let Some((i, d)) = stack.pop() {
            max = max.max(d);
            let n = &self.nodes[i as usize];
            if !n.is_leaf() && !self.is_empty() {
                stack.push((n.start, d + 1));
                stack.push((n.start + 1, d + 1));
            }
        }
        max
    }
}
