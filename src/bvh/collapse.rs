//! BVH2 → BVH8 collapse chosen by the surface area heuristic, and leaf packing into SoA
//! blocks.
//!
//! The collapse is the dynamic program of Ylitie, Karras & Laine, "Efficient Incoherent Ray
//! Traversal on GPUs Through Compressed Wide BVHs" (HPG 2017), with CPU costs: for every
//! binary node `n` and slot budget `i ≤ 8` it computes the cheapest way `C(n, i)` to represent
//! the subtree of `n` as a forest of at most `i` BVH8 children, each either
//!
//! * a leaf: `A(n) · c_block · blocks(n)`, where `blocks(n)` counts the M-wide triangle (and
//!   4-wide sphere) blocks its primitives fill — so merging two half-empty binary leaves into
//!   one full block is rewarded, and splitting a block's worth of triangles is not; or
//! * an 8-wide node: `A(n) · c_node + C(left, k) + C(right, i' - k)` for the best split of the
//!   8 slots between the two binary children.
//!
//! Binary leaves are atomic (never split), so leaves hold at most `max(binary leaf size,
//! max_leaf_prims)` primitives. A binary leaf holding both triangles and spheres is split by
//! kind into two virtual leaves first (their padded boxes stay inside the parent's, because
//! [`pad_outward`] is monotone). The greedy alternative (repeatedly open the child of largest
//! area, as Embree's BVH8 builder does) is kept for comparison: on the Stanford dragon
//! (871k triangles, M = 4, 1 thread, best of 7, Mrays/s, single-ray kernel) it gives SAH cost
//! 17.4 against 16.0, 46% against 71% of block lanes used, 130 against 71 bytes per triangle,
//! and 7.6 / 1.7 / 2.4 against 9.0 / 2.2 / 3.0 on camera / diffuse / shadow rays. The dynamic
//! program takes 0.24 s on that mesh (one thread).

use crate::bvh::build_sah::pad_outward;
use crate::bvh::node::{Bvh8Node, LeafKind, NodeRef};
use crate::bvh::{Bvh2, Bvh8};
use crate::geometry::{Sphere4, TriBlock, TriangleTest};
use crate::math::{Aabb, Vec3};

/// The shape of one primitive, as the collapse needs it to fill leaf blocks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PrimShape {
    /// A triangle's corners.
    Triangle([Vec3; 3]),
    /// A sphere's centre and radius.
    Sphere(Vec3, f32),
}

/// How the BVH8 is formed from the binary tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum CollapseMethod {
    /// SAH-optimal dynamic program (the default).
    #[default]
    Optimal,
    /// Greedy: open the largest-area child until eight slots are used; binary leaves become
    /// BVH8 leaves unchanged.
    Greedy,
}

/// Costs and limits of the collapse.
///
/// The defaults were measured on the Stanford dragon (871k triangles, M = 8, 1 thread, best
/// of 9, Mrays/s for 16-ray packets on camera / diffuse / shadow rays, interleaved in one
/// process): `block_cost` 1.0 and at most 8 primitives per merged leaf: 33.4 / 3.47 / 9.96 with
/// 73 bytes per triangle; 0.7 and 16: 34.0 / 3.56 / 10.30 with 68 bytes per triangle; 0.5 and
/// 24: no faster (33.98 / 3.04 / 7.89 against 33.84 / 3.06 / 7.79 in another run) at 63 bytes
/// per triangle. Costs of 1.5 for blocks or for nodes were slower by 3 to 10%.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CollapseOptions {
    /// Which algorithm.
    pub method: CollapseMethod,
    /// Cost of testing one ray against the eight boxes of a node.
    pub node_cost: f32,
    /// Cost of testing one ray against one leaf block.
    pub block_cost: f32,
    /// Additional cost per primitive of a leaf: packets test a leaf triangle by triangle
    /// (all rays against one), so their leaf cost grows with the primitive count, not the
    /// block count. 0 by default: 0.05 and 0.15 sped 16-ray packets up on the CS184 CBbunny
    /// (camera rays 65.3 / 69.0 against 61.3 Mrays/s) but slowed them down on the Stanford
    /// dragon (36.3 / 30.1 against 37.9; 73 / 97 MB against 59 MB), and the frustum culling of
    /// leaf triangles in the packet kernels now removes most of the CBbunny gap.
    pub prim_cost: f32,
    /// Largest number of primitives the collapse may merge into one leaf (binary leaves
    /// larger than this stay as they are).
    pub max_leaf_prims: usize,
}

