//! `raypack report A.json B.json … --out DIR` (and `raypack bench … --report DIR`): a
//! self-contained benchmark report, `index.html` with the charts as inline SVG (no network,
//! no JavaScript) and the same charts as PNG files beside it.
//!
//! It reads the JSON `raypack bench --json` writes, each field checked for its type
//! ([`input`]). The fields of schema 2 (machine, raypack and Embree versions, date, summary)
//! are optional: shown when present, "unknown" otherwise; the raypack-best / Embree-best
//! ratio is computed from "results". Every text from a JSON is escaped in the HTML (and by
//! plotters in the SVG).
//!
//! Charts are drawn in memory and written with `index.html` through [`raypack::fs::output`],
//! all or nothing: never through a link or into a FIFO planted in the directory. Building them
//! is linear in the results; a chart shows at most [`MAX_SERIES`] bars per group (the fastest
//! series, the others counted in its legend), and a report of more groups or charts than can
//! be read is an error.
//!
//! Text is laid out with a TrueType font read from the system (DejaVu Sans, Debian's
//! `fonts-dejavu-core`); without one the report is a clear error.

mod input;

use crate::CliError;
use input::{Input, Row, read_input};
use plotters::prelude::*;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Where a sans-serif TrueType font is looked for.
const FONTS: [&str; 3] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

/// Most bars per group of one chart: the fastest series are drawn, the others counted in the
/// legend (beyond this many, bars a few pixels wide cannot be told apart).
pub(crate) const MAX_SERIES: usize = 24;
/// Most groups along one chart's x axis (ray sets, or ray sets × thread counts).
const MAX_GROUPS: usize = 32;
/// Most charts of one report.
const MAX_CHARTS: usize = 64;

/// A value for the HTML: the text, or "unknown".
fn shown<T: std::fmt::Display>(v: &Option<T>) -> String {
    v.as_ref().map_or_else(|| "unknown".into(), |x| x.to_string())
}

fn numbers(v: &Option<Vec<f64>>) -> String {
    v.as_ref().map_or_else(|| "unknown".into(), |a| format!("{a:?}"))
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
    /// Series left out (beyond [`MAX_SERIES`]) and the largest value among them.
    left_out: Option<(usize, f64)>,
    /// A horizontal reference line (the ratio chart's 1.0).
    line: Option<f64>,
}

impl Bars {
    /// A chart of `series` over `groups`, keeping the [`MAX_SERIES`] series with the largest
    /// values (in their order) and counting the rest.
    fn new(title: String, y_label: &str, groups: Vec<String>, series: Vec<Series>, line: Option<f64>) -> Self {
        let top = |s: &Series| s.values.iter().flatten().copied().fold(f64::NEG_INFINITY, f64::max);
        let (series, left_out) = if series.len() > MAX_SERIES {
            let mut order: Vec<usize> = (0..series.len()).collect();
            order.sort_by(|&a, &b| top(&series[b]).total_cmp(&top(&series[a])));
            let mut keep = vec![false; series.len()];
            order[..MAX_SERIES].iter().for_each(|&i| keep[i] = true);
            let best_left = order[MAX_SERIES..].iter().map(|&i| top(&series[i])).fold(f64::NEG_INFINITY, f64::max);
            let n = series.len() - MAX_SERIES;
            (series.into_iter().zip(keep).filter(|(_, k)| *k).map(|(s, _)| s).collect(), Some((n, best_left)))
        } else {
            (series, None)
        };
        Bars { title, y_label: y_label.into(), groups, series, left_out, line }
    }
}

/// Names in first-seen order, each with its index: linear where `Vec::contains` was
/// quadratic.
#[derive(Default)]
struct Index {
    names: Vec<String>,
    at: HashMap<String, usize>,
}

impl Index {
    fn add(&mut self, name: &str) -> usize {
        if let Some(&i) = self.at.get(name) {
            return i;
        }
        self.names.push(name.to_string());
        self.at.insert(name.to_string(), self.names.len() - 1);
        self.names.len() - 1
    }
}

/// Width of the legend column beside the plot, in pixels.
const LEGEND_WIDTH: u32 = 320;
/// Height of one legend entry, in pixels.
const LEGEND_ROW: u32 = 15;

