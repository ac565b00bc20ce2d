//! Partitioning a node's primitives by a split (in place, without data-dependent branches,
//! in parallel for large nodes), gathering both sides' [`PrimInfo`] on the way.

use super::{Box4, BuildPrim, PrimInfo};
use crate::math::Vec4;

/// Nodes with more primitives than this are partitioned in parallel
/// ([`partition_with_info_par`]), in chunks of `PARALLEL_PARTITION_CHUNK`.
const PARALLEL_PARTITION_THRESHOLD: usize = 1 << 18;
const PARALLEL_PARTITION_CHUNK: usize = 1 << 16;

/// Object-median split on the largest centroid axis (by id when centroids tie), with both
/// halves' [`PrimInfo`].
pub(super) fn median_split(prims: &mut [BuildPrim], cb: &Box4) -> (usize, PrimInfo, PrimInfo) {
    let mid = prims.len() / 2;
    let axis = cb.aabb().largest_axis();
    if cb.extent()[axis] > 0.0 {
        prims.select_nth_unstable_by(mid, |a, b| {
            a.centroid2()[axis].total_cmp(&b.centroid2()[axis]).then(a.id().cmp(&b.id()))
        });
    }
    with_infos(prims, mid)
}

/// `mid` with the [`PrimInfo`] of `prims[..mid]` and of `prims[mid..]`.
#[inline]
fn with_infos(prims: &[BuildPrim], mid: usize) -> (usize, PrimInfo, PrimInfo) {
    let (l, r) = prims.split_at(mid);
    (mid, PrimInfo::of(l), PrimInfo::of(r))
}

/// Moves the primitives whose doubled centroid satisfies `left` to the front, and finds both
/// sides' [`PrimInfo`]; returns how many went left. Large nodes are partitioned in parallel.
pub(super) fn partition_node(
    prims: &mut [BuildPrim],
    left: impl Fn(Vec4) -> bool + Sync,
) -> (usize, PrimInfo, PrimInfo) {
    if prims.len() > PARALLEL_PARTITION_THRESHOLD {
        partition_with_info_par(prims, left, PARALLEL_PARTITION_CHUNK)
    } else {
        partition_with_info(prims, left)
    }
}

/// [`partition_node`] on one thread: [`partition_blocks`], each side's infos gathered from
/// its blocks as they are finished, while they are in cache.
//
// Classifying in blocks, then gathering the infos of each finished block while it is in
// cache, beat a one-pass partition that gathered them as it went (mispredicted on every other
// primitive of a mixed node) and a branch-free one with a select per lane (PERFORMANCE.md,
// "Builder").
#[inline]
fn partition_with_info(prims: &mut [BuildPrim], left: impl Fn(Vec4) -> bool) -> (usize, PrimInfo, PrimInfo) {
    let (mut li, mut ri) = (PrimInfo::EMPTY, PrimInfo::EMPTY);
    let finished = |done: &[BuildPrim], on_left: bool| {
        let info = if on_left { &mut li } else { &mut ri };
        for p in done {
            info.add(p, p.centroid2());
        }
    };
    let mid = partition_blocks(prims, |p| left(p.centroid2()), finished);
    (mid, li, ri)
}

