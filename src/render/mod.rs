//! The renderer: films, integrators and image output.
