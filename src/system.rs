//! The system's resources, probed, and allocation helpers: the memory this process may still
//! allocate ([`available`], and [`check_fits`], which refuses a size whose buffers cannot fit
//! up front instead of aborting minutes later), what it used at its peak
//! ([`peak_resident_bytes`], [`PeakResident`]), the size of the CPU's last-level cache, and
//! vectors whose pages the kernel backs with huge pages. What a render, a bench or a scene
//! needs is estimated where they are defined ([`crate::render::render_bytes`],
//! [`crate::raysets::BENCH_BYTES_PER_PIXEL`], [`crate::scene::footprint`]).

/// An image (or ray set) whose buffers cannot fit in the memory this process may allocate:
/// what it needs, what there is, and the largest size of the same shape that fits. Its
/// message is the one every front end gives, after the size ("-r 32768 32768: …" in the
/// CLI, "width, height: 32768 x 32768: …" in Python).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "needs about {} for the buffers that grow with the image ({per_pixel} bytes per pixel), but only {} can be \
     allocated ({})",
    human(*.needed),
    human(.available.bytes),
    .available.source
)]
pub struct Shortfall {
    /// Bytes the buffers need.
    pub needed: u64,
    /// Bytes per pixel (or ray) among them.
    pub per_pixel: u64,
    /// What may be allocated.
    pub available: Available,
    /// The largest width and height of the same shape that fit.
    pub fits: (usize, usize),
}

/// Refuses an image (or ray set) of `width × height` whose buffers, `needed` bytes in all
/// (`per_pixel` per pixel), cannot fit in [`available`] memory; fine where that is unknown.
pub fn check_fits(width: usize, height: usize, needed: u64, per_pixel: u64) -> Result<(), Shortfall> {
    let Some(available) = available() else { return Ok(()) };
    if needed <= available.bytes {
        return Ok(());
    }
    let scale = (available.bytes as f64 / needed as f64).sqrt();
    let fits = (((width as f64 * scale) as usize).max(1), ((height as f64 * scale) as usize).max(1));
    Err(Shortfall { needed, per_pixel, available, fits })
}

/// How much memory this process may still allocate, and what says so.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Available {
    /// Bytes.
    pub bytes: u64,
    /// Which limit this is: `"MemAvailable in /proc/meminfo"`, `"the cgroup memory limit"`,
    /// `"the address-space limit (ulimit -v)"` or `"the data-segment limit (ulimit -d)"`.
    pub source: &'static str,
}

/// The smallest of the memory the system has available, the cgroup's limit less its usage,
/// and the process's address-space and data limits less what it uses; `None` where none of
/// these can be read (not Linux).
pub fn available() -> Option<Available> {
    let mut best: Option<Available> = None;
    let mut offer = |bytes: Option<u64>, source: &'static str| {
        if let Some(bytes) = bytes
            && best.as_ref().is_none_or(|b| bytes < b.bytes)
        {
            best = Some(Available { bytes, source });
        }
    };
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok();
    offer(meminfo.as_deref().and_then(|m| kib_field(m, "MemAvailable:")), "MemAvailable in /proc/meminfo");
    offer(cgroup_room(), "the cgroup memory limit");
    let status = std::fs::read_to_string("/proc/self/status").ok();
    let used = |field| status.as_deref().and_then(|s| kib_field(s, field)).unwrap_or(0);
    #[cfg(unix)]
    {
        // The soft limit of a resource, when it is finite.
        let rlimit = |resource| {
            let mut lim = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
            // SAFETY: getrlimit writes the struct passed by pointer, which lives on this frame.
            let ok = unsafe { libc::getrlimit(resource, &mut lim) } == 0;
            #[allow(clippy::unnecessary_cast)] // `rlim_t` is `u64` on Linux, not everywhere.
            (ok && lim.rlim_cur != libc::RLIM_INFINITY).then_some(lim.rlim_cur as u64)
        };
        let (address_space, data) = (rlimit(libc::RLIMIT_AS), rlimit(libc::RLIMIT_DATA));
        offer(address_space.map(|l| l.saturating_sub(used("VmSize:"))), "the address-space limit (ulimit -v)");
        offer(data.map(|l| l.saturating_sub(used("VmData:"))), "the data-segment limit (ulimit -d)");
    }
    #[cfg(not(unix))]
    let _ = used;
    best
}

