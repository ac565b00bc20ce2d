//! Run-time knobs for measuring kernel variants side by side (A/B in one process, where the
//! shared machine's noise cancels). Not for users: the defaults are the measured choices.
#![allow(missing_docs)]

use std::sync::atomic::{AtomicU32, Ordering};

/// Knob slots; see the constants below for what each selects.
pub static KNOBS: [AtomicU32; 8] = [const { AtomicU32::new(0) }; 8];

/// Packet leaves: per-ray block tests when fewer than `min(knob, lanes)` rays are active
/// (0: never).
pub const PER_RAY_LEAF: usize = 0;

/// Prefetch hit children: 0 = on, 1 = off.
pub const NO_PREFETCH: usize = 1;

/// Packet occlusion kernel: 0 = frustum, 1 = hybrid.
pub const OCC_MODE: usize = 2;
/// Hybrid switch threshold override (0 = default).
pub const THRESHOLD: usize = 3;
/// Packet intersect kernel: 0 = frustum, 1 = hybrid.
pub const ISECT_MODE: usize = 4;

/// Occlusion packets: 1 = no frustum prefilter of children.
pub const NO_FRUSTUM_PREFILTER: usize = 5;

#[inline(always)]
pub fn knob(i: usize) -> u32 {
    KNOBS[i].load(Ordering::Relaxed)
}

pub fn set(i: usize, v: u32) {
    KNOBS[i].store(v, Ordering::Relaxed)
}
