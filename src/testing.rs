//! Fixtures the unit tests of every layer share (compiled for tests only, so no layer of the
//! library depends on it): scenes a test of a lower layer may trace without naming the
//! loaders above it.

use crate::scene::SceneBuilder;

/// The built-in Cornell box ([`crate::io::default_scene`]).
pub(crate) fn cornell_box() -> SceneBuilder {
    crate::io::default_scene()
}

/// 3000 random triangles of the unit cube's `[-1, 1]` span (seed `seed`) and one sphere at
/// `(0.5, 0.5, 0.5)` of radius 0.3, committed with the default options: a tree small enough for
/// the caches whose rays mix triangle and sphere hits.
pub(crate) fn soup_and_sphere(seed: u64) -> crate::Scene {
    let mesh = crate::generate::random_soup(3000, 0.2, seed);
    let mut b = SceneBuilder::new();
    let m = b.add_material(crate::Material::default());
    b.add_mesh(&mesh.positions, &mesh.indices, m).unwrap();
    b.add_sphere(crate::Vec3::new(0.5, 0.5, 0.5), 0.3, m).unwrap();
    b.commit(&crate::BuildOptions::default()).0
}
