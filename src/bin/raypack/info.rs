//! `raypack info SCENE`: what a scene holds and what it costs — load time, build time and
//! tree statistics per build quality, bytes per triangle of the scene store and of the
//! acceleration structures, and the peak resident memory of the process.

use crate::say;
use crate::{CliError, InfoArgs, print_warnings};
use raypack::bvh::{BuildOptions, BuildQuality, Bvh8Stats, BvhStats, TreeLayout};
use raypack::io::LoadError;
use raypack::math::Aabb;
use raypack::scene::footprint::store_bytes;
use raypack::scene::{CommitReport, SceneBuilder, TrianglesSoa};
use raypack::simd::Isa;
use raypack::system::{PeakResident, peak_resident_bytes};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What [`scene_info`] does.
#[derive(Clone, Debug)]
pub struct InfoOptions {
    /// Build qualities to time, in order.
    pub qualities: Vec<BuildQuality>,
    /// Tree layouts to build at each quality, in order.
    pub layouts: Vec<TreeLayout>,
    /// The loader's limits.
    pub load: raypack::io::LoadOptions,
    /// Commit through the BVH cache in this directory ([`SceneBuilder::commit_cached`]).
    pub cache_dir: Option<PathBuf>,
    /// Check the structural invariants of both BVHs after each build.
    pub validate: bool,
    /// Keep the binary BVH after the collapse ([`BuildOptions::keep_bvh2`]) and report it.
    pub keep_bvh2: bool,
    /// Also build Embree's BVH (MEDIUM and HIGH) over the same triangles, on as many threads
    /// as the caller's rayon pool has (needs the `embree` feature).
    pub against_embree: bool,
    /// Build Embree's BVHs before raypack's instead of after them. The first builds of a
    /// process touch fresh memory, whose page faults (zeroing, and in a virtual machine the
    /// host's own faults) can cost a third of a 20M-triangle build; whichever tracer builds
    /// second reuses pages the first freed. Comparing each tracer's figures from the run in
    /// which it went first compares cold builds with cold builds.
    pub embree_first: bool,
    /// The ISA tier for raypack's kernels and the highest Embree may use (`None`: the
    /// process's default, [`Isa::default_for_process`], and Embree's own best).
    pub isa: Option<Isa>,
}

impl Default for InfoOptions {
    fn default() -> Self {
        Self {
            qualities: vec![BuildQuality::Fast, BuildQuality::Medium, BuildQuality::High],
            layouts: vec![TreeLayout::Default],
            load: raypack::io::LoadOptions::default(),
            cache_dir: None,
            validate: false,
            keep_bvh2: false,
            against_embree: false,
            embree_first: false,
            isa: None,
        }
    }
}

/// Figures of one build (or cache load) of the acceleration structures.
#[derive(Clone, Debug)]
pub struct BuildInfo {
    /// The quality asked for.
    pub quality: BuildQuality,
    /// The tree layout asked for.
    pub layout: TreeLayout,
    /// Wall-clock seconds of the commit (filtering, then building or loading from the cache).
    pub seconds: f64,
    /// True when the structures came from the BVH cache.
    pub from_cache: bool,
    /// Cache problems (rejected file, failed write), one line each; `raypack info` prints
    /// them on stderr.
    pub cache_warnings: Vec<String>,
    /// Statistics of the binary BVH, when the build kept it (`--keep-bvh2`).
    pub bvh2: Option<BvhStats>,
    /// Statistics of the 8-wide BVH the kernels traverse (with its bytes).
    pub bvh8: Bvh8Stats,
    /// Bytes of the binary BVH (nodes and primitive ids).
    pub bvh2_bytes: usize,
    /// The result of `--validate`: `None` when not asked for.
    pub valid: Option<Result<(), String>>,
    /// Peak resident memory the commit added to the process (see [`PeakResident`]).
    pub peak_added_bytes: Option<u64>,
    /// True when the streams trace incoherent packets as interleaved single rays (the BVH8
    /// is larger than the last-level cache, [`raypack::bvh::Bvh8::interleaves`]).
    pub interleaves: bool,
    /// True when the single-ray closest-hit query speculates its descents (a small BVH8,
    /// [`raypack::bvh::Bvh8::speculates`]).
    pub speculates: bool,
}

