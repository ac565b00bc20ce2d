//! Intel Embree 3 or 4 behind a safe wrapper, for cross-checking raypack's hits and for
//! side-by-side benchmarks (cargo feature `embree`; `build.rs` says where it looks for
//! Embree: `RAYPACK_EMBREE_DIR`, pkg-config, the system headers). [`EMBREE_FOUND`] names the
//! one this build links; [`EmbreeScene::version`] the library loaded at run time.
//!
//! The C side is `src/embree/shim.c`: one Embree device and scene per [`EmbreeScene`],
//! holding one triangle mesh whose primitive ids are raypack's triangle ids. Rays and hits
//! cross the boundary as raypack's own [`Ray`] and [`Hit`] arrays (their layouts are asserted
//! below); the packet calls gather consecutive rays into Embree's 8- or 16-wide SoA packets,
//! masking the lanes past the end of the slice, so every call has the same contract as
//! raypack's kernels: `&[Ray]` in, `&mut [Hit]` (or `&mut [bool]`) out.

use crate::math::Vec3;
use crate::ray::{Hit, Ray};

/// The Embree this build was compiled against and how `build.rs` found it, e.g.
/// `Embree 3 (/usr/include/embree3)` or `Embree 4 (pkg-config embree4 4.4.0)`.
pub const EMBREE_FOUND: &str = env!("RAYPACK_EMBREE_FOUND");
use crate::scene::Scene;
use crate::simd::Isa;
use std::ffi::{CStr, c_char, c_int};
use std::mem::{align_of, offset_of, size_of};
use std::ptr::NonNull;
use std::time::{Duration, Instant};

/// The shim's `RpRay`: raypack's [`Ray`] as C sees it.
#[repr(C)]
struct RpRay {
    org: [f32; 3],
    dir: [f32; 3],
    tnear: f32,
    tfar: f32,
}

/// The shim's `RpHit`: raypack's [`Hit`] as C sees it.
#[repr(C)]
struct RpHit {
    t: f32,
    u: f32,
    v: f32,
    prim: u32,
}

// `Ray` and `Hit` are not `repr(C)`, so the rays and hits slices are passed to C as
// `RpRay` / `RpHit` arrays only because these checks prove the compiler laid them out the
// same way (glam's `Vec3` is `repr(C)`, three `f32`). Should a layout change, the build
// fails here instead of the shim reading garbage.
const _: () = {
    assert!(size_of::<Vec3>() == 12);
    assert!(size_of::<Ray>() == size_of::<RpRay>() && align_of::<Ray>() >= align_of::<RpRay>());
    assert!(offset_of!(Ray, origin) == offset_of!(RpRay, org) && offset_of!(Ray, dir) == offset_of!(RpRay, dir));
    assert!(offset_of!(Ray, tnear) == offset_of!(RpRay, tnear) && offset_of!(Ray, tfar) == offset_of!(RpRay, tfar));
    assert!(size_of::<Hit>() == size_of::<RpHit>() && align_of::<Hit>() >= align_of::<RpHit>());
    assert!(offset_of!(Hit, t) == offset_of!(RpHit, t) && offset_of!(Hit, u) == offset_of!(RpHit, u));
    assert!(offset_of!(Hit, v) == offset_of!(RpHit, v) && offset_of!(Hit, prim) == offset_of!(RpHit, prim));
    assert!(Hit::NONE == u32::MAX && size_of::<bool>() == 1);
};

#[repr(C)]
struct RpEmbree {
    _opaque: [u8; 0],
}

type IntersectFn = unsafe extern "C" fn(*const RpEmbree, *const RpRay, *mut RpHit, usize, c_int);
type OccludedFn = unsafe extern "C" fn(*const RpEmbree, *const RpRay, *mut bool, usize, c_int);