impl Default for CollapseOptions {
    fn default() -> Self {
        Self { method: CollapseMethod::Optimal, node_cost: 1.0, block_cost: 0.7, prim_cost: 0.0, max_leaf_prims: 16 }
    }
}

/// A node of the intermediate binary tree: the BVH2 with mixed leaves split by kind.
#[derive(Clone, Copy, Debug)]
struct CNode {
    bounds: Aabb,
    /// Children (inner nodes), or `u32::MAX` for leaves.
    left: u32,
    right: u32,
    /// The subtree's primitives are `ids[start .. start + ntri + nsph]`.
    start: u32,
    ntri: u32,
    nsph: u32,
}

impl CNode {
    fn is_leaf(&self) -> bool {
        self.left == u32::MAX
    }
    fn count(&self) -> u32 {
        self.ntri + self.nsph
    }
}

struct Binary {
    nodes: Vec<CNode>,
    ids: Vec<u32>,
}

/// Converts the BVH2 into the intermediate tree (pre-order: children after parents).
fn binary_tree(bvh2: &Bvh2, shape: &(impl Fn(u32) -> PrimShape + Sync)) -> Binary {
    let mut out = Binary { nodes: Vec::with_capacity(bvh2.nodes.len() + 16), ids: bvh2.prim_ids.clone() };
    if bvh2.is_empty() {
        return out;
    }
    let is_sphere = |id: u32| matches!(shape(id), PrimShape::Sphere(..));
    fn rec(bvh2: &Bvh2, n: usize, out: &mut Binary, is_sphere: &dyn Fn(u32) -> bool, shape: &dyn Fn(u32) -> PrimShape) {
        let node = bvh2.nodes[n];
        let me = out.nodes.len();
        out.nodes.push(CNode { bounds: node.bounds, left: u32::MAX, right: u32::MAX, start: 0, ntri: 0, nsph: 0 });
        if node.is_leaf() {
            let (s, c) = (node.start as usize, node.count as usize);
            let ids = &mut out.ids[s..s + c];
            // Triangles first, then spheres, each in their original order.
            ids.sort_by_key(|&id| is_sphere(id));
            let nsph = ids.iter().filter(|&&id| is_sphere(id)).count() as u32;
            let ntri = c as u32 - nsph;
            out.nodes[me].start = s as u32;
            out.nodes[me].ntri = ntri;
            out.nodes[me].nsph = nsph;
            if ntri > 0 && nsph > 0 {
                let part = |ids: &[u32]| {
                    let b = ids.iter().fold(Aabb::EMPTY, |b, &id| b.union(&shape_bounds(shape(id))));
                    pad_outward(&b)
                };
                let tri_b = part(&out.ids[s..s + ntri as usize]);
                let sph_b = part(&out.ids[s + ntri as usize..s + c]);
                let l = out.nodes.len() as u32;
                out.nodes.push(CNode {
                    bounds: tri_b,
                    left: u32::MAX,
                    right: u32::MAX,
                    start: s as u32,
                    ntri,
                    nsph: 0,
                });
                out.nodes.push(CNode {
                    bounds: sph_b,
                    left: u32::MAX,
                    right: u32::MAX,
                    start: s as u32 + ntri,
                    ntri: 0,
                    nsph,
                });
                out.nodes[me].left = l;
                out.nodes[me].right = l + 1;
            }
        } else {
            let l = out.nodes.len() as u32;
            rec(bvh2, node.start as usize, out, is_sphere, shape);
            let r = out.nodes.len() as u32;
            rec(bvh2, node.start as usize + 1, out, is_sphere, shape);
            let (a, b) = (out.nodes[l as usize], out.nodes[r as usize]);
            let n = &mut out.nodes[me];
            n.left = l;
            n.right = r;
            n.start = a.start.min(b.start);
            n.ntri = a.ntri + b.ntri;
            n.nsph = a.nsph + b.nsph;
        }
    }
    rec(bvh2, 0, &mut out, &is_sphere, shape);
    out
}

fn shape_bounds(s: PrimShape) -> Aabb {
    match s {
        PrimShape::Triangle([a, b, c]) => {
            let mut bb = Aabb::from_point(a);
            bb.grow(b);
            bb.grow(c);
            bb
        }
        PrimShape::Sphere(c, r) => Aabb { min: c - Vec3::splat(r), max: c + Vec3::splat(r) },
    }
}

