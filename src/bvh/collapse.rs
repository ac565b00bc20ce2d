// Not split: the collapse's dynamic program and the leaf packing it decides read best side by side, with their tests.
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
//! max_leaf_prims)` primitives. The triangle leaves of one node that fit in a block share
//! blocks: they are placed first fit in decreasing order of size, each in lanes of its own
//! ([`NodeRef::leaf_in_block`]), which leaves fewer padding lanes and a smaller BVH8
//! (PERFORMANCE.md, "Leaf blocks shared by a node's small leaves"). A binary leaf holding both triangles and spheres is split by
//! kind into two leaves first (their padded boxes stay inside the parent's, because
//! [`pad_outward`] is monotone); the scene's builder makes no such leaves. The greedy
//! alternative (repeatedly open the child of largest area, as Embree's BVH8 builder does) is
//! kept for comparison ([`CollapseMethod::Greedy`]; PERFORMANCE.md, "Collapse").
//!
//! (A little past 600 lines: the dynamic program, its decisions' encoding and the emission of
//! nodes and blocks that replays them are one algorithm.)

use crate::bvh::build::pad_outward;
use crate::bvh::node::{Bvh8Node, LeafKind, NodeRef};
use crate::bvh::{Bvh2, Bvh2Node, Bvh8, BvhArray};
use crate::geometry::{Sphere4, TriBlock, TriangleTest};
use crate::math::{Aabb, Vec3};
use std::borrow::Cow;
use std::sync::atomic::AtomicU64;
use std::sync::atomic::Ordering::Relaxed;

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

/// Costs and limits of the collapse. The defaults are measured (PERFORMANCE.md, "Collapse").
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
    /// block count. 0 by default (PERFORMANCE.md, "Collapse").
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

/// Most primitives a subtree may have for the emission to defer it to a parallel task is
/// `max(total / PARALLEL_EMIT_DIVISOR, 1)`: at least this many tasks for load balance, and
/// independent of the thread count, so the output is too.
const PARALLEL_EMIT_DIVISOR: u32 = 64;
/// The dynamic program runs children in parallel (`rayon::join`) down to this depth.
const PARALLEL_PLAN_DEPTH: usize = 10;

/// The dynamic program's decisions for one binary node, packed into 60 bits of a `u64`:
///
/// * bit 0: as a single forest root, a leaf (1) or an 8-wide node (0);
/// * bits 1–3: as an 8-wide node, the slots given to the left child's forest (the right
///   child's forest gets the rest of the 8);
/// * bits 4 + 7j .. 4 + 7j + 7, for `j` in `0..8`: the best forest of at most `j + 1`
///   roots, as the slots given to the left child (3 bits; 0 keeps the node as a single
///   root) and the slots used minus 1 (3 bits).
///
/// Stored in relaxed atomics so that the parallel dynamic program can write each node's
/// plan from whichever task handles it, without `unsafe`; on x86 these are plain loads and
/// stores.
#[derive(Clone, Copy, Debug, Default)]
struct Plan(u64);

impl Plan {
    fn as_leaf(self) -> bool {
        self.0 & 1 != 0
    }
    fn node_split(self) -> usize {
        (self.0 >> 1 & 7) as usize
    }
    /// `(slots to the left child, slots used)` of the best forest of at most `slots` roots.
    fn forest(self, slots: usize) -> (usize, usize) {
        let f = self.0 >> (4 + 7 * (slots - 1));
        ((f & 7) as usize, (f >> 3 & 7) as usize + 1)
    }
    fn new(as_leaf: bool, node_split: usize, forest: &[(usize, usize); 8]) -> Plan {
        let mut bits = as_leaf as u64 | (node_split as u64) << 1;
        for (j, &(k, used)) in forest.iter().enumerate() {
            bits |= (k as u64 | ((used - 1) as u64) << 3) << (4 + 7 * j);
        }
        Plan(bits)
    }
}

/// The binary tree with its per-node plans, ready for emission.
struct Planned<'a> {
    bvh2: &'a Bvh2,
    first_sphere: u32,
    plans: Vec<AtomicU64>,
    /// True when the tree holds spheres (otherwise every leaf holds triangles).
    spheres: bool,
}

