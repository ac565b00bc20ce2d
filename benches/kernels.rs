//! Micro-benchmarks of the SIMD building blocks, one ray-box or ray-primitive test per
//! element: `cargo bench --bench kernels`.
//!
//! Each kernel is checked once against its scalar twin before it is timed (CONTRIBUTING.md, rule 5).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use raypack::bvh::Bvh8Node;
use raypack::bvh::node::NodeRef;
use raypack::bvh::traverse_packet::PacketRays;
use raypack::bvh::traverse1::Ray1;
use raypack::geometry::tri_block::moller_trumbore;
use raypack::geometry::{Sphere4, Tri4, Tri8, TriBlock, intersect_triangle};
use raypack::rng::Rng;
use raypack::simd::{F32x4, F32x8, F32x16, Lanes, Vec3x};
use raypack::{Aabb, Ray, Vec3};
use std::hint::black_box;

const N: usize = 4096;

fn rng_vec(rng: &mut Rng) -> Vec3 {
    Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0
}

/// Rays from outside the unit cube aimed into it.
fn rays(seed: u64) -> Vec<Ray> {
    let mut rng = Rng::new(seed, 1);
    (0..N)
        .map(|_| {
            let o = rng_vec(&mut rng).normalize_or(Vec3::X) * 3.0;
            let target = rng_vec(&mut rng) * 0.5;
            Ray::new(o, (target - o).normalize())
        })
        .collect()
}

fn nodes(seed: u64) -> Vec<Bvh8Node> {
    let mut rng = Rng::new(seed, 2);
    (0..64)
        .map(|_| {
            let mut n = Bvh8Node::EMPTY;
            for i in 0..8 {
                let c = rng_vec(&mut rng) * 0.8;
                n.set_child(i, &Aabb::new(c - Vec3::splat(0.15), c + Vec3::splat(0.15)), NodeRef::inner(i as u32));
            }
            n
        })
        .collect()
}

fn triangles(seed: u64, n: usize) -> Vec<[Vec3; 3]> {
    let mut rng = Rng::new(seed, 3);
    (0..n)
        .map(|_| {
            let c = rng_vec(&mut rng) * 0.5;
            [c + rng_vec(&mut rng) * 0.3, c + rng_vec(&mut rng) * 0.3, c + rng_vec(&mut rng) * 0.3]
        })
        .collect()
}

fn blocks<B: TriBlock>(tris: &[[Vec3; 3]]) -> Vec<B> {
    tris.chunks(B::M)
        .enumerate()
        .map(|(k, c)| {
            let mut b = B::EMPTY;
            for (i, t) in c.iter().enumerate() {
                b.set(i, t[0], t[1], t[2], (k * B::M + i) as u32);
            }
            b
        })
        .collect()
}

fn box_tests(c: &mut Criterion) {
    let (rays, nodes) = (rays(1), nodes(2));
    let pre: Vec<Ray1<F32x8>> = rays.iter().map(Ray1::new).collect();
    // Validate: SIMD masks equal the scalar twin.
    for (r, n) in pre.iter().zip(nodes.iter().cycle()) {
        assert_eq!(r.intersect_node(n, f32::INFINITY).0, r.intersect_node_scalar(n, f32::INFINITY));
    }
    let mut g = c.benchmark_group("kernels/box");
    g.throughput(Throughput::Elements((N * 8) as u64));
    g.bench_function("1 ray x 8 boxes (simd)", |b| {
        b.iter(|| {
            let mut acc = 0u32;
            for (r, n) in pre.iter().zip(nodes.iter().cycle()) {
                acc ^= r.intersect_node(n, f32::INFINITY).0;
            }
            black_box(acc)
        })
    });
    g.bench_function("1 ray x 8 boxes (scalar twin)", |b| {
        b.iter(|| {
            let mut acc = 0u32;
            for (r, n) in pre.iter().zip(nodes.iter().cycle()) {
                acc ^= r.intersect_node_scalar(n, f32::INFINITY);
            }
            black_box(acc)
        })
    });
    let packets: Vec<PacketRays<F32x16>> = rays.chunks(16).map(|c| PacketRays::new(c, u32::MAX)).collect();
    g.bench_function("16 rays x 1 box (simd)", |b| {
        b.iter(|| {
            let mut acc = 0u32;
            for (p, n) in packets.iter().zip(nodes.iter().cycle()) {
                for i in 0..8 {
                    acc ^= p.intersect_box(n, i).0.bitmask();
                }
            }
            black_box(acc)
        })
    });
    g.finish();
}

