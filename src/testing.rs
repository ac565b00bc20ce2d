//! Fixtures the unit tests of every layer share (compiled for tests only, so no layer of the
//! library depends on it): scenes a test of a lower layer may trace without naming the
//! loaders above it.

use crate::scene::SceneBuilder;

/// The built-in Cornell box ([`crate::io::default_scene`]).
pub(crate) fn cornell_box() -> SceneBuilder {
    crate::io::default_scene()
}
