//! Ray queries on a committed [`Scene`] beyond single rays: 8- and 16-ray packets and
//! streams of any length, on the calling thread or over rayon ([`StreamOptions`]), and the
//! same queries counting their work ([`Scene::counting`]).
//!
//! All of them use the hybrid packet kernels of [`crate::bvh::traverse_packet`], which adapt
//! to the rays they are given: a frustum prefilter when the packet's direction signs agree
//! (camera and shadow rays), per-lane box tests always, and single-ray traversal for subtrees
//! that only a few of the rays want (incoherent rays).
//!
//! Streams therefore trace every batch as 16-ray packets, coherent or not (single rays for
//! incoherent batches, and tiles of 4 packets under one frustum, were slower: PERFORMANCE.md,
//! "Streams"), but in a tree larger than the last-level cache ([`crate::bvh::Bvh8::interleaves`]):
//! there the rays of incoherent packets are traced as single rays, several in flight at once
//! so that their cache misses overlap ([`crate::bvh::traverse_interleaved`];
//! [`StreamOptions::kernel`] chooses the way whatever the tree). Shadow-ray streams also carry an
//! [`OccluderCache`](crate::bvh::traverse_packet::OccluderCache) from packet to packet.

use crate::bvh::{Counter, NoCount, StreamKernel};
use crate::math::Vec3;
use crate::ray::{Hit, Ray, RayPacket8, RayPacket16};
use crate::scene::Scene;
use rayon::prelude::*;

/// Runs `$body` with `$b` the kernels' view of `$scene`'s BVH8: its stored blocks, or, in a
/// compact tree, its id blocks with the scene store they are built from. The one branch on
/// the layout per query; each arm instantiates the kernels for its layout.
macro_rules! with_tree {
    ($scene:expr, $b:ident => $body:expr) => {{
        let scene: &Scene = $scene;
        if scene.bvh8.ids.is_empty() {
            let $b = scene.bvh8.slices_with(&scene.bvh8.tris[..]);
            $body
        } else {
            let $b = scene.bvh8.compact_slices(&scene.triangles.positions, &scene.triangles.indices);
            $body
        }
    }};
}

/// Rays per rayon task of the stream queries on the pool (64 packets of 16). Every chunk is a
/// task of its own (`with_max_len(1)`): rayon's default split stops at about two tasks per
/// thread and does not split a task once it runs, so a thread could finish its share of a
/// batch and wait for the other's last large task (PERFORMANCE.md, "Work split over threads").
pub const STREAM_CHUNK: usize = 1024;

/// On which threads a stream query runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Threads {
    /// Every thread of the current rayon pool, in chunks of [`STREAM_CHUNK`] rays.
    #[default]
    Pool,
    /// The calling thread only.
    Caller,
}

/// How [`Scene::intersect_stream`] and [`Scene::occluded_stream`] run: on which threads, and
/// with which kernel ([`StreamKernel`]; every kernel gives the same answers). The default is
/// [`StreamOptions::POOL`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StreamOptions {
    /// The threads.
    pub threads: Threads,
    /// The kernel.
    pub kernel: StreamKernel,
    /// Whether sphere hits get their surface coordinates `(u, v)` ([`crate::Hit`]), an
    /// `atan2` and an `acos` per hit; without, they are 0. Everything else about a hit is the
    /// same either way. The renderer does not read them.
    pub sphere_uv: bool,
}

impl Default for StreamOptions {
    fn default() -> Self {
        Self::POOL
    }
}

impl StreamOptions {
    /// Every thread of the pool, the kernel chosen by the tree's size (the default).
    pub const POOL: StreamOptions =
        StreamOptions { threads: Threads::Pool, kernel: StreamKernel::Auto, sphere_uv: true };
    /// The calling thread, the kernel chosen by the tree's size.
    pub const CALLER: StreamOptions =
        StreamOptions { threads: Threads::Caller, kernel: StreamKernel::Auto, sphere_uv: true };

    /// These options with `kernel`.
    pub const fn with_kernel(self, kernel: StreamKernel) -> StreamOptions {
        StreamOptions { kernel, ..self }
    }

    /// These options with sphere hits' `(u, v)` left 0.
    pub const fn without_sphere_uv(self) -> StreamOptions {
        StreamOptions { sphere_uv: false, ..self }
    }
}

