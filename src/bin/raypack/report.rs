// Not split further: the HTML page and its charts are one output written all or none; the JSON input is already report/input.rs.
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
//! The charts: one per ray set (`rays-primary.png`, `rays-diffuse.png`, ...), a row per method
//! sorted closest-hit then occlusion calls, by family (one ray per call, 8- and 16-wide
//! packets, streams, ...: a hue each) and raypack's kernel beside Embree's calls of its kind
//! (solid and light), a panel per input and thread count; the ratio of the best of each
//! tracer (`ratio.png`); the build times (`build-time.png`) and the trees' sizes
//! (`build-bytes.png`). Every bar has its whisker (slowest to fastest run or build) where the
//! JSON has the spread, and its figure beside it; labels sit in their own column.
//!
//! Charts are drawn in memory and written with `index.html` through [`raypack::fs::output`],
//! all or nothing: never through a link or into a FIFO planted in the directory. Building them
//! is linear in the results; a chart shows at most [`MAX_ROWS`] rows (the fastest, the others
//! counted beneath), and a report of more panels or charts than can be read is an error.
//!
//! Text is laid out with a TrueType font read from the system (DejaVu Sans, Debian's
//! `fonts-dejavu-core`); without one the report is a clear error.

mod input;

use crate::CliError;
use input::{Input, Row, read_input};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use raypack::raysets::RaySetKind;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Where a sans-serif TrueType font is looked for.
const FONTS: [&str; 3] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

/// Most rows (methods, builds, ray sets) of one chart: the fastest are drawn, the others
/// counted in a note beneath (beyond this many, a chart is taller than a screen).
pub(crate) const MAX_ROWS: usize = 48;
/// Most panels side by side in one chart (inputs × thread counts).
const MAX_PANELS: usize = 8;
/// Most charts of one report.
const MAX_CHARTS: usize = 64;

/// A value for the HTML: the text, or "unknown".
fn shown<T: std::fmt::Display>(v: &Option<T>) -> String {
    v.as_ref().map_or_else(|| "unknown".into(), |x| x.to_string())
}

fn numbers(v: &Option<Vec<f64>>) -> String {
    v.as_ref().map_or_else(|| "unknown".into(), |a| format!("{a:?}"))
}

/// What kind of call a method is: its family decides the hue of its bars, so that each of
/// raypack's kernels stands beside the Embree calls of its kind in the same hue.
const FAMILIES: [(&str, RGBColor); 7] = [
    ("1 ray per call", RGBColor(0x4e, 0x79, 0xa7)),
    ("8-wide packets", RGBColor(0xf2, 0x8e, 0x2b)),
    ("16-wide packets", RGBColor(0x59, 0xa1, 0x4f)),
    ("streams", RGBColor(0xb0, 0x7a, 0xa1)),
    ("interleaved streams", RGBColor(0xe1, 0x57, 0x59)),
    ("scalar reference (binary BVH)", RGBColor(0x8c, 0x8c, 0x8c)),
    ("other", RGBColor(0x9c, 0x75, 0x5f)),
];

/// The colour of raypack's figures where a chart has no families (builds, ratios).
const RAYPACK: RGBColor = FAMILIES[0].1;

/// Embree's bars: the family's hue, lighter (and outlined in it), beside raypack's solid one.
fn light(c: RGBColor) -> RGBColor {
    let mix = |v: u8| ((v as u32 + 2 * 255) / 3) as u8;
    RGBColor(mix(c.0), mix(c.1), mix(c.2))
}

/// How a method sorts in its chart: closest-hit calls before occlusion calls, then by family,
/// then by the BVH quality in its name's parentheses, raypack before Embree, plain before
/// coherent.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct MethodKey {
    occluded: bool,
    family: usize,
    quality: (u8, String),
    embree: bool,
    coherent: bool,
    name: String,
}

fn method_key(tracer: &str, method: &str) -> MethodKey {
    let lower = method.to_ascii_lowercase();
    let (base, quality) = match (lower.rfind(" ("), lower.ends_with(')')) {
        (Some(at), true) => (&lower[..at], lower[at..].to_string()),
        _ => (lower.as_str(), String::new()),
    };
    let width = base.trim_end_matches(" coherent");
    let family = if base.contains("reference") {
        5
    } else if base.contains("interleaved") {
        4
    } else if base.contains("stream") {
        3
    } else if width.ends_with("16") {
        2
    } else if width.ends_with('8') {
        1
    } else if width.ends_with('1') {
        0
    } else {
        6
    };
    MethodKey {
        occluded: base.contains("occluded"),
        family,
        quality: (quality_rank(&quality), quality),
        embree: tracer == "embree",
        coherent: base.ends_with(" coherent"),
        name: method.to_string(),
    }
}