/// Figures of one Embree build over the same triangles (`raypack info --against embree`).
#[derive(Clone, Debug)]
pub struct EmbreeBuildInfo {
    /// `medium`, `high` or `compact` (MEDIUM with `RTC_SCENE_FLAG_COMPACT`).
    pub quality: &'static str,
    /// Wall-clock seconds of `rtcCommitScene`.
    pub seconds: f64,
    /// Bytes Embree holds for the BVH after the commit.
    pub bytes: u64,
    /// Peak resident memory the commit added to the process (see [`PeakResident`]).
    pub peak_added_bytes: Option<u64>,
}

/// Everything `raypack info` prints.
#[derive(Clone, Debug)]
pub struct SceneInfo {
    /// The scene file, or the built-in box's name.
    pub scene: String,
    /// Loader warnings.
    pub warnings: Vec<String>,
    /// Seconds to parse the file into a [`SceneBuilder`].
    pub load_seconds: f64,
    /// Primitives kept and dropped by the commit.
    pub report: CommitReport,
    /// Bounds of the kept geometry.
    pub bounds: Aabb,
    /// Materials, lights, and whether the file has a camera.
    pub materials: usize,
    /// Lights.
    pub lights: usize,
    /// True when the file sets a camera.
    pub has_camera: bool,
    /// Rayon threads the builds ran on.
    pub threads: usize,
    /// The ISA tier of raypack's kernels (and Embree's limit, with `against_embree`).
    pub isa: Isa,
    /// Bytes of the committed scene store (vertex positions and normals, indices, per-triangle
    /// materials, spheres).
    pub store_bytes: usize,
    /// One entry per quality.
    pub builds: Vec<BuildInfo>,
    /// Embree's builds of the same triangles (with `against_embree`).
    pub embree_builds: Vec<EmbreeBuildInfo>,
    /// Peak resident memory of the process at the end ([`peak_resident_bytes`]).
    pub peak_resident_bytes: Option<u64>,
}

/// Why [`scene_info`] failed.
#[derive(Debug, thiserror::Error)]
pub enum InfoError {
    /// The scene could not be loaded.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// Embree could not build the scene, or this build has no Embree.
    #[error("{0}")]
    Embree(String),
}

