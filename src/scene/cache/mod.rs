//! The BVH cache: a committed scene's acceleration structures saved to a file and loaded back
//! by memory-mapping, so that a second start skips the build.
//!
//! A cache file is content-addressed, as ccache's objects are: its name and its header carry a
//! [`CacheKey`], a 128-bit XXH3 hash of the committed geometry (vertex positions, triangle
//! indices, sphere centres and radii, after [`SceneBuilder::commit`]'s filtering), of the
//! [`BuildOptions`], of the leaf block type and of [`FORMAT_VERSION`]. A file is trusted only
//! when its magic, version and key match, its length is the one its header records and the
//! XXH3-64 checksum of all its other bytes agrees; the BVH8's arrays are then used in place
//! in the mapping ([`crate::bvh::BvhArray`]; the binary BVH, when kept, is copied out) and
//! verified against the scene's own geometry before use (`check_accel`, which every load goes
//! through: [`crate::scene::verify::verify_accel`]): the ranges the traversal kernels index
//! with, every child box inside its parent's, every primitive inside the leaves that
//! reference it, every leaf block holding exactly the scene's primitives, and the bounds. A
//! checksum proves nothing against a forger (anyone can recompute it); the verification
//! proves that the trees trace exactly as a build would, whoever wrote them. Anything else is
//! reported in [`CacheReport::rejected`], rebuilt and overwritten.
//!
//! The trust rule, for shared cache directories: *a loaded tree is always verified, and in a
//! directory that other users can write, only files owned by this user or root are used.* A
//! co-tenant's file could be verified correct and still be built to be slow (every box the
//! scene's bounds: each ray visits every node), and no check short of a build tells a good
//! tree from a slow one; such a file is reported ([`CacheError::Untrusted`]) and the scene is
//! built (in a sticky directory, the other user's file cannot be replaced, so the new tree is
//! not written either). Users who share one cache should let one account (or root) write it.
//!
//! Shared cache directories: a file is opened only if it is a regular file of at most
//! [`max_file_bytes`] for the scene (a FIFO or `/dev/zero` planted at its name is rejected,
//! never waited on or read without end). It is mapped in place only when nobody but this user
//! (or root) can change it: owned by this user or root and writable by neither group nor
//! others. Any other file is copied into private anonymous memory first
//! ([`CacheReport::copied`]), whose sections are then used in place as a mapping's would be,
//! so that another user truncating the file during a render cannot kill it with `SIGBUS`.
//! Files are written through [`crate::fs::output`] (an unpredictable temporary name created
//! exclusively, renamed over a regular file or nothing) with mode 0644, in a directory
//! created with mode 0755; a directory that others can write is reported. Before a file is
//! written, the temporary files of its earlier writers that were killed mid-write (which
//! nothing else removes) are removed: only this user's, and never one a live writer holds
//! locked ([`crate::fs::output::remove_stale_temporaries`]).
//!
//! Layout (little-endian, as the machine writes it):
//!
//! | bytes | content |
//! |---|---|
//! | 0..64 | [`FileHeader`]: magic, version, section count, key, checksum, file length |
//! | 64.. | one [`SectionEntry`] (32 bytes) per section: name, element size, offset, count |
//! | then | the sections, each a plain array of `bytemuck::Pod` elements starting on a 64-byte boundary |
//!
//! Sections are looked up by name and element size, so a new leaf block type (for example
//! watertight triangle blocks) is one more `Pod` array: a name, a `SectionWriter::push` in
//! `store` and a `CacheFile::section_in_place` call in `read_accel`.

pub(crate) mod file;

pub use file::{FileHeader, SectionEntry};

use crate::bvh::{BuildOptions, Bvh2, Bvh2Node, Bvh8, Bvh8Node, DefaultTriBlock};
use crate::geometry::TriangleTest;
use crate::geometry::{Sphere4, Tri8};
use crate::math::Aabb;
use crate::scene::{CommitReport, Scene, SceneBuilder, SpheresSoa, TrianglesSoa};
use file::{CacheFile, SectionWriter};
use memmap2::Mmap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use xxhash_rust::xxh3::Xxh3;

/// Version of the file layout and of everything the key does not see; bump it whenever the
/// builder, the collapse or a block layout changes what a given key would produce.
pub const FORMAT_VERSION: u32 = 5;
/// First eight bytes of every cache file (the `\r\n` catches text-mode mangling, as PNG's does).
pub const MAGIC: [u8; 8] = *b"RPKBVH\r\n";
/// File name extension of cache files.
pub const EXTENSION: &str = "rpbvh";