impl Planned<'_> {
    fn plan(&self, n: usize) -> Plan {
        Plan(self.plans[n].load(Relaxed))
    }
    /// Primitives below `n`: its subtree's range of `prim_ids`, from the start of its
    /// leftmost leaf to the end of its rightmost (a walk of two paths, which the emission
    /// only takes for leaf roots, shallow, and near the root; an array of counts would cost
    /// 4 bytes a node of peak memory).
    fn count(&self, n: usize) -> u32 {
        let mut r = n;
        while !self.bvh2.nodes[r].is_leaf() {
            r = self.bvh2.nodes[r].start as usize + 1;
        }
        let end = self.bvh2.nodes[r].start + self.bvh2.nodes[r].count;
        end - self.first_prim(n) as u32
    }
    fn children(&self, n: usize) -> (usize, usize) {
        let s = self.bvh2.nodes[n].start as usize;
        (s, s + 1)
    }
    /// First primitive of `n`'s subtree in `prim_ids` (a subtree's primitives are
    /// contiguous there): the start of its leftmost leaf.
    fn first_prim(&self, mut n: usize) -> usize {
        while !self.bvh2.nodes[n].is_leaf() {
            n = self.bvh2.nodes[n].start as usize;
        }
        self.bvh2.nodes[n].start as usize
    }
}

/// Runs the dynamic program bottom-up over `n`'s subtree, storing each node's [`Plan`];
/// returns `(C(n, 1..=8), triangles, spheres)` of the subtree.
fn plan_rec(p: &Planned, opts: &CollapseOptions, block_m: u32, n: usize, depth: usize) -> ([f32; 8], u32, u32) {
    let node = p.bvh2.nodes[n];
    let area = node.bounds.half_area();
    let blocks = |ntri: u32, nsph: u32| ntri.div_ceil(block_m) + nsph.div_ceil(Sphere4::M as u32);
    let leaf_cost = |ntri: u32, nsph: u32| {
        area * (opts.block_cost * blocks(ntri, nsph) as f32 + opts.prim_cost * (ntri + nsph) as f32)
    };
    if node.is_leaf() {
        // Leaves hold one kind (`pure_leaves`).
        let first = p.bvh2.prim_ids.get(node.start as usize).copied().unwrap_or(0);
        let (ntri, nsph) = if first < p.first_sphere { (node.count, 0) } else { (0, node.count) };
        p.plans[n].store(Plan::new(true, 0, &[(0, 1); 8]).0, Relaxed);
        return ([leaf_cost(ntri, nsph); 8], ntri, nsph);
    }
    let (l, r) = p.children(n);
    let ((cl, tl, sl), (cr, tr, sr)) = if depth < PARALLEL_PLAN_DEPTH {
        rayon::join(|| plan_rec(p, opts, block_m, l, depth + 1), || plan_rec(p, opts, block_m, r, depth + 1))
    } else {
        (plan_rec(p, opts, block_m, l, depth + 1), plan_rec(p, opts, block_m, r, depth + 1))
    };
    let (ntri, nsph) = (tl + tr, sl + sr);
    let single_kind = ntri == 0 || nsph == 0;
    let leaf = if single_kind && (ntri + nsph) as usize <= opts.max_leaf_prims {
        leaf_cost(ntri, nsph)
    } else {
        f32::INFINITY
    };
    // dist[j]: cheapest split of j + 1 slots between the children (each gets >= 1).
    let mut dist = [f32::INFINITY; 8];
    let mut dist_k = [0usize; 8];
    for j in 1..8 {
        for k in 1..=j {
            let c = cl[k - 1] + cr[j - k];
            if c < dist[j] {
                dist[j] = c;
                dist_k[j] = k;
            }
        }
    }
    let as_node = area * opts.node_cost + dist[7];
    let mut cost = [0.0f32; 8];
    let mut forest = [(0usize, 1usize); 8];
    cost[0] = leaf.min(as_node);
    for j in 1..8 {
        if dist[j] < cost[j - 1] {
            cost[j] = dist[j];
            forest[j] = (dist_k[j], j + 1);
        } else {
            cost[j] = cost[j - 1];
            forest[j] = forest[j - 1];
        }
    }
    p.plans[n].store(Plan::new(leaf <= as_node, dist_k[7], &forest).0, Relaxed);
    (cost, ntri, nsph)
}

