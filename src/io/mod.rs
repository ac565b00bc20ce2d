//! Scene loaders: COLLADA (`.dae`, CS184 dialect), OBJ and PLY. Each returns a
//! [`LoadedScene`] (the [`crate::SceneBuilder`], the warnings, and what the loader added that
//! the file did not hold) or a [`LoadError`] naming the file and the element or line. The
//! loaders never print: the caller reports the warnings its own way (the CLI prints them).
//!
//! Files without a camera get none: the renderer frames the bounding box
//! ([`crate::Scene::camera_or_framing`]). Files without lights get [`default_light_rig`]
//! (reported as [`Synthesized::DefaultLights`] and in a warning): one
//! point light above and in front of the scene, on the camera's side. A point light is a
//! delta light that a hemisphere sampler can never hit, so with `-H` (uniform hemisphere
//! sampling for direct light) such scenes render black, exactly as CS184's do for its
//! point-lit scenes such as `sky/dragon.dae`; light sampling (the default) lights them.
//! (CS184 itself adds a uniform white `AmbientLight` to light-less scenes.)

pub mod camera_file;
pub mod dae;
pub mod error;
pub mod obj;
pub mod ply;
pub mod rays;

pub use crate::fs::input::MAX_MTL_BYTES;
pub use dae::{CameraPlacement, DaeOptions};
pub use error::LoadError;

use crate::math::{Aabb, Vec3};
use crate::scene::{Camera, Light, Material, SceneBuilder};
use std::path::Path;

/// The scene file formats raypack reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneFormat {
    /// COLLADA 1.4.1 in the CS184 / CMU462 dialect.
    Dae,
    /// Wavefront OBJ (+ MTL).
    Obj,
    /// Stanford PLY.
    Ply,
}

impl SceneFormat {
    /// The format named by a file's extension (case-insensitive).
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "dae" => Some(SceneFormat::Dae),
            "obj" => Some(SceneFormat::Obj),
            "ply" => Some(SceneFormat::Ply),
            _ => None,
        }
    }
}

/// A loaded scene file: the scene to commit, and what the caller should tell its user.
#[derive(Clone, Debug)]
pub struct LoadedScene {
    /// The scene, ready to [`SceneBuilder::commit`].
    pub builder: SceneBuilder,
    /// Problems the loader worked around, each naming the file (and the line or element),
    /// and each substitution it made; nothing is printed.
    pub warnings: Vec<String>,
    /// What the loader added that the file did not hold (also among the warnings).
    pub synthesized: Vec<Synthesized>,
}

/// Something a loader added to a scene that its file did not hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Synthesized {
    /// The file has no lights: the `count` lights of [`default_light_rig`] were added (the
    /// last `count` of [`SceneBuilder::lights`]). A camera is never synthesised: a file
    /// without one leaves [`SceneBuilder::camera`] `None`, and the renderer frames the scene.
    DefaultLights {
        /// Lights added.
        count: usize,
    },
}

/// Loads a scene file, choosing the format by extension (`.dae`, `.obj`, `.ply`). Adds
/// [`default_light_rig`] when the file has no lights. Prints nothing: the warnings are
/// returned.
pub fn load_scene(path: &Path) -> Result<LoadedScene, LoadError> {
    load_scene_with_options(path, &LoadOptions::default())
}

/// What a loader may let a file make it do, beyond being well-formed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LoadOptions {
    /// At most this many primitives (triangles plus spheres, after triangulation and
    /// instancing) in any format; `None`: no cap but COLLADA's instancing budget
    /// ([`dae::INSTANCING_BUDGET_PER_BYTE`]) and [`LoadOptions::memory_cap`]. The CLI's
    /// `--max-primitives`.
    pub max_primitives: Option<u64>,
    /// Without [`LoadOptions::max_primitives`], cap the primitives at
    /// [`crate::scene::footprint::default_max_primitives`] of the file's size (what the memory estimate
    /// allows a file of that size without asking), with errors that say so. The CLI's default.
    pub memory_cap: bool,
}

/// [`load_scene`] with limits. The file is read only if it is a regular file of at most
/// [`crate::fs::input::MAX_SCENE_BYTES`] (a FIFO or `/dev/zero` is an error, not a hang).
pub fn load_scene_with_options(path: &Path, opts: &LoadOptions) -> Result<LoadedScene, LoadError> {
    let format =
        SceneFormat::from_path(path).ok_or_else(|| LoadError::UnsupportedFormat { path: path.to_path_buf() })?;
    let bytes = crate::fs::input::read_regular(path, crate::fs::input::MAX_SCENE_BYTES, "scene files")
        .map_err(|source| LoadError::Io { path: path.to_path_buf(), source })?;
    let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let read_mtl = move |p: &Path| read_material_library(&dir.join(p));
    load_with(&bytes, format, path, &read_mtl, opts)
}

