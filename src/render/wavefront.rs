//! Wavefront path tracing: a batch of paths advances together, one bounce at a time, and every
//! ray of a bounce is traced in one stream through the packet kernels.
//!
//! A batch (the camera samples of one pass over a tile) goes through:
//! 1. *generate*: the caller queues the camera samples (their random number generators) and
//!    then their camera rays ([`Wavefront::push_samples`], [`Wavefront::set_camera_rays`]);
//! 2. *trace*: the camera rays as one closest-hit stream; a sample whose ray left the scene
//!    ends there, and the others take a path each and go on in waves of 1024 paths;
//! 3. *shade*: each hit adds its emission, queues its direct-lighting samples (shadow rays, or
//!    hemisphere rays under `-H`), samples its BSDF and plays Russian roulette
//!    ([`Integrator::shade`], then [`Integrator::scatter`] for the same path), writing the
//!    continuation ray in place of the ray shaded; the wave goes in steps of eight, whose
//!    diffuse hits are shaded together in SIMD lanes ([`Integrator::shade_lanes`], the same
//!    results bit for bit);
//! 4. *trace* the shadow rays of the whole batch as one occlusion stream (and the hemisphere
//!    rays as one closest-hit stream), add each point's direct lighting
//!    ([`Integrator::direct_total`]; for the points shaded in lanes, eight at a time in lanes:
//!    [`Integrator::add_direct_lanes`]);
//! 5. *compact* the surviving paths' rays, optionally *sort* them ([`RayOrder`]), trace them as
//!    one closest-hit stream and go back to 3 until no path is left.
//!
//! A path's random numbers come from its own generator and are drawn in the same order
//! whatever else is in the batch, and every ray gets the same answer from the stream kernels as
//! alone, so the image does not depend on the batch, the order of the rays or the thread.

use super::integrator::{Entries, Integrator, PathState, STEP, SampleLanes};
use super::order::{RayOrder, SortScratch};
use super::queue::{DirectQueue, RayQueue};
use super::sampler::Sampler;
use super::stats::{RayKind, RayLog};
use crate::math::Vec3;
use crate::ray::{Hit, Ray};
use crate::scene::surface::SurfaceRows;
use std::time::{Duration, Instant};

/// How secondary rays are ordered before each stream. The default, shading order for both
/// streams, is the order measured fastest on every ISA tier (no sort made the streams of a
/// wave trace faster, and sorting costs: PERFORMANCE.md, "Secondary ray order").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct StreamOrder {
    /// Shadow rays.
    pub shadow: RayOrder,
    /// Continuation rays (and hemisphere rays).
    pub bounce: RayOrder,
}

/// One worker's wavefront: the paths of a batch and its queues, reused from batch to batch.
#[derive(Clone, Debug, Default)]
pub struct Wavefront {
    /// The random number generators of the batch's camera samples, in sample order.
    rngs: Vec<Sampler>,
    /// The radiance each camera sample brought back, in sample order.
    radiance: Vec<Vec3>,
    /// The paths of the samples whose camera ray hit something, in sample order: a sample
    /// whose camera ray leaves the scene is done then, and never takes a path.
    paths: Vec<PathState>,
    /// `sample_of[p]`: the camera sample of `paths[p]`.
    sample_of: Vec<u32>,
    /// The camera rays of the batch, owned by their samples (by their paths once traced).
    camera: RayQueue,
    /// The rays of the current bounce of the current wave, each owned by its path.
    queue: RayQueue,
    /// `alive[k]`: the path of `queue.rays[k]` goes on (its continuation replaced the ray).
    alive: Vec<bool>,
    /// The surfaces hit by `queue.rays`, in rows of [`STEP`]: ray `k`'s is lane `k % STEP` of
    /// `surfaces[k / STEP]`.
    surfaces: Vec<SurfaceRows>,
    /// Direct lighting of the current bounce.
    direct: DirectQueue,
    scratch: SortScratch,
    /// The light samples of a step of lane shading.
    lane_scratch: Vec<SampleLanes>,
}

impl Wavefront {
    /// An empty wavefront.
    pub fn new() -> Self {
        Self::default()
    }

