// Not split yet: the bench's parsing, timing and printing are one command; moving its logic into the library is issue 67's point 3.
//! `raypack bench`: times raypack's kernels (and, with `--against embree`, Embree's calls) on
//! the standard ray sets of [`raypack::raysets`], over one thread and all threads.
//!
//! The methods and their tracing over threads are the library's ([`raypack::methods`]). Each
//! method runs once to warm up and to validate its checksum against the reference, then
//! `runs` times, round-robin with the other methods of the same ray set and thread count; the
//! median time is reported. `--isa` lowers the scene's ISA tier and limits Embree to the same
//! tier.

use crate::machine::{self, CpuTimes, Machine};
use crate::say;
use crate::{BenchArgs, CliError, check_memory, load, print_warnings};
#[cfg(feature = "embree")]
use raypack::kernels::embree_methods;
use raypack::kernels::{Method, Results, raypack_methods_named, trace};
use raypack::raysets::{self, Checksum};
use raypack::{BuildOptions, SceneBuilder};
use raypack::{Isa, Scene};
use std::path::Path;
use std::time::{Duration, Instant};

/// Bytes of raypack's acceleration structure over `scene`: the BVH8 nodes and its leaf blocks
/// (which hold their own copies of the triangles, as Embree's `Triangle4` leaves do), the
/// structure every kernel but the reference traverses.
pub fn raypack_accel_bytes(scene: &Scene) -> usize {
    scene.bvh8().bytes()
}

/// Why `raypack bench` could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// `--against embree` in a build without the `embree` feature.
    #[error(
        "--against embree: this raypack was built without Embree; rebuild with `cargo build --release --features embree` (needs Embree 3 or 4: libembree-dev on Debian, or RAYPACK_EMBREE_DIR; see the README)"
    )]
    EmbreeNotBuilt,
    /// Embree refused the scene.
    #[cfg(feature = "embree")]
    #[error("Embree: {0}")]
    Embree(#[from] raypack::embree::EmbreeError),
    /// Bad settings.
    #[error("{0}")]
    Settings(String),
}

/// What to run.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchSettings {
    /// Primary-ray image width.
    pub width: usize,
    /// Primary-ray image height.
    pub height: usize,
    /// Timed runs per method (the median is reported), after one warm-up run.
    pub runs: usize,
    /// Also trace with Embree (needs the `embree` feature).
    pub against_embree: bool,
    /// Thread counts to run at; `0` means all threads of the machine.
    pub threads: Vec<usize>,
    /// Seed of the diffuse bounces.
    pub seed: u64,
    /// The ISA tier to run raypack's kernels on, and the highest Embree may use; `None`
    /// keeps the scene's tier and lets Embree pick its best.
    pub isa: Option<Isa>,
    /// Time only the methods whose name contains one of these (all when empty); the
    /// reference still runs once per set for the checksums.
    pub methods: Vec<String>,
    /// The ray sets to time; `None`: [`raysets::bench_sets`] at `width × height`.
    pub ray_sets: Option<Vec<raysets::RaySet>>,
    /// Builds of each of Embree's structures (the median is reported).
    pub build_runs: usize,
    /// Build Embree's scenes with `RTC_SCENE_FLAG_ROBUST` (conservative traversal and a
    /// watertight triangle test), to race raypack's watertight trees at equal robustness.
    pub embree_robust: bool,
}

impl Default for BenchSettings {
    fn default() -> Self {
        Self {
            width: 1024,
            height: 768,
            runs: 5,
            build_runs: 1,
            embree_robust: false,
            against_embree: false,
            threads: vec![1, 0],
            seed: 1,
            isa: None,
            methods: Vec::new(),
            ray_sets: None,
        }
    }
}

/// Build time and size of one acceleration structure.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildFigures {
    /// `raypack` or `embree`.
    pub tracer: &'static str,
    /// What was built, e.g. `bvh2 medium` or `medium`.
    pub quality: String,
    /// Wall-clock build time on all threads, the median of `runs` builds.
    pub seconds: f64,
    /// The fastest and the slowest of the builds.
    pub seconds_range: (f64, f64),
    /// Builds timed.
    pub runs: usize,
    /// Bytes of the acceleration structure.
    pub bytes: u64,
}

impl BuildFigures {
    /// The figures of builds that took `times` (at least one).
    pub fn from_times(tracer: &'static str, quality: String, times: &[Duration], bytes: u64) -> Self {
        let (lo, hi) = (times.iter().min().expect("a build"), times.iter().max().expect("a build"));
        BuildFigures {
            tracer,
            quality,
            seconds: median(times.to_vec()).as_secs_f64(),
            seconds_range: (lo.as_secs_f64(), hi.as_secs_f64()),
            runs: times.len(),
            bytes,
        }
    }
}

/// One row of results.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchRow {
    /// Ray set name.
    pub rays: &'static str,
    /// Rays in the set.
    pub ray_count: usize,
    /// `raypack` or `embree`.
    pub tracer: &'static str,
    /// Method name.
    pub method: String,
    /// Threads used.
    pub threads: usize,
    /// Million rays per second (median run).
    pub mrays_per_s: f64,
    /// Million rays per second of the slowest timed run.
    pub mrays_per_s_min: f64,
    /// Million rays per second of the fastest timed run.
    pub mrays_per_s_max: f64,
    /// Checksum of the results.
    pub checksum: Checksum,
    /// True when the hit count differs from the reference's by more than [`HIT_TOLERANCE`] of
    /// the rays.
    pub checksum_differs: bool,
}

/// The fraction of a set's rays whose hit or miss may differ from the reference before a
/// method's figures are left out of the summary: Embree rounds differently, so a ray through
/// a shared edge or vertex can hit with one tracer and slip through with the other (on a 2M
/// triangle knot, Embree's shadow rays differed on 2 of 137,095 rays, 1.5e-5). A broken
/// comparison (another scene, wrong rays) differs on far more.
const HIT_TOLERANCE: f64 = 1e-4;

