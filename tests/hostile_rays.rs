//! Hostile rays through every query: NaN, ±Inf and ±0.0 components of origins and
//! directions, zero directions, empty and inverted intervals, negative `tnear`, origins exactly
//! on surfaces, huge and tiny magnitudes.
//!
//! What each case must do (and does):
//! * Invalid rays ([`Ray::is_valid`]: a NaN or infinite origin or direction component, a zero
//!   direction, `tnear` negative or NaN, `tnear > tfar`, `tfar` NaN) miss in every closest-hit
//!   query and are never occluded; packet lanes holding them get `prim = Hit::NONE`.
//! * Valid rays (including ±0.0 direction components, `tnear == tfar`, `tnear = tfar = +inf`,
//!   origins on a surface, coordinates up to 1e18 and directions down to 1e-30) get exactly the
//!   reference traversal's and brute force's answer in every kernel, and every hit has a finite
//!   `t` in `[tnear, tfar]` (never `-0.0`), finite `u`, `v` and an existing primitive id. From origins 1e18
//!   away (beyond 1e12), where the origin's rounding dwarfs the scene and hits are rounding
//!   noise, only the last properties hold, not agreement between traversals.
//! * Nothing panics or hangs: every batch runs on a worker thread that must finish within a
//!   generous bound (a hang detector, not a timing assertion).
//!
//! Both triangle tests (Möller–Trumbore and watertight) are exercised.

mod common;

use common::{every_kernel, on_every_isa, random_rays, scene_of};
use raypack::generate::{grid, uv_sphere};
use raypack::kernels::Results;
use raypack::{BuildOptions, Hit, Ray, Scene, StreamOptions, TraversalCounts, Vec3};
use std::sync::Arc;
use std::time::Duration;

/// Runs `f` on another thread and fails if it does not return within `limit` (a hang).
fn without_hang<R: Send + 'static>(what: &str, limit: Duration, f: impl FnOnce() -> R + Send + 'static) -> R {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    match rx.recv_timeout(limit) {
        Ok(r) => r,
        Err(e) => panic!("{what}: no answer within {limit:?} ({e}): a hang or a panic on the worker"),
    }
}

fn scene(watertight: bool) -> Scene {
    let s = uv_sphere(24, 48).map_positions(|p| p * 0.8);
    let g = grid(20, 20).map_positions(|p| p * 2.0 + Vec3::new(0.0, 0.0, -1.5));
    let spheres = [(Vec3::new(1.2, 1.2, 0.0), 0.3), (Vec3::new(-1.2, 0.5, 0.5), 0.2)];
    scene_of(&[&s, &g], &spheres, &BuildOptions { watertight, keep_bvh2: true, ..BuildOptions::default() })
}

