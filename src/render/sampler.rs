//! Deterministic random numbers for rendering.
//!
//! Every pixel sample gets its own generator seeded from `(seed, sample stream)` (see
//! [`crate::render::sample_stream`]), so an image depends only on the seed, never on how pixels are
//! spread over threads. The generator itself lives in [`crate::rng`]; it is re-exported here
//! for the code that names it by this path.

pub use crate::rng::Rng;