/// Everything `raypack bench` measured.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchReport {
    /// Scene name.
    pub scene: String,
    /// Triangles traced.
    pub triangles: usize,
    /// Primary-ray resolution.
    pub resolution: (usize, usize),
    /// Timed runs per method.
    pub runs: usize,
    /// Notes on the setup (Embree version, native packet widths).
    pub notes: Vec<String>,
    /// Build figures of every structure.
    pub build: Vec<BuildFigures>,
    /// Results.
    pub rows: Vec<BenchRow>,
    /// When the run started, RFC 3339 in UTC.
    pub date: String,
    /// The CPU, its ISA flags and the memory.
    pub machine: Machine,
    /// raypack's ISA tier in this run.
    pub raypack_isa: Isa,
    /// Embree's version and the ISA it chose (with `--against embree`).
    pub embree: Option<EmbreeIdentity>,
    /// How busy the machine was.
    pub load: Load,
}

/// Which Embree ran and on what ISA.
#[derive(Clone, Debug, PartialEq)]
pub struct EmbreeIdentity {
    /// Its version, e.g. `3.13.5`.
    pub version: String,
    /// The ISA tier it ran on (`sse`, `avx`, `avx2`, `avx512`). Embree has no query for its
    /// chosen ISA, so this is inferred from its native packet widths (16-wide: AVX-512,
    /// 8-wide: AVX or AVX2, neither: SSE), capped by `max_isa`.
    pub isa: String,
}

/// The machine's load around the run: other work on the CPUs makes the figures noisy, and
/// the ratios of methods timed at different moments unreliable.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Load {
    /// 1-, 5- and 15-minute load averages before the run (shown, not judged: they lag by
    /// minutes and count this run's predecessors in a sequence of runs).
    pub before: Option<[f64; 3]>,
    /// The same after the run (which includes the run itself).
    pub after: Option<[f64; 3]>,
    /// The share of all CPUs other processes kept busy in the moment before the run.
    pub busy_before: Option<f64>,
    /// The share of all CPU time during the run that other processes used.
    pub others_during: Option<f64>,
    /// The share of the CPU time during the run that the hypervisor stole.
    pub steal: Option<f64>,
}

impl Load {
    /// Why the figures may be unreliable, if they may: other processes kept more than a
    /// quarter of the CPUs busy just before or during the run, or the hypervisor stole more
    /// than 2% of the CPU time. Only other processes count, never the run's own threads.
    pub fn busy_reason(&self) -> Option<String> {
        let mut why = Vec::new();
        if let Some(b) = self.busy_before.filter(|&b| b > 0.25) {
            why.push(format!("other processes kept {:.0}% of the CPUs busy just before the run", 100.0 * b));
        }
        if let Some(b) = self.others_during.filter(|&b| b > 0.25) {
            why.push(format!("other processes used {:.0}% of the CPU time during the run", 100.0 * b));
        }
        if let Some(st) = self.steal.filter(|&st| st > 0.02) {
            why.push(format!("the hypervisor stole {:.1}% of the CPU time during the run", 100.0 * st));
        }
        (!why.is_empty()).then(|| why.join("; "))
    }
}

/// One line of the summary: the best raypack method against the best Embree call on one ray
/// set at one thread count.
#[derive(Clone, Debug, PartialEq)]
pub struct SummaryRow {
    /// Ray set name.
    pub rays: &'static str,
    /// Threads used.
    pub threads: usize,
    /// raypack's fastest method (by median), among those whose checksum matches.
    pub raypack: BenchRow,
    /// Embree's fastest call, when Embree ran.
    pub embree: Option<BenchRow>,
}

impl SummaryRow {
    /// raypack's median over Embree's median.
    pub fn ratio(&self) -> Option<f64> {
        self.embree.as_ref().map(|e| self.raypack.mrays_per_s / e.mrays_per_s.max(1e-12))
    }

    /// The spread of the ratio over the runs: raypack's slowest over Embree's fastest, and
    /// raypack's fastest over Embree's slowest.
    pub fn ratio_range(&self) -> Option<(f64, f64)> {
        self.embree.as_ref().map(|e| {
            (
                self.raypack.mrays_per_s_min / e.mrays_per_s_max.max(1e-12),
                self.raypack.mrays_per_s_max / e.mrays_per_s_min.max(1e-12),
            )
        })
    }
}

fn median(mut xs: Vec<Duration>) -> Duration {
    xs.sort();
    xs[xs.len() / 2]
}

/// Shortest timed run: a run traces its ray set as many times as it takes to last about this
/// long, so that a fast method on a small set measures tracing, not the few microseconds of
/// starting rayon's threads (the CS184 CBbunny shadow set is traced in about 1 ms).
const MIN_RUN: Duration = Duration::from_millis(50);

/// Times a run repeats its ray set, from the warm-up's duration (at least 1, at most 1000).
fn repetitions(warm_up: Duration) -> usize {
    let one = warm_up.as_secs_f64().max(1e-7);
    ((MIN_RUN.as_secs_f64() / one).ceil() as usize).clamp(1, 1000)
}

/// A structure built again for `--build-runs`: its figures (of the first build), the times of
/// its builds so far, and how to build it once more (returning the build's time).
struct Rebuilds<'a> {
    figures: BuildFigures,
    times: Vec<Duration>,
    again: Box<dyn FnMut() -> Result<Duration, BenchError> + 'a>,
}