/// An OBJ's material library, if it is a regular file of at most [`MAX_MTL_BYTES`]: an OBJ
/// naming `mtllib /dev/zero` or a FIFO must not make the loader read forever. The error says
/// why not, for the warning.
fn read_material_library(path: &Path) -> Result<Vec<u8>, String> {
    crate::fs::input::read_regular(path, MAX_MTL_BYTES, "material libraries").map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => "not found".to_string(),
        _ => e.to_string(),
    })
}

/// Loads a scene held in memory (for tests and fuzzing). `name` only names it in errors;
/// OBJ material libraries are not looked up.
pub fn load_scene_from_bytes(bytes: &[u8], format: SceneFormat, name: &Path) -> Result<LoadedScene, LoadError> {
    load_scene_from_bytes_with_options(bytes, format, name, &LoadOptions::default())
}

/// [`load_scene_from_bytes`] with limits.
pub fn load_scene_from_bytes_with_options(
    bytes: &[u8],
    format: SceneFormat,
    name: &Path,
    opts: &LoadOptions,
) -> Result<LoadedScene, LoadError> {
    load_with(bytes, format, name, &|_| Err("not looked up for a scene held in memory".into()), opts)
}

fn load_with(
    bytes: &[u8],
    format: SceneFormat,
    path: &Path,
    read_mtl: &dyn Fn(&Path) -> Result<Vec<u8>, String>,
    opts: &LoadOptions,
) -> Result<LoadedScene, LoadError> {
    let default_cap = opts.max_primitives.is_none() && opts.memory_cap;
    let max_primitives = if default_cap {
        Some(crate::scene::footprint::default_max_primitives(bytes.len() as u64))
    } else {
        opts.max_primitives
    };
    let parsed = parse_capped(bytes, format, path, read_mtl, max_primitives, default_cap);
    let (mut builder, warnings) = match (parsed, max_primitives) {
        (Err(e), Some(max)) if default_cap => return Err(name_default_cap(e, max, bytes.len())),
        (parsed, _) => parsed?,
    };
    let mut warnings: Vec<String> = warnings.into_iter().map(|w| format!("{}: {w}", path.display())).collect();
    let mut synthesized = Vec::new();
    if builder.lights().is_empty() {
        let rig = default_light_rig(&builder.bounds(), builder.camera());
        synthesized.push(Synthesized::DefaultLights { count: rig.len() });
        for light in rig {
            builder.add_light(light);
        }
        warnings
            .push(format!("{}: no lights in the file; added the default light rig (one point light)", path.display()));
    }
    Ok(LoadedScene { builder, warnings, synthesized })
}

/// Parses `bytes` of `format` with at most `max_primitives` primitives; `default_cap`: that cap
/// is raypack's default, which does not widen COLLADA's instancing budget as a user's does.
fn parse_capped(
    bytes: &[u8],
    format: SceneFormat,
    path: &Path,
    read_mtl: &dyn Fn(&Path) -> Result<Vec<u8>, String>,
    max_primitives: Option<u64>,
    default_cap: bool,
) -> Result<(SceneBuilder, Vec<String>), LoadError> {
    Ok(match format {
        SceneFormat::Dae => {
            let text = std::str::from_utf8(bytes)
                .map_err(|e| LoadError::parse(path, format!("byte {}", e.valid_up_to()), "not UTF-8 text"))?;
            let dae_opts = DaeOptions { max_primitives, default_cap, ..DaeOptions::default() };
            dae::parse_dae(text, path, &dae_opts)?
        }
        SceneFormat::Obj => obj::parse_obj_with_limit(bytes, path, read_mtl, max_primitives)?,
        SceneFormat::Ply => {
            let mesh = ply::parse_ply(bytes, path)?;
            if let Some(max) = max_primitives.filter(|&max| mesh.triangles.len() as u64 > max) {
                return Err(LoadError::parse(
                    path,
                    "element face",
                    format!("{} triangles, more than --max-primitives {max}", mesh.triangles.len()),
                ));
            }
            let mut b = SceneBuilder::new();
            let m = b.add_material(Material::default());
            let normals = vertex_normals(&mesh.positions, &mesh.triangles);
            b.add_mesh_with_normals(&mesh.positions, Some(&normals), &mesh.triangles, m)
                .map_err(|e| LoadError::parse(path, "element face", e.to_string()))?;
            let mut w = Vec::new();
            if mesh.skipped_faces > 0 {
                w.push(format!("{} faces with fewer than 3 corners skipped", mesh.skipped_faces));
            }
            (b, w)
        }
    })
}