/// Runs `f` on matching chunks of `items` and `out` (of [`STREAM_CHUNK`] items, each a rayon
/// task of its own) over the current rayon pool, each chunk counting its work into a counter
/// of its own; the chunks' counts are added into `counter`. The stream queries' and the kernel
/// registry's parallel loop ([`par_for_each_chunk_of`] with `out`'s chunks).
///
/// # Panics
/// When `out` is shorter than `items`.
pub fn par_for_each_chunk<A, B, C, F>(items: &[A], out: &mut [B], counter: &mut C, f: F)
where
    A: Sync,
    B: Send,
    C: Counter + Default + Send + std::ops::AddAssign,
    F: Fn(&[A], &mut [B], &mut C) + Sync,
{
    assert!(out.len() >= items.len(), "one answer per item");
    par_for_each_chunk_of(items, out.par_chunks_mut(STREAM_CHUNK), counter, f);
}

/// [`par_for_each_chunk`] with the outputs of each chunk given as a parallel iterator of
/// `items.len().div_ceil(STREAM_CHUNK)` values (for example several arrays' chunks zipped):
/// the one parallel loop of the stream queries, the kernel registry's runs and the Python
/// module's queries.
///
/// # Panics
/// When `out` yields fewer values than `items` has chunks.
pub fn par_for_each_chunk_of<A, O, C, F>(items: &[A], out: O, counter: &mut C, f: F)
where
    A: Sync,
    O: IndexedParallelIterator,
    C: Counter + Default + Send + std::ops::AddAssign,
    F: Fn(&[A], O::Item, &mut C) + Sync,
{
    assert!(out.len() >= items.len().div_ceil(STREAM_CHUNK), "one output per chunk");
    let total = items
        .par_chunks(STREAM_CHUNK)
        .zip(out)
        .with_max_len(1)
        .map(|(a, b)| {
            let mut c = C::default();
            f(a, b, &mut c);
            c
        })
        .reduce(C::default, |mut a, b| {
            a += b;
            a
        });
    *counter += total;
}

macro_rules! packet_queries {
    ($intersect:ident, $occluded:ident, $packet:ty, $mask:ty, $doc_k:expr) => {
        #[doc = concat!("Closest hits of the ", $doc_k, " rays in the lanes set in `valid` (see the packet type for the")]
        /// layout). Hit lanes get `tfar = t`, `u`, `v`, `prim`; missed lanes get
        /// `prim = Hit::NONE`; invalid rays ([`Ray::is_valid`]) miss; lanes outside `valid`
        /// are left as they are.
        ///
        /// ```
        /// # use raypack::{BuildOptions, Material, Ray, RayPacket8, RayPacket16, SceneBuilder, Vec3};
        /// let mut b = SceneBuilder::new();
        /// let m = b.add_material(Material::default());
        /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
        /// let (scene, _) = b.commit(&BuildOptions::default());
        /// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(i as f32 * 0.2, 0.0, 5.0), -Vec3::Z)).collect();
        #[doc = concat!("let (mut packet, valid) = ", stringify!($packet), "::from_rays(&rays);")]
        #[doc = concat!("scene.", stringify!($intersect), "(&mut packet, valid);")]
        /// assert_eq!(packet.hit(0).t, 4.0); // straight at the centre
        /// assert!(packet.hit(4).is_hit() && !packet.hit(6).is_hit()); // x = 0.8 hits, x = 1.2 misses
        /// # Ok::<(), raypack::SceneError>(())
        /// ```
        pub fn $intersect(&self, packet: &mut $packet, valid: $mask) {
            let before = self.has_spheres().then(|| *packet);
            with_tree!(self, b => b.intersect_packet_with(self.isa, packet, valid as u32, &mut NoCount));
            if let Some(before) = before {
                for i in crate::simd::bits(valid as u32) {
                    let mut h = packet.hit(i);
                    self.finish_hit(&before.ray(i), &mut h);
                    (packet.u[i], packet.v[i]) = (h.u, h.v);
                }
            }
        }

        #[doc = concat!("Which of the ", $doc_k, " rays in the lanes set in `valid` are blocked over `[tnear, tfar]`: bit")]
        /// `i` of the result is set for lane `i`. The packet is not modified; invalid rays are
        /// never blocked.
        ///
        /// ```
        /// # use raypack::{BuildOptions, Material, Ray, RayPacket8, RayPacket16, SceneBuilder, Vec3};
        /// let mut b = SceneBuilder::new();
        /// let m = b.add_material(Material::default());
        /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
        /// let (scene, _) = b.commit(&BuildOptions::default());
        /// // Two shadow rays from z = 5 toward z = -5: one through the sphere, one beside it.
        /// let rays = [Ray::segment(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z, 0.0, 10.0), Ray::segment(Vec3::new(2.0, 0.0, 5.0), -Vec3::Z, 0.0, 10.0)];
        #[doc = concat!("let (packet, valid) = ", stringify!($packet), "::from_rays(&rays);")]
        #[doc = concat!("assert_eq!(scene.", stringify!($occluded), "(&packet, valid), 0b01);")]
        /// # Ok::<(), raypack::SceneError>(())
        /// ```
        pub fn $occluded(&self, packet: &$packet, valid: $mask) -> $mask {
            with_tree!(self, b => b.occluded_packet_with(self.isa, packet, valid as u32, &mut NoCount)) as $mask
        }
    };
}

