//! The 8-wide BVH: structural invariants, and every BVH8 kernel of the registry (single ray,
//! 8/16-ray packets, streams), on every ISA tier the CPU has, answering exactly what the
//! reference BVH2 and brute force answer.

mod common;

use common::{every_kernel, on_every_isa, random_rays, scene_of, slivers};
use raypack::bvh::validate::validate_bvh8;
use raypack::bvh::{Bvh8, CollapseMethod, CollapseOptions, NoCount, collapse};
use raypack::generate::{grid, random_soup, uv_sphere};
use raypack::geometry::{Tri4, Tri8, TriBlock};
use raypack::kernels::Results;
use raypack::rng::Rng;
use raypack::{BuildOptions, BuildQuality, Camera, Hit, Isa, Ray, RayPacket8, RayPacket16, Scene, Vec3};

fn prim_bounds(scene: &Scene) -> Vec<raypack::Aabb> {
    (0..scene.num_prims() as u32).map(|p| scene.prim_bounds(p)).collect()
}

/// Same hit as the reference: identical `t` bits, and the same primitive unless another one
/// is hit at exactly that distance.
fn same_hit(scene: &Scene, ray: &Ray, got: &Hit, want: &Hit, what: &str) {
    assert_eq!(got.is_hit(), want.is_hit(), "{what}: {ray:?}: got {got:?} want {want:?}");
    if !want.is_hit() {
        return;
    }
    assert_eq!(got.t.to_bits(), want.t.to_bits(), "{what}: {ray:?}: t {} vs {}", got.t, want.t);
    if got.prim != want.prim {
        let other = scene.intersect_prim(got.prim, ray, ray.tfar).expect("reported prim is hit");
        assert_eq!(other.0.to_bits(), want.t.to_bits(), "{what}: prim {} vs {}", got.prim, want.prim);
    } else {
        assert_eq!((got.u.to_bits(), got.v.to_bits()), (want.u.to_bits(), want.v.to_bits()), "{what}: u, v");
    }
}

/// Checks every kernel of the registry, on every ISA tier, against the reference on `rays`
/// (and the packet kernels again with partial lane masks); returns the number of hits.
fn check_kernels(scene: &Scene, rays: &[Ray], what: &str) -> usize {
    validate_bvh8(scene.bvh8(), &prim_bounds(scene)).unwrap_or_else(|e| panic!("{what}: invalid BVH8: {e}"));
    let want: Vec<Hit> = rays.iter().map(|r| scene.intersect1_reference(r)).collect();
    let want_occ: Vec<bool> = rays.iter().map(|r| scene.occluded1_reference(r)).collect();
    for (kernel, results) in every_kernel(scene, rays) {
        match results {
            Results::Hits(h) => {
                for (i, r) in rays.iter().enumerate() {
                    same_hit(scene, r, &h[i], &want[i], &format!("{what} {kernel} ray {i}"));
                }
            }
            Results::Occluded(o) => {
                for (i, r) in rays.iter().enumerate() {
                    assert_eq!(o[i], want_occ[i], "{what} {kernel} ray {i} {r:?}");
                }
            }
        }
    }
    for (isa, scene) in on_every_isa(scene) {
        check_partial_packets(&scene, rays, &want, &want_occ, &format!("{what} [{isa}]"));
    }
    want.iter().filter(|h| h.is_hit()).count()
}