/// BVH qualities in the order of their effort: fast, medium, high, then anything else.
fn quality_rank(text: &str) -> u8 {
    let lower = text.to_ascii_lowercase();
    ["fast", "medium", "high"].iter().position(|q| lower.contains(q)).map_or(3, |i| i as u8)
}

/// One bar: the figure and its spread (slowest and fastest run), drawn as a whisker.
#[derive(Clone, Copy)]
struct Bar {
    value: f64,
    range: Option<(f64, f64)>,
}

/// One row of a chart: its label, its colour and, per panel, its bar.
struct HRow {
    label: String,
    colour: RGBColor,
    /// Drawn light (Embree's figures).
    light: bool,
    /// The first row of a section ("closest hit"): the section's name is drawn above it.
    section: Option<String>,
    bars: Vec<Option<Bar>>,
}

/// A horizontal bar chart: one row per method (or build, or ray set), one panel per input
/// and thread count, the labels on the left where they never overlap.
struct Chart {
    /// The PNG file's name in the report directory.
    file: String,
    title: String,
    /// What the x axis measures.
    unit: String,
    panels: Vec<String>,
    rows: Vec<HRow>,
    /// The legend: name, colour, drawn light.
    legend: Vec<(String, RGBColor, bool)>,
    /// A vertical reference line (the ratio chart's 1.0).
    line: Option<f64>,
    /// What is not drawn (rows beyond [`MAX_ROWS`]).
    note: Option<String>,
}

impl Chart {
    /// Keeps the [`MAX_ROWS`] rows with the largest figures (in their order) and says how many
    /// were left out and the largest among them.
    fn keep_fastest(&mut self, what: &str) {
        if self.rows.len() <= MAX_ROWS {
            return;
        }
        let top = |r: &HRow| r.bars.iter().flatten().map(|b| b.value).fold(f64::NEG_INFINITY, f64::max);
        let mut order: Vec<usize> = (0..self.rows.len()).collect();
        order.sort_by(|&a, &b| top(&self.rows[b]).total_cmp(&top(&self.rows[a])));
        let mut keep = vec![false; self.rows.len()];
        order[..MAX_ROWS].iter().for_each(|&i| keep[i] = true);
        let best_left = order[MAX_ROWS..].iter().map(|&i| top(&self.rows[i])).fold(f64::NEG_INFINITY, f64::max);
        let n = self.rows.len() - MAX_ROWS;
        let rows = std::mem::take(&mut self.rows);
        self.rows = rows.into_iter().zip(keep).filter(|(_, k)| *k).map(|(r, _)| r).collect();
        self.note = Some(format!("and {n} slower {what}, at most {best_left:.3} (not drawn)"));
    }
}

/// Layout, in pixels.
const ROW: i32 = 18;
const BAR: i32 = 12;
const PANEL: i32 = 330;
const GAP: i32 = 24;
const FONT_SIZE: f64 = 13.0;

/// A round axis end and tick step for figures up to `max`: steps of 1, 2 or 5 times a power
/// of ten, four to eight ticks.
fn axis(max: f64) -> (f64, f64) {
    let max = if max.is_finite() && max > 0.0 { max } else { 1.0 };
    let raw = max / 5.0;
    let p = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| m * p).find(|s| *s >= raw).unwrap_or(10.0 * p);
    ((max / step).ceil() * step, step)
}

/// `v` with as many decimals as the tick step needs.
fn tick_text(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 { 0 } else { (-step.log10().floor()) as usize };
    format!("{v:.decimals$}")
}

