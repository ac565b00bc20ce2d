//! The `raypack` command line: `render`, `info` (and `bench`).
//!
//! CS184's flags work as short options (`-t -s -l -m -r -f -a -H -c`), each with a long
//! equivalent. `raypack SCENE [flags]` without a subcommand means `raypack render`.

use clap::{Args, Parser, Subcommand, ValueEnum};
use raypack::io::LoadError;
use raypack::render::{self, IntegratorKind, RenderSettings};
use raypack::{BuildOptions, BuildQuality, Isa, Scene, SceneBuilder};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(name = "raypack", version, about = "A data-oriented SIMD ray tracer with a CS184-style path tracer")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (the built-in Cornell box when SCENE is omitted) to an image.
    Render(RenderArgs),
    /// Load a scene, build its BVH and print statistics.
    Info(InfoArgs),
    /// Time raypack's kernels (and Embree's, with --against embree) on primary, diffuse
    /// and shadow rays.
    Bench(BenchArgs),
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum AgainstArg {
    /// Intel Embree 3 (needs a build with `--features embree`).
    Embree,
}

#[derive(Args)]
struct BenchArgs {
    /// Scene file (.dae, .obj, .ply).
    scene: PathBuf,
    /// Also trace the same rays with another tracer.
    #[arg(long, value_enum)]
    against: Option<AgainstArg>,
    /// Write the figures as JSON to this file (`-` for standard output).
    #[arg(long)]
    json: Option<PathBuf>,
    /// Primary-ray image size.
    #[arg(short = 'r', long = "resolution", num_args = 2, value_names = ["WIDTH", "HEIGHT"], default_values_t = [1024, 768])]
    resolution: Vec<usize>,
    /// Timed runs per method (the median is reported), after one warm-up run.
    #[arg(long, default_value_t = 5)]
    runs: usize,
    /// Thread counts to time at, comma-separated (0: all cores; default: 1 and all).
    #[arg(short = 't', long = "threads", value_delimiter = ',')]
    threads: Vec<usize>,
    /// Time only the methods whose name contains one of these, comma-separated (e.g.
    /// `stream,rtcIntersect8`).
    #[arg(long, value_delimiter = ',')]
    methods: Vec<String>,
    /// raypack's BVH build effort.
    #[arg(long, value_enum, default_value_t = QualityArg::Medium)]
    quality: QualityArg,
    /// Load the BVH from (or save it to) a cache file in this directory.
    #[arg(long, value_name = "DIR")]
    bvh_cache: Option<PathBuf>,
    /// Use the watertight triangle test (no ray slips through shared edges) instead of
    /// Möller–Trumbore.
    #[arg(long)]
    watertight: bool,
    /// Run raypack's kernels on this ISA tier (sse, avx2, avx512; default: the CPU's best,
    /// or RAYPACK_ISA) and limit Embree to it.
    #[arg(long, value_parser = parse_isa)]
    isa: Option<Isa>,
    /// Refuse scenes of more than N triangles and spheres (after triangulation and COLLADA
    /// instancing).
    #[arg(long, value_name = "N", long_help = MAX_PRIMITIVES_HELP)]
    max_primitives: Option<u64>,
}

const MAX_PRIMITIVES_HELP: &str = "Refuse scenes of more than N triangles and spheres, counted after \
    triangulation and COLLADA instancing, with an error naming the line or element where the count \
    passes N. Without it there is no cap, except that COLLADA instancing may expand a file to at most \
    64 node visits, vertices, triangles and spheres per byte of the file (at least 2^20); with it, \
    that budget becomes at least 4 per primitive allowed. A service sets its own cap here.";

#[derive(Clone, Copy, Debug, ValueEnum)]
enum IntegratorArg {
    /// Shading normals as colours (CS184 parts 1-2).
    Normals,
    /// Emission plus direct lighting (CS184 part 3): bounces 0 and 1.
    Direct,
    /// Global illumination up to -m bounces (CS184 part 4).
    Global,
    /// Only direct lighting: bounce 1.
    DirectOnly,
    /// Only indirect lighting: bounces 2 to -m.
    IndirectOnly,
    /// Exactly -m bounces.
    Bounce,
}

