//! The `raypack` command line: `render`, `info` (and `bench`).
//!
//! CS184's flags work as short options (`-t -s -l -m -r -f -a -H -c`), each with a long
//! equivalent. `raypack SCENE [flags]` without a subcommand means `raypack render`.

mod bench;
mod heatmap;
mod info;
mod merge;
mod rays;
mod render;
mod report;
mod say;
mod version;

use clap::{Args, Parser, Subcommand, ValueEnum};
use raypack::io::LoadError;
use raypack::render::{ImageError, IntegratorKind, SamplerKind};
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
    /// Combine `raypack bench --json` files into one report: index.html with inline SVG
    /// charts, and the charts as PNG.
    Report(ReportArgs),
    /// Put the parts of an image (`render --tile`, `--crop-window`, `--pixel-bounds`) back
    /// together: the same image, bit for bit, as one render of the whole.
    Merge(MergeArgs),
}

#[derive(Args)]
struct MergeArgs {
    /// The parts: OpenEXR files written by `raypack render` with a window.
    #[arg(required = true, value_name = "PART")]
    parts: Vec<PathBuf>,
    /// The whole image: .exr (linear radiance, the very file a whole render writes) or .png
    /// (8-bit sRGB, as `raypack render` encodes it).
    #[arg(short = 'o', long = "output", visible_short_alias = 'f', value_name = "IMAGE")]
    output: PathBuf,
    /// No statistics line (errors are still printed).
    #[arg(short = 'q', long)]
    quiet: bool,
}

#[derive(Args)]
struct ReportArgs {
    /// Bench JSON files (other machines, commits or scenes).
    #[arg(required = true)]
    json: Vec<PathBuf>,
    /// Directory to write index.html and the PNG charts into.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum AgainstArg {
    /// Intel Embree 3 or 4 (needs a build with `--features embree`).
    Embree,
}

