//! Proof that an acceleration structure describes its scene: whatever wrote it (a build, a
//! cache file, a pickle), a tree that passes [`verify_accel`] gives every ray the same closest
//! hit and the same occlusion answer as a build of the same geometry would (its speed is
//! another matter: see [`crate::scene::cache`]'s trust rule).
//!
//! What is checked, besides the index checks of [`crate::bvh::validate`] (every reference in
//! range, each node reached once, depth bounded, empty slots never hit):
//!
//! * every leaf block is exactly what the builder would store for the primitives it names:
//!   each live lane holds the scene's own triangle (or sphere) under its id, laid out for the
//!   tree's triangle test, and every padding lane is the builder's inert padding;
//! * every child box of a node lies inside the parent's box of that child;
//! * every primitive is referenced by a leaf, and lies inside the boxes of the leaves that
//!   reference it: inside one of them whole, or (a triangle cut by spatial splits) inside
//!   their union, which is checked by clipping the triangle against each box in turn;
//! * the scene's bounds are the union of its primitives' boxes.
//!
//! A ray that hits a primitive passes through every box on the path from the root to a leaf
//! holding it (or the part of it the ray hits), so the traversal reaches it, and the leaf
//! tests the scene's own primitive. One pass over the nodes and one over the blocks, in
//! parallel: far cheaper than a build (PERFORMANCE.md, "Verifying a loaded tree").

use crate::bvh::bvh8::prefetch_line;
use crate::bvh::node::LeafKind;
use crate::bvh::validate::{check_bvh2_indices, check_bvh8_indices};
use crate::bvh::{Bvh2, Bvh8};
use crate::geometry::{Sphere4, TriBlock, TriangleTest};
use crate::math::{Aabb, Vec3};
use crate::scene::{SpheresSoa, TrianglesSoa};
use rayon::prelude::*;

/// Why an acceleration structure does not describe its scene: the first violation found.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct AccelError(pub String);

fn fail<T>(what: String) -> Result<T, AccelError> {
    Err(AccelError(what))
}

/// Checks that `bvh8` (and `bvh2`, when given) over `triangles` and `spheres` (ids: triangles
/// first, then spheres) with scene bounds `bounds` traces exactly as a build would (see the
/// module docs). Linear in the tree and the primitives, and parallel.
pub fn verify_accel<T: TriBlock>(
    triangles: &TrianglesSoa,
    spheres: &SpheresSoa,
    bounds: &Aabb,
    bvh2: Option<&Bvh2>,
    bvh8: &Bvh8<T>,
) -> Result<(), AccelError> {
    let geometry = Geometry { triangles, spheres, nt: triangles.len() };
    let n = geometry.len();
    if let Some(b) = bvh2 {
        check_bvh2_indices(b, n).map_err(|e| AccelError(format!("binary BVH: {e}")))?;
    }
    check_bvh8_indices(bvh8, n).map_err(|e| AccelError(format!("8-wide BVH: {e}")))?;
    let union = check_bvh8(&geometry, bvh8).map_err(|e| AccelError(format!("8-wide BVH: {e}")))?;
    // Every primitive is in a block (checked), so the blocks' union is the primitives'.
    if bytemuck::bytes_of(&union) != bytemuck::bytes_of(bounds) {
        return fail(format!("the scene bounds {bounds:?} are not its primitives' union {union:?}"));
    }
    if let Some(b) = bvh2 {
        check_bvh2_boxes(&geometry, b).map_err(|e| AccelError(format!("binary BVH: {e}")))?;
    }
    Ok(())
}

impl crate::Scene {
    /// [`verify_accel`] of this scene's own trees: whether they trace exactly as a build of
    /// its geometry would (for trees that did not come from a build in this process).
    pub fn verify_accel(&self) -> Result<(), AccelError> {
        if self.bvh8.ids.is_empty() {
            verify_accel(&self.triangles, &self.spheres, &self.bounds, self.bvh2.as_ref(), &self.bvh8)
        } else {
            // A compact tree as the blocks its ids name: the tree the kernels trace.
            let blocks = crate::scene::cache::stored_blocks(self).into_owned();
            let b8 = crate::bvh::Bvh8 { tris: blocks.into(), ids: Default::default(), ..self.bvh8.clone() };
            verify_accel(&self.triangles, &self.spheres, &self.bounds, self.bvh2.as_ref(), &b8)
        }
    }
}

