//! The cache file's layout: a 64-byte [`FileHeader`], a table of [`SectionEntry`]s, then the
//! sections, each a plain `bytemuck::Pod` array on a 64-byte boundary. [`SectionWriter`]
//! writes one; [`CacheFile`] checks one (magic, version, key, length, checksum) and hands out
//! its sections, in place in a mapping or copied. What the sections hold, and when a file is
//! trusted, is the business of the parent module.

use super::{CacheError, CacheKey, FORMAT_VERSION, MAGIC};
use crate::bvh::BvhArray;
use memmap2::Mmap;
use std::io::Write;
use std::path::Path;
use std::sync::Arc;
use xxhash_rust::xxh3::Xxh3;

/// Sections of at least this many bytes are copied out of the mapping in parallel.
const PARALLEL_COPY_BYTES: usize = 1 << 20;

/// The file header: 64 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FileHeader {
    /// [`MAGIC`].
    pub magic: [u8; 8],
    /// [`FORMAT_VERSION`].
    pub version: u32,
    /// Number of [`SectionEntry`]s after the header.
    pub sections: u32,
    /// The [`CacheKey`], little-endian.
    pub key: [u8; 16],
    /// XXH3-64 of every byte of the file but these eight.
    pub checksum: u64,
    /// Length of the whole file.
    pub file_len: u64,
    /// Zero.
    pub reserved: [u64; 2],
}
const _: () = assert!(std::mem::size_of::<FileHeader>() == 64);
const CHECKSUM_AT: usize = std::mem::offset_of!(FileHeader, checksum);

/// One section of the table after the header: 32 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SectionEntry {
    /// ASCII name, zero-padded.
    pub name: [u8; 12],
    /// `size_of` of one element.
    pub elem_size: u32,
    /// Byte offset of the first element from the start of the file (a multiple of 64).
    pub offset: u64,
    /// Number of elements.
    pub count: u64,
}
const _: () = assert!(std::mem::size_of::<SectionEntry>() == 32);

/// Alignment of every section in the file (a cache line, the strictest block alignment).
const SECTION_ALIGN: u64 = 64;

fn section_name(name: &str) -> [u8; 12] {
    let mut n = [0u8; 12];
    assert!(name.len() <= 12, "section name {name:?} longer than 12 bytes");
    n[..name.len()].copy_from_slice(name.as_bytes());
    n
}

/// Collects `Pod` arrays and writes them as one cache file.
pub(crate) struct SectionWriter<'a> {
    entries: Vec<SectionEntry>,
    data: Vec<&'a [u8]>,
}

impl<'a> SectionWriter<'a> {
    pub(crate) fn new() -> Self {
        Self { entries: Vec::new(), data: Vec::new() }
    }

    /// Adds the array `items` under `name` (at most 12 ASCII bytes).
    pub(crate) fn push<T: bytemuck::Pod>(&mut self, name: &str, items: &'a [T]) {
        self.entries.push(SectionEntry {
            name: section_name(name),
            elem_size: std::mem::size_of::<T>() as u32,
            offset: 0,
            count: items.len() as u64,
        });
        self.data.push(bytemuck::cast_slice(items));
    }