#[derive(Args)]
struct BenchArgs {
    /// Scene file (.dae, .obj, .ply); omit for the built-in Cornell box.
    scene: Option<PathBuf>,
    /// The scene file, as a flag (instead of SCENE).
    #[arg(long = "scene", value_name = "FILE", conflicts_with = "scene")]
    scene_flag: Option<PathBuf>,
    /// Print every method's figures (the JSON always has them), not only the summary.
    #[arg(short = 'v', long)]
    verbose: bool,
    /// Also trace the same rays with another tracer.
    #[arg(long, value_enum)]
    against: Option<AgainstArg>,
    /// Write the figures as JSON to this file (`-` for standard output).
    #[arg(long)]
    json: Option<PathBuf>,
    /// Time the kernels on the rays of this file instead of the built-in sets: `.rays` (8
    /// little-endian f32 per ray: origin xyz, direction xyz, tnear, tfar) or `.npy` (float32,
    /// shape (N, 8)), traced as closest-hit rays.
    #[arg(long, value_name = "FILE")]
    rays: Option<PathBuf>,
    /// Also write a report (index.html with inline SVG charts, and PNG charts) into DIR.
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
    /// Write the built-in ray sets (primary, diffuse, shadow) to this directory as
    /// NAME.rays and NAME.npy before timing them.
    #[arg(long, value_name = "DIR", conflicts_with = "rays")]
    dump_rays: Option<PathBuf>,
    /// Primary-ray image size.
    #[arg(short = 'r', long = "resolution", num_args = 2, value_names = ["WIDTH", "HEIGHT"], default_values_t = [1024, 768])]
    resolution: Vec<usize>,
    /// Timed runs per method (the median is reported), after one warm-up run.
    #[arg(long, default_value_t = 5)]
    runs: usize,
    /// Builds of each acceleration structure (raypack's, Embree's medium and high), on all
    /// threads; the median is reported, with the fastest and slowest.
    #[arg(long, value_name = "N", default_value_t = 3)]
    build_runs: usize,
    /// Time at this many threads, as `render -t` and `info -t` run on (default: 1 and all
    /// cores; several counts: --threads-list).
    #[arg(short = 't', long = "threads", value_parser = parse_thread_count, conflicts_with = "threads_list")]
    threads: Option<usize>,
    /// Thread counts to time at, comma-separated, e.g. `--threads-list 1,2` (0 or `all`: all
    /// cores) [default: 1,all].
    #[arg(long, value_name = "N,N,...", value_delimiter = ',', value_parser = parse_list_thread_count)]
    threads_list: Vec<usize>,
    /// Time only the methods whose name contains one of these, comma-separated (e.g.
    /// `stream,rtcIntersect8`).
    #[arg(long, value_delimiter = ',')]
    methods: Vec<String>,
    /// raypack's BVH build efforts, comma-separated (e.g. `medium,high`): each tree's methods
    /// are timed, named with their quality in brackets when there are several. Default:
    /// medium; with `--against embree`, medium and high, as Embree's MEDIUM and HIGH.
    #[arg(long, value_parser = quality_parser(), value_delimiter = ',')]
    quality: Vec<BuildQuality>,
    /// raypack's tree layouts, comma-separated (`default`, `compact`: leaf blocks of triangle
    /// ids, the triangles read from the scene store; the smallest tree, the same hits): each
    /// quality's tree is built in each, a compact tree's methods named `(QUALITY compact)`.
    /// Default: default.
    #[arg(long, value_parser = layout_parser(), value_delimiter = ',')]
    layout: Vec<raypack::TreeLayout>,
    /// Load the BVH from (or save it to) a cache file in this directory.
    #[arg(long, value_name = "DIR")]
    bvh_cache: Option<PathBuf>,
    /// Use the watertight triangle test (no ray slips through shared edges) instead of
    /// Möller–Trumbore; with `--against embree`, Embree's robust mode as well
    /// (RTC_SCENE_FLAG_ROBUST: conservative traversal, watertight test), so that both tracers
    /// are robust.
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
    passes N. Without it, a scene may have as many primitives as fit in 512 MB, or 512 bytes per byte \
    of its file when that is more (128 bytes per primitive; only COLLADA instancing makes more than one \
    primitive per byte), and never more than fit in the memory available; and COLLADA instancing may \
    expand a file to at most 64 node visits, vertices, triangles and spheres per byte of the file (at \
    least 2^20). With it, that budget becomes at least 4 per primitive allowed. A service sets its \
    own cap here.";

/// `--integrator`: the library's names and descriptions ([`IntegratorKind::ALL`]), read by
/// its `FromStr`.
fn integrator_parser() -> impl clap::builder::TypedValueParser<Value = IntegratorKind> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    PossibleValuesParser::new(IntegratorKind::ALL.map(|k| PossibleValue::new(k.name()).help(k.description())))
        .try_map(|name| name.parse::<IntegratorKind>())
}

/// `--sampler`: the library's names ([`SamplerKind::ALL`]), read by its `FromStr`.
fn sampler_parser() -> impl clap::builder::TypedValueParser<Value = SamplerKind> {
    use clap::builder::{PossibleValuesParser, TypedValueParser};
    PossibleValuesParser::new(SamplerKind::ALL.map(|k| k.name())).try_map(|name| name.parse::<SamplerKind>())
}

