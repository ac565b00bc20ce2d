//! The registry of ray queries: every raypack kernel a user can call, by name, in one table
//! ([`KERNELS`]) that the benchmarks time, the kernel tests check against the scalar
//! reference and the Embree cross-check compares hit for hit; and the same kernels, and
//! Embree's calls, bound to their scene as [`Method`]s, traced over all threads by [`trace`].
//!
//! Every kernel and method has one contract: a slice of [`Ray`]s in, one result per ray out
//! ([`Results`]). Each SIMD kernel runs on every ISA tier the CPU has: set the scene's tier
//! with [`Scene::set_isa`] (the tiers to try are [`Isa::available`]) and call [`Kernel::run`].
//! Rays are spread over threads in contiguous chunks of whole 4×4 tiles
//! ([`crate::scene::STREAM_CHUNK`] rays, [`crate::scene::par_for_each_chunk`]). `raypack
//! bench`, the benchmarks and the Embree cross-check all trace through this module, so they
//! time and compare the same calls.
//!
//! The tree layout ([`crate::TreeLayout`]) is the scene's, as its ISA is: the same kernels run
//! on a compact tree through the scene built with it, or [`Scene::with_layout`]; the kernel
//! tests and the Embree cross-check run every kernel on both layouts, and `raypack bench
//! --layout default,compact` times both.
//!
//! ```
//! use raypack::kernels::{KERNELS, Results};
//! use raypack::{BuildOptions, Isa, Material, Ray, SceneBuilder, Vec3};
//!
//! let mut b = SceneBuilder::new();
//! let m = b.add_material(Material::default());
//! b.add_sphere(Vec3::ZERO, 1.0, m)?;
//! let (mut scene, _) = b.commit(&BuildOptions::default());
//! let rays: Vec<Ray> = (0..40).map(|i| Ray::new(Vec3::new(i as f32 * 0.05 - 1.0, 0.1, 5.0), -Vec3::Z)).collect();
//! for isa in Isa::available() {
//!     scene.set_isa(isa)?;
//!     for k in KERNELS {
//!         let mut out = Results::for_kernel(k, rays.len());
//!         k.run(&scene, &rays, &mut out);
//!         assert_eq!(out.hit_count(), 39, "{} on {isa}", k.name); // x = -1.0 grazes the sphere's edge and misses
//!     }
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::bvh::{NoCount, StreamKernel};
use crate::ray::{Hit, Ray, RayPacket8, RayPacket16};
use crate::raysets::Checksum;
use crate::scene::{Scene, StreamOptions, par_for_each_chunk};
#[cfg(doc)]
use crate::simd::Isa;

/// A closest-hit kernel over a slice of rays, on the calling thread.
pub type IntersectFn = fn(&Scene, &[Ray], &mut [Hit]);
/// An occlusion kernel over a slice of rays, on the calling thread.
pub type OccludedFn = fn(&Scene, &[Ray], &mut [bool]);

/// What a kernel answers.
#[derive(Clone, Copy, Debug)]
pub enum Query {
    /// The closest hit of each ray.
    Intersect(IntersectFn),
    /// Whether anything blocks each ray.
    Occluded(OccludedFn),
}

/// A named kernel.
#[derive(Clone, Copy, Debug)]
pub struct Kernel {
    /// Name in tables, JSON and test messages, e.g. `Scene::intersect16`.
    pub name: &'static str,
    /// The query and its function.
    pub query: Query,
    /// False for the scalar reference (the binary BVH), which is the same on every ISA.
    pub simd: bool,
}

impl Kernel {
    /// True for occlusion kernels.
    pub fn is_occlusion(&self) -> bool {
        matches!(self.query, Query::Occluded(_))
    }

    /// Traces `rays` on the calling thread into `out`, on the scene's ISA.
    ///
    /// # Panics
    /// When `out` holds the other query's results or its length differs from `rays`'.
    pub fn run(&self, scene: &Scene, rays: &[Ray], out: &mut Results) {
        match (self.query, out) {
            (Query::Intersect(f), Results::Hits(h)) => f(scene, rays, h),
            (Query::Occluded(f), Results::Occluded(o)) => f(scene, rays, o),
            _ => panic!("{}: results of the other query", self.name),
        }
    }
}

/// The results of one kernel or method on a ray set.
#[derive(Clone, Debug, PartialEq)]
pub enum Results {
    /// Closest hits.
    Hits(Vec<Hit>),
    /// Occlusion flags.
    Occluded(Vec<bool>),
}

impl Results {
    /// A buffer of `n` results of `kernel`'s query.
    pub fn for_kernel(kernel: &Kernel, n: usize) -> Results {
        match kernel.query {
            Query::Intersect(_) => Results::Hits(vec![Hit::MISS; n]),
            Query::Occluded(_) => Results::Occluded(vec![false; n]),
        }
    }

    /// A buffer of `n` results of `run`'s query.
    pub fn for_run(run: &Run<'_>, n: usize) -> Results {
        match run {
            Run::Intersect(_) => Results::Hits(vec![Hit::MISS; n]),
            Run::Occluded(_) => Results::Occluded(vec![false; n]),
        }
    }

    /// The checksum of these results for `rays`.
    pub fn checksum(&self, rays: &[Ray]) -> Checksum {
        match self {
            Results::Hits(h) => Checksum::of_hits(h),
            Results::Occluded(o) => Checksum::of_occlusion(rays, o),
        }
    }

    /// Rays that hit something (closest hit) or are blocked (occlusion).
    pub fn hit_count(&self) -> usize {
        match self {
            Results::Hits(h) => h.iter().filter(|h| h.is_hit()).count(),
            Results::Occluded(o) => o.iter().filter(|&&b| b).count(),
        }
    }
}

