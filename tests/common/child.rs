//! Running the `raypack` binary as a hostile user would: under a time limit (a hang fails the
//! test instead of hanging it) and an address-space limit (an endless read or allocation
//! fails fast instead of exhausting the machine), with its stderr, stdout and peak memory.

use std::io::Read;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// What a child process did.
#[derive(Debug)]
pub struct Run {
    /// Exit code, `None` when a signal ended it.
    pub code: Option<i32>,
    /// The signal that ended it.
    pub signal: Option<i32>,
    pub stderr: String,
    pub stdout: String,
    /// Killed by the test after the time limit.
    pub timed_out: bool,
    /// Peak resident memory (VmHWM) seen while it ran, in bytes (polled every 5 ms).
    pub peak_bytes: u64,
}

/// Time after which a child counts as hung.
pub const TIMEOUT: Duration = Duration::from_secs(60);
/// The address-space limit of the children: far above what any command here needs.
pub const TWO_GIB: u64 = 2 << 30;

/// The binary under test: this build's, or the one `RAYPACK_TEST_BIN` names (to show that a
/// test fails on a build from before a fix).
pub fn binary() -> std::ffi::OsString {
    std::env::var_os("RAYPACK_TEST_BIN").unwrap_or_else(|| env!("CARGO_BIN_EXE_raypack").into())
}

/// Limits a child runs under.
#[derive(Clone, Copy, Debug, Default)]
pub struct Limits {
    /// `ulimit -v`, in bytes.
    pub address_space: Option<u64>,
    /// The umask it starts with.
    pub umask: Option<u32>,
}

/// `raypack ARGS` with its environment plus `env`, under `ulimit -v TWO_GIB`.
pub fn command(args: &[&str], env: &[(&str, &std::ffi::OsStr)]) -> Command {
    command_with(args, env, Limits { address_space: Some(TWO_GIB), umask: None })
}

/// `raypack ARGS` with its environment plus `env`, under `limits`; stdout and stderr piped.
pub fn command_with(args: &[&str], env: &[(&str, &std::ffi::OsStr)], limits: Limits) -> Command {
    use std::os::unix::process::CommandExt;
    let mut c = Command::new(binary());
    c.args(args).stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
    for (k, v) in env {
        c.env(k, v);
    }
    // SAFETY: the closure runs between fork and exec and only calls setrlimit and umask,
    // which are async-signal-safe.
    unsafe {
        c.pre_exec(move || {
            if let Some(bytes) = limits.address_space {
                let lim = libc::rlimit { rlim_cur: bytes as libc::rlim_t, rlim_max: bytes as libc::rlim_t };
                if libc::setrlimit(libc::RLIMIT_AS, &lim) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
            }
            if let Some(mask) = limits.umask {
                libc::umask(mask as libc::mode_t);
            }
            Ok(())
        });
    }
    c
}

/// The peak resident memory of a running process, in bytes.
fn vm_hwm(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse::<u64>().ok().map(|kib| kib * 1024)
}

/// Waits for `child` (at most `timeout`, then kills it), collecting its output (what was
/// piped) and peak memory.
pub fn finish(mut child: Child, timeout: Duration) -> Run {
    use std::os::unix::process::ExitStatusExt;
    let reader = |mut r: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut s = Vec::new();
            let _ = r.read_to_end(&mut s);
            String::from_utf8_lossy(&s).into_owned()
        })
    };
    let err = reader(child.stderr.take().map_or_else(|| Box::new(std::io::empty()) as _, |r| Box::new(r) as _));
    let out = reader(child.stdout.take().map_or_else(|| Box::new(std::io::empty()) as _, |r| Box::new(r) as _));
    let start = Instant::now();
    let mut peak = 0;
    let (status, timed_out) = loop {
        if let Some(b) = vm_hwm(child.id()) {
            peak = peak.max(b);
        }
        if let Some(s) = child.try_wait().expect("wait") {
            break (s, false);
        }
        if start.elapsed() > timeout {
            let _ = child.kill();
            break (child.wait().expect("wait"), true);
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    Run {
        code: status.code(),
        signal: status.signal(),
        stderr: err.join().unwrap(),
        stdout: out.join().unwrap(),
        timed_out,
        peak_bytes: peak,
    }
}

/// Runs `raypack ARGS` to the end (or the time limit).
pub fn run(args: &[&str]) -> Run {
    finish(command(args, &[]).spawn().expect("runs"), TIMEOUT)
}

/// Runs `args` and expects exit code `code` and `what` in stderr: in time, by no signal.
pub fn expect(args: &[&str], code: i32, what: &str) -> Run {
    let r = run(args);
    assert!(!r.timed_out, "{args:?} hung: {r:?}");
    assert_eq!(r.signal, None, "{args:?}: {r:?}");
    assert_eq!(r.code, Some(code), "{args:?}: {r:?}");
    assert!(r.stderr.contains(what), "{args:?}: expected {what:?} in {}", r.stderr);
    r
}

pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

pub fn mkfifo(path: &Path) {
    let c = std::ffi::CString::new(s(path)).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0, "mkfifo {}", path.display());
}

pub fn is_fifo(p: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    std::fs::symlink_metadata(p).is_ok_and(|m| m.file_type().is_fifo())
}
