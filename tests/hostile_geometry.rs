//! Hostile geometry: zero-area, sliver and duplicate triangles, everything at one point, empty
//! and one-primitive scenes, coordinates up to 1e18, NaN/Inf vertices.
//!
//! For each scene, with both triangle tests: `commit` terminates and drops (and counts) what
//! cannot be traced — NaN/Inf or beyond-`MAX_COORDINATE` vertices, zero-area triangles —, both
//! trees pass their structural validators, and every query (single rays, 8/16-ray packets,
//! streams, closest and any hit) answers what brute force answers: the same hit or miss and
//! the same `t`, bit for bit. (Triangle soups, a single triangle and all-at-one-point leaves
//! are also built in `tests/bvh_vs_bruteforce.rs` and `tests/bvh8.rs`; these cases add the
//! BVH8 kernels, both triangle tests, the drop counts and the extreme magnitudes.)

mod common;

use common::random_rays;
use raypack::bvh::validate::{validate_bvh2, validate_bvh8};
use raypack::generate::{Mesh, grid, random_soup, uv_sphere};
use raypack::scene::builder::MAX_COORDINATE;
use raypack::{BuildOptions, CommitReport, Hit, Material, Ray, RayPacket16, Scene, SceneBuilder, StreamOptions, Vec3};

/// Commits triangles (`mesh`) and spheres with both triangle tests.
fn commit_both(mesh: &Mesh, spheres: &[(Vec3, f32)]) -> Vec<(Scene, CommitReport)> {
    [false, true]
        .into_iter()
        .map(|watertight| {
            let mut b = SceneBuilder::new();
            let m = b.add_material(Material::default());
            b.add_mesh(&mesh.positions, &mesh.indices, m).expect("indices in range");
            for &(c, r) in spheres {
                // Invalid spheres are refused here or dropped at commit; either way not traced.
                let _ = b.add_sphere(c, r, m);
            }
            b.commit(&BuildOptions { watertight, keep_bvh2: true, ..BuildOptions::default() })
        })
        .collect()
}

/// Validates both trees and checks every query against brute force on `rays`; returns the
/// number of hits.
fn check(what: &str, scene: &Scene, rays: &[Ray]) -> usize {
    let test = scene.triangle_test().name();
    let bounds: Vec<_> = (0..scene.num_prims() as u32).map(|p| scene.prim_bounds(p)).collect();
    validate_bvh2(scene.bvh2().expect("binary BVH kept"), &bounds)
        .unwrap_or_else(|e| panic!("{what} ({test}): BVH2: {e}"));
    validate_bvh8(scene.bvh8(), &bounds).unwrap_or_else(|e| panic!("{what} ({test}): BVH8: {e}"));
    let want: Vec<Hit> = rays.iter().map(|r| scene.intersect1_brute_force(r)).collect();
    let same = |q: &str, i: usize, got: &Hit| {
        let w = &want[i];
        assert_eq!(got.is_hit(), w.is_hit(), "{what} ({test}) {q} ray {i} {:?}: got {got:?} want {w:?}", rays[i]);
        if w.is_hit() {
            assert_eq!(got.t.to_bits(), w.t.to_bits(), "{what} ({test}) {q} ray {i}: t {} vs {}", got.t, w.t);
            assert!(got.u.is_finite() && got.v.is_finite(), "{what} ({test}) {q} ray {i}: u, v");
            assert!(got.t.is_finite(), "{what} ({test}) {q} ray {i}: t {}", got.t);
        }
    };
    for (i, r) in rays.iter().enumerate() {
        same("reference", i, &scene.intersect1_reference(r));
        same("intersect1", i, &scene.intersect1(r));
        assert_eq!(scene.occluded1(r), want[i].is_hit(), "{what} ({test}) occluded1 ray {i}");
    }
    for (c, chunk) in rays.chunks(16).enumerate() {
        let (mut p, valid) = RayPacket16::from_rays(chunk);
        let occ = scene.occluded16(&p, valid);
        scene.intersect16(&mut p, valid);
        for k in 0..chunk.len() {
            same("intersect16", c * 16 + k, &p.hit(k));
            assert_eq!(occ >> k & 1 != 0, want[c * 16 + k].is_hit(), "{what} ({test}) occluded16 ray {}", c * 16 + k);
        }
    }
    let mut hits = vec![Hit::MISS; rays.len()];
    scene.intersect_stream(rays, &mut hits, &StreamOptions::POOL);
    let mut occ = vec![false; rays.len()];
    scene.occluded_stream(rays, &mut occ, &StreamOptions::POOL);
    for i in 0..rays.len() {
        same("intersect_stream", i, &hits[i]);
        assert_eq!(occ[i], want[i].is_hit(), "{what} ({test}) occluded_stream ray {i}");
    }
    want.iter().filter(|h| h.is_hit()).count()
}

