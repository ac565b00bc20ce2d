//! Flags and environment a hostile (or careless) user may give the CLI: absurd thread counts,
//! an output name without an extension, a garbage or non-UTF-8 `RAYPACK_ISA`, a FIFO nobody
//! reads, `--write-camera -`, flags the chosen mode would ignore, and a cache that cannot be
//! written. Each is a clear error (exit 2) before any work, or does what it says.

mod common;

use common::child::{TIMEOUT, command, expect, finish, mkfifo, run, s};
use std::path::Path;

#[test]
fn thread_counts_are_capped_at_a_multiple_of_the_cpus() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t.png");
    let max = raypack::system::max_threads();
    let too_many = (max + 1).to_string();
    let want = format!("-t {too_many}: expected 1 to {max} threads");
    expect(&["render", "-t", &too_many, "-r", "16", "12", "-f", s(&out)], 2, &want);
    assert!(!out.exists());
    expect(&["info", "-t", &too_many, "--quality", "fast"], 2, &want);
    expect(&["bench", "-t", &too_many, "-r", "16", "12", "--runs", "1"], 2, &want);
    let list = format!("--threads-list {too_many}: expected 1 to {max} threads");
    expect(&["bench", "--threads-list", &format!("1,{too_many}"), "-r", "16", "12", "--runs", "1"], 2, &list);
    expect(&["render", "--integrator", "heatmap", "-t", &too_many, "-r", "16", "12", "-f", s(&out)], 2, &want);
    // The cap itself is allowed.
    let r = run(&["render", "-q", "-t", &max.to_string(), "-r", "16", "12", "-f", s(&out)]);
    assert_eq!(r.code, Some(0), "{r:?}");
}

#[test]
fn an_output_name_without_an_extension_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("noext");
    expect(&["render", "-r", "16", "12", "-f", s(&out)], 2, "the name has no extension to say the format");
    expect(&["render", "--integrator", "heatmap", "-r", "16", "12", "-f", s(&out)], 2, "a heatmap is written as .png");
    assert!(!out.exists(), "PNG bytes written to a name without an extension");
}

#[test]
fn raypack_isa_garbage_or_not_utf8_is_an_error() {
    use std::os::unix::ffi::OsStrExt;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("i.png");
    let args = ["render", "-q", "-r", "16", "12", "-f", s(&out)];
    for (value, shown) in [(&b"fastest"[..], "`fastest`"), (b"avx\xff", "`\"avx\\xFF\"`")] {
        let env = [("RAYPACK_ISA", std::ffi::OsStr::from_bytes(value))];
        let r = finish(command(&args, &env).spawn().unwrap(), TIMEOUT);
        assert_eq!(r.code, Some(2), "{value:?}: {r:?}");
        let want = format!("[raypack] error: RAYPACK_ISA: unknown ISA {shown}: expected sse, avx2 or avx512");
        assert!(r.stderr.contains(&want), "{value:?}: {}", r.stderr);
        assert!(!out.exists());
    }
}

#[test]
fn a_fifo_nobody_reads_is_refused_before_the_render() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("pipe.png");
    mkfifo(&fifo);
    // Before, the refusal came after the render (whose progress lines were printed).
    let r = expect(&["render", "-r", "64", "48", "-s", "16", "-f", s(&fifo)], 2, "that no process reads");
    assert!(!r.stderr.contains("Rendering"), "refused only after rendering: {}", r.stderr);
    let json = dir.path().join("pipe.json");
    mkfifo(&json);
    let r =
        expect(&["bench", "-r", "16", "12", "--runs", "1", "-t", "1", "--json", s(&json)], 2, "that no process reads");
    assert!(!r.stderr.contains("Mrays/s"), "refused only after the run: {}", r.stderr);
}

#[test]
fn write_camera_dash_is_standard_output() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = command(&["render", "-r", "16", "12", "--write-camera", "-"], &[]);
    let r = finish(c.current_dir(dir.path()).spawn().unwrap(), TIMEOUT);
    assert_eq!(r.code, Some(0), "{r:?}");
    assert!(r.stdout.contains("camera settings file"), "{}", r.stdout);
    assert!(!dir.path().join("-").exists(), "wrote a file named -");
    // It reads back as the camera it describes.
    let cam = dir.path().join("cam.txt");
    std::fs::write(&cam, &r.stdout).unwrap();
    raypack::io::camera_file::load_camera_file(&cam).expect("the written camera loads");
}

#[test]
fn flags_the_mode_would_ignore_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.png");
    let cam = dir.path().join("c.txt");
    expect(
        &["render", "--heatmap", "tests", "-r", "16", "12", "-f", s(&out)],
        2,
        "--heatmap applies only with --integrator heatmap",
    );
    expect(&["render", "--heatmap-rays", "shadow", "-r", "16", "12", "-f", s(&out)], 2, "--heatmap-rays applies only");
    expect(&["render", "--write-camera", s(&cam), "-f", s(&out)], 2, "with --write-camera");
    assert!(!out.exists() && !cam.exists());
    // In their mode they work.
    let r = run(&["render", "--integrator", "heatmap", "--heatmap", "tests", "-r", "16", "12", "-f", s(&out)]);
    assert_eq!(r.code, Some(0), "{r:?}");
}

#[test]
fn a_cache_that_cannot_be_written_is_not_said_to_be_cached() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    let cache = file.join("cache");
    let out = dir.path().join("x.png");
    let r = run(&["render", "-r", "16", "12", "--bvh-cache", s(&cache), "-f", s(&out)]);
    assert_eq!(r.code, Some(0), "{r:?}");
    assert!(r.stderr.contains("BVH cache not written"), "{}", r.stderr);
    assert!(!r.stderr.contains("(and cached it)") && r.stderr.contains("Built BVH (not cached)"), "{}", r.stderr);
    assert!(Path::new(&out).exists());
}