/// A figure beside its bar: three significant digits.
fn value_text(v: f64) -> String {
    let a = v.abs();
    if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

/// The width of the label column: the longest label's, within bounds.
fn label_width<DB: DrawingBackend>(root: &DrawingArea<DB, plotters::coord::Shift>, c: &Chart) -> i32 {
    let font = ("sans-serif", FONT_SIZE).into_font();
    let widest =
        c.rows.iter().filter_map(|r| root.estimate_text_size(&r.label, &font.color(&BLACK)).ok()).map(|(w, _)| w).max();
    (widest.unwrap_or(60) as i32 + 16).clamp(80, 420)
}

/// The legend's rows: entries laid out left to right, wrapped at `width`.
fn legend_lines(c: &Chart, width: i32) -> Vec<Vec<usize>> {
    let mut lines: Vec<Vec<usize>> = vec![Vec::new()];
    let mut x = 0;
    for (i, (name, _, _)) in c.legend.iter().enumerate() {
        let w = 24 + (name.chars().count() as i32 * 7) + 18;
        if x + w > width && !lines.last().unwrap().is_empty() {
            lines.push(Vec::new());
            x = 0;
        }
        lines.last_mut().unwrap().push(i);
        x += w;
    }
    lines
}

/// The chart's size in pixels.
fn chart_size(c: &Chart, label_w: i32) -> (u32, u32) {
    // Wide enough for the title (17-pixel type, under 10 pixels a character).
    let title_w = 40 + c.title.chars().count() as i32 * 10;
    let w = (20 + label_w + c.panels.len().max(1) as i32 * (PANEL + GAP)).max(title_w);
    let sections = c.rows.iter().filter(|r| r.section.is_some()).count() as i32;
    let legend = legend_lines(c, w - 40).len() as i32;
    let h =
        header_height(legend) + (c.rows.len() as i32 + sections) * ROW + 60 + if c.note.is_some() { ROW } else { 0 };
    (w as u32, h as u32)
}

fn header_height(legend_lines: i32) -> i32 {
    36 + legend_lines * ROW + 44
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    c: &Chart,
    label_w: i32,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |x: &dyn std::fmt::Display| x.to_string();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let (w, h) = root.dim_in_pixel();
    let (w, h) = (w as i32, h as i32);
    let font = ("sans-serif", FONT_SIZE).into_font();
    let small = ("sans-serif", FONT_SIZE - 2.0).into_font();
    let grey = RGBColor(0xdd, 0xdd, 0xdd);
    // Title and legend.
    root.draw(&Text::new(
        c.title.clone(),
        (20, 18),
        ("sans-serif", 17).into_font().color(&BLACK).pos(Pos::new(HPos::Left, VPos::Center)),
    ))
    .map_err(|x| e(&x))?;
    let lines = legend_lines(c, w - 40);
    for (li, line) in lines.iter().enumerate() {
        let y = 36 + li as i32 * ROW + ROW / 2;
        let mut x = 20;
        for &i in line {
            let (name, colour, is_light) = &c.legend[i];
            if name.starts_with("whisker") {
                // Drawn as the whiskers are: a line with end caps.
                root.draw(&PathElement::new(vec![(x, y), (x + 16, y)], BLACK.stroke_width(1))).map_err(|x| e(&x))?;
                for cap in [x, x + 16] {
                    root.draw(&PathElement::new(vec![(cap, y - 4), (cap, y + 4)], BLACK.stroke_width(1)))
                        .map_err(|x| e(&x))?;
                }
            } else {
                let fill = if *is_light { light(*colour) } else { *colour };
                root.draw(&Rectangle::new([(x, y - 6), (x + 16, y + 6)], fill.filled())).map_err(|x| e(&x))?;
                root.draw(&Rectangle::new([(x, y - 6), (x + 16, y + 6)], colour.stroke_width(1))).map_err(|x| e(&x))?;
            }
            root.draw(&Text::new(name.clone(), (x + 22, y), anchored(HPos::Left, &font))).map_err(|x| e(&x))?;
            let tw =
                root.estimate_text_size(name, &font.color(&BLACK)).map_or(name.len() as i32 * 7, |(w, _)| w as i32);
            x += 22 + tw + 18;
        }
    }
    let top = header_height(lines.len() as i32);
    // Where each row sits: sections take a row of their own for their name.
    let mut ys = Vec::with_capacity(c.rows.len());
    let mut y = top;
    for r in &c.rows {
        if let Some(s) = &r.section {
            root.draw(&Text::new(
                s.clone(),
                (20, y + ROW / 2),
                anchored(HPos::Left, &("sans-serif", FONT_SIZE + 1.0, FontStyle::Bold).into_font()),
            ))
            .map_err(|x| e(&x))?;
            y += ROW;
        }
        ys.push(y + ROW / 2);
        y += ROW;
    }
    let bottom = y;
    for (r, &yc) in c.rows.iter().zip(&ys) {
        root.draw(&Text::new(r.label.clone(), (20 + label_w - 8, yc), anchored(HPos::Right, &font)))
            .map_err(|x| e(&x))?;
    }
    for (pi, title) in c.panels.iter().enumerate() {
        let x0 = 20 + label_w + pi as i32 * (PANEL + GAP);
        let plot_w = PANEL - 50;
        let max = c
            .rows
            .iter()
            .filter_map(|r| r.bars.get(pi).copied().flatten())
            .map(|b| b.range.map_or(b.value, |(_, hi)| hi.max(b.value)))
            .fold(c.line.unwrap_or(0.0), f64::max);
        let (end, step) = axis(max);
        let px = |v: f64| x0 + ((v / end).clamp(0.0, 1.0) * plot_w as f64).round() as i32;
        root.draw(&Text::new(
            title.clone(),
            (x0 + plot_w / 2, top - 30),
            anchored(HPos::Center, &("sans-serif", FONT_SIZE, FontStyle::Bold).into_font()),
        ))
        .map_err(|x| e(&x))?;
        // Grid and ticks: round values, top and bottom.
        let mut t = 0.0;
        while t <= end + step * 1e-9 {
            let x = px(t);
            root.draw(&PathElement::new(vec![(x, top - 4), (x, bottom)], grey.stroke_width(1))).map_err(|x| e(&x))?;
            for ty in [top - 12, bottom + 10] {
                root.draw(&Text::new(tick_text(t, step), (x, ty), anchored(HPos::Center, &small)))
                    .map_err(|x| e(&x))?;
            }
            t += step;
        }
        root.draw(&Text::new(c.unit.clone(), (x0 + plot_w / 2, bottom + 28), anchored(HPos::Center, &font)))
            .map_err(|x| e(&x))?;
        root.draw(&PathElement::new(vec![(x0, top - 4), (x0, bottom)], BLACK.stroke_width(1))).map_err(|x| e(&x))?;
        for (r, &yc) in c.rows.iter().zip(&ys) {
            let Some(b) = r.bars.get(pi).copied().flatten() else {
                root.draw(&Text::new("–".to_string(), (x0 + 6, yc), anchored(HPos::Left, &small)))
                    .map_err(|x| e(&x))?;
                continue;
            };
            let fill = if r.light { light(r.colour) } else { r.colour };
            let (y0, y1) = (yc - BAR / 2, yc + BAR / 2);
            root.draw(&Rectangle::new([(x0, y0), (px(b.value).max(x0 + 1), y1)], fill.filled())).map_err(|x| e(&x))?;
            if r.light {
                root.draw(&Rectangle::new([(x0, y0), (px(b.value).max(x0 + 1), y1)], r.colour.stroke_width(1)))
                    .map_err(|x| e(&x))?;
            }
            let mut text_x = px(b.value);
            if let Some((lo, hi)) = b.range {
                let (a, z) = (px(lo), px(hi));
                root.draw(&PathElement::new(vec![(a, yc), (z, yc)], BLACK.stroke_width(1))).map_err(|x| e(&x))?;
                for x in [a, z] {
                    root.draw(&PathElement::new(vec![(x, yc - 4), (x, yc + 4)], BLACK.stroke_width(1)))
                        .map_err(|x| e(&x))?;
                }
                text_x = text_x.max(z);
            }
            root.draw(&Text::new(value_text(b.value), (text_x + 4, yc), anchored(HPos::Left, &small)))
                .map_err(|x| e(&x))?;
        }
        if let Some(l) = c.line {
            let x = px(l);
            root.draw(&PathElement::new(vec![(x, top - 4), (x, bottom)], BLACK.stroke_width(2))).map_err(|x| e(&x))?;
        }
    }
    if let Some(note) = &c.note {
        root.draw(&Text::new(note.clone(), (20, h - ROW), anchored(HPos::Left, &font))).map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))
}