/// The primitives a tree refers to by id.
struct Geometry<'a> {
    triangles: &'a TrianglesSoa,
    spheres: &'a SpheresSoa,
    nt: usize,
}

impl Geometry<'_> {
    fn len(&self) -> usize {
        self.nt + self.spheres.len()
    }

    /// The box of primitive `p` (below [`Geometry::len`]), as the builder computes it.
    fn bounds(&self, p: usize) -> Aabb {
        if p < self.nt { self.triangles.bounds(p) } else { self.spheres.bounds(p - self.nt) }
    }
}

/// Which primitives lie whole inside a leaf that references them; the other references are
/// collected as (primitive id, leaf box that does not hold it whole).
struct Coverage {
    whole: Vec<std::sync::atomic::AtomicBool>,
}

impl Coverage {
    fn new(n: usize) -> Self {
        Self { whole: (0..n).map(|_| Default::default()).collect() }
    }

    /// Records the `claims` on one block, whose lane `l` holds primitive `lane(l).0` with box
    /// `lane(l).1`; returns the references that do not hold their primitive whole.
    fn claimed(&self, claims: &[Claim], lane: impl Fn(usize) -> (u32, Aabb)) -> Vec<(u32, Aabb)> {
        let mut parts = Vec::new();
        for c in claims {
            for l in crate::simd::bits(c.lanes) {
                let (p, b) = lane(l);
                if p == u32::MAX {
                    continue;
                }
                if c.leaf.contains_box(&b) {
                    self.whole[p as usize].store(true, std::sync::atomic::Ordering::Relaxed);
                } else {
                    parts.push((p, c.leaf));
                }
            }
        }
        parts
    }

    /// Every primitive lies in the leaves that reference it: whole in one, or (a triangle)
    /// inside the union of the boxes of `parts`, its other references.
    fn finish(self, g: &Geometry, mut parts: Vec<(u32, Aabb)>) -> Result<(), AccelError> {
        use std::sync::atomic::Ordering::Relaxed;
        parts.par_sort_unstable_by_key(|&(p, _)| p);
        let groups: Vec<&[(u32, Aabb)]> = parts.chunk_by(|a, b| a.0 == b.0).collect();
        let whole = &self.whole;
        groups.par_iter().try_for_each(|refs| {
            let p = refs[0].0;
            if whole[p as usize].load(Relaxed) {
                return Ok(());
            }
            let boxes: Vec<Aabb> = refs.iter().map(|r| r.1).collect();
            if (p as usize) < g.nt && triangle_covered(g.triangles.vertices(p as usize), &boxes) {
                whole[p as usize].store(true, Relaxed);
                return Ok(());
            }
            fail(format!("primitive {p} is not inside the leaves that reference it"))
        })?;
        match whole.par_iter().position_any(|w| !w.load(Relaxed)) {
            Some(p) => fail(format!("primitive {p} is in no leaf")),
            None => Ok(()),
        }
    }
}

/// Triangle blocks whose primitives are fetched into the cache together.
const PREFETCH_BLOCKS: usize = 8;

/// A leaf's claim on lanes of a block: the lanes and the leaf's box.
#[derive(Clone, Copy)]
struct Claim {
    block: u32,
    lanes: u32,
    leaf: Aabb,
}