impl From<IntegratorArg> for IntegratorKind {
    fn from(a: IntegratorArg) -> Self {
        match a {
            IntegratorArg::Normals => IntegratorKind::Normals,
            IntegratorArg::Direct => IntegratorKind::Direct,
            IntegratorArg::Global => IntegratorKind::Global,
            IntegratorArg::DirectOnly => IntegratorKind::DirectOnly,
            IntegratorArg::IndirectOnly => IntegratorKind::IndirectOnly,
            IntegratorArg::Bounce => IntegratorKind::Bounce,
        }
    }
}

#[derive(Args)]
struct RenderArgs {
    /// Scene file (.dae, .obj, .ply); omit for the built-in Cornell box.
    scene: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(short = 't', long = "threads")]
    threads: Option<usize>,
    /// Camera rays per pixel.
    #[arg(short = 's', long = "samples", default_value_t = 1)]
    samples: u32,
    /// Shadow rays per area light.
    #[arg(short = 'l', long = "light-samples", default_value_t = 1)]
    light_samples: u32,
    /// Maximum ray depth.
    #[arg(short = 'm', long = "max-depth", default_value_t = 1)]
    max_depth: u32,
    /// Image size in pixels.
    #[arg(short = 'r', long = "resolution", num_args = 2, value_names = ["WIDTH", "HEIGHT"], default_values_t = [480, 360])]
    resolution: Vec<usize>,
    /// Output image (.png, or .exr for linear radiance); default: SCENE's name with .png.
    #[arg(short = 'f', long = "output")]
    output: Option<PathBuf>,
    /// CS184 camera settings file to render from.
    #[arg(short = 'c', long = "camera")]
    camera: Option<PathBuf>,
    /// Adaptive sampling: batch size and tolerance.
    #[arg(short = 'a', long = "adaptive", num_args = 2, value_names = ["BATCH", "TOLERANCE"])]
    adaptive: Option<Vec<f32>>,
    /// Uniform hemisphere sampling for direct lighting instead of light sampling.
    #[arg(short = 'H', long = "hemisphere")]
    hemisphere: bool,
    /// What to compute per camera ray.
    #[arg(long, value_enum, default_value_t = IntegratorArg::Global)]
    integrator: IntegratorArg,
    /// Never terminate paths early by Russian roulette (only -m ends them).
    #[arg(long)]
    no_russian_roulette: bool,
    /// Seed of all random numbers.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Trace without the BVH, testing every primitive (CS184's "without BVH" timing).
    #[arg(long)]
    brute_force: bool,
    /// BVH build effort.
    #[arg(long, value_enum, default_value_t = QualityArg::Medium)]
    quality: QualityArg,
    /// Load the BVH from (or save it to) a cache file in this directory.
    #[arg(long, value_name = "DIR")]
    bvh_cache: Option<PathBuf>,
    /// Use the watertight triangle test (no ray slips through shared edges) instead of
    /// Möller–Trumbore.
    #[arg(long)]
    watertight: bool,
    /// Run the kernels on this ISA tier (sse, avx2, avx512; default: the CPU's best, or
    /// RAYPACK_ISA).
    #[arg(long, value_parser = parse_isa)]
    isa: Option<Isa>,
    /// Order of the shadow-ray streams (default: the one measured fastest for the kernels).
    #[arg(long, value_enum)]
    shadow_order: Option<RayOrderArg>,
    /// Order of the bounce-ray streams (default: the one measured fastest for the kernels).
    #[arg(long, value_enum)]
    bounce_order: Option<RayOrderArg>,
    /// Refuse scenes of more than N triangles and spheres (after triangulation and COLLADA
    /// instancing).
    #[arg(long, value_name = "N", long_help = MAX_PRIMITIVES_HELP)]
    max_primitives: Option<u64>,
}

/// `--shadow-order` / `--bounce-order`: [`render::RayOrder`].
#[derive(Clone, Copy, Debug, ValueEnum)]
enum RayOrderArg {
    /// As shaded.
    Queued,
    /// By direction octant.
    Octant,
    /// By octant, then origin along a Morton curve.
    OctantMorton,
    /// By origin along a Morton curve.
    Morton,
}