/// Asks the kernel to back `v`'s allocation (its whole capacity) with transparent huge pages,
/// as Embree does with its build memory: a hint, so errors are ignored, and only the 2 MiB
/// aligned part of buffers of 4 MiB or more is advised. Call it before the first write: the
/// page faults of fresh memory then come 2 MiB at a time instead of 4 KiB. A no-op off Linux.
/// (Arrays that outlive the build are [`crate::bvh::BvhArray`]s, whose `zeroed` maps and
/// advises their own memory.)
//
// It made commits faster (PERFORMANCE.md, "Builder").
pub(crate) fn advise_huge_pages<T>(v: &Vec<T>) {
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let bytes = v.capacity().saturating_mul(std::mem::size_of::<T>());
        if bytes < 2 * HUGE {
            return;
        }
        let start = (v.as_ptr() as usize).next_multiple_of(HUGE);
        let end = (v.as_ptr() as usize + bytes) / HUGE * HUGE;
        if end > start {
            // SAFETY: [start, end) lies inside `v`'s allocation, which `v` owns for the
            // duration of the call; MADV_HUGEPAGE changes how the kernel backs those pages,
            // never their contents or their mapping.
            unsafe { libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE) };
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = v;
}

/// An empty `Vec` with room for `capacity` elements, advised as [`advise_huge_pages`] says.
pub(crate) fn huge_page_vec<T>(capacity: usize) -> Vec<T> {
    let v = Vec::with_capacity(capacity);
    advise_huge_pages(&v);
    v
}

/// Bytes of the CPU's last-level cache (the largest data or unified cache that
/// `/sys/devices/system/cpu/cpu0/cache` lists), read once per process; 32 MiB where it
/// cannot be read (not Linux, or no such directory). The streams interleave single rays in
/// trees larger than this ([`crate::bvh::Bvh8::interleaves`]).
pub fn last_level_cache_bytes() -> u64 {
    static BYTES: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
    *BYTES.get_or_init(|| read_last_level_cache().unwrap_or(32 << 20))
}

fn read_last_level_cache() -> Option<u64> {
    let dir = std::fs::read_dir("/sys/devices/system/cpu/cpu0/cache").ok()?;
    let mut best: Option<(u32, u64)> = None;
    for entry in dir.flatten() {
        let read = |name: &str| std::fs::read_to_string(entry.path().join(name)).ok();
        let (Some(level), Some(kind), Some(size)) = (read("level"), read("type"), read("size")) else { continue };
        if kind.trim() == "Instruction" {
            continue;
        }
        let (Ok(level), Some(bytes)) = (level.trim().parse::<u32>(), parse_cache_size(size.trim())) else { continue };
        if best.is_none_or(|(l, _)| level > l) {
            best = Some((level, bytes));
        }
    }
    best.map(|(_, bytes)| bytes)
}

/// A cache size as sysfs writes it: `32768K`, `1M` or a number of bytes.
fn parse_cache_size(s: &str) -> Option<u64> {
    let (digits, unit) = match s.as_bytes().last()? {
        b'K' => (&s[..s.len() - 1], 1 << 10),
        b'M' => (&s[..s.len() - 1], 1 << 20),
        b'G' => (&s[..s.len() - 1], 1 << 30),
        _ => (s, 1),
    };
    digits.parse::<u64>().ok()?.checked_mul(unit)
}

/// Peak resident set size of this process (`VmHWM` of `/proc/self/status`). Linux only:
/// `None` elsewhere or when the file cannot be read.
pub fn peak_resident_bytes() -> Option<u64> {
    proc_status_bytes("VmHWM:")
}

/// Measures how much a step raises the process's peak resident memory: resets the kernel's
/// high-water mark (`/proc/self/clear_refs`, Linux ≥ 4.0) and remembers the resident size;
/// [`PeakResident::added`] then gives the new high-water mark minus that size, i.e. the peak
/// memory of the step, temporaries included. `None` where Linux's files are missing.
pub struct PeakResident {
    resident_before: Option<u64>,
}

impl PeakResident {
    /// Starts a measurement.
    pub fn start() -> Self {
        let reset = std::fs::write("/proc/self/clear_refs", "5").is_ok();
        Self { resident_before: if reset { proc_status_bytes("VmRSS:") } else { None } }
    }

    /// Peak bytes added since [`PeakResident::start`].
    pub fn added(&self) -> Option<u64> {
        Some(peak_resident_bytes()?.saturating_sub(self.resident_before?))
    }
}