/// The hostile variants of `base` rays on `scene`, each with its name.
fn hostile_rays(scene: &Scene, base: &[Ray]) -> Vec<(String, Ray)> {
    let mut out = Vec::new();
    let specials = [("NaN", f32::NAN), ("+Inf", f32::INFINITY), ("-Inf", f32::NEG_INFINITY)];
    for (i, &r) in base.iter().enumerate() {
        let mut push = |name: String, ray: Ray| out.push((format!("{name} (base ray {i})"), ray));
        for k in 0..3 {
            for (name, x) in specials {
                let mut o = r;
                o.origin[k] = x;
                push(format!("origin[{k}] = {name}"), o);
                let mut d = r;
                d.dir[k] = x;
                push(format!("dir[{k}] = {name}"), d);
            }
            for z in [0.0f32, -0.0] {
                let mut d = r;
                d.dir[k] = z;
                push(format!("dir[{k}] = {z:?}"), d);
                // Axis-parallel: two zero components.
                let mut a = r;
                a.dir[(k + 1) % 3] = z;
                a.dir[(k + 2) % 3] = -z;
                push(format!("dir axis {k} with {z:?}"), a);
            }
        }
        push("zero direction".into(), Ray { dir: Vec3::ZERO, ..r });
        push("-0 direction".into(), Ray { dir: Vec3::splat(-0.0), ..r });
        push("tnear > tfar".into(), Ray { tnear: 2.0, tfar: 1.0, ..r });
        push("tnear = tfar = 0".into(), Ray { tnear: 0.0, tfar: 0.0, ..r });
        push("tnear = tfar = +inf".into(), Ray { tnear: f32::INFINITY, tfar: f32::INFINITY, ..r });
        push("negative tnear".into(), Ray { tnear: -1.0, ..r });
        push("tnear = -0.0".into(), Ray { tnear: -0.0, ..r });
        push("NaN tnear".into(), Ray { tnear: f32::NAN, ..r });
        push("NaN tfar".into(), Ray { tfar: f32::NAN, ..r });
        push("-inf tfar".into(), Ray { tfar: f32::NEG_INFINITY, ..r });
        let h = scene.intersect1_reference(&r);
        if h.is_hit() {
            push("tnear = tfar = hit t".into(), Ray { tnear: h.t, tfar: h.t, ..r });
            push("tfar = hit t".into(), Ray { tfar: h.t, ..r });
            let p = r.at(h.t);
            push("origin on the surface".into(), Ray::new(p, r.dir));
            push("origin on the surface, reversed".into(), Ray::new(p, -r.dir));
            push("origin on the surface, tangent".into(), Ray::new(p, r.dir.cross(Vec3::X)));
        }
        // Huge and tiny magnitudes.
        let c = scene.bounds().center();
        push("origin 1e18 away".into(), Ray::new(c - r.dir.normalize() * 1e18, r.dir));
        push("origin at 1e18".into(), Ray::new(Vec3::splat(1e18), c - Vec3::splat(1e18)));
        push("direction * 1e18".into(), Ray { dir: r.dir * 1e18, ..r });
        // |dir| radius > 1.8e19: the sphere test's sqrt(|dir|² disc) overflows.
        push("direction * 1e20".into(), Ray { dir: r.dir * 1e20, ..r });
        push("direction * 1e-30".into(), Ray { dir: r.dir * 1e-30, ..r });
        push("direction 1e-40 (subnormal)".into(), Ray { dir: r.dir.normalize() * 1e-40, ..r });
        push("tfar = f32::MAX".into(), Ray { tfar: f32::MAX, ..r });
    }
    // Rays starting exactly at mesh vertices, in several directions.
    let tris = &scene.triangles;
    for (k, p) in tris.positions.iter().enumerate().step_by(97) {
        for d in [Vec3::X, -Vec3::Y, Vec3::new(0.3, -0.4, 0.5), -*p] {
            out.push((format!("origin at vertex {k}, dir {d}"), Ray::new(*p, d)));
        }
    }
    out
}

/// Every query on `rays`: brute force, then every kernel of the registry on every ISA tier
/// (the scalar references first): `(query name, per-ray hits)`; occlusion as a hit with
/// `t = 0`.
fn all_queries(scene: &Scene, rays: &[Ray]) -> Vec<(String, Vec<Hit>)> {
    let occ = |b: bool| if b { Hit { t: 0.0, u: 0.0, v: 0.0, prim: 0 } } else { Hit::MISS };
    let mut out =
        vec![("intersect1_brute_force".to_string(), rays.iter().map(|r| scene.intersect1_brute_force(r)).collect())];
    for (name, results) in every_kernel(scene, rays) {
        out.push(match results {
            Results::Hits(h) => (name, h),
            Results::Occluded(o) => (name, o.into_iter().map(occ).collect()),
        });
    }
    out
}

