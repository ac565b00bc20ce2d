//! Wavefront OBJ through the `tobj` crate: polygons triangulated (fans), one index per
//! `v/vt/vn` corner, materials from the MTL libraries named by `mtllib` (diffuse `Kd` →
//! Lambertian albedo, emission `Ke` → emitted radiance). A missing or broken MTL file is a
//! warning, not an error: the meshes keep the default grey material. So are the other
//! substitutions, each said in a warning: a `Kd` outside `[0, 1]` or a negative `Ke` is
//! clamped, a `usemtl` naming no material takes the default one, and polylines (`l`), which
//! have no surface, are skipped (`tobj` would read them as faces).
//!
//! `tobj` reports what went wrong but not where; on an error this module scans the text once
//! more to find the first line that shows the problem, so the error names the line.
//!
//! Before `tobj` sees a file, face and line indices are checked (`check_faces`) and MTL colour
//! statements too (`check_mtl`): `tobj` 4.0.5 overflows on out-of-range relative indices and
//! panics on `Kd` with fewer than three values (both found by fuzzing, `fuzz/`).

use crate::io::{LoadError, vertex_normals};
use crate::math::Vec3;
use crate::scene::{Material, MaterialId, SceneBuilder};
use std::path::Path;

/// Parses OBJ text. MTL libraries are looked up beside `path` through `read_mtl`, which
/// returns the library's bytes or why it cannot be read.
pub fn parse_obj(
    bytes: &[u8],
    path: &Path,
    read_mtl: &dyn Fn(&Path) -> Result<Vec<u8>, String>,
) -> Result<(SceneBuilder, Vec<String>), LoadError> {
    parse_obj_with_limit(bytes, path, read_mtl, None)
}

/// [`parse_obj`] that fails, naming the line, once the faces make more than `max_triangles`
/// triangles (checked before anything is allocated for them).
pub fn parse_obj_with_limit(
    bytes: &[u8],
    path: &Path,
    read_mtl: &dyn Fn(&Path) -> Result<Vec<u8>, String>,
    max_triangles: Option<u64>,
) -> Result<(SceneBuilder, Vec<String>), LoadError> {
    let scan = check_faces(bytes, path, max_triangles)?;
    let mut warnings = Vec::new();
    // Polylines have no surface: blanked (line numbers kept) so that tobj does not fill them.
    let without_lines;
    let bytes = match scan.polylines.first() {
        None => bytes,
        Some(&first) => {
            warnings.push(format!(
                "{} polylines (`l` statements, the first at line {first}) skipped: lines have no surface to render",
                scan.polylines.len()
            ));
            without_lines = blank_lines(bytes, &scan.polylines);
            &without_lines[..]
        }
    };
    let opts = tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
    let mtl_notes = std::cell::RefCell::new(Vec::new());
    let mut reader = std::io::Cursor::new(bytes);
    let result = tobj::load_obj_buf(&mut reader, &opts, |mtl_path| match read_mtl(mtl_path) {
        Ok(data) => match check_mtl(&data) {
            Ok(()) => tobj::load_mtl_buf(&mut std::io::Cursor::new(data)),
            Err(problem) => {
                mtl_notes.borrow_mut().push(format!("material library {}: {problem}", mtl_path.display()));
                Err(tobj::LoadError::MaterialParseError)
            }
        },
        Err(why) => {
            mtl_notes.borrow_mut().push(format!("material library {}: {why}", mtl_path.display()));
            Err(tobj::LoadError::OpenFileFailed)
        }
    });
    let (models, materials) = result.map_err(|e| locate_error(bytes, path, e))?;
    let mtl_notes = mtl_notes.into_inner();
    for m in &mtl_notes {
        warnings.push(format!("{m}; using the default material"));
    }
    let libraries_read = materials.is_ok();
    let materials = materials.unwrap_or_else(|e| {
        if mtl_notes.is_empty() {
            warnings.push(format!("material library unreadable ({e}); using the default material"));
        }
        Vec::new()
    });
    if libraries_read {
        // (When a library could not be read, its warning already says what every `usemtl` gets.)
        let mut reported = std::collections::HashSet::new();
        for (line, name) in &scan.usemtl {
            if !materials.iter().any(|m| &m.name == name) && reported.insert(name) {
                warnings.push(format!(
                    "line {line}: usemtl {name:?}: no material of that name in the material libraries; using the \
                     default material"
                ));
            }
        }
    }

    let mut b = SceneBuilder::new();
    let default = b.add_material(Material::default());
    let ids: Vec<MaterialId> = materials
        .iter()
        .map(|m| {
            let kd = m.diffuse.map(Vec3::from_array).unwrap_or(Vec3::splat(0.5));
            let ke = m.emissive.map(Vec3::from_array).unwrap_or(Vec3::ZERO);
            let (albedo, emission) = (kd.clamp(Vec3::ZERO, Vec3::ONE), ke.max(Vec3::ZERO));
            if albedo != kd {
                warnings.push(format!(
                    "material {:?}: Kd {} {} {} outside [0, 1]; clamped to {} {} {}",
                    m.name, kd.x, kd.y, kd.z, albedo.x, albedo.y, albedo.z
                ));
            }
            if emission != ke {
                warnings.push(format!(
                    "material {:?}: Ke {} {} {} is negative; clamped to {} {} {}",
                    m.name, ke.x, ke.y, ke.z, emission.x, emission.y, emission.z
                ));
            }
            let mut mat = Material::diffuse(albedo).named(&m.name);
            mat.emission = emission;
            b.add_material(mat)
        })
        .collect();

    for model in &models {
        let mesh = &model.mesh;
        let positions: Vec<Vec3> = mesh.positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        let triangles: Vec<[u32; 3]> = mesh.indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let file_normals = mesh.normals.len() == mesh.positions.len() && !mesh.normals.is_empty();
        let normals = if file_normals {
            mesh.normals.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2]).normalize_or_zero()).collect()
        } else {
            vertex_normals(&positions, &triangles)
        };
        let mat = mesh.material_id.and_then(|i| ids.get(i).copied()).unwrap_or(default);
        b.add_mesh_with_normals(&positions, Some(&normals), &triangles, mat)
            .map_err(|e| LoadError::parse(path, format!("object {:?}", model.name), e.to_string()))?;
    }
    Ok((b, warnings))
}