fn reference_intersect1(scene: &Scene, rays: &[Ray], hits: &mut [Hit]) {
    for (r, h) in rays.iter().zip(hits) {
        *h = scene.intersect1_reference(r);
    }
}

fn reference_occluded1(scene: &Scene, rays: &[Ray], out: &mut [bool]) {
    for (r, o) in rays.iter().zip(out) {
        *o = scene.occluded1_reference(r);
    }
}

fn intersect1(scene: &Scene, rays: &[Ray], hits: &mut [Hit]) {
    for (r, h) in rays.iter().zip(hits) {
        *h = scene.intersect1(r);
    }
}

fn occluded1(scene: &Scene, rays: &[Ray], out: &mut [bool]) {
    for (r, o) in rays.iter().zip(out) {
        *o = scene.occluded1(r);
    }
}

macro_rules! packet_kernels {
    ($intersect:ident, $occluded:ident, $packet:ty, $k:expr) => {
        fn $intersect(scene: &Scene, rays: &[Ray], hits: &mut [Hit]) {
            for (r, h) in rays.chunks($k).zip(hits.chunks_mut($k)) {
                let (mut p, valid) = <$packet>::from_rays(r);
                scene.$intersect(&mut p, valid);
                for (i, out) in h.iter_mut().enumerate() {
                    *out = p.hit(i);
                }
            }
        }

        fn $occluded(scene: &Scene, rays: &[Ray], out: &mut [bool]) {
            for (r, o) in rays.chunks($k).zip(out.chunks_mut($k)) {
                let (p, valid) = <$packet>::from_rays(r);
                let bits = scene.$occluded(&p, valid);
                for (i, x) in o.iter_mut().enumerate() {
                    *x = bits >> i & 1 != 0;
                }
            }
        }
    };
}

packet_kernels!(intersect8, occluded8, RayPacket8, 8);
packet_kernels!(intersect16, occluded16, RayPacket16, 16);

/// The registry's streams: on the calling thread (the registry's runs spread the rays
/// over threads themselves, [`trace`]).
const CALLER: StreamOptions = StreamOptions::CALLER;

fn intersect_stream(scene: &Scene, rays: &[Ray], hits: &mut [Hit]) {
    scene.intersect_stream(rays, hits, &CALLER);
}

fn intersect_interleaved(scene: &Scene, rays: &[Ray], hits: &mut [Hit]) {
    scene.intersect_stream(rays, hits, &CALLER.with_kernel(StreamKernel::Interleaved));
}

fn occluded_interleaved(scene: &Scene, rays: &[Ray], out: &mut [bool]) {
    scene.occluded_stream(rays, out, &CALLER.with_kernel(StreamKernel::Interleaved));
}

fn occluded_stream(scene: &Scene, rays: &[Ray], out: &mut [bool]) {
    scene.occluded_stream(rays, out, &CALLER);
}

/// Every ray query of [`Scene`], one line per kernel, the scalar references first. Packet
/// kernels receive consecutive rays (4 x 4 pixel tiles for camera rays); the stream kernels
/// are [`Scene::intersect_stream`] and [`Scene::occluded_stream`] on the calling thread, by
/// default ([`StreamKernel::Auto`]) and with every ray interleaved
/// ([`StreamKernel::Interleaved`], the rows named `_interleaved`).
pub const KERNELS: &[Kernel] = &[
    Kernel { name: "bvh2 reference intersect1", query: Query::Intersect(reference_intersect1), simd: false },
    Kernel { name: "bvh2 reference occluded1", query: Query::Occluded(reference_occluded1), simd: false },
    Kernel { name: "Scene::intersect1", query: Query::Intersect(intersect1), simd: true },
    Kernel { name: "Scene::occluded1", query: Query::Occluded(occluded1), simd: true },
    Kernel { name: "Scene::intersect8", query: Query::Intersect(intersect8), simd: true },
    Kernel { name: "Scene::occluded8", query: Query::Occluded(occluded8), simd: true },
    Kernel { name: "Scene::intersect16", query: Query::Intersect(intersect16), simd: true },
    Kernel { name: "Scene::occluded16", query: Query::Occluded(occluded16), simd: true },
    Kernel { name: "Scene::intersect_stream", query: Query::Intersect(intersect_stream), simd: true },
    Kernel { name: "Scene::occluded_stream", query: Query::Occluded(occluded_stream), simd: true },
    Kernel { name: "Scene::intersect_interleaved", query: Query::Intersect(intersect_interleaved), simd: true },
    Kernel { name: "Scene::occluded_interleaved", query: Query::Occluded(occluded_interleaved), simd: true },
];

/// The SIMD kernels of [`KERNELS`] (those that run on the scene's ISA).
pub fn simd_kernels() -> impl Iterator<Item = &'static Kernel> {
    KERNELS.iter().filter(|k| k.simd)
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

/// The kernels of [`KERNELS`] bound to `scene` (on its ISA).
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

/// Traces `rays` with `run` into `out` on the current rayon pool, in the stream queries'
/// chunks ([`par_for_each_chunk`]).
///
/// # Panics
/// When `out` is of the other query kind or shorter than `rays`.
pub fn trace(run: &Run<'_>, rays: &[Ray], out: &mut Results) {
    match (run, out) {
        (Run::Intersect(f), Results::Hits(h)) => par_for_each_chunk(rays, h, &mut NoCount, |r, h, _| f(r, h)),
        (Run::Occluded(f), Results::Occluded(o)) => par_for_each_chunk(rays, o, &mut NoCount, |r, o, _| f(r, o)),
        _ => panic!("output buffer does not match the query"),
    }
}