    /// Makes room for batches of `paths` paths of `integrator`, so that tracing them
    /// allocates nothing.
    pub fn reserve(&mut self, paths: usize, integrator: &Integrator) {
        fn room<T>(v: &mut Vec<T>, n: usize) {
            v.reserve(n.saturating_sub(v.len()));
        }
        let Capacity { paths, wave, samples } = Capacity::of(paths, integrator.direct_samples_per_point() as usize);
        room(&mut self.rngs, paths);
        room(&mut self.radiance, paths);
        room(&mut self.paths, paths);
        room(&mut self.sample_of, paths);
        let c = &mut self.camera;
        room(&mut c.rays, paths);
        room(&mut c.owner, paths);
        room(&mut c.hits, paths);
        room(&mut self.alive, wave);
        room(&mut self.surfaces, wave.div_ceil(STEP));
        room(&mut self.direct.points, wave);
        room(&mut self.direct.samples, samples);
        // A step of lane points at most per STEP paths, a row per direct sample of each.
        room(&mut self.direct.lanes, wave.div_ceil(STEP));
        room(&mut self.direct.lane_samples, samples.div_ceil(STEP) + integrator.direct_samples_per_point() as usize);
        let q = &mut self.queue;
        room(&mut q.rays, wave);
        room(&mut q.owner, wave);
        room(&mut q.hits, wave);
        // Shadow rays (light sampling) or hemisphere rays (`-H`): one kind per render.
        let s = &mut self.direct.shadow;
        room(&mut s.rays, samples);
        room(&mut s.owner, samples);
        room(&mut s.occluded, samples);
        let p = &mut self.direct.probes;
        if integrator.hemisphere_sampling() {
            room(&mut p.rays, samples);
            room(&mut p.owner, samples);
            room(&mut p.hits, samples);
        }
        self.scratch.reserve(samples.max(wave));
        room(&mut self.lane_scratch, integrator.direct_samples_per_point() as usize);
    }

    /// Starts a new batch.
    pub fn clear(&mut self) {
        self.rngs.clear();
        self.camera.clear();
    }

    /// Number of camera samples in the batch.
    pub fn len(&self) -> usize {
        self.rngs.len()
    }

    /// True when the batch has no camera sample.
    pub fn is_empty(&self) -> bool {
        self.rngs.is_empty()
    }

    /// Adds a camera sample drawing from each generator of `rngs` (its path's, if its camera
    /// ray hits); their camera rays follow with [`Wavefront::set_camera_rays`].
    #[inline]
    pub fn push_samples(&mut self, rngs: impl Iterator<Item = Sampler>) {
        self.rngs.extend(rngs);
    }

    /// The random number generators of the batch's camera samples, in order (a camera
    /// sample's own numbers, such as its position in the pixel, are drawn from them first).
    pub fn sample_rngs(&mut self) -> impl Iterator<Item = &mut Sampler> {
        self.rngs.iter_mut()
    }

    /// Sets the camera rays of the batch: `write` appends to the empty vector it is given one
    /// ray per path, in the order of the paths.
    ///
    /// # Panics
    /// When `write` leaves a number of rays other than the number of camera samples.
    #[inline]
    pub fn set_camera_rays(&mut self, write: impl FnOnce(&mut Vec<Ray>)) {
        let c = &mut self.camera;
        c.clear();
        write(&mut c.rays);
        assert_eq!(c.rays.len(), self.rngs.len(), "one camera ray per sample");
    }