/// Black text of `font`, centred vertically on its position and anchored horizontally by `h`.
fn anchored<'a>(h: HPos, font: &FontDesc<'a>) -> TextStyle<'a> {
    font.color(&BLACK).pos(Pos::new(h, VPos::Center))
}

/// A ray set's name as part of a file name: lower-case letters, digits and dashes.
fn file_part(name: &str) -> String {
    let s: String =
        name.chars().map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '-' }).take(40).collect();
    let s = s.trim_matches('-').to_string();
    if s.is_empty() { "unnamed".into() } else { s }
}

/// "1 thread", "2 threads".
fn threads_text(t: u64) -> String {
    if t == 1 { "1 thread".into() } else { format!("{t} threads") }
}

/// The legend of the family hues present in `keys`, raypack solid and Embree light.
fn family_legend(keys: &[MethodKey]) -> Vec<(String, RGBColor, bool)> {
    let mut out = Vec::new();
    for (f, (name, colour)) in FAMILIES.iter().enumerate() {
        if keys.iter().any(|k| k.family == f) {
            out.push((name.to_string(), *colour, false));
        }
    }
    if keys.iter().any(|k| k.embree) {
        out.push(("raypack: solid".into(), RGBColor(0x55, 0x55, 0x55), false));
        out.push(("Embree: light".into(), RGBColor(0x55, 0x55, 0x55), true));
    }
    out
}

