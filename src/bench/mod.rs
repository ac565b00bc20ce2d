//! Benchmarking raypack's kernels (and, with the `embree` feature, Embree's calls): the
//! timing loop behind `raypack bench` ([`run_bench`]), its report ([`BenchReport`]: text,
//! table and JSON) and the machine's probes it records ([`machine`]). The methods timed and
//! their tracing over threads are the registry's ([`crate::kernels`]); the ray sets are
//! [`crate::raysets`]'s.
//!
//! Each method runs once to warm up and to validate its checksum against the reference, then
//! `runs` times, round-robin with the other methods of the same ray set and thread count; the
//! median time is reported. [`BenchSettings::isa`] lowers the scene's ISA tier and limits
//! Embree to the same tier.

pub mod machine;
mod report;
#[cfg(test)]
mod tests;

use crate::kernels::{Method, Results, raypack_methods_named, trace};
use crate::raysets::{self, Checksum};
use crate::{Isa, Scene};
use machine::{CpuTimes, Machine};
use std::time::{Duration, Instant};

/// Bytes of raypack's acceleration structure over `scene`: the BVH8 nodes and its leaf blocks
/// (which hold their own copies of the triangles, as Embree's `Triangle4` leaves do), the
/// structure every kernel but the reference traverses.
pub fn raypack_accel_bytes(scene: &Scene) -> usize {
    scene.bvh8().bytes()
}

/// Why a bench run could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// Embree asked for in a build without the `embree` feature.
    #[error(
        "--against embree: this raypack was built without Embree; rebuild with `cargo build --release --features embree` (needs Embree 3 or 4: libembree-dev on Debian, or RAYPACK_EMBREE_DIR; see the README)"
    )]
    EmbreeNotBuilt,
    /// Embree refused the scene.
    #[cfg(feature = "embree")]
    #[error("Embree: {0}")]
    Embree(#[from] crate::embree::EmbreeError),
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
pub const HIT_TOLERANCE: f64 = 1e-4;

/// Everything a bench run measured.
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
        use crate::embree::{EmbreeQuality, EmbreeScene};
        let mut v = Vec::new();
        for q in [EmbreeQuality::Medium, EmbreeQuality::High] {
            log(&format!("building Embree BVH ({})", q.name()));
            let options = crate::embree::EmbreeOptions {
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
        let again = move || Ok(crate::embree::EmbreeScene::with_options(scene, options)?.build_time());
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
        use crate::embree::EmbreeWidth;
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
        methods.extend(crate::kernels::embree_methods(e, &format!(" ({})", e.options().quality.name())));
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