#[derive(Args)]
struct RenderArgs {
    /// Scene file (.dae, .obj, .ply); omit for the built-in Cornell box.
    scene: Option<PathBuf>,
    /// The scene file, as a flag (instead of SCENE), as `info` and `bench` take it.
    #[arg(long = "scene", value_name = "FILE", conflicts_with = "scene")]
    scene_flag: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(short = 't', long = "threads", value_parser = parse_thread_count)]
    threads: Option<usize>,
    /// Camera rays per pixel, at least 1 [default: 1, as CS184; the built-in Cornell box: 128].
    #[arg(short = 's', long = "samples", visible_alias = "spp")]
    samples: Option<u32>,
    /// Shadow rays per area light [default: 1; the built-in Cornell box: 2].
    #[arg(short = 'l', long = "light-samples")]
    light_samples: Option<u32>,
    /// Maximum ray depth [default: 1; the built-in Cornell box: 5].
    #[arg(short = 'm', long = "max-depth")]
    max_depth: Option<u32>,
    /// Image size in pixels.
    #[arg(short = 'r', long = "resolution", num_args = 2, value_names = ["WIDTH", "HEIGHT"], default_values_t = [480, 360])]
    resolution: Vec<usize>,
    /// Output image: .png (8-bit sRGB) or .exr (linear radiance), `-` for PNG on standard
    /// output; default: SCENE's name with .png.
    #[arg(short = 'f', long = "output", visible_short_alias = 'o', visible_alias = "outfile")]
    output: Option<PathBuf>,
    /// CS184 camera settings file to render from (the format: README, or --write-camera).
    #[arg(short = 'c', long = "camera")]
    camera: Option<PathBuf>,
    /// Place the camera at the eye E looking at the target T (over the scene's or -c's camera).
    #[arg(long, num_args = 6, value_names = ["EX", "EY", "EZ", "TX", "TY", "TZ"], allow_negative_numbers = true)]
    lookat: Option<Vec<f32>>,
    /// The camera's up direction (default: the scene's or -c's camera's up).
    #[arg(long, num_args = 3, value_names = ["UX", "UY", "UZ"], allow_negative_numbers = true)]
    up: Option<Vec<f32>>,
    /// Vertical field of view in degrees, in (0, 180); the horizontal one follows the image's
    /// aspect ratio.
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    fov: Option<f32>,
    /// Write the camera this render would use (the scene's, -c's or the framing one, after
    /// --lookat/--up/--fov) to FILE as a commented CS184 camera file for -c, and exit
    /// without rendering.
    #[arg(long, value_name = "FILE")]
    write_camera: Option<PathBuf>,
    /// No progress or statistics lines (warnings and errors are still printed).
    #[arg(short = 'q', long)]
    quiet: bool,
    /// Adaptive sampling: batch size and tolerance.
    #[arg(short = 'a', long = "adaptive", num_args = 2, value_names = ["BATCH", "TOLERANCE"])]
    adaptive: Option<Vec<f32>>,
    /// Uniform hemisphere sampling for direct lighting instead of light sampling.
    #[arg(short = 'H', long = "hemisphere")]
    hemisphere: bool,
    /// What to compute per camera ray.
    #[arg(long, value_parser = integrator_parser(), default_value_t = IntegratorKind::Global)]
    integrator: IntegratorKind,
    /// With --integrator heatmap: which count the image shows [default: nodes].
    #[arg(long, value_enum)]
    heatmap: Option<heatmap::ViewArg>,
    /// With --integrator heatmap: count camera rays, or shadow rays toward the first light
    /// [default: camera].
    #[arg(long, value_enum)]
    heatmap_rays: Option<heatmap::RaysArg>,
    /// With --integrator heatmap: how counts map to colours: `linear` (0 to the largest
    /// count), `log` (ln(1 + count): the cheap pixels spread out when a few are costly), or
    /// `pNN` (linear up to the NN-th percentile, e.g. p99; above it the top colour)
    /// [default: linear].
    #[arg(long, value_name = "SCALE", value_parser = heatmap::parse_scale)]
    heatmap_scale: Option<raypack::render::heatmap::HeatmapScale>,
    /// Never terminate paths early by Russian roulette (only -m ends them).
    #[arg(long)]
    no_russian_roulette: bool,
    /// Scale down any camera sample whose radiance exceeds V in an RGB component (pbrt-v4's
    /// maxcomponentvalue): removes fireflies at the cost of some bias. Default: none (`inf`).
    #[arg(long, value_name = "V")]
    clamp: Option<f32>,
    /// Seed of all random numbers.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// How each path's random numbers are made: `sobol` (scrambled Sobol' points, stratified
    /// per pixel: less noise per sample) or `independent` (independent uniforms).
    #[arg(long, value_parser = sampler_parser(), default_value_t = SamplerKind::Sobol)]
    sampler: SamplerKind,
    /// Trace without the BVH, testing every primitive (CS184's "without BVH" timing).
    #[arg(long)]
    brute_force: bool,
    /// BVH build effort.
    #[arg(long, value_parser = quality_parser(), default_value_t = BuildQuality::Medium)]
    quality: BuildQuality,
    /// How the BVH stores its triangles: `default`, or `compact` (leaf blocks of triangle ids,
    /// the triangles read from the scene store: the smallest tree, the same image).
    #[arg(long, value_parser = layout_parser(), default_value_t = raypack::TreeLayout::Default)]
    layout: raypack::TreeLayout,
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
    #[arg(long, value_parser = ray_order_parser())]
    shadow_order: Option<raypack::render::RayOrder>,
    /// Order of the bounce-ray streams (default: the one measured fastest for the kernels).
    #[arg(long, value_parser = ray_order_parser())]
    bounce_order: Option<raypack::render::RayOrder>,
    /// Refuse scenes of more than N triangles and spheres (after triangulation and COLLADA
    /// instancing).
    #[arg(long, value_name = "N", long_help = MAX_PRIMITIVES_HELP)]
    max_primitives: Option<u64>,
    /// Render only this window of the image, as fractions of its width and height (pbrt's
    /// --cropwindow; rows from the top): pixels ceil(W*X0) to ceil(W*X1), likewise for rows.
    /// Written as an OpenEXR part for `raypack merge`.
    #[arg(long, num_args = 4, value_names = ["X0", "X1", "Y0", "Y1"], allow_negative_numbers = true,
        conflicts_with_all = ["pixel_bounds", "tile"])]
    crop_window: Option<Vec<f64>>,
    /// Render only pixels X0..X1 of rows Y0..Y1 (X1 and Y1 exclusive; pbrt's --pixelbounds).
    /// Written as an OpenEXR part for `raypack merge`.
    #[arg(long, num_args = 4, value_names = ["X0", "X1", "Y0", "Y1"], conflicts_with = "tile")]
    pixel_bounds: Option<Vec<usize>>,
    /// Render only part I (from 0) of N parts of a fixed grid of nearly square cells; for job
    /// arrays: `--tile $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT` with `--array=0-(N-1)`.
    /// Written as an OpenEXR part for `raypack merge`.
    #[arg(long, value_name = "I/N")]
    tile: Option<String>,
}

