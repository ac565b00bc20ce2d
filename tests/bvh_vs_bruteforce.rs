//! The BVH answers exactly what testing every primitive answers.

mod common;

use common::{random_rays, scene_of, slivers};
use raypack::bvh::validate::validate_bvh2;
use raypack::generate::{grid, random_soup, uv_sphere};
use raypack::{BuildOptions, BuildQuality, Hit, Ray, Scene, SplitMethod, Vec3};

/// Compares the reference BVH with brute force on `rays`; returns the number compared.
fn check(scene: &Scene, rays: &[Ray], what: &str) -> usize {
    let bounds: Vec<_> = (0..scene.num_prims() as u32).map(|p| scene.prim_bounds(p)).collect();
    validate_bvh2(scene.bvh2().expect("binary BVH kept"), &bounds)
        .unwrap_or_else(|e| panic!("{what}: invalid BVH: {e}"));
    let mut hits = 0;
    for (i, ray) in rays.iter().enumerate() {
        let bvh = scene.intersect1_reference(ray);
        let brute = scene.intersect1_brute_force(ray);
        assert_eq!(bvh.is_hit(), brute.is_hit(), "{what}: ray {i} {ray:?}: bvh {bvh:?} brute {brute:?}");
        if brute.is_hit() {
            hits += 1;
            let rel = (bvh.t - brute.t).abs() / brute.t.abs().max(1e-30);
            assert!(rel <= 1e-6, "{what}: ray {i}: t {} vs {}", bvh.t, brute.t);
            if bvh.prim != brute.prim {
                // Allowed only when another primitive is hit at the same distance.
                let other = scene.intersect_prim(bvh.prim, ray, ray.tfar).expect("bvh prim is hit");
                assert!(
                    (other.0 - brute.t).abs() <= 1e-6 * brute.t,
                    "{what}: ray {i}: prim {} vs {}",
                    bvh.prim,
                    brute.prim
                );
            }
        }
        let occluded = scene.occluded1_reference(ray);
        assert_eq!(occluded, brute.is_hit(), "{what}: ray {i}: occluded {occluded} vs brute {brute:?}");
        // A shortened ray is occluded exactly when the closest hit lies within it.
        if brute.is_hit() {
            let short = Ray { tfar: brute.t * 0.5, ..*ray };
            assert_eq!(
                scene.occluded1_reference(&short),
                scene.intersect1_brute_force(&short).is_hit(),
                "{what}: ray {i} short"
            );
        }
    }
    assert!(hits > rays.len() / 20, "{what}: too few hits ({hits}) for a meaningful test");
    rays.len()
}

#[test]
fn random_soups_over_leaf_sizes() {
    let mut total = 0;
    // Medium makes every node of at most `leaf` primitives a leaf; High also splits those
    // by the SAH.
    for quality in [BuildQuality::Medium, BuildQuality::High] {
        for (seed, leaf) in [(1u64, 1usize), (2, 4), (3, 8)] {
            let soup = random_soup(3000, 0.08, seed);
            let opts = BuildOptions { max_leaf_size: leaf, quality, ..BuildOptions::default() };
            let scene = scene_of(&[&soup], &[], &opts);
            if quality == BuildQuality::Medium {
                // No spatial splits: one reference per primitive, so `check`'s validation
                // proves each is referenced exactly once.
                assert_eq!(scene.bvh2().unwrap().prim_ids.len(), scene.num_prims());
            }
            total += check(&scene, &random_rays(&scene, 40_000, seed), &format!("soup leaf {leaf} {quality:?}"));
        }
    }
    assert!(total >= 200_000);
}

#[test]
fn small_nodes_are_leaves_below_high_quality() {
    // Four triangles far apart: the SAH splits them (High), Medium keeps them in one leaf
    // because they fit `max_leaf_size`, and both trees trace alike.
    let mut b = raypack::SceneBuilder::new();
    let m = b.add_material(raypack::Material::default());
    let tri = [Vec3::ZERO, Vec3::X * 4.0, Vec3::Y * 4.0];
    for i in 0..4 {
        let o = Vec3::new(10.0 * i as f32, 0.0, 0.0);
        b.add_mesh(&tri.map(|p| p + o), &[[0, 1, 2]], m).unwrap();
    }
    let leaves = |quality| {
        let opts = BuildOptions { max_leaf_size: 4, quality, keep_bvh2: true, ..BuildOptions::default() };
        let scene = b.clone().commit(&opts).0;
        check(&scene, &random_rays(&scene, 2000, 5), &format!("{quality:?}"));
        scene.bvh2().unwrap().nodes.iter().filter(|n| n.is_leaf()).count()
    };
    assert_eq!(leaves(BuildQuality::Medium), 1);
    assert_eq!(leaves(BuildQuality::High), 4);
}

