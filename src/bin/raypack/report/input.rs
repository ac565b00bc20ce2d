//! A bench JSON read for the report: through [`raypack::fs::input`] (a regular file of at
//! most [`MAX_BENCH_JSON_BYTES`]), and every field the report shows checked for its type on
//! the way in. Reports are built from other machines' files: a field of the wrong type is an
//! error naming the file and the field, never text passed through to the HTML.

use crate::CliError;
use raypack::fs::input::{MAX_BENCH_JSON_BYTES, read_regular};
use serde_json::{Map, Value};
use std::path::Path;

/// One result row of a bench JSON.
pub(super) struct Row {
    pub rays: String,
    pub threads: u64,
    pub tracer: String,
    pub method: String,
    pub mrays: f64,
    /// Slowest and fastest run (schema 2), when the JSON has them.
    pub range: Option<(f64, f64)>,
}

/// One row of a bench summary (schema 2).
pub(super) struct SummaryRow {
    pub rays: String,
    pub threads: u64,
    pub raypack_method: Option<String>,
    pub raypack_mrays: Option<f64>,
    pub embree_method: Option<String>,
    pub embree_mrays: Option<f64>,
    pub ratio: Option<f64>,
    pub ratio_range: Option<(f64, f64)>,
}

/// One build figure: its name, seconds and bytes per triangle.
pub(super) struct Build {
    pub name: String,
    pub seconds: Option<f64>,
    pub bytes_per_triangle: Option<f64>,
    /// The fastest and slowest build, when the JSON has them.
    pub seconds_range: Option<(f64, f64)>,
}

/// One bench JSON, every field typed (`None`: absent or null, shown as "unknown").
pub(super) struct Input {
    pub label: String,
    pub scene: Option<String>,
    pub triangles: Option<u64>,
    pub resolution: Option<[u64; 2]>,
    pub notes: Vec<String>,
    pub date: Option<String>,
    pub cpu: Option<String>,
    pub cpu_flags: Option<Vec<String>>,
    pub logical_cpus: Option<u64>,
    pub memory_bytes: Option<u64>,
    pub version: Option<String>,
    pub commit: Option<String>,
    pub isa: Option<String>,
    /// Embree's version and ISA, when the bench ran against it.
    pub embree: Option<(Option<String>, Option<String>)>,
    pub busy: bool,
    /// Why the bench judged the machine busy (older reports have none).
    pub busy_reason: Option<String>,
    pub load_before: Option<Vec<f64>>,
    pub load_after: Option<Vec<f64>>,
    pub builds: Vec<Build>,
    pub rows: Vec<Row>,
    pub summary: Vec<SummaryRow>,
}

/// The fields of one JSON object, each read with its type checked; errors name the file and
/// the field's path (`machine.logical_cpus`, `results[3].threads`).
struct Obj<'a> {
    file: &'a Path,
    at: String,
    map: Option<&'a Map<String, Value>>,
}

fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

impl<'a> Obj<'a> {
    fn path(&self, key: &str) -> String {
        if self.at.is_empty() { key.to_string() } else { format!("{}.{key}", self.at) }
    }

    fn bad(&self, key: &str, expected: &str, got: &Value) -> CliError {
        CliError::Usage(format!(
            "{}: {}: expected {expected}, got {}; not a bench JSON raypack reads",
            self.file.display(),
            self.path(key),
            kind(got)
        ))
    }

    /// The value of `key`, `None` when it is absent or null.
    fn get(&self, key: &str) -> Option<&'a Value> {
        self.map.and_then(|m| m.get(key)).filter(|v| !v.is_null())
    }

    fn string(&self, key: &str) -> Result<Option<String>, CliError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.clone())),
            Some(v) => Err(self.bad(key, "a string", v)),
        }
    }

    fn count(&self, key: &str) -> Result<Option<u64>, CliError> {
        match self.get(key) {
            None => Ok(None),
            Some(v) => v.as_u64().map(Some).ok_or_else(|| self.bad(key, "a whole number >= 0", v)),
        }
    }

    fn number(&self, key: &str) -> Result<Option<f64>, CliError> {
        match self.get(key) {
            None => Ok(None),
            Some(v) => {
                v.as_f64().filter(|x| x.is_finite()).map(Some).ok_or_else(|| self.bad(key, "a finite number", v))
            }
        }
    }

    fn boolean(&self, key: &str) -> Result<Option<bool>, CliError> {
        match self.get(key) {
            None => Ok(None),
            Some(v) => v.as_bool().map(Some).ok_or_else(|| self.bad(key, "true or false", v)),
        }
    }

    fn object(&self, key: &str) -> Result<Obj<'a>, CliError> {
        let map = match self.get(key) {
            None => None,
            Some(Value::Object(m)) => Some(m),
            Some(v) => return Err(self.bad(key, "an object", v)),
        };
        Ok(Obj { file: self.file, at: self.path(key), map })
    }

    fn array(&self, key: &str) -> Result<Option<&'a Vec<Value>>, CliError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::Array(a)) => Ok(Some(a)),
            Some(v) => Err(self.bad(key, "an array", v)),
        }
    }

    /// Element `i` of array `key` as an object.
    fn element(&self, key: &str, i: usize, v: &'a Value) -> Result<Obj<'a>, CliError> {
        match v {
            Value::Object(m) => Ok(Obj { file: self.file, at: format!("{}[{i}]", self.path(key)), map: Some(m) }),
            v => Err(self.bad(&format!("{key}[{i}]"), "an object", v)),
        }
    }

    fn strings(&self, key: &str) -> Result<Option<Vec<String>>, CliError> {
        let Some(a) = self.array(key)? else { return Ok(None) };
        a.iter()
            .enumerate()
            .map(|(i, v)| v.as_str().map(str::to_owned).ok_or_else(|| self.bad(&format!("{key}[{i}]"), "a string", v)))
            .collect::<Result<Vec<_>, _>>()
            .map(Some)
    }

    fn numbers(&self, key: &str) -> Result<Option<Vec<f64>>, CliError> {
        let Some(a) = self.array(key)? else { return Ok(None) };
        a.iter()
            .enumerate()
            .map(|(i, v)| {
                v.as_f64()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| self.bad(&format!("{key}[{i}]"), "a finite number", v))
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Some)
    }

    fn required<T>(&self, key: &str, v: Option<T>) -> Result<T, CliError> {
        v.ok_or_else(|| CliError::Usage(format!("{}: {}: missing", self.file.display(), self.path(key))))
    }
}

