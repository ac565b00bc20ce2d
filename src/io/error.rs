//! The error type of every loader.

use std::path::PathBuf;

/// Why a scene file could not be loaded. Every variant names the file; parse errors also
/// name the line (1-based) or the element.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The extension is not one raypack reads.
    #[error("{path}: unsupported scene format (expected .dae, .obj or .ply)")]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
    },
    /// The content is malformed.
    #[error("{path}:{location}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Where: `line N` or an element path such as `<geometry id="x">/<triangles>`.
        location: String,
        /// What is wrong.
        message: String,
    },
}
