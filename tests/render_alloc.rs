//! The render loop allocates per tile, never per sample: with a counting global allocator, a
//! render at 64 samples per pixel (also adaptive) makes no more allocations than one at 1.

use raypack::render::{self, IntegratorKind, RenderSettings};
use raypack::{BuildOptions, Camera, Light, Material, SceneBuilder, Vec3};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

struct Counting;
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn samples_do_not_allocate() {
    let mut b = SceneBuilder::new();
    let white = b.add_material(Material::diffuse(Vec3::splat(0.7)));
    let glass = b.add_material(Material::glass(1.5));
    let light = b.add_material(Material::emissive(Vec3::splat(5.0)));
    let s = raypack::generate::uv_sphere(8, 16).map_positions(|p| p * 3.0);
    b.add_mesh(&s.positions, &s.indices, white).unwrap();
    b.add_sphere(Vec3::new(0.5, -0.5, 0.0), 0.6, glass).unwrap();
    b.add_sphere(Vec3::new(0.0, 2.0, 0.0), 0.5, light).unwrap();
    b.add_light(Light::Point { position: Vec3::new(-1.0, 1.0, 1.0), intensity: Vec3::ONE });
    let (scene, _) = b.commit(&BuildOptions::default());
    let camera = Camera::look_at(Vec3::new(0.0, 0.0, 2.5), Vec3::ZERO, Vec3::Y, 70.0, 1.0, 1e-3, 100.0);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let count = |spp: u32, adaptive: Option<(u32, f32)>| {
        let st = RenderSettings {
            width: 40,
            height: 40,
            samples_per_pixel: spp,
            adaptive,
            max_depth: 5,
            light_samples: 2,
            integrator: IntegratorKind::Global,
            ..RenderSettings::default()
        };
        pool.install(|| {
            let before = ALLOCATIONS.load(Ordering::Relaxed);
            let out = render::render(&scene, &camera, &st, &|_| {});
            let n = ALLOCATIONS.load(Ordering::Relaxed) - before;
            (n, out.stats.samples)
        })
    };
    let (one, s1) = count(1, None);
    let (many, s64) = count(64, None);
    let (adaptive, sa) = count(64, Some((8, 0.05)));
    assert_eq!((s1, s64), (1600, 64 * 1600));
    assert!(sa > 1600);
    assert!(many <= one && adaptive <= one, "allocations: {one} at 1 spp, {many} at 64 spp, {adaptive} adaptive");
}