    /// The radiance each camera sample of the batch brought back, in the order they were
    /// pushed.
    pub fn radiance(&self) -> impl Iterator<Item = Vec3> + '_ {
        self.radiance.iter().copied()
    }

    /// Traces the batch to the end of its last path, logging every ray it traces (camera,
    /// shadow, bounce) in `log` and the time of each phase in `times`.
    pub fn run(&mut self, integrator: &Integrator, order: StreamOrder, log: &mut RayLog, times: &mut PhaseTimes) {
        let tracer = integrator.tracer();
        let bounds = tracer.scene().bounds();
        let mut clock = Clock::start();
        let c = &mut self.camera;
        log.record(RayKind::Camera, &c.rays);
        resize(&mut c.hits, c.rays.len(), Hit::MISS);
        tracer.intersect_stream(&c.rays, &mut c.hits);
        clock.lap(&mut times.trace[RayKind::Camera as usize]);
        if !integrator.traces_paths() {
            let values = c.rays.iter().zip(&c.hits).map(|(ray, hit)| integrator.camera_only(ray, hit));
            self.radiance.clear();
            self.radiance.extend(values);
            clock.lap(&mut times.shade);
            return;
        }
        // A camera ray that leaves the scene ends its sample here with the integrator's
        // `camera_miss` value (its path would queue nothing) and is never stored, so that the
        // waves hold only paths that go on. The others take a path each, in sample order.
        resize(&mut self.radiance, c.rays.len(), Vec3::ZERO);
        let (rngs, radiance, paths, sample_of) = (&self.rngs, &mut self.radiance, &mut self.paths, &mut self.sample_of);
        paths.clear();
        sample_of.clear();
        let miss = integrator.camera_miss();
        let mut n = 0;
        for k in 0..c.rays.len() {
            let (ray, hit) = (c.rays[k], c.hits[k]);
            if hit.is_hit() {
                (c.rays[n], c.hits[n]) = (ray, hit);
                paths.push(PathState::new(rngs[k].clone()));
                sample_of.push(k as u32);
                n += 1;
            } else {
                radiance[k] = miss;
            }
        }
        c.rays.truncate(n);
        c.hits.truncate(n);
        // Camera ray `i` of the compacted queue is path `i`'s.
        c.owner.clear();
        c.owner.extend(0..n as u32);
        clock.lap(&mut times.shade);
        // The paths go on in waves of WAVE_PATHS, whose queues stay in the cache.
        for start in (0..n).step_by(WAVE_PATHS) {
            let end = (start + WAVE_PATHS).min(n);
            let (c, q) = (&self.camera, &mut self.queue);
            q.clear();
            q.rays.extend_from_slice(&c.rays[start..end]);
            q.owner.extend_from_slice(&c.owner[start..end]);
            q.hits.clear();
            q.hits.extend_from_slice(&c.hits[start..end]);
            clock.lap(&mut times.generate);
            self.advance(integrator, order, &bounds, log, &mut clock, times);
        }
        for (path, &k) in self.paths.iter().zip(&self.sample_of) {
            self.radiance[k as usize] = path.l;
        }
        clock.lap(&mut times.film);
    }

    /// Advances the paths of `queue` (rays traced, `hits` found) to their ends.
    fn advance(
        &mut self,
        integrator: &Integrator,
        order: StreamOrder,
        bounds: &crate::math::Aabb,
        log: &mut RayLog,
        clock: &mut Clock,
        times: &mut PhaseTimes,
    ) {
        let tracer = integrator.tracer();
        loop {
            // Shade: each surviving path's continuation replaces its ray.
            let (q, d) = (&mut self.queue, &mut self.direct);
            d.clear();
            let scene = tracer.scene();
            resize(&mut self.surfaces, q.rays.len().div_ceil(STEP), SurfaceRows::default());
            scene.prefetch_hits(&q.hits);
            scene.surface_rows(&q.rays, &q.hits, &mut self.surfaces);
            let n = q.rays.len();
            resize(&mut self.alive, n, false);
            for k0 in (0..n).step_by(STEP) {
                let mut e = Entries {
                    paths: &mut self.paths,
                    rays: &mut q.rays,
                    owner: &q.owner,
                    hits: &q.hits,
                    surfaces: &self.surfaces,
                    alive: &mut self.alive,
                };
                // Diffuse hits eight at a time in SIMD lanes, the others one by one.
                let lanes = integrator.lane_entries(&e, k0);
                for k in k0..n.min(k0 + STEP) {
                    if lanes >> (k - k0) & 1 != 0 {
                        continue;
                    }
                    let id = e.owner[k];
                    let (path, surface) = (&mut e.paths[id as usize], &e.surfaces[k / STEP].get(k % STEP));
                    let at = integrator.shade(path, &e.rays[k], &e.hits[k], surface, d, id);
                    let next = at.and_then(|at| integrator.scatter(path, surface, &at));
                    if let Some(next) = next {
                        e.rays[k] = next;
                    }
                    e.alive[k] = next.is_some();
                }
                if lanes != 0 {
                    integrator.shade_lanes(&mut e, k0, lanes, d, &mut self.lane_scratch);
                }
                if d.sample_count() >= DIRECT_FLUSH {
                    // Many light samples per point (`-l`): trace what is queued now, so that
                    // the queue stays bounded.
                    clock.lap(&mut times.shade);
                    let ctx = DirectContext { integrator, order, bounds };
                    ctx.trace(d, &mut self.paths, &mut self.scratch, log, clock, times);
                    d.clear();
                }
            }
            clock.lap(&mut times.shade);

            let ctx = DirectContext { integrator, order, bounds };
            ctx.trace(d, &mut self.paths, &mut self.scratch, log, clock, times);

            // Compact the survivors, order and trace their continuations.
            q.retain(&self.alive);
            clock.lap(&mut times.compact);
            if q.is_empty() {
                return;
            }
            log.record(RayKind::Bounce, &q.rays);
            clock.lap(&mut times.compact);
            q.sort(order.bounce, bounds, &mut self.scratch);
            clock.lap(&mut times.sort);
            resize(&mut q.hits, q.rays.len(), Hit::MISS);
            tracer.intersect_stream(&q.rays, &mut q.hits);
            clock.lap(&mut times.trace[RayKind::Bounce as usize]);
        }
    }
}