unsafe extern "C" {
    fn rp_embree_new(
        positions: *const f32,
        num_vertices: usize,
        indices: *const u32,
        num_triangles: usize,
        quality: c_int,
        flags: c_int,
        threads: c_int,
        max_isa: *const c_char,
        error: *mut *const c_char,
    ) -> *mut RpEmbree;
    fn rp_embree_commit(e: *mut RpEmbree) -> c_int;
    fn rp_embree_bvh_bytes(e: *const RpEmbree) -> i64;
    fn rp_embree_error(e: *mut RpEmbree) -> *const c_char;
    fn rp_embree_version(e: *const RpEmbree) -> c_int;
    fn rp_embree_native_packet(e: *const RpEmbree, width: c_int) -> c_int;
    fn rp_embree_intersect1(e: *const RpEmbree, rays: *const RpRay, hits: *mut RpHit, n: usize, coherent: c_int);
    fn rp_embree_intersect8(e: *const RpEmbree, rays: *const RpRay, hits: *mut RpHit, n: usize, coherent: c_int);
    fn rp_embree_intersect16(e: *const RpEmbree, rays: *const RpRay, hits: *mut RpHit, n: usize, coherent: c_int);
    fn rp_embree_occluded1(e: *const RpEmbree, rays: *const RpRay, out: *mut bool, n: usize, coherent: c_int);
    fn rp_embree_occluded8(e: *const RpEmbree, rays: *const RpRay, out: *mut bool, n: usize, coherent: c_int);
    fn rp_embree_occluded16(e: *const RpEmbree, rays: *const RpRay, out: *mut bool, n: usize, coherent: c_int);
    fn rp_embree_release(e: *mut RpEmbree);
}

/// Embree's BVH build quality (`RTC_BUILD_QUALITY_*`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EmbreeQuality {
    /// Morton-code build, fastest to build.
    Low,
    /// Binned SAH, Embree's default.
    Medium,
    /// Binned SAH with spatial splits.
    High,
}

impl EmbreeQuality {
    /// Lower-case name (`low`, `medium`, `high`).
    pub fn name(self) -> &'static str {
        match self {
            EmbreeQuality::Low => "low",
            EmbreeQuality::Medium => "medium",
            EmbreeQuality::High => "high",
        }
    }
}

/// How an [`EmbreeScene`] is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EmbreeOptions {
    /// Build quality.
    pub quality: EmbreeQuality,
    /// `RTC_SCENE_FLAG_ROBUST`: conservative traversal and a watertight triangle test
    /// (slower). Off by default, as in Embree.
    pub robust: bool,
    /// `RTC_SCENE_FLAG_COMPACT`: Embree's smallest tree (its compressed leaf layout), for
    /// comparing memory with raypack's compact build. Off by default, as in Embree.
    pub compact: bool,
    /// Worker threads of the Embree device, which builds the BVH (`threads=N` in the device
    /// configuration); 0 (the default) uses every hardware thread. Queries run on the
    /// caller's threads whatever this is.
    pub threads: usize,
    /// The highest ISA Embree may use (`max_isa=` in the device configuration), so that a
    /// comparison at a lower raypack [`Isa`] restricts both tracers; `None` lets Embree pick
    /// the CPU's best.
    pub max_isa: Option<Isa>,
}

impl Default for EmbreeOptions {
    fn default() -> Self {
        Self { quality: EmbreeQuality::Medium, robust: false, compact: false, threads: 0, max_isa: None }
    }
}

/// Packet width of an Embree query: `rtc*1`, `rtc*8` or `rtc*16`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EmbreeWidth {
    /// One ray per call.
    W1,
    /// 8-ray packets.
    W8,
    /// 16-ray packets.
    W16,
}

impl EmbreeWidth {
    /// Rays per call.
    pub fn lanes(self) -> usize {
        match self {
            EmbreeWidth::W1 => 1,
            EmbreeWidth::W8 => 8,
            EmbreeWidth::W16 => 16,
        }
    }
}

/// Why an [`EmbreeScene`] could not be made.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum EmbreeError {
    /// Embree reported an error creating the device, the scene or its buffers.
    #[error("{0}")]
    Device(String),
    /// Embree reported an error building the BVH.
    #[error("building the Embree BVH failed: {0}")]
    Commit(String),
    /// The scene holds spheres, which this wrapper does not pass to Embree.
    #[error("the Embree comparison supports triangle meshes only, but the scene has {0} spheres")]
    Spheres(usize),
}

/// An Embree scene holding one triangle mesh, committed and ready for queries.
pub struct EmbreeScene {
    ptr: NonNull<RpEmbree>,
    triangles: usize,
    build_time: Duration,
    bvh_bytes: u64,
    options: EmbreeOptions,
}

// SAFETY: after `rtcCommitScene` an Embree scene is immutable and its query functions
// (`rtcIntersect*`, `rtcOccluded*`) may be called from any number of threads at once; the
// shim's query functions only read the `RpEmbree` struct. It is released only by `Drop`.
unsafe impl Send for EmbreeScene {}
// SAFETY: as above: `&EmbreeScene` only allows the thread-safe query functions.
unsafe impl Sync for EmbreeScene {}

