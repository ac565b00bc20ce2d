//! `raypack report` and `bench --report/--rays` against a hostile directory and hostile
//! JSON: links and FIFOs planted at the files they write, FIFOs and `/dev/zero` at the files
//! they read, fields of the wrong type or carrying HTML, and more series than a chart can show.
//! Nothing outside the named files may be written, nothing may hang or read without end, and
//! nothing from a JSON may reach the HTML unescaped.

mod common;

use common::child::{expect, is_fifo, mkfifo, run, s};
use std::path::{Path, PathBuf};

const FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

fn have_font(test: &str) -> bool {
    let ok = Path::new(FONT).exists();
    if !ok {
        eprintln!("SKIPPED {test}: no DejaVu Sans (apt-get install fonts-dejavu-core)");
    }
    ok
}

/// A bench JSON of schema 2 with `methods` raypack methods on one ray set at one thread,
/// method `i` at `i + 1` Mrays/s.
fn bench_json(methods: usize) -> serde_json::Value {
    let results: Vec<_> = (0..methods)
        .map(|i| {
            serde_json::json!({"rays": "primary", "ray_count": 1000, "tracer": "raypack", "method": format!("m{i}"),
                "threads": 1, "mrays_per_s": (i + 1) as f64, "hits": 10, "t_sum": 1.5})
        })
        .collect();
    serde_json::json!({"schema": 2, "scene": "a.dae", "triangles": 12, "resolution": [64, 48], "runs": 3,
        "notes": ["a note"], "date": "2024-01-01",
        "machine": {"cpu": "Test CPU", "cpu_flags": ["avx2"], "logical_cpus": 2, "memory_bytes": 1024},
        "raypack": {"version": "0.1.0", "commit": "abc1234", "isa": "avx2"},
        "load_average": {"before": [1.0, 1.0, 1.0], "after": [2.0, 1.0, 1.0]}, "busy": true,
        "build": {"raypack bvh8": {"seconds": 0.1, "bytes_per_triangle": 8.3}},
        "summary": [{"rays": "primary", "threads": 1, "raypack_method": "m0", "raypack_mrays_per_s": 1.0,
            "embree_method": null, "embree_mrays_per_s": null, "ratio": null, "ratio_min": null, "ratio_max": null}],
        "results": results})
}

fn write_json(dir: &Path, name: &str, v: &serde_json::Value) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, v.to_string()).unwrap();
    p
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn report_charts_never_go_through_links_or_into_fifos() {
    let dir = tempfile::tempdir().unwrap();
    let json = write_json(dir.path(), "b.json", &bench_json(3));
    let victim = dir.path().join("victim");
    std::fs::write(&victim, b"precious").unwrap();
    // A link planted at the first chart: refused, nothing written, the victim intact.
    let out = dir.path().join("rep");
    std::fs::create_dir(&out).unwrap();
    std::os::unix::fs::symlink(&victim, out.join("rays-primary.png")).unwrap();
    expect(&["report", s(&json), "--out", s(&out)], 2, "rays-primary.png: is a symbolic link");
    assert_eq!(std::fs::read(&victim).unwrap(), b"precious", "written through the planted link");
    assert_eq!(names(&out), ["rays-primary.png"], "a report written in part");
    // A FIFO at a chart: refused at once (no reader would ever come), and left as it was.
    let out = dir.path().join("rep2");
    std::fs::create_dir(&out).unwrap();
    mkfifo(&out.join("ratio.png"));
    expect(&["report", s(&json), "--out", s(&out)], 2, "ratio.png: is a FIFO");
    assert!(is_fifo(&out.join("ratio.png")));
    assert_eq!(names(&out), ["ratio.png"], "a report written in part");
    // A clean directory gets the whole report and no temporary files.
    if have_font("report_charts_never_go_through_links_or_into_fifos") {
        let out = dir.path().join("rep3");
        let r = run(&["report", s(&json), "--out", s(&out)]);
        assert_eq!(r.code, Some(0), "{r:?}");
        assert_eq!(names(&out), ["build-bytes.png", "build-time.png", "index.html", "ratio.png", "rays-primary.png"]);
    }
}