/// Triangles as separate vertex triples.
fn soup(tris: &[[Vec3; 3]]) -> Mesh {
    let mut m = Mesh::default();
    for t in tris {
        let b = m.positions.len() as u32;
        m.positions.extend_from_slice(t);
        m.indices.push([b, b + 1, b + 2]);
    }
    m
}

/// Rays toward random points of `scene`'s box, plus rays straight at each listed point.
fn rays_for(scene: &Scene, n: usize, points: &[Vec3]) -> Vec<Ray> {
    let mut rays = random_rays(scene, n, 17);
    let b = scene.bounds();
    let far = if b.is_valid() { b.extent().max_element().max(1.0) * 3.0 } else { 3.0 };
    for (i, p) in points.iter().enumerate() {
        let d = Vec3::new(0.3 + (i % 7) as f32 * 0.1, -0.7, 0.2 + (i % 3) as f32 * 0.3).normalize();
        rays.push(Ray::new(*p - d * far, d));
    }
    rays
}

#[test]
fn zero_area_slivers_and_duplicates() {
    let mut rng = raypack::rng::Rng::new(3, 9);
    let mut r3 = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
    let mut tris = Vec::new();
    let (mut zero, mut slivers) = (0, 0);
    for i in 0..3000 {
        let (p, d, e) = (r3(), r3() * 0.1, r3() * 0.1);
        let perp = d.cross(e).cross(d).normalize_or(Vec3::Z) * d.length();
        let t = match i % 6 {
            0 => [p, p, p + d],                         // repeated vertex: zero area
            1 => [p, p + d, p + d * 2.0],               // collinear up to rounding
            2 => [p, p + d, p + d * 0.5 + perp * 1e-5], // sliver
            3 => [p, p + d * 1e-4, p + e],              // needle
            _ => [p, p + d, p + e],
        };
        zero += (i % 6 < 2) as usize;
        slivers += (i % 6 == 2) as usize;
        tris.push(t);
    }
    // 300 copies of one triangle.
    let dup = [Vec3::new(-0.5, -0.5, 0.1), Vec3::new(0.5, -0.4, 0.1), Vec3::new(0.0, 0.6, 0.12)];
    tris.extend(std::iter::repeat_n(dup, 300));
    let mesh = soup(&tris);
    for (scene, report) in commit_both(&mesh, &[]) {
        // Repeated-vertex triangles and most "collinear" ones (those whose rounded corners are
        // collinear within rounding) are dropped; slivers and needles are kept.
        assert!((zero / 2 + zero / 4..=zero).contains(&report.dropped_degenerate), "{report}");
        assert_eq!(report.triangles + report.dropped_degenerate, tris.len(), "{report}: {slivers} slivers kept");
        let points: Vec<Vec3> = tris.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect();
        let rays = rays_for(&scene, 20_000, &points);
        let hits = check("zero-area/sliver/duplicate soup", &scene, &rays);
        eprintln!(
            "hostile geometry: soup {report}: {hits} of {} rays hit ({})",
            rays.len(),
            scene.triangle_test().name()
        );
        assert!(hits > rays.len() / 10);
    }
}

#[test]
fn everything_at_one_point() {
    let p = Vec3::new(0.25, -0.5, 1.0);
    let ulp = |x: f32| f32::from_bits(x.to_bits() + 1) - x;
    let (dx, dy) = (Vec3::X * ulp(p.x) * 2.0, Vec3::Y * ulp(p.y) * 2.0);
    // Exact points (dropped), one-ulp triangles (kept) and tiny spheres, all at `p`.
    let mut tris = vec![[p, p, p]; 100];
    tris.extend(std::iter::repeat_n([p, p + dx, p + dy], 100));
    let spheres: Vec<(Vec3, f32)> = (0..50).map(|_| (p, 1e-6)).collect();
    for (scene, report) in commit_both(&soup(&tris), &spheres) {
        assert_eq!((report.triangles, report.dropped_degenerate, report.spheres), (100, 100, 50), "{report}");
        let rays = rays_for(&scene, 2000, &[p; 64]);
        let hits = check("all at one point", &scene, &rays);
        assert!(hits >= 64, "rays straight at the point hit the spheres there ({hits})");
    }
}