/// The chart's size in pixels: 960 wide plus the legend column, tall enough for the legend.
fn chart_size(b: &Bars) -> (u32, u32) {
    (960 + LEGEND_WIDTH, 420.max(90 + LEGEND_ROW * b.series.len() as u32))
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
    let mut count = [0usize; 3];
    b.series.iter().for_each(|s| count[s.family as usize] += 1);
    let mut index = [0usize; 3];
    let mut colours = Vec::new();
    for (si, s) in b.series.iter().enumerate() {
        let i = &mut index[s.family as usize];
        let c = colour(s.family, *i, count[s.family as usize]);
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
    let mut y = y0 + b.series.len() as i32 * LEGEND_ROW as i32 + 6;
    if let Some((n, best)) = b.left_out {
        let what = format!("and {n} slower series, at most {best:.3} (not drawn)");
        legend.draw(&Text::new(what, (24, y - 1), ("sans-serif", 12))).map_err(|x| e(&x))?;
        y += LEGEND_ROW as i32;
    }
    if b.series.iter().any(|s| s.ranges.iter().any(Option::is_some)) {
        legend.draw(&PathElement::new(vec![(12, y), (12, y + 12)], BLACK.stroke_width(1))).map_err(|x| e(&x))?;
        legend
            .draw(&Text::new("slowest to fastest run".to_string(), (24, y), ("sans-serif", 12)))
            .map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))
}

/// Refuses a chart of more groups than [`MAX_GROUPS`].
fn check_groups(groups: &[String], what: &str) -> Result<(), CliError> {
    if groups.len() > MAX_GROUPS {
        return Err(CliError::Usage(format!(
            "{what}: {} groups ({}, ...) in one chart; a chart shows at most {MAX_GROUPS}: report fewer ray sets or \
             thread counts at once",
            groups.len(),
            groups[..3].join(", ")
        )));
    }
    Ok(())
}

/// The charts of `inputs`: Mrays/s per input and thread count, the ratio, the builds. Linear
/// in the results.
fn charts(inputs: &[Input]) -> Result<Vec<Bars>, CliError> {
    let mut out = Vec::new();
    for inp in inputs {
        // Rows by thread count, in increasing order.
        let mut by_threads: std::collections::BTreeMap<u64, Vec<&Row>> = Default::default();
        for r in &inp.rows {
            by_threads.entry(r.threads).or_default().push(r);
        }
        if by_threads.len() + out.len() > MAX_CHARTS {
            return Err(CliError::Usage(format!(
                "{}: {} thread counts, a chart each: more than the {MAX_CHARTS} charts a report holds",
                inp.label,
                by_threads.len()
            )));
        }
        for (t, rows) in by_threads {
            let (mut groups, mut names) = (Index::default(), Index::default());
            let mut cells: Vec<(usize, usize, &Row)> = Vec::with_capacity(rows.len());
            for r in rows {
                let g = groups.add(&r.rays);
                let s = names.add(&format!("{}: {}", r.tracer, r.method));
                cells.push((s, g, r));
            }
            check_groups(&groups.names, &inp.label)?;
            let ng = groups.names.len();
            let mut series: Vec<Series> = names
                .names
                .into_iter()
                .map(|name| Series {
                    family: if name.starts_with("embree") { Family::Embree } else { Family::Raypack },
                    name,
                    values: vec![None; ng],
                    ranges: vec![None; ng],
                })
                .collect();
            // The first row of a method and ray set counts, as before.
            for (s, g, r) in cells.into_iter().rev() {
                series[s].values[g] = Some(r.mrays);
                series[s].ranges[g] = r.range;
            }
            let title = format!("{} — {t} thread(s), ISA {}", inp.label, shown(&inp.isa));
            out.push(Bars::new(title, "Mrays/s", groups.names, series, None));
        }
    }
    // The ratio raypack-best / Embree-best per ray set and thread count, one series per input.
    let mut groups = Index::default();
    // Per input: per group, the best raypack and Embree figures, and the summary's spread.
    let mut per_input = Vec::with_capacity(inputs.len());
    for inp in inputs {
        let mut best: HashMap<usize, (Option<f64>, Option<f64>)> = HashMap::new();
        for r in &inp.rows {
            let g = groups.add(&format!("{} {}t", r.rays, r.threads));
            let b = best.entry(g).or_default();
            let slot = if r.tracer == "embree" { &mut b.1 } else { &mut b.0 };
            *slot = Some(slot.map_or(r.mrays, |x: f64| x.max(r.mrays)));
        }
        // The spread is the bench summary's (raypack's slowest run over Embree's fastest, and
        // its fastest over Embree's slowest), when the JSON has one.
        let mut spread = HashMap::new();
        for s in &inp.summary {
            if let (Some(&g), Some(r)) = (groups.at.get(&format!("{} {}t", s.rays, s.threads)), s.ratio_range) {
                spread.entry(g).or_insert(r);
            }
        }
        per_input.push((best, spread));
    }
    check_groups(&groups.names, "the ratio chart")?;
    let ng = groups.names.len();
    let series: Vec<Series> = inputs
        .iter()
        .zip(&per_input)
        .map(|(inp, (best, spread))| Series {
            name: inp.label.clone(),
            family: Family::Input,
            values: (0..ng)
                .map(|g| match best.get(&g) {
                    Some((Some(a), Some(b))) if *b > 0.0 => Some(a / b),
                    _ => None,
                })
                .collect(),
            ranges: (0..ng).map(|g| spread.get(&g).copied()).collect(),
        })
        .collect();
    out.push(Bars::new("best raypack / best Embree (1.0: as fast)".into(), "ratio", groups.names, series, Some(1.0)));
    // Build time and bytes per triangle.
    let mut groups = Index::default();
    for inp in inputs {
        for b in &inp.builds {
            groups.add(&b.name);
        }
    }
    check_groups(&groups.names, "the build charts")?;
    for (what, seconds) in [("build time (s)", true), ("bytes per triangle", false)] {
        let series = inputs
            .iter()
            .map(|inp| {
                let mut values = vec![None; groups.names.len()];
                for b in &inp.builds {
                    values[groups.at[&b.name]] = if seconds { b.seconds } else { b.bytes_per_triangle };
                }
                Series { name: inp.label.clone(), family: Family::Input, ranges: vec![None; values.len()], values }
            })
            .collect();
        out.push(Bars::new(what.into(), what, groups.names.clone(), series, None));
    }
    if out.len() > MAX_CHARTS {
        return Err(CliError::Usage(format!(
            "{} charts: more than the {MAX_CHARTS} a report holds; report fewer files at once",
            out.len()
        )));
    }
    Ok(out)
}

