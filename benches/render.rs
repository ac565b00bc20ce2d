//! The path tracer's speed on the project's own Cornell box (`scenes/cornell.dae`): samples per
//! second of each integrator at a small size, one thread (the tile loop is per thread).
//!
//! `cargo bench --bench render`. Each configuration's image is checked once (finite, lit)
//! before it is timed.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use raypack::render::{self, IntegratorKind, RenderSettings};
use raypack::{BuildOptions, Scene};
use std::path::Path;

fn cornell() -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell.dae");
    let builder = raypack::io::load_scene(&path).expect("scenes/cornell.dae loads").builder;
    builder.commit(&BuildOptions::default()).0
}

fn bench(c: &mut Criterion) {
    let scene = cornell();
    let (w, h) = (64, 48);
    let camera = scene.camera_or_framing(w as f32 / h as f32);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let configs = [
        ("direct_l4", IntegratorKind::Direct, false, 4, 1),
        ("direct_H_l4", IntegratorKind::Direct, true, 4, 1),
        ("global_m5_l1", IntegratorKind::Global, false, 1, 5),
    ];
    let mut group = c.benchmark_group("render_cornell_64x48_s4");
    group.sample_size(10);
    for (name, integrator, hemisphere, light_samples, max_depth) in configs {
        let s = RenderSettings {
            width: w,
            height: h,
            samples_per_pixel: 4,
            light_samples,
            max_depth,
            hemisphere_sampling: hemisphere,
            integrator,
            ..RenderSettings::default()
        };
        let out = pool.install(|| render::render(&scene, &camera, &s, &|_| {}));
        let mean = out.film.mean();
        assert!(mean.is_finite() && mean.max_element() > 0.01, "{name}: image mean {mean}");
        assert_eq!(out.stats.invalid_samples, 0);
        group.throughput(Throughput::Elements(out.stats.samples));
        group.bench_function(name, |b| b.iter(|| pool.install(|| render::render(&scene, &camera, &s, &|_| {}))));
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