/// Packets with a different partial mask each time: masked lanes get the reference's
/// answer, the others are neither written nor reported.
fn check_partial_packets(scene: &Scene, rays: &[Ray], want: &[Hit], want_occ: &[bool], what: &str) {
    let mut rng = Rng::new(7, 7);
    for (c, chunk) in rays.chunks(16).enumerate() {
        let (mut p16, full) = RayPacket16::from_rays(chunk);
        let mask = if c % 3 == 0 { full } else { full & rng.next_u32() as u16 };
        let before = p16;
        scene.intersect16(&mut p16, mask);
        let occ = scene.occluded16(&before, mask);
        for i in 0..chunk.len() {
            let k = c * 16 + i;
            if mask >> i & 1 == 1 {
                same_hit(scene, &rays[k], &p16.hit(i), &want[k], &format!("{what} intersect16 ray {k}"));
                assert_eq!(occ >> i & 1 == 1, want_occ[k], "{what} occluded16 ray {k}");
            } else {
                let bits = |p: &RayPacket16| (format!("{:?}", p.ray(i)), p.prim[i], p.u[i].to_bits(), p.v[i].to_bits());
                assert_eq!(bits(&p16), bits(&before), "inactive lane written");
                assert_eq!(occ >> i & 1, 0);
            }
        }
        for half in 0..2 {
            let sub = &chunk[(half * 8).min(chunk.len())..((half + 1) * 8).min(chunk.len())];
            if sub.is_empty() {
                continue;
            }
            let (mut p8, full8) = RayPacket8::from_rays(sub);
            let mask8 = if c % 2 == 0 { full8 } else { full8 & rng.next_u32() as u8 };
            let before = p8;
            scene.intersect8(&mut p8, mask8);
            let occ = scene.occluded8(&before, mask8);
            for i in 0..sub.len() {
                let k = c * 16 + half * 8 + i;
                if mask8 >> i & 1 == 1 {
                    same_hit(scene, &rays[k], &p8.hit(i), &want[k], &format!("{what} intersect8 ray {k}"));
                    assert_eq!(occ >> i & 1 == 1, want_occ[k], "{what} occluded8 ray {k}");
                } else {
                    assert_eq!(p8.prim[i], before.prim[i], "{what}: inactive lane written");
                    assert_eq!(occ >> i & 1, 0);
                }
            }
        }
    }
}