/// Where [`Emitter::pack_leaves`] put a leaf: lanes `lane .. lane + lanes` of shared block
/// `block` (numbered from 0 for the node).
#[derive(Clone, Copy)]
struct Placed {
    block: usize,
    lane: usize,
    lanes: usize,
}

/// Up to eight binary nodes: the children of one BVH8 node.
#[derive(Default)]
struct Kids {
    n: [usize; 8],
    len: usize,
}

impl Kids {
    fn push(&mut self, c: usize) {
        self.n[self.len] = c;
        self.len += 1;
    }
    fn as_slice(&self) -> &[usize] {
        &self.n[..self.len]
    }
}

/// Appends the roots of the best forest of at most `slots` roots for `n`'s subtree.
fn forest(p: &Planned, n: usize, slots: usize, out: &mut Kids) {
    let (k, used) = p.plan(n).forest(slots);
    if k == 0 {
        out.push(n);
    } else {
        let (l, r) = p.children(n);
        forest(p, l, k, out);
        forest(p, r, used - k, out);
    }
}

/// Greedy children: open the largest-area inner descendant until 8 slots are used.
fn greedy_forest(p: &Planned, n: usize, out: &mut Kids) {
    let (l, r) = p.children(n);
    out.push(l);
    out.push(r);
    let nodes = &p.bvh2.nodes;
    while out.len < 8 {
        let best = out
            .as_slice()
            .iter()
            .enumerate()
            .filter(|(_, c)| !nodes[**c].is_leaf())
            .max_by(|a, b| nodes[*a.1].bounds.half_area().total_cmp(&nodes[*b.1].bounds.half_area()));
        let Some((pos, &c)) = best else { break };
        let (cl, cr) = p.children(c);
        out.n[pos] = cl;
        out.push(cr);
    }
}

/// Where an [`Emitter`] writes: the growing arrays of the whole BVH8 (the top of the tree),
/// or the disjoint ranges of them reserved for one deferred subtree.
trait Sink<T> {
    /// Reserves `k` consecutive nodes; returns the global index of the first.
    fn alloc_nodes(&mut self, k: usize) -> usize;
    /// Stores node `i` (global index, reserved before).
    fn set_node(&mut self, i: usize, node: Bvh8Node);
    /// Appends a triangle block; returns its global index.
    fn push_tri(&mut self, b: T) -> usize;
    /// Appends a sphere block; returns its global index.
    fn push_sphere(&mut self, b: Sphere4) -> usize;
}

/// The arrays of a BVH8 being written (a [`Bvh8`]'s are read-only once made).
struct Arrays<T> {
    nodes: Vec<Bvh8Node>,
    tris: Vec<T>,
    spheres: Vec<Sphere4>,
}

impl<T: TriBlock> Arrays<T> {
    fn into_bvh8(self, test: TriangleTest) -> Bvh8<T> {
        Bvh8 {
            nodes: self.nodes.into(),
            tris: self.tris.into(),
            ids: Default::default(),
            spheres: self.spheres.into(),
            test,
        }
    }
}

impl<T> Sink<T> for Arrays<T> {
    fn alloc_nodes(&mut self, k: usize) -> usize {
        let i = self.nodes.len();
        self.nodes.resize(i + k, Bvh8Node::EMPTY);
        i
    }
    fn set_node(&mut self, i: usize, node: Bvh8Node) {
        self.nodes[i] = node;
    }
    fn push_tri(&mut self, b: T) -> usize {
        self.tris.push(b);
        self.tris.len() - 1
    }
    fn push_sphere(&mut self, b: Sphere4) -> usize {
        self.spheres.push(b);
        self.spheres.len() - 1
    }
}

/// The ranges of the final arrays reserved for one deferred subtree, sized by
/// [`Emitter::count`]: `nodes[0]` is global node `bases.0`, and so on.
struct Part<'o, T> {
    nodes: &'o mut [Bvh8Node],
    tris: &'o mut [T],
    spheres: &'o mut [Sphere4],
    bases: (usize, usize, usize),
    used: (usize, usize, usize),
}

impl<T> Sink<T> for Part<'_, T> {
    fn alloc_nodes(&mut self, k: usize) -> usize {
        self.used.0 += k;
        self.bases.0 + self.used.0 - k
    }
    fn set_node(&mut self, i: usize, node: Bvh8Node) {
        self.nodes[i - self.bases.0] = node;
    }
    fn push_tri(&mut self, b: T) -> usize {
        self.tris[self.used.1] = b;
        self.used.1 += 1;
        self.bases.1 + self.used.1 - 1
    }
    fn push_sphere(&mut self, b: Sphere4) -> usize {
        self.spheres[self.used.2] = b;
        self.used.2 += 1;
        self.bases.2 + self.used.2 - 1
    }
}

