//! The layer rule of CONTRIBUTING.md ("nothing imports backwards"), checked on the sources:
//! the table in its section "1. Layers" is parsed, so the document is the rule. Every
//! `crate::…` path in the library's modules (`src/**/*.rs` outside `src/bin`: `use` lines,
//! paths in code, in unit tests and in doc links alike) must name a module of the same layer
//! or of one before it. A name the crate root re-exports (`crate::Scene`) counts as the module
//! it comes from.

use std::collections::HashMap;
mod common;
use common::rust_sources;
use std::path::Path;

/// The layers of CONTRIBUTING.md's table, in order: each row's backquoted module names.
fn layer_table(contributing: &str) -> Vec<(String, Vec<String>)> {
    let section = contributing
        .split("\n## ")
        .find(|s| s.starts_with("1. Layers"))
        .expect("CONTRIBUTING.md has no section '## 1. Layers'");
    let mut layers = Vec::new();
    for row in section.lines().filter(|l| l.starts_with('|')) {
        let cells: Vec<&str> = row.trim_matches('|').split('|').map(str::trim).collect();
        if cells.len() < 2 || cells[0] == "layer" || cells[0].starts_with("---") {
            continue;
        }
        let modules: Vec<String> = cells[1]
            .split('`')
            .skip(1)
            .step_by(2)
            .filter(|m| !m.is_empty() && m.bytes().all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_'))
            .map(String::from)
            .collect();
        if !modules.is_empty() {
            layers.push((cells[0].to_string(), modules));
        }
    }
    layers
}

fn ident_at(s: &str) -> &str {
    let end = s.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(s.len());
    &s[..end]
}

/// The first name of every path that follows `crate::` in `text`, with its byte offset: for
/// `crate::{a::b, C}` both `a` and `C`.
fn crate_paths(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (at, _) in text.match_indices("crate::") {
        // `raypack_crate::`, `$crate::` and the like are other paths.
        if text[..at].ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_' || c == '$') {
            continue;
        }
        let rest = &text[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let (mut depth, mut start) = (0usize, 0usize);
            for (i, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => {
                        out.push((at, ident_at(group[start..i].trim_start()).to_string()));
                        break;
                    }
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        out.push((at, ident_at(group[start..i].trim_start()).to_string()));
                        start = i + 1;
                    }
                    _ => {}
                }
            }
        } else {
            out.push((at, ident_at(rest).to_string()));
        }
    }
    out.retain(|(_, name)| !name.is_empty());
    out
}

/// What the crate root re-exports: `Scene` → `scene`, from lib.rs's `pub use MODULE::…` lines.
fn root_reexports(lib: &str) -> HashMap<String, String> {
    let mut names = HashMap::new();
    for item in lib.split("pub use ").skip(1) {
        let item = &item[..item.find(';').unwrap_or(item.len())];
        let module = ident_at(item).to_string();
        let tail = item[module.len()..].trim_start_matches("::");
        for name in tail.trim_matches(|c| c == '{' || c == '}').split(',') {
            let name = name.trim().rsplit("::").next().unwrap().trim();
            if !name.is_empty() {
                names.insert(name.to_string(), module.clone());
            }
        }
    }
    names
}

#[test]
fn nothing_imports_backwards() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let contributing = std::fs::read_to_string(root.join("CONTRIBUTING.md")).unwrap();
    let table = layer_table(&contributing);
    assert!(table.len() >= 5, "CONTRIBUTING.md's layer table was not found: {table:?}");
    let layer_of: HashMap<&str, usize> =
        table.iter().enumerate().flat_map(|(i, (_, ms))| ms.iter().map(move |m| (m.as_str(), i))).collect();

    let lib = std::fs::read_to_string(root.join("src/lib.rs")).unwrap();
    // Every module the crate root declares has its row.
    for line in lib.lines() {
        if let Some(m) = line.trim().strip_prefix("pub mod ").or_else(|| line.trim().strip_prefix("mod ")) {
            let m = m.trim_end_matches(';');
            assert!(layer_of.contains_key(m), "src/lib.rs declares `{m}`, which CONTRIBUTING.md's layer table lacks");
        }
    }
    let reexports = root_reexports(&lib);

    let files = rust_sources(&[&root.join("src")]);
    let mut offences = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/");
        let Some(inside) = rel.strip_prefix("src/") else { continue };
        if inside.starts_with("bin/") || inside == "lib.rs" {
            continue;
        }
        let module = ident_at(inside);
        let Some(&own) = layer_of.get(module) else {
            offences.push(format!("{rel}: module `{module}` is not in CONTRIBUTING.md's layer table"));
            continue;
        };
        let text = std::fs::read_to_string(f).unwrap();
        let code: String = text
            .split("#[cfg(test)]\nmod tests")
            .next()
            .unwrap()
            .lines()
            .map(|l| if l.trim_start().starts_with("//") { "\n".to_string() } else { format!("{l}\n") })
            .collect();
        for (at, name) in crate_paths(&code) {
            let target = reexports.get(&name).map_or(name.as_str(), String::as_str);
            let Some(&layer) = layer_of.get(target) else { continue };
            if layer > own {
                let line = code[..at].matches('\n').count() + 1;
                offences.push(format!(
                    "{rel}:{line}: `{module}` ({}) uses crate::{name} ({}, a later layer)",
                    table[own].0, table[layer].0
                ));
            }
        }
    }
    assert!(offences.is_empty(), "backward imports (CONTRIBUTING.md, 1. Layers):\n{}", offences.join("\n"));
}

#[test]
fn the_parser_sees_grouped_and_re_exported_paths() {
    let paths = crate_paths("use crate::{bvh::Bvh8, Scene};\nlet x = crate::math::Vec3::ZERO; $crate::no");
    let names: Vec<&str> = paths.iter().map(|(_, n)| n.as_str()).collect();
    assert_eq!(names, ["bvh", "Scene", "math"]);
    let re = root_reexports("pub use scene::{\n    Bsdf, Scene,\n};\npub use simd::Isa;");
    assert_eq!((re["Scene"].as_str(), re["Bsdf"].as_str(), re["Isa"].as_str()), ("scene", "scene", "simd"));
}
