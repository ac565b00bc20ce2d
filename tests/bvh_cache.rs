//! The BVH cache: a loaded scene traces exactly as a freshly built one, and every kind of bad
//! cache file (truncated, one flipped byte, another format version, written for other options
//! or other geometry) is rejected, rebuilt and overwritten with a valid file.

use raypack::generate::{torus_knot, uv_sphere};
use raypack::raysets::random_through_bounds;
use raypack::scene::cache::{FORMAT_VERSION, cache_path};
use raypack::{BuildOptions, BuildQuality, CacheError, Material, SceneBuilder, Vec3};
use std::path::Path;

fn builder() -> SceneBuilder {
    let mut b = SceneBuilder::new();
    let m = b.add_material(Material::default());
    let knot = torus_knot(300, 12, 2.0, 3.0, 0.4, 0.05);
    b.add_mesh(&knot.positions, &knot.indices, m).unwrap();
    for i in 0..5 {
        b.add_sphere(Vec3::new(i as f32 - 2.0, 0.0, 3.0), 0.3, m).unwrap();
    }
    b
}

fn other_builder() -> SceneBuilder {
    let mut b = SceneBuilder::new();
    let m = b.add_material(Material::default());
    let s = uv_sphere(20, 30);
    b.add_mesh(&s.positions, &s.indices, m).unwrap();
    b
}

fn bytes<T: bytemuck::Pod>(v: &[T]) -> &[u8] {
    bytemuck::cast_slice(v)
}

/// Commits through the cache and checks it traces as a fresh build does.
fn commit_and_compare(dir: &Path, opts: &BuildOptions) -> raypack::CacheReport {
    let (cached, _, report) = builder().commit_cached(opts, dir);
    let (fresh, _) = builder().commit(opts);
    // Bit for bit (padding lanes hold NaN, which `==` would not equal).
    assert!(bytes(&cached.bvh8().nodes) == bytes(&fresh.bvh8().nodes));
    assert!(bytes(&cached.bvh8().tris) == bytes(&fresh.bvh8().tris));
    assert!(bytes(&cached.bvh8().spheres) == bytes(&fresh.bvh8().spheres));
    // The binary BVH is cached when the build keeps it, and only then.
    assert_eq!(cached.bvh2().is_some(), opts.keep_bvh2);
    if let (Some(c), Some(f)) = (cached.bvh2(), fresh.bvh2()) {
        assert!(bytes(&c.nodes) == bytes(&f.nodes));
        assert_eq!(c.prim_ids, f.prim_ids);
    }
    assert_eq!(cached.bounds(), fresh.bounds());
    // A loaded BVH8 is read in place from the file's mapping, a built one from memory.
    let b8 = cached.bvh8();
    assert_eq!(b8.nodes.is_mapped(), report.loaded);
    assert_eq!(b8.tris.is_mapped(), report.loaded);
    assert!(!fresh.bvh8().nodes.is_mapped());
    for r in random_through_bounds(&fresh.bounds(), 2000, 7) {
        let (a, b) = (cached.intersect1(&r), fresh.intersect1(&r));
        assert_eq!(
            (a.prim, a.t.to_bits(), a.u.to_bits(), a.v.to_bits()),
            (b.prim, b.t.to_bits(), b.u.to_bits(), b.v.to_bits())
        );
        assert_eq!(cached.occluded1(&r), fresh.occluded1(&r));
        assert_eq!(cached.intersect1_reference(&r).t.to_bits(), a.t.to_bits());
    }
    report
}

#[test]
fn a_mapped_bvh_is_copied_on_first_write_and_outlives_its_file() {
    let dir = std::env::temp_dir().join(format!("raypack-cache-cow-{}", std::process::id()));
    let opts = BuildOptions::default();
    builder().commit_cached(&opts, &dir);
    let (scene, _, report) = builder().commit_cached(&opts, &dir);
    assert!(report.loaded);
    let mut b8 = scene.bvh8().clone();
    assert!(b8.nodes.is_mapped(), "a clone shares the mapping");
    let before = b8.nodes[0];
    b8.nodes[0].children[0] = raypack::bvh::NodeRef::EMPTY;
    assert!(!b8.nodes.is_mapped(), "writing made the array owned");
    assert!(scene.bvh8().nodes.is_mapped() && scene.bvh8().nodes[0] == before, "the scene's array is untouched");
    // Deleting the file leaves the mapping (and the scene) intact.
    std::fs::remove_dir_all(&dir).unwrap();
    let (fresh, _) = builder().commit(&opts);
    for r in random_through_bounds(&fresh.bounds(), 500, 3) {
        assert_eq!(scene.intersect1(&r).t.to_bits(), fresh.intersect1(&r).t.to_bits());
    }
}

