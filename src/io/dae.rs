//! COLLADA 1.4.1 (`.dae`) as the CS184 / CMU 15-462 path tracer reads it, parsed with
//! `roxmltree`.
//!
//! What this follows, from the CS184 sources (`src/collada/collada.cpp`, `light_info.cpp`,
//! `application.cpp`, `camera.cpp`, `dynamic_scene/{area,point,spot,directional}_light.h`,
//! `dynamic_scene/{mesh,sphere}.cpp`, `static_scene/object.cpp`):
//!
//! * **Up axis.** `<asset><up_axis>` `Z_UP` enters the hierarchy under the matrix with rows
//!   `(-1 0 0)(0 0 1)(0 1 0)` (swap y and z, negate x), `X_UP` under `(0 1 0)(1 0 0)(0 0 -1)`;
//!   `Y_UP` (the default) is CS184's own convention. World = up matrix · node transforms.
//! * **Nodes.** The `<library_visual_scenes>` hierarchy under `<scene><instance_visual_scene>`;
//!   child nodes and `instance_node`s inherit the parent's transform; instances of a node are
//!   gathered after its children, as CS184 does. A node's `<matrix>` (row-major), `<translate>`,
//!   `<rotate>` (axis, degrees), `<scale>` and `<lookat>` compose in document order as the
//!   COLLADA spec says (`M = T1 · T2 · …`). CS184's parser keeps only a `<matrix>` and
//!   pre-multiplies the others with misread rotations; every CS184 scene uses `<matrix>` alone,
//!   so both read those scenes identically.
//! * **Meshes.** `<triangles>`, `<polylist>` (`<vcount>`), `<polygons>` (one `<p>` per
//!   polygon), `<trifans>` and `<tristrips>`, with any number of `<input>`s at any offsets
//!   (index stride = largest offset + 1); polygons are fan-triangulated. Positions come from
//!   the `<vertices>` `POSITION` source read through its `<accessor>` (offset, stride, count).
//!   Vertices are transformed by the full world matrix (with the homogeneous divide). Shading
//!   normals are CS184's: the area-weighted average of the faces around each position
//!   (`Vertex::normal()` of its halfedge mesh); `NORMAL` inputs are checked but, as in CS184,
//!   not used for shading.
//! * **Materials.** `instance_geometry/bind_material/technique_common/instance_material`
//!   maps a primitive's `material` symbol to a `<material>`, whose `<instance_effect>` names
//!   the effect (unmatched symbols take the first binding, which is all CS184 reads). The
//!   `profile_COMMON` diffuse colour (phong, lambert, blinn or constant) gives a Lambertian
//!   albedo (default 0.5 grey, CS184's) and its emission colour the emitted radiance; then the
//!   effect's `<extra><technique profile="CMU462">` (or `"CGL"`) children override, last one
//!   winning: `<emission><radiance>` (CS184's `EmissionBSDF`: black, emitting),
//!   `<mirror><reflectance>`, `<glass>` (`reflectance`, `transmittance`, `roughness`, `ior`),
//!   `<refraction>` (glass without reflection), `<microfacet>` (`alpha`, `eta`, `k`) and
//!   `<diffuse>` (`albedo` or `reflectance`).
//! * **Spheres.** A geometry without `<mesh>` whose CMU462/CGL extra holds `<sphere><radius>`:
//!   centre = world transform of the origin, radius × length of the transformed x axis
//!   (`Application::init_sphere`).
//! * **Lights** from the CMU462/CGL technique if the light has one, else `technique_common`;
//!   the first child names the type. With `T` the node's world matrix (`L` its linear part):
//!   point → `T·0`; spot → `T·0`, axis `L·(0,0,-1)`, cone half-angle `falloff_angle / 2`
//!   (CS184 ignores the angle and uses 90°); directional → travelling along `L·(0,0,-1)`
//!   (CS184 transforms that direction as a point, which only matters for translated
//!   directional lights); ambient → constant environment radiance (CS184's
//!   `InfiniteHemisphereLight`); **area** (CS184's `AreaLight`): centre `T·0`, emitting along
//!   `L·(0,0,-1)`, `dim_y = L·(0,1,0)`, `dim_x = L·((0,1,0) × (0,0,-1)) = L·(-1,0,0)`, full edge
//!   lengths, radiance = the `<color>`. Attenuation factors are ignored, as in CS184.
//! * **Camera.** `<perspective>` `xfov`/`yfov` (degrees), `aspect_ratio`, `znear`, `zfar`, with
//!   CS184's defaults (50°, 35°, 0.001, 1000); without `yfov`, `vFov = 2·atan(tan(xfov/2) /
//!   aspect)`. CS184 does **not** put the eye where the file does: `Application::load` takes
//!   `c_dir = unit(T·(0,0,-1,1))` and places the camera at the scene's bounding-box centre plus
//!   `1.5·|extent| · c_dir`, looking at the centre with `+y` up (`Camera::place`,
//!   `compute_position`). [`CameraPlacement::Cs184`] (the default) mirrors that, so renders
//!   frame the scene as CS184's do; [`CameraPlacement::AsAuthored`] uses the file's eye and
//!   orientation (looking down local `-z`, `+y` up). With several cameras the last one in
//!   CS184's traversal order wins.
//!
//! Robustness: a missing geometry, material, effect or source, a bad number or an index out of
//! range is a [`LoadError`] naming the element (`<geometry id="Cube-mesh">/<mesh>/<polylist
//! material="x">/<p>`); a reference to a missing light or camera (which CS184's own
//! `sky/CBgems.dae` contains) and unsupported features are warnings. What a file can make the
//! loader do is capped: node nesting at [`MAX_NODE_DEPTH`], `instance_node` cycles are errors,
//! and instancing may expand a document to at most [`INSTANCING_BUDGET_PER_BYTE`] node visits
//! and instanced primitives per byte; counts and offsets from attributes are checked against
//! the data before anything is allocated (all pinned by `tests/fuzz_regressions.rs`).