/// The dynamic program's decisions for one binary node.
#[derive(Clone, Copy, Debug, Default)]
struct Plan {
    /// As a single forest root: a leaf (`true`) or an 8-wide node.
    as_leaf: bool,
    /// As an 8-wide node: slots given to the left child's forest (the right gets the rest).
    node_split: u8,
    /// Best forest of at most `i + 1` roots: `(slots to the left child, slots used)`;
    /// `(0, 1)` keeps the node as a single root.
    forest: [(u8, u8); 8],
}

fn plan(tree: &Binary, opts: &CollapseOptions, block_m: usize) -> Vec<Plan> {
    let n = tree.nodes.len();
    // cost[n][i] = C(n, i + 1): cheapest forest of at most i + 1 roots for n's subtree.
    let mut cost = vec![[f32::INFINITY; 8]; n];
    let mut plans = vec![Plan::default(); n];
    let blocks = |c: &CNode| c.ntri.div_ceil(block_m as u32) + c.nsph.div_ceil(Sphere4::M as u32);
    for i in (0..n).rev() {
        let node = tree.nodes[i];
        let area = node.bounds.half_area();
        let single_kind = node.ntri == 0 || node.nsph == 0;
        let leaf_ok = single_kind && (node.is_leaf() || node.count() as usize <= opts.max_leaf_prims);
        let leaf_cost = if leaf_ok {
            area * (opts.block_cost * blocks(&node) as f32 + opts.prim_cost * node.count() as f32)
        } else {
            f32::INFINITY
        };
        if node.is_leaf() {
            cost[i] = [leaf_cost; 8];
            plans[i] = Plan { as_leaf: true, node_split: 0, forest: [(0, 1); 8] };
            continue;
        }
        let (l, r) = (node.left as usize, node.right as usize);
        // dist[j]: cheapest split of j + 1 slots between the children (each gets >= 1).
        let mut dist = [f32::INFINITY; 8];
        let mut dist_k = [0u8; 8];
        for j in 1..8 {
            for k in 1..=j {
                let c = cost[l][k - 1] + cost[r][j - k];
                if c < dist[j] {
                    dist[j] = c;
                    dist_k[j] = k as u8;
                }
            }
        }
        let node_cost = area * opts.node_cost + dist[7];
        let p = &mut plans[i];
        p.as_leaf = leaf_cost <= node_cost;
        p.node_split = dist_k[7];
        cost[i][0] = leaf_cost.min(node_cost);
        p.forest[0] = (0, 1);
        for j in 1..8 {
            if dist[j] < cost[i][j - 1] {
                cost[i][j] = dist[j];
                p.forest[j] = (dist_k[j], j as u8 + 1);
            } else {
                cost[i][j] = cost[i][j - 1];
                p.forest[j] = p.forest[j - 1];
            }
        }
    }
    plans
}

/// Appends the roots of the best forest of at most `slots` roots for `n`'s subtree.
fn forest(tree: &Binary, plans: &[Plan], n: usize, slots: usize, out: &mut Vec<usize>) {
    let (k, used) = plans[n].forest[slots - 1];
    if k == 0 {
        out.push(n);
    } else {
        let node = tree.nodes[n];
        forest(tree, plans, node.left as usize, k as usize, out);
        forest(tree, plans, node.right as usize, used as usize - k as usize, out);
    }
}

/// Greedy plan: every inner node is a BVH8 node, every binary leaf a BVH8 leaf; a node's
/// children come from opening the largest-area inner descendant until 8 slots are used.
fn greedy_forest(tree: &Binary, n: usize, out: &mut Vec<usize>) {
    let node = tree.nodes[n];
    out.clear();
    out.extend([node.left as usize, node.right as usize]);
    while out.len() < 8 {
        let best = out
            .iter()
            .enumerate()
            .filter(|(_, c)| !tree.nodes[**c].is_leaf())
            .max_by(|a, b| tree.nodes[*a.1].bounds.half_area().total_cmp(&tree.nodes[*b.1].bounds.half_area()));
        let Some((pos, &c)) = best else { break };
        let cn = tree.nodes[c];
        out[pos] = cn.left as usize;
        out.push(cn.right as usize);
    }
}

struct Emitter<'a, T, S> {
    tree: &'a Binary,
    plans: &'a [Plan],
    method: CollapseMethod,
    shape: &'a S,
    out: Bvh8<T>,
}