/// Loads `path` (the built-in Cornell box when `None`), commits it at each quality of `opts` (through the cache when asked) and
/// gathers the figures.
pub fn scene_info(path: Option<&Path>, opts: &InfoOptions) -> Result<SceneInfo, InfoError> {
    if opts.against_embree && !cfg!(feature = "embree") {
        return Err(InfoError::Embree(
            "--against embree: this raypack was built without Embree; rebuild with `cargo build --release --features embree` (needs Embree 3 or 4: libembree-dev on Debian, or RAYPACK_EMBREE_DIR; see the README)".into(),
        ));
    }
    let t = Instant::now();
    let (builder, warnings) = match path {
        Some(path) => {
            let loaded = raypack::io::load_scene_with_options(path, &opts.load)?;
            (loaded.builder, loaded.warnings)
        }
        None => (raypack::io::default_scene(), Vec::new()),
    };
    let load_seconds = t.elapsed().as_secs_f64();
    let mut info = SceneInfo {
        scene: path.map_or(crate::BUILT_IN_SCENE.to_string(), |p| p.display().to_string()),
        warnings,
        load_seconds,
        report: CommitReport::default(),
        bounds: Aabb::EMPTY,
        materials: 0,
        lights: 0,
        has_camera: false,
        threads: rayon::current_num_threads(),
        isa: opts.isa.unwrap_or_else(Isa::default_for_process),
        store_bytes: 0,
        builds: Vec::new(),
        embree_builds: Vec::new(),
        peak_resident_bytes: None,
    };
    if opts.against_embree && opts.embree_first {
        let (triangles, spheres) = builder.clone().into_kept_triangles();
        info.embree_builds = embree_builds(&triangles, spheres, opts.isa)?;
    }
    let mut builder = Some(builder);
    let builds: Vec<(BuildQuality, TreeLayout)> =
        opts.qualities.iter().flat_map(|&q| opts.layouts.iter().map(move |&l| (q, l))).collect();
    for (i, &(quality, layout)) in builds.iter().enumerate() {
        let last = i + 1 == builds.len();
        let b: SceneBuilder = if last { builder.take().expect("builder") } else { builder.clone().expect("builder") };
        let build_opts = BuildOptions { quality, keep_bvh2: opts.keep_bvh2, layout, ..BuildOptions::default() };
        let peak = PeakResident::start();
        let t = Instant::now();
        let (scene, report, cache) = match &opts.cache_dir {
            Some(dir) => {
                let (s, r, c) = b.commit_cached(&build_opts, dir);
                (s, r, Some(c))
            }
            None => {
                let (s, r) = b.commit(&build_opts);
                (s, r, None)
            }
        };
        let seconds = t.elapsed().as_secs_f64();
        let peak_added_bytes = peak.added();
        info.report = report;
        info.bounds = scene.bounds();
        info.materials = scene.materials.len();
        info.lights = scene.lights.len();
        info.has_camera = scene.camera.is_some();
        info.store_bytes = store_bytes(&scene);
        let valid = opts.validate.then(|| {
            let bounds: Vec<_> = (0..scene.num_prims() as u32).map(|p| scene.prim_bounds(p)).collect();
            scene
                .bvh2()
                .map_or(Ok(()), |b| raypack::bvh::validate::validate_bvh2(b, &bounds))
                .map_err(|e| format!("binary BVH: {e}"))
                .and_then(|()| raypack::bvh::validate::validate_bvh8(scene.bvh8(), &bounds))
                .map_err(|e| format!("8-wide BVH: {e}"))
        });
        info.builds.push(BuildInfo {
            quality,
            layout,
            seconds,
            from_cache: cache.as_ref().is_some_and(|c| c.loaded),
            cache_warnings: cache.map(|c| c.warnings()).unwrap_or_default(),
            bvh2: scene.bvh_stats(),
            bvh8: scene.bvh8().stats(),
            bvh2_bytes: scene.bvh2().map_or(0, |b| b.bytes()),
            valid,
            peak_added_bytes,
            interleaves: scene.interleaves(),
            speculates: scene.speculates(),
        });
        if last && opts.against_embree && !opts.embree_first {
            info.embree_builds = embree_builds(&scene.triangles, scene.num_spheres(), opts.isa)?;
        }
    }
    info.peak_resident_bytes = peak_resident_bytes();
    Ok(info)
}

/// Embree MEDIUM, HIGH and MEDIUM with `RTC_SCENE_FLAG_COMPACT` builds of a scene's triangles on the current rayon pool's thread
/// count; refused when the scene also has `spheres` (the Embree wrapper passes triangles only).
#[cfg(feature = "embree")]
fn embree_builds(
    triangles: &TrianglesSoa,
    spheres: usize,
    isa: Option<Isa>,
) -> Result<Vec<EmbreeBuildInfo>, InfoError> {
    use raypack::embree::{EmbreeError, EmbreeOptions, EmbreeQuality, EmbreeScene};
    if spheres > 0 {
        return Err(InfoError::Embree(EmbreeError::Spheres(spheres).to_string()));
    }
    let (positions, indices) = (&triangles.positions, &triangles.indices);
    let mut out = Vec::new();
    for (name, quality, compact) in [
        ("medium", EmbreeQuality::Medium, false),
        ("high", EmbreeQuality::High, false),
        ("compact", EmbreeQuality::Medium, true),
    ] {
        let threads = rayon::current_num_threads();
        let options = EmbreeOptions { quality, compact, threads, max_isa: isa, ..EmbreeOptions::default() };
        let peak = PeakResident::start();
        let e = EmbreeScene::from_mesh(positions, indices, options).map_err(|e| InfoError::Embree(e.to_string()))?;
        out.push(EmbreeBuildInfo {
            quality: name,
            seconds: e.build_time().as_secs_f64(),
            bytes: e.bvh_bytes(),
            peak_added_bytes: peak.added(),
        });
    }
    Ok(out)
}

#[cfg(not(feature = "embree"))]
fn embree_builds(_: &TrianglesSoa, _: usize, _: Option<Isa>) -> Result<Vec<EmbreeBuildInfo>, InfoError> {
    Ok(Vec::new())
}

fn mb(bytes: usize) -> String {
    format!("{:.1} MB", bytes as f64 / 1e6)
}

