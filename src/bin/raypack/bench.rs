//! `raypack bench`: parses the flags, builds the trees (timed), runs the library's bench
//! ([`raypack::bench::run_bench`]) and prints or writes its report.

use crate::say;
use crate::{BenchArgs, CliError, check_memory, load, print_warnings};
use raypack::bench::{BenchError, BenchSettings, BuildFigures, RaypackTree, raypack_accel_bytes, run_bench};
use raypack::{BuildOptions, Scene, SceneBuilder};
use std::path::Path;
use std::time::{Duration, Instant};

/// Builds `builder` with `opts` once, timed (or loads it from `--bvh-cache`); returns the
/// scene and its build figures. [`rebuild_time`] times the builds after it.
fn build_timed(builder: &SceneBuilder, opts: &BuildOptions, a: &BenchArgs) -> Result<(Scene, BuildFigures), CliError> {
    let b = builder.clone();
    let t = Instant::now();
    let (scene, report) = match a.bvh_cache.as_deref() {
        None => b.commit(opts),
        Some(dir) => {
            let (scene, report, cache) = b.commit_cached(opts, dir);
            for w in cache.warnings() {
                say::warning(w);
            }
            if cache.loaded {
                say::line(format_args!(
                    "BVH loaded from {} (the build time below is the load time)",
                    cache.path.display()
                ));
            }
            (scene, report)
        }
    };
    let time = t.elapsed();
    if report.dropped() > 0 {
        say::warning(report);
    }
    let build = BuildFigures::from_times(
        "raypack",
        match opts.layout {
            raypack::TreeLayout::Default => format!("bvh8 {} {}", opts.quality.name(), scene.triangle_test().name()),
            layout => format!("bvh8 {} {} {layout}", opts.quality.name(), scene.triangle_test().name()),
        },
        &[time],
        raypack_accel_bytes(&scene) as u64,
    );
    Ok((scene, build))
}

/// The time of one more build of `builder` with `opts`. What it built is freed outside the
/// timed region, as Embree's scenes are (their build time is `rtcCommitScene` alone):
/// unmapping a large scene's arrays took tens of milliseconds.
fn rebuild_time(builder: &SceneBuilder, opts: &BuildOptions) -> Duration {
    let b = builder.clone();
    let t = Instant::now();
    let built = b.commit(opts);
    let time = t.elapsed();
    drop(built);
    time
}

/// `raypack bench`: checks the settings and the memory, builds the scene, runs [`run_bench`] and
/// prints or writes the report.
pub(crate) fn cmd_bench(a: BenchArgs) -> Result<(), CliError> {
    use raypack::fs::output::{OutputOptions, check_target, write_file_with};
    let (width, height) = (a.resolution[0], a.resolution[1]);
    if width == 0 || height == 0 || width > 1 << 15 || height > 1 << 15 {
        return Err(CliError::Usage(format!("-r {width} {height}: width and height must be between 1 and 32768")));
    }
    if a.runs == 0 {
        return Err(CliError::Usage("--runs 0: need at least one timed run".into()));
    }
    if a.build_runs == 0 {
        return Err(CliError::Usage("--build-runs 0: need at least one build".into()));
    }
    // `-t N` is checked as on every command; in `--threads-list`, 0 means all cores.
    crate::check_threads(a.threads)?;
    for &t in a.threads_list.iter().filter(|&&t| t > 0) {
        raypack::system::check_threads(t).map_err(|e| CliError::Usage(format!("--threads-list {t}: {e}")))?;
    }
    let threads = match (a.threads, a.threads_list.is_empty()) {
        (Some(t), _) => vec![t],
        (None, false) => a.threads_list.clone(),
        (None, true) => vec![1, 0],
    };
    let mut settings = BenchSettings {
        width,
        height,
        runs: a.runs,
        build_runs: a.build_runs,
        against_embree: a.against.is_some(),
        embree_robust: a.watertight,
        isa: a.isa,
        methods: a.methods.clone(),
        threads,
        ..Default::default()
    };
    if settings.against_embree && !cfg!(feature = "embree") {
        return Err(BenchError::EmbreeNotBuilt.into());
    }
    let scene_path = a.scene_path();
    let inputs: Vec<&Path> = scene_path.into_iter().collect();
    let json_opts = OutputOptions::protecting(&inputs);
    if let Some(p) = a.json.as_deref().filter(|p| *p != Path::new("-")) {
        check_target(p, &json_opts)?;
    }
    // The report directory is checked before the run, not after it.
    let report_inputs: Vec<std::path::PathBuf> = inputs.iter().map(|p| p.to_path_buf()).collect();
    if let Some(dir) = &a.report {
        crate::report::check_report_dir(dir, &[dir.join("bench.json")], &report_inputs)?;
    }
    let per_ray = raypack::raysets::BENCH_BYTES_PER_PIXEL;
    check_memory(width, height, (width * height) as u64 * per_ray, per_ray)?;
    let (builder, warnings) = load(scene_path, a.max_primitives)?;
    print_warnings(&warnings);
    let mut trees = Vec::new();
    let mut tree_opts = Vec::new();
    let layouts = if a.layout.is_empty() { vec![raypack::TreeLayout::Default] } else { a.layout.clone() };
    let builds = a.qualities().into_iter().flat_map(|q| layouts.iter().map(move |&l| (q, l)));
    for (k, (quality, layout)) in builds.enumerate() {
        // The first tree's binary BVH stays for the reference rows and the checksums they
        // anchor.
        let opts =
            BuildOptions { quality, watertight: a.watertight, keep_bvh2: k == 0, layout, ..BuildOptions::default() };
        let (scene, build) = build_timed(&builder, &opts, &a)?;
        let name = match layout {
            raypack::TreeLayout::Default => quality.name().to_string(),
            _ => format!("{} {layout}", quality.name()),
        };
        trees.push(RaypackTree { quality: name, scene, build });
        tree_opts.push(opts);
    }
    settings.ray_sets = crate::rays::ray_sets(&a, &trees[0].scene, &settings)?;
    let name = scene_path.map_or(crate::BUILT_IN_SCENE.to_string(), |p| p.display().to_string());
    // No more builds from a BVH cache: its second "build" would be a load.
    let rebuild = |k: usize| rebuild_time(&builder, &tree_opts[k]);
    let rebuild: Option<&dyn Fn(usize) -> Duration> = if a.bvh_cache.is_none() { Some(&rebuild) } else { None };
    let out = run_bench(&name, &mut trees, &settings, rebuild, &mut |line| say::line(line))?;
    match a.json.as_deref() {
        Some(p) if p == Path::new("-") => println!("{:#}", out.json()),
        Some(p) => {
            write_file_with(p, format!("{:#}\n", out.json()).as_bytes(), &json_opts)?;
            print!("{}", out.text(a.verbose));
        }
        None => print!("{}", out.text(a.verbose)),
    }
    if let Some(dir) = &a.report {
        let json = dir.join("bench.json");
        write_file_with(&json, format!("{:#}\n", out.json()).as_bytes(), &json_opts)?;
        crate::report::write_report(&[json], dir)?;
        say::line(format_args!("report: {}", dir.join("index.html").display()));
    }
    Ok(())
}
