//! Render statistics: rays by kind, a sparse sample of them, and CS184's "intersection tests
//! per ray" measured on that sample with the reference traversal.

use crate::ray::Ray;
use crate::scene::Scene;

/// The kinds of rays a render traces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RayKind {
    /// Primary rays from the camera (closest hit).
    Camera = 0,
    /// Occlusion rays toward sampled lights (any hit).
    Shadow = 1,
    /// Closest-hit secondary rays: path continuations, and under `-H` the hemisphere rays of
    /// direct lighting.
    Bounce = 2,
}

impl RayKind {
    /// All kinds, in report order.
    pub const ALL: [RayKind; 3] = [RayKind::Camera, RayKind::Shadow, RayKind::Bounce];

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            RayKind::Camera => "camera",
            RayKind::Shadow => "shadow",
            RayKind::Bounce => "bounce",
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

    /// The count of one kind.
    pub fn of(&self, kind: RayKind) -> u64 {
        match kind {
            RayKind::Camera => self.camera,
            RayKind::Shadow => self.shadow,
            RayKind::Bounce => self.bounce,
        }
    }
}

impl std::ops::AddAssign for RayCounts {
    fn add_assign(&mut self, o: Self) {
        self.camera += o.camera;
        self.shadow += o.shadow;
        self.bounce += o.bounce;
    }
}

/// Keep one ray in this many of each kind (per tile, the first one always) for statistics.
const SAMPLE_EVERY: u64 = 997;
/// At most this many sampled rays of each kind per tile.
const SAMPLES_PER_TILE: usize = 16;

/// Per-tile ray bookkeeping: counts, and a sparse deterministic sample of the rays. Capacity
/// is reserved up front, so recording never allocates.
#[derive(Clone, Debug)]
pub struct RayLog {
    /// Rays traced by kind.
    pub counts: RayCounts,
    /// Sampled rays, indexed by `RayKind as usize`.
    pub sampled: [Vec<Ray>; 3],
}

impl Default for RayLog {
    fn default() -> Self {
        Self { counts: RayCounts::default(), sampled: std::array::from_fn(|_| Vec::with_capacity(SAMPLES_PER_TILE)) }
    }
}

impl RayLog {
    /// An empty log with room to merge the logs of `tiles` tiles without reallocating.
    pub fn for_tiles(tiles: usize) -> Self {
        Self {
            counts: RayCounts::default(),
            sampled: std::array::from_fn(|_| Vec::with_capacity(tiles * SAMPLES_PER_TILE)),
        }
    }

    /// Counts one ray of `kind` (and keeps it if it falls on the sampling grid).
    #[inline]
    pub fn record(&mut self, kind: RayKind, ray: &Ray) {
        let c = match kind {
            RayKind::Camera => &mut self.counts.camera,
            RayKind::Shadow => &mut self.counts.shadow,
            RayKind::Bounce => &mut self.counts.bounce,
        };
        let n = *c;
        *c += 1;
        if n % SAMPLE_EVERY == 0 {
            let s = &mut self.sampled[kind as usize];
            if s.len() < SAMPLES_PER_TILE {
                s.push(*ray);
            }
        }
    }

    /// Adds another log's counts and samples.
    pub fn merge(&mut self, o: RayLog) {
        self.counts += o.counts;
        for (a, b) in self.sampled.iter_mut().zip(o.sampled) {
            a.extend(b);
        }
    }
}

/// Mean primitive intersection tests per ray of `kind` over `rays`, with the scalar reference
/// traversal of the binary BVH (closest hit for camera and bounce rays, any hit for shadow
/// rays) — or, when the build did not keep it, a scalar near-to-far walk of the 8-wide BVH
/// counting the primitives of each leaf it opens — or the primitive count with brute force.
/// `None` without rays.
pub fn tests_per_ray(scene: &Scene, rays: &[Ray], kind: RayKind, brute_force: bool) -> Option<f64> {
    if rays.is_empty() {
        return None;
    }
    if brute_force {
        return Some(scene.num_prims() as f64);
    }
    let Some(bvh2) = scene.bvh2() else {
        let tests: u64 = rays.iter().map(|r| bvh8_tests(scene, r, kind == RayKind::Shadow)).sum();
        return Some(tests as f64 / rays.len() as f64);
    };
    let mut tests = 0u64;
    for ray in rays {
        match kind {
            RayKind::Shadow => {
                bvh2.occluded(ray, |prim| {
                    tests += 1;
                    scene.intersect_prim(prim, ray, ray.tfar).is_some()
                });
            }
            _ => {
                bvh2.intersect(ray, |prim, tfar| {
                    tests += 1;
                    scene.intersect_prim(prim, ray, tfar)
                });
            }
        }
    }
    Some(tests as f64 / rays.len() as f64)
}

/// Primitives tested by a scalar walk of the scene's 8-wide BVH (children visited near to
/// far, boxes re-tested against the shrinking `tfar`); stops at the first hit for `any_hit`.
fn bvh8_tests(scene: &Scene, ray: &Ray, any_hit: bool) -> u64 {
    use crate::bvh::LeafKind;
    use crate::bvh::bvh2::slab_test;
    let bvh = scene.bvh8();
    if !ray.is_valid() {
        return 0;
    }
    let inv = ray.inv_dir();
    let (mut tfar, mut tests) = (ray.tfar, 0u64);
    let mut stack = vec![(0usize, None)];
    while let Some((node, leaf)) = stack.pop() {
        if let Some(r) = leaf {
            let r: crate::bvh::NodeRef = r;
            for k in 0..r.block_count() {
                let b = r.first_block() + k;
                let prims: &[u32] = match r.kind() {
                    LeafKind::Triangles => &bvh.tris[b].prim,
                    LeafKind::Spheres => &bvh.spheres[b].prim,
                };
                let lanes = r.lanes_of_block(k, prims.len());
                for &prim in &prims[..lanes] {
                    tests += 1;
                    if let Some((t, _, _)) = scene.intersect_prim(prim, ray, tfar) {
                        if any_hit {
                            return tests;
                        }
                        tfar = t;
                    }
                }
            }
            continue;
        }
        let n = &bvh.nodes[node];
        // Children hit, far to near, so that the nearest is popped first.
        let (mut hits, mut count) = ([(0.0f32, 0usize); 8], 0);
        for k in (0..8).filter(|&k| !n.children[k].is_empty()) {
            if let Some(t) = slab_test(&n.child_bounds(k), ray.origin, inv, ray.tnear, tfar) {
                hits[count] = (t, k);
                count += 1;
            }
        }
        hits[..count].sort_by(|a, b| b.0.total_cmp(&a.0));
        for &(_, k) in &hits[..count] {
            let c = n.children[k];
            stack.push(if c.is_leaf() { (0, Some(c)) } else { (c.node_index(), None) });
        }
    }
    tests
}