impl SceneInfo {
    fn per_triangle(&self, bytes: usize) -> f64 {
        bytes as f64 / self.report.triangles.max(1) as f64
    }

    /// The figures as text, one item per line.
    pub fn text(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let b = &self.bounds;
        let _ = writeln!(s, "scene        {}", self.scene);
        let _ = writeln!(s, "load         {:.4} s", self.load_seconds);
        let _ = writeln!(s, "primitives   {}", self.report);
        let _ = writeln!(
            s,
            "bounds       [{:.4}, {:.4}, {:.4}] .. [{:.4}, {:.4}, {:.4}]",
            b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z
        );
        let _ = writeln!(
            s,
            "materials    {}, lights {}, camera {}",
            self.materials,
            self.lights,
            if self.has_camera { "from file" } else { "framing (none in file)" }
        );
        let _ = writeln!(
            s,
            "scene store  {} ({:.1} bytes/triangle: positions, normals, indices, materials)",
            mb(self.store_bytes),
            self.per_triangle(self.store_bytes)
        );
        let _ = writeln!(s, "threads      {}", self.threads);
        let _ = writeln!(s, "isa          {} (the CPU's best: {})", self.isa, Isa::detected());
        for bi in &self.builds {
            let how = if bi.from_cache { "loaded from the BVH cache" } else { "built" };
            let name = match bi.layout {
                TreeLayout::Default => format!("build {}", bi.quality.name()),
                layout => format!("build {} {layout}", bi.quality.name()),
            };
            let _ = writeln!(s, "{name:<12} {:.4} s, {how}", bi.seconds);
            match &bi.bvh2 {
                Some(b) => {
                    let _ = writeln!(s, "  bvh2       {b}");
                }
                None => {
                    let _ = writeln!(s, "  bvh2       freed after the collapse (--keep-bvh2 keeps it)");
                }
            }
            let _ = writeln!(s, "  bvh8       {}", bi.bvh8);
            let _ = write!(
                s,
                "  memory     bvh8 {} ({:.1} bytes/triangle)",
                mb(bi.bvh8.bytes),
                self.per_triangle(bi.bvh8.bytes)
            );
            let _ = if bi.bvh2.is_some() {
                writeln!(s, " + bvh2 {} ({:.1} bytes/triangle)", mb(bi.bvh2_bytes), self.per_triangle(bi.bvh2_bytes))
            } else {
                writeln!(s)
            };
            let leaves = bi.bvh8.bytes - bi.bvh8.node_bytes;
            let _ = writeln!(
                s,
                "  layout     {}: nodes {:.1} + leaves {:.1} bytes/triangle (+ scene store {:.1})",
                bi.bvh8.layout,
                self.per_triangle(bi.bvh8.node_bytes),
                self.per_triangle(leaves),
                self.per_triangle(self.store_bytes)
            );
            if let Some(p) = bi.peak_added_bytes {
                let _ = writeln!(s, "  peak       +{} resident during the commit", mb(p as usize));
            }
            let llc = mb(raypack::system::last_level_cache_bytes() as usize);
            let _ = if bi.interleaves {
                writeln!(
                    s,
                    "  streams    incoherent packets as interleaved single rays (bvh8 larger than the {llc} last-level cache)"
                )
            } else {
                writeln!(s, "  streams    16-ray packets (bvh8 within the {llc} last-level cache)")
            };
            let most = mb(raypack::bvh::queries::SPECULATION_MAX_BYTES);
            let _ = if bi.speculates {
                writeln!(s, "  single     closest-hit descents speculated (bvh8 within {most})")
            } else {
                writeln!(s, "  single     closest-hit descents not speculated (bvh8 larger than {most})")
            };
            match &bi.valid {
                Some(Ok(())) => {
                    let _ = writeln!(s, "  validate   ok");
                }
                Some(Err(e)) => {
                    let _ = writeln!(s, "  validate   FAILED: {e}");
                }
                None => {}
            }
        }
        for e in &self.embree_builds {
            let _ = writeln!(
                s,
                "{:<12} {:.4} s, {} ({:.1} bytes/triangle), peak +{} resident",
                format!("embree {}", e.quality),
                e.seconds,
                mb(e.bytes as usize),
                self.per_triangle(e.bytes as usize),
                e.peak_added_bytes.map_or("n/a".to_string(), |b| mb(b as usize))
            );
        }
        let peak = self.peak_resident_bytes.map_or("n/a".to_string(), |b| mb(b as usize));
        let _ = writeln!(s, "peak memory  {peak} (resident, VmHWM; Linux only)");
        s
    }

