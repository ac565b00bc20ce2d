//! The standard ray sets that tests, benchmarks and the SIMD kernels are measured on, all
//! deterministic functions of the scene and a seed:
//!
//! * [`primary`]: camera rays at `W × H`, one per pixel centre, ordered in 4×4 pixel tiles
//!   so that 8 or 16 consecutive rays form a coherent packet;
//! * [`diffuse_bounces`]: one cosine-distributed bounce per primary hit;
//! * [`shadow_rays`]: one ray per primary hit toward a point light ([`light_above`]),
//!   ending just short of it (an occlusion query);
//! * [`random_through_bounds`]: incoherent rays from a sphere around the scene through
//!   random points of its bounding box;
//! * [`edges_and_vertices`]: rays aimed exactly at vertices and shared edges of the mesh,
//!   where non-watertight tests and sloppy traversal disagree.
//!
//! Secondary rays start at the hit point computed from barycentrics and pushed off the
//! surface with the integer-ulp offset of Wächter & Binder, "A Fast and Robust Method for
//! Avoiding Self-Intersection", Ray Tracing Gems (2019), chapter 6, so no tracer can hit
//! the surface the ray leaves.

use crate::math::{Aabb, Vec3, orthonormal_basis};
use crate::ray::{Hit, Ray};
use crate::rng::Rng;
use crate::scene::{Camera, Scene};

/// Side of the square pixel tiles that primary rays are ordered in.
pub const TILE: usize = 4;

/// Bytes per primary ray that `raypack bench` holds at once: the three ray sets (primary,
/// diffuse bounces, shadow rays), the reference hits they are made from, and the reference
/// and timed outputs. With [`crate::system::check_fits`], it refuses a ray set that cannot fit.
pub const BENCH_BYTES_PER_PIXEL: u64 = (3 * std::mem::size_of::<Ray>() + 3 * std::mem::size_of::<Hit>()) as u64;

/// Which of the standard sets a [`RaySet`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RaySetKind {
    /// Camera rays in 4×4 tiles.
    Primary,
    /// Cosine-distributed bounces from primary hits.
    Diffuse,
    /// Rays from primary hits toward a point light.
    Shadow,
    /// Random rays through the bounding box.
    Random,
    /// Rays aimed at mesh vertices and edges.
    EdgesVertices,
    /// Rays read from a ray file ([`crate::io::rays`]), traced as closest-hit rays.
    File,
}

impl RaySetKind {
    /// Short lower-case name, as printed in tables and JSON.
    pub fn name(self) -> &'static str {
        match self {
            RaySetKind::Primary => "primary",
            RaySetKind::Diffuse => "diffuse",
            RaySetKind::Shadow => "shadow",
            RaySetKind::Random => "random",
            RaySetKind::EdgesVertices => "edges",
            RaySetKind::File => "file",
        }
    }

    /// True for sets that a renderer traces with an occlusion (any-hit) query.
    pub fn is_occlusion(self) -> bool {
        self == RaySetKind::Shadow
    }
}

/// A named set of rays.
#[derive(Clone, Debug, PartialEq)]
pub struct RaySet {
    /// Which set.
    pub kind: RaySetKind,
    /// The rays.
    pub rays: Vec<Ray>,
}

/// Hit count and sum of `t` over a set's results: two numbers that any two tracers must
/// (nearly) agree on.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Checksum {
    /// Rays that hit (or, for occlusion, were occluded).
    pub hits: u64,
    /// Sum of `t` over the hits (for occlusion: sum of `tfar` over the occluded rays).
    pub t_sum: f64,
}

impl Checksum {
    /// Of closest-hit results.
    pub fn of_hits(hits: &[Hit]) -> Self {
        let mut c = Checksum::default();
        for h in hits.iter().filter(|h| h.is_hit()) {
            c.hits += 1;
            c.t_sum += h.t as f64;
        }
        c
    }

    /// Of occlusion results for `rays`.
    pub fn of_occlusion(rays: &[Ray], occluded: &[bool]) -> Self {
        let mut c = Checksum::default();
        for (r, _) in rays.iter().zip(occluded).filter(|(_, o)| **o) {
            c.hits += 1;
            c.t_sum += r.tfar as f64;
        }
        c
    }
}

impl std::fmt::Display for Checksum {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} hits, t-sum {:.6e}", self.hits, self.t_sum)
    }
}

/// The pixel coordinates of ray `i` of [`primary`] at `width × height`: row-major 4×4 tiles,
/// row-major pixels inside each tile; tiles on the right and bottom border are clipped.
pub fn tile_order(width: usize, height: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::with_capacity(width * height);
    for ty in (0..height).step_by(TILE) {
        for tx in (0..width).step_by(TILE) {
            for y in ty..(ty + TILE).min(height) {
                for x in tx..(tx + TILE).min(width) {
                    out.push((x, y));
                }
            }
        }
    }
    out
}

