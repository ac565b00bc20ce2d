//! Spatial splits for the binned SAH builder: Stich, Friedrich and Dietrich, "Spatial Splits
//! in Bounding Volume Hierarchies" (HPG 2009), in the budgeted form of Embree's high-quality
//! builder.
//!
//! An object split sends each primitive to one side whole; where long or large triangles
//! make the two sides' boxes overlap, a *spatial* split cuts the node's box with a plane
//! instead and sends the part of each crossing triangle on either side to that side, as two
//! references with tighter boxes. [`find`] bins the node's references into
//! [`SPATIAL_BINS`] slabs per axis (clipping each crossing triangle at every slab plane it
//! crosses, so each slab holds the exact bounds of its pieces) and sweeps for the cheapest
//! plane; [`split_refs`] performs the chosen split.
//!
//! Invariants the builder relies on:
//! * A reference's box is the exact bounds of the part of its triangle inside it (up to
//!   rounding, which the node boxes' [`super::pad_outward`] covers), so the
//!   boxes of all references to a triangle together hold the whole triangle: a ray that hits
//!   it passes through a leaf that holds it, before or at the hit.
//! * Every primitive carries a budget of splits (in `BuildPrim`'s spare lane): large ones
//!   may be cut more often than small ones, and a reference with a budget of at most 1 (and
//!   every sphere) is never cut, so the number of references stays bounded besides the
//!   free space the builder reserves.

use super::BuildPrim;
use crate::math::{Aabb, Vec3};

/// Slabs per axis of the spatial binning (Embree uses 16).
pub const SPATIAL_BINS: usize = 16;
/// A spatial split is weighed only where the object split's two boxes overlap by at least
/// this fraction of the node's surface area...
const OVERLAP_OF_NODE: f32 = 0.1;
/// ... and of the whole scene's, and taken only when it costs less than this fraction of
/// the object split (the thresholds of Embree's high-quality builder).
const OVERLAP_OF_ROOT: f32 = 5e-6;
const COST_RATIO: f32 = 0.99;
/// Most splits any one primitive may take (its budget starts between 5 and this).
const MAX_BUDGET: u32 = 31;
/// Nodes with more references than this bin in parallel chunks.
const PARALLEL_THRESHOLD: usize = 1 << 14;

/// What the builder needs to cut triangles.
pub struct Splitter<'a> {
    /// The corners of triangle `id` (ids below `first_sphere`).
    pub triangle: &'a (dyn Fn(u32) -> [Vec3; 3] + Sync),
    /// Ids from here on are spheres, never cut.
    pub first_sphere: u32,
    /// Half the surface area of the whole scene's box.
    pub root_half_area: f32,
    /// Nodes of at most this many references are never split spatially: then no subtree
    /// small enough to become one leaf of the 8-wide BVH ([`crate::bvh::CollapseOptions`]'s
    /// `max_leaf_prims`) holds two references to the same triangle.
    pub min_refs: usize,
}

/// The plane a spatial split cuts along and what the binning predicted for it.
#[derive(Clone, Copy, Debug)]
pub struct SpatialSplit {
    /// 0 = x, 1 = y, 2 = z.
    pub axis: usize,
    /// The plane's coordinate on `axis`.
    pub pos: f32,
    /// `A_left N_left + A_right N_right` (half areas).
    pub cost: f32,
    /// References left of the plane after the cut.
    pub left: usize,
    /// References right of it.
    pub right: usize,
}

/// Gives every primitive its budget of splits: 4 plus a share that grows with its box's
/// surface area relative to the average (Embree's rule: `4 + clamp(ceil(10 n A_i / A), 1,
/// 27)`); spheres get none.
pub fn init_budgets(prims: &mut [BuildPrim], first_sphere: u32) {
    use rayon::prelude::*;
    let total: f64 = prims.par_iter().map(|p| f64::from(p.bounds().half_area())).sum();
    let scale = if total > 0.0 { 10.0 * prims.len() as f64 / total } else { 0.0 };
    prims.par_iter_mut().for_each(|p| {
        let budget = if p.id() >= first_sphere {
            0
        } else {
            let share = (scale * f64::from(p.bounds().half_area())).ceil();
            4 + (share.clamp(1.0, f64::from(MAX_BUDGET - 4)) as u32)
        };
        p.set_budget(budget);
    });
}

/// Whether [`find`] is worth running for a node whose object split has boxes `left` and
/// `right` (the overlap test of Embree's builder).
pub fn worth_trying(sp: &Splitter, node: &Aabb, left: &Aabb, right: &Aabb) -> bool {
    let overlap = Aabb { min: left.min.max(right.min), max: left.max.min(right.max) };
    if !overlap.is_valid() {
        return false;
    }
    let a = overlap.half_area();
    a >= OVERLAP_OF_NODE * node.half_area() && a >= OVERLAP_OF_ROOT * sp.root_half_area
}