/// Child boxes inside their parents', blocks equal to what the builder makes from the scene's
/// primitives under the ids their lanes name (triangles laid out for `bvh8.test`, padding
/// inert), primitives inside the leaves that reference them (see the module docs). Returns
/// the union of the primitives' boxes.
fn check_bvh8<T: TriBlock>(g: &Geometry, bvh8: &Bvh8<T>) -> Result<Aabb, AccelError> {
    let nodes = &bvh8.nodes;
    let mut reached = vec![false; nodes.len()];
    reached[0] = true;
    // The leaves' claims on the blocks, per kind.
    let (mut tri_claims, mut sphere_claims) = (Vec::new(), Vec::new());
    // The index checks put children after their parents: one pass in index order.
    for i in 0..nodes.len() {
        if !reached[i] {
            continue;
        }
        let n = &nodes[i];
        for (slot, &c) in n.children.iter().enumerate() {
            if c.is_empty() {
                continue;
            }
            let leaf = n.child_bounds(slot);
            if !c.is_leaf() {
                let j = c.node_index();
                reached[j] = true;
                if !leaf.contains_box(&nodes[j].bounds()) {
                    return fail(format!("slot {slot} of node {i} does not contain its child node {j}"));
                }
                continue;
            }
            let (claims, m) = match c.kind() {
                LeafKind::Triangles => (&mut tri_claims, T::M),
                LeafKind::Spheres => (&mut sphere_claims, Sphere4::M),
            };
            for (k, block) in c.blocks().enumerate() {
                claims.push(Claim { block: block as u32, lanes: c.lane_mask(k, m), leaf });
            }
        }
    }
    // By block (a counting sort), with where each block's claims start.
    let (tri_claims, tri_starts) = by_block(&tri_claims, bvh8.tris.len());
    let (sphere_claims, sphere_starts) = by_block(&sphere_claims, bvh8.spheres.len());
    let cover = Coverage::new(g.len());
    let test: TriangleTest = bvh8.test;
    // Per block: what the builder would store, compared byte for byte; then each claimed
    // lane's primitive against the claiming leaf's box.
    // Blocks in groups whose triangles' indices, then corners, are fetched ahead: in leaf
    // order they are scattered over the mesh, and waiting on each in turn took most of the time.
    let tris = bvh8.tris.par_chunks(PREFETCH_BLOCKS).enumerate().flat_map_iter(|(chunk, blocks)| {
        let lanes = || blocks.iter().flat_map(|b| (0..T::M).map(|l| b.prim(l) as usize));
        lanes().for_each(|p| g.triangles.prefetch_indices(p));
        for p in lanes() {
            for &v in g.triangles.indices.get(p).into_iter().flatten() {
                if let Some(x) = g.triangles.positions.get(v as usize) {
                    prefetch_line((x as *const Vec3).cast());
                }
            }
        }
        blocks.iter().enumerate().map(move |(i, block)| (chunk * PREFETCH_BLOCKS + i, block))
    });
    let tris = tris.map(|(k, block)| {
        let mut want = T::EMPTY;
        let mut boxes = [Aabb::EMPTY; 16];
        let mut union = Aabb::EMPTY;
        for (lane, lane_box) in boxes.iter_mut().enumerate().take(T::M) {
            let p = block.prim(lane);
            if p == u32::MAX {
                continue;
            }
            if p as usize >= g.nt {
                return fail(format!("triangle block {k} lane {lane} names primitive {p}, which is not a triangle"));
            }
            let [a, b, c] = g.triangles.vertices(p as usize);
            want.set_for(test, lane, a, b, c, p);
            *lane_box = Aabb::of_triangle([a, b, c]);
            union = union.union(lane_box);
        }
        if bytemuck::bytes_of(&want) != bytemuck::bytes_of(block) {
            let lane = (0..T::M).find(|&l| want.lane_rows(l) != block.lane_rows(l)).unwrap_or(0);
            return fail(format!(
                "triangle block {k} lane {lane} does not hold the scene's triangle {} (or its padding)",
                block.prim(lane)
            ));
        }
        let claims = &tri_claims[tri_starts[k] as usize..tri_starts[k + 1] as usize];
        let parts = cover.claimed(claims, |lane| (block.prim(lane), boxes[lane]));
        Ok((union, parts))
    });
    let spheres = bvh8.spheres.par_iter().enumerate().map(|(k, block)| {
        let mut want = Sphere4::EMPTY;
        let mut boxes = [Aabb::EMPTY; 4];
        let mut union = Aabb::EMPTY;
        for (lane, lane_box) in boxes.iter_mut().enumerate() {
            let p = block.prim[lane];
            if p == u32::MAX {
                continue;
            }
            let Some(i) = (p as usize).checked_sub(g.nt).filter(|&i| i < g.spheres.len()) else {
                return fail(format!("sphere block {k} lane {lane} names primitive {p}, which is not a sphere"));
            };
            want.set(lane, g.spheres.center[i], g.spheres.radius[i], p);
            *lane_box = g.spheres.bounds(i);
            union = union.union(lane_box);
        }
        if bytemuck::bytes_of(&want) != bytemuck::bytes_of(block) {
            return fail(format!("sphere block {k} does not hold the scene's spheres (or their padding)"));
        }
        let claims = &sphere_claims[sphere_starts[k] as usize..sphere_starts[k + 1] as usize];
        let parts = cover.claimed(claims, |lane| (block.prim[lane], boxes[lane]));
        Ok((union, parts))
    });
    let merge = |a: Result<(Aabb, Vec<(u32, Aabb)>), AccelError>, b: Result<(Aabb, Vec<(u32, Aabb)>), AccelError>| {
        let ((ua, mut pa), (ub, pb)) = (a?, b?);
        pa.extend(pb);
        Ok((ua.union(&ub), pa))
    };
    let empty = || Ok((Aabb::EMPTY, Vec::new()));
    let (union, parts) = merge(tris.reduce(empty, merge), spheres.reduce(empty, merge))?;
    cover.finish(g, parts)?;
    Ok(union)
}

