//! The `raypack render` command line: integrator names, the end-of-render report, and the
//! atomically written image and sample-rate image.

use std::path::{Path, PathBuf};
use std::process::Command;

fn raypack(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_raypack")).args(args).output().expect("runs");
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
}

fn scratch_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("raypack-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn png_size(path: &Path) -> (u32, u32) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let reader = decoder.read_info().unwrap();
    (reader.info().width, reader.info().height)
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    v.sort();
    v
}

#[test]
fn adaptive_render_writes_image_and_rate_image_and_reports_per_ray_kind() {
    let dir = scratch_dir("adaptive");
    for out in ["cb.png", "cb.exr"] {
        let path = dir.join(out);
        let (ok, log) = raypack(&[
            "render",
            "-t",
            "2",
            "-r",
            "40",
            "30",
            "-s",
            "32",
            "-a",
            "8",
            "0.05",
            "-m",
            "3",
            "-f",
            path.to_str().unwrap(),
        ]);
        assert!(ok, "{log}");
        for kind in ["camera", "shadow", "bounce"] {
            assert!(
                log.lines()
                    .any(|l| l.contains(kind) && l.contains("Mrays/s") && l.contains("intersection tests per ray")),
                "no CS184 line for {kind} rays:\n{log}"
            );
        }
        assert!(log.contains("million samples per second"), "{log}");
        assert!(log.contains("Time: load") && log.contains("render"), "{log}");
    }
    assert_eq!(png_size(&dir.join("cb.png")), (40, 30));
    // The rate image: the render's pixels, then its legend (a title and a colour bar).
    let legend = raypack::render::colorbar::title_height() + raypack::render::colorbar::height();
    assert_eq!(png_size(&dir.join("cb_rate.png")), (40, 30 + legend as u32));
    // Only the outputs: no temporary files left behind.
    assert_eq!(names(&dir), ["cb.exr", "cb.png", "cb_rate.png"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn integrator_names_and_bad_values() {
    let dir = scratch_dir("names");
    // The library's names (`IntegratorKind::name`), which the CLI takes as they are.
    let all = raypack::render::IntegratorKind::ALL.map(|k| k.name());
    for name in all {
        let path = dir.join(format!("{name}.png"));
        let (ok, log) = raypack(&["-r", "16", "12", "--integrator", name, "-m", "2", "-f", path.to_str().unwrap()]);
        assert!(ok && path.exists(), "{name}: {log}");
    }
    let (ok, log) =
        raypack(&["-r", "16", "12", "--integrator", "photon-mapping", "-f", dir.join("x.png").to_str().unwrap()]);
    assert!(!ok && log.contains("photon-mapping") && log.contains("--integrator"), "{log}");
    assert!(all.iter().all(|name| log.contains(name)), "the choices are listed: {log}");
    // Without -a there is no rate image.
    assert!(!dir.join("global_rate.png").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn same_seed_same_file_with_one_or_two_threads() {
    let dir = scratch_dir("threads");
    let run = |t: &str, name: &str| {
        let path = dir.join(name);
        let (ok, log) =
            raypack(&["-t", t, "-r", "40", "30", "-s", "8", "-m", "4", "--seed", "7", "-f", path.to_str().unwrap()]);
        assert!(ok, "{log}");
        std::fs::read(path).unwrap()
    };
    assert_eq!(run("1", "one.exr"), run("2", "two.exr"), "linear EXR output differs between -t 1 and -t 2");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `raypack info`: the binary BVH is reported only when kept, each commit's peak memory is
/// measured, and `--against embree` (with or without `--embree-first`) adds Embree's builds.
#[test]
fn info_reports_what_it_keeps_and_embree_beside_it() {
    let dir = scratch_dir("info");
    let knot = raypack::generate::torus_knot(40, 8, 2.0, 3.0, 0.4, 0.05);
    let mut obj = String::new();
    for p in &knot.positions {
        obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    for [a, b, c] in &knot.indices {
        obj += &format!("f {} {} {}\n", a + 1, b + 1, c + 1);
    }
    let scene = dir.join("knot.obj");
    std::fs::write(&scene, obj).unwrap();
    let info = |extra: &[&str]| -> Result<serde_json::Value, String> {
        let args = [&["info", scene.to_str().unwrap(), "--quality", "fast", "--json"], extra].concat();
        let out = Command::new(env!("CARGO_BIN_EXE_raypack")).args(&args).output().expect("runs");
        if out.status.success() {
            Ok(serde_json::from_slice(&out.stdout).unwrap())
        } else {
            Err(String::from_utf8_lossy(&out.stderr).into_owned())
        }
    };
    let lean = info(&[]).unwrap();
    let build = &lean["builds"][0];
    assert!(build["bvh2"].is_null(), "{build}");
    assert!(build["bvh8"]["bytes"].as_u64().unwrap() > 0);
    if cfg!(target_os = "linux") {
        assert!(build["peak_added_bytes"].as_u64().is_some(), "{build}");
    }
    let kept = info(&["--keep-bvh2"]).unwrap();
    assert!(kept["builds"][0]["bvh2"]["sah_cost"].as_f64().unwrap() > 0.0);
    for order in [&["--against", "embree"][..], &["--against", "embree", "--embree-first"][..]] {
        match info(order) {
            Ok(v) if cfg!(feature = "embree") => {
                let e = v["embree_builds"].as_array().unwrap();
                let names: Vec<_> = e.iter().map(|b| b["quality"].as_str().unwrap()).collect();
                assert_eq!(names, ["medium", "high", "compact"], "{order:?}");
                assert!(e.iter().all(|b| b["seconds"].as_f64().unwrap() > 0.0 && b["bytes"].as_u64().unwrap() > 0));
                assert_eq!(v["builds"].as_array().unwrap().len(), 1, "raypack's build is still there");
            }
            Err(e) if !cfg!(feature = "embree") => assert!(e.contains("--features embree"), "{e}"),
            other => panic!("{order:?}: {other:?}"),
        }
    }
    assert!(info(&["--embree-first"]).is_err(), "--embree-first needs --against");
}
