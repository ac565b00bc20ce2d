//! raypack's kernels beside Embree's calls on generated scenes (cargo feature `embree`):
//! `cargo bench --features embree --bench embree`. The same ray sets and methods as
//! `raypack bench --against embree`, single-threaded, under criterion's statistics.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use raypack::embree::{EmbreeQuality, EmbreeScene};
use raypack::generate::{Mesh, random_soup, torus_knot};
use raypack::kernels::{Results, embree_methods, raypack_methods, trace};
use raypack::raysets::bench_sets;
use raypack::{BuildOptions, Material, Scene, SceneBuilder, Vec3};

fn scene_of(mesh: &Mesh) -> Scene {
    let mut b = SceneBuilder::new();
    let m = b.add_material(Material::diffuse(Vec3::splat(0.5)));
    b.add_mesh(&mesh.positions, &mesh.indices, m).expect("valid mesh");
    // The binary BVH stays: the reference rows and the collapse bench need it.
    b.commit(&BuildOptions { keep_bvh2: true, ..BuildOptions::default() }).0
}

fn bench(c: &mut Criterion) {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("thread pool");
    let scenes = [
        ("knot 100k", scene_of(&torus_knot(1000, 50, 2.0, 3.0, 0.4, 0.1))),
        ("soup 100k", scene_of(&random_soup(100_000, 0.03, 1))),
    ];
    for (name, scene) in &scenes {
        let embree = EmbreeScene::new(scene, EmbreeQuality::High).expect("Embree accepts the scene");
        let mut methods = raypack_methods(scene);
        methods.extend(embree_methods(&embree, ""));
        for set in bench_sets(scene, 256, 192, 1) {
            let mut group = c.benchmark_group(format!("embree/{name}/{}", set.kind.name()));
            group.throughput(Throughput::Elements(set.rays.len() as u64)).sample_size(10);
            let reference = &methods[0];
            let mut ref_out = Results::for_run(&reference.run, set.rays.len());
            trace(&reference.run, &set.rays, &mut ref_out);
            for m in methods.iter().filter(|m| m.run.is_occlusion() == set.kind.is_occlusion()) {
                // Validate once before timing: hit counts agree with the reference within
                // the edge cases the cross-check test allows.
                let mut out = Results::for_run(&m.run, set.rays.len());
                pool.install(|| trace(&m.run, &set.rays, &mut out));
                let (a, b) = (out.checksum(&set.rays).hits, ref_out_checksum(&ref_out, &set.rays, &m.run, scene));
                assert!(a.abs_diff(b) as f64 <= 1e-3 * set.rays.len() as f64 + 1.0, "{} {}: {a} vs {b}", name, m.name);
                group.bench_function(BenchmarkId::from_parameter(format!("{} {}", m.tracer, m.name)), |bch| {
                    bch.iter(|| pool.install(|| trace(&m.run, &set.rays, &mut out)))
                });
            }
            group.finish();
        }
    }
}

/// The reference's hit count for the query `run` answers.
fn ref_out_checksum(ref_out: &Results, rays: &[raypack::Ray], run: &raypack::kernels::Run<'_>, scene: &Scene) -> u64 {
    if run.is_occlusion() {
        rays.iter().filter(|r| scene.occluded1_reference(r)).count() as u64
    } else {
        ref_out.checksum(rays).hits
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