/// What tracing a bounce's direct lighting needs besides its queue.
struct DirectContext<'i, 'a> {
    integrator: &'i Integrator<'a>,
    order: StreamOrder,
    bounds: &'i crate::math::Aabb,
}

impl DirectContext<'_, '_> {
    /// Traces the shadow rays of `d` as one occlusion stream and its hemisphere rays as one
    /// closest-hit stream, then adds each point's direct lighting to its path.
    fn trace(
        &self,
        d: &mut DirectQueue,
        paths: &mut [PathState],
        scratch: &mut SortScratch,
        log: &mut RayLog,
        clock: &mut Clock,
        times: &mut PhaseTimes,
    ) {
        let (integrator, order, bounds, tracer) = (self.integrator, self.order, self.bounds, self.integrator.tracer());
        let s = &mut d.shadow;
        if !s.is_empty() {
            log.record(RayKind::Shadow, &s.rays);
            clock.lap(&mut times.shade);
            s.sort(order.shadow, bounds, scratch);
            clock.lap(&mut times.sort);
            resize(&mut s.occluded, s.rays.len(), false);
            tracer.occluded_stream(&s.rays, &mut s.occluded);
            clock.lap(&mut times.trace[RayKind::Shadow as usize]);
            d.mark_blocked();
        }
        let p = &mut d.probes;
        if !p.is_empty() {
            log.record(RayKind::Bounce, &p.rays);
            clock.lap(&mut times.shade);
            p.sort(order.bounce, bounds, scratch);
            clock.lap(&mut times.sort);
            resize(&mut p.hits, p.rays.len(), Hit::MISS);
            tracer.intersect_stream(&p.rays, &mut p.hits);
            clock.lap(&mut times.trace[RayKind::Bounce as usize]);
            for ((ray, hit), &i) in p.rays.iter().zip(&p.hits).zip(&p.owner) {
                d.samples[i as usize].radiance = integrator.probe_radiance(hit, ray.dir);
            }
        }
        for (i, point) in d.points.iter().enumerate() {
            let path = &mut paths[point.path as usize];
            path.l += point.weight * integrator.direct_total(d.samples_of(i));
        }
        integrator.add_direct_lanes(d, paths);
        clock.lap(&mut times.shade);
    }
}

