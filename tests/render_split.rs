//! Renders split into parts (`--tile`, `--crop-window`, `--pixel-bounds`), rendered on one or
//! two threads each, with and without adaptive sampling, merge (`raypack merge`) into the very
//! file one render of the whole image writes, byte for byte; and `merge` refuses parts that do
//! not make one image, writing nothing.

use raypack::render::part::ImagePart;
use std::path::{Path, PathBuf};
use std::process::Command;

fn raypack(args: &[String]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_raypack")).args(args).output().expect("runs");
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
}

fn args(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| s.to_string()).collect()
}

fn scratch_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("raypack-split-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

/// The window flags of part `i` of `n` in each of the three ways to name one, for a
/// `w × h` image. Crop windows are bands of columns (fractions `i / n`, exact in `{:?}`);
/// pixel bounds are bands of rows of uneven heights.
fn window_flags(method: &str, i: usize, n: usize, w: usize, h: usize) -> Vec<String> {
    match method {
        "tile" => vec!["--tile".into(), format!("{i}/{n}")],
        "crop-window" => {
            let f = |k: usize| format!("{:?}", k as f64 / n as f64);
            vec!["--crop-window".into(), f(i), f(i + 1), "0".into(), "1".into()]
        }
        "pixel-bounds" => {
            // Row edges at k (k + 1) h / (n (n + 1)), so the bands grow downwards.
            let edge = |k: usize| k * (k + 1) * h / (n * (n + 1));
            let (y0, y1) = (edge(i), edge(i + 1));
            assert!(y0 < y1, "{h} rows in {n} bands");
            vec!["--pixel-bounds".into(), "0".into(), w.to_string(), y0.to_string(), y1.to_string()]
        }
        _ => unreachable!(),
    }
}

/// Renders `base` whole and in 1, 2 and 7 parts each way, parts on alternating thread
/// counts, and checks that every split merges into the whole render's EXR byte for byte (and
/// the PNG of the merge into the whole render's PNG).
fn splits_merge_bit_for_bit(name: &str, base: &[&str], (w, h): (usize, usize)) {
    let dir = scratch_dir(name);
    let size = [w.to_string(), h.to_string()];
    for adaptive in [false, true] {
        let mut base: Vec<String> = args(base);
        base.extend(["-q".into(), "-r".into(), size[0].clone(), size[1].clone()]);
        if adaptive {
            base.extend(args(&["-a", "4", "0.05"]));
        }
        let whole = dir.join(format!("whole-{adaptive}.exr"));
        let whole_png = dir.join(format!("whole-{adaptive}.png"));
        for out in [&whole, &whole_png] {
            let (ok, log) = raypack(&[base.clone(), args(&["-t", "2", "-o", &s(out)])].concat());
            assert!(ok, "{log}");
        }
        let expected = std::fs::read(&whole).unwrap();
        for method in ["tile", "crop-window", "pixel-bounds"] {
            for n in [1, 2, 7] {
                let mut parts = Vec::new();
                for i in 0..n {
                    let part = dir.join(format!("{method}-{n}-{i}-{adaptive}.exr"));
                    let threads = (1 + i % 2).to_string();
                    let cmd =
                        [base.clone(), window_flags(method, i, n, w, h), args(&["-t", &threads, "-o", &s(&part)])]
                            .concat();
                    let (ok, log) = raypack(&cmd);
                    assert!(ok, "{cmd:?}: {log}");
                    parts.push(s(&part));
                }
                // Merged in reverse order: the order of the parts does not matter.
                parts.reverse();
                let merged = dir.join(format!("merged-{method}-{n}-{adaptive}.exr"));
                let (ok, log) = raypack(&[args(&["merge", "-q", "-o", &s(&merged)]), parts.clone()].concat());
                assert!(ok, "{log}");
                assert!(
                    std::fs::read(&merged).unwrap() == expected,
                    "{name}: {n} parts by {method} (adaptive: {adaptive}) do not merge into the whole render's EXR"
                );
                if n == 7 && method == "tile" {
                    let png = dir.join(format!("merged-{adaptive}.png"));
                    let (ok, log) = raypack(&[args(&["merge", "-q", "-o", &s(&png)]), parts].concat());
                    assert!(ok, "{log}");
                    assert!(std::fs::read(&png).unwrap() == std::fs::read(&whole_png).unwrap(), "{name}: PNG");
                }
            }
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn splits_of_the_built_in_box_merge_bit_for_bit() {
    splits_merge_bit_for_bit("box", &["render", "-s", "8", "-m", "5"], (61, 37));
}

#[test]
fn splits_of_cbbunny_merge_bit_for_bit() {
    let Some(root) = std::env::var_os("RAYPACK_SCENES") else {
        eprintln!("SKIPPED: RAYPACK_SCENES is not set (CBbunny)");
        return;
    };
    let scene = Path::new(&root).join("cs184/sky/CBbunny.dae");
    if !scene.exists() {
        eprintln!("SKIPPED: {} is missing", scene.display());
        return;
    }
    splits_merge_bit_for_bit("bunny", &["render", &s(&scene), "-s", "4", "-m", "5"], (64, 48));
}

/// Parts that do not make one image: each refusal names what is wrong, and nothing is written.
#[test]
fn merge_refuses_parts_of_other_renders_conflicts_and_holes() {
    let dir = scratch_dir("refuse");
    let out = dir.join("out.exr");
    let render = |extra: &[&str], part: &str| {
        let p = dir.join(part);
        let (ok, log) = raypack(
            &[args(&["render", "-q", "-r", "32", "24", "-s", "2"]), args(extra), args(&["-o", &s(&p)])].concat(),
        );
        assert!(ok, "{log}");
        s(&p)
    };
    let merge = |parts: &[&String]| {
        let (ok, log) =
            raypack(&[args(&["merge", "-o", &s(&out)]), parts.iter().map(|p| p.to_string()).collect()].concat());
        assert!(!ok, "merged: {log}");
        assert!(!out.exists(), "wrote {} although: {log}", out.display());
        log
    };
    let a = render(&["--tile", "0/2"], "a.exr");
    let b = render(&["--tile", "1/2"], "b.exr");

    // Other settings: the field is named.
    let seed = render(&["--tile", "1/2", "--seed", "9"], "seed.exr");
    let log = merge(&[&a, &seed]);
    assert!(log.contains("other settings") && log.contains("seed `0` there, `9` here"), "{log}");
    let light = render(&["--tile", "1/2", "-l", "3"], "light.exr");
    assert!(merge(&[&a, &light]).contains("light-samples `2` there, `3` here"));

    // Another scene: a triangle of our own.
    let ply = dir.join("tri.ply");
    std::fs::write(
        &ply,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
         element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    )
    .unwrap();
    let other = render(&[&s(&ply), "--tile", "1/2", "-m", "5", "-l", "2"], "other.exr");
    let log = merge(&[&a, &other]);
    assert!(log.contains("another scene") && log.contains("tri.ply"), "{log}");

    // Overlapping parts with different values: a forged copy of `b` over `a`'s columns.
    let mut forged = ImagePart::decode_exr(&std::fs::read(&b).unwrap()).unwrap();
    let whole = ImagePart::decode_exr(&std::fs::read(render(&[], "whole.exr")).unwrap()).unwrap();
    let (x0, x1) = (forged.window.x0 - 3, forged.window.x1);
    forged.window.x0 = x0;
    forged.film = raypack::render::Film { width: x1 - x0, height: 24, pixels: Vec::new() };
    for y in 0..24 {
        forged.film.pixels.extend_from_slice(&whole.film.pixels[y * 32 + x0..y * 32 + x1]);
    }
    let equal = dir.join("equal.exr");
    std::fs::write(&equal, forged.encode_exr().unwrap()).unwrap();
    forged.film.pixels[5 * forged.film.width + 1].y += 0.25;
    let differ = dir.join("differ.exr");
    std::fs::write(&differ, forged.encode_exr().unwrap()).unwrap();
    let log = merge(&[&a, &s(&differ)]);
    assert!(
        log.contains("overlap")
            && log.contains("differ in 1 of its pixels")
            && log.contains(&format!("({}, 5)", x0 + 1)),
        "{log}"
    );
    // The same pixels twice, with equal values, are fine.
    let (ok, log) = raypack(&args(&["merge", "-o", &s(&out), &a, &s(&equal)]));
    assert!(ok, "{log}");
    assert!(log.contains("were in more than one part"), "{log}");
    assert!(std::fs::read(&out).unwrap() == std::fs::read(dir.join("whole.exr")).unwrap());
    std::fs::remove_file(&out).unwrap();

    // Missing pixels: the rectangle and the flags that render it.
    let log = merge(&[&b]);
    let left = whole.film.width / 2;
    assert!(log.contains(&format!("{} of the 32x24 image's pixels are in no part", left * 24)), "{log}");
    assert!(log.contains(&format!("--pixel-bounds 0 {left} 0 24")), "{log}");

    // Files that are not parts.
    let png = render(&[], "whole.png");
    let log = merge(&[&a, &png]);
    assert!(log.contains("whole.png") && log.contains("not a readable OpenEXR file"), "{log}");
    let plain = dir.join("plain.exr");
    raypack::render::Film::new(4, 4).write(&plain, raypack::render::Encoding::Srgb).unwrap();
    assert!(merge(&[&s(&plain)]).contains("has no `raypack` attribute"));
    let missing = s(&dir.join("missing.exr"));
    assert!(merge(&[&a, &missing]).contains("missing.exr"));

    // Parts are written as EXR only, and the window flags are checked.
    for (flags, says) in [
        (vec!["--tile", "0/2", "-o", "part.png"], "name an .exr output"),
        (vec!["--tile", "2/2"], "expected an index from 0 to 1"),
        (vec!["--tile", "x"], "expected I/N"),
        (vec!["--crop-window", "0.5", "0.5", "0", "1"], "0 <= x0 < x1 <= 1"),
        (vec!["--pixel-bounds", "0", "33", "0", "24"], "x1 <= 32"),
        (vec!["--tile", "0/2", "--integrator", "heatmap"], "whole images only"),
    ] {
        let (ok, log) = raypack(&[args(&["render", "-q", "-r", "32", "24"]), args(&flags)].concat());
        assert!(!ok && log.contains(says), "{flags:?}: {log}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