/// [`partition_node`] in parallel: fixed chunks of `chunk` primitives are partitioned on
/// their own ([`partition_with_info`]), then the chunks' right parts that lie before the
/// final boundary trade places with their left parts that lie after it, in pieces swapped in
/// parallel. The chunks do not depend on the thread count, so neither does the order of
/// the primitives.
//
// In parallel, the large nodes' partitions (the root's above all) stop being a serial part of
// the build (PERFORMANCE.md, "Builder").
fn partition_with_info_par(
    prims: &mut [BuildPrim],
    left: impl Fn(Vec4) -> bool + Sync,
    chunk: usize,
) -> (usize, PrimInfo, PrimInfo) {
    use rayon::prelude::*;
    let parts: Vec<(usize, PrimInfo, PrimInfo)> =
        prims.par_chunks_mut(chunk).map(|c| partition_with_info(c, &left)).collect();
    let mid: usize = parts.iter().map(|p| p.0).sum();
    let (li, ri) = parts.iter().fold((PrimInfo::EMPTY, PrimInfo::EMPTY), |(l, r), p| (l.merge(&p.1), r.merge(&p.2)));
    // The misplaced ranges, in increasing order: right-side primitives before `mid`, and
    // left-side ones from `mid` on (counted from `mid`). Both lists hold as many primitives.
    let (mut wrong_left, mut wrong_right) = (Vec::new(), Vec::new());
    for (c, p) in parts.iter().enumerate() {
        let start = c * chunk;
        let (split, end) = (start + p.0, (start + chunk).min(prims.len()));
        if split < mid {
            wrong_left.push(split..end.min(mid));
        }
        if split > mid {
            wrong_right.push(start.max(mid) - mid..split - mid);
        }
    }
    // Pairs of equal-length pieces (at most SWAP_PIECE, for balance), cut from both sides
    // in increasing order so that every piece is a disjoint slice.
    const SWAP_PIECE: usize = 1 << 14;
    let (mut before, mut after) = prims.split_at_mut(mid);
    let (mut before_at, mut after_at) = (0, 0);
    let mut swaps: Vec<(&mut [BuildPrim], &mut [BuildPrim])> = Vec::new();
    let (mut a, mut b) = (wrong_left.into_iter().peekable(), wrong_right.into_iter().peekable());
    while let (Some(ra), Some(rb)) = (a.peek_mut(), b.peek_mut()) {
        let len = ra.len().min(rb.len()).min(SWAP_PIECE);
        let (x, rest) = std::mem::take(&mut before)[ra.start - before_at..].split_at_mut(len);
        (before, before_at) = (rest, ra.start + len);
        let (y, rest) = std::mem::take(&mut after)[rb.start - after_at..].split_at_mut(len);
        (after, after_at) = (rest, rb.start + len);
        swaps.push((x, y));
        ra.start += len;
        rb.start += len;
        if ra.start == ra.end {
            a.next();
        }
        if rb.start == rb.end {
            b.next();
        }
    }
    swaps.into_par_iter().for_each(|(x, y)| x.swap_with_slice(y));
    (mid, li, ri)
}

/// [`partition`] in blocks, as BlockQuicksort does (Edelkamp and Weiß, "BlockQuicksort:
/// Avoiding Branch Mispredictions in Quicksort", ESA 2016): a block at each end is
/// classified without branches, recording where the elements on the wrong side are, and
/// those are then swapped pairwise. Whatever is left between the blocks (all of a node of
/// fewer than two blocks) is partitioned by [`partition_lomuto`], also without branches.
/// `finished(slice, on_left)` sees every primitive once, in slices that are already on
/// their final side.
#[inline]
fn partition_blocks(
    prims: &mut [BuildPrim],
    pred: impl Fn(&BuildPrim) -> bool,
    mut finished: impl FnMut(&[BuildPrim], bool),
) -> usize {
    const BLOCK: usize = 64;
    let (mut l, mut r) = (0, prims.len());
    // Offsets into the left block `[l, l + BLOCK)` of elements that belong right, and into
    // the right block `[r - BLOCK, r)` (counted from its end) of elements that belong left;
    // `off_l[sl..nl]` and `off_r[sr..nr]` are those not swapped yet.
    let (mut off_l, mut off_r) = ([0u8; BLOCK], [0u8; BLOCK]);
    let (mut sl, mut nl, mut sr, mut nr) = (0, 0, 0, 0);
    // Invariant: `[0, l)` all satisfy `pred`, `[r, len)` none does.
    while r - l >= 2 * BLOCK {
        if sl == nl {
            (sl, nl) = (0, 0);
            for (i, p) in prims[l..l + BLOCK].iter().enumerate() {
                off_l[nl] = i as u8;
                nl += !pred(p) as usize;
            }
        }
        if sr == nr {
            (sr, nr) = (0, 0);
            for (i, p) in prims[r - BLOCK..r].iter().rev().enumerate() {
                off_r[nr] = i as u8;
                nr += pred(p) as usize;
            }
        }
        let m = (nl - sl).min(nr - sr);
        for k in 0..m {
            prims.swap(l + off_l[sl + k] as usize, r - 1 - off_r[sr + k] as usize);
        }
        (sl, sr) = (sl + m, sr + m);
        if sl == nl {
            finished(&prims[l..l + BLOCK], true);
            l += BLOCK;
        }
        if sr == nr {
            finished(&prims[r - BLOCK..r], false);
            r -= BLOCK;
        }
    }
    // A block with unswapped elements stays inside `[l, r)`, fewer than 2 * BLOCK
    // elements: finish them without branches too.
    let m = partition_lomuto(&mut prims[l..r], pred);
    finished(&prims[l..l + m], true);
    finished(&prims[l + m..r], false);
    l + m
}

