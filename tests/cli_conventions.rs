//! The command line's conventions (issue 18): `-o`/`--outfile`/`--spp`/`--quiet`, refused
//! output formats, unknown commands, clamped values said aloud, `-H` on delta lights, the
//! camera flags (`--lookat`, `--up`, `--fov`, `--write-camera`), and `info`/`bench` on the
//! built-in box.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs raypack; returns (exit code, stderr, stdout).
fn raypack(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_raypack")).args(args).output().expect("runs");
    let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
    (out.status.code().unwrap_or(-1), text(&out.stderr), text(&out.stdout))
}

fn scratch_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("raypack-conv-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The 8-bit RGB pixels of a PNG file.
fn pixels(path: &Path) -> Vec<u8> {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    buf
}

#[test]
fn a_mistyped_command_is_an_unknown_command() {
    let (code, err, _) = raypack(&["rendr", "-r", "8", "6"]);
    assert_eq!(code, 2);
    assert!(err.contains("unknown command 'rendr'") && err.contains("render, info, bench"), "{err}");
    // A missing file with a scene extension is still a missing scene, not a command.
    let (code, err, _) = raypack(&["/nonexistent/box.dae"]);
    assert_eq!(code, 2);
    assert!(!err.contains("unknown command") && err.contains("/nonexistent/box.dae"), "{err}");
}

#[test]
fn an_unwritable_extension_is_refused_before_rendering() {
    let dir = scratch_dir("ext");
    let jpg = dir.join("x.jpg");
    let (code, err, _) = raypack(&["render", "-r", "8", "6", "-o", s(&jpg)]);
    assert_eq!(code, 2);
    assert!(err.contains("cannot write .jpg") && err.contains(".png") && err.contains(".exr"), "{err}");
    assert!(!err.contains("Rendering") && !err.contains("Collecting"), "refused before any work: {err}");
    assert!(!jpg.exists());
}

#[test]
fn output_and_sample_aliases_and_quiet() {
    let dir = scratch_dir("alias");
    let (a, b) = (dir.join("a.png"), dir.join("b.png"));
    let (code, err, _) = raypack(&["render", "-r", "16", "12", "-s", "2", "-f", s(&a)]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("Rendering"), "{err}");
    // The same render through -o / --outfile, --spp and --quiet: the same pixels, no output.
    for flag in ["-o", "--outfile"] {
        let (code, err, out) = raypack(&["render", "-r", "16", "12", "--spp", "2", flag, s(&b), "--quiet"]);
        assert_eq!(code, 0, "{err}");
        assert_eq!((err.as_str(), out.as_str()), ("", ""), "--quiet prints nothing");
        assert_eq!(pixels(&a), pixels(&b));
        std::fs::remove_file(&b).unwrap();
    }
    // Errors still show under --quiet.
    let (code, err, _) = raypack(&["render", "-r", "0", "12", "--quiet", "-o", s(&b)]);
    assert_eq!(code, 2);
    assert!(err.contains("width and height"), "{err}");
}

#[test]
fn clamped_values_are_warned_about() {
    let dir = scratch_dir("clamp");
    let (a, b) = (dir.join("a.png"), dir.join("b.png"));
    let (code, err, _) = raypack(&["render", "-r", "16", "12", "-s", "0", "-l", "0", "-q", "-o", s(&a)]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("warning: -s 0: rendering 1 sample per pixel"), "{err}");
    assert!(err.contains("warning: -l 0: taking 1 shadow ray"), "{err}");
    let (code, err, _) = raypack(&["render", "-r", "16", "12", "-s", "1", "-l", "1", "-q", "-o", s(&b)]);
    assert_eq!((code, err.as_str()), (0, ""));
    assert_eq!(pixels(&a), pixels(&b), "-s 0 -l 0 renders as -s 1 -l 1");
    let (code, err, _) = raypack(&["render", "-r", "16", "12", "-s", "4", "-a", "64", "0.05", "-q", "-o", s(&a)]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("-a 64: the batch is larger than the 4 samples per pixel"), "{err}");
}

#[test]
fn hemisphere_sampling_on_point_lights_is_black_with_a_warning() {
    let dir = scratch_dir("hemi");
    // A quad facing +z: the loader adds one point light (and says so).
    let obj = dir.join("quad.obj");
    std::fs::write(&obj, "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3 4\n").unwrap();
    let out = dir.join("q.png");
    let (code, err, _) = raypack(&["render", s(&obj), "-r", "16", "12", "-H", "-q", "-o", s(&out)]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("warning: -H: ") && err.contains("point, directional or spot"), "{err}");
    assert!(pixels(&out).iter().all(|&p| p == 0), "CS184's black image stays");
    // With light sampling the quad is lit, and there is no -H warning.
    let (code, err, _) = raypack(&["render", s(&obj), "-r", "16", "12", "-q", "-o", s(&out)]);
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains("-H"), "{err}");
    assert!(pixels(&out).iter().any(|&p| p > 0));
    // The built-in box has an area light: no warning with -H.
    let (code, err, _) = raypack(&["render", "-r", "16", "12", "-H", "-q", "-o", s(&out)]);
    assert_eq!((code, err.as_str()), (0, ""));
}