/// `claims` on `blocks` blocks ordered by block, and where each block's start: block `k`'s are
/// `starts[k] .. starts[k + 1]`.
fn by_block(claims: &[Claim], blocks: usize) -> (Vec<Claim>, Vec<u32>) {
    let mut starts = vec![0u32; blocks + 1];
    for c in claims {
        starts[c.block as usize + 1] += 1;
    }
    for k in 0..blocks {
        starts[k + 1] += starts[k];
    }
    let mut next = starts.clone();
    let mut sorted = claims.to_vec();
    for c in claims {
        let at = &mut next[c.block as usize];
        sorted[*at as usize] = *c;
        *at += 1;
    }
    (sorted, starts)
}

/// [`check_bvh8`]'s boxes for the binary BVH: child boxes inside their parents', primitives
/// inside the leaves that reference them.
fn check_bvh2_boxes(g: &Geometry, bvh2: &Bvh2) -> Result<(), AccelError> {
    let nodes = &bvh2.nodes;
    let cover = Coverage::new(g.len());
    let mut parts = Vec::new();
    if bvh2.prim_ids.is_empty() {
        return cover.finish(g, parts);
    }
    let mut reached = vec![false; nodes.len()];
    reached[0] = true;
    for i in 0..nodes.len() {
        if !reached[i] {
            continue;
        }
        let n = &nodes[i];
        let (start, count) = (n.start as usize, n.count as usize);
        if n.is_leaf() {
            let ids = &bvh2.prim_ids[start..start + count];
            let claim = [Claim { block: 0, lanes: u32::MAX, leaf: n.bounds }];
            for chunk in ids.chunks(32) {
                let lanes = claim.map(|c| Claim { lanes: (u64::MAX >> (64 - chunk.len())) as u32, ..c });
                parts.extend(cover.claimed(&lanes, |l| (chunk[l], g.bounds(chunk[l] as usize))));
            }
            continue;
        }
        for c in [start, start + 1] {
            reached[c] = true;
            if !n.bounds.contains_box(&nodes[c].bounds) {
                return fail(format!("node {i} does not contain its child {c}"));
            }
        }
    }
    cover.finish(g, parts)
}

/// Most pieces a triangle is cut into while it is checked against a union of boxes; a
/// triangle that needs more is reported as not covered (spatial splits cut a triangle into
/// at most 32 references, whose boxes leave nothing outside).
const MAX_PIECES: usize = 4096;

