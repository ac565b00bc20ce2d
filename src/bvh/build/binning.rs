//! The SAH bins of a node: each primitive's doubled centroid mapped to one of `k` equal
//! intervals per axis, the bins' bounds and counts gathered (in parallel chunks for large
//! nodes, with exact reductions, so the result does not depend on the thread count).

use super::{Box4, BuildPrim, MAX_BINS, PARALLEL_BIN_THRESHOLD};

/// Nodes of fewer primitives than this bin into one set of bins, not two ([`bin_prims`]).
const SMALL_NODE: usize = 32;

/// One SAH bin: bounds of the primitives in it and their count.
#[derive(Clone, Copy, Debug)]
pub(super) struct Bin {
    pub(super) bounds: Box4,
    pub(super) count: u32,
}

impl Bin {
    const EMPTY: Bin = Bin { bounds: Box4::EMPTY, count: 0 };

    #[inline(always)]
    fn add(&mut self, p: &BuildPrim) {
        self.bounds.grow(p.lower, p.upper);
        self.count += 1;
    }
}

/// Adds the first `k` bins of each axis of `from` to those of `into` (exact: unions and sums).
fn merge_bins(into: &mut [Bin], from: &[Bin], k: usize) {
    for axis in 0..3 {
        for i in axis * MAX_BINS..axis * MAX_BINS + k {
            into[i].bounds = into[i].bounds.union(&from[i].bounds);
            into[i].count += from[i].count;
        }
    }
}

/// Per-task scratch memory of the builder, reused for every node the task splits (only the
/// first `k` bins of each axis are touched per node), so splitting allocates nothing.
pub(super) struct Scratch {
    /// `3 * MAX_BINS` bins, axis-major.
    pub(super) bins: Vec<Bin>,
    /// A second set of bins: odd primitives bin here (see [`bin_prims`]).
    pub(super) bins2: Vec<Bin>,
    pub(super) right_area: Vec<f32>,
    pub(super) right_count: Vec<u32>,
}

impl Scratch {
    pub(super) fn new() -> Self {
        Self {
            bins: vec![Bin::EMPTY; 3 * MAX_BINS],
            bins2: vec![Bin::EMPTY; 3 * MAX_BINS],
            right_area: vec![0.0; MAX_BINS],
            right_count: vec![0; MAX_BINS],
        }
    }
}

/// Maps doubled centroids on `axis` to `[0, k)`: `(c2 - lo) * scale`.
#[inline]
fn bin_mapping(cb: &Box4, axis: usize, k: usize) -> (f32, f32) {
    let ext = cb.extent()[axis];
    (cb.lower[axis], k as f32 * (1.0 - 1e-6) / ext)
}

/// [`bin_mapping`] of each axis of `cb` with an extent; the others map every centroid to bin 0.
#[inline]
pub(super) fn bin_mappings(cb: &Box4, k: usize) -> [(f32, f32); 3] {
    let ext = cb.extent();
    std::array::from_fn(|a| if ext[a] > 0.0 { bin_mapping(cb, a, k) } else { (cb.lower[a], 0.0) })
}