const _: () = assert!(std::mem::size_of::<Tri8>() == 3 * 3 * 8 * 4 + 8 * 4);

/// The content hash a cache file is named and checked by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CacheKey(pub u128);

impl std::fmt::Display for CacheKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:032x}", self.0)
    }
}

impl CacheKey {
    /// The key of a scene's committed geometry built with `opts`.
    ///
    /// The options enter through their `Debug` text, which names every field and prints
    /// floats exactly, so a field added to [`BuildOptions`] later changes the key by itself.
    pub fn of(triangles: &crate::scene::TrianglesSoa, spheres: &crate::scene::SpheresSoa, opts: &BuildOptions) -> Self {
        let mut h = Xxh3::new();
        h.update(b"raypack bvh cache");
        h.update(&FORMAT_VERSION.to_le_bytes());
        h.update(std::any::type_name::<DefaultTriBlock>().as_bytes());
        h.update(&(std::mem::size_of::<DefaultTriBlock>() as u64).to_le_bytes());
        h.update(format!("{opts:?}").as_bytes());
        for bytes in [
            bytemuck::cast_slice::<_, u8>(&triangles.positions),
            bytemuck::cast_slice(&triangles.indices),
            bytemuck::cast_slice(&spheres.center),
            bytemuck::cast_slice(&spheres.radius),
        ] {
            h.update(&(bytes.len() as u64).to_le_bytes());
            h.update(bytes);
        }
        CacheKey(h.digest128())
    }

    /// The file this key names inside `dir`.
    pub fn path_in(&self, dir: &Path) -> PathBuf {
        dir.join(format!("{self}.{EXTENSION}"))
    }
}

/// Why a cache file was not used, or could not be written.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    /// Reading, writing or creating the file or its directory failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// The first bytes are not [`MAGIC`].
    #[error("{}: not a raypack BVH cache file (bad magic bytes)", path.display())]
    BadMagic {
        /// The file.
        path: PathBuf,
    },
    /// Written by another version of the format.
    #[error("{}: cache format version {found}, this raypack reads version {expected}", path.display())]
    Version {
        /// The file.
        path: PathBuf,
        /// Version in the file.
        found: u32,
        /// [`FORMAT_VERSION`].
        expected: u32,
    },
    /// Written for other geometry or other build options.
    #[error("{}: stale: written for key {found}, the scene and options give {expected}", path.display())]
    Stale {
        /// The file.
        path: PathBuf,
        /// Key in the file.
        found: CacheKey,
        /// Key of the scene being committed.
        expected: CacheKey,
    },
    /// Shorter than its header says (or than a header).
    #[error("{}: truncated: {len} bytes, expected {expected}", path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Its length.
        len: u64,
        /// The length its header records (or the header's).
        expected: u64,
    },
    /// The checksum of the file's bytes disagrees with the header's.
    #[error("{}: checksum mismatch (the file was edited or corrupted)", path.display())]
    Checksum {
        /// The file.
        path: PathBuf,
    },
    /// In a directory other users can write, a file owned by someone else (neither this user
    /// nor root): never used (see the module docs).
    #[error(
        "{}: owned by uid {uid} in a directory other users can write; raypack uses only its own (or root's) cache \
         files there",
        path.display()
    )]
    Untrusted {
        /// The file.
        path: PathBuf,
        /// Its owner.
        uid: u32,
    },
    /// Well-formed header, but the sections or the trees in them are not what a build makes.
    #[error("{}: malformed: {what}", path.display())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
}

/// What [`SceneBuilder::commit_cached`] did with the cache.
#[derive(Debug)]
pub struct CacheReport {
    /// The cache file of this scene and these options.
    pub path: PathBuf,
    /// True when the acceleration structures came from the file.
    pub loaded: bool,
    /// True when the file could be changed by another user, so it was copied into private
    /// memory instead of being mapped in place (see the module docs).
    pub copied: bool,
    /// Who else can write the cache directory, when someone can (`"others"`, `"its group"`,
    /// `"its owner, uid N"`): they can replace the cache files.
    pub dir_writable_by: Option<String>,
    /// The file that was there but not trusted (and has been rebuilt), if any.
    pub rejected: Option<CacheError>,
    /// Writing the rebuilt structures failed (the scene is fine; the next start builds again).
    pub write_error: Option<CacheError>,
}