/// Camera rays over the scene in 4 x 4 pixel tiles (the coherent case).
fn camera_rays(scene: &Scene, w: usize, h: usize) -> Vec<Ray> {
    let cam: Camera = scene.camera_or_framing(w as f32 / h as f32);
    let mut rays = Vec::with_capacity(w * h);
    for ty in (0..h).step_by(4) {
        for tx in (0..w).step_by(4) {
            for y in ty..(ty + 4).min(h) {
                for x in tx..(tx + 4).min(w) {
                    rays.push(cam.generate_ray((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32));
                }
            }
        }
    }
    rays
}

/// Shadow rays from the reference hits of `primary` toward a point above the scene.
fn shadow_rays(scene: &Scene, primary: &[Ray]) -> Vec<Ray> {
    let b = scene.bounds();
    let light = b.center() + Vec3::new(0.0, b.extent().y * 1.5 + 0.1, 0.0);
    primary
        .iter()
        .filter_map(|r| {
            let h = scene.intersect1_reference(r);
            h.is_hit().then(|| {
                let p = r.at(h.t);
                let d = light - p;
                Ray::segment(p, d, 1e-3, 1.0 - 1e-4)
            })
        })
        .collect()
}

#[test]
fn soups_over_leaf_sizes_and_block_widths() {
    let mut total = 0;
    for (seed, leaf) in [(1u64, 1usize), (2, 4), (3, 8)] {
        let soup = random_soup(3000, 0.08, seed);
        let opts = BuildOptions { max_leaf_size: leaf, ..BuildOptions::default() };
        let scene = scene_of(&[&soup], &[], &opts);
        let rays = random_rays(&scene, 40_000, seed);
        let hits = check_kernels(&scene, &rays, &format!("soup leaf {leaf}"));
        assert!(hits > rays.len() / 20, "too few hits ({hits})");
        total += rays.len();
    }
    assert!(total >= 100_000);
}

/// The single-ray closest-hit query speculates its descents only in small trees; the large
/// tree's form answers like the reference too, on every tier.
#[test]
fn large_trees_trace_without_speculation_like_the_reference() {
    use raypack::bvh::queries::SPECULATION_MAX_BYTES;
    let small = scene_of(&[&random_soup(3000, 0.08, 11)], &[], &BuildOptions::default());
    assert!(small.bvh8().speculates());
    let soup = random_soup(120_000, 0.02, 12);
    let scene = scene_of(&[&soup], &[], &BuildOptions::default());
    assert!(scene.bvh8().bytes() > SPECULATION_MAX_BYTES, "{} bytes", scene.bvh8().bytes());
    assert!(!scene.bvh8().speculates());
    let rays = random_rays(&scene, 20_000, 12);
    let hits = check_kernels(&scene, &rays, "large soup");
    assert!(hits > rays.len() / 20, "too few hits ({hits})");
}

#[test]
fn shared_edges_spheres_and_coherent_rays() {
    let g = grid(60, 60).map_positions(|p| p + Vec3::new(0.0, 0.0, -0.5));
    let s = uv_sphere(40, 60).map_positions(|p| p * 0.4 + Vec3::new(0.3, 0.0, 0.2));
    let spheres = [(Vec3::new(-0.5, 0.5, 0.0), 0.3), (Vec3::new(0.5, -0.5, 0.3), 0.2), (Vec3::new(0.3, 0.0, 0.2), 0.1)];
    let scene = scene_of(&[&g, &s], &spheres, &BuildOptions::default());
    check_kernels(&scene, &random_rays(&scene, 60_000, 9), "grid+sphere random");
    let cam = camera_rays(&scene, 160, 120);
    let hits = check_kernels(&scene, &cam, "grid+sphere camera");
    assert!(hits > cam.len() / 10, "{hits} of {} camera rays hit", cam.len());
    let shadow = shadow_rays(&scene, &cam);
    check_kernels(&scene, &shadow, "grid+sphere shadow");
    // Rays exactly through grid vertices and edge midpoints, straight down.
    let mut rays = Vec::new();
    for p in &g.positions {
        rays.push(Ray::new(*p + Vec3::new(0.0, 0.0, 2.0), -Vec3::Z));
    }
    for t in &g.indices {
        let (a, b) = (g.positions[t[0] as usize], g.positions[t[1] as usize]);
        rays.push(Ray::new((a + b) * 0.5 + Vec3::new(0.0, 0.0, 2.0), -Vec3::Z));
    }
    let hits = check_kernels(&scene, &rays, "grid vertices and edges");
    assert_eq!(hits, rays.len(), "every ray straight down hits the grid");
}

#[test]
fn spatial_splits_trace_like_the_reference() {
    // Long slivers across a soup, at High quality: the builder cuts triangles (more
    // references than primitives), no BVH8 leaf holds a triangle twice (validate_bvh8), the
    // tree's SAH cost drops, and every kernel on every ISA still answers exactly what the
    // reference does, watertight or not, spheres included.
    let mut mesh = random_soup(2000, 0.08, 41);
    mesh.append(&slivers(300, 42));
    let spheres = [(Vec3::new(0.2, -0.3, 0.1), 0.25), (Vec3::new(-0.6, 0.5, -0.2), 0.15)];
    for watertight in [false, true] {
        let high = BuildOptions { quality: BuildQuality::High, watertight, ..BuildOptions::default() };
        let scene = scene_of(&[&mesh], &spheres, &high);
        let refs = scene.bvh2().expect("kept").prim_ids.len();
        assert!(
            refs > scene.num_prims() + 100,
            "{refs} references to {} primitives: no spatial splits",
            scene.num_prims()
        );
        let plain = scene_of(&[&mesh], &spheres, &BuildOptions { spatial_split_budget: 0.0, ..high.clone() });
        assert_eq!(plain.bvh2().unwrap().prim_ids.len(), plain.num_prims());
        let (cost, plain_cost) = (scene.bvh_stats().unwrap().sah_cost, plain.bvh_stats().unwrap().sah_cost);
        assert!(cost < 0.9 * plain_cost, "SAH cost {cost} with spatial splits, {plain_cost} without");
        let what = format!("slivers watertight {watertight}");
        let hits = check_kernels(&scene, &random_rays(&scene, 30_000, 43), &what);
        assert!(hits > 3000, "{what}: {hits} hits");
        let cam = camera_rays(&scene, 96, 72);
        check_kernels(&scene, &cam, &format!("{what} camera"));
        check_kernels(&scene, &shadow_rays(&scene, &cam), &format!("{what} shadow"));
    }
}

#[test]
fn watertight_kernels_match_the_scalar_reference() {
    // Every kernel with the watertight test against the scalar reference (which uses the
    // scalar watertight test on the same scene): soups, a shared-edge grid with spheres, and
    // rays exactly through grid vertices and edges.
    let opts = BuildOptions { watertight: true, keep_bvh2: true, ..BuildOptions::default() };
    let soup = random_soup(3000, 0.08, 31);
    let scene = scene_of(&[&soup], &[], &opts);
    assert_eq!(scene.triangle_test(), raypack::geometry::TriangleTest::Watertight);
    check_kernels(&scene, &random_rays(&scene, 30_000, 31), "watertight soup");
    let g = grid(40, 40).map_positions(|p| p + Vec3::new(0.0, 0.0, -0.5));
    let s = uv_sphere(30, 40).map_positions(|p| p * 0.4 + Vec3::new(0.3, 0.0, 0.2));
    let scene = scene_of(&[&g, &s], &[(Vec3::new(-0.5, 0.5, 0.0), 0.3)], &opts);
    let cam = camera_rays(&scene, 120, 90);
    check_kernels(&scene, &cam, "watertight grid+sphere camera");
    check_kernels(&scene, &shadow_rays(&scene, &cam), "watertight grid+sphere shadow");
    let mut rays = Vec::new();
    for p in &g.positions {
        rays.push(Ray::new(*p + Vec3::new(0.0, 0.0, 2.0), -Vec3::Z));
    }
    for t in &g.indices {
        let (a, b) = (g.positions[t[0] as usize], g.positions[t[1] as usize]);
        rays.push(Ray::new((a + b) * 0.5 + Vec3::new(0.0, 0.0, 2.0), -Vec3::Z));
    }
    let hits = check_kernels(&scene, &rays, "watertight grid vertices and edges");
    assert_eq!(hits, rays.len(), "every ray at a grid vertex or edge hits the grid");
}

#[test]
fn invalid_rays_miss_in_every_kernel() {
    let scene = scene_of(&[&uv_sphere(20, 20)], &[(Vec3::ZERO, 0.5)], &BuildOptions::default());
    let good = Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z);
    let bad = [
        Ray { origin: Vec3::new(f32::NAN, 0.0, 5.0), ..good },
        Ray { dir: Vec3::new(0.0, f32::INFINITY, -1.0), ..good },
        Ray { dir: Vec3::ZERO, ..good },
        Ray { tnear: 3.0, tfar: 2.0, ..good },
        Ray { tnear: f32::NAN, ..good },
        Ray { tfar: f32::NAN, ..good },
        Ray { origin: Vec3::new(0.0, f32::NEG_INFINITY, 5.0), ..good },
    ];
    // Mix invalid rays into packets with valid ones, in every position.
    let mut rays = Vec::new();
    for i in 0..64 {
        rays.push(if i % 3 == 1 { bad[i % bad.len()] } else { good });
    }
    for (i, r) in rays.iter().enumerate() {
        assert_eq!(scene.intersect1(r).is_hit(), r.is_valid(), "ray {i}");
        assert_eq!(scene.occluded1(r), r.is_valid(), "ray {i}");
    }
    check_kernels(&scene, &rays, "invalid mix");
}