/// Builds every structure of `builds` `rounds` more times, one build of each per round, in the
/// reverse order every other round, so that a phase of the machine's load falls on all
/// builders alike rather than on whichever built during it (as the methods' timed runs go
/// round-robin). Built one after the other, raypack's builds and then Embree's, their medians
/// had come from different minutes of a shared machine.
fn build_rounds(builds: &mut [Rebuilds<'_>], rounds: usize) -> Result<(), BenchError> {
    let n = builds.len();
    for round in 0..rounds {
        for j in 0..n {
            let b = &mut builds[if round % 2 == 1 { n - 1 - j } else { j }];
            let time = (b.again)()?;
            b.times.push(time);
        }
    }
    Ok(())
}

/// One of raypack's trees to time: the scene built at one quality, and its build figures.
pub struct RaypackTree {
    /// The build quality, as in `--quality` (e.g. `medium`).
    pub quality: String,
    /// The scene (its BVH built at `quality`).
    pub scene: Scene,
    /// Its build time and size.
    pub build: BuildFigures,
}

/// Times every method on every ray set at every thread count. The trees in `trees` were built
/// by the caller (timed there); the first makes the ray sets and the reference checksums, and
/// when there are several, each tree's method names end in its quality in brackets, as
/// Embree's do. `log` receives progress lines.
///
/// With `rebuild` (which builds tree `k` again and returns the build's time, the freeing of
/// what it built not included), each tree is built `settings.build_runs - 1` more times,
/// round-robin with Embree's builds, and its figures are those of all its builds; without,
/// its figures are the caller's.
pub fn run_bench(
    name: &str,
    trees: &mut [RaypackTree],
    settings: &BenchSettings,
    rebuild: Option<&dyn Fn(usize) -> Duration>,
    log: &mut dyn FnMut(&str),
) -> Result<BenchReport, BenchError> {
    assert!(!trees.is_empty(), "run_bench needs a tree");
    if settings.width == 0 || settings.height == 0 || settings.runs == 0 {
        return Err(BenchError::Settings("resolution and run count must be positive".into()));
    }
    #[cfg(not(feature = "embree"))]
    if settings.against_embree {
        return Err(BenchError::EmbreeNotBuilt);
    }
    if let Some(isa) = settings.isa {
        for t in trees.iter_mut() {
            t.scene.set_isa(isa).map_err(|e| BenchError::Settings(e.to_string()))?;
        }
    }
    let trees = &*trees;
    let scene = &trees[0].scene;
    let date = humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string();
    let load_before = machine::load_average();
    let busy_before = machine::busy_fraction(Duration::from_millis(300));
    let cpu_before = CpuTimes::now();
    let mut report = BenchReport {
        scene: name.to_string(),
        triangles: scene.num_triangles(),
        resolution: (settings.width, settings.height),
        runs: settings.runs,
        notes: vec![format!("raypack ISA: {} (CPU's best: {})", scene.isa(), Isa::detected())],
        build: trees.iter().map(|t| t.build.clone()).collect(),
        rows: Vec::new(),
        date,
        machine: machine::machine(),
        raypack_isa: scene.isa(),
        embree: None,
        load: Load { before: load_before, busy_before, ..Load::default() },
    };

    #[cfg(feature = "embree")]
    let embree_scenes = if settings.against_embree {
        use raypack::embree::{EmbreeQuality, EmbreeScene};
        let mut v = Vec::new();
        for q in [EmbreeQuality::Medium, EmbreeQuality::High] {
            log(&format!("building Embree BVH ({})", q.name()));
            let options = raypack::embree::EmbreeOptions {
                quality: q,
                max_isa: settings.isa,
                robust: settings.embree_robust,
                ..Default::default()
            };
            v.push(EmbreeScene::with_options(scene, options)?);
        }
        v
    } else {
        Vec::new()
    };

    // Each structure's builds after its first, in rounds (see `build_rounds`).
    let mut builds: Vec<Rebuilds<'_>> = Vec::new();
    if let Some(rebuild) = rebuild {
        for (k, t) in trees.iter().enumerate() {
            let first = Duration::from_secs_f64(t.build.seconds);
            builds.push(Rebuilds {
                figures: t.build.clone(),
                times: vec![first],
                again: Box::new(move || Ok(rebuild(k))),
            });
        }
    }
    let first_embree = builds.len();
    #[cfg(feature = "embree")]
    for e in &embree_scenes {
        let options = e.options();
        let figures =
            BuildFigures::from_times("embree", options.quality.name().to_string(), &[e.build_time()], e.bvh_bytes());
        let again = move || Ok(raypack::embree::EmbreeScene::with_options(scene, options)?.build_time());
        builds.push(Rebuilds { figures, times: vec![e.build_time()], again: Box::new(again) });
    }
    if settings.build_runs > 1 && !builds.is_empty() {
        log(&format!("{} more builds of each structure, round-robin", settings.build_runs - 1));
    }
    build_rounds(&mut builds, settings.build_runs.max(1) - 1)?;
    for (j, b) in builds.iter().enumerate() {
        let f = BuildFigures::from_times(b.figures.tracer, b.figures.quality.clone(), &b.times, b.figures.bytes);
        if j < first_embree {
            report.build[j] = f;
        } else {
            report.build.push(f);
        }
    }

    #[cfg(feature = "embree")]
    if let Some(e) = embree_scenes.first() {
        use raypack::embree::EmbreeWidth;
        let isa = if e.native_packets(EmbreeWidth::W16) {
            "avx512"
        } else if !e.native_packets(EmbreeWidth::W8) {
            "sse"
        } else if settings.isa.is_none_or(|i| i >= Isa::Avx2) && Isa::detected() >= Isa::Avx2 {
            "avx2"
        } else {
            "avx"
        };
        report.embree = Some(EmbreeIdentity { version: e.version(), isa: isa.to_string() });
        report.notes.push(format!(
            "Embree {} (max_isa {}{}): native 8-wide packets {}, 16-wide {}",
            e.version(),
            settings.isa.map_or("none", |i| i.name()),
            if settings.embree_robust { ", RTC_SCENE_FLAG_ROBUST" } else { "" },
            if e.native_packets(EmbreeWidth::W8) { "yes" } else { "no (emulated)" },
            if e.native_packets(EmbreeWidth::W16) { "yes" } else { "no (emulated)" },
        ));
    }

    #[cfg_attr(not(feature = "embree"), allow(unused_mut))]
    let mut methods = Vec::new();
    for (k, t) in trees.iter().enumerate() {
        let suffix = if trees.len() > 1 { format!(" ({})", t.quality) } else { String::new() };
        // The scalar reference (the binary BVH) is the same whatever the tree: the first's.
        methods.extend(raypack_methods_named(&t.scene, &suffix, k == 0));
    }
    #[cfg(feature = "embree")]
    for e in &embree_scenes {
        methods.extend(embree_methods(e, &format!(" ({})", e.options().quality.name())));
    }

    log(&format!("making ray sets at {}x{}", settings.width, settings.height));
    let sets = match &settings.ray_sets {
        Some(sets) => sets.clone(),
        None => raysets::bench_sets(scene, settings.width, settings.height, settings.seed).to_vec(),
    };
    let all = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    for set in &sets {
        let occlusion = set.kind.is_occlusion();
        let reference =
            methods.iter().find(|m| m.run.is_occlusion() == occlusion).expect("KERNELS has a kernel of each query");
        let mut ref_out = Results::for_run(&reference.run, set.rays.len());
        trace(&reference.run, &set.rays, &mut ref_out);
        let ref_sum = ref_out.checksum(&set.rays);
        for &t in &settings.threads {
            let threads = if t == 0 { all } else { t };
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .map_err(|e| BenchError::Settings(e.to_string()))?;
            let wanted = |m: &&Method<'_>| {
                settings.methods.is_empty() || settings.methods.iter().any(|f| m.name.contains(f.as_str()))
            };
            // Every method warms up once (and sizes its repetitions), then the timed runs go
            // round-robin over the methods, so a phase of the machine's load falls on all of
            // them alike rather than on whichever ran during it.
            let chosen: Vec<&Method<'_>> =
                methods.iter().filter(|m| m.run.is_occlusion() == occlusion).filter(wanted).collect();
            // One output buffer for all methods; each checksum is taken from the warm-up.
            let mut out = Results::for_run(&reference.run, set.rays.len());
            let mut times: Vec<Vec<Duration>> = vec![Vec::with_capacity(settings.runs); chosen.len()];
            let (reps, checksums): (Vec<usize>, Vec<Checksum>) = pool.install(|| {
                chosen
                    .iter()
                    .map(|m| {
                        let t0 = Instant::now();
                        trace(&m.run, &set.rays, &mut out); // warm-up
                        let reps = repetitions(t0.elapsed());
                        (reps, out.checksum(&set.rays))
                    })
                    .unzip()
            });
            pool.install(|| {
                for _ in 0..settings.runs {
                    for ((m, &reps), times) in chosen.iter().zip(&reps).zip(&mut times) {
                        let t0 = Instant::now();
                        for _ in 0..reps {
                            trace(&m.run, &set.rays, &mut out);
                        }
                        times.push(t0.elapsed());
                    }
                }
            });
            for ((m, checksum), (reps, times)) in chosen.iter().zip(checksums).zip(reps.into_iter().zip(times)) {
                let allowed = set.rays.len() as f64 * HIT_TOLERANCE;
                let checksum_differs = (checksum.hits as f64 - ref_sum.hits as f64).abs() > allowed;
                let secs = |d: Duration| d.as_secs_f64().max(1e-12);
                let mrays = |d: Duration| (reps * set.rays.len()) as f64 / secs(d) / 1e6;
                let (fastest, slowest) =
                    (*times.iter().min().expect("runs > 0"), *times.iter().max().expect("runs > 0"));
                let med = median(times);
                let row = BenchRow {
                    rays: set.kind.name(),
                    ray_count: set.rays.len(),
                    tracer: m.tracer,
                    method: m.name.clone(),
                    threads,
                    mrays_per_s: mrays(med),
                    mrays_per_s_min: mrays(slowest),
                    mrays_per_s_max: mrays(fastest),
                    checksum,
                    checksum_differs,
                };
                log(&format!(
                    "{:<8} {} threads {:<8} {:<34} {:>9.3} Mrays/s",
                    row.rays, threads, row.tracer, row.method, row.mrays_per_s
                ));
                report.rows.push(row);
            }
        }
    }
    report.load.after = machine::load_average();
    if let Some((a, b)) = cpu_before.zip(CpuTimes::now()) {
        report.load.steal = Some(b.since(&a).1);
        report.load.others_during = Some(b.others_since(&a));
    }
    Ok(report)
}