impl CacheReport {
    /// One line per problem, for the user (empty when the cache worked).
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if let Some(who) = &self.dir_writable_by {
            let dir = self.path.parent().unwrap_or(Path::new("."));
            w.push(format!(
                "BVH cache directory {} is writable by {who}: they can replace its files (raypack checks every \
                 file, and copies files it does not own instead of mapping them)",
                dir.display()
            ));
        }
        if self.copied {
            w.push(format!(
                "BVH cache file {} can be changed by other users: read into memory instead of mapped (a slower start)",
                self.path.display()
            ));
        }
        if let Some(e) = &self.rejected {
            w.push(format!("BVH cache rejected and rebuilt: {e}"));
        }
        if let Some(e) = &self.write_error {
            w.push(format!("BVH cache not written: {e}"));
        }
        w
    }
}

impl SceneBuilder {
    /// [`SceneBuilder::commit`] through a BVH cache in `dir` (created if missing): loads the
    /// acceleration structures from the file of this geometry and `opts` when it is valid,
    /// otherwise builds them and writes the file. Never fails: cache problems are reported
    /// in the [`CacheReport`] and the scene is built instead.
    ///
    /// ```
    /// use raypack::{BuildOptions, Material, Ray, SceneBuilder, Vec3};
    ///
    /// let dir = std::env::temp_dir().join(format!("raypack-doc-cache-{}", std::process::id()));
    /// let scene = || {
    ///     let mut b = SceneBuilder::new();
    ///     let m = b.add_material(Material::default());
    ///     b.add_mesh(&[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]], m).unwrap();
    ///     b
    /// };
    /// let (_, _, first) = scene().commit_cached(&BuildOptions::default(), &dir);
    /// let (s, _, second) = scene().commit_cached(&BuildOptions::default(), &dir);
    /// assert!(!first.loaded && second.loaded && second.warnings().is_empty());
    /// assert_eq!(s.intersect1(&Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z)).t, 1.0);
    /// # std::fs::remove_dir_all(&dir).unwrap();
    /// ```
    pub fn commit_cached(self, opts: &BuildOptions, dir: &Path) -> (Scene, CommitReport, CacheReport) {
        let (kept, report) = self.filter();
        let key = CacheKey::of(&kept.triangles, &kept.spheres, opts);
        let path = key.path_in(dir);
        let mut cache = CacheReport {
            path: path.clone(),
            loaded: false,
            copied: false,
            dir_writable_by: None,
            rejected: None,
            write_error: None,
        };
        cache.dir_writable_by = writable_by_others(dir);
        // The key covers `opts`, so the file's blocks are laid out for their triangle test.
        let test = TriangleTest::from_watertight(opts.watertight);
        let shared = cache.dir_writable_by.is_some();
        match load(&path, key, (&kept.triangles, &kept.spheres), test, shared) {
            Ok(Some((accel, copied))) => {
                cache.loaded = true;
                cache.copied = copied;
                let accel = accel.into_layout(opts.layout);
                return (kept.with_accel(accel.bounds, accel.bvh2, accel.bvh8), report, cache);
            }
            Ok(None) => {}
            Err(e) => cache.rejected = Some(e),
        }
        let scene = kept.build(opts);
        cache.write_error = store(dir, &path, key, &scene).err();
        cache.dir_writable_by = writable_by_others(dir);
        (scene, report, cache)
    }
}

/// The triangle blocks of `scene`'s BVH8 in the default layout: its own, or those its id
/// blocks name, built as the kernels build them (so a file holds the same bytes either way).
pub(crate) fn stored_blocks(scene: &Scene) -> std::borrow::Cow<'_, [Tri8]> {
    let b = &scene.bvh8;
    if b.ids.is_empty() {
        std::borrow::Cow::Borrowed(&b.tris[..])
    } else {
        let t = &scene.triangles;
        std::borrow::Cow::Owned(b.ids.iter().map(|ids| ids.tri8(&t.positions, &t.indices, b.test)).collect())
    }
}

/// The acceleration structures a cache file holds.
pub(crate) struct Accel {
    pub(crate) bounds: Aabb,
    /// Stored as empty sections when the build did not keep it.
    pub(crate) bvh2: Option<Bvh2>,
    pub(crate) bvh8: Bvh8,
}

