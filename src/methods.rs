//! raypack's kernels and Embree's calls behind one interface ([`Method`]), traced over a
//! slice of rays on all threads of the current rayon pool ([`trace`]).
//!
//! Every method has the same contract: a slice of [`Ray`]s in, a slice of [`Hit`]s (or
//! occlusion flags) out. Rays are spread over threads in contiguous chunks of whole 4×4
//! tiles ([`CHUNK`] rays). `raypack bench`, the benchmarks and the Embree cross-check all
//! trace through this module, so they time and compare the same calls.
//!
//! The raypack side is the kernel registry [`crate::kernels::KERNELS`], run on the scene's ISA
//! tier.

use crate::kernels::{KERNELS, Query};
use crate::ray::{Hit, Ray};
use crate::raysets::Checksum;
use crate::scene::Scene;
use rayon::prelude::*;

/// Rays per work item when tracing on several threads: 64 tiles of 4×4.
pub const CHUNK: usize = 1024;

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

/// A traceable method of either tracer, bound to its scene.
pub struct Method<'a> {
    /// `raypack` or `embree`.
    pub tracer: &'static str,
    /// Method name, e.g. `rtcIntersect16 coherent (high)`.
    pub name: String,
    /// What it runs.
    pub run: Run<'a>,
}

/// A closest-hit function bound to its scene: one hit per ray.
pub type IntersectRays<'a> = Box<dyn Fn(&[Ray], &mut [Hit]) + Sync + 'a>;
/// An occlusion function bound to its scene: one flag per ray.
pub type OccludedRays<'a> = Box<dyn Fn(&[Ray], &mut [bool]) + Sync + 'a>;

/// A bound closest-hit or occlusion function.
pub enum Run<'a> {
    /// Closest hit of each ray.
    Intersect(IntersectRays<'a>),
    /// Occlusion of each ray.
    Occluded(OccludedRays<'a>),
}

impl Run<'_> {
    /// True for occlusion queries.
    pub fn is_occlusion(&self) -> bool {
        matches!(self, Run::Occluded(_))
    }
}

/// The kernels of [`crate::kernels::KERNELS`] bound to `scene` (on its ISA).
pub fn raypack_methods(scene: &Scene) -> Vec<Method<'_>> {
    raypack_methods_named(scene, "", true)
}

/// [`raypack_methods`] with `suffix` (e.g. ` (high)`) appended to every name; without
/// `reference`, the SIMD kernels only (the scalar reference is the same whatever the BVH8).
pub fn raypack_methods_named<'a>(scene: &'a Scene, suffix: &str, reference: bool) -> Vec<Method<'a>> {
    KERNELS
        .iter()
        .filter(|k| reference || k.simd)
        .map(|k| Method {
            tracer: "raypack",
            name: format!("{}{suffix}", k.name),
            run: match k.query {
                Query::Intersect(f) => Run::Intersect(Box::new(move |r, h| f(scene, r, h))),
                Query::Occluded(f) => Run::Occluded(Box::new(move |r, o| f(scene, r, o))),
            },
        })
        .collect()
}

/// Embree's calls on `e`: `rtcIntersect1/8/16`, `rtcOccluded1/8/16`, and the 8- and 16-wide
/// packet calls again with `RTC_INTERSECT_CONTEXT_FLAG_COHERENT`. `suffix` (e.g. ` (high)`)
/// is appended to every name.
#[cfg(feature = "embree")]
pub fn embree_methods<'a>(e: &'a crate::embree::EmbreeScene, suffix: &str) -> Vec<Method<'a>> {
    use crate::embree::EmbreeWidth::{W1, W8, W16};
    let mut out = Vec::new();
    for (width, coherent) in [(W1, false), (W8, false), (W16, false), (W8, true), (W16, true)] {
        let tag = if coherent { " coherent" } else { "" };
        let lanes = width.lanes();
        out.push(Method {
            tracer: "embree",
            name: format!("rtcIntersect{lanes}{tag}{suffix}"),
            run: Run::Intersect(Box::new(move |r, h| e.intersect(width, coherent, r, h))),
        });
        out.push(Method {
            tracer: "embree",
            name: format!("rtcOccluded{lanes}{tag}{suffix}"),
            run: Run::Occluded(Box::new(move |r, o| e.occluded(width, coherent, r, o))),
        });
    }
    out
}

/// The results of one method on one ray set.
#[derive(Clone, Debug, PartialEq)]
pub enum Output {
    /// Closest hits.
    Hits(Vec<Hit>),
    /// Occlusion flags.
    Occluded(Vec<bool>),
}

impl Output {
    /// The checksum of these results for `rays`.
    pub fn checksum(&self, rays: &[Ray]) -> Checksum {
        match self {
            Output::Hits(h) => Checksum::of_hits(h),
            Output::Occluded(o) => Checksum::of_occlusion(rays, o),
        }
    }
}

/// An output buffer of the right kind for `run`.
pub fn output_for(run: &Run<'_>, n: usize) -> Output {
    match run {
        Run::Intersect(_) => Output::Hits(vec![Hit::MISS; n]),
        Run::Occluded(_) => Output::Occluded(vec![false; n]),
    }
}

/// Traces `rays` with `run` into `out` on the current rayon pool, in contiguous chunks of
/// [`CHUNK`] rays, each chunk a rayon task of its own (as [`Scene::intersect_stream`] does:
/// with rayon's default split, a thread's last large task could leave the other idle;
/// PERFORMANCE.md, "Work split over threads").
///
/// # Panics
/// When `out` is of the other query kind or shorter than `rays`.
pub fn trace(run: &Run<'_>, rays: &[Ray], out: &mut Output) {
    match (run, out) {
        (Run::Intersect(f), Output::Hits(h)) => {
            rays.par_chunks(CHUNK).zip(h.par_chunks_mut(CHUNK)).with_max_len(1).for_each(|(r, h)| f(r, h))
        }
        (Run::Occluded(f), Output::Occluded(o)) => {
            rays.par_chunks(CHUNK).zip(o.par_chunks_mut(CHUNK)).with_max_len(1).for_each(|(r, o)| f(r, o))
        }
        _ => panic!("output buffer does not match the query"),
    }
}