use crate::io::{LoadError, vertex_normals};
use crate::math::{Mat3, Mat4, Vec3, Vec4};
use crate::scene::{Bsdf, Camera, Light, Material, MaterialId, SceneBuilder};
use roxmltree::{Document, Node};
use std::collections::HashMap;
use std::path::Path;
use std::rc::Rc;

/// How the COLLADA camera becomes the scene camera.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CameraPlacement {
    /// As CS184 does: aimed at the bounding-box centre from the file camera's direction, at
    /// 1.5 × the box diagonal (see the module docs).
    #[default]
    Cs184,
    /// The file's camera position and orientation, unchanged.
    AsAuthored,
}

/// Options of the COLLADA loader.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DaeOptions {
    /// Where the camera goes.
    pub camera: CameraPlacement,
    /// At most this many triangles plus spheres after instancing; `None`: only the
    /// per-byte instancing budget (see [`instancing_budget`]).
    pub max_primitives: Option<u64>,
}

/// Deepest node nesting (including `instance_node` indirections) accepted: deeper files are
/// rejected instead of overflowing the stack.
pub const MAX_NODE_DEPTH: usize = 256;

/// What instancing may expand a document to, in node visits plus instanced vertices,
/// triangles and spheres: `max(MIN_INSTANCING_BUDGET, INSTANCING_BUDGET_PER_BYTE × file size)`,
/// or [`BUDGET_PER_ALLOWED_PRIMITIVE`] units per primitive when that is more and
/// [`DaeOptions::max_primitives`] is set. `instance_node` and `instance_geometry` multiply: 30
/// nested nodes that each instance the next twice are 2³⁰ copies from a 2 kB file. Without a
/// cap such a file takes hours and all memory; with it, an error names the element where the
/// budget ran out. A legitimate file may still expand a lot (a 292 KB file to 11.4 M
/// triangles, 1.3 GB once built): the loader's warnings report every expansion.
pub const INSTANCING_BUDGET_PER_BYTE: usize = 64;
/// The smallest instancing budget (see [`INSTANCING_BUDGET_PER_BYTE`]).
pub const MIN_INSTANCING_BUDGET: usize = 1 << 20;
/// Instancing that adds at least this many primitives to those the file defines is reported
/// in a warning (how many geometries, how many primitives, by what factor).
pub const REPORTED_EXPANSION: u64 = 1 << 20;
/// Instancing budget units per primitive that [`DaeOptions::max_primitives`] allows: room for
/// a triangle soup's three vertices and the triangle itself.
pub const BUDGET_PER_ALLOWED_PRIMITIVE: usize = 4;