impl Accel {
    /// The structures with the BVH8 in `layout` (files hold the default layout's blocks,
    /// verified before this).
    pub(crate) fn into_layout(mut self, layout: crate::bvh::TreeLayout) -> Self {
        if layout == crate::bvh::TreeLayout::Compact {
            self.bvh8 = self.bvh8.into_compact();
        }
        self
    }
}

/// The largest cache file read for a scene of `num_prims` primitives: far above what a build
/// writes (at most about 620 bytes per primitive, when every leaf block holds one triangle and
/// the binary BVH is kept), so that a planted file cannot make the loader read more.
pub fn max_file_bytes(num_prims: usize) -> u64 {
    (num_prims as u64).saturating_mul(1024).saturating_add(1 << 20)
}

/// Reads the cache file at `path` for the committed `geometry`, whose trees are laid out for
/// `test`; `shared`: other users can write the directory. `Ok(None)` when there is none; with
/// the structures, whether the file was copied rather than mapped (see the module docs).
fn load(
    path: &Path,
    key: CacheKey,
    geometry: (&TrianglesSoa, &SpheresSoa),
    test: TriangleTest,
    shared: bool,
) -> Result<Option<(Accel, bool)>, CacheError> {
    use crate::fs::input::open_regular;
    let num_prims = geometry.0.len() + geometry.1.len();
    let (file, len) = match open_regular(path, max_file_bytes(num_prims), "BVH cache files of this scene") {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(path)(e)),
    };
    if len < std::mem::size_of::<FileHeader>() as u64 {
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(&mut std::io::Read::take(&file, len), &mut bytes).map_err(io(path))?;
        return CacheFile::check(path, &bytes, key).map(|_| None);
    }
    let meta = file.metadata().map_err(io(path))?;
    if shared && let Some(uid) = foreign_owner(&meta) {
        return Err(CacheError::Untrusted { path: path.to_path_buf(), uid });
    }
    let private = changed_only_by_us(&meta);
    let map = if private {
        // SAFETY: the mapping is read-only, and the BVH8's arrays read it in place for as long
        // as the scene lives. Only this user or root can change the file (checked just above on
        // the open descriptor), and raypack never modifies a cache file in place (it renames a
        // new file over it, which leaves this mapping's inode intact). The user truncating the
        // file by hand during a render would raise SIGBUS, the risk of every memory-mapped
        // reader; files others can change are copied instead. Bytes changed under us after the
        // checks below cannot cause undefined behaviour (the arrays are plain `Pod` data and
        // every kernel index is bounds-checked), only wrong hits or a panic. `populate` reads
        // the whole file ahead (MAP_POPULATE) instead of faulting page by page.
        unsafe { memmap2::MmapOptions::new().populate().map(&file) }.map_err(io(path))?
    } else {
        copy_to_private_memory(&file, len).map_err(io(path))?
    };
    let map = Arc::new(map);
    let file = CacheFile::check_mapped(path, &map, key)?;
    let mut accel = read_accel(&file)?;
    accel.bvh8.test = test;
    check_accel(&accel, geometry).map_err(|what| CacheError::Malformed { path: path.to_path_buf(), what })?;
    Ok(Some((accel, !private)))
}

/// The owners whose files no other user can change: this user and root.
#[cfg(unix)]
fn trusted_owner(uid: u32) -> bool {
    // SAFETY: geteuid has no preconditions and cannot fail.
    uid == 0 || uid == unsafe { libc::geteuid() }
}

/// The owner of the file, when it is neither this user nor root.
fn foreign_owner(meta: &std::fs::Metadata) -> Option<u32> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        (!trusted_owner(meta.uid())).then_some(meta.uid())
    }
    #[cfg(not(unix))]
    {
        let _ = meta;
        None
    }
}

/// True when nobody but this user (or root) can write the file: it is owned by one of them
/// and writable by neither group nor others.
fn changed_only_by_us(meta: &std::fs::Metadata) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        trusted_owner(meta.uid()) && meta.mode() & 0o022 == 0
    }
    #[cfg(not(unix))]
    {
        let _ = meta;
        false
    }
}

/// Who besides this user can create, replace or delete files in `dir` (see
/// [`CacheReport::dir_writable_by`]); `None` when nobody, or when `dir` cannot be read.
fn writable_by_others(dir: &Path) -> Option<String> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let meta = std::fs::metadata(dir).ok()?;
        if meta.mode() & 0o002 != 0 {
            Some(format!("all users (mode {:o})", meta.mode() & 0o7777))
        } else if meta.mode() & 0o020 != 0 {
            Some(format!("its group (gid {}, mode {:o})", meta.gid(), meta.mode() & 0o7777))
        } else if !trusted_owner(meta.uid()) {
            Some(format!("its owner (uid {})", meta.uid()))
        } else {
            None
        }
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        None
    }
}