#[test]
fn shared_edge_meshes_and_spheres() {
    let g = grid(60, 60).map_positions(|p| p + Vec3::new(0.0, 0.0, -0.5));
    let s = uv_sphere(40, 60).map_positions(|p| p * 0.4 + Vec3::new(0.3, 0.0, 0.2));
    let spheres = [(Vec3::new(-0.5, 0.5, 0.0), 0.3), (Vec3::new(0.5, -0.5, 0.3), 0.2)];
    let scene = scene_of(&[&g, &s], &spheres, &BuildOptions::default());
    check(&scene, &random_rays(&scene, 60_000, 9), "grid+sphere");
    // Rays exactly through grid vertices and edge midpoints, straight down: every one must
    // hit the grid, and BVH and brute force must agree.
    let mut rays = Vec::new();
    for p in &g.positions {
        rays.push(Ray::new(*p + Vec3::new(0.0, 0.0, 2.0), -Vec3::Z));
    }
    for t in &g.indices {
        let (a, b) = (g.positions[t[0] as usize], g.positions[t[1] as usize]);
        rays.push(Ray::new((a + b) * 0.5 + Vec3::new(0.0, 0.0, 2.0), -Vec3::Z));
    }
    check(&scene, &rays, "grid vertices and edges");
}

#[test]
fn degenerate_inputs_build_valid_trees() {
    // All triangles at one point, duplicates, and a single primitive.
    let point = random_soup(100, 0.0, 5).map_positions(|_| Vec3::splat(0.25));
    let dup = {
        let mut m = random_soup(1, 0.3, 6);
        for _ in 0..200 {
            m.append(&random_soup(1, 0.3, 6));
        }
        m
    };
    for (what, mesh) in [("point", &point), ("duplicates", &dup), ("single", &random_soup(1, 0.5, 7))] {
        for leaf in [1, 4] {
            let scene = scene_of(&[mesh], &[], &BuildOptions { max_leaf_size: leaf, ..BuildOptions::default() });
            let bounds: Vec<_> = (0..scene.num_prims() as u32).map(|p| scene.prim_bounds(p)).collect();
            validate_bvh2(scene.bvh2().expect("binary BVH kept"), &bounds).unwrap_or_else(|e| panic!("{what}: {e}"));
            for r in random_rays(&scene, 2000, 3) {
                assert_eq!(scene.intersect1_reference(&r).t.to_bits(), scene.intersect1_brute_force(&r).t.to_bits());
            }
        }
    }
    // An empty scene misses everything.
    let empty = scene_of(&[], &[], &BuildOptions::default());
    assert_eq!(empty.intersect1(&Ray::new(Vec3::ZERO, Vec3::X)), Hit::MISS);
}

#[test]
fn sah_beats_median_split() {
    for (what, mesh) in [
        ("soup", random_soup(20_000, 0.05, 11)),
        ("clustered", {
            let mut m = random_soup(10_000, 0.01, 12).map_positions(|p| p * 0.1);
            m.append(&random_soup(2_000, 0.05, 13).map_positions(|p| p + Vec3::splat(3.0)));
            m
        }),
        ("sphere", uv_sphere(100, 100)),
    ] {
        let sah = scene_of(&[&mesh], &[], &BuildOptions::default()).bvh_stats().expect("kept");
        let med = scene_of(&[&mesh], &[], &BuildOptions { split: SplitMethod::Median, ..BuildOptions::default() })
            .bvh_stats()
            .expect("kept");
        eprintln!("{what}: SAH {sah}\n{what}: median {med}");
        assert!(
            sah.sah_cost < med.sah_cost,
            "{what}: SAH cost {} is not below median's {}",
            sah.sah_cost,
            med.sah_cost
        );
    }
}

