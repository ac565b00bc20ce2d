//! A co-tenant poisoning a shared BVH cache: files forged with a valid checksum (emptied or
//! shrunk boxes, moved or swapped triangles, live padding, grown spheres, a dropped leaf, other
//! bounds, and 150 random edits) are never used to trace, and a file another user owns in a
//! directory others can write is never used at all. Whatever is accepted traces exactly as a
//! build: the same closest hit on every ray.

use raypack::generate::torus_knot;
use raypack::raysets::random_through_bounds;
use raypack::rng::Rng;
use raypack::scene::cache::{FileHeader, SectionEntry, cache_path};
use raypack::{BuildOptions, CacheError, Material, Ray, Scene, SceneBuilder, Vec3};
use std::path::Path;

fn builder() -> SceneBuilder {
    let mut b = SceneBuilder::new();
    let m = b.add_material(Material::default());
    let knot = torus_knot(120, 10, 2.0, 3.0, 0.4, 0.05);
    b.add_mesh(&knot.positions, &knot.indices, m).unwrap();
    for i in 0..6 {
        b.add_sphere(Vec3::new(i as f32 - 2.5, 0.0, 3.0), 0.3, m).unwrap();
    }
    b
}

/// The options of the cached trees: the binary BVH kept, so that its sections are forged too.
fn opts() -> BuildOptions {
    BuildOptions { keep_bvh2: true, ..BuildOptions::default() }
}

/// Closest hits as bits, for exact comparison.
fn hits(scene: &Scene, rays: &[Ray]) -> Vec<(u32, u32)> {
    rays.iter().map(|r| scene.intersect1(r)).map(|h| (h.prim, h.t.to_bits())).collect()
}

/// The byte range of section `name` in a cache file.
fn section(bytes: &[u8], name: &str) -> std::ops::Range<usize> {
    let header: FileHeader = bytemuck::pod_read_unaligned(&bytes[..64]);
    (0..header.sections as usize)
        .map(|i| bytemuck::pod_read_unaligned::<SectionEntry>(&bytes[64 + 32 * i..96 + 32 * i]))
        .find(|e| e.name.starts_with(name.as_bytes()) && e.name[name.len()..].iter().all(|&c| c == 0))
        .map(|e| e.offset as usize..(e.offset + e.count * e.elem_size as u64) as usize)
        .unwrap_or_else(|| panic!("no section {name}"))
}

/// Writes `bytes` as the cache file with its checksum made right again (XXH3-64 of every
/// byte but the checksum's eight), as a forger would.
fn write_with_valid_checksum(path: &Path, mut bytes: Vec<u8>) {
    let at = std::mem::offset_of!(FileHeader, checksum);
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    h.update(&bytes[..at]);
    h.update(&bytes[at + 8..]);
    bytes[at..at + 8].copy_from_slice(&h.digest().to_le_bytes());
    std::fs::write(path, bytes).unwrap();
}

/// An `f32` at byte `at` of `bytes`.
fn f32_at(bytes: &mut [u8], at: usize, f: impl Fn(f32) -> f32) {
    let v = f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    bytes[at..at + 4].copy_from_slice(&f(v).to_le_bytes());
}