#[test]
fn bvh8_invariants_for_every_collapse() {
    let soup = random_soup(5000, 0.05, 4);
    let g = grid(30, 30);
    let point = random_soup(50, 0.0, 5).map_positions(|_| Vec3::splat(0.25));
    let spheres: Vec<(Vec3, f32)> = (0..40).map(|i| (Vec3::new(i as f32 * 0.05 - 1.0, 0.0, 0.0), 0.04)).collect();
    for (what, scene) in [
        ("soup", scene_of(&[&soup], &[], &BuildOptions::default())),
        ("grid+spheres leaf 8", scene_of(&[&g], &spheres, &BuildOptions { max_leaf_size: 8, ..Default::default() })),
        ("point", scene_of(&[&point], &[], &BuildOptions::default())),
        ("single", scene_of(&[&random_soup(1, 0.5, 7)], &[], &BuildOptions::default())),
        ("one sphere", scene_of(&[], &[(Vec3::ZERO, 1.0)], &BuildOptions::default())),
        ("empty", scene_of(&[], &[], &BuildOptions::default())),
    ] {
        let bounds = prim_bounds(&scene);
        for method in [CollapseMethod::Optimal, CollapseMethod::Greedy] {
            let opts = CollapseOptions { method, ..CollapseOptions::default() };
            let b4: Bvh8<Tri4> = collapse(
                scene.bvh2().expect("binary BVH kept"),
                |id| scene.prim_shape(id),
                scene.num_triangles() as u32,
                &opts,
            );
            let b8: Bvh8<Tri8> = collapse(
                scene.bvh2().expect("binary BVH kept"),
                |id| scene.prim_shape(id),
                scene.num_triangles() as u32,
                &opts,
            );
            validate_bvh8(&b4, &bounds).unwrap_or_else(|e| panic!("{what} {method:?} Tri4: {e}"));
            validate_bvh8(&b8, &bounds).unwrap_or_else(|e| panic!("{what} {method:?} Tri8: {e}"));
            // Both block widths and both collapses give the reference's hits, on every ISA.
            for r in random_rays(&scene, 3000, 11) {
                let want = scene.intersect1_reference(&r);
                for isa in Isa::available() {
                    for got in [b4.intersect1_with(isa, &r, &mut NoCount), b8.intersect1_with(isa, &r, &mut NoCount)] {
                        assert_eq!(got.t.to_bits(), want.t.to_bits(), "{what} {method:?} {isa}");
                    }
                    assert_eq!(b4.occluded1_with(isa, &r, &mut NoCount), want.is_hit(), "{what} {method:?} {isa}");
                    assert_eq!(b8.occluded1_with(isa, &r, &mut NoCount), want.is_hit(), "{what} {method:?} {isa}");
                }
            }
            eprintln!("{what} {method:?}: Tri4 {}", b4.stats());
        }
    }
    // Empty slots never hit: a ray through everything sees only used slots.
    let scene = scene_of(&[&soup], &[], &BuildOptions::default());
    let r1 = raypack::bvh::traverse1::Ray1::<raypack::simd::F32x8>::new(&Ray::new(Vec3::splat(-3.0), Vec3::ONE));
    for n in &scene.bvh8().nodes {
        let (mask, _) = r1.intersect_node(n, f32::INFINITY);
        let used = (0..8).filter(|&i| !n.children[i].is_empty()).fold(0u32, |m, i| m | 1 << i);
        assert_eq!(mask & !used, 0, "an empty slot was hit");
    }
    // Inner children come first, at consecutive indices (`Bvh8Node::inner_child`, which the
    // single-ray kernels follow): two inner slots swapped are rejected.
    let bounds = prim_bounds(&scene);
    let mut forged = scene.bvh8().clone();
    let (i, n) = forged.nodes.iter().enumerate().find(|(_, n)| !n.children[1].is_leaf()).expect("two inner children");
    let mut swapped = *n;
    let (b0, b1) = (n.child_bounds(0), n.child_bounds(1));
    swapped.set_child(0, &b1, n.children[1]);
    swapped.set_child(1, &b0, n.children[0]);
    forged.nodes[i] = swapped;
    let err = validate_bvh8(&forged, &bounds).expect_err("inner children out of place");
    assert!(err.contains("out of place"), "{err}");
}

