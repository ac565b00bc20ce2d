//! Traces `raypack bench`'s three ray sets once with the single-ray kernels and once with the
//! stream (16-ray packet) kernels, on one thread, for instruction counts under callgrind — the
//! comparison of the two triangle tests that the shared machine's noisy clocks cannot give:
//!
//! ```sh
//! cargo build --release --features tools --bin triangle_test_cost
//! for w in "" --watertight; do
//!   valgrind --tool=callgrind --callgrind-out-file=/tmp/cg$w.out --collect-atstart=no \
//!     --toggle-collect='*trace_single*' --toggle-collect='*trace_packets*' \
//!     target/release/triangle_test_cost SCENE 512 384 $w
//!   callgrind_annotate --inclusive=yes /tmp/cg$w.out | grep trace_
//! done
//! ```

use raypack::raysets::{RaySet, bench_sets};
use raypack::{BuildOptions, Hit, StreamOptions};
use std::path::PathBuf;
use std::process::ExitCode;

/// Every set through the single-ray queries; returns a checksum so nothing is optimised away.
#[inline(never)]
fn trace_single(scene: &raypack::Scene, sets: &[RaySet]) -> u64 {
    let mut sum = 0u64;
    for set in sets {
        for r in &set.rays {
            sum += if set.kind.is_occlusion() { scene.occluded1(r) as u64 } else { scene.intersect1(r).prim as u64 };
        }
    }
    sum
}

/// Every set through the stream queries (16-ray packets) on the calling thread.
#[inline(never)]
fn trace_packets(scene: &raypack::Scene, sets: &[RaySet]) -> u64 {
    let mut sum = 0u64;
    for set in sets {
        if set.kind.is_occlusion() {
            let mut occ = vec![false; set.rays.len()];
            scene.occluded_stream(&set.rays, &mut occ, &StreamOptions::CALLER);
            sum += occ.iter().filter(|&&o| o).count() as u64;
        } else {
            let mut hits = vec![Hit::MISS; set.rays.len()];
            scene.intersect_stream(&set.rays, &mut hits, &StreamOptions::CALLER);
            sum += hits.iter().map(|h| h.prim as u64).sum::<u64>();
        }
    }
    sum
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: triangle_test_cost SCENE WIDTH HEIGHT [--watertight]";
    let (Some(path), Some(w), Some(h)) = (
        args.get(1).map(PathBuf::from),
        args.get(2).and_then(|s| s.parse::<usize>().ok()),
        args.get(3).and_then(|s| s.parse::<usize>().ok()),
    ) else {
        eprintln!("{usage}");
        return ExitCode::from(2);
    };
    let watertight = args.get(4).is_some_and(|a| a == "--watertight");
    let builder = match raypack::io::load_scene(&path) {
        Ok(loaded) => loaded.builder,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let (scene, _) = builder.commit(&BuildOptions { watertight, ..BuildOptions::default() });
    let sets = bench_sets(&scene, w, h, 1);
    let rays: usize = sets.iter().map(|s| s.rays.len()).sum();
    let (a, b) = (trace_single(&scene, &sets), trace_packets(&scene, &sets));
    println!("{} test: {rays} rays, checksums {a} {b}", scene.triangle_test().name());
    ExitCode::SUCCESS
}
