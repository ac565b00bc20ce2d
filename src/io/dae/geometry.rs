//! Geometry: `<instance_geometry>` with its material bindings, `<mesh>` sources read through
//! their accessors, the polygon elements (`<triangles>`, `<polylist>`, `<polygons>`,
//! `<trifans>`, `<tristrips>`) triangulated with every index checked, and CMU462/CGL spheres.

use super::Ctx;
use super::scene_graph::project;
use super::xml::{child, children, cmu_technique, describe, elem_path, element_children};
use crate::io::{LoadError, vertex_normals};
use crate::math::{Mat4, Vec3, Vec4};
use crate::scene::{Material, MaterialId};
use roxmltree::Node;
use std::rc::Rc;

/// A parsed `<mesh>`: positions in geometry space and triangles grouped by material symbol.
pub(super) struct ParsedMesh {
    positions: Vec<Vec3>,
    groups: Vec<(Option<String>, Vec<[u32; 3]>)>,
    /// Warnings found while parsing.
    notes: Vec<String>,
}

impl<'a, 'i> Ctx<'a, 'i> {
    pub(super) fn instance_geometry(&mut self, ig: Node<'a, 'i>, world: &Mat4) -> Result<(), LoadError> {
        let geom = self.resolve(ig, "url", "geometry")?;
        let mut bindings = Vec::new();
        if let Some(tc) = child(ig, "bind_material").and_then(|b| child(b, "technique_common")) {
            for im in children(tc, "instance_material") {
                let target = self.resolve(im, "target", "material")?;
                bindings.push((im.attribute("symbol").unwrap_or(""), target));
            }
        }
        if let Some(mesh) = child(geom, "mesh") {
            let parsed = match self.meshes.get(&geom.id()) {
                Some(p) => p.clone(),
                None => {
                    let p = Rc::new(self.parse_mesh(mesh)?);
                    self.warnings.extend(p.notes.iter().cloned());
                    self.meshes.insert(geom.id(), p.clone());
                    p
                }
            };
            let triangles = parsed.groups.iter().map(|(_, t)| t.len()).sum::<usize>();
            self.charge(ig, parsed.positions.len() + triangles)?;
            self.add_primitives(ig, geom, triangles)?;
            let positions: Vec<Vec3> = parsed.positions.iter().map(|&p| project(world, p)).collect();
            let all: Vec<[u32; 3]> = parsed.groups.iter().flat_map(|(_, t)| t.iter().copied()).collect();
            let normals = vertex_normals(&positions, &all);
            // Merge groups that resolve to the same material, then add one mesh per material.
            let mut by_material: Vec<(MaterialId, Vec<[u32; 3]>)> = Vec::new();
            for (symbol, tris) in &parsed.groups {
                let mat = self.bind(&bindings, symbol.as_deref())?;
                match by_material.iter_mut().find(|(m, _)| *m == mat) {
                    Some((_, t)) => t.extend_from_slice(tris),
                    None => by_material.push((mat, tris.clone())),
                }
            }
            for (mat, tris) in by_material {
                self.builder
                    .add_mesh_with_normals(&positions, Some(&normals), &tris, mat)
                    .map_err(|e| self.err(ig, e.to_string()))?;
            }
            return Ok(());
        }
        let radius = cmu_technique(geom).and_then(|t| child(t, "sphere")).map(|s| self.required(s, "radius"));
        match radius {
            Some(r) => {
                self.charge(ig, 1)?;
                self.add_primitives(ig, geom, 1)?;
                let radius = self.number(r?)?;
                let center = project(world, Vec3::ZERO);
                let scale = (*world * Vec4::X).truncate().length();
                let mat = self.bind(&bindings, None)?;
                self.builder.add_sphere(center, radius * scale, mat).map_err(|e| self.err(ig, e.to_string()))?;
            }
            None => self.warn(geom, "no <mesh> and no CMU462/CGL <sphere>: geometry skipped"),
        }
        Ok(())
    }

    /// The material bound to a primitive's symbol (CS184: the first binding).
    fn bind(&mut self, bindings: &[(&str, Node<'a, 'i>)], symbol: Option<&str>) -> Result<MaterialId, LoadError> {
        let chosen = symbol.and_then(|s| bindings.iter().find(|(sym, _)| *sym == s)).or(bindings.first());
        match chosen {
            Some(&(_, m)) => self.material(m),
            None => Ok(*self.default_material.get_or_insert_with(|| self.builder.add_material(Material::default()))),
        }
    }