/// A convex polygon in `f64`.
type Polygon = Vec<[f64; 3]>;

/// True when the triangle `tri` lies inside the union of `boxes`: it is cut by each box in turn
/// (Sutherland–Hodgman against the box's six planes), keeping only the pieces outside, and
/// nothing of positive area may remain.
fn triangle_covered(tri: [Vec3; 3], boxes: &[Aabb]) -> bool {
    let corner = |v: Vec3| [f64::from(v.x), f64::from(v.y), f64::from(v.z)];
    let tri = tri.map(corner);
    let whole = area(&tri.to_vec());
    // Pieces smaller than this are rounding, not surface: 2^-40 of the triangle (the box
    // coordinates are f32, exact in f64; the clipped corners are within a few f64 ulps).
    let tiny = whole * f64::powi(2.0, -40);
    let mut pieces: Vec<Polygon> = vec![tri.to_vec()];
    for b in boxes {
        let (lo, hi) = (corner(b.min), corner(b.max));
        if !(0..3).all(|a| lo[a] <= hi[a]) {
            continue;
        }
        let mut outside = Vec::new();
        for mut p in pieces {
            for axis in 0..3 {
                // The parts below the box's lower plane and above its upper one are outside
                // it; go on with the rest.
                let (below, rest) = split(&p, axis, lo[axis], true);
                let (above, rest) = split(&rest, axis, hi[axis], false);
                outside.extend([below, above]);
                p = rest;
            }
        }
        pieces = outside.into_iter().filter(|p| p.len() >= 3 && area(p) > tiny).collect();
        if pieces.is_empty() {
            return true;
        }
        if pieces.len() > MAX_PIECES {
            return false;
        }
    }
    pieces.is_empty()
}

/// `p` clipped to the closed half-space `x[axis] <= at` (`below`) or `x[axis] >= at`.
fn clip(p: &Polygon, axis: usize, at: f64, below: bool) -> Polygon {
    let side = |v: &[f64; 3]| if below { at - v[axis] } else { v[axis] - at };
    let mut out = Vec::with_capacity(p.len() + 1);
    for (i, a) in p.iter().enumerate() {
        let b = &p[(i + 1) % p.len()];
        let (da, db) = (side(a), side(b));
        if da >= 0.0 {
            out.push(*a);
        }
        if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
            let s = da / (da - db);
            let mut x = [0.0; 3];
            for k in 0..3 {
                x[k] = a[k] + s * (b[k] - a[k]);
            }
            x[axis] = at;
            out.push(x);
        }
    }
    out
}

/// The part of `p` strictly beyond the plane `x[axis] = at` (below it, or above it), and the
/// rest, which keeps the plane: a polygon lying in the plane is wholly in the rest.
fn split(p: &Polygon, axis: usize, at: f64, below: bool) -> (Polygon, Polygon) {
    let beyond = |v: &[f64; 3]| if below { v[axis] < at } else { v[axis] > at };
    if !p.iter().any(beyond) {
        return (Vec::new(), p.clone());
    }
    (clip(p, axis, at, below), clip(p, axis, at, !below))
}