/// One camera ray through the centre of every pixel, in [`tile_order`]. Row 0 is the top
/// of the image.
pub fn primary(camera: &Camera, width: usize, height: usize) -> Vec<Ray> {
    let (w, h) = (width as f32, height as f32);
    tile_order(width, height)
        .into_iter()
        .map(|(x, y)| camera.generate_ray((x as f32 + 0.5) / w, 1.0 - (y as f32 + 0.5) / h))
        .collect()
}

/// [`primary`] from the scene's camera, or one framing the scene.
pub fn primary_for_scene(scene: &Scene, width: usize, height: usize) -> Vec<Ray> {
    primary(&scene.camera_or_framing(width as f32 / height as f32), width, height)
}

/// Pushes `p` off a surface with unit normal `n` (pointing to the side the new ray leaves
/// on) by a few ulps of each coordinate, or by a fixed tiny distance near the origin
/// (Wächter & Binder 2019).
#[inline]
pub fn offset_off_surface(p: Vec3, n: Vec3) -> Vec3 {
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    let step = |p: f32, n: f32| {
        let of = (INT_SCALE * n) as i32;
        let bits = p.to_bits() as i32;
        let moved = f32::from_bits(bits.wrapping_add(if p < 0.0 { -of } else { of }) as u32);
        if p.abs() < ORIGIN { p + FLOAT_SCALE * n } else { moved }
    };
    Vec3::new(step(p.x, n.x), step(p.y, n.y), step(p.z, n.z))
}

/// The hit point and unit geometric normal (facing the side `ray` came from) of a hit. For
/// triangles the point is interpolated from the barycentrics, which is more accurate than
/// `origin + t dir`.
pub fn hit_point(scene: &Scene, ray: &Ray, hit: &Hit) -> (Vec3, Vec3) {
    let surface = scene.surface(ray, hit);
    let nt = scene.num_triangles();
    let p = if (hit.prim as usize) < nt {
        let [a, b, c] = scene.triangles.vertices(hit.prim as usize);
        a * (1.0 - hit.u - hit.v) + b * hit.u + c * hit.v
    } else {
        surface.position
    };
    let n = surface.geometric_normal;
    (p, if n.dot(ray.dir) > 0.0 { -n } else { n })
}

/// One cosine-distributed bounce from each primary hit (`rays[i]` with `hits[i]`), leaving
/// on the side the primary ray came from. Misses produce no ray.
pub fn diffuse_bounces(scene: &Scene, rays: &[Ray], hits: &[Hit], seed: u64) -> Vec<Ray> {
    let mut out = Vec::new();
    for (i, (ray, hit)) in rays.iter().zip(hits).enumerate() {
        if !hit.is_hit() {
            continue;
        }
        let (p, n) = hit_point(scene, ray, hit);
        let mut rng = Rng::new(seed, i as u64);
        let (u1, u2) = rng.next_2d();
        // Malley's method: uniform on the disk, projected up to the hemisphere.
        let r = u1.sqrt();
        let phi = std::f32::consts::TAU * u2;
        let (t, b) = orthonormal_basis(n);
        let z = (1.0 - u1).max(0.0).sqrt();
        let dir = (t * (r * phi.cos()) + b * (r * phi.sin()) + n * z).normalize_or(n);
        out.push(Ray::new(offset_off_surface(p, n), dir));
    }
    out
}

/// A point light above the scene: over the centre of its bounds (slightly off-axis, to
/// avoid rays exactly along mesh edges), at half the diagonal above the top (`+y`).
pub fn light_above(bounds: &Aabb) -> Vec3 {
    if !bounds.is_valid() {
        return Vec3::new(0.1, 10.0, 0.07);
    }
    let diag = bounds.extent().length().max(1e-3);
    let c = bounds.center();
    Vec3::new(c.x + 0.11 * diag, bounds.max.y + 0.5 * diag, c.z + 0.07 * diag)
}

/// One ray from each primary hit toward `light`, with unit direction and `tfar` just short
/// of the light (`(1 - 1e-4)` of the distance). Misses produce no ray.
pub fn shadow_rays(scene: &Scene, rays: &[Ray], hits: &[Hit], light: Vec3) -> Vec<Ray> {
    let mut out = Vec::new();
    for (ray, hit) in rays.iter().zip(hits) {
        if !hit.is_hit() {
            continue;
        }
        let (p, n) = hit_point(scene, ray, hit);
        let to_light = light - p;
        // Leave on the light's side of the surface (the ray starts on the surface).
        let n = if n.dot(to_light) < 0.0 { -n } else { n };
        let origin = offset_off_surface(p, n);
        let d = light - origin;
        let dist = d.length();
        if dist > 0.0 && dist.is_finite() {
            out.push(Ray::segment(origin, d / dist, 0.0, dist * (1.0 - 1e-4)));
        }
    }
    out
}