#[test]
fn build_is_identical_whatever_the_thread_count() {
    // The BVH2 and the BVH8 arrays (nodes, triangle and sphere blocks), bit for bit, built in a
    // rayon pool of 1 and of 2 threads, for both block layouts. (The image part of determinism
    // is in tests/render_cli.rs.)
    // High quality with slivers makes the builder cut triangles, its spatial binning in
    // parallel chunks near the root.
    let mut mesh = random_soup(200_000, 0.01, 21);
    mesh.append(&uv_sphere(60, 120));
    mesh.append(&slivers(2000, 22));
    let spheres: Vec<(Vec3, f32)> = (0..300).map(|i| (Vec3::new(i as f32 * 0.006 - 0.9, 0.1, -0.2), 0.01)).collect();
    for (watertight, quality) in
        [(false, BuildQuality::Medium), (true, BuildQuality::Medium), (false, BuildQuality::High)]
    {
        let opts = BuildOptions { watertight, quality, keep_bvh2: true, ..BuildOptions::default() };
        let build = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| scene_of(&[&mesh], &spheres, &opts))
        };
        let (a, b) = (build(1), build(2));
        assert_eq!(a.bvh2().unwrap().prim_ids, b.bvh2().unwrap().prim_ids);
        assert_eq!(a.bvh2().unwrap().nodes, b.bvh2().unwrap().nodes);
        assert_eq!(bvh8_bits(&a), bvh8_bits(&b), "BVH8 differs between 1 and 2 threads ({opts:?})");
        let refs = a.bvh2().unwrap().prim_ids.len();
        assert_eq!(refs > a.num_prims(), quality == BuildQuality::High, "{refs} references ({quality:?})");
        assert!(a.bvh8().tris.len() > 10_000 && !a.bvh8().spheres.is_empty());
    }
}

/// Every bit of a scene's BVH8: node boxes and references, block rows and ids.
fn bvh8_bits(scene: &Scene) -> Vec<u64> {
    use raypack::geometry::TriBlock;
    let bvh = scene.bvh8();
    let mut out = vec![bvh.nodes.len() as u64, bvh.tris.len() as u64, bvh.spheres.len() as u64];
    for n in &bvh.nodes {
        out.extend(n.bounds.iter().flatten().map(|x| x.to_bits() as u64));
        out.extend(n.children.iter().map(|c| c.0));
    }
    for b in &bvh.tris {
        for lane in 0..raypack::geometry::Tri8::M {
            out.extend(b.lane_rows(lane).iter().flat_map(|v| v.to_array()).map(|x| x.to_bits() as u64));
            out.push(b.prim(lane) as u64);
        }
    }
    for s in &bvh.spheres {
        out.extend(s.center.iter().flatten().chain(&s.radius).map(|x| x.to_bits() as u64));
        out.extend(s.prim.iter().map(|&p| p as u64));
    }
    out
}

/// Without `keep_bvh2` the binary BVH is freed after the collapse; the reference queries then
/// test every primitive and still give the brute-force answers, and the kernels are untouched.
#[test]
fn reference_queries_without_the_binary_bvh_fall_back_to_brute_force() {
    let mesh = random_soup(3_000, 0.05, 31);
    let spheres = [(Vec3::new(0.2, 0.1, -0.3), 0.2)];
    let mut b = raypack::SceneBuilder::new();
    let m = b.add_material(raypack::Material::default());
    b.add_mesh(&mesh.positions, &mesh.indices, m).unwrap();
    b.add_sphere(spheres[0].0, spheres[0].1, m).unwrap();
    let (lean, _) = b.clone().commit(&BuildOptions::default());
    let (kept, _) = b.commit(&BuildOptions { keep_bvh2: true, ..BuildOptions::default() });
    assert!(lean.bvh2().is_none() && lean.bvh_stats().is_none() && kept.bvh2().is_some());
    let mut hits = 0;
    for r in random_rays(&kept, 5_000, 32) {
        let want = kept.intersect1_brute_force(&r);
        let got = lean.intersect1_reference(&r);
        assert_eq!((got.prim, got.t.to_bits()), (want.prim, want.t.to_bits()));
        assert_eq!(lean.occluded1_reference(&r), want.is_hit());
        assert_eq!(lean.intersect1(&r).t.to_bits(), kept.intersect1(&r).t.to_bits());
        hits += usize::from(want.is_hit());
    }
    assert!(hits > 500, "too few hits to mean anything: {hits}");
}