/// A `kB` field of `/proc/self/status`, in bytes.
fn proc_status_bytes(field: &str) -> Option<u64> {
    kib_field(&std::fs::read_to_string("/proc/self/status").ok()?, field)
}

/// A `NAME: N kB` field of a `/proc` file, in bytes.
fn kib_field(text: &str, name: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    let kib: u64 = line[name.len()..].split_whitespace().next()?.parse().ok()?;
    Some(kib.saturating_mul(1024))
}

/// What the memory cgroup of this process still allows (v2 `memory.max` less
/// `memory.current`, or v1 `memory.limit_in_bytes` less `memory.usage_in_bytes`).
fn cgroup_room() -> Option<u64> {
    let read = |p: &str| std::fs::read_to_string(p).ok()?.trim().parse::<u64>().ok();
    let groups = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let v2 = groups.lines().find_map(|l| l.strip_prefix("0::"));
    let v1 = groups.lines().find_map(|l| {
        let mut f = l.splitn(3, ':');
        let (_, controllers, path) = (f.next()?, f.next()?, f.next()?);
        controllers.split(',').any(|c| c == "memory").then_some(path)
    });
    let candidates = [
        v2.map(|p| (format!("/sys/fs/cgroup{p}/memory.max"), format!("/sys/fs/cgroup{p}/memory.current"))),
        v1.map(|p| {
            (
                format!("/sys/fs/cgroup/memory{p}/memory.limit_in_bytes"),
                format!("/sys/fs/cgroup/memory{p}/memory.usage_in_bytes"),
            )
        }),
        Some((
            "/sys/fs/cgroup/memory/memory.limit_in_bytes".into(),
            "/sys/fs/cgroup/memory/memory.usage_in_bytes".into(),
        )),
    ];
    // "max" (v2) does not parse; v1 writes a number near 2^63 for "no limit".
    candidates.into_iter().flatten().find_map(|(limit, usage)| {
        let limit = read(&limit).filter(|&l| l < 1 << 60)?;
        Some(limit.saturating_sub(read(&usage).unwrap_or(0)))
    })
}

/// Formats a byte count for messages: "75.2 GB".
pub fn human(bytes: u64) -> String {
    let b = bytes as f64;
    match bytes {
        0..1_000_000 => format!("{:.1} kB", b / 1e3),
        1_000_000..1_000_000_000 => format!("{:.1} MB", b / 1e6),
        _ => format!("{:.1} GB", b / 1e9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_fields_parse() {
        assert_eq!(kib_field("MemTotal: 10 kB\nMemAvailable:    7 kB\n", "MemAvailable:"), Some(7 * 1024));
        assert_eq!(kib_field("x", "MemAvailable:"), None);
        if cfg!(target_os = "linux") {
            assert!(available().is_some_and(|a| a.bytes > 0));
        }
    }

    #[test]
    fn peak_memory_is_read_on_linux() {
        let peak = peak_resident_bytes();
        if cfg!(target_os = "linux") {
            // At least the pages this vector touches.
            let v = vec![1u8; 8 << 20];
            assert!(peak_resident_bytes().unwrap() >= v.len() as u64 && v.iter().all(|&b| b == 1));
        } else {
            assert_eq!(peak, None);
        }
    }
}

/// Most threads a thread count may ask for, per logical CPU: more only costs thread starts
/// and gains nothing (a huge count stalls a render for seconds before its first pixel).
pub const THREADS_PER_CPU: usize = 8;

/// A thread count above [`max_threads`] (or zero).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("expected 1 to {max} threads ({THREADS_PER_CPU} per logical CPU; this machine has {cpus})")]
pub struct ThreadsError {
    /// The count asked for.
    pub requested: usize,
    /// [`max_threads`].
    pub max: usize,
    /// Logical CPUs this process may run on.
    pub cpus: usize,
}

/// The most threads [`check_threads`] allows: [`THREADS_PER_CPU`] per logical CPU this
/// process may run on.
pub fn max_threads() -> usize {
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    cpus.saturating_mul(THREADS_PER_CPU)
}

/// `threads` if it is between 1 and [`max_threads`].
pub fn check_threads(threads: usize) -> Result<usize, ThreadsError> {
    let max = max_threads();
    if threads == 0 || threads > max {
        return Err(ThreadsError { requested: threads, max, cpus: max / THREADS_PER_CPU });
    }
    Ok(threads)
}
