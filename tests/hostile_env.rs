//! raypack in a hostile environment (issue 19): a shared directory where someone plants
//! links, FIFOs and devices at the names raypack reads and writes, flags that ask for absurd
//! sizes, and a cache file truncated while a render uses it. Nothing outside the output path
//! may be written, no input may make raypack wait forever or use unbounded memory, and no
//! signal may end a render.
//!
//! The children run under a time limit (a hang fails the test instead of hanging it) and,
//! where a bug would allocate without end, under an address-space limit (`ulimit -v`), so
//! that a regression fails fast instead of exhausting the machine.

use std::io::{BufRead, Read};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::child::{Limits, Run, TIMEOUT, TWO_GIB, command_with, finish};

/// `raypack ARGS` under `limits`, its stdout discarded.
fn command(args: &[&str], limits: Limits) -> Command {
    let mut c = command_with(args, &[], limits);
    c.stdout(Stdio::null());
    c
}

fn run(args: &[&str], limits: Limits) -> Run {
    finish(command(args, limits).spawn().expect("runs"), TIMEOUT)
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A torus knot of about `2 · n_len · n_around` triangles as OBJ text.
fn knot_obj(n_len: usize, n_around: usize) -> String {
    let knot = raypack::generate::torus_knot(n_len, n_around, 2.0, 3.0, 0.4, 0.05);
    let mut obj = String::new();
    for p in &knot.positions {
        obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    for [a, b, c] in &knot.indices {
        obj += &format!("f {} {} {}\n", a + 1, b + 1, c + 1);
    }
    obj
}

fn mkfifo(path: &Path) {
    let c = std::ffi::CString::new(s(path)).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0, "mkfifo {}", path.display());
}

fn symlink(to: &Path, at: &Path) {
    std::os::unix::fs::symlink(to, at).unwrap();
}

fn is_fifo(p: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    std::fs::symlink_metadata(p).is_ok_and(|m| m.file_type().is_fifo())
}

/// The cache file in `dir` (there is one).
fn cache_file(dir: &Path) -> PathBuf {
    let files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "rpbvh"))
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    files[0].clone()
}

// ----- 1. Temporary files and output paths --------------------------------------------------

/// The names the writers used to create their temporary files with (`.NAME.tmpPID`, the cache
/// `.NAME.tmpPID-SERIAL`): a link planted at any of them must not be followed.
fn plant_links_at_old_temp_names(dir: &Path, names: &[&str], pid: u32, victim: &Path) -> Vec<PathBuf> {
    let mut planted = Vec::new();
    for name in names {
        let mut at = vec![dir.join(format!(".{name}.tmp{pid}"))];
        at.extend((0..8).map(|serial| dir.join(format!(".{name}.tmp{pid}-{serial}"))));
        for p in at {
            symlink(victim, &p);
            planted.push(p);
        }
    }
    planted
}

