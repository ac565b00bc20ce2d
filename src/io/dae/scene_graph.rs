//! The scene graph: the up axis, node transforms in document order, the node hierarchy with
//! `instance_node`, and the guards on what a document may make the loader do (nesting depth,
//! `instance_node` cycles, the instancing budget and `--max-primitives`).

use super::Ctx;
use super::xml::{child, elem_path, element_children};
use crate::io::LoadError;
use crate::math::{Mat3, Mat4, Vec3};
use roxmltree::Node;

/// Deepest node nesting (including `instance_node` indirections) accepted: deeper files are
/// rejected instead of overflowing the stack.
pub const MAX_NODE_DEPTH: usize = 256;

/// What instancing may expand a document to, in node visits plus instanced vertices,
/// triangles and spheres: `max(MIN_INSTANCING_BUDGET, INSTANCING_BUDGET_PER_BYTE × file size)`,
/// or [`BUDGET_PER_ALLOWED_PRIMITIVE`] units per primitive when that is more and
/// [`DaeOptions::max_primitives`](super::DaeOptions::max_primitives) is set. `instance_node` and `instance_geometry` multiply: 30
/// nested nodes that each instance the next twice are 2³⁰ copies from a 2 kB file. Without a
/// cap such a file takes hours and all memory; with it, an error names the element where the
/// budget ran out. A legitimate file may still expand a lot (a file of a few hundred kB to
/// millions of triangles): the loader's warnings report every expansion.
pub const INSTANCING_BUDGET_PER_BYTE: usize = 64;
/// The smallest instancing budget (see [`INSTANCING_BUDGET_PER_BYTE`]).
pub const MIN_INSTANCING_BUDGET: usize = 1 << 20;
/// Instancing that adds at least this many primitives to those the file defines is reported
/// in a warning (how many geometries, how many primitives, by what factor).
pub const REPORTED_EXPANSION: u64 = 1 << 20;
/// Instancing budget units per primitive that [`DaeOptions::max_primitives`](super::DaeOptions::max_primitives) allows: room for
/// a triangle soup's three vertices and the triangle itself.
pub const BUDGET_PER_ALLOWED_PRIMITIVE: usize = 4;

/// The instancing budget of a document of `len` bytes (see [`INSTANCING_BUDGET_PER_BYTE`]).
pub fn instancing_budget(len: usize) -> usize {
    MIN_INSTANCING_BUDGET.max(INSTANCING_BUDGET_PER_BYTE.saturating_mul(len))
}

/// The budget of a document of `len` bytes when at most `max_primitives` may be instanced.
pub(super) fn budget_of(len: usize, max_primitives: Option<u64>) -> usize {
    let allowed = max_primitives
        .map_or(0, |n| usize::try_from(n).unwrap_or(usize::MAX).saturating_mul(BUDGET_PER_ALLOWED_PRIMITIVE));
    instancing_budget(len).max(allowed)
}

/// `m · (p, 1)` with the homogeneous divide (`projectTo3D`).
pub(super) fn project(m: &Mat4, p: Vec3) -> Vec3 {
    let h = *m * p.extend(1.0);
    if h.w != 0.0 && h.w != 1.0 { h.truncate() / h.w } else { h.truncate() }
}

impl<'a, 'i> Ctx<'a, 'i> {
    pub(super) fn up_axis(&self, root: Node) -> Result<Mat4, LoadError> {
        let Some(up) = child(root, "asset").and_then(|a| child(a, "up_axis")) else {
            return Ok(Mat4::IDENTITY);
        };
        let m = |c0: [f32; 3], c1: [f32; 3], c2: [f32; 3]| {
            Mat4::from_mat3(Mat3::from_cols(Vec3::from(c0), Vec3::from(c1), Vec3::from(c2)))
        };
        match up.text().unwrap_or("").trim() {
            "Y_UP" => Ok(Mat4::IDENTITY),
            "Z_UP" => Ok(m([-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0])),
            "X_UP" => Ok(m([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0])),
            other => Err(self.err(up, format!("unknown up axis {other:?} (expected X_UP, Y_UP or Z_UP)"))),
        }
    }