#[test]
fn optimal_collapse_beats_greedy_sah() {
    let soup = random_soup(20_000, 0.03, 8);
    let scene = scene_of(&[&soup], &[], &BuildOptions::default());
    let opt: Bvh8<Tri4> = collapse(
        scene.bvh2().expect("binary BVH kept"),
        |id| scene.prim_shape(id),
        scene.num_triangles() as u32,
        &CollapseOptions::default(),
    );
    let greedy: Bvh8<Tri4> = collapse(
        scene.bvh2().expect("binary BVH kept"),
        |id| scene.prim_shape(id),
        scene.num_triangles() as u32,
        &CollapseOptions { method: CollapseMethod::Greedy, ..Default::default() },
    );
    let (o, g) = (opt.stats(), greedy.stats());
    eprintln!("optimal {o}\ngreedy  {g}");
    assert!(o.sah_cost <= g.sah_cost, "optimal {} > greedy {}", o.sah_cost, g.sah_cost);
    assert!(o.block_fill > g.block_fill);
    let _ = Tri8::M;
}

#[test]
fn collapse_splits_leaves_that_mix_triangles_and_spheres() {
    // The scene's builder never mixes kinds in a leaf; a binary BVH built without that rule
    // (plain `build_bvh2`, large median-split leaves, spheres sitting on the grid) does, and the collapse
    // must split those leaves rather than put spheres in triangle blocks.
    use raypack::bvh::{BuildPrim, build_bvh2};
    let g = grid(20, 20);
    let spheres: Vec<(Vec3, f32)> =
        (0..60).map(|i| (Vec3::new((i % 10) as f32 * 0.2 - 0.9, 0.0, (i / 10) as f32 * 0.3 - 0.9), 0.03)).collect();
    let scene = scene_of(&[&g], &spheres, &BuildOptions::default());
    let nt = scene.num_triangles() as u32;
    let mut prims: Vec<BuildPrim> =
        (0..scene.num_prims() as u32).map(|id| BuildPrim::new(scene.prim_bounds(id), id)).collect();
    let opts = BuildOptions { max_leaf_size: 16, split: raypack::bvh::SplitMethod::Median, ..BuildOptions::default() };
    let bvh2 = build_bvh2(&mut prims, &opts);
    let mixed = bvh2.nodes.iter().filter(|n| n.is_leaf()).any(|n| {
        let ids = &bvh2.prim_ids[n.start as usize..(n.start + n.count) as usize];
        ids.iter().any(|&id| id < nt) && ids.iter().any(|&id| id >= nt)
    });
    assert!(mixed, "the test needs a leaf that mixes kinds");
    let bounds = prim_bounds(&scene);
    for method in [CollapseMethod::Optimal, CollapseMethod::Greedy] {
        let opts = CollapseOptions { method, ..CollapseOptions::default() };
        let b: Bvh8<Tri8> = collapse(&bvh2, |id| scene.prim_shape(id), nt, &opts);
        validate_bvh8(&b, &bounds).unwrap_or_else(|e| panic!("{method:?}: {e}"));
        assert!(!b.spheres.is_empty());
        for r in random_rays(&scene, 3000, 5) {
            let want = scene.intersect1_reference(&r);
            assert_eq!(b.intersect1(&r).t.to_bits(), want.t.to_bits(), "{method:?}");
            assert_eq!(b.occluded1(&r), want.is_hit(), "{method:?}");
        }
    }
}