#[test]
fn links_planted_at_temporary_names_are_never_followed() {
    let dir = tempfile::tempdir().unwrap();
    let victim = dir.path().join("victim.txt");
    std::fs::write(&victim, b"precious").unwrap();

    // In this process: the image writer, the file writer (the benchmark's JSON) and the cache store,
    // with links at every name they could use.
    let pid = std::process::id();
    let out = dir.path().join("lib");
    std::fs::create_dir(&out).unwrap();
    let mut b = raypack::SceneBuilder::new();
    let m = b.add_material(raypack::Material::default());
    let grid = raypack::generate::grid(4, 4);
    b.add_mesh(&grid.positions, &grid.indices, m).unwrap();
    let cache = out.join("cache");
    std::fs::create_dir(&cache).unwrap();
    let opts = raypack::BuildOptions::default();
    let cache_name = raypack::scene::cache::cache_path(&b, &opts, &cache);
    let cache_name = cache_name.file_name().unwrap().to_str().unwrap();
    plant_links_at_old_temp_names(&out, &["a.png", "a.exr", "b.json"], pid, &victim);
    plant_links_at_old_temp_names(&cache, &[cache_name], pid, &victim);
    let film = raypack::render::Film::new(4, 3);
    film.write(&out.join("a.png"), raypack::render::Encoding::Srgb).unwrap();
    film.write(&out.join("a.exr"), raypack::render::Encoding::Srgb).unwrap();
    raypack::fs::output::write_file(&out.join("b.json"), b"{}\n").unwrap();
    let (_, _, report) = b.commit_cached(&opts, &cache);
    assert!(report.write_error.is_none(), "{report:?}");
    assert!(std::fs::read(&victim).unwrap() == b"precious", "a planted link was followed");
    for p in [out.join("a.png"), out.join("a.exr"), out.join("b.json"), report.path.clone()] {
        assert!(std::fs::symlink_metadata(&p).unwrap().is_file(), "{} is not a regular file", p.display());
    }

    // The CLI: the render's image, its sample-rate image and the cache, links planted as
    // soon as the child's PID is known (it loads, builds and renders for a while first).
    let cli = dir.path().join("cli");
    std::fs::create_dir(&cli).unwrap();
    let cache = cli.join("cache");
    let png = cli.join("out.png");
    let args = ["-r", "64", "48", "-s", "64", "-a", "8", "0.01", "-m", "3", "-f", s(&png), "--bvh-cache", s(&cache)];
    // A first run makes the cache directory and tells the cache file's name.
    let first = run(&args, Limits { address_space: Some(TWO_GIB), ..Limits::default() });
    assert_eq!(first.code, Some(0), "{first:?}");
    let cache_file = cache_file(&cache);
    std::fs::remove_file(&cache_file).unwrap();
    let child = command(&args, Limits { address_space: Some(TWO_GIB), ..Limits::default() }).spawn().unwrap();
    let cache_name = cache_file.file_name().unwrap().to_str().unwrap();
    plant_links_at_old_temp_names(&cli, &["out.png", "out_rate.png"], child.id(), &victim);
    plant_links_at_old_temp_names(&cache, &[cache_name], child.id(), &victim);
    let second = finish(child, TIMEOUT);
    assert_eq!(second.code, Some(0), "{second:?}");
    assert!(std::fs::read(&victim).unwrap() == b"precious", "a planted link was followed: {}", second.stderr);
    for p in [&png, &cli.join("out_rate.png"), &cache_file] {
        assert!(std::fs::symlink_metadata(p).unwrap().is_file(), "{} is not a regular file", p.display());
    }
}

#[test]
fn an_output_naming_an_input_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("knot.obj");
    std::fs::write(&scene, knot_obj(20, 6)).unwrap();
    let before = std::fs::read(&scene).unwrap();
    for args in [
        vec!["render", s(&scene), "-r", "8", "6", "-f", s(&scene)],
        vec!["render", s(&scene), "-r", "8", "6", "-f", s(&scene), "-a", "4", "0.1"],
        vec!["bench", s(&scene), "-r", "8", "6", "--runs", "1", "--json", s(&scene)],
    ] {
        let r = run(&args, Limits { address_space: Some(TWO_GIB), ..Limits::default() });
        assert_eq!(r.code, Some(2), "{args:?}: {r:?}");
        assert!(r.stderr.contains("is the input file"), "{args:?}: {}", r.stderr);
        assert_eq!(std::fs::read(&scene).unwrap(), before, "{args:?} overwrote the scene");
    }
    // The camera file is an input too.
    let cam = dir.path().join("cam.txt");
    std::fs::write(&cam, "49 38 1.3 0.1 100\n0 1 5 0 1 0\n1.57 0 5 1 50\n1 0 0 0 1 0 0 0 1\n480 360 1\n").unwrap();
    let r = run(&["-c", s(&cam), "-r", "8", "6", "-f", s(&cam)], Limits::default());
    assert_eq!(r.code, Some(2), "{r:?}");
    assert!(std::fs::read_to_string(&cam).unwrap().starts_with("49 38"));
}