#[test]
fn bench_report_directory_is_checked_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let bench = |report: &Path| {
        let args = ["bench", "-r", "16", "12", "--runs", "1", "--build-runs", "1", "-t", "1", "--methods", "stream"];
        run(&[&args[..], &["--report", s(report)]].concat())
    };
    // Before the fix each failed after the whole run, whose table went to stdout.
    let file = dir.path().join("afile");
    std::fs::write(&file, b"x").unwrap();
    let r = bench(&file);
    assert_eq!(r.code, Some(2), "{r:?}");
    assert!(r.stderr.contains("report directory") && r.stderr.contains("not a directory"), "{}", r.stderr);
    assert!(r.stdout.is_empty() && !r.stderr.contains("Mrays/s"), "ran before refusing: {r:?}");
    let victim = dir.path().join("victim");
    std::fs::write(&victim, b"precious").unwrap();
    for planted in ["rays-primary.png", "index.html", "bench.json"] {
        let out = dir.path().join(format!("rep-{planted}"));
        std::fs::create_dir(&out).unwrap();
        std::os::unix::fs::symlink(&victim, out.join(planted)).unwrap();
        let r = bench(&out);
        assert_eq!(r.code, Some(2), "{planted}: {r:?}");
        assert!(r.stderr.contains("symbolic link"), "{planted}: {}", r.stderr);
        assert!(r.stdout.is_empty() && !r.stderr.contains("Mrays/s"), "{planted}: ran before refusing: {r:?}");
        assert_eq!(std::fs::read(&victim).unwrap(), b"precious", "{planted}: written through the link");
        assert_eq!(names(&out), [planted]);
    }
}

#[test]
fn report_and_rays_inputs_go_through_the_guarded_reader() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("rep");
    let fifo_json = d.join("fifo.json");
    mkfifo(&fifo_json);
    let zero_json = d.join("zero.json");
    std::os::unix::fs::symlink("/dev/zero", &zero_json).unwrap();
    expect(&["report", s(&fifo_json), "--out", s(&out)], 2, "is a FIFO (named pipe), not a regular file");
    expect(&["report", s(&zero_json), "--out", s(&out)], 2, "is a character device, not a regular file");
    let fifo_rays = d.join("fifo.rays");
    mkfifo(&fifo_rays);
    let zero_rays = d.join("zero.npy");
    std::os::unix::fs::symlink("/dev/zero", &zero_rays).unwrap();
    for rays in [&fifo_rays, &zero_rays] {
        let r = run(&["bench", "-r", "16", "12", "--runs", "1", "-t", "1", "--methods", "stream", "--rays", s(rays)]);
        assert!(!r.timed_out && r.code == Some(2), "{rays:?}: {r:?}");
        assert!(r.stderr.contains("not a regular file") && r.stderr.contains(s(rays)), "{}", r.stderr);
    }
    // A bench JSON over the size limit is refused before it is parsed.
    let big = d.join("big.json");
    let f = std::fs::File::create(&big).unwrap();
    f.set_len(raypack::fs::input::MAX_BENCH_JSON_BYTES + 1).unwrap();
    expect(&["report", s(&big), "--out", s(&out)], 2, "more than the 67108864-byte limit for bench JSON files");
}