/// The charts of `inputs`: one per ray set (a row per method, a panel per input and thread
/// count), the ratio of the best of each tracer, the build times and the trees' sizes.
/// Linear in the results.
fn charts(inputs: &[Input]) -> Result<Vec<Chart>, CliError> {
    let mut out = Vec::new();
    let many = inputs.len() > 1;
    // Ray sets in first-seen order, over all inputs.
    let mut sets = Index::default();
    for inp in inputs {
        for r in &inp.rows {
            sets.add(&r.rays);
        }
    }
    if sets.names.len() + 3 > MAX_CHARTS {
        return Err(CliError::Usage(format!(
            "{} ray sets ({}, ...), a chart each: more than the {MAX_CHARTS} charts a report holds",
            sets.names.len(),
            sets.names[..3].join(", ")
        )));
    }
    let mut files = HashMap::new();
    for set in &sets.names {
        // Panels: (input, thread count) in order; rows: methods.
        let mut panels: Vec<(usize, u64)> = Vec::new();
        let mut panel_at: HashMap<(usize, u64), usize> = HashMap::new();
        let mut methods: HashMap<(String, String), usize> = HashMap::new();
        let mut keys: Vec<MethodKey> = Vec::new();
        let mut cells: Vec<(usize, usize, Bar)> = Vec::new();
        for (ii, inp) in inputs.iter().enumerate() {
            let mut threads: Vec<u64> = inp.rows.iter().filter(|r| &r.rays == set).map(|r| r.threads).collect();
            threads.sort_unstable();
            threads.dedup();
            for t in threads {
                panel_at.insert((ii, t), panels.len());
                panels.push((ii, t));
            }
            for r in inp.rows.iter().filter(|r| &r.rays == set) {
                let m = *methods.entry((r.tracer.clone(), r.method.clone())).or_insert_with(|| {
                    keys.push(method_key(&r.tracer, &r.method));
                    keys.len() - 1
                });
                cells.push((panel_at[&(ii, r.threads)], m, Bar { value: r.mrays, range: r.range }));
            }
        }
        if panels.len() > MAX_PANELS {
            return Err(CliError::Usage(format!(
                "ray set {set}: {} inputs and thread counts, a panel each: a chart shows at most {MAX_PANELS}; report \
                 fewer files or thread counts at once",
                panels.len()
            )));
        }
        let mut bars = vec![vec![None; panels.len()]; keys.len()];
        // The first row of a method, ray set and thread count counts.
        for (p, m, b) in cells.into_iter().rev() {
            bars[m][p] = Some(b);
        }
        let mut order: Vec<usize> = (0..keys.len()).collect();
        order.sort_by(|&a, &b| keys[a].cmp(&keys[b]));
        let section = |k: &MethodKey| if k.occluded { "any hit (occluded)" } else { "closest hit (intersect)" };
        let mut rows = Vec::with_capacity(order.len());
        let mut last: Option<bool> = None;
        for &m in &order {
            let k = &keys[m];
            let both = keys.iter().any(|k| k.occluded) && keys.iter().any(|k| !k.occluded);
            rows.push(HRow {
                label: k.name.clone(),
                colour: FAMILIES[k.family].1,
                light: k.embree,
                section: (both && last != Some(k.occluded)).then(|| section(k).to_string()),
                bars: std::mem::take(&mut bars[m]),
            });
            last = Some(k.occluded);
        }
        let panels = panels
            .iter()
            .map(|&(ii, t)| if many { format!("{}, {}", inputs[ii].label, threads_text(t)) } else { threads_text(t) })
            .collect();
        let title = if many {
            format!("{set} rays: Mrays/s, higher is better")
        } else {
            format!("{}: {set} rays, Mrays/s (higher is better), ISA {}", inputs[0].label, shown(&inputs[0].isa))
        };
        let mut legend = family_legend(&keys);
        if rows.iter().any(|r| r.bars.iter().flatten().any(|b| b.range.is_some())) {
            legend.push(("whisker: slowest to fastest run".into(), BLACK, true));
        }
        let mut file = format!("rays-{}", file_part(set));
        let n = files.entry(file.clone()).or_insert(0usize);
        *n += 1;
        if *n > 1 {
            file = format!("{file}-{n}");
        }
        let mut chart = Chart {
            file: format!("{file}.png"),
            title,
            unit: "Mrays/s".into(),
            panels,
            rows,
            legend,
            line: None,
            note: None,
        };
        chart.keep_fastest("methods");
        out.push(chart);
    }
    out.push(ratio_chart(inputs)?);
    out.extend(build_charts(inputs)?);
    Ok(out)
}