/// `n` incoherent rays: origins uniform on a sphere of radius one bounding-box diagonal
/// around the box centre, each aimed at a uniform random point of the box.
pub fn random_through_bounds(bounds: &Aabb, n: usize, seed: u64) -> Vec<Ray> {
    let b = if bounds.is_valid() { *bounds } else { Aabb::new(-Vec3::ONE, Vec3::ONE) };
    let (c, e) = (b.center(), b.extent());
    let radius = e.length().max(1e-3);
    (0..n)
        .map(|i| {
            let mut rng = Rng::new(seed, i as u64);
            let origin = c + uniform_sphere(&mut rng) * radius;
            let target = b.min + e * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            Ray::new(origin, (target - origin).normalize_or(Vec3::X))
        })
        .collect()
}

fn uniform_sphere(rng: &mut Rng) -> Vec3 {
    let z = 1.0 - 2.0 * rng.next_f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = std::f32::consts::TAU * rng.next_f32();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Up to `n` rays aimed exactly at mesh features of the scene's triangles: cycling through a
/// vertex, an edge midpoint, a random point on an edge and a vertex again, each from a
/// random direction at least 17° off the triangle's plane (every fourth along the axis
/// closest to the normal, the classic crack test for axis-aligned grids), starting a random
/// distance of `0.25 .. 0.75` scene diagonals away. Empty for a scene without triangles.
pub fn edges_and_vertices(scene: &Scene, n: usize, seed: u64) -> Vec<Ray> {
    let nt = scene.num_triangles();
    if nt == 0 {
        return Vec::new();
    }
    let diag = scene.bounds().extent().length().max(1e-3);
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut rng = Rng::new(seed, i as u64);
        let tri = (rng.next_u32() as usize) % nt;
        let v = scene.triangles.vertices(tri);
        let k = (rng.next_u32() % 3) as usize;
        let (a, b) = (v[k], v[(k + 1) % 3]);
        let target = match i % 4 {
            0 | 3 => a,
            1 => a + (b - a) * 0.5,
            _ => a + (b - a) * rng.next_f32(),
        };
        let normal = (v[1] - v[0]).cross(v[2] - v[0]).normalize_or(Vec3::Z);
        let side = if rng.next_f32() < 0.5 { 1.0 } else { -1.0 };
        let dir = if i % 4 == 3 {
            let axis = normal.abs().max_position();
            let mut d = Vec3::ZERO;
            d[axis] = -normal[axis].signum() * side;
            d
        } else {
            loop {
                let d = uniform_sphere(&mut rng);
                if d.dot(normal).abs() >= 0.3 {
                    break d;
                }
            }
        };
        let dist = diag * (0.25 + 0.5 * rng.next_f32());
        out.push(Ray::new(target - dir * dist, dir));
    }
    out
}