#[test]
fn round_trip_traces_like_a_fresh_build() {
    for keep_bvh2 in [false, true] {
        let dir = tempfile::tempdir().unwrap();
        let opts = BuildOptions { keep_bvh2, ..BuildOptions::default() };
        let first = commit_and_compare(dir.path(), &opts);
        assert!(!first.loaded && first.rejected.is_none() && first.write_error.is_none(), "{first:?}");
        assert!(first.path.exists());
        let second = commit_and_compare(dir.path(), &opts);
        assert!(second.loaded && second.warnings().is_empty(), "{second:?}");
        assert_eq!(second.path, first.path);
    }
}

/// Damages the cache file with `damage`, then expects the next commit to reject it with an
/// error matching `expected`, rebuild it, and leave a file the commit after loads.
fn rejected_then_rebuilt(damage: impl FnOnce(&Path), expected: fn(&CacheError) -> bool) {
    let dir = tempfile::tempdir().unwrap();
    let opts = BuildOptions::default();
    let path = commit_and_compare(dir.path(), &opts).path;
    damage(&path);
    let report = commit_and_compare(dir.path(), &opts);
    assert!(!report.loaded, "damaged file trusted: {report:?}");
    let e = report.rejected.as_ref().expect("damage not reported");
    assert!(expected(e), "unexpected reason: {e}");
    assert!(e.to_string().contains(&path.display().to_string()), "the message names the file: {e}");
    assert_eq!(report.warnings().len(), 1);
    let again = commit_and_compare(dir.path(), &opts);
    assert!(again.loaded && again.warnings().is_empty(), "rebuilt file not valid: {again:?}");
}

#[test]
fn truncated_file_is_rejected_and_rebuilt() {
    for keep in [0.5, 0.999] {
        rejected_then_rebuilt(
            |p| {
                let bytes = std::fs::read(p).unwrap();
                std::fs::write(p, &bytes[..(bytes.len() as f64 * keep) as usize]).unwrap();
            },
            |e| matches!(e, CacheError::Truncated { .. }),
        );
    }
    rejected_then_rebuilt(|p| std::fs::write(p, b"RPKB").unwrap(), |e| matches!(e, CacheError::Truncated { .. }));
    rejected_then_rebuilt(|p| std::fs::write(p, b"").unwrap(), |e| matches!(e, CacheError::Truncated { .. }));
}

#[test]
fn one_flipped_payload_byte_is_rejected_and_rebuilt() {
    for at in [0.3, 0.77, 1.0] {
        rejected_then_rebuilt(
            |p| {
                let mut bytes = std::fs::read(p).unwrap();
                let i = ((bytes.len() - 1) as f64 * at) as usize;
                bytes[i] ^= 0x01;
                std::fs::write(p, &bytes).unwrap();
            },
            |e| matches!(e, CacheError::Checksum { .. }),
        );
    }
}