/// Writes the 8-wide BVH (or one deferred part of it) from the planned binary tree.
struct Emitter<'a, S> {
    p: &'a Planned<'a>,
    method: CollapseMethod,
    shape: &'a S,
    test: TriangleTest,
    /// With `Some`, inner children with at most `cut` primitives are not written but listed
    /// as `(node index, binary node)` for parallel tasks.
    defer: Option<(u32, Vec<(usize, usize)>)>,
}

impl<'a, S: Fn(u32) -> PrimShape + Sync> Emitter<'a, S> {
    /// An emitter that writes everything it visits (for one deferred part).
    fn clone_plain(&self) -> Self {
        Emitter { p: self.p, method: self.method, shape: self.shape, test: self.test, defer: None }
    }

    fn is_leaf_root(&self, c: usize) -> bool {
        match self.method {
            CollapseMethod::Optimal => self.p.plan(c).as_leaf(),
            CollapseMethod::Greedy => self.p.bvh2.nodes[c].is_leaf(),
        }
    }

    fn children_of(&self, n: usize) -> Kids {
        let mut kids = Kids::default();
        match self.method {
            CollapseMethod::Optimal => {
                let k = self.p.plan(n).node_split();
                let (l, r) = self.p.children(n);
                forest(self.p, l, k, &mut kids);
                forest(self.p, r, 8 - k, &mut kids);
            }
            CollapseMethod::Greedy => greedy_forest(self.p, n, &mut kids),
        }
        // Inner roots first, each group in forest order (a stable sort): the layout invariant
        // of `Bvh8Node` (slot `i < k` holds node `first + i`).
        let len = kids.len;
        kids.n[..len].sort_by_key(|&c| self.is_leaf_root(c));
        kids
    }

    /// The triangle leaf roots among `kids` that share blocks: those of at most `m`
    /// triangles, placed first fit in decreasing order of size into blocks of `m` lanes
    /// (ties in slot order). Entry `slot` says where its leaf went, blocks numbered from 0 for
    /// this node; the second value is the number of shared blocks.
    fn pack_leaves(&self, kids: &[usize], m: usize) -> ([Option<Placed>; 8], usize) {
        let (mut small, mut size) = (Kids::default(), [0usize; 8]);
        for (slot, &c) in kids.iter().enumerate() {
            if !self.is_leaf_root(c) {
                continue;
            }
            size[slot] = self.p.count(c) as usize;
            let triangles = !self.p.spheres || self.p.bvh2.prim_ids[self.p.first_prim(c)] < self.p.first_sphere;
            if size[slot] <= m && triangles {
                small.push(slot);
            }
        }
        let order = &mut small.n[..small.len];
        order.sort_by_key(|&slot| std::cmp::Reverse(size[slot]));
        let (mut place, mut fill, mut blocks) = ([None; 8], [0usize; 8], 0);
        for &slot in order.iter() {
            let n = size[slot];
            let b = (0..blocks).find(|&b| fill[b] + n <= m).unwrap_or_else(|| {
                blocks += 1;
                blocks - 1
            });
            place[slot] = Some(Placed { block: b, lane: fill[b], lanes: n });
            fill[b] += n;
        }
        (place, blocks)
    }

    /// Writes the shared blocks of `kids` as [`Emitter::pack_leaves`] placed them; returns
    /// each packed slot's leaf reference.
    fn packed_leaves<T: TriBlock>(&self, kids: &[usize], out: &mut impl Sink<T>) -> [Option<NodeRef>; 8] {
        let (place, blocks) = self.pack_leaves(kids, T::M);
        let mut refs = [None; 8];
        for b in 0..blocks {
            let in_block =
                || (0..kids.len()).filter_map(|slot| place[slot].filter(|p| p.block == b).map(|p| (slot, p)));
            let mut block = T::EMPTY;
            for (slot, p) in in_block() {
                self.set_triangles(&mut block, p.lane, self.leaf_ids(kids[slot]));
            }
            let at = out.push_tri(block) as u32;
            for (slot, p) in in_block() {
                refs[slot] = Some(NodeRef::leaf_in_block(LeafKind::Triangles, at, p.lane, p.lanes));
            }
        }
        refs
    }