/// Finds what `tobj` cannot take in an MTL library, or what would make nonsense of it: a
/// colour statement (`Ka`, `Kd`, `Ks`, `Ke`) with fewer than three values makes `tobj` 4.0.5
/// panic (`parse_float3` unwraps; found by fuzzing), and one with a NaN or infinite value
/// would be read as it is. Returns the first such line and what is wrong with it.
fn check_mtl(bytes: &[u8]) -> Result<(), String> {
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let text = String::from_utf8_lossy(line);
        let mut words = text.split_whitespace();
        if let Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) = words.next() {
            let values: Vec<&str> = words.collect();
            if values.len() < 3 {
                return Err(format!("line {}: {key} needs 3 values, found {}", i + 1, values.len()));
            }
            if let Some(v) = values.iter().take(3).find(|v| v.parse::<f32>().is_ok_and(|x| !x.is_finite())) {
                return Err(format!("line {}: {key} value {v} is not a finite number", i + 1));
            }
        }
    }
    Ok(())
}

/// `bytes` with the given lines (1-based) emptied, every newline kept.
fn blank_lines(bytes: &[u8], lines: &[usize]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len());
    let mut blank = lines.iter().peekable();
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        if i > 0 {
            out.push(b'\n');
        }
        if blank.next_if_eq(&&(i + 1)).is_none() {
            out.extend_from_slice(line);
        }
    }
    out
}

/// What [`check_faces`] found besides errors.
struct FaceScan {
    /// Lines (1-based) of `l` statements.
    polylines: Vec<usize>,
    /// `usemtl` statements: line and material name (as `tobj` reads it).
    usemtl: Vec<(usize, String)>,
}

