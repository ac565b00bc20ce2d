//! The traversal stack every BVH8 kernel keeps its deferred subtrees on: a fixed array of
//! [`BVH8_STACK`] entries, as Embree's `StackItemT` arrays and pbrt-v4's `nodesToVisit` are.
//!
//! The entries are left uninitialised until pushed: a kernel call starts with an empty stack
//! and most rays push a few dozen entries, so writing the whole array (kilobytes) per ray
//! would cost more than the traversal of a small tree. The one `unsafe` block reads the
//! pushed entries, which the stack's length keeps track of.

use crate::bvh::BVH8_STACK;
use crate::bvh::node::NodeRef;
use std::mem::MaybeUninit;

/// A stack of at most `N` entries of `T` (a child reference, with its entry distance or lane
/// mask where the kernel needs them) in storage the kernel owns ([`stack_storage`]). Pushing
/// past `N` panics; the trees built here are at most [`crate::bvh::MAX_DEPTH`] deep, which
/// bounds a traversal's stack by [`BVH8_STACK`].
///
/// The stack borrows its storage rather than holding it so that it is two words, a pointer
/// and the length, which the compiler keeps in registers: with the length beside the array
/// in one value it stayed in memory, a store and a load per pop.
pub(crate) struct TraversalStack<'s, T: Copy, const N: usize = BVH8_STACK> {
    items: &'s mut [MaybeUninit<T>; N],
    /// Entries `0..len` of `items` were written by this stack's pushes.
    len: usize,
}

/// Storage for a [`TraversalStack`] of `N` entries, not initialised.
#[inline(always)]
pub(crate) const fn stack_storage<T: Copy, const N: usize>() -> [MaybeUninit<T>; N] {
    [const { MaybeUninit::uninit() }; N]
}

/// An entry that carries a distance to sort by (the closest-hit kernels' order).
pub(crate) trait Distance: Copy {
    /// The entry's distance (a lower bound of where its subtree's hits lie).
    fn distance(&self) -> f32;
}

impl<'s, T: Copy, const N: usize> TraversalStack<'s, T, N> {
    /// An empty stack in `items` (whatever they hold).
    #[inline(always)]
    pub(crate) fn new(items: &'s mut [MaybeUninit<T>; N]) -> Self {
        Self { items, len: 0 }
    }

    /// The number of entries.
    #[inline(always)]
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Drops every entry.
    #[inline(always)]
    pub(crate) fn clear(&mut self) {
        self.len = 0;
    }

    /// Pushes `item`.
    #[inline(always)]
    pub(crate) fn push(&mut self, item: T) {
        self.items[self.len] = MaybeUninit::new(item);
        self.len += 1;
    }

    /// Removes and returns the top entry; `None` when the stack is empty.
    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<T> {
        let top = *self.entries_mut().last()?;
        self.len -= 1;
        Some(top)
    }

    /// Every entry, the bottom first.
    #[inline(always)]
    fn entries_mut(&mut self) -> &mut [T] {
        // SAFETY: `len <= N` (`new` starts at 0; `push` indexes `items` with bounds checks
        // before it grows `len`), entries `0..len` were written by this stack's `push` (the
        // storage is borrowed for the stack's life, so nothing else writes it), and
        // `MaybeUninit<T>` has `T`'s layout.
        unsafe { std::slice::from_raw_parts_mut(self.items.as_mut_ptr().cast::<T>(), self.len) }
    }
}

impl<T: Distance, const N: usize> TraversalStack<'_, T, N> {
    /// Sorts the entries from `base` (at most the length) up by decreasing distance
    /// (insertion sort, stable: of equal distances the later pushed stays above), so that
    /// the nearest pops first. Kernels push at most seven entries per node and sort them.
    #[inline(always)]
    pub(crate) fn sort_from_by_decreasing_distance(&mut self, base: usize) {
        let run = &mut self.entries_mut()[base..];
        for i in 1..run.len() {
            let e = run[i];
            let mut j = i;
            while j > 0 && run[j - 1].distance() < e.distance() {
                run[j] = run[j - 1];
                j -= 1;
            }
            run[j] = e;
        }
    }
}

/// A deferred subtree and the entry distance of its box: the closest-hit kernels' entry.
/// Packed to 12 bytes (the reference at 4-byte alignment; x86 loads it unaligned at no
/// cost), the size of the two arrays it replaces, so that the stack's frame stays as small.
#[derive(Clone, Copy, Debug)]
#[repr(C, packed(4))]
pub(crate) struct NearEntry {
    /// The subtree.
    pub(crate) node: NodeRef,
    /// A lower bound of the distances of its hits.
    pub(crate) dist: f32,
}

impl Distance for NearEntry {
    #[inline(always)]
    fn distance(&self) -> f32 {
        self.dist
    }
}

impl Distance for (NodeRef, u32, f32) {
    #[inline(always)]
    fn distance(&self) -> f32 {
        self.2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    impl Distance for (u32, f32) {
        fn distance(&self) -> f32 {
            self.1
        }
    }

    #[test]
    fn pops_in_reverse_push_order_and_then_none() {
        let mut items = stack_storage::<u32, 8>();
        let mut s = TraversalStack::new(&mut items);
        assert_eq!(s.pop(), None);
        for i in 0..8 {
            s.push(i);
        }
        assert_eq!(s.len(), 8);
        let popped: Vec<u32> = std::iter::from_fn(|| s.pop()).collect();
        assert_eq!(popped, (0..8).rev().collect::<Vec<_>>());
        assert_eq!((s.len(), s.pop()), (0, None));
        s.push(1);
        s.push(2);
        s.clear();
        assert_eq!((s.len(), s.pop()), (0, None));
    }

    #[test]
    #[should_panic]
    fn pushing_past_the_capacity_panics() {
        let mut items = stack_storage::<u32, 2>();
        let mut s = TraversalStack::new(&mut items);
        for i in 0..3 {
            s.push(i);
        }
    }

    /// The sorted run against a stable sort by decreasing distance; entries below `base` stay.
    #[test]
    fn sorts_the_run_above_base_by_decreasing_distance_stably() {
        let mut rng = crate::rng::Rng::new(3, 1);
        for case in 0..500 {
            let below = case % 3;
            let run = 1 + case % 7;
            let entries: Vec<(u32, f32)> =
                (0..below + run).map(|i| (i as u32, (rng.next_f32() * 4.0).floor())).collect();
            let mut items = stack_storage::<(u32, f32), 16>();
            let mut s = TraversalStack::new(&mut items);
            for &e in &entries {
                s.push(e);
            }
            s.sort_from_by_decreasing_distance(below);
            let mut want = entries.clone();
            want[below..].sort_by(|a, b| b.1.total_cmp(&a.1));
            let got: Vec<(u32, f32)> = std::iter::from_fn(|| s.pop()).collect();
            want.reverse();
            assert_eq!(got, want, "case {case}");
        }
    }
}