    fn parse_mesh(&self, mesh: Node<'a, 'i>) -> Result<ParsedMesh, LoadError> {
        let vertices = child(mesh, "vertices");
        let positions = match vertices {
            Some(v) => {
                let input = children(v, "input")
                    .find(|i| i.attribute("semantic") == Some("POSITION"))
                    .ok_or_else(|| self.err(v, "no POSITION input"))?;
                let source = self.mesh_source(mesh, input)?;
                let (data, stride, count) = self.read_source(source, 3)?;
                (0..count).map(|i| Vec3::from_slice(&data[i * stride..i * stride + 3])).collect()
            }
            None => Vec::new(),
        };
        let mut groups = Vec::new();
        let mut notes = Vec::new();
        for prim in element_children(mesh) {
            let tag = prim.tag_name().name();
            // Everything else (<lines>, <linestrips>, <source>, …) has no surface to render.
            if !matches!(tag, "triangles" | "polylist" | "polygons" | "trifans" | "tristrips") {
                continue;
            }
            let tris = self.primitive(mesh, prim, vertices, positions.len(), &mut notes)?;
            groups.push((prim.attribute("material").map(str::to_string), tris));
        }
        Ok(ParsedMesh { positions, groups, notes })
    }

    /// A `<source>` of this mesh named by an input's `source` attribute.
    fn mesh_source(&self, mesh: Node<'a, 'i>, input: Node<'a, 'i>) -> Result<Node<'a, 'i>, LoadError> {
        let src = self.resolve(input, "source", "source")?;
        if src.parent_element() != Some(mesh) {
            return Err(self.err(input, "source belongs to another mesh"));
        }
        Ok(src)
    }

    /// A source's floats through its accessor: `(data from offset, stride, count)`, checked to
    /// hold `count` elements of at least `width` values.
    fn read_source(&self, source: Node, width: usize) -> Result<(Vec<f32>, usize, usize), LoadError> {
        let array = self.required(source, "float_array")?;
        let mut data = self.floats(array)?;
        if let Some(c) = array.attribute("count") {
            let c: usize = c.parse().map_err(|_| self.err(array, format!("count {c:?} is not a whole number")))?;
            if data.len() < c {
                return Err(self.err(array, format!("count says {c} values but the array has {}", data.len())));
            }
            data.truncate(c);
        }
        let accessor = child(source, "technique_common").and_then(|t| child(t, "accessor"));
        let attr = |a: &str, default: usize| -> Result<usize, LoadError> {
            match accessor.and_then(|acc| acc.attribute(a)) {
                None => Ok(default),
                Some(v) => {
                    v.parse().map_err(|_| self.err(accessor.unwrap(), format!("{a} {v:?} is not a whole number")))
                }
            }
        };
        let stride = attr("stride", width)?;
        let offset = attr("offset", 0)?;
        // Checked: offset and stride come from the file (usize::MAX must not wrap around).
        let available = match data.len().checked_sub(offset).and_then(|n| n.checked_sub(width)) {
            Some(rest) if stride > 0 => rest / stride + 1,
            _ => 0,
        };
        let count = attr("count", available)?;
        if stride < width {
            return Err(self.err(accessor.unwrap_or(source), format!("stride {stride} is below {width}")));
        }
        if count > available {
            return Err(self.err(
                accessor.unwrap_or(source),
                format!("{count} elements of stride {stride} need more than the {} values in the array", data.len()),
            ));
        }
        // (`count = 0` passes with any offset.)
        data.drain(..offset.min(data.len()));
        Ok((data, stride, count))
    }