impl Scene {
    /// True when the streams interleave the single rays of incoherent packets: when what the
    /// kernels read (the BVH8, and in a compact tree the scene store's positions and indices
    /// its blocks are built from) is larger than the last-level cache
    /// ([`crate::bvh::Bvh8Ref::interleaves`]).
    pub fn interleaves(&self) -> bool {
        with_tree!(self, b => b.interleaves())
    }

    /// True when the single-ray closest-hit query speculates its descents (what the kernels
    /// read is small: [`crate::bvh::Bvh8Ref::speculates`]).
    pub fn speculates(&self) -> bool {
        with_tree!(self, b => b.speculates())
    }

    packet_queries!(intersect8, occluded8, RayPacket8, u8, "8");
    packet_queries!(intersect16, occluded16, RayPacket16, u16, "16");

    /// Closest hits of `rays` into `hits` (same length), on the threads and with the kernel
    /// of `opts`. By default ([`StreamOptions::POOL`]) over all threads of the rayon pool, as
    /// 16-ray packets in the order given, so consecutive rays should be coherent when they
    /// can be (camera rays in small pixel tiles, shadow rays of neighbouring pixels). The
    /// packet kernel adapts to incoherent rays by itself (see
    /// [`crate::bvh::traverse_packet`]); in a scene whose BVH is larger than the last-level
    /// cache, the rays of incoherent packets are traced as single rays several at a time
    /// instead ([`StreamKernel`]). The hits are [`Scene::intersect1`]'s.
    ///
    /// ```
    /// # use raypack::{BuildOptions, Hit, Material, Ray, SceneBuilder, StreamKernel, StreamOptions, Vec3};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
    /// let (scene, _) = b.commit(&BuildOptions::default());
    /// let rays: Vec<Ray> = (0..100).map(|i| Ray::new(Vec3::new(i as f32 * 0.01, 0.0, 5.0), -Vec3::Z)).collect();
    /// let mut hits = vec![Hit::MISS; rays.len()];
    /// scene.intersect_stream(&rays, &mut hits, &StreamOptions::POOL);
    /// assert!(hits.iter().all(|h| h.prim == 0 && h.t < 5.0));
    /// // On this thread only, every ray a single ray: the same hits.
    /// let mut again = vec![Hit::MISS; rays.len()];
    /// scene.intersect_stream(&rays, &mut again, &StreamOptions::CALLER.with_kernel(StreamKernel::Interleaved));
    /// assert_eq!(hits, again);
    /// # Ok::<(), raypack::SceneError>(())
    /// ```
    pub fn intersect_stream(&self, rays: &[Ray], hits: &mut [Hit], opts: &StreamOptions) {
        self.counting(&mut NoCount).intersect_stream(rays, hits, opts);
    }

    /// Occlusion of `rays` into `occluded` (same length), on the threads and with the kernel
    /// of `opts` (see [`Scene::intersect_stream`]); packets carry an
    /// [`OccluderCache`](crate::bvh::traverse_packet::OccluderCache) from one to the next.
    /// The answers are [`Scene::occluded1`]'s.
    ///
    /// ```
    /// # use raypack::{BuildOptions, Material, Ray, SceneBuilder, StreamOptions, Vec3};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
    /// let (scene, _) = b.commit(&BuildOptions::default());
    /// let rays: Vec<Ray> = (0..40).map(|i| Ray::segment(Vec3::new(i as f32 * 0.05 + 0.025, 0.0, 5.0), -Vec3::Z, 0.0, 10.0)).collect();
    /// let mut blocked = vec![false; rays.len()];
    /// scene.occluded_stream(&rays, &mut blocked, &StreamOptions::default());
    /// assert_eq!(blocked.iter().filter(|&&b| b).count(), 20); // x < 1 passes through the sphere
    /// # Ok::<(), raypack::SceneError>(())
    /// ```
    pub fn occluded_stream(&self, rays: &[Ray], occluded: &mut [bool], opts: &StreamOptions) {
        self.counting(&mut NoCount).occluded_stream(rays, occluded, opts);
    }