    /// The node's own transform: its transform elements composed in document order.
    fn local_transform(&mut self, node: Node) -> Result<Mat4, LoadError> {
        let mut notes = Vec::new();
        let mut m = Mat4::IDENTITY;
        for e in element_children(node) {
            let need = |k: usize| -> Result<Vec<f32>, LoadError> {
                let v = self.floats(e)?;
                if v.len() < k {
                    return Err(self.err(e, format!("expected {k} numbers, found {}", v.len())));
                }
                if !v.iter().all(|x| x.is_finite()) {
                    return Err(self.err(e, "values must be finite"));
                }
                Ok(v)
            };
            let t = match e.tag_name().name() {
                "matrix" => {
                    // CS184's own sky/CBgems.dae has a 15-value camera matrix; CS184's parser
                    // (C++ stream extraction) reads the missing value as 0, and so do we.
                    let mut v = need(1)?;
                    if v.len() < 16 {
                        notes.push(format!(
                            "{}: {} of 16 values; the missing ones are taken as 0, as CS184 does",
                            elem_path(e),
                            v.len()
                        ));
                        v.resize(16, 0.0);
                    }
                    Mat4::from_cols_array(&v[..16].try_into().expect("16 values")).transpose()
                }
                "translate" => {
                    let v = need(3)?;
                    Mat4::from_translation(Vec3::new(v[0], v[1], v[2]))
                }
                "scale" => {
                    let v = need(3)?;
                    Mat4::from_scale(Vec3::new(v[0], v[1], v[2]))
                }
                "rotate" => {
                    let v = need(4)?;
                    let axis = Vec3::new(v[0], v[1], v[2])
                        .try_normalize()
                        .ok_or_else(|| self.err(e, "rotation axis has zero length"))?;
                    Mat4::from_axis_angle(axis, v[3].to_radians())
                }
                "lookat" => {
                    let v = need(9)?;
                    let (eye, at, up) =
                        (Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5]), Vec3::new(v[6], v[7], v[8]));
                    // Camera-to-parent: x = right, y = up, z = backward, origin = eye.
                    let f = (at - eye).try_normalize();
                    let right = f.and_then(|f| f.cross(up).try_normalize());
                    let (Some(f), Some(right)) = (f, right) else {
                        return Err(self.err(e, "degenerate lookat (eye = interest, or up parallel to the view)"));
                    };
                    Mat4::from_cols(right.extend(0.0), right.cross(f).extend(0.0), (-f).extend(0.0), eye.extend(1.0))
                }
                "skew" => {
                    return Err(self.err(e, "<skew> is not supported"));
                }
                _ => continue,
            };
            m *= t;
        }
        self.warnings.append(&mut notes);
        Ok(m)
    }

    /// Takes `amount` from the instancing budget, or fails naming `at`.
    pub(super) fn charge(&mut self, at: Node, amount: usize) -> Result<(), LoadError> {
        match self.budget.checked_sub(amount) {
            Some(rest) => {
                self.budget = rest;
                Ok(())
            }
            None => Err(self.err(
                at,
                format!(
                    "instancing expands the scene past {} node visits, vertices, triangles and spheres (the cap for \
                     a file of {} bytes: {INSTANCING_BUDGET_PER_BYTE} per byte, at least {MIN_INSTANCING_BUDGET}, \
                     or {BUDGET_PER_ALLOWED_PRIMITIVE} per primitive --max-primitives allows)",
                    self.total_budget, self.file_len
                ),
            )),
        }
    }

    /// Counts `count` more primitives of geometry `geom` instanced at `at`, or fails when
    /// that passes [`DaeOptions::max_primitives`](super::DaeOptions::max_primitives).
    pub(super) fn add_primitives(&mut self, at: Node, geom: Node, count: usize) -> Result<(), LoadError> {
        self.defined.insert(geom.id(), count);
        self.primitives = self.primitives.saturating_add(count as u64);
        match self.max_primitives {
            Some(max) if self.primitives > max => Err(self.err(
                at,
                format!(
                    "this instance brings the scene to {} triangles and spheres, more than --max-primitives {max}",
                    self.primitives
                ),
            )),
            _ => Ok(()),
        }
    }

    pub(super) fn visit_node(&mut self, node: Node<'a, 'i>, parent: Mat4, depth: usize) -> Result<(), LoadError> {
        if depth > MAX_NODE_DEPTH {
            return Err(self.err(node, format!("nodes nested deeper than {MAX_NODE_DEPTH}")));
        }
        self.charge(node, 1)?;
        let world = parent * self.local_transform(node)?;
        self.visiting.push(node.id());
        // Children first, then this node's own instances: CS184's order.
        for c in element_children(node) {
            match c.tag_name().name() {
                "node" => self.visit_node(c, world, depth + 1)?,
                "instance_node" => {
                    let target = self.resolve(c, "url", "node")?;
                    if self.visiting.contains(&target.id()) {
                        let url = c.attribute("url").unwrap_or("");
                        return Err(
                            self.err(c, format!("instance_node cycle: {url} is this node or one containing it"))
                        );
                    }
                    self.visit_node(target, world, depth + 1)?;
                }
                _ => {}
            }
        }
        self.visiting.pop();
        for c in element_children(node) {
            match c.tag_name().name() {
                "instance_geometry" => self.instance_geometry(c, &world)?,
                "instance_light" => self.instance_light(c, &world)?,
                "instance_camera" => self.instance_camera(c, &world)?,
                "instance_controller" => {
                    self.warn(c, "skinned/morphed geometry (instance_controller) is not supported")
                }
                _ => {}
            }
        }
        Ok(())
    }
}