#[test]
fn report_fields_are_typed_on_read_and_escaped_when_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rep");
    // The fields that were written into the HTML unchecked: a string where a number belongs.
    type Edit = fn(&mut serde_json::Value);
    let cases: [(&str, Edit); 9] = [
        ("triangles", |j| j["triangles"] = "<script>t</script>".into()),
        ("machine.logical_cpus", |j| j["machine"]["logical_cpus"] = "<script>c</script>".into()),
        ("machine.memory_bytes", |j| j["machine"]["memory_bytes"] = "<img src=x onerror=alert(1)>".into()),
        ("summary[0].threads", |j| j["summary"][0]["threads"] = "<script>s</script>".into()),
        ("load_average.before", |j| j["load_average"]["before"] = "<script>l</script>".into()),
        ("load_average.after[1]", |j| j["load_average"]["after"][1] = "<script>l</script>".into()),
        ("results[2].mrays_per_s", |j| j["results"][2]["mrays_per_s"] = "fast".into()),
        ("raypack.commit", |j| j["raypack"]["commit"] = serde_json::json!({"x": 1})),
        ("busy_reason", |j| j["busy_reason"] = serde_json::json!([1])),
    ];
    for (field, set) in cases {
        let mut j = bench_json(3);
        set(&mut j);
        let p = write_json(dir.path(), "bad.json", &j);
        expect(&["report", s(&p), "--out", s(&out)], 2, &format!("bad.json: {field}: expected"));
        assert!(!out.join("index.html").exists(), "{field}: a report was written");
    }
    if !have_font("report_fields_are_typed_on_read_and_escaped_when_written") {
        return;
    }
    // Strings are strings: shown, but escaped, in the HTML and in the SVG.
    let mut j = bench_json(3);
    j["scene"] = "\"><script>scene</script>".into();
    j["machine"]["cpu"] = "<script>cpu</script>".into();
    j["notes"] = serde_json::json!(["<script>note</script>"]);
    j["raypack"]["isa"] = "<b>isa</b>".into();
    j["results"][0]["method"] = "<script>method</script>".into();
    j["results"][1]["rays"] = "<script>rays</script>".into();
    j["summary"][0]["raypack_method"] = "<script>best</script>".into();
    j["busy"] = true.into();
    j["busy_reason"] = "<script>busy</script>".into();
    let p = write_json(dir.path(), "evil.json", &j);
    let r = run(&["report", s(&p), "--out", s(&out)]);
    assert_eq!(r.code, Some(0), "{r:?}");
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(!html.contains("<script") && !html.contains("<b>isa"), "unescaped markup in the report");
    for shown in [
        "&lt;script&gt;cpu",
        "&lt;script&gt;note",
        "&lt;script&gt;scene",
        "&lt;script&gt;best",
        "&lt;b&gt;isa",
        "&lt;script&gt;busy",
    ] {
        assert!(html.contains(shown), "{shown} is not shown");
    }
    // Every SVG still parses, with the method name as text.
    let mut texts = String::new();
    for (start, _) in html.match_indices("<svg") {
        let end = start + html[start..].find("</svg>").unwrap() + "</svg>".len();
        let doc = roxmltree::Document::parse(&html[start..end]).expect("the SVG parses");
        doc.descendants().filter(|n| n.is_text()).filter_map(|n| n.text()).for_each(|t| texts += t);
    }
    assert!(texts.contains("<script>method</script>") && texts.contains("<script>rays</script>"), "{texts}");
}

#[test]
fn many_series_are_linear_and_a_chart_shows_the_fastest() {
    if !have_font("many_series_are_linear_and_a_chart_shows_the_fastest") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // 10,000 methods: the report's time must stay linear in them (no name search per series
    // and per cell) and its legend bounded (not one entry per method).
    let p = write_json(dir.path(), "many.json", &bench_json(10_000));
    let out = dir.path().join("rep");
    let r = run(&["report", s(&p), "--out", s(&out)]);
    assert_eq!(r.code, Some(0), "{r:?}");
    assert!(r.peak_bytes < 200 << 20, "peak resident memory {} MB", r.peak_bytes >> 20);
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    let start = html.find("<svg").unwrap();
    let end = start + html[start..].find("</svg>").unwrap();
    let doc = roxmltree::Document::parse(&html[start..end + 6]).unwrap();
    let texts: Vec<&str> = doc.descendants().filter(|n| n.is_text()).filter_map(|n| n.text()).map(str::trim).collect();
    // The 48 fastest methods are drawn (m9952 .. m9999 at 9953 .. 10000 Mrays/s), the rest
    // counted with the fastest of them.
    let mut drawn: Vec<&str> =
        texts.iter().copied().filter(|t| t.starts_with('m') && t[1..].bytes().all(|b| b.is_ascii_digit())).collect();
    drawn.sort();
    let want: Vec<String> = (9952..10_000).map(|i| format!("m{i}")).collect();
    assert_eq!(drawn, want);
    assert!(texts.contains(&"and 9952 slower methods, at most 9952.000 (not drawn)"), "{texts:?}");
}