/// The horizontal field of view CS184 (and `Camera::set_aspect`) gives a vertical one of
/// `vfov` degrees at `aspect`.
fn hfov(vfov: f32, aspect: f32) -> f32 {
    (2.0 * ((vfov.to_radians() * 0.5).tan() * aspect).atan()).to_degrees()
}

#[test]
fn camera_flags_equal_a_camera_file_of_the_same_camera() {
    let dir = scratch_dir("camera");
    let (flags, file, written) = (dir.join("flags.png"), dir.join("file.png"), dir.join("written.png"));
    let view = ["--lookat", "0.5", "0", "3.5", "0.5", "0", "0", "--up", "0", "1", "0", "--fov", "40"];
    let common = ["render", "-r", "40", "30", "-s", "2", "-m", "2", "-q"];
    let (code, err, _) = raypack(&[&common[..], &view, &["-o", s(&flags)]].concat());
    assert_eq!(code, 0, "{err}");
    // The same camera, written by hand in CS184's format: eye (0.5, 0, 3.5) looking down -z.
    let cam = dir.join("cam.txt");
    let text = format!(
        "{} 40 1.333 0.1 100\n0.5 0 3.5 0.5 0 0\n1.5708 0 3.5 0.35 35\n1 0 0\n0 1 0\n0 0 1\n40 30 41.2\n",
        hfov(40.0, 40.0 / 30.0)
    );
    std::fs::write(&cam, text).unwrap();
    let (code, err, _) = raypack(&[&common[..], &["-c", s(&cam), "-o", s(&file)]].concat());
    assert_eq!(code, 0, "{err}");
    let image = pixels(&flags);
    assert!(image.iter().any(|&p| p > 0), "the box is in view");
    assert_eq!(image, pixels(&file), "--lookat/--up/--fov and the camera file render the same image");
    // --write-camera writes that camera, commented, and renders nothing (so an image name
    // beside it is refused); -c reads it back.
    let cam2 = dir.join("written.txt");
    let (code, err, _) = raypack(&[&common[..], &view, &["--write-camera", s(&cam2), "-o", s(&written)]].concat());
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("with --write-camera") && !cam2.exists() && !written.exists(), "{err}");
    let (code, err, _) = raypack(&[&common[..], &view, &["--write-camera", s(&cam2)]].concat());
    assert_eq!(code, 0, "{err}");
    assert!(!written.exists(), "nothing rendered");
    let text = std::fs::read_to_string(&cam2).unwrap();
    assert!(text.starts_with('#') && text.contains("0.5 0 3.5 0.5 0 0"), "{text}");
    let (code, err, _) = raypack(&[&common[..], &["-c", s(&cam2), "-o", s(&written)]].concat());
    assert_eq!(code, 0, "{err}");
    assert_eq!(image, pixels(&written));
}

#[test]
fn bad_camera_flags_are_clear_errors() {
    let dir = scratch_dir("badcam");
    let out = dir.join("x.png");
    let cases: [(&[&str], &str); 7] = [
        (&["--fov", "0"], "--fov 0: the vertical field of view must be between 0 and 180"),
        (&["--fov", "180"], "--fov 180: the vertical field of view must be between 0 and 180"),
        (&["--fov", "-10"], "--fov -10:"),
        (&["--lookat", "1", "2", "3", "1", "2", "3"], "--lookat: the eye and the target are the same point (1 2 3)"),
        (&["--lookat", "0", "0", "5", "0", "0", "0", "--up", "0", "0", "2"], "--up (0.000 0.000 2.000) is parallel"),
        // Looking straight down with the box camera's up (+y): the roll is undefined.
        (&["--lookat", "0", "5", "0", "0", "0", "0"], "the camera's up vector (give --up)"),
        (&["--up", "0", "0", "0"], "--up 0 0 0: the up vector must not be zero"),
    ];
    for (flags, message) in cases {
        let (code, err, _) = raypack(&[&["render", "-r", "8", "6", "-q", "-o", s(&out)][..], flags].concat());
        assert_eq!(code, 2, "{flags:?}: {err}");
        assert!(err.contains(message), "{flags:?}: expected {message:?} in {err}");
        assert!(!out.exists());
    }
}