impl BenchReport {
    /// The best Embree speed on the same ray set and thread count as `row`.
    pub fn embree_best(&self, rays: &str, threads: usize) -> Option<f64> {
        self.rows
            .iter()
            .filter(|r| r.tracer == "embree" && r.rays == rays && r.threads == threads)
            .map(|r| r.mrays_per_s)
            .fold(None, |a, x| Some(a.map_or(x, |a: f64| a.max(x))))
    }

    /// Per ray set and thread count, in the order they ran: the fastest raypack method and the
    /// fastest Embree call (methods whose checksum differs from the reference's are left out).
    pub fn summary(&self) -> Vec<SummaryRow> {
        let mut out: Vec<SummaryRow> = Vec::new();
        let faster = |a: &Option<BenchRow>, r: &BenchRow| a.as_ref().is_none_or(|a| r.mrays_per_s > a.mrays_per_s);
        for r in self.rows.iter().filter(|r| !r.checksum_differs) {
            let i = match out.iter().position(|s| s.rays == r.rays && s.threads == r.threads) {
                Some(i) => i,
                None if r.tracer == "raypack" => {
                    out.push(SummaryRow { rays: r.rays, threads: r.threads, raypack: r.clone(), embree: None });
                    continue;
                }
                None => continue,
            };
            let s = &mut out[i];
            if r.tracer == "raypack" && r.mrays_per_s > s.raypack.mrays_per_s {
                s.raypack = r.clone();
            } else if r.tracer == "embree" && faster(&s.embree, r) {
                s.embree = Some(r.clone());
            }
        }
        out
    }

    /// The build times in one line: each structure's median over its builds, on all threads.
    fn build_line(&self) -> Option<String> {
        let runs = self.build.iter().map(|b| b.runs).max()?;
        let each: Vec<String> = self
            .build
            .iter()
            .map(|b| {
                let several = self.build.iter().filter(|b| b.tracer == "raypack").count() > 1;
                let what = match b.tracer {
                    "raypack" if several => format!("raypack {}", b.quality),
                    "raypack" => "raypack".to_string(),
                    _ => format!("Embree {}", b.quality),
                };
                format!("{what} {:.3} s ({:.3}-{:.3})", b.seconds, b.seconds_range.0, b.seconds_range.1)
            })
            .collect();
        let of = if runs == 1 { "one build each".to_string() } else { format!("median of {runs} builds") };
        Some(format!("build: {} ({of}, all threads)", each.join(", ")))
    }