    /// The primitive ids below leaf root `c`.
    fn leaf_ids(&self, c: usize) -> &[u32] {
        let start = self.p.first_prim(c);
        &self.p.bvh2.prim_ids[start..start + self.p.count(c) as usize]
    }

    /// Stores the triangles `ids` in `block` from lane `first_lane` on.
    fn set_triangles<T: TriBlock>(&self, block: &mut T, first_lane: usize, ids: &[u32]) {
        for (k, &id) in ids.iter().enumerate() {
            let PrimShape::Triangle([v0, v1, v2]) = (self.shape)(id) else { unreachable!("triangle leaf") };
            block.set_for(self.test, first_lane + k, v0, v1, v2, id);
        }
    }

    /// Writes the leaf blocks of leaf root `c`.
    fn leaf<T: TriBlock>(&self, c: usize, out: &mut impl Sink<T>) -> NodeRef {
        let ids = self.leaf_ids(c);
        let (kind, m) =
            if ids[0] < self.p.first_sphere { (LeafKind::Triangles, T::M) } else { (LeafKind::Spheres, Sphere4::M) };
        let mut first = 0;
        for (k, chunk) in ids.chunks(m).enumerate() {
            let at = if kind == LeafKind::Triangles {
                let mut b = T::EMPTY;
                self.set_triangles(&mut b, 0, chunk);
                out.push_tri(b)
            } else {
                let mut b = Sphere4::EMPTY;
                for (lane, &id) in chunk.iter().enumerate() {
                    let PrimShape::Sphere(center, r) = (self.shape)(id) else { unreachable!("sphere leaf") };
                    b.set(lane, center, r, id);
                }
                out.push_sphere(b)
            };
            if k == 0 {
                first = at;
            }
        }
        NodeRef::leaf(kind, first as u32, ids.len().div_ceil(m), (ids.len() - 1) % m + 1)
    }

    /// Builds the node for inner root `n`, writing its inner children (allocated
    /// consecutively, siblings adjacent) and everything below them — or deferring them.
    fn fill<T: TriBlock>(&mut self, n: usize, out: &mut impl Sink<T>) -> Bvh8Node {
        let kids = self.children_of(n);
        let inner = kids.as_slice().iter().filter(|&&c| !self.is_leaf_root(c)).count();
        let first = out.alloc_nodes(inner);
        let mut node = Bvh8Node::EMPTY;
        let mut todo = Kids::default();
        let packed = self.packed_leaves(kids.as_slice(), out);
        for (slot, &c) in kids.as_slice().iter().enumerate() {
            let r = if let Some(r) = packed[slot] {
                r
            } else if self.is_leaf_root(c) {
                self.leaf(c, out)
            } else {
                todo.push(c);
                NodeRef::inner((first + todo.len - 1) as u32)
            };
            node.set_child(slot, &self.p.bvh2.nodes[c].bounds, r);
        }
        for (k, &c) in todo.as_slice().iter().enumerate() {
            match &mut self.defer {
                Some((cut, list)) if self.p.count(c) <= *cut => list.push((first + k, c)),
                _ => {
                    let child = self.fill(c, out);
                    out.set_node(first + k, child);
                }
            }
        }
        node
    }

    /// `(nodes, triangle blocks, sphere blocks)` that [`Emitter::fill`] writes below inner
    /// root `n` (without deferring; its own node not included).
    fn count(&self, n: usize, block_m: usize) -> (usize, usize, usize) {
        let kids = self.children_of(n);
        let (packed, shared) = self.pack_leaves(kids.as_slice(), block_m);
        let mut total = (0, shared, 0);
        for (slot, &c) in kids.as_slice().iter().enumerate() {
            if packed[slot].is_some() {
                continue;
            }
            if self.is_leaf_root(c) {
                let count = self.p.count(c) as usize;
                let first = self.p.bvh2.prim_ids[self.p.first_prim(c)];
                if first < self.p.first_sphere {
                    total.1 += count.div_ceil(block_m);
                } else {
                    total.2 += count.div_ceil(Sphere4::M);
                }
            } else {
                let (a, b, s) = self.count(c, block_m);
                total = (total.0 + 1 + a, total.1 + b, total.2 + s);
            }
        }
        total
    }
}