/// The area of the planar convex polygon `p`.
fn area(p: &Polygon) -> f64 {
    let mut n = [0.0f64; 3];
    for i in 1..p.len().saturating_sub(1) {
        let (a, b, c) = (p[0], p[i], p[i + 1]);
        let (u, v) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
        n[0] += u[1] * v[2] - u[2] * v[1];
        n[1] += u[2] * v[0] - u[0] * v[2];
        n[2] += u[0] * v[1] - u[1] * v[0];
    }
    0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::{BuildOptions, BuildQuality};
    use crate::{Material, SceneBuilder};

    /// Long thin triangles across a cube in random directions: where High quality's spatial
    /// splits cut triangles into several references.
    fn slivers(n: usize) -> crate::generate::Mesh {
        let mut rng = crate::rng::Rng::new(5, 7);
        let mut m = crate::generate::Mesh::default();
        for i in 0..n as u32 {
            let mut r3 = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
            let a = r3();
            let (b, c) = (-a + r3() * 0.1, a + r3() * 0.05);
            m.positions.extend([a, b, c]);
            m.indices.push([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        m
    }

    #[test]
    fn every_build_verifies() {
        let knot = crate::generate::torus_knot(200, 12, 2.0, 3.0, 0.4, 0.05);
        let scenes: [(&str, crate::generate::Mesh, usize); 4] = [
            ("knot", knot, 0),
            ("slivers", slivers(3000), 0),
            ("knot and spheres", crate::generate::torus_knot(50, 8, 2.0, 3.0, 0.4, 0.05), 40),
            ("empty", crate::generate::Mesh::default(), 0),
        ];
        let mut split = false;
        for (name, mesh, spheres) in scenes {
            for quality in [BuildQuality::Fast, BuildQuality::Medium, BuildQuality::High] {
                for watertight in [false, true] {
                    let mut b = SceneBuilder::new();
                    let m = b.add_material(Material::default());
                    if !mesh.indices.is_empty() {
                        b.add_mesh(&mesh.positions, &mesh.indices, m).unwrap();
                    }
                    for i in 0..spheres {
                        b.add_sphere(Vec3::new(i as f32 * 0.3, 0.0, 1.0), 0.1 + 0.01 * i as f32, m).unwrap();
                    }
                    let opts = BuildOptions { quality, watertight, keep_bvh2: true, ..BuildOptions::default() };
                    let (scene, _) = b.commit(&opts);
                    let what = format!("{name}, {quality:?}, watertight {watertight}");
                    assert_eq!(scene.verify_accel(), Ok(()), "{what}");
                    let refs = scene.bvh2.as_ref().unwrap().prim_ids.len();
                    split |= refs > scene.triangles.len() + scene.spheres.len();
                }
            }
        }
        assert!(split, "no build cut a triangle: the union check went untested");
    }

    #[test]
    fn a_triangle_is_covered_by_boxes_that_hold_all_of_it_and_only_then() {
        let t = [Vec3::ZERO, Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 4.0, 0.0)];
        let b = |min: [f32; 3], max: [f32; 3]| Aabb::new(Vec3::from(min), Vec3::from(max));
        assert!(triangle_covered(t, &[b([0.0; 3], [4.0, 4.0, 0.0])]));
        // Cut at x = 1 and y = 2, as spatial splits would: the boxes of the three parts.
        let parts = [
            b([0.0, 0.0, 0.0], [1.0, 4.0, 0.0]),
            b([1.0, 0.0, 0.0], [4.0, 2.0, 0.0]),
            b([1.0, 2.0, 0.0], [2.0, 3.0, 0.0]),
        ];
        assert!(triangle_covered(t, &parts));
        // Leave out any part, or shrink one by a little, and some of the triangle is in no box.
        for skip in 0..3 {
            let some: Vec<Aabb> = (0..3).filter(|&i| i != skip).map(|i| parts[i]).collect();
            assert!(!triangle_covered(t, &some), "without part {skip}");
        }
        let mut shrunk = parts;
        shrunk[1].max.y = 1.999;
        assert!(!triangle_covered(t, &shrunk));
        // Boxes whose bounding box holds the triangle but whose union does not.
        assert!(!triangle_covered(t, &[b([0.0; 3], [1.0, 1.0, 0.0]), b([3.0, 0.0, 0.0], [4.0, 4.0, 0.0])]));
        // A triangle in a box's face is inside it; beside the face, it is not.
        assert!(triangle_covered(t, &[b([-1.0, -1.0, 0.0], [5.0, 5.0, 1.0])]));
        assert!(!triangle_covered(t, &[b([-1.0, 4.5, 0.0], [5.0, 5.0, 1.0])]));
        // Invalid or NaN boxes hold nothing.
        assert!(!triangle_covered(t, &[Aabb::EMPTY]));
        assert!(!triangle_covered(t, &[b([f32::NAN; 3], [4.0, 4.0, 0.0])]));
    }
}
