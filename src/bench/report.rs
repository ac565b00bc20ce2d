//! A bench run's report: the summary, the text and table `raypack bench` prints, and the
//! JSON document it writes.

use super::{BenchReport, BenchRow, HIT_TOLERANCE, SummaryRow};
use crate::raysets;

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
    pub(super) fn build_line(&self) -> Option<String> {
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