/// The three sets that `raypack bench` times: primary rays at `width × height`, and the
/// diffuse bounces and shadow rays of their hits. The hits come from the reference traversal
/// of the binary BVH when the scene kept it ([`crate::BuildOptions::keep_bvh2`]), else from
/// the BVH8 kernel, which the tests hold equal to it: the reference without a binary BVH tests
/// every primitive, hours on a million triangles.
pub fn bench_sets(scene: &Scene, width: usize, height: usize, seed: u64) -> [RaySet; 3] {
    let primary = primary_for_scene(scene, width, height);
    let hits: Vec<Hit> = match scene.bvh2() {
        Some(_) => primary.iter().map(|r| scene.intersect1_reference(r)).collect(),
        None => primary.iter().map(|r| scene.intersect1(r)).collect(),
    };
    let diffuse = diffuse_bounces(scene, &primary, &hits, seed);
    let shadow = shadow_rays(scene, &primary, &hits, light_above(&scene.bounds()));
    [
        RaySet { kind: RaySetKind::Primary, rays: primary },
        RaySet { kind: RaySetKind::Diffuse, rays: diffuse },
        RaySet { kind: RaySetKind::Shadow, rays: shadow },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::grid;
    use crate::{BuildOptions, Material, SceneBuilder};

    /// An 8 × 8 grid in the plane z = 0, material 0.
    fn grid_builder() -> SceneBuilder {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::default());
        let g = grid(8, 8);
        b.add_mesh(&g.positions, &g.indices, m).unwrap();
        b
    }

    fn grid_scene() -> Scene {
        grid_builder().commit(&BuildOptions::default()).0
    }

    #[test]
    fn tiles_cover_every_pixel_once() {
        for (w, h) in [(8, 4), (10, 7), (1, 1)] {
            let mut order = tile_order(w, h);
            assert_eq!(order.len(), w * h);
            assert!(order[..order.len().min(4)].iter().all(|&(_, y)| y == 0));
            order.sort_by_key(|&(x, y)| (y, x));
            order.dedup();
            assert_eq!(order.len(), w * h);
        }
        // The first 16 rays at 8x8 are exactly the top-left 4x4 tile.
        assert!(tile_order(8, 8)[..16].iter().all(|&(x, y)| x < 4 && y < 4));
    }

    #[test]
    fn offset_leaves_the_surface_on_the_normal_side() {
        for p in [Vec3::new(0.5, -0.25, 0.0), Vec3::new(1e6, -1e6, 3.0), Vec3::ZERO] {
            for n in [Vec3::Z, -Vec3::Z, Vec3::new(0.6, 0.0, -0.8)] {
                let q = offset_off_surface(p, n);
                assert!((q - p).dot(n) > 0.0, "{p} {n} -> {q}");
                assert!((q - p).length() <= 1e-3 * p.abs().max_element().max(1.0));
            }
        }
    }

    #[test]
    fn secondary_rays_leave_the_surface_and_do_not_self_hit() {
        let scene = grid_scene();
        let cam = Camera::look_at(Vec3::new(0.3, 0.4, 3.0), Vec3::ZERO, Vec3::Y, 40.0, 1.0, 0.01, 100.0);
        let rays = primary(&cam, 32, 32);
        let hits: Vec<Hit> = rays.iter().map(|r| scene.intersect1(r)).collect();
        let n_hits = hits.iter().filter(|h| h.is_hit()).count();
        assert!(n_hits > 500);
        let bounces = diffuse_bounces(&scene, &rays, &hits, 1);
        assert_eq!(bounces.len(), n_hits);
        // A single plane: a bounce off it can never hit it again.
        assert!(bounces.iter().all(|r| !scene.occluded1(r) && r.dir.z > 0.0));
        let light = light_above(&scene.bounds());
        let shadows = shadow_rays(&scene, &rays, &hits, light);
        assert!(shadows.iter().all(|r| !scene.occluded1(r) && (r.at(r.tfar) - light).length() < 1e-3));
        assert_eq!(Checksum::of_occlusion(&shadows, &vec![false; shadows.len()]).hits, 0);
    }

    #[test]
    fn bench_sets_are_the_same_with_or_without_the_binary_bvh() {
        let mut b = grid_builder();
        b.add_sphere(Vec3::new(0.2, 0.1, 0.3), 0.25, 0).unwrap();
        let lean = b.clone().commit(&BuildOptions::default()).0;
        let kept = b.commit(&BuildOptions { keep_bvh2: true, ..BuildOptions::default() }).0;
        assert!(lean.bvh2().is_none() && kept.bvh2().is_some());
        let (a, b) = (bench_sets(&lean, 48, 32, 5), bench_sets(&kept, 48, 32, 5));
        assert!(a[1].rays.len() > 300, "a diffuse ray per primary hit: {}", a[1].rays.len());
        for (a, b) in a.iter().zip(&b) {
            assert_eq!(a.rays, b.rays, "{}", a.kind.name());
        }
    }

    #[test]
    fn edge_rays_hit_the_features_they_aim_at() {
        let scene = grid_scene();
        let rays = edges_and_vertices(&scene, 400, 3);
        assert_eq!(rays.len(), 400);
        // Every ray passes through a point of the grid plane z = 0 inside [-1, 1]^2.
        for r in &rays {
            let t = -r.origin.z / r.dir.z;
            let p = r.at(t);
            assert!(p.x.abs() <= 1.0 + 1e-5 && p.y.abs() <= 1.0 + 1e-5 && p.z.abs() < 1e-5, "{r:?}");
        }
        assert_eq!(edges_and_vertices(&scene, 50, 3), edges_and_vertices(&scene, 50, 3));
    }

    #[test]
    fn random_rays_pass_through_the_box() {
        let b = Aabb::new(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(3.0, 1.0, 2.5));
        for r in random_through_bounds(&b, 1000, 7) {
            let t = crate::bvh::bvh2::slab_test(&b, r.origin, r.inv_dir(), 0.0, f32::INFINITY);
            assert!(t.is_some(), "{r:?}");
        }
    }

    #[test]
    fn checksums_count_hits() {
        let hits = [Hit::MISS, Hit { t: 2.0, u: 0.0, v: 0.0, prim: 3 }, Hit { t: 0.5, u: 0.0, v: 0.0, prim: 0 }];
        assert_eq!(Checksum::of_hits(&hits), Checksum { hits: 2, t_sum: 2.5 });
    }
}
