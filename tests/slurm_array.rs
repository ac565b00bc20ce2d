//! The Slurm-array loop of docs/more-than-one-machine.md runs as written from the
//! repository's root: four parts rendered by `tools/slurm/render-array.sh` as four tasks of a
//! job array, merged by its `--merge`, equal one whole render byte for byte (`cmp`).

use std::path::Path;
use std::process::Command;

/// The ```bash block of docs/more-than-one-machine.md.
fn guide_loop() -> String {
    let page = include_str!("../docs/more-than-one-machine.md");
    let block = page.split("```bash\n").nth(1).expect("a ```bash block");
    block.split("```").next().unwrap().to_string()
}

#[test]
fn the_guides_slurm_loop_merges_into_the_whole_render() {
    let script = guide_loop();
    assert!(script.contains("SLURM_ARRAY_TASK_ID=$i") && script.contains("cmp"), "{script}");
    // Run in a scratch directory holding the repository's tools/ and scenes/, with the
    // binary under test first on PATH.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = std::env::temp_dir().join(format!("raypack-slurm-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for name in ["tools", "scenes"] {
        std::os::unix::fs::symlink(root.join(name), dir.join(name)).unwrap();
    }
    let bin = Path::new(env!("CARGO_BIN_EXE_raypack")).parent().unwrap().to_path_buf();
    let path =
        std::env::join_paths(std::iter::once(bin).chain(std::env::split_paths(&std::env::var_os("PATH").unwrap())))
            .unwrap();
    let out = Command::new("bash")
        .args(["-euo", "pipefail", "-c", &script])
        .current_dir(&dir)
        .env("PATH", path)
        .env_remove("RAYPACK")
        .output()
        .expect("bash runs");
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert_eq!(stdout.trim(), "identical", "{stderr}");
    let parts: Vec<_> = std::fs::read_dir(dir.join("box.parts")).unwrap().collect();
    assert_eq!(parts.len(), 4);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_script_says_what_is_wrong() {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/slurm/render-array.sh");
    let run = |args: &[&str], env: &[(&str, &str)]| {
        let mut c = Command::new("bash");
        c.arg(&script).args(args).env("RAYPACK", env!("CARGO_BIN_EXE_raypack")).env_remove("SLURM_ARRAY_TASK_ID");
        for (k, v) in env {
            c.env(k, v);
        }
        let out = c.output().unwrap();
        (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
    };
    let (code, err) = run(&["scene.dae", "out.exr"], &[]);
    assert!(code != Some(0) && err.contains("not a job array task"), "{err}");
    let dir = std::env::temp_dir().join(format!("raypack-slurm-empty-{}", std::process::id()));
    let (code, err) = run(&["--merge", dir.join("none.exr").to_str().unwrap()], &[]);
    assert!(code == Some(2) && err.contains("no parts in"), "{err}");
    // An array numbered from 1: task 1 renders part 0.
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("one.exr");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell.dae");
    let env = [("SLURM_ARRAY_TASK_ID", "1"), ("SLURM_ARRAY_TASK_COUNT", "2"), ("SLURM_ARRAY_TASK_MIN", "1")];
    let (code, err) = run(&[scene.to_str().unwrap(), out.to_str().unwrap(), "-r", "16", "12", "-s", "1"], &env);
    assert_eq!(code, Some(0), "{err}");
    assert!(dir.join("one.parts/part-0.exr").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