/// Whether a spatial split of cost `spatial` beats an object split of cost `object`.
pub fn better(spatial: f32, object: f32) -> bool {
    spatial < COST_RATIO * object
}

/// The slab mapping of one node: `SPATIAL_BINS` equal slabs of `bounds` per axis.
struct Slabs {
    lo: Vec3,
    step: Vec3,
    scale: Vec3,
}

impl Slabs {
    fn new(bounds: &Aabb) -> Self {
        let ext = bounds.extent();
        let step = ext / SPATIAL_BINS as f32;
        let scale = Vec3::select(ext.cmpgt(Vec3::ZERO), SPATIAL_BINS as f32 / ext, Vec3::ZERO);
        Self { lo: bounds.min, step, scale }
    }
    /// The slab of coordinate `x` on `axis`.
    #[inline]
    fn bin(&self, axis: usize, x: f32) -> usize {
        (((x - self.lo[axis]) * self.scale[axis]).max(0.0) as usize).min(SPATIAL_BINS - 1)
    }
    /// The plane between slabs `i - 1` and `i`.
    #[inline]
    fn plane(&self, axis: usize, i: usize) -> f32 {
        self.lo[axis] + i as f32 * self.step[axis]
    }
}

/// Per axis and slab: the bounds of the pieces in it, and how many references start and end
/// in it.
#[derive(Clone)]
struct Bins {
    bounds: [[Aabb; SPATIAL_BINS]; 3],
    enter: [[u32; SPATIAL_BINS]; 3],
    exit: [[u32; SPATIAL_BINS]; 3],
}

impl Bins {
    fn new() -> Self {
        Self { bounds: [[Aabb::EMPTY; SPATIAL_BINS]; 3], enter: [[0; SPATIAL_BINS]; 3], exit: [[0; SPATIAL_BINS]; 3] }
    }

    /// Adds `other` (exact: unions and integer sums, so the result does not depend on how
    /// the references were chunked).
    fn merge(mut self, other: &Bins) -> Bins {
        for a in 0..3 {
            for i in 0..SPATIAL_BINS {
                self.bounds[a][i] = self.bounds[a][i].union(&other.bounds[a][i]);
                self.enter[a][i] += other.enter[a][i];
                self.exit[a][i] += other.exit[a][i];
            }
        }
        self
    }

    fn bin(&mut self, sp: &Splitter, slabs: &Slabs, axes: &[usize], prims: &[BuildPrim]) {
        for p in prims {
            let b = p.bounds();
            let cuttable = p.budget() > 1 && p.id() < sp.first_sphere;
            let mut tri = None;
            for &a in axes {
                let (mut first, mut last) = (slabs.bin(a, b.min[a]), slabs.bin(a, b.max[a]));
                if !cuttable {
                    // Whole, in the slab of its centre.
                    first = slabs.bin(a, 0.5 * (b.min[a] + b.max[a]));
                    last = first;
                }
                // Only planes strictly inside the box cut it.
                while first < last && slabs.plane(a, first + 1) <= b.min[a] {
                    first += 1;
                }
                while first < last && slabs.plane(a, last) >= b.max[a] {
                    last -= 1;
                }
                if first == last {
                    self.bounds[a][first] = self.bounds[a][first].union(&b);
                    self.enter[a][first] += 1;
                    self.exit[a][first] += 1;
                    continue;
                }
                let v = *tri.get_or_insert_with(|| (sp.triangle)(p.id()));
                let mut rest = b;
                let (mut enter, mut exit) = (first, last);
                for i in first..last {
                    let (l, r) = clip_triangle(&v, &rest, a, slabs.plane(a, i + 1));
                    if l.is_valid() {
                        self.bounds[a][i] = self.bounds[a][i].union(&l);
                    } else if enter == i {
                        enter += 1;
                    }
                    rest = r;
                }
                if rest.is_valid() {
                    self.bounds[a][last] = self.bounds[a][last].union(&rest);
                } else {
                    exit = exit.saturating_sub(1).max(enter);
                }
                let enter = enter.min(exit);
                self.enter[a][enter] += 1;
                self.exit[a][exit] += 1;
            }
        }
    }
}