impl<T: TriBlock, S: Fn(u32) -> PrimShape> Emitter<'_, T, S> {
    fn is_leaf_root(&self, c: usize) -> bool {
        match self.method {
            CollapseMethod::Optimal => self.plans[c].as_leaf,
            CollapseMethod::Greedy => self.tree.nodes[c].is_leaf(),
        }
    }

    fn children_of(&self, n: usize) -> Vec<usize> {
        let mut v = Vec::with_capacity(8);
        match self.method {
            CollapseMethod::Optimal => {
                let node = self.tree.nodes[n];
                let k = self.plans[n].node_split as usize;
                forest(self.tree, self.plans, node.left as usize, k, &mut v);
                forest(self.tree, self.plans, node.right as usize, 8 - k, &mut v);
            }
            CollapseMethod::Greedy => greedy_forest(self.tree, n, &mut v),
        }
        v
    }

    fn leaf(&mut self, c: usize) -> NodeRef {
        let node = self.tree.nodes[c];
        let ids = &self.tree.ids[node.start as usize..(node.start + node.count()) as usize];
        if node.nsph == 0 {
            let first = self.out.tris.len();
            for chunk in ids.chunks(T::M) {
                let mut b = T::EMPTY;
                for (lane, &id) in chunk.iter().enumerate() {
                    let PrimShape::Triangle([a, bb, cc]) = (self.shape)(id) else { unreachable!("triangle leaf") };
                    b.set_for(self.out.test, lane, a, bb, cc, id);
                }
                self.out.tris.push(b);
            }
            NodeRef::leaf(LeafKind::Triangles, first as u32, self.out.tris.len() - first, (ids.len() - 1) % T::M + 1)
        } else {
            let first = self.out.spheres.len();
            for chunk in ids.chunks(Sphere4::M) {
                let mut b = Sphere4::EMPTY;
                for (lane, &id) in chunk.iter().enumerate() {
                    let PrimShape::Sphere(center, r) = (self.shape)(id) else { unreachable!("sphere leaf") };
                    b.set(lane, center, r, id);
                }
                self.out.spheres.push(b);
            }
            NodeRef::leaf(
                LeafKind::Spheres,
                first as u32,
                self.out.spheres.len() - first,
                (ids.len() - 1) % Sphere4::M + 1,
            )
        }
    }

    /// Fills node `index` from binary node `n`, allocating the inner children's nodes
    /// consecutively (siblings adjacent) before descending into them.
    fn fill(&mut self, index: usize, n: usize) {
        let kids = self.children_of(n);
        debug_assert!(kids.len() <= 8);
        let first_inner = self.out.nodes.len();
        let inner_count = kids.iter().filter(|&&c| !self.is_leaf_root(c)).count();
        self.out.nodes.resize(first_inner + inner_count, Bvh8Node::EMPTY);
        let mut next = first_inner;
        let mut todo = Vec::with_capacity(inner_count);
        for (slot, &c) in kids.iter().enumerate() {
            let r = if self.is_leaf_root(c) {
                self.leaf(c)
            } else {
                todo.push((next, c));
                next += 1;
                NodeRef::inner((next - 1) as u32)
            };
            let b = self.tree.nodes[c].bounds;
            self.out.nodes[index].set_child(slot, &b, r);
        }
        for (i, c) in todo {
            self.fill(i, c);
        }
    }
}

/// Collapses `bvh2` into an 8-wide BVH with leaf blocks of `T` laid out for
/// Möller–Trumbore. `shape(id)` gives the geometry of primitive `id`.
pub fn collapse<T: TriBlock>(bvh2: &Bvh2, shape: impl Fn(u32) -> PrimShape + Sync, opts: &CollapseOptions) -> Bvh8<T> {
    collapse_for(bvh2, shape, opts, TriangleTest::MollerTrumbore)
}

/// [`collapse()`] with leaf blocks laid out for triangle test `test`.
pub fn collapse_for<T: TriBlock>(
    bvh2: &Bvh2,
    shape: impl Fn(u32) -> PrimShape + Sync,
    opts: &CollapseOptions,
    test: TriangleTest,
) -> Bvh8<T> {
    let tree = binary_tree(bvh2, &shape);
    let out = Bvh8 { nodes: vec![Bvh8Node::EMPTY], tris: Vec::new(), spheres: Vec::new(), test };
    if tree.nodes.is_empty() {
        return out;
    }
    let plans = if opts.method == CollapseMethod::Optimal { plan(&tree, opts, T::M) } else { Vec::new() };
    let mut em = Emitter { tree: &tree, plans: &plans, method: opts.method, shape: &shape, out };
    if tree.nodes[0].is_leaf() || em.is_leaf_root(0) {
        let r = em.leaf(0);
        let b = tree.nodes[0].bounds;
        em.out.nodes[0].set_child(0, &b, r);
    } else {
        em.fill(0, 0);
    }
    em.out
}