/// Fills the first `k` bins of each axis of `bins` with `prims`; large inputs bin in
/// parallel chunks whose exact reduction keeps the result independent of the thread count.
pub(super) fn bin_prims(prims: &[BuildPrim], maps: &[(f32, f32); 3], k: usize, bins: &mut [Bin], bins2: &mut [Bin]) {
    use wide::f32x4;
    // All three axes' bin indices in one SIMD step (one truncating conversion for the four
    // lanes); clamping in the float domain makes it exact and maps the unused fourth lane
    // to bin 0.
    let lo = f32x4::new([maps[0].0, maps[1].0, maps[2].0, 0.0]);
    let scale = f32x4::new([maps[0].1, maps[1].1, maps[2].1, 0.0]);
    let top = f32x4::splat((k - 1) as f32);
    // `fast_min`/`fast_max` (one instruction each; a NaN lane would take `top`, still a bin)
    // rather than the NaN-propagating forms, which were measurably slower (PERFORMANCE.md,
    // "Builder").
    let index = |p: &BuildPrim| {
        let c: f32x4 = bytemuck::cast(p.centroid2());
        ((c - lo) * scale).fast_min(top).fast_max(f32x4::ZERO).fast_trunc_int().to_array()
    };
    // Even and odd primitives go to two sets of bins, merged at the end: neighbours in a
    // mesh mostly fall into the same bins, and one set would chain every update to the
    // previous one through memory. (Unions and sums are exact, so the bins are the same.)
    // Nodes of fewer than SMALL_NODE primitives, the most numerous by far, use one set: for
    // them clearing and merging the second set costs more than the chain.
    let bin_chunk = |chunk: &[BuildPrim], bins: &mut [Bin], bins2: &mut [Bin]| {
        // As arrays, and with indices masked to `MAX_BINS - 1` (a no-op after the clamp),
        // the compiler sees every index in range and drops the bounds checks.
        let bins: &mut [Bin; 3 * MAX_BINS] = bins.try_into().expect("3 * MAX_BINS bins");
        let bins2: &mut [Bin; 3 * MAX_BINS] = bins2.try_into().expect("3 * MAX_BINS bins");
        // Primitive `p` into bin `idx[a]` of each axis `a` of `bins`.
        let add = |bins: &mut [Bin; 3 * MAX_BINS], idx: [i32; 4], p: &BuildPrim| {
            for a in 0..3 {
                bins[a * MAX_BINS + (idx[a] as usize & (MAX_BINS - 1))].add(p);
            }
        };
        for a in 0..3 {
            bins[a * MAX_BINS..a * MAX_BINS + k].fill(Bin::EMPTY);
        }
        if chunk.len() < SMALL_NODE {
            for p in chunk {
                add(bins, index(p), p);
            }
            return;
        }
        for a in 0..3 {
            bins2[a * MAX_BINS..a * MAX_BINS + k].fill(Bin::EMPTY);
        }
        let mut pairs = chunk.chunks_exact(2);
        for pair in &mut pairs {
            let (p, q) = (&pair[0], &pair[1]);
            let (ip, iq) = (index(p), index(q));
            add(bins, ip, p);
            add(bins2, iq, q);
        }
        for p in pairs.remainder() {
            add(bins, index(p), p);
        }
        merge_bins(bins, bins2, k);
    };
    if prims.len() < PARALLEL_BIN_THRESHOLD {
        return bin_chunk(prims, bins, bins2);
    }
    use rayon::prelude::*;
    let partial = prims
        .par_chunks(PARALLEL_BIN_THRESHOLD / 4)
        .map(|chunk| {
            let (mut b, mut b2) = (vec![Bin::EMPTY; 3 * MAX_BINS], vec![Bin::EMPTY; 3 * MAX_BINS]);
            bin_chunk(chunk, &mut b, &mut b2);
            b
        })
        .reduce_with(|mut a, b| {
            merge_bins(&mut a, &b, k);
            a
        })
        .expect("non-empty");
    bins.copy_from_slice(&partial);
}

#[cfg(test)]
mod tests {
    use super::super::PrimInfo;
    use super::*;
    use crate::math::{Aabb, Vec3};
    use crate::rng::Rng;

    #[test]
    fn bins_hold_every_primitive_whatever_the_node_size() {
        // Small nodes bin into one set of bins, larger ones into two that are merged: either
        // way each bin holds exactly the primitives whose centroid falls in it.
        let mut rng = Rng::new(3, 8);
        let mut r3 = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 10.0 - 5.0;
        let mut scratch = Scratch::new();
        for len in (1..80).chain([200, 1000]) {
            let prims: Vec<BuildPrim> = (0..len as u32)
                .map(|id| {
                    let c = r3();
                    BuildPrim::new(Aabb::new(c - r3().abs() * 0.1, c + r3().abs() * 0.1), id)
                })
                .collect();
            let cb = PrimInfo::of(&prims).centroids;
            let k = 4 + len / 20;
            let maps = bin_mappings(&cb, k);
            bin_prims(&prims, &maps, k, &mut scratch.bins, &mut scratch.bins2);
            for (a, &(lo, scale)) in maps.iter().enumerate() {
                let mut want = vec![Bin::EMPTY; k];
                for p in &prims {
                    let x = ((p.centroid2()[a] - lo) * scale).clamp(0.0, (k - 1) as f32) as usize;
                    want[x].add(p);
                }
                for (i, w) in want.iter().enumerate() {
                    let got = &scratch.bins[a * MAX_BINS + i];
                    assert_eq!(got.count, w.count, "len {len} axis {a} bin {i}");
                    if w.count > 0 {
                        assert_eq!(got.bounds.aabb(), w.bounds.aabb(), "len {len} axis {a} bin {i}");
                    }
                }
            }
        }
    }
}