/// `Scene::cone_may_hit` answers "no" only when no ray of the cone hits anything: random
/// cones (narrow and wide) through a sparse soup of triangles and spheres, on every ISA tier,
/// against rays of the cone tested against every primitive.
#[test]
fn cones_are_culled_only_when_no_ray_of_them_hits() {
    let soup = random_soup(400, 0.06, 9);
    let spheres = [(Vec3::new(0.2, 0.3, 0.4), 0.05), (Vec3::new(0.8, 0.6, 0.3), 0.08)];
    for watertight in [false, true] {
        let scene = scene_of(&[&soup], &spheres, &BuildOptions { watertight, ..BuildOptions::default() });
        let (c, e) = (scene.bounds().center(), scene.bounds().extent());
        for (isa, scene) in common::on_every_isa(&scene) {
            let mut rng = raypack::rng::Rng::new(4, watertight as u64);
            let mut r3 = move || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let (mut culled, mut hit) = (0, 0);
            for k in 0..3000 {
                let origin = c + (r3() - 0.5) * e * 3.0;
                let towards = (c + (r3() - 0.5) * e - origin).normalize();
                let half = Vec3::splat([0.001, 0.01, 0.05, 0.2][k % 4]) * (r3() + 0.5);
                let (lo, hi) = (towards - half, towards + half);
                let may_hit = scene.cone_may_hit(origin, lo, hi);
                if (0..3).any(|a| lo[a] <= 0.0 && hi[a] >= 0.0) {
                    assert!(may_hit, "{isa}: a cone across a coordinate plane is never culled");
                    continue;
                }
                culled += !may_hit as usize;
                for _ in 0..32 {
                    let dir = (lo + (hi - lo) * r3()) * (0.1 + 10.0 * r3().x);
                    let ray = Ray::new(origin, dir);
                    if scene.intersect1_brute_force(&ray).is_hit() {
                        hit += 1;
                        assert!(may_hit, "{isa}, watertight {watertight}: cone {k} culled, but {ray:?} hits");
                    }
                }
            }
            assert!(culled > 200 && hit > 1000, "{isa}: {culled} cones culled, {hit} rays hit");
        }
    }
}

/// Streams without sphere coordinates (`StreamOptions::without_sphere_uv`, the renderer's)
/// give the same hits as with them, but `(u, v) = 0` on spheres; triangle hits are untouched.
#[test]
fn streams_without_sphere_coordinates_differ_only_in_sphere_uv() {
    let soup = random_soup(500, 0.06, 12);
    let spheres = [(Vec3::new(0.2, 0.3, 0.4), 0.15), (Vec3::new(0.7, 0.6, 0.3), 0.2)];
    let scene = scene_of(&[&soup], &spheres, &BuildOptions::default());
    let rays = random_rays(&scene, 4_000, 5);
    let nt = scene.num_prims() as u32 - spheres.len() as u32;
    let (mut with, mut without) = (vec![Hit::MISS; rays.len()], vec![Hit::MISS; rays.len()]);
    scene.intersect_stream(&rays, &mut with, &raypack::StreamOptions::POOL);
    scene.intersect_stream(&rays, &mut without, &raypack::StreamOptions::POOL.without_sphere_uv());
    let mut sphere_hits = 0;
    for (i, (w, o)) in with.iter().zip(&without).enumerate() {
        assert_eq!((w.prim, w.t.to_bits()), (o.prim, o.t.to_bits()), "ray {i}");
        if w.is_hit() && w.prim >= nt {
            sphere_hits += 1;
            assert_eq!((o.u, o.v), (0.0, 0.0), "ray {i}");
            assert_eq!(
                (w.u, w.v),
                raypack::geometry::sphere::sphere_uv((rays[i].at(w.t) - spheres[(w.prim - nt) as usize].0).normalize()),
                "ray {i}"
            );
        } else {
            assert_eq!((w.u.to_bits(), w.v.to_bits()), (o.u.to_bits(), o.v.to_bits()), "ray {i}");
        }
    }
    assert!(sphere_hits > 50, "too few sphere hits to mean anything: {sphere_hits}");
}