/// Splits every binary leaf that mixes triangles (`id < first_sphere`) and spheres into an
/// inner node over one leaf per kind; borrows `bvh2` when no leaf mixes them (as
/// [`crate::bvh::build_bvh2_kinds`] guarantees).
fn pure_leaves<'a>(bvh2: &'a Bvh2, first_sphere: u32, shape: &dyn Fn(u32) -> PrimShape) -> Cow<'a, Bvh2> {
    let mixed = |n: &Bvh2Node| {
        let ids = || bvh2.prim_ids[n.start as usize..(n.start + n.count) as usize].iter();
        n.is_leaf() && ids().any(|&id| id < first_sphere) && ids().any(|&id| id >= first_sphere)
    };
    use rayon::prelude::*;
    // Most scenes hold one kind only: the ids say so faster than the nodes.
    let ids = &bvh2.prim_ids;
    let both_kinds = ids.par_iter().any(|&id| id < first_sphere) && ids.par_iter().any(|&id| id >= first_sphere);
    if bvh2.is_empty() || !both_kinds || !bvh2.nodes.par_iter().any(mixed) {
        return Cow::Borrowed(bvh2);
    }
    let mut out = Bvh2 { nodes: vec![bvh2.nodes[0]], prim_ids: bvh2.prim_ids.clone() };
    // (source node, output node), depth first with siblings adjacent as in the builder.
    let mut stack = vec![(0usize, 0usize)];
    while let Some((s, o)) = stack.pop() {
        let node = bvh2.nodes[s];
        if node.is_leaf() && !mixed(&node) {
            out.nodes[o] = node;
        } else if node.is_leaf() {
            let (a, c) = (node.start as usize, node.count as usize);
            let ids = &mut out.prim_ids[a..a + c];
            ids.sort_by_key(|&id| id >= first_sphere);
            let nt = ids.iter().filter(|&&id| id < first_sphere).count();
            let part =
                |ids: &[u32]| pad_outward(&ids.iter().fold(Aabb::EMPTY, |b, &id| b.union(&shape_bounds(shape(id)))));
            let k = out.nodes.len() as u32;
            out.nodes[o] = Bvh2Node { bounds: node.bounds, start: k, count: 0 };
            out.nodes.push(Bvh2Node { bounds: part(&out.prim_ids[a..a + nt]), start: a as u32, count: nt as u32 });
            out.nodes.push(Bvh2Node {
                bounds: part(&out.prim_ids[a + nt..a + c]),
                start: (a + nt) as u32,
                count: (c - nt) as u32,
            });
        } else {
            let k = out.nodes.len();
            out.nodes[o] = Bvh2Node { start: k as u32, ..node };
            out.nodes.extend([Bvh2Node { bounds: Aabb::EMPTY, start: 0, count: 0 }; 2]);
            stack.push((node.start as usize + 1, k + 1));
            stack.push((node.start as usize, k));
        }
    }
    Cow::Owned(out)
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

/// Collapses `bvh2` into an 8-wide BVH with leaf blocks of `T` laid out for
/// Möller–Trumbore. `shape(id)` gives the geometry of primitive `id`; ids below
/// `first_sphere` are triangles, the others spheres. Every subtree of `bvh2` must hold a
/// contiguous range of `prim_ids`, left subtree first, as [`crate::bvh::build_bvh2`]'s trees
/// do.
pub fn collapse<T: TriBlock>(
    bvh2: &Bvh2,
    shape: impl Fn(u32) -> PrimShape + Sync,
    first_sphere: u32,
    opts: &CollapseOptions,
) -> Bvh8<T> {
    collapse_for(bvh2, shape, first_sphere, opts, TriangleTest::MollerTrumbore)
}