#[test]
fn links_fifos_and_devices_at_the_output_are_never_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let limits = Limits { address_space: Some(TWO_GIB), ..Limits::default() };
    // A link: refused, and neither it nor what it points to changes.
    let victim = dir.path().join("victim.png");
    std::fs::write(&victim, b"precious").unwrap();
    let link = dir.path().join("link.png");
    symlink(&victim, &link);
    let r = run(&["-r", "8", "6", "-f", s(&link)], limits);
    assert_eq!(r.code, Some(2), "{r:?}");
    assert!(r.stderr.contains("symbolic link"), "{}", r.stderr);
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read(&victim).unwrap(), b"precious");

    // A FIFO nobody reads: an error at once, not a hang, and the FIFO stays.
    let fifo = dir.path().join("pipe.png");
    mkfifo(&fifo);
    let r = run(&["-r", "8", "6", "-f", s(&fifo)], limits);
    assert_eq!(r.code, Some(2), "{r:?}");
    assert!(r.stderr.contains("FIFO"), "{}", r.stderr);
    assert!(is_fifo(&fifo), "the FIFO was replaced");

    // A FIFO someone reads: the image goes into it.
    let reader = {
        use std::os::unix::fs::OpenOptionsExt;
        // Opened non-blocking so that it is a reader before the writer comes.
        let f = std::fs::OpenOptions::new().read(true).custom_flags(libc::O_NONBLOCK).open(&fifo).unwrap();
        std::thread::spawn(move || {
            let (mut f, mut got) = (f, Vec::new());
            let start = Instant::now();
            let mut buf = [0u8; 1 << 16];
            loop {
                match f.read(&mut buf) {
                    Ok(0) if !got.is_empty() || start.elapsed() > TIMEOUT => break got,
                    Ok(0) => std::thread::sleep(Duration::from_millis(5)),
                    Ok(n) => got.extend_from_slice(&buf[..n]),
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                        std::thread::sleep(Duration::from_millis(5))
                    }
                    Err(e) => panic!("{e}"),
                }
            }
        })
    };
    let r = run(&["-r", "8", "6", "-f", s(&fifo)], limits);
    assert_eq!(r.code, Some(0), "{r:?}");
    let got = reader.join().unwrap();
    assert!(got.starts_with(b"\x89PNG\r\n\x1a\n"), "{} bytes, not a PNG", got.len());
    assert!(is_fifo(&fifo), "the FIFO was replaced");

    // A device node (made here: /dev itself must never be touched by a test). Needs
    // CAP_MKNOD; without it this part is skipped.
    let dev = dir.path().join("full.png");
    let c = std::ffi::CString::new(s(&dev)).unwrap();
    // SAFETY: a valid NUL-terminated path; makedev(1, 7) is /dev/full.
    let made = unsafe { libc::mknod(c.as_ptr(), libc::S_IFCHR | 0o666, libc::makedev(1, 7)) } == 0;
    if made {
        let r = run(&["-r", "8", "6", "-f", s(&dev)], limits);
        assert_eq!(r.code, Some(2), "{r:?}");
        assert!(r.stderr.contains("character device"), "{}", r.stderr);
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::symlink_metadata(&dev).unwrap().file_type().is_char_device(), "the device was replaced");
    } else {
        eprintln!("SKIPPED the device part: mknod is not permitted here");
    }

    // `-f -` writes the image to standard output.
    let out = command(&["-r", "8", "6", "-f", "-"], limits).stdout(Stdio::piped()).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.stdout.starts_with(b"\x89PNG\r\n\x1a\n"));
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(names.iter().all(|n| !n.to_string_lossy().starts_with('.')), "temporary files left: {names:?}");
}

#[test]
fn a_sample_rate_image_that_cannot_be_written_leaves_no_image() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cb.png");
    // A directory where the sample-rate image goes.
    std::fs::create_dir(dir.path().join("cb_rate.png")).unwrap();
    let r = run(&["-r", "16", "12", "-s", "8", "-a", "4", "0.1", "-f", s(&out)], Limits::default());
    assert_eq!(r.code, Some(2), "{r:?}");
    assert!(r.stderr.contains("cb_rate.png"), "{}", r.stderr);
    assert!(!out.exists(), "the image was written without its sample-rate image");
    // An old image stays as it was.
    std::fs::write(&out, b"old").unwrap();
    let r = run(&["-r", "16", "12", "-s", "8", "-a", "4", "0.1", "-f", s(&out)], Limits::default());
    assert_eq!(r.code, Some(2), "{r:?}");
    assert_eq!(std::fs::read(&out).unwrap(), b"old");
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names.len(), 2, "no temporary files: {names:?}");
}

// ----- 2. Sizes a flag can blow up ----------------------------------------------------------

#[test]
fn adaptive_sampling_memory_does_not_grow_with_the_batch() {
    // 65536 samples per pixel in one batch: 16.7 M camera samples at once before the fix
    // (1.1 GB). The normals integrator keeps the run short; the buffers are the same.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("a.png");
    let args = ["-s", "65536", "-a", "65536", "0.05", "-r", "16", "16", "-t", "2", "--integrator", "normals"];
    let r = run(&[&args[..], &["-f", s(&out)]].concat(), Limits { address_space: Some(TWO_GIB), ..Limits::default() });
    assert_eq!(r.code, Some(0), "{r:?}");
    assert!(r.peak_bytes > 0 && r.peak_bytes < 100 << 20, "peak resident memory {} MB", r.peak_bytes >> 20);
    assert!(r.stderr.contains("16777216 samples (65536.0 per pixel)"), "{}", r.stderr);

    // 2^32 - 1 samples in one batch: it used to abort at once asking for 35 TB. Now it
    // samples (for ages) in bounded memory: watched for a second, then stopped.
    let huge = ["-s", "4294967295", "-a", "4294967295", "0.05", "-r", "16", "16", "-t", "2", "-f", s(&out)];
    let child = command(&huge, Limits { address_space: Some(TWO_GIB), ..Limits::default() }).spawn().unwrap();
    let r = finish(child, Duration::from_secs(2));
    assert!(r.timed_out, "ended instead of sampling: {r:?}");
    assert!(r.peak_bytes < 100 << 20, "peak resident memory {} MB", r.peak_bytes >> 20);
}