/// `--shadow-order` / `--bounce-order`: the library's names ([`raypack::render::RayOrder::ALL`]).
fn ray_order_parser() -> impl clap::builder::TypedValueParser<Value = raypack::render::RayOrder> {
    use clap::builder::{PossibleValuesParser, TypedValueParser};
    use raypack::render::RayOrder;
    PossibleValuesParser::new(RayOrder::ALL.map(RayOrder::name))
        .try_map(|name| RayOrder::ALL.into_iter().find(|o| o.name() == name).ok_or("not an order"))
}

/// `--layout`'s parser: the library's names ([`raypack::TreeLayout::name`]), listed in `--help`.
fn layout_parser() -> impl clap::builder::TypedValueParser<Value = raypack::TreeLayout> {
    use clap::builder::TypedValueParser as _;
    clap::builder::PossibleValuesParser::new(raypack::TreeLayout::ALL.map(raypack::TreeLayout::name))
        .try_map(|s| raypack::TreeLayout::parse(&s))
}

/// `--quality`'s parser: the library's names ([`BuildQuality::name`]), listed in `--help`.
fn quality_parser() -> impl clap::builder::TypedValueParser<Value = BuildQuality> {
    use clap::builder::TypedValueParser as _;
    clap::builder::PossibleValuesParser::new(BuildQuality::ALL.map(BuildQuality::name))
        .try_map(|s| s.parse::<BuildQuality>())
}

/// Checks a `-t N` flag (`None`: all cores): at least 1, at most
/// [`raypack::system::max_threads`].
fn check_threads(threads: Option<usize>) -> Result<(), CliError> {
    match threads {
        Some(0) => Err(CliError::Usage("-t 0: need at least one thread".into())),
        Some(t) => raypack::system::check_threads(t).map(|_| ()).map_err(|e| CliError::Usage(format!("-t {t}: {e}"))),
        None => Ok(()),
    }
}