#[test]
fn empty_and_single_primitive_scenes() {
    let one = soup(&[[Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)]]);
    let cases = [
        ("empty", Mesh::default(), vec![]),
        ("only dropped primitives", soup(&[[Vec3::ZERO; 3], [Vec3::NAN, Vec3::X, Vec3::Y]]), vec![(Vec3::ZERO, -1.0)]),
        ("one triangle", one, vec![]),
        ("one sphere", Mesh::default(), vec![(Vec3::new(0.0, 0.0, 0.5), 0.5)]),
    ];
    for (what, mesh, spheres) in &cases {
        for (scene, report) in commit_both(mesh, spheres) {
            let rays = if scene.num_prims() == 0 {
                let r = Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z);
                vec![r; 40]
            } else {
                rays_for(&scene, 2000, &[Vec3::new(0.0, 0.0, 0.2); 8])
            };
            let hits = check(what, &scene, &rays);
            assert_eq!(hits > 0, scene.num_prims() > 0, "{what}: {report}: {hits} hits");
        }
    }
}

#[test]
fn coordinates_up_to_1e18() {
    // A sphere and a grid scaled to 1e18, and triangles beyond MAX_COORDINATE (dropped).
    let big = 1e18f32;
    let mut mesh = uv_sphere(20, 40).map_positions(|p| p * big);
    mesh.append(&grid(10, 10).map_positions(|p| p * big * 1.5 + Vec3::new(0.0, 0.0, -big * 1.2)));
    let kept = mesh.indices.len();
    mesh.append(&soup(&[[Vec3::splat(MAX_COORDINATE * 2.0), Vec3::new(0.0, 1.0, 0.0) * 4e18, Vec3::X * 1e19]; 5]));
    // And a tiny mesh far from the origin: large coordinates, small extent.
    mesh.append(&random_soup(200, 1e-3, 4).map_positions(|p| p * 1e-3 + Vec3::splat(1e12)));
    for (scene, report) in commit_both(&mesh, &[(Vec3::new(big, big, 0.0), big * 0.1)]) {
        assert_eq!(report.dropped_non_finite, 5, "{report}");
        assert!(report.triangles >= kept, "{report}");
        let points = [Vec3::ZERO, Vec3::new(big * 0.5, 0.0, 0.0), Vec3::splat(1e12), Vec3::new(big, big, 0.0)];
        let rays = rays_for(&scene, 20_000, &points);
        let hits = check("1e18 coordinates", &scene, &rays);
        eprintln!(
            "hostile geometry: 1e18 {report}: {hits} of {} rays hit ({})",
            rays.len(),
            scene.triangle_test().name()
        );
        assert!(hits > rays.len() / 10);
    }
}

#[test]
fn nan_and_inf_vertices_are_dropped_and_counted() {
    let mut mesh = grid(8, 8);
    let n = mesh.indices.len();
    let bad =
        [Vec3::new(f32::NAN, 0.0, 0.0), Vec3::new(0.0, f32::INFINITY, 0.0), Vec3::new(0.0, 0.0, f32::NEG_INFINITY)];
    let mut expect = 0;
    for (k, b) in bad.iter().enumerate() {
        // Replace one vertex: every triangle using it must go.
        let v = 10 + k * 20;
        mesh.positions[v] = *b;
        expect += mesh.indices.iter().filter(|t| t.contains(&(v as u32))).count();
    }
    for (scene, report) in commit_both(&mesh, &[(Vec3::new(f32::NAN, 0.0, 0.0), 1.0), (Vec3::ZERO, f32::INFINITY)]) {
        assert_eq!(report.dropped_non_finite, expect, "{report}");
        assert_eq!(report.triangles, n - expect, "{report}");
        assert_eq!(report.spheres, 0, "{report}");
        let rays = rays_for(&scene, 5000, &[]);
        check("NaN/Inf vertices", &scene, &rays);
    }
}
