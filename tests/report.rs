//! `raypack report`: the report of bench JSON files (today's fields only, and one with the
//! schema-2 fields) is well-formed — every inline SVG parses — and every result of the JSON
//! appears in a chart (its ray set and its method as SVG text), with a PNG per chart.

use std::process::Command;

fn result(rays: &str, tracer: &str, method: &str, threads: u64, mrays: f64) -> serde_json::Value {
    serde_json::json!({"rays": rays, "ray_count": 1000, "tracer": tracer, "method": method, "threads": threads,
        "mrays_per_s": mrays, "hits": 10, "t_sum": 1.5})
}

#[test]
fn report_svgs_parse_and_show_every_result() {
    if !std::path::Path::new("/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf").exists() {
        eprintln!(
            "SKIPPED report_svgs_parse_and_show_every_result: no DejaVu Sans (apt-get install fonts-dejavu-core)"
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let results = vec![
        result("primary", "raypack", "Scene::intersect_stream", 1, 20.0),
        result("primary", "embree", "rtcIntersect8 (medium)", 1, 18.0),
        result("shadow", "raypack", "Scene::occluded_stream", 2, 30.0),
        result("shadow", "embree", "rtcOccluded16 (high)", 2, 33.0),
    ];
    let old = serde_json::json!({"scene": "a.dae", "triangles": 12, "resolution": [64, 48], "runs": 3, "notes": [],
        "build": {"raypack bvh8": {"tracer": "raypack", "quality": "bvh8", "seconds": 0.1, "bytes": 100, "bytes_per_triangle": 8.3}},
        "results": results});
    let mut new = old.clone();
    new["schema"] = 2.into();
    new["machine"] =
        serde_json::json!({"cpu": "Test CPU 9000", "cpu_flags": ["avx2"], "logical_cpus": 2, "memory_bytes": 1});
    new["raypack"] = serde_json::json!({"version": "0.1.0", "commit": "abc1234", "isa": "avx2"});
    new["summary"] = serde_json::json!([{"rays": "primary", "threads": 1, "raypack_method": "Scene::intersect_stream",
        "raypack_mrays_per_s": 20.0, "embree_method": "rtcIntersect8 (medium)", "embree_mrays_per_s": 18.0,
        "ratio": 1.111, "ratio_min": 0.987, "ratio_max": 1.234}]);
    new["busy"] = true.into();
    new["busy_reason"] = "other processes used 40% of the CPU time during the run".into();
    new["load_average"] = serde_json::json!({"before": [1.9, 1.0, 0.5], "after": [2.1, 1.1, 0.6]});
    let (a, b) = (dir.path().join("old.json"), dir.path().join("new.json"));
    std::fs::write(&a, old.to_string()).unwrap();
    std::fs::write(&b, new.to_string()).unwrap();
    let out = dir.path().join("report");
    let o = Command::new(env!("CARGO_BIN_EXE_raypack"))
        .args(["report", a.to_str().unwrap(), b.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(html.contains("Test CPU 9000") && html.contains("abc1234") && html.contains("unknown"));
    // The summary of the schema-2 JSON is a table, with its spread and the busy warning.
    assert!(html.contains("<td>1.11</td><td>0.99–1.23</td>"), "{html}");
    assert!(html.contains("was busy during this run</b> (other processes used 40%"), "{html}");
    let mut texts = Vec::new();
    let mut svgs = 0;
    for (start, _) in html.match_indices("<svg") {
        let end = start + html[start..].find("</svg>").unwrap() + "</svg>".len();
        let doc = roxmltree::Document::parse(&html[start..end]).expect("the SVG parses");
        texts.extend(doc.descendants().filter_map(|n| n.text()).map(str::to_owned));
        svgs += 1;
    }
    // A chart per ray set (each with a panel per input and thread count), the ratio, build
    // time and size; each as a PNG named for what it shows, linked under its SVG.
    assert_eq!(svgs, 2 + 3);
    let pngs: Vec<&str> = html.split("<a href=\"").skip(1).map(|r| &r[..r.find('"').unwrap()]).collect();
    assert_eq!(pngs, ["rays-primary.png", "rays-shadow.png", "ratio.png", "build-time.png", "build-bytes.png"]);
    for png in &pngs {
        assert!(out.join(png).exists(), "{png}");
    }
    let all = texts.join("\n");
    for r in old["results"].as_array().unwrap() {
        for key in ["rays", "method"] {
            let want = r[key].as_str().unwrap();
            assert!(all.contains(want), "{want} is in no chart: {all}");
        }
    }
    // The ratio chart has a bar of 20/18 and one of 30/33 per input: its labels say 1.0.
    assert!(all.contains("ratio"));
}