/// The first `len` bytes of `file` in fresh read-only anonymous memory (page-aligned, so the
/// sections can be used in place as in a mapping of the file); a file cut short meanwhile is
/// an error. (The page faults of the fresh memory are most of the cost: PERFORMANCE.md,
/// "BVH cache".)
pub(crate) fn copy_to_private_memory(file: &std::fs::File, len: u64) -> std::io::Result<Mmap> {
    let mut copy = memmap2::MmapMut::map_anon(len as usize)?;
    #[cfg(unix)]
    std::os::unix::fs::FileExt::read_exact_at(file, &mut copy, 0)?;
    #[cfg(not(unix))]
    std::io::Read::read_exact(&mut &*file, &mut copy)?;
    copy.make_read_only()
}

pub(crate) fn read_accel(f: &CacheFile) -> Result<Accel, CacheError> {
    let bounds = f.section::<Aabb>("bounds")?;
    let bounds = match bounds[..] {
        [b] => b,
        _ => return Err(CacheError::Malformed { path: f.path.to_path_buf(), what: "bounds is not one box".into() }),
    };
    Ok(Accel {
        bounds,
        bvh2: Some(Bvh2 { nodes: f.section::<Bvh2Node>("bvh2.nodes")?, prim_ids: f.section("bvh2.prims")? })
            .filter(|b| !b.nodes.is_empty()),
        bvh8: Bvh8 {
            nodes: f.section_in_place::<Bvh8Node>("bvh8.nodes")?,
            tris: f.section_in_place::<DefaultTriBlock>("bvh8.tris")?,
            ids: Default::default(),
            spheres: f.section_in_place::<Sphere4>("bvh8.spheres")?,
            // Set from the options by the caller (the key covers them).
            test: TriangleTest::default(),
        },
    })
}

/// The check every cache image passes before it is used: [`crate::scene::verify::verify_accel`]
/// against the scene's committed geometry, so that the trees trace exactly as a build would
/// (the ranges the kernels index with, every box holding its children and its primitives,
/// every block holding the scene's own primitives, the bounds). The caller sets
/// `a.bvh8.test` first: the blocks are compared in its layout.
pub(crate) fn check_accel(a: &Accel, geometry: (&TrianglesSoa, &SpheresSoa)) -> Result<(), String> {
    crate::scene::verify::verify_accel(geometry.0, geometry.1, &a.bounds, a.bvh2.as_ref(), &a.bvh8)
        .map_err(|e| e.to_string())
}

fn io(p: &Path) -> impl Fn(std::io::Error) -> CacheError + '_ {
    move |source| CacheError::Io { path: p.to_path_buf(), source }
}

fn store(dir: &Path, path: &Path, key: CacheKey, scene: &Scene) -> Result<(), CacheError> {
    use crate::fs::output::{OutputOptions, stage};
    let mut create = std::fs::DirBuilder::new();
    create.recursive(true);
    #[cfg(unix)]
    std::os::unix::fs::DirBuilderExt::mode(&mut create, 0o755);
    create.create(dir).map_err(io(dir))?;
    // What writers of this file killed before they finished left behind (never another's).
    #[cfg(unix)]
    crate::fs::output::remove_stale_temporaries(path);
    let mut w = SectionWriter::new();
    let bounds = [scene.bounds];
    let tris = stored_blocks(scene);
    push_accel(&mut w, scene, &bounds, &tris);
    // Readable by the other users of a shared cache; only a regular file is replaced.
    let opts = OutputOptions { mode: 0o644, exact_mode: true, allow_fifo: false, sync: false, ..Default::default() };
    let mut w = Some(w);
    let output = |e: crate::fs::output::OutputError| CacheError::Io { path: e.path, source: e.source };
    stage(path, &opts, &mut |out| w.take().map_or(Ok(()), |w| w.write_to(key, out).map(|_| ())))
        .map_err(output)?
        .commit()
        .map_err(output)
}