/// Parses a COLLADA document. `path` only names the file in errors. Returns the scene and
/// warnings about what was skipped.
pub fn parse_dae(text: &str, path: &Path, opts: &DaeOptions) -> Result<(SceneBuilder, Vec<String>), LoadError> {
    let doc = Document::parse(text).map_err(|e| {
        let pos = e.pos();
        LoadError::parse(path, format!("line {}, column {}", pos.row, pos.col), format!("malformed XML: {e}"))
    })?;
    let root = doc.root_element();
    if root.tag_name().name() != "COLLADA" {
        return Err(LoadError::parse(
            path,
            elem_path(root),
            "not a COLLADA document (the root element must be <COLLADA>)",
        ));
    }
    let mut ids = HashMap::new();
    for n in root.descendants().filter(Node::is_element) {
        if let Some(id) = n.attribute("id") {
            ids.entry(id).or_insert(n);
        }
    }
    let mut cx = Ctx {
        path,
        ids,
        builder: SceneBuilder::new(),
        warnings: Vec::new(),
        materials: HashMap::new(),
        default_material: None,
        meshes: HashMap::new(),
        camera: None,
        visiting: Vec::new(),
        budget: budget_of(text.len(), opts.max_primitives),
        file_len: text.len(),
        max_primitives: opts.max_primitives,
        primitives: 0,
        defined: HashMap::new(),
    };

    let up = cx.up_axis(root)?;
    let scene = match child(root, "scene").and_then(|s| child(s, "instance_visual_scene")) {
        Some(ivs) => cx.resolve(ivs, "url", "visual_scene")?,
        None => {
            let first = child(root, "library_visual_scenes").and_then(|l| child(l, "visual_scene"));
            match first {
                Some(vs) => {
                    cx.warnings.push("no <scene>/<instance_visual_scene>: using the first <visual_scene>".into());
                    vs
                }
                None => return Err(cx.err(root, "no <scene>/<instance_visual_scene> and no <visual_scene>")),
            }
        }
    };
    for node in children(scene, "node") {
        cx.visit_node(node, up, 1)?;
    }
    let defined: usize = cx.defined.values().sum();
    if cx.primitives >= (defined as u64).saturating_add(REPORTED_EXPANSION) {
        let note = format!(
            "instancing expands the {defined} primitives of {} instanced geometries to {} triangles and spheres \
             ({:.1}x; --max-primitives caps the expansion)",
            cx.defined.len(),
            cx.primitives,
            cx.primitives as f64 / defined.max(1) as f64
        );
        cx.warnings.push(note);
    }

    if let Some(cam) = cx.camera.take() {
        let bounds = cx.builder.bounds();
        let camera = match opts.camera {
            CameraPlacement::Cs184 if bounds.is_valid() => cam.cs184(&bounds).unwrap_or_else(|| cam.as_authored()),
            _ => cam.as_authored(),
        };
        cx.builder.set_camera(camera);
    }
    Ok((cx.builder, cx.warnings))
}

/// A COLLADA camera and the world matrix of its node.
#[derive(Clone, Copy, Debug)]
struct CameraInfo {
    hfov: f32,
    vfov: f32,
    near: f32,
    far: f32,
    world: Mat4,
}

impl CameraInfo {
    fn as_authored(&self) -> Camera {
        let position = project(&self.world, Vec3::ZERO);
        let l = Mat3::from_mat4(self.world);
        let forward = (l * -Vec3::Z).normalize_or(-Vec3::Z);
        let up = l * Vec3::Y;
        let mut cam = Camera::look_at(position, position + forward, up, self.vfov, 1.0, self.near, self.far);
        cam.hfov_deg = self.hfov;
        cam
    }

    /// `Application::load` + `Camera::place` + `compute_position`.
    fn cs184(&self, bounds: &crate::math::Aabb) -> Option<Camera> {
        // `(transform * Vector4D(view_dir, 1)).to3D().unit()`: a point transform, no divide.
        let c_dir = (self.world * Vec4::new(0.0, 0.0, -1.0, 1.0)).truncate().try_normalize()?;
        let target = bounds.center();
        let r = 1.5 * bounds.extent().length() as f64;
        let mut phi = (c_dir.y as f64).clamp(-1.0, 1.0).acos();
        if phi.sin() == 0.0 {
            phi += 1e-5; // CS184's EPS_F
        }
        let theta = (c_dir.x as f64).atan2(c_dir.z as f64);
        let to_camera = Vec3::new(
            (r * phi.sin() * theta.sin()) as f32,
            (r * phi.cos()) as f32,
            (r * phi.sin() * theta.cos()) as f32,
        );
        if r == 0.0 || !to_camera.is_finite() {
            return None;
        }
        let up = Vec3::new(0.0, if phi.sin() > 0.0 { 1.0 } else { -1.0 }, 0.0);
        let x = up.cross(to_camera).try_normalize()?;
        let y = to_camera.cross(x).try_normalize()?;
        Some(Camera {
            position: target + to_camera,
            c2w: Mat3::from_cols(x, y, to_camera.normalize()),
            hfov_deg: self.hfov,
            vfov_deg: self.vfov,
            near: self.near,
            far: self.far,
        })
    }
}

/// A parsed `<mesh>`: positions in geometry space and triangles grouped by material symbol.
struct ParsedMesh {
    positions: Vec<Vec3>,
    groups: Vec<(Option<String>, Vec<[u32; 3]>)>,
    /// Warnings found while parsing.
    notes: Vec<String>,
}

struct Ctx<'a, 'input> {
    path: &'a Path,
    ids: HashMap<&'a str, Node<'a, 'input>>,
    builder: SceneBuilder,
    warnings: Vec<String>,
    /// Material ids by `<material id>`.
    materials: HashMap<String, MaterialId>,
    default_material: Option<MaterialId>,
    /// Parsed meshes by `<geometry id>` (geometries instanced twice are parsed once).
    meshes: HashMap<roxmltree::NodeId, Rc<ParsedMesh>>,
    camera: Option<CameraInfo>,
    /// The nodes being visited, outermost first: an `instance_node` of one of them is a cycle.
    visiting: Vec<roxmltree::NodeId>,
    /// What instancing may still add (see [`INSTANCING_BUDGET_PER_BYTE`]).
    budget: usize,
    /// The document's length in bytes.
    file_len: usize,
    /// [`DaeOptions::max_primitives`].
    max_primitives: Option<u64>,
    /// Triangles and spheres added so far (every instance counted).
    primitives: u64,
    /// Triangles (or the one sphere) of each geometry instanced at least once, counted once.
    defined: HashMap<roxmltree::NodeId, usize>,
}

