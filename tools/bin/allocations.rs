//! How much of a BVH build and of a render is spent in the allocator: the measurement behind
//! not using an arena (`bumpalo`) for the builder's temporaries or per-tile render buffers.
//!
//! ```sh
//! cargo run --release --features tools --bin allocations -- SCENE [WIDTH HEIGHT SPP]
//! ```
//!
//! Prints, for the commit (medium quality) and for a render of the scene's camera, the wall
//! time, the allocator calls and the time spent inside them, on all threads.

use raypack::render::{self, RenderSettings};
use raypack::{BuildOptions, Camera};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::Instant;

struct Timed;
static CALLS: AtomicU64 = AtomicU64::new(0);
static BYTES: AtomicU64 = AtomicU64::new(0);
static NANOS: AtomicU64 = AtomicU64::new(0);

fn timed<T>(f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let r = f();
    NANOS.fetch_add(t.elapsed().as_nanos() as u64, Relaxed);
    CALLS.fetch_add(1, Relaxed);
    r
}

// SAFETY: forwards to the system allocator unchanged; only counts and times the calls.
unsafe impl GlobalAlloc for Timed {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        BYTES.fetch_add(layout.size() as u64, Relaxed);
        // SAFETY: same contract as the caller's.
        timed(|| unsafe { System.alloc(layout) })
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        timed(|| unsafe { System.dealloc(ptr, layout) })
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        BYTES.fetch_add(new_size as u64, Relaxed);
        // SAFETY: same contract as the caller's.
        timed(|| unsafe { System.realloc(ptr, layout, new_size) })
    }
}

#[global_allocator]
static GLOBAL: Timed = Timed;

/// Runs `f` and prints its wall time and its allocator calls.
fn measure<T>(what: &str, f: impl FnOnce() -> T) -> T {
    let (c0, b0, n0) = (CALLS.load(Relaxed), BYTES.load(Relaxed), NANOS.load(Relaxed));
    let t = Instant::now();
    let r = f();
    let wall = t.elapsed().as_secs_f64();
    let (calls, bytes, nanos) = (CALLS.load(Relaxed) - c0, BYTES.load(Relaxed) - b0, NANOS.load(Relaxed) - n0);
    println!(
        "{what:<8} {wall:>8.4} s wall, {calls:>8} allocator calls ({:.1} MB asked), {:.4} s inside them on all threads ({:.2}% of wall x threads)",
        bytes as f64 / 1e6,
        nanos as f64 / 1e9,
        100.0 * nanos as f64 / 1e9 / (wall * rayon::current_num_threads() as f64)
    );
    r
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: allocations SCENE [WIDTH HEIGHT SPP]");
        std::process::exit(2);
    };
    let num = |i: usize, d: usize| args.get(i).map_or(d, |s| s.parse().expect("a number"));
    let (width, height, spp) = (num(2, 320), num(3, 240), num(4, 4) as u32);
    let builder = raypack::io::load_scene(std::path::Path::new(path)).unwrap_or_else(|e| panic!("{e}")).builder;
    println!("{path}, {} threads", rayon::current_num_threads());
    let (scene, _) = measure("build", || builder.commit(&BuildOptions::default()));
    let camera = scene.camera.unwrap_or_else(|| Camera::framing(&scene.bounds(), width as f32 / height as f32));
    let settings = RenderSettings { width, height, samples_per_pixel: spp, ..RenderSettings::default() };
    measure("render", || render::render(&scene, &camera, &settings, &|_| {}));
}
