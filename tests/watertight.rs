//! Rays aimed exactly at the shared edges and vertices of closed meshes, in the manner of
//! Embree's `verify` watertight tests: with the watertight triangle test
//! (`BuildOptions::watertight`) no ray may pass through, in any kernel; with Möller–Trumbore
//! the pass-throughs are counted and printed (not asserted: that test is not watertight).
//!
//! Targets are vertices whose one-ring is closed and points on edges shared by two triangles
//! (the exact midpoint and two other fractions, all within rounding of the edge). Each ray
//! starts outside the bounding box and points along the mean of the incident faces' unit
//! normals, and only targets where every incident face faces the ray are used: the projected
//! fan then covers a neighbourhood of the target, so a ray passing within rounding of it must
//! hit there (a silhouette target could be missed legitimately). A ray *passes through* when
//! it misses, or its first hit lies beyond the target by more than a relative tolerance, or
//! (occlusion queries) it is not blocked before that point. On the sphere, rays from the
//! centre toward the same targets are added (every ray from inside a closed mesh must hit).

mod common;

use common::{every_kernel_where, scene_of, scenes_dir};
use raypack::generate::{Mesh, uv_sphere};
use raypack::kernels::Results;
use raypack::{BuildOptions, Ray, Scene, Vec3};
use std::collections::HashMap;

/// Relative distance beyond the target at which a first hit counts as a pass-through.
const T_TOLERANCE: f32 = 1e-3;

/// A ray aimed at a target at parameter `t_target` (directions are unit length).
#[derive(Clone, Copy, Debug)]
struct Aimed {
    ray: Ray,
    t_target: f32,
}

fn face_normal(m: &Mesh, t: [u32; 3]) -> Vec3 {
    let [a, b, c] = t.map(|i| m.positions[i as usize]);
    (b - a).cross(c - a).normalize_or_zero()
}

/// Rays at the shared edges and closed-ring vertices of `mesh` (every `stride`-th target).
fn aimed_rays(mesh: &Mesh, stride: usize) -> Vec<Aimed> {
    let mut edges: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (f, t) in mesh.indices.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            edges.entry((a.min(b), a.max(b))).or_default().push(f);
        }
    }
    let mut vertex_faces: Vec<Vec<usize>> = vec![Vec::new(); mesh.positions.len()];
    for (f, t) in mesh.indices.iter().enumerate() {
        for &v in t {
            vertex_faces[v as usize].push(f);
        }
    }
    let normals: Vec<Vec3> = mesh.indices.iter().map(|&t| face_normal(mesh, t)).collect();
    let (lo, hi) = mesh
        .positions
        .iter()
        .fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(l, h), p| (l.min(*p), h.max(*p)));
    let reach = (hi - lo).length() * 2.0;
    // The direction along which every face of `faces` is seen from the same side, if any.
    let facing = |faces: &[usize]| -> Option<Vec3> {
        let d = -faces.iter().map(|&f| normals[f]).sum::<Vec3>().normalize_or_zero();
        (d != Vec3::ZERO && faces.iter().all(|&f| normals[f].dot(d) < -0.05)).then_some(d)
    };
    let mut out = Vec::new();
    let mut aim = |target: Vec3, d: Vec3| {
        let origin = target - d * reach;
        let dir = (target - origin).normalize();
        out.push(Aimed { ray: Ray::new(origin, dir), t_target: (target - origin).length() });
    };
    // Vertices whose incident edges are all shared by exactly two faces (a closed one-ring).
    for (v, faces) in vertex_faces.iter().enumerate().step_by(stride) {
        let closed = faces.len() >= 3
            && faces.iter().all(|&f| {
                mesh.indices[f].iter().filter(|&&w| w as usize != v).all(|&w| {
                    let key = ((v as u32).min(w), (v as u32).max(w));
                    edges.get(&key).is_some_and(|fs| fs.len() == 2)
                })
            });
        if let (true, Some(d)) = (closed, facing(faces)) {
            aim(mesh.positions[v], d);
        }
    }
    let mut keys: Vec<_> = edges.iter().filter(|(_, fs)| fs.len() == 2).map(|(k, fs)| (*k, fs.clone())).collect();
    keys.sort_unstable();
    for ((a, b), faces) in keys.iter().step_by(stride) {
        let Some(d) = facing(faces) else { continue };
        let (pa, pb) = (mesh.positions[*a as usize], mesh.positions[*b as usize]);
        for f in [0.5, 0.25, 0.8125] {
            aim(pa + (pb - pa) * f, d);
        }
    }
    out
}

/// Rays from `center` toward the same targets as [`aimed_rays`] (for meshes enclosing it).
fn from_inside(aimed: &[Aimed], center: Vec3) -> Vec<Aimed> {
    aimed
        .iter()
        .map(|a| {
            let target = a.ray.at(a.t_target);
            Aimed { ray: Ray::new(center, (target - center).normalize()), t_target: (target - center).length() }
        })
        .collect()
}