/// The ratio of raypack's best to Embree's best per ray set and thread count, a panel per
/// input, with the bench summary's spread as whiskers.
fn ratio_chart(inputs: &[Input]) -> Result<Chart, CliError> {
    let mut groups = Index::default();
    let mut per_input = Vec::with_capacity(inputs.len());
    for inp in inputs {
        let mut best: HashMap<usize, (Option<f64>, Option<f64>)> = HashMap::new();
        for r in &inp.rows {
            let g = groups.add(&format!("{}, {}", r.rays, threads_text(r.threads)));
            let b = best.entry(g).or_default();
            let slot = if r.tracer == "embree" { &mut b.1 } else { &mut b.0 };
            *slot = Some(slot.map_or(r.mrays, |x: f64| x.max(r.mrays)));
        }
        // The spread is the bench summary's (raypack's slowest run over Embree's fastest, and
        // its fastest over Embree's slowest), when the JSON has one.
        let mut spread = HashMap::new();
        for s in &inp.summary {
            if let (Some(&g), Some(r)) =
                (groups.at.get(&format!("{}, {}", s.rays, threads_text(s.threads))), s.ratio_range)
            {
                spread.entry(g).or_insert(r);
            }
        }
        per_input.push((best, spread));
    }
    check_panels(inputs.len(), "the ratio chart")?;
    let rows = groups
        .names
        .iter()
        .enumerate()
        .map(|(g, name)| HRow {
            label: name.clone(),
            colour: RAYPACK,
            light: false,
            section: None,
            bars: per_input
                .iter()
                .map(|(best, spread)| match best.get(&g) {
                    Some((Some(a), Some(b))) if *b > 0.0 => Some(Bar { value: a / b, range: spread.get(&g).copied() }),
                    _ => None,
                })
                .collect(),
        })
        .collect();
    let mut chart = Chart {
        file: "ratio.png".into(),
        title: "best raypack / best Embree on the same rays and threads (1.0: as fast; above: raypack faster)".into(),
        unit: "ratio".into(),
        panels: inputs.iter().map(|i| i.label.clone()).collect(),
        rows,
        legend: vec![("whisker: the ratio's range over the runs".into(), BLACK, true)],
        line: Some(1.0),
        note: None,
    };
    chart.keep_fastest("rows");
    Ok(chart)
}