/// The compact layout (id blocks, the triangles built from the scene store as the kernels
/// reach them) answers every SIMD kernel of the registry exactly as the default layout does:
/// hits (`t`, `prim`, `u`, `v`) and occlusion bit for bit, on every ISA tier, for both
/// triangle tests and both build qualities, on random, camera and shadow rays; cone culling
/// alike. Its tree is valid, verifies, and is the default tree's with ids for blocks.
#[test]
fn compact_trees_answer_bit_for_bit_as_default_trees() {
    use raypack::TreeLayout;
    use raypack::kernels::simd_kernels;
    let mut mesh = random_soup(20_000, 0.03, 41);
    mesh.append(&uv_sphere(30, 60).map_positions(|p| p * 0.3));
    mesh.append(&slivers(500, 42));
    let spheres = [(Vec3::new(0.3, -0.2, 0.1), 0.15), (Vec3::new(-0.4, 0.4, -0.2), 0.1)];
    let bits = |r: &Results| -> Vec<u128> {
        match r {
            Results::Hits(h) => h
                .iter()
                .map(|h| {
                    (h.t.to_bits() as u128) << 96
                        | (h.u.to_bits() as u128) << 64
                        | (h.v.to_bits() as u128) << 32
                        | h.prim as u128
                })
                .collect(),
            Results::Occluded(o) => o.iter().map(|&b| b as u128).collect(),
        }
    };
    for (watertight, quality) in
        [(false, BuildQuality::Medium), (true, BuildQuality::Medium), (false, BuildQuality::High)]
    {
        let opts = BuildOptions { watertight, quality, ..BuildOptions::default() };
        let default = scene_of(&[&mesh], &spheres, &opts);
        let compact = scene_of(&[&mesh], &spheres, &BuildOptions { layout: TreeLayout::Compact, ..opts });
        let what = format!("watertight {watertight}, {quality:?}");
        assert_eq!((default.layout(), compact.layout()), (TreeLayout::Default, TreeLayout::Compact));
        let (d, c) = (default.bvh8(), compact.bvh8());
        assert!(c.tris.is_empty() && c.ids.len() == d.tris.len(), "{what}: blocks");
        assert!(c.nodes.len() == d.nodes.len() && c.spheres.len() == d.spheres.len(), "{what}: sizes");
        assert!(c.nodes == d.nodes, "{what}: nodes");
        // (Debug text: padding lanes hold NaNs, which `==` never equates.)
        assert_eq!(format!("{:?}", &c.spheres[..]), format!("{:?}", &d.spheres[..]), "{what}: spheres");
        assert!(c.ids.iter().zip(d.tris.iter()).all(|(ids, b)| ids.prim == b.prim), "{what}: ids");
        assert!(c.bytes() * 3 < d.bytes(), "{what}: compact {} bytes, default {}", c.bytes(), d.bytes());
        validate_bvh8(c, &prim_bounds(&compact)).unwrap_or_else(|e| panic!("{what}: invalid compact BVH8: {e}"));
        compact.verify_accel().unwrap_or_else(|e| panic!("{what}: compact tree does not verify: {e}"));
        assert_eq!(compact.with_layout(TreeLayout::Default).bvh8().tris, d.tris, "{what}: back to blocks");
        let mut rays = random_rays(&default, 20_000, 43);
        let camera = camera_rays(&default, 96, 64);
        rays.extend(shadow_rays(&default, &camera));
        rays.extend(camera);
        let mut hits = 0;
        for ((isa, d), (_, c)) in on_every_isa(&default).iter().zip(on_every_isa(&compact)) {
            for k in simd_kernels() {
                let run = |s: &Scene| {
                    let mut out = Results::for_kernel(k, rays.len());
                    k.run(s, &rays, &mut out);
                    out
                };
                let (want, got) = (run(d), run(&c));
                hits += want.hit_count();
                let (want, got) = (bits(&want), bits(&got));
                if let Some(i) = (0..rays.len()).find(|&i| want[i] != got[i]) {
                    panic!(
                        "{what} {} [{isa}]: ray {i} {:?}: compact {:x}, default {:x}",
                        k.name, rays[i], got[i], want[i]
                    );
                }
            }
            let mut rng = Rng::new(44, watertight as u64);
            let mut r3 = move || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5;
            for _ in 0..2000 {
                let (o, dir, half) = (r3() * 3.0, r3(), r3().abs() * 0.2);
                let (lo, hi) = (dir - half, dir + half);
                assert_eq!(d.cone_may_hit(o, lo, hi), c.cone_may_hit(o, lo, hi), "{what} [{isa}]: cone");
            }
        }
        assert!(hits > rays.len(), "{what}: too few hits ({hits}) to mean anything");
    }
}
