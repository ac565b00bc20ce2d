//! The renderer: tile-parallel image formation over a committed [`Scene`].
//!
//! Pixels are split into square tiles, one rayon task each; every worker keeps its own
//! buffers and counters (no allocation per sample; a worker's buffers sit behind a lock that
//! only it takes). A tile is rendered in passes: each pass generates a batch of camera rays
//! for the pixels still sampling and traces their paths together, one bounce at a time, every
//! kind of ray in one stream through the packet kernels ([`wavefront`]). Pixels none of whose
//! camera rays can hit the scene are found first, by cones of rays over rectangles of pixels
//! ([`crate::Scene::cone_may_hit`]), and take the value of a miss without tracing. Each sample
//! `s` of pixel `p` draws its random numbers from its own generator seeded by `(seed, p, s)`,
//! so the image is a pure function of the scene, the settings and the seed, whatever the
//! thread count; and a pixel's value does not depend on the window it is rendered in
//! ([`render_window`], [`window`]), so parts of an image rendered anywhere merge bit for bit
//! ([`merge`]).

pub mod adaptive;
pub mod bsdf;
pub mod camera;
pub mod colorbar;
pub mod film;
pub mod frame;
pub mod heatmap;
pub mod integrator;
pub mod light;
pub mod memory;
pub mod merge;
pub mod order;
pub mod part;
pub mod queue;
pub mod sampler;
pub mod sampling;
pub mod spawn;
pub mod stats;
pub mod trace;
pub mod wavefront;
pub mod window;

pub use film::{Encoding, Film, ImageError, ImageFormat};
pub use integrator::{IntegratorKind, UnknownIntegrator};
pub use memory::{render_bytes, render_bytes_per_pixel};
pub use order::RayOrder;
pub use sampler::SamplerKind;
pub use stats::{RayCounts, RayKind, RayLog};
pub use wavefront::{PhaseTimes, StreamOrder};
pub use window::{PixelBounds, WindowError};

use crate::math::Vec3;
use crate::ray::Ray;
use crate::scene::{Camera, Scene};
use adaptive::PixelEstimate;
use sampler::SamplerSource;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, TryLockError};
use std::time::{Duration, Instant};

/// Edge length of a render tile in pixels.
pub const TILE: usize = 16;

/// Everything that controls a render.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Camera rays per pixel (`-s`).
    pub samples_per_pixel: u32,
    /// Shadow rays per area light per shading point (`-l`).
    pub light_samples: u32,
    /// Maximum ray depth (`-m`).
    pub max_depth: u32,
    /// Sample the hemisphere uniformly instead of the lights (`-H`).
    pub hemisphere_sampling: bool,
    /// Adaptive sampling `(batch size, tolerance)` (`-a`).
    pub adaptive: Option<(u32, f32)>,
    /// What to compute per camera ray.
    pub integrator: IntegratorKind,
    /// What [`IntegratorKind::Heatmap`] shows (the other integrators ignore it).
    pub heatmap: heatmap::HeatmapSettings,
    /// Seed of all random numbers.
    pub seed: u64,
    /// How each path's random numbers are made ([`SamplerKind`]; the image depends on it).
    pub sampler: SamplerKind,
    /// Test every primitive instead of using the BVH (CS184's "without BVH" timing).
    pub brute_force: bool,
    /// Terminate paths by Russian roulette from the second bounce on (unbiased).
    pub russian_roulette: bool,
    /// How secondary rays are ordered before they are traced; `None`: the default order,
    /// measured fastest ([`StreamOrder`]). The image is the same whatever the order.
    pub stream_order: Option<StreamOrder>,
    /// Largest value a camera sample's radiance may have in any RGB component (pbrt-v4's
    /// film `maxcomponentvalue`): a sample above it is scaled down so that its largest
    /// component equals it. This trades bias (darker caustics) for the rare paths that would
    /// otherwise show as fireflies. `None` keeps every sample as it is (CS184, unbiased).
    pub max_sample_value: Option<f32>,
    /// Give the pixels none of whose camera rays can hit the scene (their cone of rays
    /// misses every primitive's box, [`crate::Scene::cone_may_hit`]) a miss's value without
    /// generating or tracing their rays. The image is the same, bit for bit, either way;
    /// `false` is for measuring what it saves. (Never with `brute_force`, whose point is to
    /// test every ray against every primitive.)
    pub pixel_culling: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 480,
            height: 360,
            samples_per_pixel: 1,
            light_samples: 1,
            max_depth: 1,
            hemisphere_sampling: false,
            adaptive: None,
            integrator: IntegratorKind::Global,
            heatmap: heatmap::HeatmapSettings::default(),
            seed: 0,
            sampler: SamplerKind::default(),
            brute_force: false,
            russian_roulette: true,
            stream_order: None,
            max_sample_value: None,
            pixel_culling: true,
        }
    }
}