    /// Writes header, table and sections to `out`, returning the number of bytes.
    pub(crate) fn write_to(mut self, key: CacheKey, out: &mut dyn Write) -> std::io::Result<u64> {
        let table_end = (64 + 32 * self.entries.len()) as u64;
        let mut at = table_end.next_multiple_of(SECTION_ALIGN);
        for (e, d) in self.entries.iter_mut().zip(&self.data) {
            e.offset = at;
            at = (at + d.len() as u64).next_multiple_of(SECTION_ALIGN);
        }
        let file_len = self.data.last().map_or(table_end, |d| self.entries.last().unwrap().offset + d.len() as u64);
        let mut header = FileHeader {
            magic: MAGIC,
            version: FORMAT_VERSION,
            sections: self.entries.len() as u32,
            key: key.0.to_le_bytes(),
            checksum: 0,
            file_len,
            reserved: [0; 2],
        };
        let table: &[u8] = bytemuck::cast_slice(&self.entries);
        let zeros = [0u8; SECTION_ALIGN as usize];
        // The pieces of the file in order: header, table, then per section padding and data.
        let mut pieces: Vec<&[u8]> = vec![table];
        let mut pos = table_end;
        for (e, d) in self.entries.iter().zip(&self.data) {
            pieces.push(&zeros[..(e.offset - pos) as usize]);
            pieces.push(d);
            pos = e.offset + d.len() as u64;
        }
        let mut h = Xxh3::new();
        let head_bytes = bytemuck::bytes_of(&header);
        h.update(&head_bytes[..CHECKSUM_AT]);
        h.update(&head_bytes[CHECKSUM_AT + 8..]);
        for p in &pieces {
            h.update(p);
        }
        header.checksum = h.digest();
        out.write_all(bytemuck::bytes_of(&header))?;
        for p in &pieces {
            out.write_all(p)?;
        }
        out.flush()?;
        Ok(file_len)
    }
}

/// A cache file mapped into memory whose header, length and checksum have been checked.
pub(crate) struct CacheFile<'a> {
    /// The file, for errors.
    pub(crate) path: &'a Path,
    bytes: &'a [u8],
    entries: Vec<SectionEntry>,
    /// The mapping `bytes` is, when sections may be used in place.
    map: Option<Arc<Mmap>>,
}

impl<'a> CacheFile<'a> {
    /// Checks `bytes` (the whole file at `path`) against `key`.
    pub(crate) fn check(path: &'a Path, bytes: &'a [u8], key: CacheKey) -> Result<Self, CacheError> {
        let p = || path.to_path_buf();
        let header_len = std::mem::size_of::<FileHeader>();
        if bytes.len() < header_len {
            if bytes.len() >= 8 && bytes[..8] != MAGIC {
                return Err(CacheError::BadMagic { path: p() });
            }
            return Err(CacheError::Truncated { path: p(), len: bytes.len() as u64, expected: header_len as u64 });
        }
        let header: FileHeader = bytemuck::pod_read_unaligned(&bytes[..header_len]);
        if header.magic != MAGIC {
            return Err(CacheError::BadMagic { path: p() });
        }
        if header.version != FORMAT_VERSION {
            return Err(CacheError::Version { path: p(), found: header.version, expected: FORMAT_VERSION });
        }
        let found = CacheKey(u128::from_le_bytes(header.key));
        if found != key {
            return Err(CacheError::Stale { path: p(), found, expected: key });
        }
        if (bytes.len() as u64) < header.file_len {
            return Err(CacheError::Truncated { path: p(), len: bytes.len() as u64, expected: header.file_len });
        }
        let mut h = Xxh3::new();
        h.update(&bytes[..CHECKSUM_AT]);
        h.update(&bytes[CHECKSUM_AT + 8..]);
        if h.digest() != header.checksum {
            return Err(CacheError::Checksum { path: p() });
        }
        if bytes.len() as u64 != header.file_len {
            // Consistent checksum over extra bytes: only a forged file gets here.
            return Err(CacheError::Malformed { path: p(), what: "trailing bytes".into() });
        }
        let table_end = 64 + 32 * header.sections as usize;
        let table = bytes.get(64..table_end).ok_or_else(|| CacheError::Malformed {
            path: p(),
            what: format!("{} sections do not fit", header.sections),
        })?;
        let entries = table.chunks_exact(32).map(bytemuck::pod_read_unaligned).collect();
        Ok(Self { path, bytes, entries, map: None })
    }

    /// [`CacheFile::check`] of a whole mapped file, whose sections
    /// [`CacheFile::section_in_place`] can then use where they lie.
    pub(crate) fn check_mapped(path: &'a Path, map: &'a Arc<Mmap>, key: CacheKey) -> Result<Self, CacheError> {
        Ok(Self { map: Some(map.clone()), ..Self::check(path, map, key)? })
    }