#[test]
fn other_format_version_is_rejected_and_rebuilt() {
    rejected_then_rebuilt(
        |p| {
            let mut bytes = std::fs::read(p).unwrap();
            bytes[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
            std::fs::write(p, &bytes).unwrap();
        },
        |e| matches!(e, CacheError::Version { found, .. } if *found == FORMAT_VERSION + 1),
    );
    rejected_then_rebuilt(
        |p| {
            let mut bytes = std::fs::read(p).unwrap();
            bytes[0] = b'X';
            std::fs::write(p, &bytes).unwrap();
        },
        |e| matches!(e, CacheError::BadMagic { .. }),
    );
}

#[test]
fn file_for_other_options_or_geometry_is_rejected_and_rebuilt() {
    let high = BuildOptions { quality: BuildQuality::High, ..BuildOptions::default() };
    let leaf2 = BuildOptions { max_leaf_size: 2, ..BuildOptions::default() };
    assert_ne!(
        cache_path(&builder(), &high, Path::new("d")),
        cache_path(&builder(), &BuildOptions::default(), Path::new("d"))
    );
    for (b, opts) in [(builder(), high), (builder(), leaf2), (other_builder(), BuildOptions::default())] {
        rejected_then_rebuilt(
            |p| {
                // A valid cache file, but of other options or geometry, put where this one goes.
                let dir = p.parent().unwrap().join("other");
                let (_, _, r) = b.commit_cached(&opts, &dir);
                assert!(r.path.exists() && r.path.file_name() != p.file_name());
                std::fs::rename(&r.path, p).unwrap();
            },
            |e| matches!(e, CacheError::Stale { .. }),
        );
    }
}

#[test]
fn dropped_primitives_are_not_part_of_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let with_bad = || {
        let mut b = builder();
        let m = 0;
        b.add_mesh(&[Vec3::ZERO, Vec3::ZERO, Vec3::X], &[[0, 1, 2]], m).unwrap(); // zero area
        b
    };
    let opts = BuildOptions::default();
    // The kept geometry differs from builder()'s only by three vertices no triangle uses.
    let (_, report, first) = with_bad().commit_cached(&opts, dir.path());
    assert_eq!(report.dropped_degenerate, 1);
    let (_, _, second) = with_bad().commit_cached(&opts, dir.path());
    assert!(!first.loaded && second.loaded);
}

#[test]
fn unwritable_cache_dir_is_a_warning_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    // A regular file where the directory should be: nothing can be created inside it,
    // whatever the user's permissions (root included).
    let blocker = dir.path().join("not-a-dir");
    std::fs::write(&blocker, b"x").unwrap();
    let (scene, _, report) = builder().commit_cached(&BuildOptions::default(), &blocker.join("cache"));
    assert!(!report.loaded);
    let e = report.write_error.as_ref().expect("write failure reported");
    assert!(matches!(e, CacheError::Io { .. }), "{e}");
    assert!(report.warnings()[0].contains("not-a-dir"), "{:?}", report.warnings());
    let (fresh, _) = builder().commit(&BuildOptions::default());
    assert!(bytes(&scene.bvh8().nodes) == bytes(&fresh.bvh8().nodes));

    // A read-only directory (meaningful when not root: root writes anyway).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let ro = dir.path().join("ro");
        std::fs::create_dir(&ro).unwrap();
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
        let (_, _, report) = builder().commit_cached(&BuildOptions::default(), &ro);
        assert!(!report.loaded);
        assert!(report.write_error.is_some() || report.path.exists(), "{report:?}");
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
}

/// The CLI: `info` and `render` share the cache; a damaged file is reported once on stderr
/// and rebuilt.
#[test]
fn cli_reports_loads_and_rebuilds() {
    let dir = tempfile::tempdir().unwrap();
    let knot = torus_knot(60, 8, 2.0, 3.0, 0.4, 0.05);
    let mut obj = String::new();
    for p in &knot.positions {
        obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    for [a, b, c] in &knot.indices {
        obj += &format!("f {} {} {}\n", a + 1, b + 1, c + 1);
    }
    let scene = dir.path().join("knot.obj");
    std::fs::write(&scene, obj).unwrap();
    let cache = dir.path().join("cache");
    let run = |args: &[&str]| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_raypack")).args(args).output().expect("runs");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        (String::from_utf8(out.stdout).unwrap(), String::from_utf8(out.stderr).unwrap())
    };
    let (s, c) = (scene.to_str().unwrap(), cache.to_str().unwrap());
    let info = |args: &[&str]| {
        let (out, err) = run(&[&["info", s, "--quality", "medium", "--json", "--bvh-cache", c], args].concat());
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(v["triangles"], knot.indices.len());
        (v["builds"][0]["from_cache"].as_bool().unwrap(), err)
    };
    assert!(!info(&[]).0, "the first start builds");
    assert!(info(&["-t", "1"]).0, "the second start loads from the cache");
    let file = std::fs::read_dir(&cache).unwrap().next().unwrap().unwrap().path();
    let mut bytes = std::fs::read(&file).unwrap();
    let n = bytes.len();
    bytes[n / 2] ^= 0x80;
    std::fs::write(&file, &bytes).unwrap();
    let (loaded, err) = info(&[]);
    assert!(!loaded);
    assert_eq!(err.matches("checksum mismatch").count(), 1, "{err}");
    let png = dir.path().join("k.png");
    let (_, err) =
        run(&["render", s, "-r", "32", "24", "--integrator", "normals", "--bvh-cache", c, "-f", png.to_str().unwrap()]);
    assert!(err.contains("Loaded BVH") && !err.contains("warning: BVH cache"), "{err}");
    assert!(png.exists());
}