fn triangle_tests(c: &mut Criterion) {
    let rays = rays(3);
    let tris = triangles(4, 64);
    let (b4, b8) = (blocks::<Tri4>(&tris), blocks::<Tri8>(&tris));
    for r in rays.iter().take(256) {
        let h = b8[0].intersect1(&Vec3x::splat(r.origin), &Vec3x::splat(r.dir), F32x8::splat(0.0), F32x8::splat(9.0));
        for (i, t) in tris.iter().take(8).enumerate() {
            let want = intersect_triangle(r.origin, r.dir, 0.0, 9.0, t[0], t[1], t[2]);
            assert_eq!(want.map(|x| x.0.to_bits()), (h.mask >> i & 1 == 1).then(|| h.t.lane(i).to_bits()));
        }
    }
    let mut g = c.benchmark_group("kernels/triangle");
    g.throughput(Throughput::Elements((N * tris.len()) as u64));
    g.bench_function(BenchmarkId::new("1 ray x block", "M=4"), |b| {
        b.iter(|| {
            let mut acc = 0u32;
            for r in &rays {
                let (o, d) = (Vec3x::splat(r.origin), Vec3x::splat(r.dir));
                for blk in &b4 {
                    acc ^= blk.intersect1(&o, &d, F32x4::splat(0.0), F32x4::splat(f32::INFINITY)).mask;
                }
            }
            black_box(acc)
        })
    });
    g.bench_function(BenchmarkId::new("1 ray x block", "M=8"), |b| {
        b.iter(|| {
            let mut acc = 0u32;
            for r in &rays {
                let (o, d) = (Vec3x::splat(r.origin), Vec3x::splat(r.dir));
                for blk in &b8 {
                    acc ^= blk.intersect1(&o, &d, F32x8::splat(0.0), F32x8::splat(f32::INFINITY)).mask;
                }
            }
            black_box(acc)
        })
    });
    g.bench_function("1 ray x 1 triangle (scalar reference)", |b| {
        b.iter(|| {
            let mut acc = 0usize;
            for r in &rays {
                for t in &tris {
                    acc += intersect_triangle(r.origin, r.dir, 0.0, f32::INFINITY, t[0], t[1], t[2]).is_some() as usize;
                }
            }
            black_box(acc)
        })
    });
    let packets: Vec<PacketRays<F32x16>> = rays.chunks(16).map(|c| PacketRays::new(c, u32::MAX)).collect();
    g.bench_function("16 rays x 1 triangle", |b| {
        b.iter(|| {
            let mut acc = 0u32;
            for p in &packets {
                for t in &tris {
                    let (m, ..) = moller_trumbore(
                        &p.org,
                        &p.dir,
                        p.tnear,
                        p.tfar,
                        &Vec3x::splat(t[0]),
                        &Vec3x::splat(t[1] - t[0]),
                        &Vec3x::splat(t[2] - t[0]),
                    );
                    acc ^= m.bitmask();
                }
            }
            black_box(acc)
        })
    });
    g.finish();

    let mut sph = Sphere4::EMPTY;
    for i in 0..4 {
        sph.set(i, Vec3::new(i as f32 * 0.3 - 0.45, 0.0, 0.0), 0.2, i as u32);
    }
    for r in rays.iter().take(256) {
        let (m, t) = sph.intersect1::<F32x4>(r.origin, r.dir, 0.0, f32::INFINITY);
        let twin = sph.intersect1_scalar(r.origin, r.dir, 0.0, f32::INFINITY);
        for (i, w) in twin.iter().enumerate() {
            assert_eq!(w.map(f32::to_bits), (m >> i & 1 == 1).then(|| t.lane(i).to_bits()));
        }
    }
    let mut g = c.benchmark_group("kernels/sphere");
    g.throughput(Throughput::Elements((N * 4) as u64));
    g.bench_function("1 ray x 4 spheres", |b| {
        b.iter(|| {
            let mut acc = 0u32;
            for r in &rays {
                acc ^= sph.intersect1::<F32x4>(r.origin, r.dir, 0.0, f32::INFINITY).0;
            }
            black_box(acc)
        })
    });
    g.finish();
}

criterion_group!(benches, box_tests, triangle_tests);
criterion_main!(benches);