#[derive(Args)]
struct InfoArgs {
    /// Scene file (.dae, .obj, .ply); omit for the built-in Cornell box.
    scene: Option<PathBuf>,
    /// The scene file, as a flag (instead of SCENE).
    #[arg(long = "scene", value_name = "FILE", conflicts_with = "scene")]
    scene_flag: Option<PathBuf>,
    /// Check the BVH's structural invariants.
    #[arg(long)]
    validate: bool,
    /// Only this build quality (default: fast, medium and high).
    #[arg(long, value_parser = quality_parser())]
    quality: Option<BuildQuality>,
    /// Tree layouts to build, comma-separated (`default`, `compact`: leaf blocks of triangle
    /// ids), each reported with its bytes per triangle [default: default].
    #[arg(long, value_parser = layout_parser(), value_delimiter = ',')]
    layout: Vec<raypack::TreeLayout>,
    /// Load the BVHs from (or save them to) cache files in this directory.
    #[arg(long, value_name = "DIR")]
    bvh_cache: Option<PathBuf>,
    /// Worker threads of the builds (default: all cores).
    #[arg(short = 't', long = "threads", value_parser = parse_thread_count)]
    threads: Option<usize>,
    /// Print the figures as JSON.
    #[arg(long)]
    json: bool,
    /// Keep the binary BVH after the collapse and report it (the kernels do not need it).
    #[arg(long)]
    keep_bvh2: bool,
    /// Also time Embree's MEDIUM, HIGH and compact (MEDIUM with `RTC_SCENE_FLAG_COMPACT`) builds
    /// of the same triangles on as many threads.
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

/// How reports name the scene used when none is given.
const BUILT_IN_SCENE: &str = "built-in Cornell box (scenes/cornell.dae)";

impl BenchArgs {
    /// SCENE or `--scene`; `None`: the built-in Cornell box.
    fn scene_path(&self) -> Option<&Path> {
        self.scene.as_deref().or(self.scene_flag.as_deref())
    }