    /// Triangulates one primitive element.
    fn primitive(
        &self,
        mesh: Node<'a, 'i>,
        prim: Node<'a, 'i>,
        vertices: Option<Node<'a, 'i>>,
        num_positions: usize,
        notes: &mut Vec<String>,
    ) -> Result<Vec<[u32; 3]>, LoadError> {
        let tag = prim.tag_name().name();
        let mut stride = 0usize;
        let mut vertex_offset = None;
        let mut checks: Vec<(usize, usize, Node)> = Vec::new(); // (offset, element count, input)
        for input in children(prim, "input") {
            let off: usize = match input.attribute("offset") {
                Some(o) => o.parse().map_err(|_| self.err(input, format!("offset {o:?} is not a whole number")))?,
                None => return Err(self.err(input, "missing attribute offset")),
            };
            if off > 64 {
                return Err(self.err(input, format!("offset {off} is implausibly large")));
            }
            stride = stride.max(off + 1);
            match input.attribute("semantic") {
                Some("VERTEX") => {
                    let v = vertices.ok_or_else(|| self.err(mesh, "a VERTEX input but no <vertices>"))?;
                    let target = self.resolve(input, "source", "vertices")?;
                    if target != v {
                        return Err(self.err(input, "VERTEX input must name this mesh's <vertices>"));
                    }
                    vertex_offset = Some(off);
                }
                Some("NORMAL") => {
                    let src = self.mesh_source(mesh, input)?;
                    let (_, _, n) = self.read_source(src, 3)?;
                    checks.push((off, n, input));
                }
                Some("TEXCOORD") | Some("COLOR") | Some("TEXTANGENT") | Some("TEXBINORMAL") => {
                    self.mesh_source(mesh, input)?;
                }
                _ => {}
            }
        }
        let v_off = vertex_offset.ok_or_else(|| self.err(prim, "no VERTEX input"))?;
        checks.push((v_off, num_positions, prim));

        // Polygon corner lists: (index array, corner counts) per <p>.
        let count = |what: &str| -> Result<usize, LoadError> {
            let c =
                prim.attribute("count").ok_or_else(|| self.err(prim, format!("missing attribute count ({what})")))?;
            c.parse().map_err(|_| self.err(prim, format!("count {c:?} is not a whole number")))
        };
        let mut tris = Vec::new();
        // Indices past the last polygon: the count, `<vcount>` and `<p>` disagree.
        let surplus = |p: Node, idx: &[u32], corners: usize| -> Result<(), LoadError> {
            let used = corners.saturating_mul(stride);
            if idx.len() > used {
                return Err(self.err(
                    p,
                    format!(
                        "has {} indices but the polygons use only {used} ({corners} corners, {stride} inputs per \
                         corner): the polygon count or sizes disagree with <p>",
                        idx.len()
                    ),
                ));
            }
            Ok(())
        };
        let mut emit =
            |p: Node, idx: &[u32], sizes: &mut dyn Iterator<Item = usize>, fan: bool| -> Result<(), LoadError> {
                let need = |corners: usize| corners.saturating_mul(stride);
                let mut base = 0usize; // corner index
                for (poly, n) in sizes.enumerate() {
                    if need(base.saturating_add(n)) > idx.len() {
                        return Err(self.err(
                            p,
                            format!(
                                "has {} indices but the polygons need {} ({} inputs per corner)",
                                idx.len(),
                                need(base.saturating_add(n)),
                                stride
                            ),
                        ));
                    }
                    for &(off, limit, input) in &checks {
                        for k in 0..n {
                            let i = idx[(base + k) * stride + off] as usize;
                            if i >= limit {
                                let what = if input == prim { "vertex".to_string() } else { describe(input) };
                                return Err(self.err(
                                    p,
                                    format!("polygon {poly} corner {k}: {what} index {i} out of range (only {limit})"),
                                ));
                            }
                        }
                    }
                    let corner = |k: usize| idx[(base + k) * stride + v_off];
                    for k in 2..n {
                        tris.push(if fan {
                            [corner(0), corner(k - 1), corner(k)]
                        } else if k % 2 == 0 {
                            [corner(k - 2), corner(k - 1), corner(k)]
                        } else {
                            [corner(k - 1), corner(k - 2), corner(k)]
                        });
                    }
                    base += n;
                }
                Ok(())
            };
        match tag {
            "triangles" => {
                let n = count("triangles")?;
                let p = self.required(prim, "p");
                if n == 0 && p.is_err() {
                    return Ok(tris);
                }
                let p = p?;
                let idx = self.indices(p)?;
                emit(p, &idx, &mut std::iter::repeat_n(3, n), true)?;
                surplus(p, &idx, n.saturating_mul(3))?;
            }
            "polylist" => {
                let n = count("polygons")?;
                let vc = self.required(prim, "vcount")?;
                let sizes = self.indices(vc)?;
                if sizes.len() != n {
                    return Err(self.err(vc, format!("{} polygon sizes for count {n}", sizes.len())));
                }
                let p = child(prim, "p");
                if n == 0 && p.is_none() {
                    return Ok(tris);
                }
                let p = self.required(prim, "p")?;
                let idx = self.indices(p)?;
                emit(p, &idx, &mut sizes.iter().map(|&s| s as usize), true)?;
                surplus(p, &idx, sizes.iter().fold(0usize, |a, &s| a.saturating_add(s as usize)))?;
            }
            "polygons" | "trifans" | "tristrips" => {
                for p in children(prim, "p") {
                    let idx = self.indices(p)?;
                    if stride == 0 || idx.len() % stride != 0 {
                        return Err(self.err(p, format!("{} indices is not a multiple of {stride} inputs", idx.len())));
                    }
                    emit(p, &idx, &mut std::iter::once(idx.len() / stride), tag != "tristrips")?;
                }
                if child(prim, "ph").is_some() {
                    notes.push(format!("{}: polygons with holes (<ph>) are skipped", elem_path(prim)));
                }
            }
            _ => unreachable!("filtered by the caller"),
        }
        Ok(tris)
    }
}