impl std::fmt::Debug for EmbreeScene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EmbreeScene")
            .field("triangles", &self.triangles)
            .field("build_time", &self.build_time)
            .field("bvh_bytes", &self.bvh_bytes)
            .field("options", &self.options)
            .finish()
    }
}

impl Drop for EmbreeScene {
    fn drop(&mut self) {
        // SAFETY: `ptr` came from `rp_embree_new`, is released exactly once, here.
        unsafe { rp_embree_release(self.ptr.as_ptr()) }
    }
}

fn c_message(p: *const c_char, fallback: &str) -> String {
    if p.is_null() {
        fallback.to_string()
    } else {
        // SAFETY: the shim only returns pointers to static NUL-terminated strings.
        unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
    }
}

impl EmbreeScene {
    /// Passes the triangles of a committed raypack scene to Embree and builds its BVH.
    /// Uses the committed triangles (after raypack dropped degenerate ones), so Embree's
    /// primitive ids are raypack's. Scenes with spheres are refused.
    pub fn new(scene: &Scene, quality: EmbreeQuality) -> Result<Self, EmbreeError> {
        Self::with_options(scene, EmbreeOptions { quality, ..EmbreeOptions::default() })
    }

    /// [`EmbreeScene::new`] with all options.
    pub fn with_options(scene: &Scene, options: EmbreeOptions) -> Result<Self, EmbreeError> {
        if scene.num_spheres() > 0 {
            return Err(EmbreeError::Spheres(scene.num_spheres()));
        }
        Self::from_mesh(&scene.triangles.positions, &scene.triangles.indices, options)
    }

    /// Builds an Embree scene from positions and index triples (each index must be
    /// `< positions.len()`; Embree itself skips triangles with non-finite vertices).
    pub fn from_mesh(positions: &[Vec3], indices: &[[u32; 3]], options: EmbreeOptions) -> Result<Self, EmbreeError> {
        let n = positions.len() as u64;
        if let Some(t) = indices.iter().position(|t| t.iter().any(|&i| i as u64 >= n)) {
            return Err(EmbreeError::Device(format!("triangle {t} refers to a vertex beyond the {n} given")));
        }
        let quality = match options.quality {
            EmbreeQuality::Low => 0,
            EmbreeQuality::Medium => 1,
            EmbreeQuality::High => 2,
        };
        // The shim's `RpSceneFlags` bits.
        let flags = c_int::from(options.robust) | c_int::from(options.compact) << 1;
        let max_isa: &CStr = match options.max_isa {
            None => c"",
            Some(Isa::Baseline) => c"sse2",
            Some(Isa::Avx2) => c"avx2",
            Some(Isa::Avx512) => c"avx512",
        };
        let mut error: *const c_char = std::ptr::null();
        // SAFETY: `positions` is `len` contiguous `Vec3`s, i.e. `3 len` f32 (size asserted
        // above); `indices` is `len` contiguous `[u32; 3]`; the shim copies both before
        // returning, reads `max_isa` as a NUL-terminated string and writes `error` only through
        // the valid pointer we pass.
        let raw = unsafe {
            rp_embree_new(
                positions.as_ptr().cast::<f32>(),
                positions.len(),
                indices.as_ptr().cast::<u32>(),
                indices.len(),
                quality,
                flags,
                options.threads.min(c_int::MAX as usize) as c_int,
                max_isa.as_ptr(),
                &mut error,
            )
        };
        let ptr = NonNull::new(raw).ok_or_else(|| EmbreeError::Device(c_message(error, "Embree: unknown error")))?;
        let mut scene =
            EmbreeScene { ptr, triangles: indices.len(), build_time: Duration::ZERO, bvh_bytes: 0, options };
        let t = Instant::now();
        // SAFETY: `ptr` is a live scene not yet shared with any other thread.
        let code = unsafe { rp_embree_commit(scene.ptr.as_ptr()) };
        scene.build_time = t.elapsed();
        if code != 0 {
            // SAFETY: as above.
            let msg = unsafe { rp_embree_error(scene.ptr.as_ptr()) };
            return Err(EmbreeError::Commit(c_message(msg, &format!("Embree error code {code}"))));
        }
        // SAFETY: `ptr` is live; the call only reads two integers.
        scene.bvh_bytes = unsafe { rp_embree_bvh_bytes(scene.ptr.as_ptr()) }.max(0) as u64;
        Ok(scene)
    }

    /// Number of triangles given to Embree.
    pub fn num_triangles(&self) -> usize {
        self.triangles
    }