    /// Why a summary row has no Embree figure although Embree ran on its set: every Embree
    /// call's hits differed from the reference's by more than the summary allows (edge cases
    /// of a large mesh can do that). One line per ray set, naming both hit counts.
    fn left_out(&self, summary: &[SummaryRow]) -> Vec<String> {
        let mut out = Vec::new();
        let mut seen: Vec<&str> = Vec::new();
        for r in summary.iter().filter(|r| r.embree.is_none()) {
            let embree = self.rows.iter().find(|e| e.tracer == "embree" && e.rays == r.rays && e.threads == r.threads);
            let Some(e) = embree.filter(|_| !seen.contains(&r.rays)) else { continue };
            seen.push(r.rays);
            out.push(format!(
                "{}: Embree left out: its hits ({}) differ from raypack's ({}) on more than {HIT_TOLERANCE:e} of the {} rays; --verbose lists its figures",
                r.rays, e.checksum.hits, r.raypack.checksum.hits, e.ray_count
            ));
        }
        out
    }

    /// The one line that names what the figures depend on outside the scene: the CPU and its
    /// ISA flags, raypack's ISA (and commit), Embree's version and ISA, and the load average
    /// before and after the run.
    pub fn header(&self) -> String {
        let m = &self.machine;
        let commit = option_env!("RAYPACK_GIT_COMMIT").map_or(String::new(), |c| format!(" {c}"));
        let embree = self.embree.as_ref().map_or(String::new(), |e| {
            format!(" | Embree {} ISA {} (inferred from its native packet widths)", e.version, e.isa)
        });
        let load = |l: Option<[f64; 3]>| l.map_or("?".into(), |l| format!("{:.2} {:.2} {:.2}", l[0], l[1], l[2]));
        format!(
            "machine: {} ({} logical CPUs; {}) | raypack {}{} ISA {}{} | load average {} before, {} after",
            m.cpu,
            m.logical_cpus,
            m.cpu_flags.join(" "),
            env!("CARGO_PKG_VERSION"),
            commit,
            self.raypack_isa,
            embree,
            load(self.load.before),
            load(self.load.after),
        )
    }

    /// The warning to print under the header when the machine was busy.
    pub fn busy_warning(&self) -> Option<String> {
        self.load.busy_reason().map(|why| {
            format!(
                "WARNING: the machine was busy ({why}); the figures and ratios may be off, run again on an idle machine"
            )
        })
    }

    /// What the rays were: the built-in sets, or the `--rays` file's (whose rows are the set
    /// `file`).
    fn ray_sets(&self) -> String {
        match self.rows.iter().find(|r| r.rays == raysets::RaySetKind::File.name()) {
            Some(r) => format!("{} rays from the --rays file, traced as closest-hit rays", r.ray_count),
            None => format!(
                "primary rays {}x{} in 4x4 tiles, diffuse and shadow rays from their hits",
                self.resolution.0, self.resolution.1
            ),
        }
    }

    /// The report as text: the scene and ray sets, (with `verbose`) the build figures and
    /// every method's row, then the header line and the summary table.
    pub fn text(&self, verbose: bool) -> String {
        use std::fmt::Write;
        let mut s = if verbose { self.table() } else { String::new() };
        if !verbose {
            let _ = writeln!(
                s,
                "scene {} ({} triangles); {}; median of {} runs",
                self.scene,
                self.triangles,
                self.ray_sets(),
                self.runs
            );
        } else {
            s.push('\n');
        }
        let _ = writeln!(s, "{}", self.header());
        if let Some(w) = self.busy_warning() {
            let _ = writeln!(s, "{w}");
        }
        let summary = self.summary();
        let with_embree = summary.iter().any(|r| r.embree.is_some());
        let _ = write!(s, "\n{:<8} {:>3}  {:<32} {:>9}", "rays", "thr", "best raypack", "Mrays/s");
        if with_embree {
            let _ = writeln!(s, "  {:<32} {:>9} {:>6}  {:<13}", "best Embree", "Mrays/s", "ratio", "ratio min-max");
        } else {
            let _ = writeln!(s, "  min-max Mrays/s");
        }
        for r in &summary {
            let _ =
                write!(s, "{:<8} {:>3}  {:<32} {:>9.2}", r.rays, r.threads, r.raypack.method, r.raypack.mrays_per_s);
            match (&r.embree, r.ratio(), r.ratio_range()) {
                (Some(e), Some(ratio), Some((lo, hi))) => {
                    let _ = writeln!(s, "  {:<32} {:>9.2} {:>5.2}x  {lo:.2}-{hi:.2}x", e.method, e.mrays_per_s, ratio);
                }
                _ if with_embree => {
                    let _ = writeln!(s, "  {:<32} {:>9} {:>6}  -", "-", "-", "-");
                }
                _ => {
                    let _ = writeln!(s, "  {:.2}-{:.2}", r.raypack.mrays_per_s_min, r.raypack.mrays_per_s_max);
                }
            }
        }
        if with_embree {
            let _ = writeln!(
                s,
                "ratio: best raypack median over best Embree median; min-max: raypack's slowest run over Embree's fastest, and its fastest over Embree's slowest"
            );
        }
        for line in self.left_out(&summary) {
            let _ = writeln!(s, "{line}");
        }
        if let Some(line) = self.build_line() {
            let _ = writeln!(s, "{line}");
        }
        if !verbose {
            let _ = writeln!(s, "(every method's figures: --verbose or --json)");
        }
        s
    }