fn register_font() -> Result<(), CliError> {
    use raypack::fs::input::{MAX_FONT_BYTES, read_regular};
    let bytes = FONTS.iter().find_map(|p| read_regular(Path::new(p), MAX_FONT_BYTES, "font files").ok()).ok_or_else(|| {
        CliError::Usage(format!(
            "the report needs a TrueType font to lay out its text: none of {FONTS:?} exists (Debian: apt-get install fonts-dejavu-core)"
        ))
    })?;
    let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
        .map_err(|_| CliError::Usage("the system font could not be read".into()))
}

/// How the report's files are written: never over an input, never into a FIFO (a report
/// directory holds files).
fn output_options(inputs: &[PathBuf]) -> raypack::fs::output::OutputOptions {
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    raypack::fs::output::OutputOptions { allow_fifo: false, ..raypack::fs::output::OutputOptions::protecting(&inputs) }
}

/// The names a report writes in its directory: `index.html` and `chartN.png`.
fn report_files(dir: &Path) -> impl Iterator<Item = PathBuf> + '_ {
    std::iter::once(dir.join("index.html")).chain((0..MAX_CHARTS).map(|i| dir.join(format!("chart{i}.png"))))
}

/// Makes the report directory `dir` (if missing) and checks, before any work, that the
/// report can be written there: a directory this process can create files in, with nothing
/// but regular files (or nothing) at the names it writes; `extra` names more files it will
/// write (`bench.json`), `inputs` the files none of them may be.
pub(crate) fn check_report_dir(dir: &Path, extra: &[PathBuf], inputs: &[PathBuf]) -> Result<(), CliError> {
    let bad = |m: String| CliError::Usage(format!("report directory {}: {m}", dir.display()));
    match std::fs::metadata(dir) {
        Ok(m) if !m.is_dir() => {
            return Err(bad(format!("is {}, not a directory", raypack::fs::input::describe_type(&m))));
        }
        Ok(_) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            std::fs::create_dir_all(dir).map_err(|e| bad(format!("cannot create it: {e}")))?;
        }
        Err(e) => return Err(bad(e.to_string())),
    }
    // An anonymous temporary file: whether files can be created there (permissions, a
    // read-only file system), leaving nothing behind.
    tempfile::tempfile_in(dir).map_err(|e| bad(format!("cannot create files in it: {e}")))?;
    let opts = output_options(inputs);
    for p in report_files(dir).chain(extra.iter().cloned()) {
        raypack::fs::output::check_target(&p, &opts)?;
    }
    Ok(())
}