/// Reads and checks the bench JSON at `path`.
pub(super) fn read_input(path: &Path) -> Result<Input, CliError> {
    let bytes = read_regular(path, MAX_BENCH_JSON_BYTES, "bench JSON files")
        .map_err(|e| CliError::Usage(format!("{}: {e}", path.display())))?;
    let json: Value = serde_json::from_slice(&bytes)
        .map_err(|e| CliError::Usage(format!("{}: not bench JSON: {e}", path.display())))?;
    let Value::Object(top) = &json else {
        return Err(CliError::Usage(format!("{}: not bench JSON: the document is {}", path.display(), kind(&json))));
    };
    let j = Obj { file: path, at: String::new(), map: Some(top) };
    let results =
        j.array("results")?.ok_or_else(|| CliError::Usage(format!("{}: no \"results\" array", path.display())))?;
    let mut rows = Vec::with_capacity(results.len());
    for (i, r) in results.iter().enumerate() {
        let r = j.element("results", i, r)?;
        let min_max = r.number("mrays_per_s_min")?.zip(r.number("mrays_per_s_max")?);
        rows.push(Row {
            rays: r.required("rays", r.string("rays")?)?,
            tracer: r.required("tracer", r.string("tracer")?)?,
            method: r.required("method", r.string("method")?)?,
            threads: r.required("threads", r.count("threads")?)?,
            mrays: r.required("mrays_per_s", r.number("mrays_per_s")?)?,
            range: min_max,
        });
    }
    let mut summary = Vec::new();
    for (i, s) in j.array("summary")?.into_iter().flatten().enumerate() {
        let s = j.element("summary", i, s)?;
        summary.push(SummaryRow {
            rays: s.required("rays", s.string("rays")?)?,
            threads: s.required("threads", s.count("threads")?)?,
            raypack_method: s.string("raypack_method")?,
            raypack_mrays: s.number("raypack_mrays_per_s")?,
            embree_method: s.string("embree_method")?,
            embree_mrays: s.number("embree_mrays_per_s")?,
            ratio: s.number("ratio")?,
            ratio_range: s.number("ratio_min")?.zip(s.number("ratio_max")?),
        });
    }
    let build = j.object("build")?;
    let mut builds = Vec::new();
    for (name, b) in build.map.into_iter().flatten() {
        let b = build.element_named(name, b)?;
        builds.push(Build {
            name: name.clone(),
            seconds: b.number("seconds")?,
            bytes_per_triangle: b.number("bytes_per_triangle")?,
            seconds_range: b.number("seconds_min")?.zip(b.number("seconds_max")?),
        });
    }
    let resolution = match j.array("resolution")? {
        None => None,
        Some(a) => match a.as_slice() {
            [w, h] if w.as_u64().is_some() && h.as_u64().is_some() => Some([w.as_u64().unwrap(), h.as_u64().unwrap()]),
            _ => {
                return Err(CliError::Usage(format!(
                    "{}: resolution: expected [width, height] as whole numbers",
                    path.display()
                )));
            }
        },
    };
    let (machine, raypack, load) = (j.object("machine")?, j.object("raypack")?, j.object("load_average")?);
    let embree = match j.get("embree") {
        None => None,
        Some(_) => {
            let e = j.object("embree")?;
            Some((e.string("version")?, e.string("isa")?))
        }
    };
    let scene = j.string("scene")?;
    let commit = raypack.string("commit")?;
    let scene_name = scene.as_deref().map_or("unknown scene".into(), |s| {
        Path::new(s).file_name().map_or(s.to_owned(), |n| n.to_string_lossy().into_owned())
    });
    let label = format!(
        "{scene_name} ({}, {})",
        commit.as_deref().unwrap_or("unknown"),
        path.file_stem().map_or("".into(), |s| s.to_string_lossy())
    );
    Ok(Input {
        label,
        scene,
        triangles: j.count("triangles")?,
        resolution,
        notes: j.strings("notes")?.unwrap_or_default(),
        date: j.string("date")?,
        cpu: machine.string("cpu")?,
        cpu_flags: machine.strings("cpu_flags")?,
        logical_cpus: machine.count("logical_cpus")?,
        memory_bytes: machine.count("memory_bytes")?,
        version: raypack.string("version")?,
        commit,
        isa: raypack.string("isa")?,
        embree,
        busy: j.boolean("busy")?.unwrap_or(false),
        busy_reason: j.string("busy_reason")?,
        load_before: load.numbers("before")?,
        load_after: load.numbers("after")?,
        builds,
        rows,
        summary,
    })
}

impl<'a> Obj<'a> {
    /// Member `name` of this object as an object.
    fn element_named(&self, name: &str, v: &'a Value) -> Result<Obj<'a>, CliError> {
        match v {
            Value::Object(m) => Ok(Obj { file: self.file, at: self.path(name), map: Some(m) }),
            v => Err(self.bad(name, "an object", v)),
        }
    }
}