fn check(scene: &Scene, named: &[(String, Ray)]) -> (usize, usize) {
    let rays: Vec<Ray> = named.iter().map(|(_, r)| *r).collect();
    let answers = all_queries(scene, &rays);
    let find = |name: &str| answers.iter().position(|(q, _)| q == name).expect("a reference kernel");
    let (reference, reference_occ) = (find("bvh2 reference intersect1"), find("bvh2 reference occluded1"));
    let test = scene.triangle_test().name();
    let (mut invalid, mut hits) = (0, 0);
    for (i, (name, r)) in named.iter().enumerate() {
        let want = &answers[reference].1[i];
        let want_occ = answers[reference_occ].1[i].is_hit();
        invalid += !r.is_valid() as usize;
        hits += want.is_hit() as usize;
        for (query, got) in &answers {
            let h = &got[i];
            let what = format!("{test} {query}: {name}: {r:?} gave {h:?}");
            if !r.is_valid() {
                assert!(!h.is_hit(), "{what}: an invalid ray must miss");
                continue;
            }
            // From origins so far away that the origin's rounding (ulp 6.9e10 at 1e18) dwarfs
            // the scene, whether and where a ray hits is rounding noise (the triangle tests'
            // cancellation in `origin - v0`), often outside the triangle's box where no BVH
            // looks: only the properties below are checked there, not agreement.
            let noise = r.origin.abs().max_element() > 1e12;
            if noise {
                if h.is_hit() && !query.contains("occluded") {
                    assert!(h.t >= r.tnear && h.t <= r.tfar && h.t.is_finite(), "{what}: t outside [tnear, tfar]");
                    assert_ne!(h.t.to_bits(), (-0.0f32).to_bits(), "{what}: t = -0.0");
                    assert!(h.u.is_finite() && h.v.is_finite(), "{what}: u, v not finite");
                }
                continue;
            }
            if query.contains("occluded") {
                assert_eq!(h.is_hit(), want_occ, "{what}: occlusion differs from the reference");
                continue;
            }
            assert_eq!(h.is_hit(), want.is_hit(), "{what}: reference gave {want:?}");
            if h.is_hit() {
                assert!(h.t >= r.tnear && h.t <= r.tfar && h.t.is_finite(), "{what}: t outside [tnear, tfar]");
                assert_ne!(h.t.to_bits(), (-0.0f32).to_bits(), "{what}: t = -0.0");
                assert!(h.u.is_finite() && h.v.is_finite(), "{what}: u, v not finite");
                assert!((h.prim as usize) < scene.num_prims(), "{what}: no such primitive");
                assert_eq!(h.t.to_bits(), want.t.to_bits(), "{what}: t differs from the reference {want:?}");
            }
        }
        // Occluded over [tnear, tfar] exactly when the closest hit exists.
        if r.origin.abs().max_element() > 1e12 {
            continue;
        }
        assert_eq!(want_occ, want.is_hit(), "{test}: {name}: occluded1_reference vs intersect1_reference");
    }
    (invalid, hits)
}

#[test]
fn hostile_rays_miss_or_match_the_reference_in_every_query() {
    for watertight in [false, true] {
        let scene = Arc::new(scene(watertight));
        let base = random_rays(&scene, 120, 5 + watertight as u64);
        let named = hostile_rays(&scene, &base);
        let s = scene.clone();
        let (invalid, hits) = without_hang("hostile rays", Duration::from_secs(120), move || check(&s, &named.clone()));
        eprintln!(
            "hostile rays ({}): {} invalid rays all missed; valid rays matched the reference ({hits} hits)",
            scene.triangle_test().name(),
            invalid
        );
        assert!(invalid > 100 && hits > 100, "the cases must cover both ({invalid} invalid, {hits} hits)");
    }
}

#[test]
fn nan_rays_do_no_traversal_work() {
    // Traversal work by count, not time: the kernels' own counters, on every ISA tier.
    let scene = scene(false);
    let valid = random_rays(&scene, 4096, 3);
    let nan: Vec<Ray> = valid.iter().map(|r| Ray { dir: Vec3::new(f32::NAN, r.dir.y, r.dir.z), ..*r }).collect();
    let work = |scene: &Scene, rays: &[Ray]| {
        let mut c = TraversalCounts::default();
        for r in rays {
            std::hint::black_box(scene.counting(&mut c).intersect1(r));
            std::hint::black_box(scene.counting(&mut c).occluded1(r));
        }
        let mut hits = vec![Hit::MISS; rays.len()];
        scene.counting(&mut c).intersect_stream(rays, &mut hits, &StreamOptions::CALLER);
        let mut occ = vec![false; rays.len()];
        scene.counting(&mut c).occluded_stream(rays, &mut occ, &StreamOptions::CALLER);
        c
    };
    for (isa, scene) in on_every_isa(&scene) {
        let (w_valid, w_nan) = (work(&scene, &valid), work(&scene, &nan));
        eprintln!("traversal work [{isa}], 4096 valid rays: {w_valid:?}");
        eprintln!("traversal work [{isa}], 4096 NaN rays: {w_nan:?}");
        assert!(w_valid.nodes > 4096 && w_valid.packet_nodes > 0, "valid rays visit nodes");
        assert_eq!(w_nan, TraversalCounts::default(), "NaN rays are rejected before traversal");
    }
}