/// What a render measured.
#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    /// Rays traced by kind.
    pub rays: RayCounts,
    /// A sparse sample of the rays traced, by kind (`RayKind as usize`), for statistics.
    pub sampled_rays: [Vec<Ray>; 3],
    /// Camera samples taken (all pixels).
    pub samples: u64,
    /// Samples whose radiance was NaN or infinite (counted as black).
    pub invalid_samples: u64,
    /// Samples scaled down to [`RenderSettings::max_sample_value`].
    pub clamped_samples: u64,
    /// Camera samples of pixels whose cone of camera rays misses the scene
    /// ([`crate::Scene::cone_may_hit`]): valued as misses without tracing their rays (and
    /// not counted among the rays traced).
    pub culled_samples: u64,
    /// Wall-clock time of the render.
    pub time: Duration,
    /// Thread time of each phase (summed over threads).
    pub phases: PhaseTimes,
}

/// The result of a render.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// The pixels of [`RenderOutput::window`] (the whole image unless [`render_window`] was
    /// given a part of it).
    pub film: Film,
    /// The pixels rendered, in the whole image of [`RenderSettings::width`] ×
    /// [`RenderSettings::height`].
    pub window: PixelBounds,
    /// Samples taken per pixel of the window, row-major (differs from the setting only with
    /// adaptive sampling).
    pub samples_per_pixel: Vec<u32>,
    /// Measurements.
    pub stats: RenderStats,
    /// What [`IntegratorKind::Heatmap`] made (its picture, or why it could not be made);
    /// `None` for the other integrators. A heatmap render's film is black, its samples one
    /// per pixel and its statistics its time only.
    pub heatmap: Option<Result<heatmap::Heatmap, heatmap::HeatmapError>>,
}

/// Samples per pixel per pass: bounds the per-tile buffers, whatever `-s` and the adaptive
/// batch size (a batch larger than this is taken in several passes).
pub const PASS_SAMPLES: u32 = 16;