#[test]
fn forged_cache_files_with_valid_checksums_are_never_traced() {
    let dir = tempfile::tempdir().unwrap();
    let (fresh, _) = builder().commit(&opts());
    let rays = random_through_bounds(&fresh.bounds(), 3000, 11);
    let want = hits(&fresh, &rays);
    let (_, _, first) = builder().commit_cached(&opts(), dir.path());
    assert!(first.write_error.is_none(), "{first:?}");
    let path = cache_path(&builder(), &opts(), dir.path());
    let good = std::fs::read(&path).unwrap();
    let (_, _, again) = builder().commit_cached(&opts(), dir.path());
    assert!(again.loaded && again.rejected.is_none(), "the genuine file is used: {again:?}");

    type Forge = fn(&mut Vec<u8>);
    let forgeries: [(&str, Forge); 11] = [
        ("the root's child boxes emptied", |b| {
            let nodes = section(b, "bvh8.nodes");
            // The six bound planes of the root's eight slots, all set to 0: every ray misses.
            for k in 0..48 {
                f32_at(b, nodes.start + 4 * k, |v| if v.is_finite() { 0.0 } else { v });
            }
        }),
        ("a child box shrunk", |b| {
            let nodes = section(b, "bvh8.nodes");
            // Node 1's slot 0, upper x: pulled in by a tenth of the box.
            let (lo, hi) = (nodes.start + 256, nodes.start + 256 + 4 * 8);
            let lo_x = f32::from_le_bytes(b[lo..lo + 4].try_into().unwrap());
            f32_at(b, hi, |v| v - 0.1 * (v - lo_x));
        }),
        ("every box of a node shifted", |b| {
            let nodes = section(b, "bvh8.nodes");
            for k in 0..48 {
                f32_at(b, nodes.start + 2 * 256 + 4 * k, |v| if v.is_finite() { v + 0.5 } else { v });
            }
        }),
        ("a triangle moved", |b| {
            let at = section(b, "bvh8.tris").start;
            f32_at(b, at, |v| v + 0.25)
        }),
        ("two triangles' ids swapped", |b| {
            let tris = section(b, "bvh8.tris");
            // The prim ids of lanes 0 and 1 of the first block (after 9 rows of 8 floats).
            let ids = tris.start + 9 * 32;
            let (a, c) = (b[ids..ids + 4].to_vec(), b[ids + 4..ids + 8].to_vec());
            b[ids..ids + 4].copy_from_slice(&c);
            b[ids + 4..ids + 8].copy_from_slice(&a);
        }),
        ("a triangle in a padding lane", |b| {
            let tris = section(b, "bvh8.tris");
            let blocks = (tris.end - tris.start) / 320;
            let pad = (0..blocks)
                .flat_map(|k| (0..8).map(move |l| (k, l)))
                .find(|&(k, l)| {
                    let at = tris.start + 320 * k + 9 * 32 + 4 * l;
                    b[at..at + 4] == [0xFF; 4]
                })
                .expect("a padding lane");
            // Its edges made non-zero: a live triangle with no id.
            for row in 3..9 {
                f32_at(b, tris.start + 320 * pad.0 + 32 * row + 4 * pad.1, |_| 1.0);
            }
        }),
        ("a sphere grown", |b| {
            let at = section(b, "bvh8.spheres").start + 48;
            f32_at(b, at, |r| r * 3.0)
        }),
        ("a leaf dropped", |b| {
            let nodes = section(b, "bvh8.nodes");
            let n = (nodes.end - nodes.start) / 256;
            // The first leaf slot: its reference made empty, its box the empty box.
            let (i, k) = (0..n)
                .flat_map(|i| (0..8).map(move |k| (i, k)))
                .find(|&(i, k)| {
                    let at = nodes.start + 256 * i + 192 + 8 * k;
                    let r = u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
                    r >> 63 == 1 && r != u64::MAX
                })
                .expect("a leaf");
            let at = nodes.start + 256 * i;
            b[at + 192 + 8 * k..at + 200 + 8 * k].copy_from_slice(&u64::MAX.to_le_bytes());
            for plane in 0..6 {
                let empty = if plane % 2 == 0 { f32::INFINITY } else { f32::NEG_INFINITY };
                f32_at(b, at + 32 * plane + 4 * k, |_| empty);
            }
        }),
        ("NaN boxes", |b| {
            let at = section(b, "bvh8.nodes").start;
            f32_at(b, at, |_| f32::NAN)
        }),
        ("other bounds", |b| {
            let at = section(b, "bounds").start;
            f32_at(b, at, |v| v - 1.0)
        }),
        ("a binary BVH box shrunk", |b| {
            let at = section(b, "bvh2.nodes").start + 32;
            f32_at(b, at, |v| v + 0.5)
        }),
    ];
    for (what, forge) in forgeries {
        let mut bytes = good.clone();
        forge(&mut bytes);
        assert_ne!(bytes, good, "{what}: nothing changed");
        write_with_valid_checksum(&path, bytes);
        let (scene, _, r) = builder().commit_cached(&opts(), dir.path());
        assert!(matches!(r.rejected, Some(CacheError::Malformed { .. })), "{what}: {r:?}");
        assert!(!r.loaded, "{what}: used");
        assert_eq!(hits(&scene, &rays), want, "{what}: traces differently");
    }

    // Random edits of the trees' sections: whatever is accepted traces exactly as a build.
    let mut rng = Rng::new(65, 3);
    let sections: Vec<_> =
        ["bounds", "bvh2.nodes", "bvh8.nodes", "bvh8.tris", "bvh8.spheres"].map(|s| section(&good, s)).into();
    let (mut accepted, mut wrong) = (0, Vec::new());
    for round in 0..150 {
        let mut bytes = good.clone();
        for _ in 0..1 + rng.next_u32() % 3 {
            let s = &sections[rng.next_u32() as usize % sections.len()];
            let at = s.start + 4 * (rng.next_u32() as usize % ((s.end - s.start) / 4));
            let word = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
            let new = match rng.next_u32() % 4 {
                0 => word ^ (1 << (rng.next_u32() % 32)),
                1 => 0,
                2 => f32::from_bits(word).mul_add(1.0 + rng.next_f32(), 0.0).to_bits(),
                _ => rng.next_u32(),
            };
            bytes[at..at + 4].copy_from_slice(&new.to_le_bytes());
        }
        write_with_valid_checksum(&path, bytes);
        let (scene, _, r) = builder().commit_cached(&opts(), dir.path());
        if r.loaded {
            accepted += 1;
            if hits(&scene, &rays) != want {
                wrong.push(round);
            }
        }
    }
    assert!(wrong.is_empty(), "{} of 150 random forgeries were used and traced differently: {wrong:?}", wrong.len());
    eprintln!("{accepted} of 150 random forgeries accepted, each tracing exactly as the build");
}

