//! The README's first render: the built-in Cornell box without flags gets its own sampling
//! defaults (global illumination, several samples and light samples), while a scene file keeps
//! CS184's flag defaults (`-s 1 -l 1 -m 1`); neither clamps its samples unless asked to.

use std::path::Path;
use std::process::Command;

fn render(args: &[&str], out: &Path) -> Vec<u8> {
    let mut all = vec!["render", "-t", "2", "-r", "48", "36", "-f", out.to_str().unwrap()];
    all.extend(args);
    let o = Command::new(env!("CARGO_BIN_EXE_raypack")).args(&all).output().expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut reader = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(out).unwrap())).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    buf
}

fn mean(px: &[u8]) -> f64 {
    px.iter().map(|&v| v as f64).sum::<f64>() / px.len() as f64
}

#[test]
fn built_in_box_defaults_to_global_illumination_and_files_to_cs184_flags() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let default = render(&[], &p("default.png"));
    let explicit = render(&["-s", "128", "-l", "2", "-m", "5", "--clamp", "inf"], &p("explicit.png"));
    assert_eq!(default, explicit, "the built-in box's defaults are -s 128 -l 2 -m 5, no clamp");
    // Direct light only (CS184's defaults, asked for explicitly) is darker: indirect light
    // only adds.
    let cs184 = render(&["-s", "128", "-l", "2", "-m", "1"], &p("direct.png"));
    assert!(mean(&default) > mean(&cs184) * 1.05, "{} vs {}", mean(&default), mean(&cs184));

    // A scene file without flags renders exactly as with -s 1 -l 1 -m 1.
    let cornell = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell.dae");
    let file = cornell.to_str().unwrap();
    let a = render(&[file], &p("file.png"));
    let b = render(&[file, "-s", "1", "-l", "1", "-m", "1"], &p("file_flags.png"));
    assert_eq!(a, b);
    assert_ne!(a, default);
    // A clamp below the lamp's radiance (3) scales samples down: the box differs from its
    // default.
    let clamped = render(&["--clamp", "1"], &p("clamped.png"));
    assert_ne!(clamped, default);
}
