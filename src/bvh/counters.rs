//! Traversal work counters: what a kernel did for the rays it traced.
//!
//! Every traversal kernel takes a [`Counter`] as a type parameter. [`NoCount`] compiles to
//! nothing (the queries of [`crate::Scene`] use it); [`TraversalCounts`] adds up the work,
//! so statistics, the traversal-cost heatmap and the tests that compare work all count the
//! very kernels that trace, not a separate walk that could drift from them.

/// Receives the kernels' work as it happens.
pub trait Counter {
    /// Adds `n` to counter `what`.
    fn add(&mut self, what: Work, n: u32);
}

/// The kinds of work a kernel counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Work {
    /// Inner nodes visited by a single ray (each an 8-box test).
    Nodes,
    /// Leaves visited by a single ray.
    Leaves,
    /// Primitive blocks tested by a single ray (each M triangles or 4 spheres at once).
    Blocks,
    /// Inner nodes visited by a packet.
    PacketNodes,
    /// Triangles tested against all of a packet's wanted rays at once.
    PacketTriangles,
    /// Rays that left a packet to finish a subtree alone.
    FallbackRays,
}

/// Counts nothing; every call compiles away.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoCount;

impl Counter for NoCount {
    #[inline(always)]
    fn add(&mut self, _: Work, _: u32) {}
}

impl std::ops::AddAssign for NoCount {
    #[inline(always)]
    fn add_assign(&mut self, _: Self) {}
}

/// Totals of every kind of [`Work`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TraversalCounts {
    /// [`Work::Nodes`].
    pub nodes: u64,
    /// [`Work::Leaves`].
    pub leaves: u64,
    /// [`Work::Blocks`].
    pub blocks: u64,
    /// [`Work::PacketNodes`].
    pub packet_nodes: u64,
    /// [`Work::PacketTriangles`].
    pub packet_triangles: u64,
    /// [`Work::FallbackRays`].
    pub fallback_rays: u64,
}

impl Counter for TraversalCounts {
    #[inline(always)]
    fn add(&mut self, what: Work, n: u32) {
        let c = match what {
            Work::Nodes => &mut self.nodes,
            Work::Leaves => &mut self.leaves,
            Work::Blocks => &mut self.blocks,
            Work::PacketNodes => &mut self.packet_nodes,
            Work::PacketTriangles => &mut self.packet_triangles,
            Work::FallbackRays => &mut self.fallback_rays,
        };
        *c += n as u64;
    }
}

impl std::ops::AddAssign for TraversalCounts {
    fn add_assign(&mut self, o: Self) {
        self.nodes += o.nodes;
        self.leaves += o.leaves;
        self.blocks += o.blocks;
        self.packet_nodes += o.packet_nodes;
        self.packet_triangles += o.packet_triangles;
        self.fallback_rays += o.fallback_rays;
    }
}

impl TraversalCounts {
    /// Single-ray box and primitive-block tests: CS184's "intersection tests".
    pub fn tests(&self) -> u64 {
        self.nodes + self.blocks
    }
}