#[test]
fn a_resolution_that_cannot_fit_is_refused_up_front() {
    // Under an 8 GiB address-space limit the answer is the same on every machine.
    let limits = Limits { address_space: Some(8 << 30), ..Limits::default() };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.png");
    for args in [
        &["render", "-r", "32768", "32768", "-f", s(&out)][..],
        &["bench", "scenes/cornell.dae", "-r", "32768", "32768"],
    ] {
        let start = Instant::now();
        let r = run(args, limits);
        assert_eq!(r.code, Some(2), "{args:?}: {r:?}");
        assert!(
            r.stderr.contains("-r 32768 32768: needs about")
                && r.stderr.contains("ulimit -v")
                && r.stderr.contains("use a smaller size, such as -r "),
            "{}",
            r.stderr
        );
        // Refused before any work: a sanity bound far above the cost of the check.
        assert!(start.elapsed() < Duration::from_secs(20), "{:?}", start.elapsed());
        assert!(!out.exists());
    }
    // Without a limit, whenever this machine has less memory than the estimate (75 GB).
    let meminfo = std::fs::read_to_string("/proc/meminfo").unwrap_or_default();
    let avail_kib: u64 = meminfo
        .lines()
        .find_map(|l| l.strip_prefix("MemAvailable:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap_or(u64::MAX);
    if avail_kib < 60 << 20 {
        let r = run(&["-r", "32768", "32768", "-f", s(&out)], Limits::default());
        assert_eq!(r.code, Some(2), "{r:?}");
        assert!(r.stderr.contains("needs about"), "{}", r.stderr);
    }
}

// ----- 3. Special files at input paths ------------------------------------------------------

/// Runs `args` and expects exit code `code` with `what` in the message: in time, in bounded
/// memory, by no signal.
fn expect_prompt(args: &[&str], code: i32, what: &[&str]) -> Run {
    let r = finish(
        command(args, Limits { address_space: Some(TWO_GIB), ..Limits::default() }).spawn().unwrap(),
        Duration::from_secs(30),
    );
    assert!(!r.timed_out, "{args:?} hung: {r:?}");
    assert_eq!(r.signal, None, "{args:?}: {r:?}");
    assert_eq!(r.code, Some(code), "{args:?}: {r:?}");
    assert!(what.iter().any(|w| r.stderr.contains(w)), "{args:?}: expected one of {what:?} in {}", r.stderr);
    r
}

#[test]
fn fifos_and_dev_zero_at_every_input_path_fail_fast() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out.png");
    let fifo_msg = ["FIFO"];
    let dev_msg = ["character device"];
    // The scene.
    let fifo_scene = d.join("fifo.obj");
    mkfifo(&fifo_scene);
    let zero_scene = d.join("zero.ply");
    symlink(Path::new("/dev/zero"), &zero_scene);
    expect_prompt(&["render", s(&fifo_scene), "-r", "8", "6", "-f", s(&out)], 2, &fifo_msg);
    expect_prompt(&["render", s(&zero_scene), "-r", "8", "6", "-f", s(&out)], 2, &dev_msg);
    expect_prompt(&["info", s(&fifo_scene)], 2, &fifo_msg);
    // The camera file.
    let fifo_cam = d.join("cam.fifo");
    mkfifo(&fifo_cam);
    expect_prompt(&["-c", s(&fifo_cam), "-r", "8", "6", "-f", s(&out)], 2, &fifo_msg);
    expect_prompt(&["-c", "/dev/zero", "-r", "8", "6", "-f", s(&out)], 2, &dev_msg);
    // The material library: a warning, and the default material.
    let mtl_fifo = d.join("m.mtl");
    mkfifo(&mtl_fifo);
    for lib in ["m.mtl", "/dev/zero"] {
        let obj = d.join("lib.obj");
        std::fs::write(&obj, format!("mtllib {lib}\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")).unwrap();
        let r = expect_prompt(&["render", s(&obj), "-r", "8", "6", "-f", s(&out)], 0, &["material library"]);
        assert!(r.stderr.contains("using the default material"), "{}", r.stderr);
    }
    // The BVH cache file: rejected, rebuilt, and the planted file left alone.
    let scene = d.join("knot.obj");
    std::fs::write(&scene, knot_obj(40, 8)).unwrap();
    let cache = d.join("cache");
    let info = |extra: &[&str]| {
        let args = [&["info", s(&scene), "--quality", "fast", "--bvh-cache", s(&cache)][..], extra].concat();
        args.iter().map(|a| a.to_string()).collect::<Vec<_>>()
    };
    let first = info(&[]);
    expect_prompt(&first.iter().map(String::as_str).collect::<Vec<_>>(), 0, &["no lights in the file"]);
    let file = cache_file(&cache);
    for (plant, msg) in [(None, &fifo_msg), (Some("/dev/zero"), &dev_msg)] {
        std::fs::remove_file(&file).unwrap();
        match plant {
            None => mkfifo(&file),
            Some(to) => symlink(Path::new(to), &file),
        }
        let r = expect_prompt(&first.iter().map(String::as_str).collect::<Vec<_>>(), 0, &msg[..]);
        assert!(r.stderr.contains("BVH cache rejected and rebuilt"), "{}", r.stderr);
        assert!(r.stderr.contains("BVH cache not written"), "{}", r.stderr);
    }
}

// ----- 4. A cache file truncated during a render --------------------------------------------

#[test]
fn truncating_a_shared_cache_file_during_a_render_does_not_kill_it() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("knot.obj");
    std::fs::write(&scene, knot_obj(1200, 40)).unwrap();
    let cache = dir.path().join("shared-cache");
    let out = dir.path().join("k.png");
    let args = [
        "render",
        s(&scene),
        "--bvh-cache",
        s(&cache),
        "-r",
        "320",
        "240",
        "-s",
        "16",
        "-m",
        "2",
        "-t",
        "2",
        "-f",
        s(&out),
    ];
    let limits = Limits { address_space: Some(TWO_GIB), ..Limits::default() };
    let first = run(&["info", s(&scene), "--quality", "medium", "--bvh-cache", s(&cache)], limits);
    assert_eq!(first.code, Some(0), "{first:?}");
    // A shared cache: the directory and the file writable by everybody, as another user's
    // would be for this one.
    let file = cache_file(&cache);
    std::fs::set_permissions(&cache, std::fs::Permissions::from_mode(0o777)).unwrap();
    std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o666)).unwrap();
    let mut child = command(&args, limits).spawn().unwrap();
    let mut stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut log = String::new();
    // The cache is loaded (and the render about to start): now another user truncates it.
    loop {
        let mut line = String::new();
        if stderr.read_line(&mut line).unwrap() == 0 {
            break;
        }
        log += &line;
        if line.contains("Loaded BVH") {
            std::fs::OpenOptions::new().write(true).open(&file).unwrap().set_len(0).unwrap();
            break;
        }
    }
    stderr.read_to_string(&mut log).unwrap();
    let status = child.wait().unwrap();
    use std::os::unix::process::ExitStatusExt;
    assert_eq!(status.signal(), None, "killed by signal {:?} (7 is SIGBUS):\n{log}", status.signal());
    assert!(status.success(), "{log}");
    assert!(log.contains("Loaded BVH"), "{log}");
    assert!(log.contains("can be changed by other users") && log.contains("writable by all users"), "{log}");
    assert!(out.exists());
}

#[test]
fn cache_files_are_0644_in_a_0755_directory_whatever_the_umask() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("knot.obj");
    std::fs::write(&scene, knot_obj(40, 8)).unwrap();
    let cache = dir.path().join("a/b/cache");
    let args = ["info", s(&scene), "--quality", "fast", "--bvh-cache", s(&cache)];
    let r = run(&args, Limits { umask: Some(0), ..Limits::default() });
    assert_eq!(r.code, Some(0), "{r:?}");
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode(&cache), 0o755);
    assert_eq!(mode(&cache_file(&cache)), 0o644);
    // A private cache is mapped without a word; one others can write is reported.
    let r = run(&args, Limits::default());
    assert!(r.code == Some(0) && !r.stderr.contains("warning: BVH cache"), "{r:?}");
    std::fs::set_permissions(&cache, std::fs::Permissions::from_mode(0o777)).unwrap();
    let r = run(&args, Limits::default());
    assert_eq!(r.code, Some(0), "{r:?}");
    assert!(r.stderr.contains("writable by all users (mode 777)"), "{}", r.stderr);
}