/// The instancing budget of a document of `len` bytes (see [`INSTANCING_BUDGET_PER_BYTE`]).
pub fn instancing_budget(len: usize) -> usize {
    MIN_INSTANCING_BUDGET.max(INSTANCING_BUDGET_PER_BYTE.saturating_mul(len))
}

/// The budget of a document of `len` bytes when at most `max_primitives` may be instanced.
fn budget_of(len: usize, max_primitives: Option<u64>) -> usize {
    let allowed = max_primitives
        .map_or(0, |n| usize::try_from(n).unwrap_or(usize::MAX).saturating_mul(BUDGET_PER_ALLOWED_PRIMITIVE));
    instancing_budget(len).max(allowed)
}

fn children<'a, 'i>(n: Node<'a, 'i>, tag: &'static str) -> impl Iterator<Item = Node<'a, 'i>> {
    n.children().filter(move |c| c.is_element() && c.tag_name().name() == tag)
}

fn child<'a, 'i>(n: Node<'a, 'i>, tag: &'static str) -> Option<Node<'a, 'i>> {
    children(n, tag).next()
}

fn element_children<'a, 'i>(n: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
    n.children().filter(Node::is_element)
}

/// `<tag attr="…">` for messages.
fn describe(n: Node) -> String {
    let tag = n.tag_name().name();
    for a in ["id", "url", "profile", "symbol", "semantic", "material", "target", "source"] {
        if let Some(v) = n.attribute(a) {
            return format!("<{tag} {a}=\"{v}\">");
        }
    }
    format!("<{tag}>")
}

/// The element's path from the nearest enclosing library object (geometry, node, effect…).
fn elem_path(n: Node) -> String {
    const ANCHORS: [&str; 9] =
        ["geometry", "node", "effect", "material", "light", "camera", "visual_scene", "asset", "scene"];
    let mut parts = Vec::new();
    let mut cur = Some(n);
    while let Some(e) = cur.filter(Node::is_element) {
        parts.push(describe(e));
        if ANCHORS.contains(&e.tag_name().name()) {
            break;
        }
        cur = e.parent_element();
    }
    parts.reverse();
    parts.join("/")
}

/// `m · (p, 1)` with the homogeneous divide (`projectTo3D`).
fn project(m: &Mat4, p: Vec3) -> Vec3 {
    let h = *m * p.extend(1.0);
    if h.w != 0.0 && h.w != 1.0 { h.truncate() / h.w } else { h.truncate() }
}

impl<'a, 'i> Ctx<'a, 'i> {
    fn err(&self, n: Node, msg: impl Into<String>) -> LoadError {
        LoadError::parse(self.path, elem_path(n), msg)
    }

    fn warn(&mut self, n: Node, msg: impl std::fmt::Display) {
        self.warnings.push(format!("{}: {msg}", elem_path(n)));
    }

    /// The element a `#id` attribute points to, which must have tag `want`.
    fn resolve(&self, n: Node<'a, 'i>, attr: &str, want: &str) -> Result<Node<'a, 'i>, LoadError> {
        let url = n.attribute(attr).ok_or_else(|| self.err(n, format!("missing attribute {attr}")))?;
        let id = url.strip_prefix('#').ok_or_else(|| {
            self.err(n, format!("{attr}=\"{url}\": only references within the file (#id) are supported"))
        })?;
        let target =
            *self.ids.get(id).ok_or_else(|| self.err(n, format!("refers to a missing <{want} id=\"{id}\">")))?;
        if target.tag_name().name() != want {
            return Err(self.err(n, format!("{url} is a <{}>, not a <{want}>", target.tag_name().name())));
        }
        Ok(target)
    }

    fn floats(&self, n: Node) -> Result<Vec<f32>, LoadError> {
        let text = n.text().unwrap_or("");
        let mut out = Vec::with_capacity(text.len() / 4);
        for (i, tok) in text.split_ascii_whitespace().enumerate() {
            let v: f32 = tok.parse().map_err(|_| self.err(n, format!("value {i} is {tok:?}, not a number")))?;
            out.push(v);
        }
        Ok(out)
    }

    fn indices(&self, n: Node) -> Result<Vec<u32>, LoadError> {
        let text = n.text().unwrap_or("");
        let mut out = Vec::with_capacity(text.len() / 3);
        for (i, tok) in text.split_ascii_whitespace().enumerate() {
            let v: u32 = tok.parse().map_err(|_| self.err(n, format!("index {i} is {tok:?}, not a whole number")))?;
            out.push(v);
        }
        Ok(out)
    }

