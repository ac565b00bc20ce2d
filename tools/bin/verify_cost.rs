//! What verifying a loaded tree ([`raypack::Scene::verify_accel`], run on every BVH cache
//! load) costs against building it: the measurement behind verifying every cache file.
//!
//! ```sh
//! cargo run --release --features tools --bin verify_cost -- SCENE [QUALITY] [ROUNDS]
//! ```
//!
//! Builds the scene (fast, medium or high; default medium) and verifies the result, ROUNDS
//! times interleaved (default 7), on the global thread pool (`RAYON_NUM_THREADS`), and prints
//! each one's median, fastest and slowest.

use raypack::{BuildOptions, BuildQuality};
use std::time::{Duration, Instant};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: verify_cost SCENE [fast|medium|high] [ROUNDS]");
    let quality = match args.get(2).map_or("medium", String::as_str) {
        "fast" => BuildQuality::Fast,
        "high" => BuildQuality::High,
        _ => BuildQuality::Medium,
    };
    let rounds: usize = args.get(3).and_then(|r| r.parse().ok()).unwrap_or(7);
    let loaded = raypack::io::load_scene(std::path::Path::new(path)).expect("the scene loads");
    let opts = BuildOptions { quality, ..BuildOptions::default() };
    let (mut builds, mut checks) = (Vec::new(), Vec::new());
    for _ in 0..rounds {
        let b = loaded.builder.clone();
        let t = Instant::now();
        let (scene, _) = b.commit(&opts);
        builds.push(t.elapsed());
        let t = Instant::now();
        scene.verify_accel().expect("a build verifies");
        checks.push(t.elapsed());
    }
    let show = |mut v: Vec<Duration>| {
        v.sort();
        format!("{:.4} s ({:.4}-{:.4})", v[v.len() / 2].as_secs_f64(), v[0].as_secs_f64(), v[v.len() - 1].as_secs_f64())
    };
    println!("{path} {quality:?}, {} threads, {rounds} interleaved rounds", rayon::current_num_threads());
    println!("commit (filter and build) {}", show(builds));
    println!("verify_accel              {}", show(checks));
}