/// [`partition`] without data-dependent branches: Lomuto's scheme, each element swapped
/// with the first one of the right side whether it goes left or not (a swap with itself or
/// with another right-side element changes nothing that matters), the boundary moved by the
/// predicate. One swap per element, against a mispredicted branch for every other element
/// of a mixed run in the plain partition.
//
// Small nodes are most of a build's nodes, and their runs are mixed: the swap per element
// costs less than the mispredictions (PERFORMANCE.md, "Builder").
#[inline]
fn partition_lomuto(prims: &mut [BuildPrim], pred: impl Fn(&BuildPrim) -> bool) -> usize {
    let mut j = 0;
    for i in 0..prims.len() {
        let go = pred(&prims[i]);
        prims.swap(i, j);
        j += go as usize;
    }
    j
}

/// Moves the elements satisfying `pred` to the front; returns how many there are.
pub(super) fn partition(prims: &mut [BuildPrim], pred: impl Fn(&BuildPrim) -> bool) -> usize {
    let mut i = 0;
    let mut j = prims.len();
    while i < j {
        if pred(&prims[i]) {
            i += 1;
        } else {
            j -= 1;
            prims.swap(i, j);
        }
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Aabb, Vec3};
    use crate::rng::Rng;

    #[test]
    fn parallel_partition_splits_like_the_serial_one() {
        // Chunks of 64 (instead of 65536) so that small inputs have many chunks, partial last
        // chunks, chunks all on one side and boundaries inside or between chunks.
        let mut rng = Rng::new(7, 11);
        for len in (1..200).chain([640, 1000, 4097, 20000]) {
            let mut prims: Vec<BuildPrim> = (0..len as u32)
                .map(|id| {
                    let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                    BuildPrim::new(Aabb::new(c, c + Vec3::splat(rng.next_f32() * 0.01)), id)
                })
                .collect();
            let mut serial = prims.clone();
            let cut = 2.0 * rng.next_f32();
            let left = |c2: Vec4| c2.x < cut;
            let (mid, li, ri) = partition_with_info_par(&mut prims, left, 64);
            let (want, wl, wr) = partition_with_info(&mut serial, left);
            assert_eq!(mid, want, "len {len}");
            assert!(prims[..mid].iter().all(|p| left(p.centroid2())), "len {len}");
            assert!(!prims[mid..].iter().any(|p| left(p.centroid2())), "len {len}");
            let mut ids: Vec<u32> = prims.iter().map(|p| p.id()).collect();
            ids.sort_unstable();
            assert_eq!(ids, (0..len as u32).collect::<Vec<_>>(), "len {len}");
            for (got, want) in [(li, wl), (ri, wr)] {
                assert_eq!(got.bounds.aabb(), want.bounds.aabb(), "len {len}");
                assert_eq!(got.centroids.aabb(), want.centroids.aabb(), "len {len}");
            }
        }
    }

    #[test]
    fn block_partition_splits_like_the_plain_one() {
        // Below two blocks (128 elements) this is `partition_lomuto` alone; above, the
        // blocks and then `partition_lomuto` on the rest.
        let mut rng = Rng::new(5, 9);
        for len in (0..300).chain([511, 512, 513, 1000, 4099]) {
            // Runs of each side of random lengths, and uniformly mixed sides.
            for runs in [false, true] {
                let mut left = rng.next_f32() < 0.5;
                let mut prims: Vec<BuildPrim> = (0..len as u32)
                    .map(|id| {
                        left = if runs { left ^ (rng.next_f32() < 0.1) } else { rng.next_f32() < 0.5 };
                        let x = if left { -1.0 } else { 1.0 };
                        BuildPrim::new(Aabb::new(Vec3::new(x, 0.0, 0.0), Vec3::new(x, 1.0, 1.0)), id)
                    })
                    .collect();
                let mut plain = prims.clone();
                let pred = |p: &BuildPrim| p.lower.x < 0.0;
                let mid = partition_blocks(&mut prims, pred, |_, _| {});
                assert_eq!(mid, partition(&mut plain, pred), "len {len}");
                assert!(prims[..mid].iter().all(pred) && !prims[mid..].iter().any(pred), "len {len}");
                let ids = |v: &[BuildPrim]| {
                    let mut ids: Vec<u32> = v.iter().map(|p| p.id()).collect();
                    ids.sort_unstable();
                    ids
                };
                assert_eq!(ids(&prims), (0..len as u32).collect::<Vec<_>>());
            }
        }
    }
}
