//! The wavefront's queues: batches of rays with the path (or sample) each belongs to, and the
//! direct-lighting samples of the shading points of one bounce, waiting for their rays.
//!
//! Every buffer is allocated once per worker and reused from batch to batch and bounce to
//! bounce (`clear` keeps the capacity), so that tracing a sample allocates nothing.

use super::order::{RayOrder, SortScratch};
use crate::math::{Aabb, Vec3};
use crate::ray::{Hit, Ray};

/// Rays to trace together, each with the index of what it belongs to (a path, or a direct
/// sample), and their answers.
#[derive(Clone, Debug, Default)]
pub struct RayQueue {
    /// The rays, in the order they are traced.
    pub rays: Vec<Ray>,
    /// `owner[i]`: the path or sample `rays[i]` belongs to.
    pub owner: Vec<u32>,
    /// Closest hits of `rays` (closest-hit queues).
    pub hits: Vec<Hit>,
    /// Occlusion of `rays` (shadow queues).
    pub occluded: Vec<bool>,
}

impl RayQueue {
    /// An empty queue.
    pub fn clear(&mut self) {
        self.rays.clear();
        self.owner.clear();
    }

    /// Number of rays queued.
    #[inline]
    pub fn len(&self) -> usize {
        self.rays.len()
    }

    /// True when no ray is queued.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.rays.is_empty()
    }

    /// Queues `ray` for `owner`.
    #[inline]
    pub fn push(&mut self, ray: Ray, owner: u32) {
        self.rays.push(ray);
        self.owner.push(owner);
    }

    /// Keeps the rays whose `keep[i]` is set, in order (`keep` as long as the queue).
    pub fn retain(&mut self, keep: &[bool]) {
        debug_assert_eq!(keep.len(), self.len());
        let mut n = 0;
        for (i, &k) in keep.iter().enumerate() {
            self.rays[n] = self.rays[i];
            self.owner[n] = self.owner[i];
            n += k as usize;
        }
        self.rays.truncate(n);
        self.owner.truncate(n);
    }

    /// Reorders the rays (with their owners) for coherent tracing; a pure function of the
    /// rays, so that the order never depends on the thread.
    pub fn sort(&mut self, order: RayOrder, bounds: &Aabb, scratch: &mut SortScratch) {
        scratch.sort(order, bounds, &mut self.rays, &mut self.owner);
    }
}

/// One direct-lighting sample of a shading point: a light sample (answered by a shadow ray,
/// or by nothing when no surface can lie between) or a uniform hemisphere ray (answered by
/// its closest hit's emission). It adds `f · radiance · scale` when visible.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectSample {
    /// The BSDF toward the sampled direction.
    pub f: Vec3,
    /// Radiance arriving from the sample if nothing is in the way (hemisphere samples: filled
    /// in from their ray's closest hit).
    pub radiance: Vec3,
    /// `|cos θ| / pdf` of the sampled direction.
    pub scale: f32,
    /// The light sampled (its index), or [`super::integrator::HEMISPHERE`].
    pub group: u32,
    /// False once the sample's shadow ray is found blocked.
    pub visible: bool,
}

/// A shading point whose direct lighting waits for its samples' rays.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectPoint {
    /// The path shaded.
    pub path: u32,
    /// The path's throughput at the point (before its BSDF sample).
    pub weight: Vec3,
    /// Its first sample in [`DirectQueue::samples`]; the next point's `start` ends them.
    pub start: u32,
}

/// Paths shaded together in SIMD lanes (the lanes of [`LanePoints`] and [`LaneSample`]): a
/// step of the scene's surface rows ([`crate::scene::surface::SurfaceRows`]).
pub const STEP: usize = crate::scene::surface::STEP;

/// `N` rows of one value per lane.
pub type Rows<const N: usize> = [[f32; STEP]; N];

/// Up to [`STEP`] shading points shaded together in lanes, whose direct lighting is added
/// together, in lanes, once their shadow rays are traced. Each lane is one path's point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LanePoints {
    /// Lane `j`'s path (for the bits `j` of `mask`).
    pub path: [u32; STEP],
    /// The lanes that are shading points.
    pub mask: u32,
    /// Each lane's throughput at its point (before its BSDF sample).
    pub weight: Rows<3>,
    /// Their first row in [`DirectQueue::lane_samples`]: one row per light sample of a point,
    /// in the order the integrator draws them; the next entry's `start` ends them.
    pub start: u32,
}