#[test]
fn info_and_bench_default_to_the_built_in_box() {
    let (code, err, out) = raypack(&["info", "--quality", "fast"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("built-in Cornell box") && out.contains("12 triangles, 2 spheres"), "{out}");
    let (code, err, out) =
        raypack(&["bench", "-r", "16", "12", "--runs", "2", "-t", "1", "--methods", "stream", "--json", "-"]);
    assert_eq!(code, 0, "{err}");
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(json["schema"], 2);
    assert!(json["scene"].as_str().unwrap().contains("built-in Cornell box"));
    assert!(json["embree"].is_null());
    assert_eq!(json["summary"].as_array().unwrap().len(), 3, "primary, diffuse, shadow at 1 thread");
    for row in json["results"].as_array().unwrap() {
        let (lo, med, hi) =
            (row["mrays_per_s_min"].as_f64(), row["mrays_per_s"].as_f64(), row["mrays_per_s_max"].as_f64());
        assert!(lo <= med && med <= hi, "{row}");
    }
    // The text report: the header line and the summary, the per-method table only with -v.
    let (code, err, out) = raypack(&["bench", "-r", "16", "12", "--runs", "1", "-t", "1", "--methods", "stream"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("machine: ") && out.contains("best raypack") && !out.contains("t-sum"), "{out}");
    let (code, err, out) = raypack(&["bench", "-v", "-r", "16", "12", "--runs", "1", "-t", "1", "--methods", "stream"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("t-sum") && out.contains("best raypack"), "{out}");
}

#[test]
fn version_names_the_commit_the_features_and_the_kernels() {
    let run = |isa: Option<&str>| {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_raypack"));
        cmd.arg("--version").env_remove("RAYPACK_ISA");
        if let Some(isa) = isa {
            cmd.env("RAYPACK_ISA", isa);
        }
        let out = cmd.output().unwrap();
        assert!(out.status.success());
        String::from_utf8(out.stdout).unwrap()
    };
    let text = run(None);
    let line = |key: &str| {
        text.lines().find_map(|l| l.strip_prefix(key)).unwrap_or_else(|| panic!("no {key} line: {text}")).to_string()
    };
    assert_eq!(text.lines().next(), Some(concat!("raypack ", env!("CARGO_PKG_VERSION"))));
    // The commit is HEAD's when the tests run in a checkout (the build and the tests see the
    // same HEAD), else "unknown".
    let head =
        Command::new("git").args(["rev-parse", "--short", "HEAD"]).current_dir(env!("CARGO_MANIFEST_DIR")).output();
    let commit = line("commit: ");
    match head.ok().filter(|o| o.status.success()) {
        Some(o) => {
            let head = String::from_utf8(o.stdout).unwrap().trim().to_string();
            assert!(commit == head || commit == format!("{head}-dirty"), "{commit} vs HEAD {head}");
        }
        None => assert_eq!(commit, "unknown"),
    }
    let features = line("features: ");
    assert!(features.split(", ").any(|f| f == "cli") && features.split(", ").any(|f| f == "image"), "{features}");
    let embree = line("embree: ");
    if cfg!(feature = "embree") {
        assert!(features.contains("embree") && embree.starts_with("Embree ") && embree.contains(" linked"), "{embree}");
    } else {
        assert!(embree.starts_with("not built in"), "{embree}");
    }
    let best = raypack::Isa::detected();
    assert!(line("kernels: ").starts_with(&format!("{best} (")), "{text}");
    // RAYPACK_ISA lowers the kernels' tier, and --version says so.
    let sse = run(Some("sse"));
    let kernels = sse.lines().find_map(|l| l.strip_prefix("kernels: ")).unwrap();
    assert!(kernels.starts_with(&format!("{} (RAYPACK_ISA=", raypack::Isa::Baseline)), "{kernels}");
}

#[test]
fn render_takes_the_scene_as_a_flag_as_info_and_bench_do() {
    let dir = scratch_dir("scene-flag");
    let obj = dir.join("quad.obj");
    std::fs::write(&obj, "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3 4\n").unwrap();
    let (a, b, c) = (dir.join("a.png"), dir.join("b.png"), dir.join("c.png"));
    let (code, err, _) = raypack(&["render", s(&obj), "-r", "16", "12", "-q", "-o", s(&a)]);
    assert_eq!(code, 0, "{err}");
    let (code, err, _) = raypack(&["render", "--scene", s(&obj), "-r", "16", "12", "-q", "-o", s(&b)]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(pixels(&a), pixels(&b), "--scene FILE renders what SCENE does");
    // The CS184 form without a command, with the flag.
    let (code, err, _) = raypack(&["--scene", s(&obj), "-r", "16", "12", "-q", "-o", s(&c)]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(pixels(&a), pixels(&c));
    let (code, err, _) = raypack(&["render", s(&obj), "--scene", s(&obj), "-r", "16", "12", "-q"]);
    assert_eq!(code, 2);
    assert!(err.contains("--scene"), "{err}");
}

#[test]
fn t_is_one_thread_count_on_every_command() {
    for cmd in ["render", "info", "bench"] {
        let (code, err, _) = raypack(&[cmd, "-t", "1,2"]);
        assert_eq!(code, 2, "{cmd}: {err}");
        assert!(err.contains("-t takes one thread count") && err.contains("--threads-list 1,2"), "{cmd}: {err}");
        let (code, err, _) = raypack(&[cmd, "-t", "0"]);
        assert_eq!(code, 2, "{cmd}: {err}");
        assert!(err.contains("-t 0: need at least one thread"), "{cmd}: {err}");
    }
    let (code, err, _) = raypack(&["bench", "-t", "1", "--threads-list", "1,2"]);
    assert_eq!(code, 2);
    assert!(err.contains("--threads-list"), "{err}");
    // bench -t N times at N threads; --threads-list at each of its counts (`all`: every core).
    let bench = |threads: &[&str]| {
        let args = [&["bench", "-r", "8", "6", "--runs", "1", "--build-runs", "1", "--methods", "stream"][..], threads];
        let (code, err, out) = raypack(&[&args.concat()[..], &["--json", "-"]].concat());
        assert_eq!(code, 0, "{err}");
        let json: serde_json::Value = serde_json::from_str(&out).unwrap();
        let mut counts: Vec<u64> =
            json["results"].as_array().unwrap().iter().map(|r| r["threads"].as_u64().unwrap()).collect();
        counts.sort();
        counts.dedup();
        counts
    };
    assert_eq!(bench(&["-t", "1"]), [1]);
    let all = std::thread::available_parallelism().unwrap().get() as u64;
    let mut want = vec![1, all];
    want.dedup();
    assert_eq!(bench(&["--threads-list", "1,all"]), want);
}

#[test]
fn every_error_has_one_prefix_on_a_line_of_its_own() {
    let dir = scratch_dir("prefix");
    // An argument error (clap's), a missing scene and a malformed one (after "Collecting
    // primitives... " has been printed): each error line starts with "[raypack] error: ".
    let bad = dir.join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nf 1 2 7\n").unwrap();
    let out = dir.join("x.png");
    for args in [
        vec!["render", "--no-such-flag"],
        vec!["render", "/nonexistent/box.dae", "-r", "8", "6", "-o", s(&out)],
        vec!["render", s(&bad), "-r", "8", "6", "-o", s(&out)],
        vec!["info", "-t", "x"],
        vec!["rendr"],
    ] {
        let (code, err, _) = raypack(&args);
        assert_eq!(code, 2, "{args:?}: {err}");
        let lines: Vec<&str> = err.lines().filter(|l| l.contains("error")).collect();
        assert!(!lines.is_empty(), "{args:?}: {err}");
        for l in &lines {
            assert!(l.starts_with("[raypack] error: ") || !l.contains("error:"), "{args:?}: {l:?} in {err}");
        }
        assert!(err.lines().any(|l| l.starts_with("[raypack] error: ")), "{args:?}: {err}");
    }
    // The malformed scene's error comes after the progress line, not on it.
    let (_, err, _) = raypack(&["render", s(&bad), "-r", "8", "6", "-o", s(&out)]);
    let progress = err.lines().find(|l| l.contains("Collecting primitives")).expect("progress shown");
    assert!(!progress.contains("error"), "{err}");
}