/// In a directory others can write, a cache file owned by another user is never used; in
/// one only its owner can write, the same file is used (after the checks).
#[test]
fn a_cache_file_another_user_owns_in_a_shared_directory_is_not_used() {
    use std::os::unix::fs::PermissionsExt;
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("SKIPPED a_cache_file_another_user_owns_in_a_shared_directory_is_not_used: needs root to chown");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (_, _, first) = builder().commit_cached(&opts(), dir.path());
    assert!(first.write_error.is_none());
    let path = cache_path(&builder(), &opts(), dir.path());
    // Planted by user 65534 (a genuine file: what a co-tenant could make).
    std::os::unix::fs::chown(&path, Some(65534), Some(65534)).unwrap();
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o1777)).unwrap();
    let (_, _, r) = builder().commit_cached(&opts(), dir.path());
    assert!(matches!(r.rejected, Some(CacheError::Untrusted { uid: 65534, .. })), "{r:?}");
    assert!(!r.loaded);
    assert!(r.warnings().iter().any(|w| w.contains("owned by uid 65534")), "{:?}", r.warnings());
    // Root rewrote it (in a sticky directory another user could not have).
    let (_, _, r) = builder().commit_cached(&opts(), dir.path());
    assert!(r.loaded && r.rejected.is_none(), "{r:?}");
    // In a directory nobody else can write, another owner's file is checked and used.
    std::os::unix::fs::chown(&path, Some(65534), Some(65534)).unwrap();
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let (_, _, r) = builder().commit_cached(&opts(), dir.path());
    assert!(r.loaded && r.rejected.is_none(), "{r:?}");
}

/// The temporary files of writers killed mid-write (SIGKILL leaves them) are removed by the
/// next store of the same file: only this user's, only of this file, never one a live writer
/// holds.
#[test]
fn stale_cache_temporaries_of_the_same_file_are_removed() {
    use std::os::fd::AsRawFd;
    let dir = tempfile::tempdir().unwrap();
    let path = cache_path(&builder(), &opts(), dir.path());
    let name = path.file_name().unwrap().to_str().unwrap().to_owned();
    let at = |n: &str| dir.path().join(n);
    // A dead writer's file, and a live one's (held locked, as a writer holds its own).
    std::fs::write(at(&format!(".{name}.dead01.tmp")), b"partial").unwrap();
    let live = std::fs::File::create(at(&format!(".{name}.live01.tmp"))).unwrap();
    // SAFETY: flock on a descriptor `live` owns and keeps open, with integer arguments only.
    assert_eq!(unsafe { libc::flock(live.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) }, 0);
    // Another file's temporary, and a file that only looks alike.
    std::fs::write(at(".0123456789abcdef0123456789abcdef.rpbvh.dead02.tmp"), b"other").unwrap();
    std::fs::write(at(&format!(".{name}.tmp")), b"not a temporary").unwrap();
    // Another user's (when this test may make one).
    let foreign = at(&format!(".{name}.their01.tmp"));
    std::fs::write(&foreign, b"theirs").unwrap();
    // SAFETY: geteuid has no preconditions.
    let root = unsafe { libc::geteuid() } == 0;
    if root {
        std::os::unix::fs::chown(&foreign, Some(65534), Some(65534)).unwrap();
    } else {
        std::fs::remove_file(&foreign).unwrap();
    }
    let (_, _, r) = builder().commit_cached(&opts(), dir.path());
    assert!(r.write_error.is_none(), "{r:?}");
    let mut left: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    left.sort();
    let mut want = vec![
        ".0123456789abcdef0123456789abcdef.rpbvh.dead02.tmp".to_string(),
        format!(".{name}.live01.tmp"),
        format!(".{name}.tmp"),
        name.clone(),
    ];
    if root {
        want.push(format!(".{name}.their01.tmp"));
    }
    want.sort();
    assert_eq!(left, want);
    drop(live);
}