    /// The queries of this scene that add the kernels' work to `counter` (for example a
    /// [`crate::bvh::TraversalCounts`]); [`NoCount`] compiles away, and is what the
    /// scene's own query methods use.
    ///
    /// ```
    /// # use raypack::{BuildOptions, Material, Ray, SceneBuilder, TraversalCounts, Vec3};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
    /// let (scene, _) = b.commit(&BuildOptions::default());
    /// let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z);
    /// let mut counts = TraversalCounts::default();
    /// assert_eq!(scene.counting(&mut counts).intersect1(&ray), scene.intersect1(&ray));
    /// assert!(counts.blocks >= 1); // the hit was found by testing a block
    /// # Ok::<(), raypack::SceneError>(())
    /// ```
    pub fn counting<'a, C: Counter>(&'a self, counter: &'a mut C) -> Counting<'a, C> {
        Counting { scene: self, counter }
    }

    /// Could any ray from `origin` along a positive multiple of a vector in the box
    /// `[dir_lo, dir_hi]` hit the scene (a cone of rays, such as the camera rays through one
    /// pixel)? `false` is exact: none of those rays hits anything, whatever its length or
    /// interval. `true` may be conservative (a primitive's bounding box meets the cone), and
    /// is the answer whenever some component of the box can be 0.
    ///
    /// ```
    /// # use raypack::{BuildOptions, Material, SceneBuilder, Vec3};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
    /// let (scene, _) = b.commit(&BuildOptions::default());
    /// let eye = Vec3::new(0.0, 0.0, 5.0);
    /// // Towards the sphere, and well to its side.
    /// assert!(scene.cone_may_hit(eye, Vec3::new(0.01, 0.01, -1.0), Vec3::new(0.02, 0.02, -1.0)));
    /// assert!(!scene.cone_may_hit(eye, Vec3::new(0.5, 0.5, -1.0), Vec3::new(0.6, 0.6, -1.0)));
    /// # Ok::<(), raypack::SceneError>(())
    /// ```
    pub fn cone_may_hit(&self, origin: Vec3, dir_lo: Vec3, dir_hi: Vec3) -> bool {
        with_tree!(self, b => b.cone_may_hit_with(self.isa, origin, dir_lo, dir_hi))
    }
}

/// A scene's queries counting their work into a [`Counter`] ([`Scene::counting`]).
pub struct Counting<'a, C> {
    scene: &'a Scene,
    counter: &'a mut C,
}

impl<C: Counter> Counting<'_, C> {
    /// [`Scene::intersect1`], counted.
    #[inline]
    pub fn intersect1(&mut self, ray: &Ray) -> Hit {
        let s = self.scene;
        let mut hit = with_tree!(s, b => b.intersect1_with(s.isa, ray, self.counter));
        s.finish_hit(ray, &mut hit);
        hit
    }

    /// [`Scene::occluded1`], counted.
    #[inline]
    pub fn occluded1(&mut self, ray: &Ray) -> bool {
        let s = self.scene;
        with_tree!(s, b => b.occluded1_with(s.isa, ray, self.counter))
    }

    /// [`Scene::intersect_stream`], counted (on the pool, each chunk into a counter of its own,
    /// added up).
    pub fn intersect_stream(&mut self, rays: &[Ray], hits: &mut [Hit], opts: &StreamOptions)
    where
        C: Default + Send + std::ops::AddAssign,
    {
        assert_eq!(rays.len(), hits.len(), "one hit per ray");
        let (scene, kernel) = (self.scene, opts.kernel);
        let trace = |r: &[Ray], h: &mut [Hit], c: &mut C| {
            with_tree!(scene, b => b.intersect_stream_with(scene.isa, r, h, kernel, c));
            if opts.sphere_uv && scene.has_spheres() {
                for (ray, out) in r.iter().zip(h.iter_mut()) {
                    scene.finish_hit(ray, out);
                }
            }
        };
        match opts.threads {
            Threads::Caller => trace(rays, hits, self.counter),
            Threads::Pool => par_for_each_chunk(rays, hits, self.counter, trace),
        }
    }

    /// [`Scene::occluded_stream`], counted.
    pub fn occluded_stream(&mut self, rays: &[Ray], occluded: &mut [bool], opts: &StreamOptions)
    where
        C: Default + Send + std::ops::AddAssign,
    {
        assert_eq!(rays.len(), occluded.len(), "one answer per ray");
        let (scene, kernel) = (self.scene, opts.kernel);
        let trace = |r: &[Ray], o: &mut [bool], c: &mut C| with_tree!(scene, b => b.occluded_stream_with(scene.isa, r, o, kernel, c));
        match opts.threads {
            Threads::Caller => trace(rays, occluded, self.counter),
            Threads::Pool => par_for_each_chunk(rays, occluded, self.counter, trace),
        }
    }
}