impl From<RayOrderArg> for render::RayOrder {
    fn from(a: RayOrderArg) -> Self {
        match a {
            RayOrderArg::Queued => render::RayOrder::Queued,
            RayOrderArg::Octant => render::RayOrder::Octant,
            RayOrderArg::OctantMorton => render::RayOrder::OctantMorton,
            RayOrderArg::Morton => render::RayOrder::Morton,
        }
    }
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum QualityArg {
    Fast,
    Medium,
    High,
}

impl From<QualityArg> for BuildQuality {
    fn from(q: QualityArg) -> Self {
        match q {
            QualityArg::Fast => BuildQuality::Fast,
            QualityArg::Medium => BuildQuality::Medium,
            QualityArg::High => BuildQuality::High,
        }
    }
}

#[derive(Args)]
struct InfoArgs {
    /// Scene file (.dae, .obj, .ply).
    scene: PathBuf,
    /// Check the BVH's structural invariants.
    #[arg(long)]
    validate: bool,
    /// Only this build quality (default: fast, medium and high).
    #[arg(long, value_enum)]
    quality: Option<QualityArg>,
    /// Load the BVHs from (or save them to) cache files in this directory.
    #[arg(long, value_name = "DIR")]
    bvh_cache: Option<PathBuf>,
    /// Worker threads of the builds (default: all cores).
    #[arg(short = 't', long = "threads")]
    threads: Option<usize>,
    /// Print the figures as JSON.
    #[arg(long)]
    json: bool,
    /// Keep the binary BVH after the collapse and report it (the kernels do not need it).
    #[arg(long)]
    keep_bvh2: bool,
    /// Also time Embree's MEDIUM and HIGH builds of the same triangles on as many threads.
    #[arg(long, value_enum)]
    against: Option<AgainstArg>,
    /// With --against: build Embree's BVHs first (the first builds of a process pay for
    /// touching fresh memory; compare each tracer's figures from a run in which it went first).
    #[arg(long, requires = "against")]
    embree_first: bool,
    /// Run raypack's kernels on this ISA tier (sse, avx2, avx512; default: the CPU's best,
    /// or RAYPACK_ISA) and limit Embree to it.
    #[arg(long, value_parser = parse_isa)]
    isa: Option<Isa>,
    /// Refuse scenes of more than N triangles and spheres (after triangulation and COLLADA
    /// instancing).
    #[arg(long, value_name = "N", long_help = MAX_PRIMITIVES_HELP)]
    max_primitives: Option<u64>,
}

/// Parses `--isa`, refusing a tier the CPU lacks.
fn parse_isa(s: &str) -> Result<Isa, String> {
    Isa::parse(s).and_then(Isa::check).map_err(|e| e.to_string())
}

/// A failure the CLI reports: bad input or environment exits with 2, as issue #2 asks.
#[derive(Debug, thiserror::Error)]
enum CliError {
    #[error(transparent)]
    Load(#[from] LoadError),
    #[error(transparent)]
    Info(#[from] raypack::info::InfoError),
    #[error(transparent)]
    Image(#[from] render::ImageError),
    #[error(transparent)]
    Bench(#[from] raypack::bench::BenchError),
    #[error(transparent)]
    Output(#[from] raypack::io::output::OutputError),
    #[error("{0}")]
    Usage(String),
}

fn main() -> ExitCode {
    let mut args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    // CS184 style: `raypack scene.dae -t 8 ...` means `raypack render scene.dae -t 8 ...`.
    let known = ["render", "info", "bench", "help", "-h", "--help", "-V", "--version"];
    if args.len() > 1 && !known.iter().any(|k| args[1] == *k) {
        args.insert(1, "render".into());
    }
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    match Isa::from_env() {
        Err(e) => {
            eprintln!("raypack: error: RAYPACK_ISA: {e}");
            return ExitCode::from(2);
        }
        Ok(Some(isa)) if !isa.is_supported() => {
            eprintln!("[raypack] warning: RAYPACK_ISA={isa}: this CPU's best is {}; using it", Isa::detected());
        }
        _ => {}
    }
    let result = match cli.command {
        Command::Render(a) => cmd_render(a),
        Command::Info(a) => cmd_info(a),
        Command::Bench(a) => cmd_bench(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("raypack: error: {e}");
            ExitCode::from(2)
        }
    }
}

/// Loads SCENE (or the built-in Cornell box); returns the loader's warnings for printing.
fn load(scene: Option<&Path>, max_primitives: Option<u64>) -> Result<(SceneBuilder, Vec<String>), CliError> {
    let opts = raypack::io::LoadOptions { max_primitives };
    Ok(match scene {
        Some(p) => raypack::io::load_scene_with_options(p, &opts)?,
        None => (raypack::io::default_scene(), Vec::new()),
    })
}

/// Refuses an image (or ray set) of `width × height` whose buffers, `needed` bytes in all
/// (`per_pixel` per pixel), cannot fit in the memory this process may still use.
fn check_memory(width: usize, height: usize, needed: u64, per_pixel: u64) -> Result<(), CliError> {
    use raypack::memory::{available, human};
    let Some(avail) = available() else { return Ok(()) };
    if needed <= avail.bytes {
        return Ok(());
    }
    // The largest image of the same shape that fits.
    let scale = (avail.bytes as f64 / needed as f64).sqrt();
    let (w, h) = (((width as f64 * scale) as usize).max(1), ((height as f64 * scale) as usize).max(1));
    Err(CliError::Usage(format!(
        "-r {width} {height}: needs about {} for the buffers that grow with the image ({per_pixel} bytes per pixel), but only {} \
         can be allocated ({}); use a smaller size, such as -r {w} {h}",
        human(needed),
        human(avail.bytes),
        avail.source
    )))
}

fn print_warnings(warnings: &[String]) {
    for w in warnings {
        eprintln!("[raypack] warning: {w}");
    }
}

fn commit(builder: SceneBuilder, opts: &BuildOptions, cache: Option<&Path>) -> Scene {
    let n = builder.num_triangles() + builder.num_spheres();
    let t = Instant::now();
    let (scene, report) = match cache {
        None => {
            eprint!("[raypack] Building BVH from {n} primitives... ");
            let r = builder.commit(opts);
            eprintln!("Done! ({:.4} sec)", t.elapsed().as_secs_f64());
            r
        }
        Some(dir) => {
            let (scene, report, cache) = builder.commit_cached(opts, dir);
            for w in cache.warnings() {
                eprintln!("[raypack] warning: {w}");
            }
            let how = if cache.loaded { "Loaded BVH of" } else { "Built BVH (and cached it) from" };
            eprintln!(
                "[raypack] {how} {n} primitives: {} ({:.4} sec)",
                cache.path.display(),
                t.elapsed().as_secs_f64()
            );
            (scene, report)
        }
    };
    if report.dropped() > 0 {
        eprintln!("[raypack] warning: {report}");
    }
    scene
}

fn cmd_render(a: RenderArgs) -> Result<(), CliError> {
    let (width, height) = (a.resolution[0], a.resolution[1]);
    if width == 0 || height == 0 || width > 1 << 15 || height > 1 << 15 {
        return Err(CliError::Usage(format!("-r {width} {height}: width and height must be between 1 and 32768")));
    }
    let adaptive = match a.adaptive.as_deref() {
        None => None,
        Some([batch, tol]) if *batch >= 1.0 && batch.fract() == 0.0 && *tol > 0.0 => Some((*batch as u32, *tol)),
        Some(v) => {
            return Err(CliError::Usage(format!("-a {v:?}: expected a whole batch size >= 1 and a tolerance > 0")));
        }
    };
    if a.threads == Some(0) {
        return Err(CliError::Usage("-t 0: need at least one thread".into()));
    }
    let output = a.output.clone().unwrap_or_else(|| {
        let stem = a.scene.as_ref().and_then(|s| s.file_stem()).map(|s| s.to_string_lossy().into_owned());
        PathBuf::from(format!("{}.png", stem.as_deref().unwrap_or("cornell")))
    });
    // The outputs are checked before anything is computed: `-` is standard output; otherwise
    // only a regular file that is not an input (or nothing, or a FIFO) may be written.
    let to_stdout = output == Path::new("-");
    if to_stdout && adaptive.is_some() {
        return Err(CliError::Usage("-f - with -a: the sample-rate image needs a file name (-f NAME.png)".into()));
    }
    let inputs: Vec<&Path> = [a.scene.as_deref(), a.camera.as_deref()].into_iter().flatten().collect();
    let out_opts = raypack::io::output::OutputOptions::protecting(&inputs);
    let rate_path = adaptive.map(|_| render::adaptive::rate_path(&output));
    if !to_stdout {
        for p in std::iter::once(&output).chain(&rate_path) {
            raypack::io::output::check_target(p, &out_opts)?;
        }
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .map_err(|e| CliError::Usage(e.to_string()))?;
    pool.install(|| {
        let mut settings = RenderSettings {
            width,
            height,
            samples_per_pixel: a.samples.max(1),
            light_samples: a.light_samples.max(1),
            max_depth: a.max_depth,
            hemisphere_sampling: a.hemisphere,
            adaptive,
            integrator: a.integrator.into(),
            seed: a.seed,
            brute_force: a.brute_force,
            russian_roulette: !a.no_russian_roulette,
            stream_order: None,
        };
        let format = render::ImageFormat::of(&output);
        let exr = format == render::ImageFormat::Exr;
        check_memory(
            width,
            height,
            raypack::memory::render_bytes(&settings, rayon::current_num_threads(), exr),
            raypack::memory::render_bytes_per_pixel(&settings, exr),
        )?;
        // Read before the scene: a bad camera file fails at once.
        let file_camera = a.camera.as_deref().map(raypack::io::camera_file::load_camera_file).transpose()?;
        eprint!("[raypack] Collecting primitives... ");
        let t = Instant::now();
        let (builder, warnings) = load(a.scene.as_deref(), a.max_primitives)?;
        let load_time = t.elapsed().as_secs_f64();
        eprintln!("Done! ({load_time:.4} sec)");
        print_warnings(&warnings);
        let opts = BuildOptions { quality: a.quality.into(), watertight: a.watertight, ..BuildOptions::default() };
        let t = Instant::now();
        let mut scene = commit(builder, &opts, a.bvh_cache.as_deref());
        let setup_time = [("load", load_time), ("BVH build", t.elapsed().as_secs_f64())];
        if let Some(isa) = a.isa {
            scene.set_isa(isa).map_err(|e| CliError::Usage(e.to_string()))?;
        }
        if a.shadow_order.is_some() || a.bounce_order.is_some() {
            let default = render::StreamOrder::default_for(scene.isa());
            settings.stream_order = Some(render::StreamOrder {
                shadow: a.shadow_order.map_or(default.shadow, Into::into),
                bounce: a.bounce_order.map_or(default.bounce, Into::into),
            });
        }
        let aspect = width as f32 / height as f32;
        let camera = file_camera.unwrap_or_else(|| scene.camera_or_framing(aspect));
        let bar = progress_bar(width.div_ceil(render::TILE) * height.div_ceil(render::TILE));
        eprintln!(
            "[raypack] Rendering {width}x{height} with {} threads ({} kernels)...",
            rayon::current_num_threads(),
            scene.isa()
        );
        let out = render::render(&scene, &camera, &settings, &|done| bar.set_position(done));
        bar.finish_and_clear();
        eprintln!("[raypack] Rendering... 100%! ({:.4}s)", out.stats.time.as_secs_f64());
        report(&scene, &settings, &out, setup_time);
        let t = Instant::now();
        let encode = |film: &render::Film, path: &Path, format, encoding| {
            film.encode(format, encoding).map_err(|message| render::ImageError::Encode { path: path.into(), message })
        };
        let image = encode(&out.film, &output, format, settings.integrator.encoding())?;
        if to_stdout {
            eprint!("[raypack] Writing the image to standard output... ");
            use std::io::Write;
            let mut stdout = std::io::stdout().lock();
            stdout
                .write_all(&image)
                .and_then(|()| stdout.flush())
                .map_err(|source| render::ImageError::Io { path: output.clone(), source })?;
        } else {
            use raypack::io::output::{commit_all, stage};
            eprint!("[raypack] Saving to file: {}... ", output.display());
            let mut files = vec![stage(&output, &out_opts, &mut |w| w.write_all(&image))?];
            if let (Some(rate), Some((batch, tol))) = (&rate_path, settings.adaptive) {
                let spp = settings.samples_per_pixel;
                let film = render::adaptive::rate_film(&out.samples_per_pixel, width, height, spp);
                let bytes = encode(&film, rate, render::ImageFormat::Png, render::Encoding::Display)?;
                files.push(stage(rate, &out_opts, &mut |w| w.write_all(&bytes))?);
                eprint!("(sample rate: {}, batch {batch}, tolerance {tol}) ", rate.display());
            }
            // The image and its sample-rate image: both or neither.
            commit_all(files)?;
        }
        eprintln!("Done! ({:.4} sec)", t.elapsed().as_secs_f64());
        Ok(())
    })
}

/// The end-of-render report: CS184's lines (rays traced, Mrays/s, tests per ray), per kind of
/// ray, then samples per second and time per phase.
fn report(scene: &Scene, settings: &RenderSettings, out: &render::RenderOutput, setup: [(&str, f64); 2]) {
    let s = &out.stats;
    let secs = s.time.as_secs_f64().max(1e-9);
    let rays = s.rays;
    eprintln!("[raypack] BVH traced {} rays.", rays.total());
    eprintln!("[raypack] Average speed {:.4} million rays per second.", rays.total() as f64 / secs / 1e6);
    for kind in render::RayKind::ALL {
        let n = rays.of(kind);
        let tests = render::stats::tests_per_ray(scene, &s.sampled_rays[kind as usize], kind, settings.brute_force);
        let tests = tests.map_or("-".into(), |t| format!("{t:.3}"));
        eprintln!(
            "[raypack]   {:<6} {:>12} rays, {:>9.4} Mrays/s, {} intersection tests per ray",
            kind.name(),
            n,
            n as f64 / secs / 1e6,
            tests
        );
    }
    let px = (settings.width * settings.height) as f64;
    eprintln!(
        "[raypack] {} samples ({:.1} per pixel), {:.4} million samples per second.",
        s.samples,
        s.samples as f64 / px,
        s.samples as f64 / secs / 1e6
    );
    if s.invalid_samples > 0 {
        eprintln!("[raypack] warning: {} samples were NaN or infinite and counted as black.", s.invalid_samples);
    }
    eprintln!(
        "[raypack] Time: {} {:.4}s, {} {:.4}s, render {:.4}s.",
        setup[0].0, setup[0].1, setup[1].0, setup[1].1, secs
    );
    let p = &s.phases;
    let total = p.total().as_secs_f64().max(1e-9);
    let phase = |name: &str, d: std::time::Duration| {
        format!("{name} {:.4}s ({:.1}%)", d.as_secs_f64(), 100.0 * d.as_secs_f64() / total)
    };
    eprintln!(
        "[raypack] Thread time by phase: {}, {}, {}, {}, {}, {}, {}, {}.",
        phase("generate", p.generate),
        phase("trace camera", p.trace[0]),
        phase("trace shadow", p.trace[1]),
        phase("trace bounce", p.trace[2]),
        phase("shade", p.shade),
        phase("sort", p.sort),
        phase("compact", p.compact),
        phase("film", p.film)
    );
}

fn progress_bar(len: usize) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("[raypack] {bar:40} {percent:>3}% tiles {pos}/{len} eta {eta}")
            .expect("valid template"),
    );
    bar
}

fn cmd_info(a: InfoArgs) -> Result<(), CliError> {
    use raypack::info::{InfoOptions, scene_info};
    if a.threads == Some(0) {
        return Err(CliError::Usage("-t 0: need at least one thread".into()));
    }
    let mut opts = InfoOptions {
        load: raypack::io::LoadOptions { max_primitives: a.max_primitives },
        cache_dir: a.bvh_cache.clone(),
        validate: a.validate,
        keep_bvh2: a.keep_bvh2,
        against_embree: a.against.is_some(),
        embree_first: a.embree_first,
        isa: a.isa,
        ..InfoOptions::default()
    };
    if let Some(q) = a.quality {
        opts.qualities = vec![q.into()];
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .map_err(|e| CliError::Usage(e.to_string()))?;
    let info = pool.install(|| scene_info(&a.scene, &opts))?;
    print_warnings(&info.warnings);
    for w in info.builds.iter().flat_map(|b| &b.cache_warnings) {
        eprintln!("[raypack] warning: {w}");
    }
    if a.json {
        println!("{:#}", info.json());
    } else {
        print!("{}", info.text());
    }
    match info.builds.iter().find_map(|b| b.valid.as_ref().and_then(|v| v.as_ref().err())) {
        Some(e) => Err(CliError::Usage(format!("BVH invalid: {e}"))),
        None => Ok(()),
    }
}

fn cmd_bench(a: BenchArgs) -> Result<(), CliError> {
    use raypack::bench::{BenchSettings, BuildFigures, raypack_accel_bytes, run_bench};
    use raypack::io::output::{OutputOptions, check_target, write_file_with};
    let (width, height) = (a.resolution[0], a.resolution[1]);
    if width == 0 || height == 0 || width > 1 << 15 || height > 1 << 15 {
        return Err(CliError::Usage(format!("-r {width} {height}: width and height must be between 1 and 32768")));
    }
    if a.runs == 0 {
        return Err(CliError::Usage("--runs 0: need at least one timed run".into()));
    }
    let settings = BenchSettings {
        width,
        height,
        runs: a.runs,
        against_embree: a.against.is_some(),
        isa: a.isa,
        methods: a.methods.clone(),
        threads: if a.threads.is_empty() { vec![1, 0] } else { a.threads.clone() },
        ..Default::default()
    };
    if settings.against_embree && !cfg!(feature = "embree") {
        return Err(raypack::bench::BenchError::EmbreeNotBuilt.into());
    }
    let json_opts = OutputOptions::protecting(&[&a.scene]);
    if let Some(p) = a.json.as_deref().filter(|p| *p != Path::new("-")) {
        check_target(p, &json_opts)?;
    }
    let per_ray = raypack::memory::BENCH_BYTES_PER_PIXEL;
    check_memory(width, height, (width * height) as u64 * per_ray, per_ray)?;
    let (builder, warnings) = load(Some(&a.scene), a.max_primitives)?;
    print_warnings(&warnings);
    let quality: BuildQuality = a.quality.into();
    let t = Instant::now();
    // The binary BVH stays for the reference rows and the checksums they anchor.
    let opts = BuildOptions { quality, watertight: a.watertight, keep_bvh2: true, ..BuildOptions::default() };
    let (mut scene, report) = match a.bvh_cache.as_deref() {
        None => builder.commit(&opts),
        Some(dir) => {
            let (scene, report, cache) = builder.commit_cached(&opts, dir);
            for w in cache.warnings() {
                eprintln!("[raypack] warning: {w}");
            }
            if cache.loaded {
                eprintln!("[raypack] BVH loaded from {} (the build time below is the load time)", cache.path.display());
            }
            (scene, report)
        }
    };
    let seconds = t.elapsed().as_secs_f64();
    if report.dropped() > 0 {
        eprintln!("[raypack] warning: {report}");
    }
    let build = BuildFigures {
        tracer: "raypack",
        quality: format!("bvh8 {} {}", format!("{quality:?}").to_lowercase(), scene.triangle_test().name()),
        seconds,
        bytes: raypack_accel_bytes(&scene) as u64,
    };
    let name = a.scene.display().to_string();
    let out = run_bench(&name, &mut scene, build, &settings, &mut |line| eprintln!("[raypack] {line}"))?;
    match a.json.as_deref() {
        Some(p) if p == Path::new("-") => println!("{:#}", out.json()),
        Some(p) => {
            write_file_with(p, format!("{:#}\n", out.json()).as_bytes(), &json_opts)?;
            print!("{}", out.table());
        }
        None => print!("{}", out.table()),
    }
    Ok(())
}