#[test]
fn empty_and_sphere_only_scenes_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let opts = BuildOptions::default();
    let spheres = || {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::default());
        for i in 0..40 {
            b.add_sphere(Vec3::new(i as f32, (i % 7) as f32, 0.0), 0.4, m).unwrap();
        }
        b
    };
    for make in [SceneBuilder::new as fn() -> SceneBuilder, spheres] {
        let (fresh, _) = make().commit(&opts);
        let (_, _, first) = make().commit_cached(&opts, dir.path());
        let (cached, _, second) = make().commit_cached(&opts, dir.path());
        assert!(!first.loaded && second.loaded && second.warnings().is_empty(), "{second:?}");
        for r in random_through_bounds(&spheres().commit(&opts).0.bounds(), 500, 3) {
            assert_eq!(cached.intersect1(&r).t.to_bits(), fresh.intersect1(&r).t.to_bits());
        }
    }
}

/// Cache files are keyed by the tree layout: a compact build never loads the default tree's
/// file nor the default build the compact one's, even when one is copied over the other's
/// name; each layout loads its own file, as its layout, tracing exactly as a fresh build.
#[test]
fn cache_files_are_keyed_by_tree_layout() {
    use raypack::TreeLayout;
    let dir = tempfile::tempdir().unwrap();
    let default = BuildOptions::default();
    let compact = BuildOptions { layout: TreeLayout::Compact, ..BuildOptions::default() };
    let (dpath, cpath) = (cache_path(&builder(), &default, dir.path()), cache_path(&builder(), &compact, dir.path()));
    assert_ne!(dpath, cpath);
    let first = builder().commit_cached(&default, dir.path()).2;
    assert!(!first.loaded && first.path == dpath && dpath.exists());
    let (scene, _, report) = builder().commit_cached(&compact, dir.path());
    assert!(!report.loaded && report.rejected.is_none() && report.path == cpath, "{report:?}");
    assert_eq!(scene.layout(), TreeLayout::Compact);
    // The default tree's file under the compact one's name: stale, rebuilt, rewritten.
    std::fs::copy(&dpath, &cpath).unwrap();
    let (scene, _, report) = builder().commit_cached(&compact, dir.path());
    assert!(!report.loaded, "{report:?}");
    assert!(matches!(report.rejected, Some(CacheError::Stale { .. })), "{report:?}");
    assert_eq!(scene.layout(), TreeLayout::Compact);
    let (fresh, _) = builder().commit(&default);
    for (opts, layout) in [(&compact, TreeLayout::Compact), (&default, TreeLayout::Default)] {
        let (scene, _, report) = builder().commit_cached(opts, dir.path());
        assert!(report.loaded && report.warnings().is_empty(), "{layout}: {report:?}");
        assert_eq!(scene.layout(), layout);
        for r in random_through_bounds(&fresh.bounds(), 2000, 9) {
            let (a, b) = (scene.intersect1(&r), fresh.intersect1(&r));
            assert_eq!(
                (a.prim, a.t.to_bits(), a.u.to_bits(), a.v.to_bits()),
                (b.prim, b.t.to_bits(), b.u.to_bits(), b.v.to_bits()),
                "{layout}"
            );
            assert_eq!(scene.occluded1(&r), fresh.occluded1(&r), "{layout}");
        }
    }
}
