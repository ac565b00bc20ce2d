//! Memory a command will need, estimated before it starts, and memory the process may use:
//! a size that cannot fit is refused up front instead of aborting minutes later. Also what a
//! committed scene holds ([`store_bytes`]; the BVHs count their own, [`crate::bvh::Bvh8::bytes`]
//! and [`crate::bvh::Bvh2::bytes`]) and what the process used at its peak
//! ([`peak_resident_bytes`], [`PeakResident`]).
//!
//! The estimates count the buffers that grow with the image (or ray set) size; the scene and
//! its BVH come on top, so an estimate that barely fits may still fail.

use crate::render::{PASS_SAMPLES, RenderSettings, TILE};
use crate::scene::Scene;

/// Bytes per pixel that a render keeps until its image is written: the tile results
/// ([`crate::render::adaptive::PixelEstimate`]), the film (linear RGB), the sample counts and
/// the encoded output (8-bit RGB plus the PNG; an EXR needs twice the film), and the
/// sample-rate image with `-a`.
pub fn render_bytes_per_pixel(settings: &RenderSettings, exr: bool) -> u64 {
    let estimate = std::mem::size_of::<crate::render::adaptive::PixelEstimate>();
    let film = std::mem::size_of::<crate::math::Vec3>();
    let output = if exr { 2 * film } else { 3 + 3 };
    let rate = if settings.adaptive.is_some() { film + 3 + 3 } else { 0 };
    (estimate + film + std::mem::size_of::<u32>() + output + rate) as u64
}

/// Bytes a render of `settings` on `threads` threads needs beyond the scene: every pixel
/// ([`render_bytes_per_pixel`]) plus each thread's tile and wavefront buffers (bounded by
/// [`PASS_SAMPLES`] and the wavefront's wave size, whatever the sample count; counted for the
/// light samples of one area light per shading point).
pub fn render_bytes(settings: &RenderSettings, threads: usize, exr: bool) -> u64 {
    let pixels = settings.width as u64 * settings.height as u64;
    let paths = TILE * TILE * PASS_SAMPLES.min(settings.samples_per_pixel.max(1)) as usize;
    let tile = crate::render::wavefront::worker_bytes(paths, settings.light_samples.max(1) as usize)
        + (paths * std::mem::size_of::<u32>()) as u64;
    pixels.saturating_mul(render_bytes_per_pixel(settings, exr)).saturating_add((threads as u64).saturating_mul(tile))
}

/// Bytes per primary ray that `raypack bench` holds at once: the three ray sets (primary,
/// diffuse bounces, shadow rays), the reference hits they are made from, and the reference
/// and timed outputs.
pub const BENCH_BYTES_PER_PIXEL: u64 =
    (3 * std::mem::size_of::<crate::Ray>() + 3 * std::mem::size_of::<crate::Hit>()) as u64;

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

/// Bytes per primitive (triangle or sphere) a scene needs at its peak while it is loaded and
/// built: the parsed file's vertices and indices, the committed store and the builder's
/// temporaries. Measured with `raypack info FILE --quality medium` (the process's peak
/// resident memory over the triangles): 123 on a COLLADA file of 213 KB instanced to 5.0 M
/// triangles, 122 on the Stanford dragon's PLY (871 k); rounded up.
pub const SCENE_BYTES_PER_PRIMITIVE: u64 = 128;

/// The memory a scene may need without the user asking for more (`--max-primitives`): 512 MiB
/// (4 M primitives), or [`DEFAULT_SCENE_BYTES_PER_FILE_BYTE`] per byte of its file when that is
/// more. A file that is not instanced holds at most about one primitive per byte (an OBJ
/// face line or a PLY polygon costs a byte or more per triangle), so only COLLADA instancing
/// meets this cap: a 292 KB file that expands to 11.4 M triangles (1.3 GB) must ask.
pub const DEFAULT_SCENE_BYTES: u64 = 512 << 20;
/// See [`DEFAULT_SCENE_BYTES`]: four primitives per byte of the file.
pub const DEFAULT_SCENE_BYTES_PER_FILE_BYTE: u64 = 4 * SCENE_BYTES_PER_PRIMITIVE;

/// The most primitives a scene file of `file_bytes` bytes may make without `--max-primitives`
/// (the CLI's default cap): what [`DEFAULT_SCENE_BYTES`] allows for its size, and never more
/// than fits in the memory this process may allocate ([`available`]), as `-r` is refused
/// when its buffers cannot fit.
pub fn default_max_primitives(file_bytes: u64) -> u64 {
    let budget = DEFAULT_SCENE_BYTES.max(file_bytes.saturating_mul(DEFAULT_SCENE_BYTES_PER_FILE_BYTE));
    let budget = available().map_or(budget, |a| budget.min(a.bytes));
    budget / SCENE_BYTES_PER_PRIMITIVE
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
// On the builder's temporaries (primitive references, slots, binary nodes, leaf ids, collapse
// plans), Intel Xeon (model 167), 2 threads, `raypack bench --build-runs 7 --against embree`,
// three rounds at each of AVX-512 and AVX2, medians: the Stanford dragon's commit 0.166-0.177 s
// before, 0.156-0.175 s after (Embree MEDIUM 0.156-0.207 s in the same runs); the 2M knot
// 0.365-0.383 s before, 0.337-0.354 s after (Embree 0.335-0.346 s).
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

/// Bytes of a committed scene's geometry store: vertex positions and normals, indices,
/// per-triangle materials and spheres (materials, lights and camera excluded).
pub fn store_bytes(scene: &Scene) -> usize {
    let t = &scene.triangles;
    let s = &scene.spheres;
    std::mem::size_of_val(t.positions.as_slice())
        + std::mem::size_of_val(t.normals.as_slice())
        + std::mem::size_of_val(t.indices.as_slice())
        + std::mem::size_of_val(t.material.as_slice())
        + std::mem::size_of_val(s.center.as_slice())
        + std::mem::size_of_val(s.radius.as_slice())
        + std::mem::size_of_val(s.material.as_slice())
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
    fn render_estimate_grows_with_pixels_not_samples() {
        let small = RenderSettings { width: 16, height: 16, samples_per_pixel: 1, ..RenderSettings::default() };
        let many = RenderSettings { samples_per_pixel: u32::MAX, adaptive: Some((u32::MAX, 0.05)), ..small.clone() };
        // Two workers' wavefronts of a 16-sample pass (4096 paths each): under 1 MB apiece.
        assert!(render_bytes(&many, 2, false) < 2 << 20, "{}", render_bytes(&many, 2, false));
        let huge = RenderSettings { width: 32768, height: 32768, ..small };
        let bytes = render_bytes(&huge, 2, false);
        assert!(bytes > 60_000_000_000 && bytes < 100_000_000_000, "{}", human(bytes));
    }

    #[test]
    fn the_default_primitive_cap_grows_with_the_file_within_the_memory_available() {
        let fits = available().map_or(u64::MAX, |a| a.bytes / SCENE_BYTES_PER_PRIMITIVE);
        let floor = DEFAULT_SCENE_BYTES / SCENE_BYTES_PER_PRIMITIVE;
        assert_eq!(default_max_primitives(0), floor.min(fits));
        assert_eq!(default_max_primitives(1000), floor.min(fits));
        assert_eq!(default_max_primitives(10 << 20), (40u64 << 20).min(fits));
        assert_eq!(default_max_primitives(u64::MAX / 2), (u64::MAX / SCENE_BYTES_PER_PRIMITIVE).min(fits));
    }

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
