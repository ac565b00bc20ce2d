//! The arrays of the 8-wide BVH: owned, fresh zero pages, or used in place from a
//! memory-mapped cache file.

use std::ops::{Deref, DerefMut, Range};
use std::sync::Arc;

/// An array of BVH nodes or leaf blocks: a `Vec`, fresh anonymous memory a build filled, or
/// a section of a memory-mapped BVH cache file ([`crate::scene::cache`]) used where it lies.
/// Reads see a slice either way; the first mutable access to a mapped array
/// ([`BvhArray::to_mut`], `DerefMut`) copies it into an owned one.
///
/// Using the mapping in place is what makes a cached start cheap: pages the file's mapping
/// shares with the page cache cost nothing, where a copy pays a page fault per fresh page
/// (PERFORMANCE.md, "BVH cache").
///
/// The builder's large arrays are anonymous mappings (`BvhArray::zeroed`): zero pages that
/// the kernel provides on first touch, so the parallel tasks that fill them pay the page
/// faults in parallel, and nothing writes them twice (a `Vec` of 64-byte-aligned blocks is
/// zeroed by one thread with `memset`).
pub struct BvhArray<T> {
    repr: Repr<T>,
}

enum Repr<T> {
    Owned(Vec<T>),
    /// `map[range]` holds a whole number of `T`s and starts on a `T` boundary (checked by
    /// [`BvhArray::mapped`]); `view` is that range as `T`s.
    Mapped {
        map: Arc<memmap2::Mmap>,
        range: Range<usize>,
        view: View<T>,
    },
    /// The first `len` elements of an anonymous mapping (page-aligned, so aligned for `T`);
    /// `view` is them as `T`s.
    Anon {
        map: memmap2::MmapMut,
        len: usize,
        view: View<T>,
    },
}

/// A mapping's elements as `T`s, cast once when the array is made: every query takes the
/// arrays' slices, and the cast's checks (alignment, whole elements) cost ~15 instructions
/// each time, measurable in the single-ray kernels (see [`View::slice`]).
struct View<T> {
    ptr: std::ptr::NonNull<T>,
    len: usize,
}

impl<T: bytemuck::Pod> View<T> {
    fn of(bytes: &[u8]) -> Self {
        let s: &[T] = bytemuck::cast_slice(bytes);
        Self { ptr: std::ptr::NonNull::from(s).cast(), len: s.len() }
    }

    /// The elements, from the cast made once when the view was made: casting at every
    /// access cost the single-ray kernel instructions (PERFORMANCE.md, "Smaller measured
    /// choices").
    #[inline(always)]
    fn slice(&self) -> &[T] {
        // SAFETY: `ptr` and `len` describe the cast of the mapping's bytes made in `View::of`;
        // the mapping is owned by (or shared through an `Arc` with) the same `Repr` variant
        // and never moves or shrinks while it lives, so the elements stay valid, initialised
        // (Pod) and aligned for as long as `&self`.
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

// SAFETY: a `View` only points into the memory map held next to it in the same `Repr`
// variant (`Mmap` and `MmapMut` are `Send` and `Sync`); `BvhArray` hands out `&[T]` through
// `&self` and `&mut [T]` only through `&mut self`, so the usual rules for `T` apply.
unsafe impl<T: Send> Send for View<T> {}
// SAFETY: as above.
unsafe impl<T: Sync> Sync for View<T> {}

impl<T: bytemuck::Pod> BvhArray<T> {
    /// The elements in `map[range]`, in place; `None` when the range is out of the map,
    /// misaligned for `T` or not a whole number of elements.
    pub(crate) fn mapped(map: Arc<memmap2::Mmap>, range: Range<usize>) -> Option<Self> {
        bytemuck::try_cast_slice::<u8, T>(map.get(range.clone())?).ok()?;
        let view = View::of(&map[range.clone()]);
        Some(Self { repr: Repr::Mapped { map, range, view } })
    }

    /// `len` zeroed elements in fresh memory that is not touched until written.
    pub(crate) fn zeroed(len: usize) -> Self {
        let bytes = len.checked_mul(std::mem::size_of::<T>()).expect("array size overflows");
        match memmap2::MmapMut::map_anon(bytes) {
            Ok(map) if bytes > 0 => {
                // Transparent huge pages where the system allows them (a hint; errors are
                // ignored): incoherent rays touch the BVH all over, and with 4 KiB pages a
                // large tree misses the TLB on most node visits. Embree advises the same on its
                // BVH memory (PERFORMANCE.md, "Smaller measured choices").
                let _ = map.advise(memmap2::Advice::HugePage);
                let view = View::of(&map[..bytes]);
                Self { repr: Repr::Anon { map, len, view } }
            }
            _ => bytemuck::zeroed_vec(len).into(),
        }
    }

    /// The elements as a `Vec`, copying them first if they are not in one.
    pub fn to_mut(&mut self) -> &mut Vec<T> {
        if !matches!(self.repr, Repr::Owned(_)) {
            self.repr = Repr::Owned(self.deref().to_vec());
        }
        match &mut self.repr {
            Repr::Owned(v) => v,
            _ => unreachable!("made owned above"),
        }
    }

    /// The elements as a `Vec` (copied unless they are in one).
    pub fn into_vec(mut self) -> Vec<T> {
        std::mem::take(self.to_mut())
    }

    /// True when the elements are read from a memory-mapped cache file.
    pub fn is_mapped(&self) -> bool {
        matches!(self.repr, Repr::Mapped { .. })
    }
}

impl<T: bytemuck::Pod> Deref for BvhArray<T> {
    type Target = [T];

    #[inline(always)]
    fn deref(&self) -> &[T] {
        match &self.repr {
            Repr::Owned(v) => v,
            Repr::Mapped { view, .. } | Repr::Anon { view, .. } => view.slice(),
        }
    }
}

impl<T: bytemuck::Pod> DerefMut for BvhArray<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        if !matches!(self.repr, Repr::Anon { .. }) {
            return self.to_mut();
        }
        match &mut self.repr {
            Repr::Anon { map, len, .. } => bytemuck::cast_slice_mut(&mut map[..*len * std::mem::size_of::<T>()]),
            _ => unreachable!("checked above"),
        }
    }
}