/// Adds the sections of `scene`'s acceleration structures (`bounds` is `[scene.bounds]`):
/// what [`read_accel`] reads.
///
/// A compact tree ([`crate::bvh::TreeLayout::Compact`]) is written as the default layout's
/// blocks (`tris`: [`stored_blocks`]), which the verification of a load checks as it checks
/// any tree; the reader turns them back into id blocks ([`Accel::into_layout`]).
pub(crate) fn push_accel<'a>(w: &mut SectionWriter<'a>, scene: &'a Scene, bounds: &'a [Aabb; 1], tris: &'a [Tri8]) {
    w.push("bounds", bounds);
    let (nodes, prims) = scene.bvh2.as_ref().map_or((&[][..], &[][..]), |b| (&b.nodes[..], &b.prim_ids[..]));
    w.push("bvh2.nodes", nodes);
    w.push("bvh2.prims", prims);
    w.push("bvh8.nodes", &scene.bvh8.nodes);
    w.push("bvh8.tris", tris);
    w.push("bvh8.spheres", &scene.bvh8.spheres);
}

/// The file name of the cache of `builder`'s geometry with `opts` inside `dir` (what
/// [`SceneBuilder::commit_cached`] reads and writes); for tests and tools.
pub fn cache_path(builder: &SceneBuilder, opts: &BuildOptions, dir: &Path) -> PathBuf {
    let (kept, _) = builder.clone().filter();
    CacheKey::of(&kept.triangles, &kept.spheres, opts).path_in(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::node::{LeafKind, NodeRef};

    /// A file whose checksum and key are right but whose trees are not what a build makes
    /// (only a forged file) is still rejected before a query could index out of range.
    #[test]
    fn forged_trees_are_rejected() {
        use crate::{Material, SceneBuilder};
        let dir = std::env::temp_dir().join(format!("raypack-forged-{}", std::process::id()));
        let make = || {
            let mut b = SceneBuilder::new();
            let m = b.add_material(Material::default());
            let s = crate::generate::grid(2, 2);
            b.add_mesh(&s.positions, &s.indices, m).unwrap();
            b.add_sphere(crate::Vec3::Z, 0.5, m).unwrap();
            b
        };
        let opts = BuildOptions { keep_bvh2: true, ..BuildOptions::default() };
        let (scene, _, report) = make().commit_cached(&opts, &dir);
        let key = CacheKey::of(&scene.triangles, &scene.spheres, &opts);
        let forge = |what: &str, edit: &dyn Fn(&mut Scene)| {
            let (mut s, _) = make().commit(&opts);
            edit(&mut s);
            store(&dir, &report.path, key, &s).unwrap();
            let (_, _, r) = make().commit_cached(&opts, &dir);
            assert!(matches!(r.rejected, Some(CacheError::Malformed { .. })), "{what}: {r:?}");
        };
        forge("1", &|s| s.bvh8.nodes[0].children[0] = NodeRef::inner(1 << 30));
        forge("2", &|s| s.bvh8.nodes[0].children[1] = NodeRef::inner(0));
        forge("3", &|s| {
            // An empty slot whose box can be hit: the kernels would follow its reference.
            let (i, k) = (0..s.bvh8.nodes.len())
                .find_map(|i| s.bvh8.nodes[i].children.iter().position(|c| c.is_empty()).map(|k| (i, k)))
                .expect("a node with an empty slot");
            s.bvh8.nodes[i].set_child(k, &Aabb::from_point(crate::Vec3::ZERO), NodeRef::EMPTY);
        });
        forge("4", &|s| s.bvh8.tris.to_mut().clear());
        forge("5", &|s| s.bvh8.tris[0].prim[0] = 1 << 20);
        forge("6", &|s| s.bvh2.as_mut().unwrap().nodes[0].start = 1 << 30);
        forge("7", &|s| s.bvh2.as_mut().unwrap().prim_ids[0] = 1 << 20);
        forge("8", &|s| {
            // A leaf whose lanes run past its block's eight: the packet kernels would index them.
            let (i, k) = (0..s.bvh8.nodes.len())
                .find_map(|i| {
                    let n = &s.bvh8.nodes[i];
                    n.children
                        .iter()
                        .position(|c| c.is_leaf() && !c.is_empty() && c.kind() == LeafKind::Triangles)
                        .map(|k| (i, k))
                })
                .expect("a triangle leaf");
            let c = s.bvh8.nodes[i].children[k];
            s.bvh8.nodes[i].children[k] = NodeRef::leaf_in_block(LeafKind::Triangles, c.first_block() as u32, 7, 2);
        });
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
