//! Traversal statistics (nodes, leaves, primitive tests per ray), compiled in only with the
//! `kernel-stats` feature; otherwise every `count!` is empty.
#![allow(missing_docs)]

pub const NODES: usize = 0;
pub const LEAVES: usize = 1;
pub const BLOCKS: usize = 2;
pub const FRUSTUM_NODES: usize = 3;
pub const PACKET_LEAVES: usize = 4;
pub const PACKET_LEAF_LANES: usize = 5;
pub const PACKET_TRI_TESTS: usize = 6;
pub const PER_RAY_BLOCKS: usize = 7;
pub const HYBRID_NODES: usize = 8;
pub const FALLBACK_RAYS: usize = 9;
pub const N: usize = 10;
pub const NAMES: [&str; N] = [
    "nodes",
    "leaves",
    "blocks",
    "frustum nodes",
    "packet leaves",
    "packet leaf lanes",
    "packet tri tests",
    "per-ray blocks",
    "hybrid nodes",
    "fallback rays",
];

#[cfg(feature = "kernel-stats")]
thread_local! {
    static C: std::cell::RefCell<[u64; N]> = const { std::cell::RefCell::new([0; N]) };
}

#[cfg(feature = "kernel-stats")]
#[inline(always)]
pub fn add(i: usize, n: u64) {
    C.with(|c| c.borrow_mut()[i] += n);
}

/// Returns and clears this thread's counters (all zero without `kernel-stats`).
pub fn take() -> [u64; N] {
    #[cfg(feature = "kernel-stats")]
    {
        C.with(|c| std::mem::take(&mut *c.borrow_mut()))
    }
    #[cfg(not(feature = "kernel-stats"))]
    {
        [0; N]
    }
}

macro_rules! count {
    ($i:expr, $n:expr) => {
        #[cfg(feature = "kernel-stats")]
        $crate::bvh::counters::add($i, $n as u64);
    };
}
pub(crate) use count;