/// Writes the report of the bench JSON files `inputs` into `out`: `index.html` and its PNG
/// charts, all or none.
pub(crate) fn write_report(inputs: &[PathBuf], out: &Path) -> Result<(), CliError> {
    use raypack::fs::output::{commit_all, stage};
    if inputs.is_empty() {
        return Err(CliError::Usage("raypack report: give at least one bench JSON file".into()));
    }
    let read: Vec<Input> = inputs.iter().map(|p| read_input(p)).collect::<Result<_, _>>()?;
    check_report_dir(out, &[], inputs)?;
    let charts = charts(&read)?;
    register_font()?;
    let mut html = String::from(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>raypack benchmark report</title>\
         <style>body{font-family:sans-serif;max-width:1300px;margin:auto}td,th{padding:2px 8px;text-align:left}</style>\
         </head><body>\n<h1>raypack benchmark report</h1>\n",
    );
    for inp in &read {
        let embree =
            inp.embree.as_ref().map_or("unknown".into(), |(v, isa)| format!("{} (ISA {})", shown(v), shown(isa)));
        let resolution = inp.resolution.map(|[w, h]| format!("{w}x{h}"));
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
            esc(&shown(&inp.scene)),
            esc(&shown(&inp.triangles)),
            esc(&shown(&inp.cpu)),
            esc(&inp.cpu_flags.as_ref().map_or("unknown".into(), |f| f.join(" "))),
            esc(&shown(&inp.logical_cpus)),
            esc(&shown(&inp.memory_bytes)),
            esc(&shown(&inp.version)),
            esc(&shown(&inp.commit)),
            esc(&shown(&inp.isa)),
            esc(&embree),
            esc(&shown(&inp.date)),
            esc(&format!("{} (primary resolution {})", ray_sets(&inp.rows), shown(&resolution))),
            esc(&inp.notes.join("; ")),
        );
        html.push_str(&summary_table(inp));
    }
    let opts = output_options(inputs);
    let mut files = Vec::new();
    for (i, chart) in charts.iter().enumerate() {
        let mut svg = String::new();
        let size = chart_size(chart);
        draw(SVGBackend::with_string(&mut svg, size).into_drawing_area(), chart).map_err(CliError::Usage)?;
        let png_path = out.join(format!("chart{i}.png"));
        let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
        draw(BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area(), chart)
            .map_err(|m| CliError::Usage(format!("{}: {m}", png_path.display())))?;
        let png = raypack::render::film::encode_png(size.0 as usize, size.1 as usize, &rgb)
            .map_err(|message| raypack::render::ImageError::Encode { path: png_path.clone(), message })?;
        files.push(stage(&png_path, &opts, &mut |w| w.write_all(&png))?);
        let _ = write!(html, "<h3>{}</h3>\n{svg}\n<p><a href=\"chart{i}.png\">PNG</a></p>\n", esc(&chart.title));
    }
    html.push_str("</body></html>\n");
    files.push(stage(&out.join("index.html"), &opts, &mut |w| w.write_all(html.as_bytes()))?);
    commit_all(files)?;
    Ok(())
}

/// The bench summary (schema 2) as a table: per ray set and thread count, the best raypack
/// method and the best Embree call, their ratio and its spread; with the load line's warning
/// when the machine was busy. Empty for a JSON without a summary.
fn summary_table(inp: &Input) -> String {
    let mut t = String::new();
    if !inp.summary.is_empty() {
        t.push_str(
            "<table><tr><th>rays</th><th>threads</th><th>best raypack</th><th>Mrays/s</th>\
         <th>best Embree</th><th>Mrays/s</th><th>ratio</th><th>ratio min–max</th></tr>\n",
        );
    }
    let num = |v: Option<f64>| v.map_or("–".into(), |x| format!("{x:.2}"));
    let dash = |v: &Option<String>| v.clone().unwrap_or_else(|| "–".into());
    for r in &inp.summary {
        let _ = writeln!(
            t,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}–{}</td></tr>",
            esc(&r.rays),
            r.threads,
            esc(&shown(&r.raypack_method)),
            num(r.raypack_mrays),
            esc(&dash(&r.embree_method)),
            num(r.embree_mrays),
            num(r.ratio),
            num(r.ratio_range.map(|r| r.0)),
            num(r.ratio_range.map(|r| r.1)),
        );
    }
    if !inp.summary.is_empty() {
        t.push_str("</table>\n");
    }
    if inp.busy {
        let _ = writeln!(
            t,
            "<p><b>The machine was busy during this run</b> (load average {} before, {} after): the figures may be off.</p>",
            esc(&numbers(&inp.load_before)),
            esc(&numbers(&inp.load_after))
        );
    }
    t
}

/// The ray sets of `rows`, in first-seen order.
fn ray_sets(rows: &[Row]) -> String {
    let mut seen = Index::default();
    rows.iter().for_each(|r| _ = seen.add(&r.rays));
    seen.names.join(", ")
}

/// `s` as HTML text or attribute value.
fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}