impl<'a, T: bytemuck::Pod> IntoIterator for &'a BvhArray<T> {
    type Item = &'a T;
    type IntoIter = std::slice::Iter<'a, T>;

    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl<T> From<Vec<T>> for BvhArray<T> {
    fn from(v: Vec<T>) -> Self {
        Self { repr: Repr::Owned(v) }
    }
}

impl<T> Default for BvhArray<T> {
    fn default() -> Self {
        Self { repr: Repr::Owned(Vec::new()) }
    }
}

impl<T: bytemuck::Pod> Clone for BvhArray<T> {
    fn clone(&self) -> Self {
        let repr = match &self.repr {
            Repr::Owned(v) => Repr::Owned(v.clone()),
            Repr::Mapped { map, range, .. } => {
                Repr::Mapped { map: map.clone(), range: range.clone(), view: View::of(&map[range.clone()]) }
            }
            Repr::Anon { .. } => Repr::Owned(self.to_vec()),
        };
        Self { repr }
    }
}

impl<T: bytemuck::Pod + std::fmt::Debug> std::fmt::Debug for BvhArray<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<T: bytemuck::Pod + PartialEq> PartialEq for BvhArray<T> {
    fn eq(&self, o: &Self) -> bool {
        self[..] == o[..]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mapped_ranges_are_checked_and_writes_copy() {
        let mut m = memmap2::MmapMut::map_anon(4096).unwrap();
        m[..8].copy_from_slice(&[1, 0, 0, 0, 2, 0, 0, 0]);
        let map = Arc::new(m.make_read_only().unwrap());
        assert!(BvhArray::<u32>::mapped(map.clone(), 1..5).is_none(), "misaligned");
        assert!(BvhArray::<u32>::mapped(map.clone(), 0..6).is_none(), "not whole elements");
        assert!(BvhArray::<u32>::mapped(map.clone(), 4092..4100).is_none(), "past the end");
        let mut a = BvhArray::<u32>::mapped(map, 0..8).unwrap();
        assert!(a.is_mapped() && a[..] == [1, 2]);
        a[1] = 5;
        assert!(!a.is_mapped() && a[..] == [1, 5]);
        assert_eq!(a.into_vec(), vec![1, 5]);
    }

    #[test]
    fn zeroed_arrays_are_written_in_place() {
        let mut a = BvhArray::<[u64; 8]>::zeroed(1000);
        assert!(a.len() == 1000 && a.iter().all(|x| *x == [0; 8]));
        a[999][7] = 3;
        assert!(!a.is_mapped() && a[999][7] == 3);
        assert_eq!(a.clone()[999][7], 3);
        assert!(BvhArray::<u32>::zeroed(0).is_empty());
    }
}