    /// The full report as a plain-text table: the setup, the build figures and every
    /// method's row.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let tri = self.triangles.max(1) as f64;
        let _ = writeln!(s, "scene      {} ({} triangles)", self.scene, self.triangles);
        let _ = writeln!(
            s,
            "rays       {}; median of {} runs (each repeats the set to last at least 50 ms)",
            self.ray_sets(),
            self.runs
        );
        for n in &self.notes {
            let _ = writeln!(s, "note       {n}");
        }
        for b in &self.build {
            let _ = writeln!(
                s,
                "build      {:<8} {:<12} {:>9.4} s ({:.4}-{:.4} s, {} builds)  {:>12} bytes  {:>7.1} bytes/triangle",
                b.tracer,
                b.quality,
                b.seconds,
                b.seconds_range.0,
                b.seconds_range.1,
                b.runs,
                b.bytes,
                b.bytes as f64 / tri
            );
        }
        let _ = writeln!(
            s,
            "\n{:<8} {:>8} {:>3} {:<8} {:<34} {:>9} {:>7} {:>9} {:>18}",
            "rays", "count", "thr", "tracer", "method", "Mrays/s", "ratio", "hits", "t-sum"
        );
        for r in &self.rows {
            let ratio = match self.embree_best(r.rays, r.threads) {
                Some(best) if best > 0.0 => format!("{:.2}x", r.mrays_per_s / best),
                _ => "-".to_string(),
            };
            let _ = writeln!(
                s,
                "{:<8} {:>8} {:>3} {:<8} {:<34} {:>9.3} {:>7} {:>9} {:>18.10e}{}",
                r.rays,
                r.ray_count,
                r.threads,
                r.tracer,
                r.method,
                r.mrays_per_s,
                ratio,
                r.checksum.hits,
                r.checksum.t_sum,
                if r.checksum_differs { "  CHECKSUM DIFFERS FROM REFERENCE" } else { "" }
            );
        }
        let _ = writeln!(s, "ratio: Mrays/s over the best Embree method on the same rays and threads");
        s
    }

    /// The report as one JSON document (schema 2):
    /// `{"schema", "date", "scene", "triangles", "resolution", "runs", "notes", "machine",
    /// "raypack", "embree", "load_average", "busy", "build": {...}, "results": [{"rays",
    /// "ray_count", "tracer", "method", "threads", "mrays_per_s", "mrays_per_s_min",
    /// "mrays_per_s_max", "hits", "t_sum"}], "summary": [...]}`.
    pub fn json(&self) -> serde_json::Value {
        use serde_json::{Map, Value, json};
        let mut build = Map::new();
        for b in &self.build {
            build.insert(
                format!("{} {}", b.tracer, b.quality),
                json!({
                    "tracer": b.tracer,
                    "quality": b.quality,
                    "seconds": b.seconds,
                    "seconds_min": b.seconds_range.0,
                    "seconds_max": b.seconds_range.1,
                    "runs": b.runs,
                    "bytes": b.bytes,
                    "bytes_per_triangle": b.bytes as f64 / self.triangles.max(1) as f64,
                }),
            );
        }
        let results: Vec<Value> = self
            .rows
            .iter()
            .map(|r| {
                json!({
                    "rays": r.rays,
                    "ray_count": r.ray_count,
                    "tracer": r.tracer,
                    "method": r.method,
                    "threads": r.threads,
                    "mrays_per_s": r.mrays_per_s,
                    "mrays_per_s_min": r.mrays_per_s_min,
                    "mrays_per_s_max": r.mrays_per_s_max,
                    "hits": r.checksum.hits,
                    "t_sum": r.checksum.t_sum,
                })
            })
            .collect();
        let summary: Vec<Value> = self
            .summary()
            .iter()
            .map(|r| {
                let range = r.ratio_range();
                json!({
                    "rays": r.rays,
                    "threads": r.threads,
                    "raypack_method": r.raypack.method,
                    "raypack_mrays_per_s": r.raypack.mrays_per_s,
                    "embree_method": r.embree.as_ref().map(|e| &e.method),
                    "embree_mrays_per_s": r.embree.as_ref().map(|e| e.mrays_per_s),
                    "ratio": r.ratio(),
                    "ratio_min": range.map(|r| r.0),
                    "ratio_max": range.map(|r| r.1),
                })
            })
            .collect();
        let m = &self.machine;
        json!({
            "schema": 2,
            "date": self.date,
            "machine": {
                "cpu": m.cpu,
                "cpu_flags": m.cpu_flags,
                "logical_cpus": m.logical_cpus,
                "memory_bytes": m.memory_bytes,
            },
            "raypack": {
                "version": env!("CARGO_PKG_VERSION"),
                "commit": option_env!("RAYPACK_GIT_COMMIT"),
                "isa": self.raypack_isa.name(),
            },
            "embree": self.embree.as_ref().map(|e| json!({"version": e.version, "isa": e.isa})),
            "load_average": {"before": self.load.before, "after": self.load.after},
            "busy": self.busy_warning().is_some(),
            "busy_reason": self.load.busy_reason(),
            "summary": summary,
            "scene": self.scene,
            "triangles": self.triangles,
            "resolution": [self.resolution.0, self.resolution.1],
            "runs": self.runs,
            "notes": self.notes,
            "build": build,
            "results": results,
        })
    }
}

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
    let quality = format!("{:?}", opts.quality).to_lowercase();
    let build = BuildFigures::from_times(
        "raypack",
        format!("bvh8 {quality} {}", scene.triangle_test().name()),
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
    crate::machine::check_threads(a.threads)?;
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
    for (k, &q) in a.qualities().iter().enumerate() {
        let quality = q;
        // The first tree's binary BVH stays for the reference rows and the checksums they
        // anchor.
        let opts = BuildOptions { quality, watertight: a.watertight, keep_bvh2: k == 0, ..BuildOptions::default() };
        let (scene, build) = build_timed(&builder, &opts, &a)?;
        let name = quality.name().to_string();
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

#[cfg(test)]
mod tests {
    use super::*;
    use raypack::generate::uv_sphere;
    use raypack::kernels::KERNELS;
    use raypack::{BuildOptions, BuildQuality, Material, SceneBuilder};

    /// A UV sphere of 16 × 24 quads, committed with `opts`.
    fn sphere_scene(opts: &BuildOptions) -> Scene {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::default());
        let s = uv_sphere(16, 24);
        b.add_mesh(&s.positions, &s.indices, m).unwrap();
        b.commit(opts).0
    }

    #[test]
    fn bench_runs_every_kernel_and_checksums_agree() {
        let scene = sphere_scene(&BuildOptions::default());
        let build = BuildFigures::from_times("raypack", "medium".into(), &[Duration::ZERO], 0);
        let settings = BenchSettings { width: 32, height: 24, runs: 1, threads: vec![1, 2], ..Default::default() };
        let mut trees = [RaypackTree { quality: "medium".into(), scene, build }];
        let report = run_bench("sphere", &mut trees, &settings, None, &mut |_| {}).unwrap();
        let scene = &trees[0].scene;
        // 3 sets x 2 thread counts x the kernels of the matching query.
        let per_query = |occ: bool| KERNELS.iter().filter(move |k| k.is_occlusion() == occ);
        assert_eq!(report.rows.len(), 2 * (2 * per_query(false).count() + per_query(true).count()));
        assert!(report.rows.iter().all(|r| !r.checksum_differs));
        let primary = report.rows.iter().find(|r| r.rays == "primary").unwrap();
        assert_eq!(primary.ray_count, 32 * 24);
        assert!(primary.checksum.hits > 100 && primary.checksum.t_sum > 0.0);
        let json = report.json();
        assert_eq!(json["triangles"], scene.num_triangles());
        assert_eq!(json["results"].as_array().unwrap().len(), report.rows.len());
        assert!(json["results"][0]["mrays_per_s"].as_f64().unwrap() > 0.0);
        assert!(report.table().contains("bvh2 reference intersect1"));
    }

    #[test]
    fn several_trees_are_timed_under_their_quality_with_one_reference() {
        let mut trees = Vec::new();
        for (name, quality) in [("medium", BuildQuality::Medium), ("high", BuildQuality::High)] {
            let scene = sphere_scene(&BuildOptions { quality, keep_bvh2: name == "medium", ..BuildOptions::default() });
            let build = BuildFigures::from_times("raypack", format!("bvh8 {name}"), &[Duration::ZERO], 0);
            trees.push(RaypackTree { quality: name.into(), scene, build });
        }
        let settings = BenchSettings { width: 32, height: 24, runs: 1, threads: vec![1], ..Default::default() };
        let report = run_bench("sphere", &mut trees, &settings, None, &mut |_| {}).unwrap();
        let simd = KERNELS.iter().filter(|k| k.simd).count();
        let per_set = |occ: bool| KERNELS.iter().filter(|k| k.is_occlusion() == occ).count();
        let simd_per_set = |occ: bool| KERNELS.iter().filter(|k| k.simd && k.is_occlusion() == occ).count();
        // The reference once, each SIMD kernel once per tree: 2 closest-hit sets, 1 occlusion.
        assert!(simd > 0);
        assert_eq!(report.rows.len(), 2 * (per_set(false) + simd_per_set(false)) + per_set(true) + simd_per_set(true));
        assert!(report.rows.iter().all(|r| !r.checksum_differs));
        for q in ["medium", "high"] {
            let tag = format!(" ({q})");
            assert!(report.rows.iter().any(|r| r.method == format!("Scene::intersect1{tag}")), "{q}");
        }
        assert_eq!(report.rows.iter().filter(|r| r.method.contains("reference") && r.rays == "primary").count(), 1);
        assert_eq!(report.build.len(), 2);
        assert!(report.build_line().unwrap().contains("raypack bvh8 high"));
    }

    #[test]
    fn more_builds_go_round_robin_and_count_in_the_figures() {
        let mut trees = Vec::new();
        for (name, ms) in [("medium", 10), ("high", 40)] {
            let scene = sphere_scene(&BuildOptions::default());
            let build = BuildFigures::from_times("raypack", format!("bvh8 {name}"), &[Duration::from_millis(ms)], 7);
            trees.push(RaypackTree { quality: name.into(), scene, build });
        }
        // Tree k's builds after the first take 1 + 2k ms (medium) or 30 + k ms (high).
        let calls = std::cell::RefCell::new(Vec::new());
        let rebuild = |k: usize| {
            let mut c = calls.borrow_mut();
            c.push(k);
            let n = c.iter().filter(|&&j| j == k).count() as u64;
            Duration::from_millis(if k == 0 { 1 + 2 * n } else { 30 + n })
        };
        let settings = BenchSettings {
            width: 8,
            height: 6,
            runs: 1,
            threads: vec![1],
            build_runs: 4,
            methods: vec!["Scene::intersect1".into()],
            ..Default::default()
        };
        let report = run_bench("sphere", &mut trees, &settings, Some(&rebuild), &mut |_| {}).unwrap();
        // Three rounds, every other one reversed.
        assert_eq!(*calls.borrow(), [0, 1, 1, 0, 0, 1]);
        let (m, h) = (&report.build[0], &report.build[1]);
        assert_eq!((m.runs, h.runs), (4, 4));
        // Medium: 10, 3, 5, 7 ms; high: 40, 31, 32, 33 ms.
        assert_eq!((m.seconds_range, h.seconds_range), ((0.003, 0.010), (0.031, 0.040)));
        assert_eq!((m.seconds, h.seconds), (0.007, 0.033));
        assert_eq!((m.quality.as_str(), m.bytes), ("bvh8 medium", 7));
    }

    fn row(rays: &'static str, threads: usize, tracer: &'static str, method: &str, mrays: [f64; 3]) -> BenchRow {
        BenchRow {
            rays,
            ray_count: 10,
            tracer,
            method: method.into(),
            threads,
            mrays_per_s: mrays[1],
            mrays_per_s_min: mrays[0],
            mrays_per_s_max: mrays[2],
            checksum: Checksum::default(),
            checksum_differs: false,
        }
    }

    #[test]
    fn summary_pairs_the_fastest_of_each_tracer_and_spans_the_runs() {
        let (scene, _) = SceneBuilder::new().commit(&BuildOptions::default());
        let build = BuildFigures::from_times("raypack", "medium".into(), &[Duration::ZERO], 0);
        let settings = BenchSettings { width: 4, height: 4, runs: 1, threads: vec![1], ..Default::default() };
        let mut trees = [RaypackTree { quality: "medium".into(), scene, build }];
        let mut report = run_bench("empty", &mut trees, &settings, None, &mut |_| {}).unwrap();
        let mut wrong = row("primary", 1, "raypack", "wrong", [90.0, 100.0, 110.0]);
        wrong.checksum_differs = true;
        report.rows = vec![
            row("primary", 1, "raypack", "a", [8.0, 10.0, 12.0]),
            row("primary", 1, "raypack", "b", [18.0, 20.0, 21.0]),
            wrong,
            row("primary", 1, "embree", "e1", [4.0, 5.0, 6.0]),
            row("primary", 1, "embree", "e2", [9.0, 10.0, 12.0]),
            row("primary", 2, "raypack", "a", [30.0, 30.0, 30.0]),
        ];
        let s = report.summary();
        assert_eq!(s.len(), 2);
        assert_eq!((s[0].raypack.method.as_str(), s[0].embree.as_ref().unwrap().method.as_str()), ("b", "e2"));
        assert_eq!(s[0].ratio(), Some(2.0));
        assert_eq!(s[0].ratio_range(), Some((18.0 / 12.0, 21.0 / 9.0)));
        assert_eq!((s[1].threads, s[1].embree.as_ref(), s[1].ratio()), (2, None, None));
        let json = report.json();
        assert_eq!(json["schema"], 2);
        assert_eq!(json["summary"][0]["ratio"], 2.0);
        assert_eq!(json["summary"][0]["embree_method"], "e2");
        assert!(json["summary"][1]["ratio"].is_null());
        assert_eq!(json["results"][1]["mrays_per_s_max"], 21.0);
        assert_eq!(json["machine"]["logical_cpus"], report.machine.logical_cpus);
        let text = report.text(false);
        assert!(text.contains("machine: ") && text.contains(" 2.00x  1.50-2.33x"), "{text}");
        assert!(!text.contains("wrong"));
        // (The 2-thread row has no Embree figure because Embree did not run there.)
        assert!(!text.contains("left out"), "{text}");

        // Embree's calls all differ from the reference: the summary says so instead of a bare dash.
        for r in report.rows.iter_mut().filter(|r| r.tracer == "embree") {
            r.checksum_differs = true;
            r.checksum.hits = 7;
        }
        let text = report.text(false);
        assert!(
            text.contains(
                "primary: Embree left out: its hits (7) differ from raypack's (0) on more than 1e-4 of the 10 rays"
            ),
            "{text}"
        );
        assert_eq!(text.matches("left out").count(), 1, "{text}");

        // Build times: the median of the builds, with the fastest and slowest.
        let ms = |v: &[u64]| v.iter().map(|&m| Duration::from_millis(m)).collect::<Vec<_>>();
        report.build = vec![
            BuildFigures::from_times("raypack", "bvh8 medium".into(), &ms(&[300, 100, 200]), 1000),
            BuildFigures::from_times("embree", "medium".into(), &ms(&[250, 150, 400]), 2000),
        ];
        let text = report.text(false);
        assert!(
            text.contains(
                "build: raypack 0.200 s (0.100-0.300), Embree medium 0.250 s (0.150-0.400) (median of 3 builds, all threads)"
            ),
            "{text}"
        );
        let json = report.json();
        let b = &json["build"]["embree medium"];
        assert_eq!(
            (b["seconds"].as_f64(), b["seconds_min"].as_f64(), b["runs"].as_u64()),
            (Some(0.25), Some(0.15), Some(3))
        );
    }

    #[test]
    fn busy_counts_other_processes_and_steal_never_the_load_average() {
        let idle = Load {
            before: Some([0.4, 0.3, 0.2]),
            busy_before: Some(0.05),
            others_during: Some(0.01),
            steal: Some(0.0),
            ..Load::default()
        };
        assert_eq!(idle.busy_reason(), None);
        // A sequence of runs leaves its own load average behind: not busy.
        let after_own_runs = Load { before: Some([1.9, 1.5, 1.0]), ..idle.clone() };
        assert_eq!(after_own_runs.busy_reason(), None);
        let before = Load { busy_before: Some(0.6), ..idle.clone() };
        assert!(before.busy_reason().unwrap().contains("60% of the CPUs busy just before"));
        let during = Load { others_during: Some(0.4), ..idle.clone() };
        assert!(during.busy_reason().unwrap().contains("used 40% of the CPU time during"));
        let stolen = Load { steal: Some(0.1), ..idle };
        assert!(stolen.busy_reason().unwrap().contains("stole 10.0%"));
    }

    /// `--watertight --against embree`: raypack's watertight tree against Embree's robust
    /// mode, both finding the same hits on every set.
    #[cfg(feature = "embree")]
    #[test]
    fn watertight_races_embree_in_robust_mode() {
        let scene = sphere_scene(&BuildOptions { watertight: true, ..BuildOptions::default() });
        let build = BuildFigures::from_times("raypack", "medium".into(), &[Duration::ZERO], 0);
        let settings = BenchSettings {
            width: 32,
            height: 24,
            runs: 1,
            threads: vec![1],
            against_embree: true,
            embree_robust: true,
            ..Default::default()
        };
        let mut trees = [RaypackTree { quality: "medium".into(), scene, build }];
        let report = run_bench("sphere", &mut trees, &settings, None, &mut |_| {}).unwrap();
        assert!(report.notes.iter().any(|n| n.contains("RTC_SCENE_FLAG_ROBUST")), "{:?}", report.notes);
        let embree: Vec<_> = report.rows.iter().filter(|r| r.tracer == "embree").collect();
        assert!(embree.len() >= 6, "Embree's calls on the three sets");
        assert!(report.rows.iter().all(|r| !r.checksum_differs), "{}", report.table());
    }

    #[cfg(not(feature = "embree"))]
    #[test]
    fn against_embree_without_the_feature_is_a_clear_error() {
        let (scene, _) = SceneBuilder::new().commit(&BuildOptions::default());
        let build = BuildFigures::from_times("raypack", "medium".into(), &[Duration::ZERO], 0);
        let settings = BenchSettings { against_embree: true, ..Default::default() };
        let mut trees = [RaypackTree { quality: "medium".into(), scene, build }];
        let err = run_bench("empty", &mut trees, &settings, None, &mut |_| {}).unwrap_err();
        assert!(matches!(err, BenchError::EmbreeNotBuilt));
        assert!(err.to_string().contains("--features embree"));
    }
}
