//! Wavefront OBJ through the `tobj` crate: polygons triangulated (fans), one index per
//! `v/vt/vn` corner, materials from the MTL libraries named by `mtllib` (diffuse `Kd` →
//! Lambertian albedo, emission `Ke` → emitted radiance). A missing or broken MTL file is a
//! warning, not an error: the meshes keep the default grey material.
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
/// returns the library's bytes (or `None` when it cannot be read).
pub fn parse_obj(
    bytes: &[u8],
    path: &Path,
    read_mtl: &dyn Fn(&Path) -> Option<Vec<u8>>,
) -> Result<(SceneBuilder, Vec<String>), LoadError> {
    check_faces(bytes, path)?;
    let opts = tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
    let mut warnings = Vec::new();
    let mtl_notes = std::cell::RefCell::new(Vec::new());
    let mut reader = std::io::Cursor::new(bytes);
    let result = tobj::load_obj_buf(&mut reader, &opts, |mtl_path| match read_mtl(mtl_path) {
        Some(data) => match check_mtl(&data) {
            Ok(()) => tobj::load_mtl_buf(&mut std::io::Cursor::new(data)),
            Err(problem) => {
                mtl_notes.borrow_mut().push(format!("material library {}: {problem}", mtl_path.display()));
                Err(tobj::LoadError::MaterialParseError)
            }
        },
        None => {
            mtl_notes.borrow_mut().push(format!(
                "material library {} not found (or not a regular file of at most 64 MiB)",
                mtl_path.display()
            ));
            Err(tobj::LoadError::OpenFileFailed)
        }
    });
    let (models, materials) = result.map_err(|e| locate_error(bytes, path, e))?;
    let mtl_notes = mtl_notes.into_inner();
    for m in &mtl_notes {
        warnings.push(format!("{m}; using the default material"));
    }
    let materials = materials.unwrap_or_else(|e| {
        if mtl_notes.is_empty() {
            warnings.push(format!("material library unreadable ({e}); using the default material"));
        }
        Vec::new()
    });

    let mut b = SceneBuilder::new();
    let default = b.add_material(Material::default());
    let ids: Vec<MaterialId> = materials
        .iter()
        .map(|m| {
            let kd = m.diffuse.map(Vec3::from_array).unwrap_or(Vec3::splat(0.5));
            let ke = m.emissive.map(Vec3::from_array).unwrap_or(Vec3::ZERO);
            let mut mat = Material::diffuse(kd.clamp(Vec3::ZERO, Vec3::ONE)).named(&m.name);
            mat.emission = ke.max(Vec3::ZERO);
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

/// Finds what `tobj` cannot take in an MTL library: a colour statement (`Ka`, `Kd`, `Ks`,
/// `Ke`) with fewer than three values makes `tobj` 4.0.5 panic (`parse_float3` unwraps;
/// found by fuzzing). Returns the first such line and what is wrong with it.
fn check_mtl(bytes: &[u8]) -> Result<(), String> {
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let text = String::from_utf8_lossy(line);
        let mut words = text.split_whitespace();
        if let Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) = words.next() {
            let n = words.count();
            if n < 3 {
                return Err(format!("line {}: {key} needs 3 values, found {n}", i + 1));
            }
        }
    }
    Ok(())
}

/// Checks every `f` and `l` statement before `tobj` sees it: a face needs at least three
/// corners (`tobj` silently reads shorter ones as points or lines: in OBJ they are malformed,
/// and typically the last line of a truncated file), and every index must name an element that
/// exists: `0`, one past the file's count, or a relative (negative) one reaching before the
/// first element is an error naming the line. `tobj` 4.0.5 turns such indices into `usize`
/// values near `2⁶⁴` and multiplies them unchecked (a panic with overflow checks on; found by
/// fuzzing).
fn check_faces(bytes: &[u8], path: &Path) -> Result<(), LoadError> {
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
            Some("f") | Some("l") => {
                let corners: Vec<&str> = words.collect();
                if keyword == Some("f") && corners.len() < 3 {
                    return Err(LoadError::at_line(
                        path,
                        i + 1,
                        format!("a face needs at least 3 corners, found {} (truncated file?)", corners.len()),
                    ));
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
    Ok(())
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