    fn number(&self, n: Node) -> Result<f32, LoadError> {
        let v = self.floats(n)?;
        match v.as_slice() {
            [x, ..] if x.is_finite() => Ok(*x),
            [x, ..] => Err(self.err(n, format!("{x} is not a finite number"))),
            [] => Err(self.err(n, "expected a number, found nothing")),
        }
    }

    /// An RGB triple (a fourth alpha value is ignored), finite.
    fn rgb(&self, n: Node) -> Result<Vec3, LoadError> {
        let v = self.floats(n)?;
        if v.len() < 3 {
            return Err(self.err(n, format!("expected 3 colour components, found {}", v.len())));
        }
        let c = Vec3::new(v[0], v[1], v[2]);
        if !c.is_finite() {
            return Err(self.err(n, "colour components must be finite"));
        }
        Ok(c)
    }

    fn required(&self, n: Node<'a, 'i>, tag: &'static str) -> Result<Node<'a, 'i>, LoadError> {
        child(n, tag).ok_or_else(|| self.err(n, format!("missing <{tag}>")))
    }

    fn up_axis(&self, root: Node) -> Result<Mat4, LoadError> {
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
    fn charge(&mut self, at: Node, amount: usize) -> Result<(), LoadError> {
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
                    budget_of(self.file_len, self.max_primitives),
                    self.file_len
                ),
            )),
        }
    }

    /// Counts `count` more primitives of geometry `geom` instanced at `at`, or fails when
    /// that passes [`DaeOptions::max_primitives`].
    fn add_primitives(&mut self, at: Node, geom: Node, count: usize) -> Result<(), LoadError> {
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

    fn visit_node(&mut self, node: Node<'a, 'i>, parent: Mat4, depth: usize) -> Result<(), LoadError> {
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

    // ----- geometry -------------------------------------------------------------------------

    fn instance_geometry(&mut self, ig: Node<'a, 'i>, world: &Mat4) -> Result<(), LoadError> {
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

    // ----- materials ------------------------------------------------------------------------

    fn material(&mut self, m: Node<'a, 'i>) -> Result<MaterialId, LoadError> {
        let key = m.attribute("id").unwrap_or("").to_string();
        if let Some(&id) = self.materials.get(&key) {
            return Ok(id);
        }
        let ie = self.required(m, "instance_effect")?;
        let effect = self.resolve(ie, "url", "effect")?;
        let name = m.attribute("name").or(m.attribute("id")).unwrap_or("");
        let mut albedo = Vec3::splat(0.5);
        let mut emission = Vec3::ZERO;
        // The elements that set the BSDF and the emission, for errors about their values.
        let (mut bsdf_at, mut emission_at) = (effect, effect);
        if let Some(profile) = child(effect, "profile_COMMON") {
            let technique = children(profile, "technique")
                .find(|t| t.attribute("sid") == Some("common"))
                .or(child(profile, "technique"));
            let shading = technique.and_then(|t| {
                element_children(t).find(|s| matches!(s.tag_name().name(), "phong" | "lambert" | "blinn" | "constant"))
            });
            if let Some(s) = shading {
                if let Some(c) = child(s, "diffuse").and_then(|d| child(d, "color")) {
                    albedo = self.rgb(c)?;
                    bsdf_at = c;
                }
                if let Some(c) = child(s, "emission").and_then(|d| child(d, "color")) {
                    emission = self.rgb(c)?;
                    emission_at = c;
                }
            }
        }
        let mut bsdf = Bsdf::Diffuse { albedo };
        if let Some(t) = cmu_technique(effect) {
            for e in element_children(t) {
                let rgb_of = |tag: &'static str| -> Result<Vec3, LoadError> { self.rgb(self.required(e, tag)?) };
                let opt_rgb = |tag: &'static str, d: Vec3| child(e, tag).map_or(Ok(d), |c| self.rgb(c));
                let opt_num = |tag: &'static str, d: f32| child(e, tag).map_or(Ok(d), |c| self.number(c));
                let model = e.tag_name().name();
                if matches!(model, "emission" | "mirror" | "glass" | "refraction" | "microfacet" | "diffuse") {
                    bsdf_at = e;
                }
                match model {
                    "emission" => {
                        emission = rgb_of("radiance")?;
                        emission_at = e;
                        bsdf = Bsdf::Diffuse { albedo: Vec3::ZERO };
                    }
                    "mirror" => bsdf = Bsdf::Mirror { reflectance: rgb_of("reflectance")? },
                    "glass" => {
                        bsdf = Bsdf::Glass {
                            reflectance: opt_rgb("reflectance", Vec3::ONE)?,
                            transmittance: opt_rgb("transmittance", Vec3::ONE)?,
                            ior: self.number(self.required(e, "ior")?)?,
                            roughness: opt_num("roughness", 0.0)?,
                        }
                    }
                    "refraction" => {
                        bsdf = Bsdf::Glass {
                            reflectance: Vec3::ZERO,
                            transmittance: opt_rgb("transmittance", Vec3::ONE)?,
                            ior: self.number(self.required(e, "ior")?)?,
                            roughness: opt_num("roughness", 0.0)?,
                        }
                    }
                    "microfacet" => {
                        bsdf = Bsdf::Microfacet {
                            eta: rgb_of("eta")?,
                            k: rgb_of("k")?,
                            alpha: self.number(self.required(e, "alpha")?)?,
                        }
                    }
                    "diffuse" => {
                        let c = child(e, "albedo")
                            .or(child(e, "reflectance"))
                            .ok_or_else(|| self.err(e, "missing <albedo>"))?;
                        bsdf = Bsdf::Diffuse { albedo: self.rgb(c)? };
                    }
                    other => {
                        let msg = format!("material model <{other}> is not supported; ignored");
                        self.warnings.push(format!("{}: {msg}", elem_path(e)));
                    }
                }
            }
        }
        bsdf.check().map_err(|m| self.err(bsdf_at, m))?;
        crate::scene::material::check_radiance("emission", emission).map_err(|m| self.err(emission_at, m))?;
        let id = self.builder.add_material(Material { name: name.to_string(), bsdf, emission });
        self.materials.insert(key, id);
        Ok(id)
    }

    // ----- lights and cameras ---------------------------------------------------------------

    fn instance_light(&mut self, il: Node<'a, 'i>, world: &Mat4) -> Result<(), LoadError> {
        let light = match self.resolve(il, "url", "light") {
            Ok(l) => l,
            Err(e) => {
                self.warnings.push(format!("{}; light skipped", without_path(e)));
                return Ok(());
            }
        };
        let Some(technique) = cmu_technique(light).or(child(light, "technique_common")) else {
            self.warn(light, "no technique_common or CMU462/CGL technique; light skipped");
            return Ok(());
        };
        let Some(kind) = element_children(technique).next() else {
            self.warn(technique, "empty technique; light skipped");
            return Ok(());
        };
        let color_node = self.required(kind, "color")?;
        let color = self.rgb(color_node)?;
        let l = Mat3::from_mat4(*world);
        let position = project(world, Vec3::ZERO);
        let forward = (l * -Vec3::Z).normalize_or(-Vec3::Y);
        let light = match kind.tag_name().name() {
            "ambient" => Light::Environment { radiance: color },
            "directional" => Light::Directional { direction: forward, radiance: color },
            "point" => Light::Point { position, intensity: color },
            "spot" => {
                let angle = child(kind, "falloff_angle").map_or(Ok(180.0), |a| self.number(a))?;
                let half = (angle * 0.5).clamp(0.0, 90.0);
                Light::Spot {
                    position,
                    direction: forward,
                    intensity: color,
                    inner_angle_deg: half,
                    outer_angle_deg: half,
                }
            }
            "area" => Light::Area {
                radiance: color,
                position,
                direction: forward,
                dim_x: l * Vec3::new(-1.0, 0.0, 0.0),
                dim_y: l * Vec3::Y,
            },
            other => {
                self.warn(kind, format!("light type <{other}> is not supported; light skipped"));
                return Ok(());
            }
        };
        light.check().map_err(|m| self.err(color_node, m))?;
        self.builder.add_light(light);
        Ok(())
    }

    fn instance_camera(&mut self, ic: Node<'a, 'i>, world: &Mat4) -> Result<(), LoadError> {
        let cam = match self.resolve(ic, "url", "camera") {
            Ok(c) => c,
            Err(e) => {
                self.warnings.push(format!("{}; camera skipped", without_path(e)));
                return Ok(());
            }
        };
        let persp =
            child(cam, "optics").and_then(|o| child(o, "technique_common")).and_then(|t| child(t, "perspective"));
        let Some(p) = persp else {
            self.warn(
                cam,
                "no <optics>/<technique_common>/<perspective> (only perspective cameras are supported); camera skipped",
            );
            return Ok(());
        };
        let get = |tag: &'static str| child(p, tag).map(|n| self.number(n)).transpose();
        let (xfov, yfov, aspect) = (get("xfov")?, get("yfov")?, get("aspect_ratio")?);
        let half_tan = |deg: f32| (deg.to_radians() * 0.5).tan();
        let to_deg = |t: f32| (2.0 * t.atan()).to_degrees();
        let (hfov, vfov) = match (xfov, yfov, aspect) {
            (Some(x), Some(y), _) => (x, y),
            (Some(x), None, Some(a)) if a > 0.0 => (x, to_deg(half_tan(x) / a)),
            (None, Some(y), Some(a)) if a > 0.0 => (to_deg(half_tan(y) * a), y),
            (None, Some(y), _) => (50.0, y),
            _ => {
                return Err(
                    self.err(p, "incomplete perspective: needs <yfov>, or <xfov> with a positive <aspect_ratio>")
                );
            }
        };
        let near = get("znear")?.unwrap_or(0.001);
        let far = get("zfar")?.unwrap_or(1000.0);
        if !(hfov > 0.0 && hfov < 180.0 && vfov > 0.0 && vfov < 180.0) {
            return Err(self.err(p, format!("fields of view must be in (0, 180) degrees, found {hfov} and {vfov}")));
        }
        if !(near >= 0.0 && far > near) {
            return Err(self.err(p, format!("clip planes must satisfy 0 <= znear < zfar, found {near} and {far}")));
        }
        if self.camera.is_some() {
            self.warn(ic, "more than one camera: the last one is used, as in CS184");
        }
        self.camera = Some(CameraInfo { hfov, vfov, near, far, world: *world });
        Ok(())
    }
}

/// The `<extra><technique profile="CMU462">` (or `"CGL"`) child of `n`, if any.
fn cmu_technique<'a, 'i>(n: Node<'a, 'i>) -> Option<Node<'a, 'i>> {
    children(n, "extra")
        .flat_map(|e| children(e, "technique"))
        .find(|t| matches!(t.attribute("profile"), Some("CMU462") | Some("CGL")))
}

/// An error's location and message, for turning it into a warning.
fn without_path(e: LoadError) -> String {
    match e {
        LoadError::Parse { location, message, .. } => format!("{location}: {message}"),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A document with the given library contents and visual-scene nodes.
    fn doc(libraries: &str, nodes: &str) -> String {
        format!(
            r##"<?xml version="1.0"?><COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
            {libraries}
            <library_visual_scenes><visual_scene id="s">{nodes}</visual_scene></library_visual_scenes>
            <scene><instance_visual_scene url="#s"/></scene></COLLADA>"##
        )
    }

    fn load(text: &str) -> (SceneBuilder, Vec<String>) {
        parse_dae(text, Path::new("t.dae"), &DaeOptions::default()).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn lights_of_every_type_follow_cs184() {
        let lib = r##"<library_lights>
            <light id="p"><technique_common><point><color>1 2 3</color></point></technique_common></light>
            <light id="d"><technique_common><directional><color>4 4 4</color></directional></technique_common></light>
            <light id="a"><technique_common><ambient><color>0.5 0.5 0.5</color></ambient></technique_common></light>
            <light id="sp"><technique_common><spot><color>7 7 7</color><falloff_angle>60</falloff_angle></spot></technique_common></light>
            <light id="q"><technique_common><point><color>1 1 1</color></point></technique_common>
              <extra><technique profile="CGL"><area><color>9 9 9</color></area></technique></extra></light>
            </library_lights>"##;
        let nodes = r##"<node id="np"><translate>1 2 3</translate><instance_light url="#p"/></node>
            <node id="nd"><rotate>1 0 0 -90</rotate><instance_light url="#d"/></node>
            <node id="na"><instance_light url="#a"/></node>
            <node id="ns"><translate>0 5 0</translate><rotate>1 0 0 -90</rotate><instance_light url="#sp"/></node>
            <node id="nq"><translate>0 2 0</translate><rotate>0 1 0 90</rotate><scale>2 3 1</scale><instance_light url="#q"/></node>"##;
        let (b, _) = load(&doc(lib, nodes));
        let l = b.lights();
        assert_eq!(l[0], Light::Point { position: Vec3::new(1.0, 2.0, 3.0), intensity: Vec3::new(1.0, 2.0, 3.0) });
        // -90° about x turns local -z into -y.
        let Light::Directional { direction, radiance } = l[1] else { panic!("{:?}", l[1]) };
        assert!((direction - -Vec3::Y).length() < 1e-6 && radiance == Vec3::splat(4.0));
        assert_eq!(l[2], Light::Environment { radiance: Vec3::splat(0.5) });
        let Light::Spot { position, direction, outer_angle_deg, .. } = l[3] else { panic!("{:?}", l[3]) };
        assert!((position - Vec3::new(0.0, 5.0, 0.0)).length() < 1e-6 && (direction - -Vec3::Y).length() < 1e-6);
        assert_eq!(outer_angle_deg, 30.0);
        // Area: 90° about y maps x -> -z and z -> x; scale (2, 3, 1) first.
        // direction = R·S·(0,0,-1) = R·(0,0,-1) = (-1,0,0); dim_x = R·S·(-1,0,0) = R·(-2,0,0) = (0,0,2);
        // dim_y = R·S·(0,1,0) = (0,3,0).
        let Light::Area { radiance, position, direction, dim_x, dim_y } = l[4] else { panic!("{:?}", l[4]) };
        assert_eq!((radiance, position), (Vec3::splat(9.0), Vec3::new(0.0, 2.0, 0.0)));
        assert!((direction - -Vec3::X).length() < 1e-6, "{direction}");
        assert!((dim_x - Vec3::new(0.0, 0.0, 2.0)).length() < 1e-6, "{dim_x}");
        assert!((dim_y - Vec3::new(0.0, 3.0, 0.0)).length() < 1e-6, "{dim_y}");
    }

    #[test]
    fn cgl_materials_and_sphere_scale() {
        let lib = r##"<library_effects>
            <effect id="e-mf"><extra><technique profile="CGL"><microfacet><alpha>0.25</alpha><eta>0.2 0.3 0.4</eta><k>3 2 1</k></microfacet></technique></extra></effect>
            <effect id="e-d"><profile_COMMON><technique sid="common"><blinn><diffuse><color>0.1 0.2 0.3 1</color></diffuse></blinn></technique></profile_COMMON>
              <extra><technique profile="CGL"><refraction><transmittance>1 1 1</transmittance><roughness>0</roughness><ior>1.33</ior></refraction></technique></extra></effect>
            </library_effects>
            <library_materials><material id="mf"><instance_effect url="#e-mf"/></material><material id="d"><instance_effect url="#e-d"/></material></library_materials>
            <library_geometries><geometry id="ball"><extra><technique profile="CGL"><sphere><radius>0.5</radius></sphere></technique></extra></geometry></library_geometries>"##;
        let nodes = r##"<node id="a"><translate>1 0 0</translate><scale>4 4 4</scale><instance_geometry url="#ball">
              <bind_material><technique_common><instance_material symbol="x" target="#mf"/></technique_common></bind_material></instance_geometry></node>
            <node id="b"><instance_geometry url="#ball">
              <bind_material><technique_common><instance_material symbol="y" target="#d"/></technique_common></bind_material></instance_geometry></node>"##;
        let (b, _) = load(&doc(lib, nodes));
        let (scene, _) = b.commit(&crate::BuildOptions::default());
        assert_eq!(scene.spheres.center, vec![Vec3::new(1.0, 0.0, 0.0), Vec3::ZERO]);
        assert_eq!(scene.spheres.radius, vec![2.0, 0.5]);
        let m0 = &scene.materials[scene.spheres.material[0] as usize];
        assert_eq!(
            m0.bsdf,
            Bsdf::Microfacet { eta: Vec3::new(0.2, 0.3, 0.4), k: Vec3::new(3.0, 2.0, 1.0), alpha: 0.25 }
        );
        let m1 = &scene.materials[scene.spheres.material[1] as usize];
        assert!(matches!(m1.bsdf, Bsdf::Glass { ior, reflectance, .. } if ior == 1.33 && reflectance == Vec3::ZERO));
    }

    #[test]
    fn camera_fields_of_view_and_placements() {
        let lib = |persp: &str| {
            format!(
                r##"<library_cameras><camera id="c"><optics><technique_common><perspective>{persp}</perspective></technique_common></optics></camera></library_cameras>
              <library_geometries><geometry id="g"><mesh><source id="p"><float_array id="pa" count="9">-1 -1 0 1 -1 0 0 1 0</float_array></source>
              <vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
              <triangles count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles></mesh></geometry></library_geometries>"##
            )
        };
        let nodes = r##"<node id="cam"><translate>0 0 10</translate><instance_camera url="#c"/></node><node id="m"><instance_geometry url="#g"/></node>"##;
        // yfov and aspect without xfov: hFov from the aspect.
        let (b, _) =
            load(&doc(&lib("<yfov>40</yfov><aspect_ratio>2</aspect_ratio><znear>1</znear><zfar>50</zfar>"), nodes));
        let c = b.camera().unwrap();
        let want_h = (2.0 * ((20f32).to_radians().tan() * 2.0).atan()).to_degrees();
        assert!((c.vfov_deg - 40.0).abs() < 1e-5 && (c.hfov_deg - want_h).abs() < 1e-4);
        assert_eq!((c.near, c.far), (1.0, 50.0));
        // CS184 placement: c_dir = unit((0,0,10) + (0,0,-1)) = +z; bounds [-1,1]x[-1,1]x[0,0]:
        // centre 0, distance 1.5 |(2,2,0)|.
        assert!((c.position - Vec3::new(0.0, 0.0, 1.5 * 8f32.sqrt())).length() < 1e-5, "{}", c.position);
        // As authored: the file's eye.
        let text = doc(&lib("<xfov>50</xfov><yfov>40</yfov>"), nodes);
        let opts = DaeOptions { camera: CameraPlacement::AsAuthored, ..DaeOptions::default() };
        let (b, _) = parse_dae(&text, Path::new("t.dae"), &opts).unwrap();
        assert_eq!(b.camera().unwrap().position, Vec3::new(0.0, 0.0, 10.0));
        // Neither yfov nor aspect: CS184 rejects it too.
        let e = parse_dae(&doc(&lib("<xfov>50</xfov>"), nodes), Path::new("t.dae"), &opts).unwrap_err();
        assert!(e.to_string().contains("<camera id=\"c\">/<optics>/<technique_common>/<perspective>"), "{e}");
    }
}