    /// Wall-clock time of `rtcCommitScene` (the BVH build, on Embree's own threads).
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Bytes Embree allocated while building and still holds: the BVH with its triangle
    /// leaves, measured with `rtcSetDeviceMemoryMonitorFunction`.
    pub fn bvh_bytes(&self) -> u64 {
        self.bvh_bytes
    }

    /// The options the scene was built with.
    pub fn options(&self) -> EmbreeOptions {
        self.options
    }

    /// Embree's version as `major.minor.patch`.
    pub fn version(&self) -> String {
        // SAFETY: `ptr` is live; the call only reads a device property.
        let v = unsafe { rp_embree_version(self.ptr.as_ptr()) };
        format!("{}.{}.{}", v / 10000, v / 100 % 100, v % 100)
    }

    /// True when this Embree library has native (not emulated) packets of `width` lanes.
    pub fn native_packets(&self, width: EmbreeWidth) -> bool {
        // SAFETY: `ptr` is live; the call only reads a device property.
        unsafe { rp_embree_native_packet(self.ptr.as_ptr(), width.lanes() as c_int) != 0 }
    }

    /// Closest hits of `rays` into `hits` with `rtcIntersect{1,8,16}`, consecutive rays
    /// forming each packet. `coherent` sets `RTC_INTERSECT_CONTEXT_FLAG_COHERENT`.
    ///
    /// # Panics
    /// When `hits` is shorter than `rays`.
    pub fn intersect(&self, width: EmbreeWidth, coherent: bool, rays: &[Ray], hits: &mut [Hit]) {
        assert!(hits.len() >= rays.len(), "{} hits for {} rays", hits.len(), rays.len());
        let f: IntersectFn = match width {
            EmbreeWidth::W1 => rp_embree_intersect1,
            EmbreeWidth::W8 => rp_embree_intersect8,
            EmbreeWidth::W16 => rp_embree_intersect16,
        };
        // SAFETY: the scene is committed and queries are thread-safe; `rays` holds
        // `rays.len()` readable `Ray`s and `hits` at least as many writable `Hit`s, whose
        // layouts match the shim's `RpRay` / `RpHit` (asserted above); the shim reads and
        // writes exactly `n` elements and keeps no pointer after returning.
        unsafe {
            f(
                self.ptr.as_ptr(),
                rays.as_ptr().cast::<RpRay>(),
                hits.as_mut_ptr().cast::<RpHit>(),
                rays.len(),
                coherent as c_int,
            )
        }
    }

    /// Occlusion of `rays` over `[tnear, tfar]` into `out` with `rtcOccluded{1,8,16}` (Embree
    /// documents no guarantee for hits at exactly `tnear`: its robust mode counts them, the
    /// default mode of Embree 3 does not).
    ///
    /// # Panics
    /// When `out` is shorter than `rays`.
    pub fn occluded(&self, width: EmbreeWidth, coherent: bool, rays: &[Ray], out: &mut [bool]) {
        assert!(out.len() >= rays.len(), "{} results for {} rays", out.len(), rays.len());
        let f: OccludedFn = match width {
            EmbreeWidth::W1 => rp_embree_occluded1,
            EmbreeWidth::W8 => rp_embree_occluded8,
            EmbreeWidth::W16 => rp_embree_occluded16,
        };
        // SAFETY: as in `intersect`; the shim writes only the bytes 0 and 1, which are valid
        // `bool`s (1 byte, asserted above).
        unsafe { f(self.ptr.as_ptr(), rays.as_ptr().cast::<RpRay>(), out.as_mut_ptr(), rays.len(), coherent as c_int) }
    }

    /// `rtcIntersect1` over `rays`.
    pub fn intersect1(&self, rays: &[Ray], hits: &mut [Hit]) {
        self.intersect(EmbreeWidth::W1, false, rays, hits)
    }

    /// `rtcIntersect8` over consecutive groups of 8 rays.
    pub fn intersect8(&self, rays: &[Ray], hits: &mut [Hit]) {
        self.intersect(EmbreeWidth::W8, false, rays, hits)
    }

    /// `rtcIntersect16` over consecutive groups of 16 rays.
    pub fn intersect16(&self, rays: &[Ray], hits: &mut [Hit]) {
        self.intersect(EmbreeWidth::W16, false, rays, hits)
    }

    /// `rtcOccluded1` over `rays`.
    pub fn occluded1(&self, rays: &[Ray], out: &mut [bool]) {
        self.occluded(EmbreeWidth::W1, false, rays, out)
    }

    /// `rtcOccluded8` over consecutive groups of 8 rays.
    pub fn occluded8(&self, rays: &[Ray], out: &mut [bool]) {
        self.occluded(EmbreeWidth::W8, false, rays, out)
    }