/// Checks every `f` and `l` statement before `tobj` sees it: a face needs at least three
/// corners (`tobj` silently reads shorter ones as points or lines: in OBJ they are malformed,
/// and typically the last line of a truncated file), and every index must name an element that
/// exists: `0`, one past the file's count, or a relative (negative) one reaching before the
/// first element is an error naming the line. `tobj` 4.0.5 turns such indices into `usize`
/// values near `2⁶⁴` and multiplies them unchecked (a panic with overflow checks on; found by
/// fuzzing). The faces' fan triangles are counted against `max_triangles`.
fn check_faces(bytes: &[u8], path: &Path, max_triangles: Option<u64>) -> Result<FaceScan, LoadError> {
    let mut scan = FaceScan { polylines: Vec::new(), usemtl: Vec::new() };
    let mut triangles = 0u64;
    let lines = || bytes.split(|&b| b == b'\n').map(String::from_utf8_lossy);
    let mut total = [0i64; 3];
    for line in lines() {
        match line.split_whitespace().next() {
            Some("v") => total[0] += 1,
            Some("vt") => total[1] += 1,
            Some("vn") => total[2] += 1,
            _ => {}
        }
    }
    let mut seen = [0i64; 3];
    for (i, line) in lines().enumerate() {
        let mut words = line.split_whitespace();
        let keyword = words.next();
        match keyword {
            Some("v") => seen[0] += 1,
            Some("vt") => seen[1] += 1,
            Some("vn") => seen[2] += 1,
            Some("usemtl") => {
                let name = line.trim_start().split_once(' ').unwrap_or_default().1.trim();
                scan.usemtl.push((i + 1, name.to_string()));
            }
            Some("f") | Some("l") => {
                let corners: Vec<&str> = words.collect();
                if keyword == Some("f") && corners.len() < 3 {
                    return Err(LoadError::at_line(
                        path,
                        i + 1,
                        format!("a face needs at least 3 corners, found {} (truncated file?)", corners.len()),
                    ));
                }
                if keyword == Some("l") {
                    scan.polylines.push(i + 1);
                } else {
                    triangles += corners.len() as u64 - 2;
                    if let Some(max) = max_triangles.filter(|&max| triangles > max) {
                        return Err(LoadError::at_line(
                            path,
                            i + 1,
                            format!("the faces so far make {triangles} triangles, more than --max-primitives {max}"),
                        ));
                    }
                }
                for c in corners {
                    for (k, part) in c.split('/').enumerate().take(3) {
                        // Empty (`v//vn`) and malformed parts are tobj's to report.
                        let Ok(index) = part.parse::<i64>() else { continue };
                        let what = ["vertex", "texture coordinate", "normal"][k];
                        let bad = if index > 0 { index > total[k] } else { index == 0 || -index > seen[k] };
                        if bad {
                            let have = if index < 0 { seen[k] } else { total[k] };
                            let before = if index < 0 { " before this line" } else { "" };
                            return Err(LoadError::at_line(
                                path,
                                i + 1,
                                format!("{what} index {index} out of range: the file has {have}{before}"),
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(scan)
}

/// Turns a `tobj` error into one that names the first offending line.
fn locate_error(bytes: &[u8], path: &Path, e: tobj::LoadError) -> LoadError {
    use tobj::LoadError as E;
    let text = String::from_utf8_lossy(bytes);
    let lines: Vec<&str> = text.lines().collect();
    let total = |tag: &str| lines.iter().filter(|l| l.split_whitespace().next() == Some(tag)).count() as i64;
    let (nv, nt, nn) = (total("v"), total("vt"), total("vn"));
    let floats_ok = |l: &str, min: usize| {
        let f: Vec<_> = l.split_whitespace().skip(1).collect();
        f.len() >= min && f.iter().all(|t| t.parse::<f32>().is_ok())
    };
    // Checks one `f` line: arity, syntax and index ranges; returns what is wrong.
    let face_problem = |l: &str| -> Option<String> {
        let corners: Vec<_> = l.split_whitespace().skip(1).collect();
        if corners.len() < 3 {
            return Some(format!("a face needs at least 3 corners, found {}", corners.len()));
        }
        for c in corners {
            for (k, part) in c.split('/').enumerate() {
                if part.is_empty() && k > 0 {
                    continue;
                }
                let Ok(i) = part.parse::<i64>() else {
                    return Some(format!("bad face corner {c:?}"));
                };
                let n = [nv, nt, nn].get(k).copied().unwrap_or(0);
                let what = ["vertex", "texture coordinate", "normal"].get(k).copied().unwrap_or("index");
                if i == 0 || i > n || i < -n {
                    return Some(format!("{what} index {i} out of range: the file has {n}"));
                }
            }
        }
        None
    };
    let find = |pred: &dyn Fn(&str) -> Option<String>| {
        lines.iter().enumerate().find_map(|(i, l)| pred(l.trim()).map(|m| (i + 1, m)))
    };
    let located = match e {
        E::PositionParseError => {
            find(&|l| (l.starts_with("v ") && !floats_ok(l, 3)).then(|| "bad vertex position".to_string()))
        }
        E::NormalParseError => find(&|l| (l.starts_with("vn") && !floats_ok(l, 3)).then(|| "bad normal".to_string())),
        E::TexcoordParseError => {
            find(&|l| (l.starts_with("vt") && !floats_ok(l, 1)).then(|| "bad texture coordinate".to_string()))
        }
        E::FaceParseError
        | E::InvalidPolygon
        | E::FaceVertexOutOfBounds
        | E::FaceTexCoordOutOfBounds
        | E::FaceNormalOutOfBounds => find(&|l| if l.starts_with("f ") { face_problem(l) } else { None }),
        _ => None,
    };
    match located {
        Some((line, msg)) => LoadError::at_line(path, line, format!("{msg} ({e})")),
        None => LoadError::parse(path, format!("line {}", lines.len().max(1)), format!("malformed OBJ: {e}")),
    }
}