    /// The figures as JSON.
    pub fn json(&self) -> serde_json::Value {
        let b = &self.bounds;
        let builds: Vec<_> = self
            .builds
            .iter()
            .map(|bi| {
                json!({
                    "quality": bi.quality.name(),
                    "layout": bi.bvh8.layout.name(),
                    "seconds": bi.seconds,
                    "from_cache": bi.from_cache,
                    "cache_warnings": bi.cache_warnings,
                    "bvh2": bi.bvh2.as_ref().map(|b2| json!({
                        "sah_cost": b2.sah_cost,
                        "inner_nodes": b2.inner_nodes,
                        "leaves": b2.leaves,
                        "mean_leaf_size": b2.mean_leaf_size,
                        "depth": b2.depth,
                        "bytes": bi.bvh2_bytes,
                        "bytes_per_triangle": self.per_triangle(bi.bvh2_bytes),
                    })),
                    "bvh8": {
                        "sah_cost": bi.bvh8.sah_cost,
                        "nodes": bi.bvh8.nodes,
                        "leaves": bi.bvh8.leaves,
                        "tri_blocks": bi.bvh8.tri_blocks,
                        "sphere_blocks": bi.bvh8.sphere_blocks,
                        "node_fill": bi.bvh8.node_fill,
                        "block_fill": bi.bvh8.block_fill,
                        "depth": bi.bvh8.depth,
                        "bytes": bi.bvh8.bytes,
                        "bytes_per_triangle": self.per_triangle(bi.bvh8.bytes),
                        "node_bytes": bi.bvh8.node_bytes,
                        "leaf_bytes": bi.bvh8.bytes - bi.bvh8.node_bytes,
                    },
                    "valid": bi.valid.as_ref().map(|v| v.clone().err().unwrap_or_else(|| "ok".into())),
                    "peak_added_bytes": bi.peak_added_bytes,
                    "streams_interleave": bi.interleaves,
                    "single_ray_speculates": bi.speculates,
                })
            })
            .collect();
        json!({
            "scene": self.scene,
            "load_seconds": self.load_seconds,
            "triangles": self.report.triangles,
            "spheres": self.report.spheres,
            "dropped": self.report.dropped(),
            "bounds": [[b.min.x, b.min.y, b.min.z], [b.max.x, b.max.y, b.max.z]],
            "materials": self.materials,
            "lights": self.lights,
            "threads": self.threads,
            "isa": self.isa.name(),
            "store_bytes": self.store_bytes,
            "store_bytes_per_triangle": self.per_triangle(self.store_bytes),
            "builds": builds,
            "embree_builds": self.embree_builds.iter().map(|e| json!({
                "quality": e.quality,
                "seconds": e.seconds,
                "bytes": e.bytes,
                "bytes_per_triangle": self.per_triangle(e.bytes as usize),
                "peak_added_bytes": e.peak_added_bytes,
            })).collect::<Vec<_>>(),
            "peak_resident_bytes": self.peak_resident_bytes,
        })
    }
}

/// `raypack info`: the figures of [`scene_info`] as text or JSON.
pub(crate) fn cmd_info(a: InfoArgs) -> Result<(), CliError> {
    crate::check_threads(a.threads)?;
    let mut opts = InfoOptions {
        load: raypack::io::LoadOptions { max_primitives: a.max_primitives, memory_cap: true },
        cache_dir: a.bvh_cache.clone(),
        validate: a.validate,
        keep_bvh2: a.keep_bvh2,
        against_embree: a.against.is_some(),
        embree_first: a.embree_first,
        isa: a.isa,
        ..InfoOptions::default()
    };
    if let Some(q) = a.quality {
        opts.qualities = vec![q];
    }
    if !a.layout.is_empty() {
        opts.layouts = a.layout.clone();
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .map_err(|e| CliError::Usage(e.to_string()))?;
    let info = pool.install(|| scene_info(a.scene_path(), &opts))?;
    print_warnings(&info.warnings);
    for w in info.builds.iter().flat_map(|b| &b.cache_warnings) {
        say::warning(w);
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