    /// Section `name` used in place in the mapping (copied when the file is not mapped or
    /// the section is misaligned for `T`), checking its element size and extent.
    pub(crate) fn section_in_place<T: bytemuck::Pod + Send + Sync>(
        &self,
        name: &str,
    ) -> Result<BvhArray<T>, CacheError> {
        let range = self.section_range::<T>(name)?;
        match self.map.as_ref().and_then(|m| BvhArray::mapped(m.clone(), range)) {
            Some(a) => Ok(a),
            None => self.section(name).map(BvhArray::from),
        }
    }

    /// The byte range of section `name`, checking its element size and extent.
    fn section_range<T>(&self, name: &str) -> Result<std::ops::Range<usize>, CacheError> {
        let malformed = |what: String| CacheError::Malformed { path: self.path.to_path_buf(), what };
        let wanted = section_name(name);
        let e =
            self.entries.iter().find(|e| e.name == wanted).ok_or_else(|| malformed(format!("no section {name}")))?;
        let size = std::mem::size_of::<T>();
        if e.elem_size as usize != size {
            return Err(malformed(format!("section {name} has {}-byte elements, expected {size}", e.elem_size)));
        }
        e.count
            .checked_mul(size as u64)
            .and_then(|n| n.checked_add(e.offset))
            .filter(|&end| end <= self.bytes.len() as u64)
            .map(|end| e.offset as usize..end as usize)
            .ok_or_else(|| malformed(format!("section {name} runs past the end of the file")))
    }

    /// Copies out section `name`, checking its element size and extent.
    pub(crate) fn section<T: bytemuck::Pod + Send + Sync>(&self, name: &str) -> Result<Vec<T>, CacheError> {
        let range = self.section_range::<T>(name)?;
        if std::mem::size_of::<T>() == 0 {
            return Ok(Vec::new());
        }
        let bytes = &self.bytes[range];
        // Sections start on 64-byte boundaries of a page-aligned mapping, so the cast succeeds
        // and the copy needs no zeroing first; the fallback handles any alignment. Large
        // sections are copied by all threads: the page faults of the fresh destination are
        // most of a cached start.
        Ok(match bytemuck::try_cast_slice::<u8, T>(bytes) {
            Ok(items) if bytes.len() >= PARALLEL_COPY_BYTES => {
                use rayon::prelude::*;
                let mut v = Vec::with_capacity(items.len());
                v.par_extend(items.par_iter().copied());
                v
            }
            Ok(items) => items.to_vec(),
            Err(_) => bytemuck::pod_collect_to_vec(bytes),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Aabb;

    #[test]
    fn sections_round_trip_through_bytes() {
        let a = [1u32, 2, 3];
        let b = [Aabb::from_point(crate::Vec3::X)];
        let mut w = SectionWriter::new();
        w.push("a", &a);
        w.push("b", &b);
        let mut bytes = Vec::new();
        let len = w.write_to(CacheKey(7), &mut bytes).unwrap();
        assert_eq!(len as usize, bytes.len());
        let f = CacheFile::check(Path::new("x"), &bytes, CacheKey(7)).unwrap();
        assert_eq!(f.section::<u32>("a").unwrap(), a);
        assert_eq!(f.section::<Aabb>("b").unwrap(), b);
        assert!(matches!(f.section::<u64>("a"), Err(CacheError::Malformed { .. })));
        assert!(matches!(f.section::<u32>("c"), Err(CacheError::Malformed { .. })));
        assert!(matches!(CacheFile::check(Path::new("x"), &bytes, CacheKey(8)), Err(CacheError::Stale { .. })));
        for i in 0..bytes.len() {
            let mut bad = bytes.clone();
            bad[i] ^= 0x10;
            assert!(CacheFile::check(Path::new("x"), &bad, CacheKey(7)).is_err(), "flipped byte {i} accepted");
        }
    }
}
