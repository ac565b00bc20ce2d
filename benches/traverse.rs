//! Build and traversal on generated scenes: `cargo bench --bench traverse`.
//!
//! * `build/*`: the binned-SAH BVH2 and its collapse into the BVH8, per primitive;
//! * `traverse/<scene>/<rays>`: every kernel of `raypack::kernels::KERNELS` on the
//!   standard ray sets (camera rays in 4 x 4 tiles, diffuse bounces, shadow rays), one
//!   thread, in rays per second (criterion's element throughput).
//!
//! Every kernel's hit count is checked against the scalar reference once before timing, and
//! each scene's BVH quality is printed beside the speeds (CONTRIBUTING.md, rule 5).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use raypack::bvh::{BuildPrim, Bvh8, CollapseOptions, build_bvh2, collapse};
use raypack::generate::{Mesh, grid, random_soup, torus_knot, uv_sphere};
use raypack::kernels::{Results, raypack_methods, trace};
use raypack::raysets::bench_sets;
use raypack::{BuildOptions, Material, Scene, SceneBuilder, Vec3};

fn scene_of(mesh: &Mesh, spheres: &[(Vec3, f32)]) -> Scene {
    let mut b = SceneBuilder::new();
    let m = b.add_material(Material::diffuse(Vec3::splat(0.5)));
    b.add_mesh(&mesh.positions, &mesh.indices, m).expect("valid mesh");
    for &(c, r) in spheres {
        b.add_sphere(c, r, m).expect("valid sphere");
    }
    // The binary BVH stays: the reference rows and the collapse bench need it.
    b.commit(&BuildOptions { keep_bvh2: true, ..BuildOptions::default() }).0
}

fn scenes() -> Vec<(&'static str, Scene)> {
    let mut floor = grid(100, 100).map_positions(|p| Vec3::new(p.x * 2.0, -1.0, p.y * 2.0));
    floor.append(&uv_sphere(60, 120).map_positions(|p| p * 0.7));
    let spheres: Vec<(Vec3, f32)> = (0..20).map(|i| (Vec3::new(i as f32 * 0.2 - 2.0, -0.7, 1.2), 0.09)).collect();
    vec![
        ("knot 200k", scene_of(&torus_knot(2000, 50, 2.0, 3.0, 0.4, 0.1), &[])),
        ("soup 100k", scene_of(&random_soup(100_000, 0.03, 1), &[])),
        ("floor+sphere+spheres 34k", scene_of(&floor, &spheres)),
    ]
}

fn build(c: &mut Criterion) {
    let mesh = torus_knot(2000, 50, 2.0, 3.0, 0.4, 0.1);
    let scene = scene_of(&mesh, &[]);
    let n = scene.num_prims();
    let prims: Vec<BuildPrim> = (0..n as u32).map(|id| BuildPrim::new(scene.prim_bounds(id), id)).collect();
    let mut g = c.benchmark_group("build/knot 200k");
    g.throughput(Throughput::Elements(n as u64)).sample_size(10);
    g.bench_function("binned SAH BVH2", |b| {
        b.iter(|| {
            let mut p = prims.clone();
            build_bvh2(&mut p, &BuildOptions::default())
        })
    });
    g.bench_function("collapse to BVH8 (M=8)", |b| {
        b.iter(|| -> Bvh8 {
            collapse(
                scene.bvh2().expect("kept"),
                |id| scene.prim_shape(id),
                scene.num_triangles() as u32,
                &CollapseOptions::default(),
            )
        })
    });
    g.finish();
}

fn traverse(c: &mut Criterion) {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("thread pool");
    for (name, scene) in scenes() {
        eprintln!("{name}: BVH2 {}; BVH8 {}", scene.bvh_stats().expect("kept"), scene.bvh8().stats());
        let methods = raypack_methods(&scene);
        for set in bench_sets(&scene, 512, 384, 1) {
            let occlusion = set.kind.is_occlusion();
            let mut group = c.benchmark_group(format!("traverse/{name}/{}", set.kind.name()));
            group.throughput(Throughput::Elements(set.rays.len() as u64)).sample_size(10);
            let reference = methods.iter().find(|m| m.run.is_occlusion() == occlusion).expect("reference kernel");
            let mut want = Results::for_run(&reference.run, set.rays.len());
            trace(&reference.run, &set.rays, &mut want);
            let want = want.checksum(&set.rays);
            for m in methods.iter().filter(|m| m.run.is_occlusion() == occlusion) {
                let mut out = Results::for_run(&m.run, set.rays.len());
                pool.install(|| trace(&m.run, &set.rays, &mut out));
                let got = out.checksum(&set.rays);
                assert_eq!((got.hits, got.t_sum.to_bits()), (want.hits, want.t_sum.to_bits()), "{name} {}", m.name);
                group.bench_function(BenchmarkId::from_parameter(&m.name), |b| {
                    b.iter(|| pool.install(|| trace(&m.run, &set.rays, &mut out)))
                });
            }
            group.finish();
        }
    }
}

criterion_group!(benches, build, traverse);
criterion_main!(benches);