/// One light sample of each lane of a [`LanePoints`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaneSample {
    /// `f · radiance · scale` of each lane's sample ([`DirectSample`]'s product).
    pub value: Rows<3>,
    /// The lanes whose sample is queued (it carries light).
    pub kept: u32,
    /// The kept lanes not found blocked (a shadow ray clears its lane's bit).
    pub visible: u32,
}

/// Marks a shadow ray's owner as a lane sample: `LANE_OWNER | (row · STEP + lane)`, `row` in
/// [`DirectQueue::lane_samples`].
pub const LANE_OWNER: u32 = 1 << 31;

/// The direct lighting of one bounce of a batch of paths: the shading points, their samples in
/// the order they were drawn, and the rays that answer them. Points shaded one path at a time
/// list their samples one by one (`points`, `samples`); points shaded in lanes whose every
/// light is sampled in the lanes keep them in rows (`lanes`, `lane_samples`).
#[derive(Clone, Debug, Default)]
pub struct DirectQueue {
    /// Shading points, in the order they were shaded.
    pub points: Vec<DirectPoint>,
    /// Samples of all points, grouped by point.
    pub samples: Vec<DirectSample>,
    /// Shading points taken in lanes, a step of up to [`STEP`] points each.
    pub lanes: Vec<LanePoints>,
    /// Their samples, grouped by step.
    pub lane_samples: Vec<LaneSample>,
    /// Shadow rays (any hit), each owned by its sample.
    pub shadow: RayQueue,
    /// Hemisphere rays (closest hit), each owned by its sample.
    pub probes: RayQueue,
}

impl DirectQueue {
    /// Empties the queue, keeping its buffers.
    pub fn clear(&mut self) {
        self.points.clear();
        self.samples.clear();
        self.lanes.clear();
        self.lane_samples.clear();
        self.shadow.clear();
        self.probes.clear();
    }

    /// Starts the samples of a shading point of path `path` with throughput `weight`.
    #[inline]
    pub fn begin(&mut self, path: u32, weight: Vec3) {
        self.points.push(DirectPoint { path, weight, start: self.samples.len() as u32 });
    }

    /// Adds a light sample of the current point, answered by `shadow` (none: always visible).
    #[inline]
    pub fn push_light(&mut self, sample: DirectSample, shadow: Option<Ray>) {
        if let Some(r) = shadow {
            self.shadow.push(r, self.samples.len() as u32);
        }
        self.samples.push(sample);
    }

    /// Adds a hemisphere sample of the current point, answered by `ray`'s closest hit.
    #[inline]
    pub fn push_probe(&mut self, sample: DirectSample, ray: Ray) {
        self.probes.push(ray, self.samples.len() as u32);
        self.samples.push(sample);
    }

    /// Direct samples queued, counting every lane of the lane rows.
    #[inline]
    pub fn sample_count(&self) -> usize {
        self.samples.len() + self.lane_samples.len() * STEP
    }

    /// Marks not visible the samples whose shadow ray `shadow.occluded` finds blocked.
    pub fn mark_blocked(&mut self) {
        for (&blocked, &owner) in self.shadow.occluded.iter().zip(&self.shadow.owner) {
            if !blocked {
                continue;
            }
            if owner & LANE_OWNER != 0 {
                let i = (owner & !LANE_OWNER) as usize;
                self.lane_samples[i / STEP].visible &= !(1 << (i % STEP));
            } else {
                self.samples[owner as usize].visible = false;
            }
        }
    }

    /// The sample rows of lane step `i`.
    #[inline]
    pub fn lane_samples_of(&self, i: usize) -> &[LaneSample] {
        group(&self.lane_samples, self.lanes[i].start, self.lanes.get(i + 1).map(|p| p.start))
    }

    /// The samples of point `i`.
    #[inline]
    pub fn samples_of(&self, i: usize) -> &[DirectSample] {
        group(&self.samples, self.points[i].start, self.points.get(i + 1).map(|p| p.start))
    }
}

/// The group of `items` from `start` to the next group's start (`None`: the end).
#[inline]
fn group<T>(items: &[T], start: u32, next: Option<u32>) -> &[T] {
    &items[start as usize..next.map_or(items.len(), |n| n as usize)]
}