/// Thread time of each phase of the wavefront (summed over threads).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhaseTimes {
    /// Generating camera rays (and their paths' random number generators).
    pub generate: Duration,
    /// Tracing, by kind of ray (`RayKind as usize`).
    pub trace: [Duration; 3],
    /// Shading hits (emission, light and BSDF sampling, Russian roulette) and adding the
    /// direct lighting their shadow rays found.
    pub shade: Duration,
    /// Ordering secondary rays before they are traced.
    pub sort: Duration,
    /// Compacting the surviving paths.
    pub compact: Duration,
    /// Adding finished samples to their pixels (and adaptive sampling's test).
    pub film: Duration,
}

impl PhaseTimes {
    /// All phases.
    pub fn total(&self) -> Duration {
        self.generate + self.trace.iter().sum::<Duration>() + self.shade + self.sort + self.compact + self.film
    }
}

impl std::ops::AddAssign for PhaseTimes {
    fn add_assign(&mut self, o: Self) {
        self.generate += o.generate;
        for (a, b) in self.trace.iter_mut().zip(o.trace) {
            *a += b;
        }
        self.shade += o.shade;
        self.sort += o.sort;
        self.compact += o.compact;
        self.film += o.film;
    }
}

/// How many elements a worker's buffers hold.
struct Capacity {
    /// Paths of a batch (camera queue, path states).
    paths: usize,
    /// Paths of a wave (bounce queue, surfaces, shading points).
    wave: usize,
    /// Direct-lighting samples of a wave's bounce before they are traced.
    samples: usize,
}

impl Capacity {
    /// For batches of `paths` paths and at most `direct` direct samples per shading point.
    fn of(paths: usize, direct: usize) -> Self {
        let wave = paths.min(WAVE_PATHS);
        // The shading of a bounce stops to trace its direct lighting past DIRECT_FLUSH samples
        // (checked after each step of STEP paths).
        let samples = wave.saturating_mul(direct.max(1)).min(DIRECT_FLUSH + STEP * direct);
        Self { paths, wave, samples }
    }
}

/// Bytes one worker's [`Wavefront`] holds for batches of `paths` paths with at most `direct`
/// direct-lighting samples per shading point (light sampling; hemisphere sampling's rays take
/// as much again).
pub fn worker_bytes(paths: usize, direct: usize) -> u64 {
    use std::mem::size_of;
    let Capacity { paths, wave, samples } = Capacity::of(paths, direct);
    let ray = size_of::<Ray>() + size_of::<u32>();
    let per_path =
        size_of::<Sampler>() + size_of::<Vec3>() + size_of::<PathState>() + size_of::<u32>() + ray + size_of::<Hit>();
    let per_wave = ray
        + size_of::<Hit>()
        + size_of::<bool>()
        + size_of::<SurfaceRows>() / STEP
        + size_of::<super::queue::DirectPoint>();
    let per_wave = per_wave + size_of::<super::queue::LanePoints>() / STEP;
    // Samples one by one or in rows (a row for eight samples).
    let per_sample = size_of::<super::queue::DirectSample>()
        + size_of::<super::queue::LaneSample>() / STEP
        + ray
        + size_of::<bool>();
    let sort = SortScratch::bytes_per_ray() * samples.max(wave);
    (paths * per_path + wave * per_wave + samples * per_sample + sort) as u64
}

/// Paths advanced together: a wave's queues (rays, hits, surfaces, shadow rays) stay in the
/// L2 cache beside the BVH's upper levels.
const WAVE_PATHS: usize = 1024;

/// Direct-lighting samples queued before the bounce's shading is interrupted to trace them.
const DIRECT_FLUSH: usize = 1 << 16;

/// Splits elapsed time into phases.
struct Clock(Instant);

impl Clock {
    fn start() -> Self {
        Self(Instant::now())
    }

    /// Adds the time since the last lap to `phase`.
    #[inline]
    fn lap(&mut self, phase: &mut Duration) {
        let now = Instant::now();
        *phase += now - self.0;
        self.0 = now;
    }
}

/// `v` with exactly `n` elements, all `fill`, keeping its capacity.
#[inline]
fn resize<T: Clone>(v: &mut Vec<T>, n: usize, fill: T) {
    v.clear();
    v.resize(n, fill);
}