/// Pass-through counts of every kernel of the registry, on every ISA tier, on `rays`, as
/// `(kernel name, count)`: closest-hit kernels trace the aimed rays, occlusion kernels
/// segments that end just beyond the target.
fn pass_throughs(scene: &Scene, rays: &[Aimed]) -> Vec<(String, usize)> {
    let limit = |a: &Aimed| a.t_target * (1.0 + T_TOLERANCE);
    let plain: Vec<Ray> = rays.iter().map(|a| a.ray).collect();
    let shadow: Vec<Ray> = rays.iter().map(|a| Ray::segment(a.ray.origin, a.ray.dir, 0.0, limit(a))).collect();
    let mut out = Vec::new();
    for (name, results) in every_kernel_where(scene, &plain, |k| !k.is_occlusion()) {
        let Results::Hits(h) = results else { unreachable!("closest-hit kernels") };
        out.push((name, rays.iter().zip(&h).filter(|(a, h)| !h.is_hit() || h.t > limit(a)).count()));
    }
    for (name, results) in every_kernel_where(scene, &shadow, |k| k.is_occlusion()) {
        let Results::Occluded(o) = results else { unreachable!("occlusion kernels") };
        out.push((name, o.iter().filter(|&&b| !b).count()));
    }
    out
}

/// Shoots `rays` at `mesh` with both triangle tests, prints the counts, and asserts none
/// passes through with the watertight test.
fn check(name: &str, mesh: &Mesh, rays: &[Aimed]) {
    assert!(rays.len() > 1000, "{name}: only {} rays", rays.len());
    for watertight in [false, true] {
        let scene = scene_of(&[mesh], &[], &BuildOptions { watertight, keep_bvh2: true, ..BuildOptions::default() });
        let counts = pass_throughs(&scene, rays);
        let test = scene.triangle_test().name();
        let list: Vec<String> = counts.iter().map(|(q, n)| format!("{q} {n}")).collect();
        eprintln!(
            "watertight: {name} ({} triangles), {} rays at edges and vertices, {test}: pass-throughs {}",
            scene.num_triangles(),
            rays.len(),
            list.join(", ")
        );
        if watertight {
            for (q, n) in &counts {
                assert_eq!(*n, 0, "{name}: {n} of {} rays passed through with the watertight test ({q})", rays.len());
            }
        }
    }
}

#[test]
fn no_ray_passes_through_a_tessellated_sphere() {
    let sphere = uv_sphere(160, 320).map_positions(|p| p * 3.0 + Vec3::new(0.3, -0.2, 0.1));
    let mut rays = aimed_rays(&sphere, 1);
    rays.extend(from_inside(&rays.clone(), Vec3::new(0.3, -0.2, 0.1)));
    check("uv sphere 160x320", &sphere, &rays);
}

#[test]
fn no_ray_passes_through_a_sphere_of_needles() {
    // Few rings, many segments: long thin triangles, and fans of needles at the poles.
    let sphere = uv_sphere(6, 4000).map_positions(|p| p * 0.01);
    let rays = aimed_rays(&sphere, 1);
    let inside = from_inside(&rays, Vec3::ZERO);
    check("needle sphere 6x4000", &sphere, &[rays, inside].concat());
}

#[test]
fn no_ray_passes_through_the_stanford_dragon() {
    let Some(dir) = scenes_dir("watertight dragon") else { return };
    let path = dir.join("models/stanford-dragon-871k.ply");
    let builder = raypack::io::load_scene(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).builder;
    let (loaded, _) = builder.commit(&BuildOptions { keep_bvh2: true, ..BuildOptions::default() });
    let mesh = Mesh { positions: loaded.triangles.positions.clone(), indices: loaded.triangles.indices.clone() };
    drop(loaded);
    let rays = aimed_rays(&mesh, 8);
    check("Stanford dragon", &mesh, &rays);
}

#[test]
fn watertight_bvh_round_trips_through_the_cache() {
    // The cache key covers `BuildOptions::watertight`, and a loaded BVH keeps the layout its
    // blocks were written in: the same answers as a fresh build, and no cross-over with the
    // Möller–Trumbore file of the same geometry.
    let mesh = uv_sphere(40, 80);
    let dir = tempfile::tempdir().expect("temp dir");
    let builder = || {
        let mut b = raypack::SceneBuilder::new();
        let m = b.add_material(raypack::Material::default());
        b.add_mesh(&mesh.positions, &mesh.indices, m).expect("valid mesh");
        b
    };
    let rays = aimed_rays(&mesh, 1);
    for watertight in [true, false, true] {
        let opts = BuildOptions { watertight, keep_bvh2: true, ..BuildOptions::default() };
        let (cached, _, report) = builder().commit_cached(&opts, dir.path());
        let (fresh, _) = builder().commit(&opts);
        assert_eq!(cached.triangle_test(), fresh.triangle_test());
        for a in &rays {
            let (x, y) = (cached.intersect1(&a.ray), fresh.intersect1(&a.ray));
            assert_eq!((x.prim, x.t.to_bits()), (y.prim, y.t.to_bits()), "loaded {}: {:?}", report.loaded, a.ray);
        }
    }
}