/// Build time (with the fastest and slowest build as whiskers) and the trees' bytes per
/// triangle: a row per tree, a panel per input.
fn build_charts(inputs: &[Input]) -> Result<Vec<Chart>, CliError> {
    let mut names = Index::default();
    for inp in inputs {
        for b in &inp.builds {
            names.add(&b.name);
        }
    }
    check_panels(inputs.len(), "the build charts")?;
    // Each of raypack's trees beside Embree's of the same effort.
    let mut order: Vec<usize> = (0..names.names.len()).collect();
    order.sort_by_key(|&i| (quality_rank(&names.names[i]), names.names[i].starts_with("embree"), i));
    let mut row_of = vec![0; order.len()];
    order.iter().enumerate().for_each(|(r, &i)| row_of[i] = r);
    let mut out = Vec::new();
    for (file, title, unit, seconds) in [
        ("build-time.png", "Acceleration structure builds on all threads (lower is better)", "seconds", true),
        ("build-bytes.png", "Acceleration structure size (lower is smaller)", "bytes per triangle", false),
    ] {
        let mut rows: Vec<HRow> = order
            .iter()
            .map(|&i| &names.names[i])
            .map(|n| HRow {
                label: n.clone(),
                colour: RAYPACK,
                light: n.starts_with("embree"),
                section: None,
                bars: vec![None; inputs.len()],
            })
            .collect();
        for (ii, inp) in inputs.iter().enumerate() {
            for b in &inp.builds {
                let value = if seconds { b.seconds } else { b.bytes_per_triangle };
                let range = if seconds { b.seconds_range } else { None };
                rows[row_of[names.at[&b.name]]].bars[ii] = value.map(|value| Bar { value, range });
            }
        }
        let mut legend = vec![("raypack".to_string(), RAYPACK, false)];
        if rows.iter().any(|r| r.light) {
            legend.push(("Embree".into(), RAYPACK, true));
        }
        if seconds {
            legend.push(("whisker: fastest to slowest build".into(), BLACK, true));
        }
        let mut chart = Chart {
            file: file.into(),
            title: title.into(),
            unit: unit.into(),
            panels: inputs.iter().map(|i| i.label.clone()).collect(),
            rows,
            legend,
            line: None,
            note: None,
        };
        chart.keep_fastest("structures");
        out.push(chart);
    }
    Ok(out)
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

/// Refuses a chart of more panels than [`MAX_PANELS`].
fn check_panels(n: usize, what: &str) -> Result<(), CliError> {
    if n > MAX_PANELS {
        return Err(CliError::Usage(format!(
            "{what}: {n} inputs, a panel each: a chart shows at most {MAX_PANELS}; report fewer files at once"
        )));
    }
    Ok(())
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

/// The names a report writes in its directory, as far as they are known before the results:
/// `index.html`, the ratio and build charts, and the charts of the built-in ray sets and of a
/// `--rays` file.
fn report_files(dir: &Path) -> impl Iterator<Item = PathBuf> + '_ {
    let fixed = ["index.html", "ratio.png", "build-time.png", "build-bytes.png"].map(String::from);
    use RaySetKind::*;
    let kinds = [Primary, Diffuse, Shadow, Random, EdgesVertices, File];
    let sets = kinds.into_iter().map(|k| format!("rays-{}.png", file_part(k.name())));
    fixed.into_iter().chain(sets).map(|n| dir.join(n))
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
    for chart in &charts {
        let png_path = out.join(&chart.file);
        // The label column is measured with the font once, on a drawing area of any size.
        let label_w = {
            let mut probe = String::new();
            label_width(&SVGBackend::with_string(&mut probe, (10, 10)).into_drawing_area(), chart)
        };
        let size = chart_size(chart, label_w);
        let mut svg = String::new();
        draw(SVGBackend::with_string(&mut svg, size).into_drawing_area(), chart, label_w).map_err(CliError::Usage)?;
        let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
        draw(BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area(), chart, label_w)
            .map_err(|m| CliError::Usage(format!("{}: {m}", png_path.display())))?;
        let png = raypack::render::film::encode_png(size.0 as usize, size.1 as usize, &rgb)
            .map_err(|message| raypack::render::ImageError::Encode { path: png_path.clone(), message })?;
        files.push(stage(&png_path, &opts, &mut |w| w.write_all(&png))?);
        let _ = write!(
            html,
            "<h3>{}</h3>\n{svg}\n<p><a href=\"{}\">{}</a></p>\n",
            esc(&chart.title),
            esc(&chart.file),
            esc(&chart.file)
        );
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
        let why = match &inp.busy_reason {
            Some(why) => why.clone(),
            None => format!("load average {} before, {} after", numbers(&inp.load_before), numbers(&inp.load_after)),
        };
        let _ =
            writeln!(t, "<p><b>The machine was busy during this run</b> ({}): the figures may be off.</p>", esc(&why));
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
