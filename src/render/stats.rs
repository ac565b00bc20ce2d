//! Render statistics, which the renderer keeps as it traces and the CLI prints after a render.
//!
//! * [`RayCounts`]: every ray handed to the trace kernels, by [`RayKind`]. Camera rays count
//!   only when traced: a camera sample that takes a miss's value untraced (its pixel's cone
//!   of rays misses the scene) is not a ray here. Shadow rays are light sampling's occlusion
//!   rays (a light sample that touches its point, or carries no light, has none); bounce rays
//!   are path continuations and, under `-H`, direct lighting's hemisphere rays.
//! * [`RayLog::sampled`]: of each kind, one ray in 997 in the order traced (the first one
//!   included), at most 16 per tile: the same rays whatever the thread count or batch sizes.
//! * [`tests_per_ray`]: CS184's "intersection tests per ray", the mean over those sampled
//!   rays of [`TraversalCounts::tests`] (inner nodes visited, each one ray against 8 boxes,
//!   plus primitive blocks tested), counted by tracing each sampled ray again alone through
//!   the single-ray kernels ([`crate::bvh::counters`]). It is the single-ray traversal's work
//!   for those rays, not the packet streams' that rendered them (the streams share node
//!   visits among the rays of a packet); with `--brute-force`, every primitive of the scene.

use crate::bvh::TraversalCounts;
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

/// Per-tile ray bookkeeping: the rays traced by kind, and one ray in `SAMPLE_EVERY` of each
/// kind (at most `SAMPLES_PER_TILE` per tile; see the module docs). Capacity is reserved up
/// front, so recording never allocates.
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

    /// Counts the rays of `rays` as rays of `kind`, keeping those that fall on the sampling
    /// grid (one ray in `SAMPLE_EVERY` of the kind, the first one included, at most
    /// `SAMPLES_PER_TILE` per log).
    #[inline]
    pub fn record(&mut self, kind: RayKind, rays: &[Ray]) {
        let c = match kind {
            RayKind::Camera => &mut self.counts.camera,
            RayKind::Shadow => &mut self.counts.shadow,
            RayKind::Bounce => &mut self.counts.bounce,
        };
        let n = *c;
        *c += rays.len() as u64;
        // The rays whose count `n + k` falls on the sampling grid.
        let first = ((SAMPLE_EVERY - n % SAMPLE_EVERY) % SAMPLE_EVERY) as usize;
        let s = &mut self.sampled[kind as usize];
        for ray in rays.iter().skip(first).step_by(SAMPLE_EVERY as usize) {
            if s.len() >= SAMPLES_PER_TILE {
                break;
            }
            s.push(*ray);
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

/// Mean intersection tests per ray of `kind` over `rays`, counted by the 8-wide BVH kernels
/// themselves ([`Scene::counting`]: `intersect1` for camera and bounce rays,
/// `occluded1` for shadow rays): node tests (each one ray against 8 boxes)
/// plus primitive-block tests, [`TraversalCounts::tests`]. With brute force every primitive is
/// one test. `None` without rays.
pub fn tests_per_ray(scene: &Scene, rays: &[Ray], kind: RayKind, brute_force: bool) -> Option<f64> {
    if rays.is_empty() {
        return None;
    }
    if brute_force {
        return Some(scene.num_prims() as f64);
    }
    let mut counts = TraversalCounts::default();
    for ray in rays {
        match kind {
            RayKind::Shadow => {
                scene.counting(&mut counts).occluded1(ray);
            }
            RayKind::Camera | RayKind::Bounce => {
                scene.counting(&mut counts).intersect1(ray);
            }
        }
    }
    Some(counts.tests() as f64 / rays.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BuildOptions;
    use crate::generate::grid;
    use crate::math::Vec3;
    use crate::scene::{Material, SceneBuilder};

    /// A 32 × 32 grid of 2048 triangles in the unit square of the z = 0 plane.
    fn grid_scene() -> Scene {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::default());
        let g = grid(32, 32);
        b.add_mesh(&g.positions, &g.indices, m).unwrap();
        b.commit(&BuildOptions::default()).0
    }

    #[test]
    fn tests_per_ray_counts_the_kernels_work() {
        let scene = grid_scene();
        let b = scene.bounds();
        let over = |x: f32, y: f32, dir: Vec3| Ray::new(Vec3::new(x, y, b.max.z + 1.0), dir);
        let xy =
            |i: usize| (b.min.x + (b.max.x - b.min.x) * (i as f32 + 0.5) / 64.0, b.min.y + 0.37 * (b.max.y - b.min.y));
        // Pointing away from the plane: the root's eight boxes are tested once, nothing else.
        let away: Vec<Ray> = (0..64).map(|i| over(xy(i).0, xy(i).1, Vec3::Z)).collect();
        for kind in RayKind::ALL {
            assert_eq!(tests_per_ray(&scene, &away, kind, false), Some(1.0), "{kind:?}");
        }
        // Straight down onto the grid: every ray hits, through at least the root and a block.
        let down: Vec<Ray> = (0..64).map(|i| over(xy(i).0, xy(i).1, -Vec3::Z)).collect();
        assert!(down.iter().all(|r| scene.intersect1(r).is_hit()));
        let closest = tests_per_ray(&scene, &down, RayKind::Camera, false).unwrap();
        let any = tests_per_ray(&scene, &down, RayKind::Shadow, false).unwrap();
        assert!(closest >= 2.0 && any >= 2.0, "{closest} {any}");
        // The any-hit kernel stops at its first hit, so it never does more than the closest-hit one.
        assert!(any <= closest, "{any} > {closest}");
        assert_eq!(tests_per_ray(&scene, &down, RayKind::Bounce, false), Some(closest));
        assert_eq!(tests_per_ray(&scene, &down, RayKind::Camera, true), Some(2048.0));
        assert_eq!(tests_per_ray(&scene, &[], RayKind::Camera, false), None);
    }

    #[test]
    fn the_log_keeps_every_997th_ray_whatever_the_runs_it_is_given_in() {
        let ray = |i: usize| Ray::new(Vec3::new(i as f32, 0.0, 0.0), Vec3::Z);
        let rays: Vec<Ray> = (0..20_000).map(ray).collect();
        for runs in [vec![20_000], vec![1; 3000], vec![996, 1, 1, 997, 5000, 3], vec![0, 997, 998, 1994, 7]] {
            let mut log = RayLog::default();
            let mut at = 0;
            for n in runs {
                log.record(RayKind::Shadow, &rays[at..at + n]);
                at += n;
            }
            assert_eq!(log.counts.shadow, at as u64);
            assert_eq!(log.counts.camera + log.counts.bounce, 0);
            let expect: Vec<Ray> = (0..at).step_by(997).take(SAMPLES_PER_TILE).map(ray).collect();
            assert_eq!(log.sampled[RayKind::Shadow as usize], expect);
        }
    }
}