/// The cheapest spatial split of a node holding `prims` within `bounds`, if any plane
/// leaves references on both sides.
pub fn find(sp: &Splitter, prims: &[BuildPrim], bounds: &Aabb) -> Option<SpatialSplit> {
    let slabs = Slabs::new(bounds);
    let (mut axes, mut na) = ([0usize; 3], 0);
    for a in (0..3).filter(|&a| slabs.scale[a] > 0.0) {
        axes[na] = a;
        na += 1;
    }
    let axes = &axes[..na];
    let bins = if prims.len() < PARALLEL_THRESHOLD {
        let mut bins = Bins::new();
        bins.bin(sp, &slabs, axes, prims);
        bins
    } else {
        use rayon::prelude::*;
        prims
            .par_chunks(PARALLEL_THRESHOLD / 4)
            .map(|chunk| {
                let mut bins = Bins::new();
                bins.bin(sp, &slabs, axes, chunk);
                bins
            })
            .reduce(Bins::new, |a, b| a.merge(&b))
    };
    let mut best: Option<SpatialSplit> = None;
    for &a in axes {
        let mut right_area = [0.0f32; SPATIAL_BINS];
        let mut right_count = [0usize; SPATIAL_BINS];
        let (mut acc, mut cnt) = (Aabb::EMPTY, 0usize);
        for i in (1..SPATIAL_BINS).rev() {
            acc = acc.union(&bins.bounds[a][i]);
            cnt += bins.exit[a][i] as usize;
            right_area[i] = acc.half_area();
            right_count[i] = cnt;
        }
        let (mut acc, mut cnt) = (Aabb::EMPTY, 0usize);
        for i in 1..SPATIAL_BINS {
            acc = acc.union(&bins.bounds[a][i - 1]);
            cnt += bins.enter[a][i - 1] as usize;
            if cnt == 0 || right_count[i] == 0 {
                continue;
            }
            let cost = acc.half_area() * cnt as f32 + right_area[i] * right_count[i] as f32;
            if best.is_none_or(|b| cost < b.cost) {
                best = Some(SpatialSplit { axis: a, pos: slabs.plane(a, i), cost, left: cnt, right: right_count[i] });
            }
        }
    }
    best
}

/// Cuts every reference among the first `n` of `prims` that crosses the plane `pos` on
/// `axis` (and may still be cut) in two: the left part stays in place, the right part goes
/// to the free space after `n`, as long as there is some. Returns the new number of
/// references. Sequential, so the result does not depend on the thread count.
pub fn split_refs(sp: &Splitter, prims: &mut [BuildPrim], n: usize, axis: usize, pos: f32) -> usize {
    let mut end = n;
    for i in 0..n {
        if end == prims.len() {
            break;
        }
        let p = prims[i];
        let b = p.bounds();
        if !(b.min[axis] < pos && pos < b.max[axis]) || p.budget() <= 1 || p.id() >= sp.first_sphere {
            continue;
        }
        let (l, r) = clip_triangle(&(sp.triangle)(p.id()), &b, axis, pos);
        if !l.is_valid() || !r.is_valid() {
            continue;
        }
        let budget = p.budget() - 1;
        prims[i] = BuildPrim::with_budget(l, p.id(), budget);
        prims[end] = BuildPrim::with_budget(r, p.id(), budget);
        end += 1;
    }
    end
}

/// The bounds of the parts of triangle `v` on either side of the plane `pos` on `axis`,
/// each clipped to `b` (an empty box where nothing of it lies inside `b` on that side).
/// A corner on the plane belongs to both sides; where an edge crosses it, the crossing point
/// (with its `axis` coordinate set to `pos` exactly) does.
pub fn clip_triangle(v: &[Vec3; 3], b: &Aabb, axis: usize, pos: f32) -> (Aabb, Aabb) {
    let (mut left, mut right) = (Aabb::EMPTY, Aabb::EMPTY);
    for i in 0..3 {
        let (p, q) = (v[i], v[(i + 1) % 3]);
        let (pa, qa) = (p[axis], q[axis]);
        if pa <= pos {
            left.grow(p);
        }
        if pa >= pos {
            right.grow(p);
        }
        if (pa < pos && pos < qa) || (qa < pos && pos < pa) {
            let t = ((pos - pa) / (qa - pa)).clamp(0.0, 1.0);
            let mut x = p + (q - p) * t;
            x[axis] = pos;
            left.grow(x);
            right.grow(x);
        }
    }
    let clip = |s: Aabb| Aabb { min: s.min.max(b.min), max: s.max.min(b.max) };
    (clip(left), clip(right))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_a_triangle_gives_the_bounds_of_each_side() {
        let v = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 4.0, 2.0)];
        let b = Aabb::new(Vec3::ZERO, Vec3::new(4.0, 4.0, 2.0));
        let (l, r) = clip_triangle(&v, &b, 0, 1.0);
        // Left of x = 1: the corners at x = 0 and the crossings (1, 0, 0) and (1, 3, 1.5).
        assert_eq!(l, Aabb::new(Vec3::ZERO, Vec3::new(1.0, 4.0, 2.0)));
        assert_eq!(r, Aabb::new(Vec3::new(1.0, 0.0, 0.0), Vec3::new(4.0, 3.0, 1.5)));
        // A plane beside the triangle leaves one side empty.
        let (l, r) = clip_triangle(&v, &b, 0, 5.0);
        assert_eq!(l, b);
        assert!(!r.is_valid());
        // Clipping never grows the reference's box.
        let small = Aabb::new(Vec3::ZERO, Vec3::new(2.0, 1.0, 1.0));
        let (l, r) = clip_triangle(&v, &small, 0, 1.0);
        assert!(small.contains_box(&l) && small.contains_box(&r));
    }
}
