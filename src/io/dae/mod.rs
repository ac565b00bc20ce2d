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
//!
//! The loader is split as the document is organised: XML-level reading (references,
//! numbers, colours, error locations), the scene graph (nodes, transforms, instancing and its
//! cycle and budget guards), geometry (sources and the polygon elements), materials (effects
//! and their CMU462/CGL extras), lights and cameras.

mod camera;
mod geometry;
mod light;
mod material;
mod scene_graph;
mod xml;

pub use camera::CameraPlacement;
pub use scene_graph::{
    BUDGET_PER_ALLOWED_PRIMITIVE, INSTANCING_BUDGET_PER_BYTE, MAX_NODE_DEPTH, MIN_INSTANCING_BUDGET,
    REPORTED_EXPANSION, instancing_budget,
};

use crate::io::LoadError;
use crate::scene::{MaterialId, SceneBuilder};
use camera::CameraInfo;
use geometry::ParsedMesh;
use roxmltree::{Document, Node};
use scene_graph::budget_of;
use std::collections::HashMap;
use std::path::Path;
use std::rc::Rc;
use xml::{child, children, elem_path};

/// Options of the COLLADA loader.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DaeOptions {
    /// Where the camera goes.
    pub camera: CameraPlacement,
    /// At most this many triangles plus spheres after instancing; `None`: only the
    /// per-byte instancing budget (see [`instancing_budget`]).
    pub max_primitives: Option<u64>,
    /// `max_primitives` is raypack's default cap rather than the user's: it does not widen
    /// the instancing budget.
    pub default_cap: bool,
}

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
        budget: budget_of(text.len(), opts.max_primitives.filter(|_| !opts.default_cap)),
        total_budget: budget_of(text.len(), opts.max_primitives.filter(|_| !opts.default_cap)),
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

/// The loader's state while it walks one document.
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
    /// What it could add at the start.
    total_budget: usize,
    /// The document's length in bytes.
    file_len: usize,
    /// [`DaeOptions::max_primitives`].
    max_primitives: Option<u64>,
    /// Triangles and spheres added so far (every instance counted).
    primitives: u64,
    /// Triangles (or the one sphere) of each geometry instanced at least once, counted once.
    defined: HashMap<roxmltree::NodeId, usize>,
}

#[cfg(test)]
pub(super) mod test_doc {
    use super::*;

    /// A document with the given library contents and visual-scene nodes.
    pub fn doc(libraries: &str, nodes: &str) -> String {
        format!(
            r##"<?xml version="1.0"?><COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
            {libraries}
            <library_visual_scenes><visual_scene id="s">{nodes}</visual_scene></library_visual_scenes>
            <scene><instance_visual_scene url="#s"/></scene></COLLADA>"##
        )
    }

    /// [`parse_dae`] of `text` with the default options, which must succeed.
    pub fn load(text: &str) -> (SceneBuilder, Vec<String>) {
        parse_dae(text, Path::new("t.dae"), &DaeOptions::default()).unwrap_or_else(|e| panic!("{e}"))
    }
}
