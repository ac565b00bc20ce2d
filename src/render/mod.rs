//! The renderer: tile-parallel image formation over a committed [`Scene`].
//!
//! Pixels are split into square tiles rendered by rayon tasks. Each pixel draws its random
//! numbers from its own generator seeded by `(seed, pixel index)`, so the image is a pure
//! function of the scene, the settings and the seed, whatever the thread count.

pub mod film;
pub mod integrator;
pub mod sampler;
pub mod stats;

pub use film::{Encoding, Film, ImageError};
pub use integrator::IntegratorKind;

use crate::scene::{Camera, Scene};
use sampler::Rng;
use std::sync::atomic::{AtomicU64, Ordering};
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
    /// Seed of all random numbers.
    pub seed: u64,
    /// Test every primitive instead of using the BVH (CS184's "without BVH" timing).
    pub brute_force: bool,
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
            integrator: IntegratorKind::Normals,
            seed: 0,
            brute_force: false,
        }
    }
}

/// Rays traced, by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    /// Camera (primary) rays.
    pub camera: u64,
    /// Shadow (occlusion) rays.
    pub shadow: u64,
    /// Bounce (secondary closest-hit) rays.
    pub bounce: u64,
}

impl RayCounts {
    /// All rays.
    pub fn total(&self) -> u64 {
        self.camera + self.shadow + self.bounce
    }
}

impl std::ops::AddAssign for RayCounts {
    fn add_assign(&mut self, o: Self) {
        self.camera += o.camera;
        self.shadow += o.shadow;
        self.bounce += o.bounce;
    }
}

/// What a render measured.
#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    /// Rays traced by kind.
    pub rays: RayCounts,
    /// Camera samples taken (all pixels).
    pub samples: u64,
    /// Wall-clock time of the render.
    pub time: Duration,
}

/// The result of a render.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// The image.
    pub film: Film,
    /// Samples taken per pixel (differs from the setting only with adaptive sampling).
    pub samples_per_pixel: Vec<u32>,
    /// Measurements.
    pub stats: RenderStats,
}

/// Renders `scene` through `camera`. `progress` is called with the number of tiles done
/// each time a tile completes.
pub fn render(
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> RenderOutput {
    use rayon::prelude::*;
    let (w, h) = (settings.width, settings.height);
    let start = Instant::now();
    let tiles_x = w.div_ceil(TILE);
    let tiles: Vec<(usize, usize)> =
        (0..h.div_ceil(TILE)).flat_map(|ty| (0..tiles_x).map(move |tx| (tx, ty))).collect();
    let done = AtomicU64::new(0);
    let integrator = integrator::Integrator::new(scene, settings);
    let rendered: Vec<(Vec<crate::math::Vec3>, Vec<u32>, RayCounts)> = tiles
        .par_iter()
        .map(|&(tx, ty)| {
            let r = render_tile(&integrator, camera, settings, tx, ty);
            progress(done.fetch_add(1, Ordering::Relaxed) + 1);
            r
        })
        .collect();
    let mut film = Film::new(w, h);
    let mut spp = vec![0u32; w * h];
    let mut rays = RayCounts::default();
    for (&(tx, ty), (pixels, counts, r)) in tiles.iter().zip(rendered) {
        rays += r;
        let (x0, y0) = (tx * TILE, ty * TILE);
        let tw = TILE.min(w - x0);
        for (i, (p, c)) in pixels.into_iter().zip(counts).enumerate() {
            let (x, y) = (x0 + i % tw, y0 + i / tw);
            film.pixels[y * w + x] = p;
            spp[y * w + x] = c;
        }
    }
    let samples = spp.iter().map(|&s| s as u64).sum();
    RenderOutput { film, samples_per_pixel: spp, stats: RenderStats { rays, samples, time: start.elapsed() } }
}

fn render_tile(
    integrator: &integrator::Integrator,
    camera: &Camera,
    settings: &RenderSettings,
    tx: usize,
    ty: usize,
) -> (Vec<crate::math::Vec3>, Vec<u32>, RayCounts) {
    let (w, h) = (settings.width, settings.height);
    let (x0, y0) = (tx * TILE, ty * TILE);
    let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
    let mut pixels = Vec::with_capacity((x1 - x0) * (y1 - y0));
    let mut counts = Vec::with_capacity(pixels.capacity());
    let mut rays = RayCounts::default();
    for y in y0..y1 {
        for x in x0..x1 {
            let mut rng = Rng::new(settings.seed, (y * w + x) as u64);
            let (value, n) = integrator.pixel(camera, x, y, &mut rng, &mut rays);
            pixels.push(value);
            counts.push(n);
        }
    }
    (pixels, counts, rays)
}