    /// The qualities of `--quality`, repeats dropped; by default medium, and high as well
    /// against Embree, whose MEDIUM and HIGH trees are both timed.
    fn qualities(&self) -> Vec<BuildQuality> {
        let mut q = self.quality.clone();
        if q.is_empty() {
            q.push(BuildQuality::Medium);
            if self.against.is_some() {
                q.push(BuildQuality::High);
            }
        }
        let mut out = Vec::with_capacity(q.len());
        for x in q {
            if !out.contains(&x) {
                out.push(x);
            }
        }
        out
    }
}

impl InfoArgs {
    /// SCENE or `--scene`; `None`: the built-in Cornell box.
    fn scene_path(&self) -> Option<&Path> {
        self.scene.as_deref().or(self.scene_flag.as_deref())
    }
}

/// Parses `-t`: one thread count, the same on every command (a list is `bench
/// --threads-list`'s; the limits are checked by [`check_threads`]).
fn parse_thread_count(s: &str) -> Result<usize, String> {
    if s.contains(',') {
        return Err(format!("-t takes one thread count; to time `bench` at several, use --threads-list {s}"));
    }
    s.trim().parse().map_err(|_| format!("expected a whole number of threads, got '{s}'"))
}

/// Parses one entry of `bench --threads-list`: a thread count, or 0 or `all` for all cores.
fn parse_list_thread_count(s: &str) -> Result<usize, String> {
    match s.trim() {
        "all" => Ok(0),
        t => t.parse().map_err(|_| format!("expected a whole number of threads or 'all', got '{s}'")),
    }
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
    Info(#[from] info::InfoError),
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error(transparent)]
    Bench(#[from] raypack::bench::BenchError),
    #[error(transparent)]
    Output(#[from] raypack::fs::output::OutputError),
    #[error(transparent)]
    Rays(#[from] raypack::io::rays::RayFileError),
    #[error(transparent)]
    Merge(#[from] merge::MergeFailure),
    #[error("{0}")]
    Usage(String),
}

fn main() -> ExitCode {
    let mut args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    // Before clap, whose version flag prints a fixed string: the commit, features, Embree
    // and kernels are this binary's and this machine's.
    if args.len() == 2 && (args[1] == "-V" || args[1] == "--version") {
        print!("{}", version::text());
        return ExitCode::SUCCESS;
    }
    // CS184 style: `raypack scene.dae -t 8 ...` means `raypack render scene.dae -t 8 ...`.
    let known = ["render", "info", "bench", "report", "merge", "help", "-h", "--help", "-V", "--version"];
    if args.len() > 1 && !known.iter().any(|k| args[1] == *k) {
        // A scene file (or a flag of `render`) means `render`; any other first word is a
        // mistyped subcommand, not a scene of an unsupported format.
        let first = Path::new(&args[1]);
        let is_flag = args[1].to_string_lossy().starts_with('-');
        if !is_flag && !first.exists() && raypack::io::SceneFormat::from_path(first).is_none() {
            say::error(format_args!(
                "unknown command '{}'; the commands are render, info, bench, report, merge and help \
                 (`raypack SCENE` renders a .dae, .obj or .ply file; `raypack --help` lists the flags)",
                args[1].to_string_lossy()
            ));
            return ExitCode::from(2);
        }
        args.insert(1, "render".into());
    }
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(e) if e.use_stderr() => {
            // clap's own "error: " becomes the command's one prefix; its colours stay on a
            // terminal.
            use std::io::IsTerminal;
            let styled = e.render();
            let text = if std::io::stderr().is_terminal() { styled.ansi().to_string() } else { styled.to_string() };
            match text.find("error:") {
                Some(at) => eprint!("{}{} {}", &text[..at], say::PREFIX, &text[at..]),
                None => eprint!("{text}"),
            }
            return ExitCode::from(2);
        }
        Err(e) => {
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
    };
    match Isa::env_report() {
        Err(e) => {
            say::error(e);
            return ExitCode::from(2);
        }
        Ok(Some(warning)) => say::warning(warning),
        Ok(None) => {}
    }
    let result = match cli.command {
        Command::Render(mut a) => {
            a.scene = a.scene.take().or(a.scene_flag.take());
            render::cmd_render(a)
        }
        Command::Info(a) => info::cmd_info(a),
        Command::Bench(a) => bench::cmd_bench(a),
        Command::Report(a) => report::write_report(&a.json, &a.out),
        Command::Merge(a) => merge::cmd_merge(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            say::error(e);
            ExitCode::from(2)
        }
    }
}

/// Loads SCENE (or the built-in Cornell box); returns the loader's warnings for printing.
fn load(scene: Option<&Path>, max_primitives: Option<u64>) -> Result<(SceneBuilder, Vec<String>), CliError> {
    let opts = raypack::io::LoadOptions { max_primitives, memory_cap: true };
    Ok(match scene {
        Some(p) => {
            let loaded = raypack::io::load_scene_with_options(p, &opts)?;
            (loaded.builder, loaded.warnings)
        }
        None => (raypack::io::default_scene(), Vec::new()),
    })
}

/// Refuses an image (or ray set) of `width × height` whose buffers, `needed` bytes in all
/// (`per_pixel` per pixel), cannot fit in the memory this process may still use.
fn check_memory(width: usize, height: usize, needed: u64, per_pixel: u64) -> Result<(), CliError> {
    raypack::system::check_fits(width, height, needed, per_pixel).map_err(|e| {
        let (w, h) = e.fits;
        CliError::Usage(format!("-r {width} {height}: {e}; use a smaller size, such as -r {w} {h}"))
    })
}

fn print_warnings(warnings: &[String]) {
    for w in warnings {
        say::warning(w);
    }
}

/// Commits `builder` (through the cache in `cache`), printing what it did unless `quiet`;
/// warnings are always printed.
fn commit(builder: SceneBuilder, opts: &BuildOptions, cache: Option<&Path>, quiet: bool) -> Scene {
    let n = builder.num_triangles() + builder.num_spheres();
    let t = Instant::now();
    let (scene, report) = match cache {
        None => {
            if !quiet {
                say::start(format_args!("Building BVH from {n} primitives... "));
            }
            let r = builder.commit(opts);
            if !quiet {
                say::done(format_args!("Done! ({:.4} sec)", t.elapsed().as_secs_f64()));
            }
            r
        }
        Some(dir) => {
            let (scene, report, cache) = builder.commit_cached(opts, dir);
            for w in cache.warnings() {
                say::warning(w);
            }
            let how = match (cache.loaded, &cache.write_error) {
                (true, _) => "Loaded BVH of",
                (false, None) => "Built BVH (and cached it) from",
                (false, Some(_)) => "Built BVH (not cached) from",
            };
            if !quiet {
                say::line(format_args!(
                    "{how} {n} primitives: {} ({:.4} sec)",
                    cache.path.display(),
                    t.elapsed().as_secs_f64()
                ));
            }
            (scene, report)
        }
    };
    if report.dropped() > 0 {
        say::warning(report);
    }
    scene
}