/// Renders `scene` through `camera`. `progress` is called with the number of tiles done
/// each time a tile completes.
pub fn render(
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> RenderOutput {
    render_window(scene, camera, settings, &PixelBounds::full(settings.width, settings.height), progress)
}

/// Renders the pixels of `window` of the image [`render`] would make: each of them has,
/// bit for bit, the value it has in the whole image. `progress` is called with the number of
/// tiles done each time a tile completes ([`tiles_in`] tiles in all).
///
/// # Panics
/// When `window` is empty or not inside the image ([`PixelBounds::within`] checks it).
pub fn render_window(
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    window: &PixelBounds,
    progress: &(dyn Fn(u64) + Sync),
) -> RenderOutput {
    use rayon::prelude::*;
    let window = window.within(settings.width, settings.height).unwrap_or_else(|e| panic!("render_window: {e}"));
    let start = Instant::now();
    if settings.integrator == IntegratorKind::Heatmap {
        let made = heatmap::render_window(scene, camera, settings, &window);
        progress(tiles_in(&window) as u64);
        let stats = RenderStats { time: start.elapsed(), ..RenderStats::default() };
        let (film, spp) = (Film::new(window.width(), window.height()), vec![1; window.width() * window.height()]);
        return RenderOutput { film, window, samples_per_pixel: spp, stats, heatmap: Some(made) };
    }
    let tiles = tiles_of(&window);
    let done = AtomicU64::new(0);
    let integrator = integrator::Integrator::new(scene, settings);
    let camera = camera::CameraRays::new(camera);
    let order = settings.stream_order.unwrap_or_default();
    let wavefronts = Wavefronts::for_pool();
    let rendered: Vec<TileResult> = tiles
        .par_iter()
        .with_max_len(1)
        .map(|tile| {
            let r = wavefronts.with(|wf| render_tile(&integrator, &camera, settings, order, wf, tile));
            progress(done.fetch_add(1, Ordering::Relaxed) + 1);
            r
        })
        .collect();
    let (w, h) = (window.width(), window.height());
    let mut film = Film::new(w, h);
    let mut spp = vec![0u32; w * h];
    let mut log = RayLog::for_tiles(tiles.len());
    let mut stats = RenderStats::default();
    for (b, tile) in tiles.iter().zip(rendered) {
        log.merge(tile.log);
        stats.invalid_samples += tile.invalid_samples;
        stats.clamped_samples += tile.clamped_samples;
        stats.culled_samples += tile.culled_samples;
        stats.phases += tile.phases;
        let tw = b.width();
        for (i, est) in tile.pixels.iter().enumerate() {
            let (x, y) = (b.x0 - window.x0 + i % tw, b.y0 - window.y0 + i / tw);
            film.pixels[y * w + x] = est.mean();
            spp[y * w + x] = est.n;
        }
    }
    stats.samples = spp.iter().map(|&s| s as u64).sum();
    stats.rays = log.counts;
    stats.sampled_rays = log.sampled;
    stats.time = start.elapsed();
    RenderOutput { film, window, samples_per_pixel: spp, stats, heatmap: None }
}

/// The number of tiles a render of `window` takes (what its `progress` counts up to).
pub fn tiles_in(window: &PixelBounds) -> usize {
    window.width().div_ceil(TILE) * window.height().div_ceil(TILE)
}

/// `window` cut into tiles of [`TILE`] × [`TILE`] pixels from its top-left corner, row by row.
fn tiles_of(window: &PixelBounds) -> Vec<PixelBounds> {
    let mut tiles = Vec::with_capacity(tiles_in(window));
    for y0 in (window.y0..window.y1).step_by(TILE) {
        for x0 in (window.x0..window.x1).step_by(TILE) {
            tiles.push(PixelBounds { x0, x1: (x0 + TILE).min(window.x1), y0, y1: (y0 + TILE).min(window.y1) });
        }
    }
    tiles
}

/// One wavefront per thread of the rayon pool, reused from tile to tile. Every tile is a rayon
/// task of its own (`with_max_len(1)`): with rayon's default split (about two tasks per
/// thread, a running task never split again) a thread could finish and wait for the other's
/// last run of tiles; a new wavefront per task, instead of one per thread, cost the cheap
/// tiles (PERFORMANCE.md, "Work split over threads").
struct Wavefronts(Vec<Mutex<wavefront::Wavefront>>);

impl Wavefronts {
    /// One (empty) wavefront per thread of the current pool.
    fn for_pool() -> Self {
        Self((0..rayon::current_num_threads()).map(|_| Mutex::default()).collect())
    }

    /// Runs `f` with the calling thread's wavefront. Only thread `i` takes wavefront `i`, so
    /// it is free unless a tile started inside another on the same thread (nothing in a tile
    /// waits on rayon today); such a tile gets a wavefront of its own rather than waiting.
    fn with<R>(&self, f: impl FnOnce(&mut wavefront::Wavefront) -> R) -> R {
        let i = rayon::current_thread_index().unwrap_or(0) % self.0.len();
        match self.0[i].try_lock() {
            Ok(mut wf) => f(&mut wf),
            // A tile panicked holding it: rayon ends the render in that panic, so whatever
            // later tiles compute with the wavefront it left is thrown away.
            Err(TryLockError::Poisoned(e)) => f(&mut e.into_inner()),
            Err(TryLockError::WouldBlock) => f(&mut wavefront::Wavefront::new()),
        }
    }
}

struct TileResult {
    pixels: Vec<PixelEstimate>,
    log: RayLog,
    invalid_samples: u64,
    clamped_samples: u64,
    culled_samples: u64,
    phases: PhaseTimes,
}

/// The random number stream of sample `sample` of pixel `pixel`.
#[inline]
pub fn sample_stream(pixel: usize, sample: u32) -> u64 {
    ((sample as u64) << 32) | pixel as u64
}

fn render_tile(
    integrator: &integrator::Integrator,
    camera: &camera::CameraRays,
    settings: &RenderSettings,
    order: StreamOrder,
    wavefront: &mut wavefront::Wavefront,
    tile: &PixelBounds,
) -> TileResult {
    let (w, h) = (settings.width, settings.height);
    let PixelBounds { x0, x1, y0, y1 } = *tile;
    let tw = x1 - x0;
    let npix = tw * (y1 - y0);
    let spp = settings.samples_per_pixel.max(1);
    // Convergence is tested after every batch (CS184's samplesPerBatch); a batch is taken in
    // passes of at most PASS_SAMPLES samples per pixel, so the buffers stay small.
    let batch = match settings.adaptive {
        Some((b, _)) => b.clamp(1, spp),
        None => spp,
    };
    let pass = PASS_SAMPLES.min(spp);
    let centre_only = spp == 1;
    let mut pixels = vec![PixelEstimate::default(); npix];
    // Per-pass buffers, sized for the largest pass (the wavefront's are kept by the worker).
    let cap = npix * pass as usize;
    wavefront.reserve(cap, integrator);
    let mut owner: Vec<u32> = Vec::with_capacity(cap);
    // The image positions of the pass's samples, made into camera rays together.
    let mut positions: Vec<[f32; 2]> = Vec::with_capacity(cap);
    // The top-left corner of each pixel of the tile, in image coordinates.
    let corners: Vec<[f32; 2]> = (0..npix).map(|i| [(x0 + i % tw) as f32, (y0 + i / tw) as f32]).collect();
    let samplers = SamplerSource::new(settings.sampler, settings.seed);
    // Pixels none of whose camera rays can hit the scene (their cone misses every
    // primitive's box) take the value of a miss for every sample, without tracing: the same
    // value, bit for bit, that tracing their rays would give (`Integrator::camera_miss`).
    let cull_start = Instant::now();
    let mut culled = vec![false; npix];
    if settings.pixel_culling && !settings.brute_force {
        let scene = integrator.tracer().scene();
        let may_hit = |xs: (usize, usize), ys: (usize, usize)| {
            let (o, lo, hi) = camera.pixels_cone(xs, ys, (w, h));
            scene.cone_may_hit(o, lo, hi)
        };
        // A test costs about as much as three camera samples of a missing ray (generated,
        // traced, filed): rectangles of fewer than 16 samples are not worth splitting.
        let edge = match spp {
            16.. => 1,
            4..16 => 2,
            _ => 4,
        };
        cull_pixels(&may_hit, edge, (x0, x1), (y0, y1), &mut |x, y| culled[(y - y0) * tw + x - x0] = true);
    }
    let mut log = RayLog::default();
    let mut phases = PhaseTimes { generate: cull_start.elapsed(), ..PhaseTimes::default() };
    let mut invalid = 0u64;
    let mut clamped = 0u64;
    let mut culled_samples = 0u64;
    // What the film takes for each culled sample, and whether it counts as invalid or clamped.
    let (mut miss_invalid, mut miss_clamped) = (0u64, 0u64);
    let miss = finish_sample(integrator.camera_miss(), settings, &mut miss_invalid, &mut miss_clamped);
    // Every pixel still sampling has taken `taken` samples: all start together and a batch
    // adds the same number to each.
    let mut taken = 0u32;
    while taken < spp && pixels.iter().any(|p| !p.done) {
        let batch_end = taken.saturating_add(batch).min(spp);
        while taken < batch_end {
            let pass_end = taken.saturating_add(pass).min(batch_end);
            let t0 = Instant::now();
            wavefront.clear();
            owner.clear();
            positions.clear();
            for (i, est) in pixels.iter_mut().enumerate() {
                if est.done {
                    continue;
                }
                if culled[i] {
                    let n = (pass_end - taken) as u64;
                    for _ in 0..n {
                        est.add(miss);
                    }
                    (culled_samples, invalid, clamped) =
                        (culled_samples + n, invalid + n * miss_invalid, clamped + n * miss_clamped);
                    continue;
                }
                let pixel = (y0 + i / tw) * w + x0 + i % tw;
                let pixel = samplers.pixel(pixel);
                wavefront.push_samples((taken..pass_end).map(|s| pixel.sampler(s)));
                owner.extend(std::iter::repeat_n(i as u32, (pass_end - taken) as usize));
            }
            // One sample goes through the pixel centre; more are jittered uniformly, by the
            // first numbers of their paths' generators.
            positions.extend(wavefront.sample_rngs().zip(&owner).map(|(rng, &i)| {
                let (jx, jy) = if centre_only { (0.5, 0.5) } else { rng.next_2d() };
                let [x, y] = corners[i as usize];
                [x + jx, y + jy]
            }));
            wavefront.set_camera_rays(|rays| camera.rays_into(&positions, w, h, rays));
            phases.generate += t0.elapsed();
            wavefront.run(integrator, order, &mut log, &mut phases);
            let t1 = Instant::now();
            for (l, &i) in wavefront.radiance().zip(&owner) {
                pixels[i as usize].add(finish_sample(l, settings, &mut invalid, &mut clamped));
            }
            taken = pass_end;
            phases.film += t1.elapsed();
        }
        let t = Instant::now();
        for est in &mut pixels {
            est.done = est.n >= spp || settings.adaptive.is_some_and(|(_, tol)| est.converged(tol));
        }
        phases.film += t.elapsed();
    }
    TileResult { pixels, log, invalid_samples: invalid, clamped_samples: clamped, culled_samples, phases }
}

/// Calls `cull(x, y)` for each pixel of `xs` × `ys` whose cone of camera rays cannot hit the
/// scene (`may_hit` of a rectangle of pixels is false): the whole rectangle when its cone
/// misses, else each quarter in turn, down to rectangles of `edge` × `edge` pixels.
fn cull_pixels(
    may_hit: &impl Fn((usize, usize), (usize, usize)) -> bool,
    edge: usize,
    xs: (usize, usize),
    ys: (usize, usize),
    cull: &mut impl FnMut(usize, usize),
) {
    if xs.0 >= xs.1 || ys.0 >= ys.1 {
        return;
    }
    if !may_hit(xs, ys) {
        for y in ys.0..ys.1 {
            for x in xs.0..xs.1 {
                cull(x, y);
            }
        }
    } else if xs.1 - xs.0 > edge || ys.1 - ys.0 > edge {
        let (xm, ym) = ((xs.0 + xs.1).div_ceil(2), (ys.0 + ys.1).div_ceil(2));
        for (a, b) in [(xs.0, xm), (xm, xs.1)] {
            for (c, d) in [(ys.0, ym), (ym, ys.1)] {
                cull_pixels(may_hit, edge, (a, b), (c, d), cull);
            }
        }
    }
}

/// A camera sample's radiance `l` as the film takes it: black when not finite (counted in
/// `invalid`), scaled down to [`RenderSettings::max_sample_value`] (counted in `clamped`).
#[inline]
fn finish_sample(mut l: Vec3, settings: &RenderSettings, invalid: &mut u64, clamped: &mut u64) -> Vec3 {
    if !l.is_finite() {
        *invalid += 1;
        l = Vec3::ZERO;
    }
    if let Some(max) = settings.max_sample_value {
        let largest = l.max_element();
        if largest > max {
            l *= max / largest;
            *clamped += 1;
        }
    }
    l
}
