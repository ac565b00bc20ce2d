// Traces `raypack bench`'s ray sets with raypack's SIMD kernels on one thread, as a
// dependent crate built with no RUSTFLAGS does, and prints one line per set and kernel:
// `set kernel isa Mrays/s` (median of `--runs`, each run repeating the set to last 50 ms).
//
// Usage: dependent-check SCENE [--isa sse|avx2|avx512] [--runs N] [-r W H]
//        dependent-check --list-isas
//
// The project builds the same source as `tools/bin/dependent_kernels.rs` (which includes this
// file), so `run.sh` compares one program under two builds.

use raypack::kernels::{Results, simd_kernels};
use raypack::{BuildOptions, Isa};
use std::time::{Duration, Instant};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("--list-isas") {
        let isas: Vec<&str> = Isa::ALL.iter().filter(|i| i.is_supported()).map(|i| i.name()).collect();
        println!("{}", isas.join(" "));
        return Ok(());
    }
    let scene_path = args.get(1).ok_or("usage: dependent-check SCENE [--isa I] [--runs N] [-r W H]")?;
    let mut isa = Isa::detected();
    let (mut runs, mut width, mut height) = (5usize, 1024usize, 768usize);
    let mut i = 2;
    while i < args.len() {
        match args[i].as_str() {
            "--isa" => isa = Isa::parse(&args[i + 1])?.check()?,
            "--runs" => runs = args[i + 1].parse()?,
            "-r" => {
                width = args[i + 1].parse()?;
                height = args[i + 2].parse()?;
                i += 1;
            }
            other => return Err(format!("unknown argument {other}").into()),
        }
        i += 2;
    }
    let builder = raypack::io::load_scene(std::path::Path::new(scene_path))?.builder;
    let opts = BuildOptions { keep_bvh2: true, ..BuildOptions::default() };
    let (mut scene, _) = builder.commit(&opts);
    scene.set_isa(isa)?;
    let sets = raypack::raysets::bench_sets(&scene, width, height, 1);
    for set in &sets {
        for k in simd_kernels().filter(|k| k.is_occlusion() == set.kind.is_occlusion()) {
            let mut out = Results::for_kernel(k, set.rays.len());
            let mrays = {
                let t0 = Instant::now();
                k.run(&scene, &set.rays, &mut out);
                let reps = ((0.05 / t0.elapsed().as_secs_f64().max(1e-7)).ceil() as usize).clamp(1, 1000);
                let mut times: Vec<Duration> = (0..runs)
                    .map(|_| {
                        let t0 = Instant::now();
                        for _ in 0..reps {
                            k.run(&scene, &set.rays, &mut out);
                        }
                        t0.elapsed()
                    })
                    .collect();
                times.sort();
                (reps * set.rays.len()) as f64 / times[times.len() / 2].as_secs_f64() / 1e6
            };
            println!("{} {} {} {:.3} hits {}", set.kind.name(), k.name, isa, mrays, out.hit_count());
        }
    }
    Ok(())
}