/// [`collapse()`] with leaf blocks laid out for triangle test `test`.
///
/// The dynamic program runs bottom-up with the two children of each node in parallel near
/// the root. The emission writes the top of the tree on one thread and defers the subtrees
/// of at most 1/64 of the primitives; their sizes are counted, ranges of the final arrays
/// reserved for each in order, and parallel tasks fill them — so the result is the same
/// whatever the thread count, and nothing is copied twice.
pub fn collapse_for<T: TriBlock>(
    bvh2: &Bvh2,
    shape: impl Fn(u32) -> PrimShape + Sync,
    first_sphere: u32,
    opts: &CollapseOptions,
    test: TriangleTest,
) -> Bvh8<T> {
    use rayon::prelude::*;
    let bvh2 = pure_leaves(bvh2, first_sphere, &shape);
    let m = bvh2.nodes.len();
    // Allocated and first written in parallel (as the output arrays below are first written
    // by parallel tasks): for large meshes the page faults of fresh memory are a large part
    // of the cost.
    let mut plans = crate::system::huge_page_vec(m);
    (0..m).into_par_iter().map(|_| AtomicU64::new(0)).collect_into_vec(&mut plans);
    let mut p = Planned { bvh2: &bvh2, first_sphere, plans, spheres: true };
    let mut out = Arrays { nodes: vec![Bvh8Node::EMPTY], tris: Vec::new(), spheres: Vec::new() };
    if bvh2.is_empty() {
        return out.into_bvh8(test);
    }
    p.spheres = plan_rec(&p, opts, T::M as u32, 0, 0).2 > 0;
    let cut = (p.count(0) / PARALLEL_EMIT_DIVISOR).max(1);
    let mut em = Emitter { p: &p, method: opts.method, shape: &shape, test, defer: Some((cut, Vec::new())) };
    if bvh2.nodes[0].is_leaf() || em.is_leaf_root(0) {
        let r = em.leaf(0, &mut out);
        out.nodes[0].set_child(0, &bvh2.nodes[0].bounds, r);
        return out.into_bvh8(test);
    }
    out.nodes[0] = em.fill(0, &mut out);
    let deferred = em.defer.take().map(|d| d.1).unwrap_or_default();
    // Reserve each deferred subtree's ranges, in order, after the top of the tree.
    let sizes: Vec<_> = deferred.par_iter().map(|&(_, n)| em.count(n, T::M)).collect();
    let mut bases = Vec::with_capacity(sizes.len());
    let mut end = (out.nodes.len(), out.tris.len(), out.spheres.len());
    for s in &sizes {
        bases.push(end);
        end = (end.0 + s.0, end.1 + s.1, end.2 + s.2);
    }
    let top = bases.first().copied().unwrap_or(end);
    // The final arrays: fresh zero pages that the parallel tasks below touch first (see
    // `BvhArray::zeroed`), with the top of the tree copied in.
    let mut nodes_out = BvhArray::<Bvh8Node>::zeroed(end.0);
    nodes_out[..top.0].copy_from_slice(&out.nodes);
    let mut tris_out = BvhArray::<T>::zeroed(end.1);
    tris_out[..top.1].copy_from_slice(&out.tris);
    out.spheres.resize(end.2, Sphere4::EMPTY);
    let (mut nodes, mut tris, mut spheres) =
        (&mut nodes_out[top.0..], &mut tris_out[top.1..], &mut out.spheres[top.2..]);
    let mut parts = Vec::with_capacity(sizes.len());
    for (s, &bases) in sizes.iter().zip(&bases) {
        let (a, rest) = std::mem::take(&mut nodes).split_at_mut(s.0);
        let (b, rest_t) = std::mem::take(&mut tris).split_at_mut(s.1);
        let (c, rest_s) = std::mem::take(&mut spheres).split_at_mut(s.2);
        (nodes, tris, spheres) = (rest, rest_t, rest_s);
        parts.push(Part { nodes: a, tris: b, spheres: c, bases, used: (0, 0, 0) });
    }
    let em = Emitter { defer: None, ..em };
    let roots: Vec<Bvh8Node> = parts
        .into_par_iter()
        .zip(&deferred)
        .map(|(mut part, &(_, n))| {
            let root = em.clone_plain().fill(n, &mut part);
            // Every element of the reserved ranges is written (zero pages are not valid
            // nodes: a zero child reference would point back at the root).
            assert_eq!(
                (part.used.0, part.used.1, part.used.2),
                (part.nodes.len(), part.tris.len(), part.spheres.len())
            );
            root
        })
        .collect();
    for (root, &(at, _)) in roots.into_iter().zip(&deferred) {
        nodes_out[at] = root;
    }
    Bvh8 { nodes: nodes_out, tris: tris_out, ids: Default::default(), spheres: out.spheres.into(), test }
}
