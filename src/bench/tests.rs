//! The bench run and its report, on small scenes.

use super::*;
use crate::generate::uv_sphere;
use crate::kernels::KERNELS;
use crate::{BuildOptions, BuildQuality, Material, SceneBuilder};

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
