//! `raypack bench --dump-rays DIR` and `--rays FILE`: the built-in sets written to ray files
//! and timed again from them give the same checksums (hits and t-sum) as the built-in sets;
//! a `.npy` laid out the way numpy writes it is read; bad ray files are clear errors.

use std::path::{Path, PathBuf};
use std::process::Command;

fn raypack(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_raypack")).args(args).output().expect("runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn scratch_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("raypack-rays-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A sphere and a plane as an OBJ file.
fn scene_file(dir: &Path) -> PathBuf {
    let mut obj = String::new();
    for mesh in [raypack::generate::uv_sphere(12, 24), raypack::generate::grid(6, 6)] {
        let base = obj.lines().filter(|l| l.starts_with("v ")).count();
        for p in &mesh.positions {
            obj += &format!("v {} {} {}\n", p.x, p.y, p.z * 0.5 - 0.7);
        }
        for t in &mesh.indices {
            obj +=
                &format!("f {} {} {}\n", base + t[0] as usize + 1, base + t[1] as usize + 1, base + t[2] as usize + 1);
        }
    }
    let path = dir.join("scene.obj");
    std::fs::write(&path, obj).unwrap();
    path
}

/// `(rays, hits, t_sum)` of every result of a `--json -` run.
fn checksums(json: &str) -> Vec<(String, u64, f64)> {
    let v: serde_json::Value = serde_json::from_str(json).unwrap();
    v["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| (r["rays"].as_str().unwrap().to_owned(), r["hits"].as_u64().unwrap(), r["t_sum"].as_f64().unwrap()))
        .collect()
}

/// `raypack bench SCENE` at a small size, one run on one thread, JSON to standard output,
/// plus `extra`.
fn bench(scene: &Path, extra: &[&str]) -> (bool, String, String) {
    let mut args = vec!["bench", scene.to_str().unwrap(), "-r", "48", "32", "--runs", "1", "-t", "1", "--json", "-"];
    args.extend(["--methods", "stream"]);
    args.extend(extra);
    raypack(&args)
}

#[test]
fn dumped_rays_give_the_same_checksums() {
    let dir = scratch_dir("dump");
    let scene = scene_file(&dir);
    let dump = dir.join("sets");
    let (ok, out, err) = bench(&scene, &["--dump-rays", dump.to_str().unwrap()]);
    assert!(ok, "{err}");
    let built_in = checksums(&out);
    for set in ["primary", "diffuse"] {
        let (_, hits, t_sum) = built_in.iter().find(|r| r.0 == set).unwrap().clone();
        assert!(hits > 0, "{set}: the scene is in view");
        for ext in ["rays", "npy"] {
            let file = dump.join(format!("{set}.{ext}"));
            let (ok, out, err) = bench(&scene, &["--rays", file.to_str().unwrap()]);
            assert!(ok, "{err}");
            let from_file = checksums(&out);
            assert_eq!(from_file.len(), 1);
            assert_eq!((from_file[0].1, from_file[0].2), (hits, t_sum), "{set}.{ext}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn numpy_layout_is_read_and_bad_files_are_errors() {
    let dir = scratch_dir("npy");
    let scene = scene_file(&dir);
    // What `numpy.save(path, a.astype('<f4'))` writes for a (2, 8) array: version 1.0, the
    // header padded with spaces to 128 bytes in all (a multiple of 64) and ended with a
    // newline.
    let dict = "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 8), }";
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(128u16 - 10).to_le_bytes());
    bytes.extend_from_slice(dict.as_bytes());
    bytes.resize(127, b' ');
    bytes.push(b'\n');
    // Two rays straight down beside the z axis onto the sphere (radius 1 at the origin,
    // squashed to z in [-1.2, -0.2]): they hit the fan around its pole, within 0.01 of
    // z = -0.2, so at t = 10.2 within 0.01.
    for x in [0.02f32, 0.03] {
        for v in [x, 0.0, 10.0, 0.0, 0.0, -1.0, 0.0, f32::INFINITY] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    let good = dir.join("two.npy");
    std::fs::write(&good, &bytes).unwrap();
    let (ok, out, err) = bench(&scene, &["--rays", good.to_str().unwrap()]);
    assert!(ok, "{err}");
    let sums = checksums(&out);
    assert_eq!(sums[0].1, 2);
    assert!((sums[0].2 - 2.0 * 10.2).abs() < 0.02, "{sums:?}");
    // The summary's header names the file's rays, not the built-in sets it did not trace.
    let (ok, text, err) =
        raypack(&["bench", scene.to_str().unwrap(), "--runs", "1", "-t", "1", "--rays", good.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(text.contains("2 rays from the --rays file") && !text.contains("primary rays"), "{text}");

    let bad = dir.join("bad.rays");
    std::fs::write(&bad, [0u8; 40]).unwrap();
    let (ok, _, err) = bench(&scene, &["--rays", bad.to_str().unwrap()]);
    assert!(!ok && err.contains("bad.rays") && err.contains("not a whole number of rays"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