    /// `rtcOccluded16` over consecutive groups of 16 rays.
    pub fn occluded16(&self, rays: &[Ray], out: &mut [bool]) {
        self.occluded(EmbreeWidth::W16, false, rays, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        (vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y], vec![[0, 1, 2], [0, 2, 3]])
    }

    /// Embree at every ISA tier this process may use (its `max_isa`): its kernels round
    /// differently per ISA (AVX2's `t` of a hit at 2 is 1.9999999), so tests allow a few ulps.
    fn per_isa() -> impl Iterator<Item = EmbreeOptions> {
        Isa::available().map(|isa| EmbreeOptions { max_isa: Some(isa), ..EmbreeOptions::default() })
    }

    #[test]
    fn hits_and_misses_in_every_width() {
        for options in per_isa() {
            hits_and_misses_in_every_width_on(options);
        }
    }

    fn hits_and_misses_in_every_width_on(options: EmbreeOptions) {
        let (p, i) = quad();
        let e = EmbreeScene::from_mesh(&p, &i, options).unwrap();
        // 19 rays: two full 8-packets and a partial one, one full 16-packet and a partial one.
        let rays: Vec<Ray> = (0..19)
            .map(|k| {
                let x = (k % 5) as f32 * 0.22 - 0.1; // -0.1 misses, the rest hit
                Ray::new(Vec3::new(x, 0.2 + 0.03 * k as f32, 2.0), -Vec3::Z)
            })
            .collect();
        for width in [EmbreeWidth::W1, EmbreeWidth::W8, EmbreeWidth::W16] {
            for coherent in [false, true] {
                let mut hits = vec![Hit { t: -1.0, u: -1.0, v: -1.0, prim: 77 }; rays.len()];
                e.intersect(width, coherent, &rays, &mut hits);
                let mut occ = vec![false; rays.len()];
                e.occluded(width, coherent, &rays, &mut occ);
                for (k, (r, h)) in rays.iter().zip(&hits).enumerate() {
                    if r.origin.x < 0.0 {
                        assert_eq!(*h, Hit::MISS, "{width:?} ray {k}");
                        assert!(!occ[k]);
                    } else {
                        assert!((h.t - 2.0).abs() <= 8.0 * f32::EPSILON, "{options:?} {width:?} ray {k}: t {}", h.t);
                        let expect = if r.origin.x >= r.origin.y { 0 } else { 1 };
                        assert_eq!(h.prim, expect, "{width:?} ray {k} {r:?}");
                        assert!(occ[k]);
                    }
                }
            }
        }
        assert_eq!(e.num_triangles(), 2);
        assert!(e.bvh_bytes() > 0);
    }

    #[test]
    fn interval_is_open_closed_like_raypack() {
        // The hit is at t = 1 within Embree's rounding, which differs per ISA and between its
        // intersect and occluded kernels: a segment ending a few ulps past it is blocked, one
        // ending clearly before it is not.
        for options in per_isa() {
            let (p, i) = quad();
            let e = EmbreeScene::from_mesh(&p, &i, options).unwrap();
            let o = Vec3::new(0.6, 0.3, 1.0);
            let mut hit = [Hit::MISS];
            e.intersect(EmbreeWidth::W1, false, &[Ray::new(o, -Vec3::Z)], &mut hit);
            assert!((hit[0].t - 1.0).abs() <= 4.0 * f32::EPSILON, "{options:?}: t {}", hit[0].t);
            let rays =
                [Ray::segment(o, -Vec3::Z, 0.0, 1.0 + 8.0 * f32::EPSILON), Ray::segment(o, -Vec3::Z, 0.0, 0.999)];
            let mut occ = [false; 2];
            e.occluded1(&rays, &mut occ);
            assert_eq!(occ, [true, false], "{options:?}");
        }
    }

    #[test]
    fn rejects_bad_indices_and_spheres() {
        let (p, _) = quad();
        assert!(matches!(
            EmbreeScene::from_mesh(&p, &[[0, 1, 4]], EmbreeOptions::default()),
            Err(EmbreeError::Device(_))
        ));
        let mut b = crate::SceneBuilder::new();
        let m = b.add_material(crate::Material::default());
        b.add_sphere(Vec3::ZERO, 1.0, m).unwrap();
        let (scene, _) = b.commit(&crate::BuildOptions::default());
        assert_eq!(EmbreeScene::new(&scene, EmbreeQuality::High).unwrap_err(), EmbreeError::Spheres(1));
    }
}
