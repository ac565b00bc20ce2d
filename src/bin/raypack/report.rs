//! `raypack report A.json B.json … --out DIR` (and `raypack bench … --report DIR`): a
//! self-contained benchmark report, `index.html` with the charts as inline SVG (no network,
//! no JavaScript) and the same charts as PNG files beside it.
//!
//! It reads the JSON `raypack bench --json` writes. The fields of schema 2 (machine, raypack
//! and Embree versions, date, summary) are optional: shown when present, "unknown"
//! otherwise; the raypack-best / Embree-best ratio is computed from "results".
//!
//! Text is laid out with a TrueType font read from the system (DejaVu Sans, Debian's
//! `fonts-dejavu-core`); without one the report is a clear error.

use crate::CliError;
use plotters::prelude::*;
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Where a sans-serif TrueType font is looked for.
const FONTS: [&str; 3] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

/// One result row of a bench JSON.
struct Row {
    rays: String,
    threads: u64,
    tracer: String,
    method: String,
    mrays: f64,
    /// Slowest and fastest run (schema 2), when the JSON has them.
    range: Option<(f64, f64)>,
}

/// One bench JSON.
struct Input {
    label: String,
    json: Value,
    rows: Vec<Row>,
}

fn text(v: &Value) -> String {
    match v {
        Value::Null => "unknown".into(),
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

fn read_input(path: &Path) -> Result<Input, CliError> {
    let bad = |m: String| CliError::Usage(format!("{}: {m}", path.display()));
    let bytes = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    let json: Value = serde_json::from_slice(&bytes).map_err(|e| bad(format!("not bench JSON: {e}")))?;
    let results = json["results"].as_array().ok_or_else(|| bad("no \"results\" array".into()))?;
    let mut rows = Vec::new();
    for (i, r) in results.iter().enumerate() {
        let field = |k: &str| r[k].as_str().map(str::to_owned).ok_or_else(|| bad(format!("results[{i}]: no \"{k}\"")));
        rows.push(Row {
            rays: field("rays")?,
            tracer: field("tracer")?,
            method: field("method")?,
            threads: r["threads"].as_u64().ok_or_else(|| bad(format!("results[{i}]: no \"threads\"")))?,
            mrays: r["mrays_per_s"].as_f64().ok_or_else(|| bad(format!("results[{i}]: no \"mrays_per_s\"")))?,
            range: r["mrays_per_s_min"].as_f64().zip(r["mrays_per_s_max"].as_f64()),
        });
    }
    let scene = json["scene"].as_str().map_or("unknown scene".into(), |s| {
        Path::new(s).file_name().map_or(s.to_owned(), |n| n.to_string_lossy().into_owned())
    });
    let commit = text(&json["raypack"]["commit"]);
    let label = format!("{scene} ({commit}, {})", path.file_stem().map_or("".into(), |s| s.to_string_lossy()));
    Ok(Input { label, json, rows })
}

/// The colour of series `i` of `n` in `family`: raypack's methods in blues, Embree's in
/// oranges, other series (one per input) from a categorical palette.
fn colour(family: Family, i: usize, n: usize) -> RGBColor {
    let c = match family {
        // Shades from the middle of the sequential maps: light enough to tell apart, dark
        // enough to see on white.
        Family::Raypack => colorous::BLUES.eval_rational(i + n / 2 + 2, n + n / 2 + 3),
        Family::Embree => colorous::ORANGES.eval_rational(i + n / 2 + 2, n + n / 2 + 3),
        Family::Input => colorous::TABLEAU10[i % colorous::TABLEAU10.len()],
    };
    RGBColor(c.r, c.g, c.b)
}

#[derive(Clone, Copy, PartialEq)]
enum Family {
    Raypack,
    Embree,
    Input,
}

/// One bar per group: its name, colour family, and per group the value and the spread
/// (slowest and fastest run) drawn as a whisker.
struct Series {
    name: String,
    family: Family,
    values: Vec<Option<f64>>,
    ranges: Vec<Option<(f64, f64)>>,
}

/// A grouped bar chart: `groups` along x, one bar per series in each.
struct Bars {
    title: String,
    y_label: String,
    groups: Vec<String>,
    series: Vec<Series>,
    /// A horizontal reference line (the ratio chart's 1.0).
    line: Option<f64>,
}

/// Width of the legend column beside the plot, in pixels.
const LEGEND_WIDTH: u32 = 320;
/// Height of one legend entry, in pixels.
const LEGEND_ROW: u32 = 15;

/// The chart's size in pixels: 960 wide plus the legend column, tall enough for the legend.
fn chart_size(b: &Bars) -> (u32, u32) {
    (960 + LEGEND_WIDTH, 420.max(60 + LEGEND_ROW * b.series.len() as u32))
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, plotters::coord::Shift>, b: &Bars) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |x: &dyn std::fmt::Display| x.to_string();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let (w, _) = root.dim_in_pixel();
    let (plot, legend) = root.split_horizontally(w - LEGEND_WIDTH);
    let top = b.series.iter().flat_map(|s| s.values.iter().zip(&s.ranges)).filter_map(|(v, r)| match (v, r) {
        (_, Some((_, hi))) => Some(*hi),
        (Some(v), None) => Some(*v),
        _ => None,
    });
    let max = top.fold(b.line.unwrap_or(0.0), f64::max);
    let n = b.groups.len().max(1) as f64;
    let mut chart = ChartBuilder::on(&plot)
        .caption(&b.title, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(10)
        .y_label_area_size(60)
        .build_cartesian_2d(-0.5..n - 0.5, 0.0..max * 1.15 + 1e-9)
        .map_err(|x| e(&x))?;
    chart.configure_mesh().disable_x_mesh().disable_x_axis().y_desc(&b.y_label).draw().map_err(|x| e(&x))?;
    let k = b.series.len().max(1) as f64;
    let bw = 0.8 / k;
    let count = |f: Family| b.series.iter().filter(|s| s.family == f).count();
    let mut index = [0usize; 3];
    let mut colours = Vec::new();
    for (si, s) in b.series.iter().enumerate() {
        let i = &mut index[s.family as usize];
        let c = colour(s.family, *i, count(s.family));
        *i += 1;
        colours.push(c);
        let x0 = |gi: usize| gi as f64 - 0.4 + si as f64 * bw;
        chart
            .draw_series(
                s.values.iter().enumerate().filter_map(|(gi, v)| {
                    v.map(|v| Rectangle::new([(x0(gi), 0.0), (x0(gi) + bw * 0.9, v)], c.filled()))
                }),
            )
            .map_err(|x| e(&x))?;
        chart
            .draw_series(s.ranges.iter().enumerate().filter_map(|(gi, r)| {
                let xm = x0(gi) + bw * 0.45;
                r.map(|(lo, hi)| PathElement::new(vec![(xm, lo), (xm, hi)], BLACK.stroke_width(1)))
            }))
            .map_err(|x| e(&x))?;
    }
    if let Some(l) = b.line {
        chart.draw_series(LineSeries::new([(-0.5, l), (n - 0.5, l)], BLACK.stroke_width(2))).map_err(|x| e(&x))?;
    }
    chart
        .draw_series(
            b.groups
                .iter()
                .enumerate()
                .map(|(gi, g)| Text::new(g.clone(), (gi as f64 - 0.1, max * 1.1), ("sans-serif", 14))),
        )
        .map_err(|x| e(&x))?;
    // The legend: its own column, so that it never hides a bar.
    let y0 = 40;
    for (si, (s, c)) in b.series.iter().zip(&colours).enumerate() {
        let y = y0 + si as i32 * LEGEND_ROW as i32;
        legend.draw(&Rectangle::new([(6, y), (18, y + 10)], c.filled())).map_err(|x| e(&x))?;
        legend.draw(&Text::new(s.name.clone(), (24, y - 1), ("sans-serif", 12))).map_err(|x| e(&x))?;
    }
    if b.series.iter().any(|s| s.ranges.iter().any(Option::is_some)) {
        let y = y0 + b.series.len() as i32 * LEGEND_ROW as i32 + 6;
        legend.draw(&PathElement::new(vec![(12, y), (12, y + 12)], BLACK.stroke_width(1))).map_err(|x| e(&x))?;
        legend
            .draw(&Text::new("slowest to fastest run".to_string(), (24, y), ("sans-serif", 12)))
            .map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))
}

/// The charts of `inputs`: Mrays/s per input and thread count, the ratio, the builds.
fn charts(inputs: &[Input]) -> Vec<Bars> {
    let mut out = Vec::new();
    for inp in inputs {
        let mut threads: Vec<u64> = inp.rows.iter().map(|r| r.threads).collect();
        threads.sort();
        threads.dedup();
        for t in threads {
            let rows: Vec<&Row> = inp.rows.iter().filter(|r| r.threads == t).collect();
            let mut groups: Vec<String> = Vec::new();
            let mut names: Vec<String> = Vec::new();
            for r in &rows {
                if !groups.contains(&r.rays) {
                    groups.push(r.rays.clone());
                }
                let n = format!("{}: {}", r.tracer, r.method);
                if !names.contains(&n) {
                    names.push(n);
                }
            }
            let series = names
                .iter()
                .map(|n| {
                    let row =
                        |g: &String| rows.iter().find(|r| &r.rays == g && &format!("{}: {}", r.tracer, r.method) == n);
                    let family = if n.starts_with("embree") { Family::Embree } else { Family::Raypack };
                    Series {
                        name: n.clone(),
                        family,
                        values: groups.iter().map(|g| row(g).map(|r| r.mrays)).collect(),
                        ranges: groups.iter().map(|g| row(g).and_then(|r| r.range)).collect(),
                    }
                })
                .collect();
            let isa = text(&inp.json["raypack"]["isa"]);
            out.push(Bars {
                title: format!("{} — {t} thread(s), ISA {isa}", inp.label),
                y_label: "Mrays/s".into(),
                groups,
                series,
                line: None,
            });
        }
    }
    // The ratio raypack-best / Embree-best per ray set and thread count, one series per input.
    let mut groups: Vec<String> = Vec::new();
    for inp in inputs {
        for r in &inp.rows {
            let g = format!("{} {}t", r.rays, r.threads);
            if !groups.contains(&g) {
                groups.push(g);
            }
        }
    }
    let best = |inp: &Input, g: &str, tracer: &str| {
        inp.rows
            .iter()
            .filter(|r| format!("{} {}t", r.rays, r.threads) == g && (r.tracer == "embree") == (tracer == "embree"))
            .map(|r| r.mrays)
            .fold(None, |a: Option<f64>, x| Some(a.map_or(x, |a| a.max(x))))
    };
    // The spread is the bench summary's (raypack's slowest run over Embree's fastest, and its
    // fastest over Embree's slowest), when the JSON has one.
    let spread = |inp: &Input, g: &str| {
        inp.json["summary"].as_array()?.iter().find_map(|s| {
            let name = format!("{} {}t", s["rays"].as_str()?, s["threads"].as_u64()?);
            (name == g).then(|| s["ratio_min"].as_f64().zip(s["ratio_max"].as_f64())).flatten()
        })
    };
    let series: Vec<Series> = inputs
        .iter()
        .map(|inp| Series {
            name: inp.label.clone(),
            family: Family::Input,
            values: groups
                .iter()
                .map(|g| match (best(inp, g, "raypack"), best(inp, g, "embree")) {
                    (Some(a), Some(b)) if b > 0.0 => Some(a / b),
                    _ => None,
                })
                .collect(),
            ranges: groups.iter().map(|g| spread(inp, g)).collect(),
        })
        .collect();
    out.push(Bars {
        title: "best raypack / best Embree (1.0: as fast)".into(),
        y_label: "ratio".into(),
        groups,
        series,
        line: Some(1.0),
    });
    // Build time and bytes per triangle.
    for (what, key) in [("build time (s)", "seconds"), ("bytes per triangle", "bytes_per_triangle")] {
        let mut groups: Vec<String> = Vec::new();
        for inp in inputs {
            if let Some(b) = inp.json["build"].as_object() {
                for k in b.keys() {
                    if !groups.contains(k) {
                        groups.push(k.clone());
                    }
                }
            }
        }
        let series = inputs
            .iter()
            .map(|inp| Series {
                name: inp.label.clone(),
                family: Family::Input,
                values: groups.iter().map(|g| inp.json["build"][g][key].as_f64()).collect(),
                ranges: vec![None; groups.len()],
            })
            .collect();
        out.push(Bars { title: what.into(), y_label: what.into(), groups, series, line: None });
    }
    out
}

fn register_font() -> Result<(), CliError> {
    let bytes = FONTS.iter().find_map(|p| std::fs::read(p).ok()).ok_or_else(|| {
        CliError::Usage(format!(
            "the report needs a TrueType font to lay out its text: none of {FONTS:?} exists (Debian: apt-get install fonts-dejavu-core)"
        ))
    })?;
    let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
        .map_err(|_| CliError::Usage("the system font could not be read".into()))
}

/// Writes the report of the bench JSON files `inputs` into `out`.
pub(crate) fn write_report(inputs: &[PathBuf], out: &Path) -> Result<(), CliError> {
    if inputs.is_empty() {
        return Err(CliError::Usage("raypack report: give at least one bench JSON file".into()));
    }
    let inputs: Vec<Input> = inputs.iter().map(|p| read_input(p)).collect::<Result<_, _>>()?;
    register_font()?;
    std::fs::create_dir_all(out).map_err(|e| CliError::Usage(format!("{}: {e}", out.display())))?;
    let mut html = String::from(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>raypack benchmark report</title>\
         <style>body{font-family:sans-serif;max-width:1300px;margin:auto}td,th{padding:2px 8px;text-align:left}</style>\
         </head><body>\n<h1>raypack benchmark report</h1>\n",
    );
    for inp in &inputs {
        let j = &inp.json;
        let m = &j["machine"];
        let flags = m["cpu_flags"].as_array().map(|a| a.iter().map(text).collect::<Vec<_>>().join(" "));
        let _ = writeln!(
            html,
            "<h2>{}</h2><table>\
             <tr><th>scene</th><td>{}</td></tr><tr><th>triangles</th><td>{}</td></tr>\
             <tr><th>CPU</th><td>{}</td></tr><tr><th>ISA flags</th><td>{}</td></tr>\
             <tr><th>threads</th><td>{}</td></tr><tr><th>memory (bytes)</th><td>{}</td></tr>\
             <tr><th>raypack</th><td>version {}, commit {}, ISA {}</td></tr>\
             <tr><th>Embree</th><td>{}</td></tr><tr><th>date</th><td>{}</td></tr>\
             <tr><th>ray sets</th><td>{}</td></tr><tr><th>notes</th><td>{}</td></tr></table>",
            esc(&inp.label),
            esc(&text(&j["scene"])),
            text(&j["triangles"]),
            esc(&text(&m["cpu"])),
            esc(&flags.unwrap_or_else(|| "unknown".into())),
            text(&m["logical_cpus"]),
            text(&m["memory_bytes"]),
            esc(&text(&j["raypack"]["version"])),
            esc(&text(&j["raypack"]["commit"])),
            esc(&text(&j["raypack"]["isa"])),
            esc(&if j["embree"].is_object() {
                format!("{} (ISA {})", text(&j["embree"]["version"]), text(&j["embree"]["isa"]))
            } else {
                "unknown".into()
            }),
            esc(&text(&j["date"])),
            esc(&ray_sets(&inp.rows, &j["resolution"])),
            esc(&j["notes"].as_array().map_or("".into(), |a| a.iter().map(text).collect::<Vec<_>>().join("; "))),
        );
        html.push_str(&summary_table(j));
    }
    for (i, chart) in charts(&inputs).iter().enumerate() {
        let mut svg = String::new();
        let size = chart_size(chart);
        draw(SVGBackend::with_string(&mut svg, size).into_drawing_area(), chart).map_err(CliError::Usage)?;
        let png = out.join(format!("chart{i}.png"));
        draw(BitMapBackend::new(&png, size).into_drawing_area(), chart)
            .map_err(|m| CliError::Usage(format!("{}: {m}", png.display())))?;
        let _ = write!(html, "<h3>{}</h3>\n{svg}\n<p><a href=\"chart{i}.png\">PNG</a></p>\n", esc(&chart.title));
    }
    html.push_str("</body></html>\n");
    raypack::io::output::write_file(&out.join("index.html"), html.as_bytes())?;
    Ok(())
}

/// The bench summary (schema 2) as a table: per ray set and thread count, the best raypack
/// method and the best Embree call, their ratio and its spread; with the load line's warning
/// when the machine was busy. Empty for a JSON without a summary.
fn summary_table(j: &Value) -> String {
    let Some(rows) = j["summary"].as_array() else { return String::new() };
    let mut t = String::from(
        "<table><tr><th>rays</th><th>threads</th><th>best raypack</th><th>Mrays/s</th>\
         <th>best Embree</th><th>Mrays/s</th><th>ratio</th><th>ratio min–max</th></tr>\n",
    );
    let num = |v: &Value, digits: usize| v.as_f64().map_or("–".into(), |x| format!("{x:.digits$}"));
    for r in rows {
        let _ = writeln!(
            t,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}–{}</td></tr>",
            esc(&text(&r["rays"])),
            text(&r["threads"]),
            esc(&text(&r["raypack_method"])),
            num(&r["raypack_mrays_per_s"], 2),
            esc(&r["embree_method"].as_str().map_or("–".into(), str::to_owned)),
            num(&r["embree_mrays_per_s"], 2),
            num(&r["ratio"], 2),
            num(&r["ratio_min"], 2),
            num(&r["ratio_max"], 2),
        );
    }
    t.push_str("</table>\n");
    if j["busy"].as_bool() == Some(true) {
        let _ = writeln!(
            t,
            "<p><b>The machine was busy during this run</b> (load average {} before, {} after): the figures may be off.</p>",
            text(&j["load_average"]["before"]),
            text(&j["load_average"]["after"])
        );
    }
    t
}

fn ray_sets(rows: &[Row], resolution: &Value) -> String {
    let mut sets: Vec<&str> = rows.iter().map(|r| r.rays.as_str()).collect();
    sets.dedup();
    let mut seen = Vec::new();
    for s in sets {
        if !seen.contains(&s) {
            seen.push(s);
        }
    }
    format!("{} (primary resolution {})", seen.join(", "), text(resolution))
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}