/// `e`, a loader's error, with the cap `max` it names (every loader says "more than
/// --max-primitives N") named as raypack's default for a file of `file_len` bytes.
fn name_default_cap(e: LoadError, max: u64, file_len: usize) -> LoadError {
    let named = format!("more than --max-primitives {max}");
    match e {
        LoadError::Parse { path, location, message } if message.contains(&named) => {
            use crate::scene::footprint::{
                DEFAULT_SCENE_BYTES, DEFAULT_SCENE_BYTES_PER_FILE_BYTE, SCENE_BYTES_PER_PRIMITIVE,
            };
            let default = format!(
                "more than the {max} raypack allows a file of {file_len} bytes without --max-primitives ({} per byte, \
                 at least {}, at most what fits in the memory available at {SCENE_BYTES_PER_PRIMITIVE} bytes each); \
                 give --max-primitives N to allow more",
                DEFAULT_SCENE_BYTES_PER_FILE_BYTE / SCENE_BYTES_PER_PRIMITIVE,
                DEFAULT_SCENE_BYTES / SCENE_BYTES_PER_PRIMITIVE,
            );
            LoadError::Parse { path, location, message: message.replace(&named, &default) }
        }
        e => e,
    }
}

/// The lights given to scenes that have none: one point light above and in front of the
/// scene on the camera's side (`camera`, or the framing camera when `None`), three bounding
/// radii from the centre, with intensity `π d²` so that the irradiance at the centre is `π`
/// (a white Lambertian surface facing the light there has radiance 1), whatever the scene's
/// scale.
pub fn default_light_rig(bounds: &Aabb, camera: Option<&Camera>) -> Vec<Light> {
    let (center, radius) = if bounds.is_valid() && bounds.min.is_finite() && bounds.max.is_finite() {
        (bounds.center(), (bounds.extent().length() * 0.5).max(1e-3))
    } else {
        (Vec3::ZERO, 1.0)
    };
    let cam = camera.copied().unwrap_or_else(|| Camera::framing(bounds, 4.0 / 3.0));
    let (right, up, back) = (cam.c2w.x_axis, cam.c2w.y_axis, cam.c2w.z_axis);
    let dir = (back + up + 0.5 * right).normalize_or(Vec3::Y);
    let d = 3.0 * radius;
    vec![Light::Point { position: center + dir * d, intensity: Vec3::splat(std::f32::consts::PI * d * d) }]
}

/// Per-vertex shading normals as CS184 computes them (`Vertex::normal()` of its halfedge
/// mesh): the sum of the incident faces' `(b - a) × (c - a)`, i.e. area-weighted, normalised.
/// Vertices on no (finite, non-degenerate) face get a zero normal ("use the geometric one").
pub fn vertex_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut n = vec![Vec3::ZERO; positions.len()];
    for t in triangles {
        let [Some(&a), Some(&b), Some(&c)] = t.map(|i| positions.get(i as usize)) else {
            continue;
        };
        let f = (b - a).cross(c - a);
        if f.is_finite() {
            for &i in t {
                n[i as usize] += f;
            }
        }
    }
    for v in &mut n {
        *v = v.normalize_or_zero();
    }
    n
}

/// The project's own scene `scenes/cornell.dae`, compiled in: a Cornell box with a mirror
/// and a glass sphere and an area light (see `scenes/README.md`).
pub fn default_scene() -> SceneBuilder {
    const CORNELL: &str = include_str!("../../scenes/cornell.dae");
    let (builder, _) = dae::parse_dae(CORNELL, Path::new("scenes/cornell.dae"), &DaeOptions::default())
        .expect("the built-in scenes/cornell.dae parses (tested)");
    builder
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_scene_is_the_cornell_box() {
        let b = default_scene();
        assert_eq!(b.num_spheres(), 2);
        assert!(b.num_triangles() >= 10);
        assert!(b.lights().iter().any(|l| matches!(l, Light::Area { .. })));
        assert!(b.camera().is_some());
    }

    #[test]
    fn light_rig_scales_with_the_scene_and_sits_above_in_front() {
        let small = Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0));
        let big = Aabb::new(Vec3::splat(-100.0), Vec3::splat(100.0));
        let (Light::Point { position: p1, intensity: i1 }, Light::Point { position: p2, intensity: i2 }) =
            (default_light_rig(&small, None)[0], default_light_rig(&big, None)[0])
        else {
            panic!("point lights expected");
        };
        assert!(p1.y > 1.0 && p1.z > 1.0, "above and in front of the framing camera's side: {p1}");
        // Irradiance at the centre, I / d², is the same at both scales.
        assert!((i1.x / p1.length_squared() - i2.x / p2.length_squared()).abs() < 1e-3);
    }
}
