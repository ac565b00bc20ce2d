//! The error type of every loader.
//!
//! Every variant names the file. Parse errors also say where: `line N` for the line-based
//! formats (OBJ, ASCII PLY, camera files), `byte N` for binary PLY, and an element path such
//! as `<geometry id="Cube-mesh">/<mesh>/<triangles>/<p>` for COLLADA.

use std::path::{Path, PathBuf};

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
        /// Where: `line N`, `byte N` or an element path such as `<geometry id="x">/<triangles>`.
        location: String,
        /// What is wrong.
        message: String,
    },
}

impl LoadError {
    /// A [`LoadError::Parse`].
    pub fn parse(path: &Path, location: impl Into<String>, message: impl Into<String>) -> Self {
        LoadError::Parse { path: path.to_path_buf(), location: location.into(), message: message.into() }
    }

    /// A [`LoadError::Parse`] located at a 1-based line.
    pub fn at_line(path: &Path, line: usize, message: impl Into<String>) -> Self {
        Self::parse(path, format!("line {line}"), message)
    }

    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            LoadError::Io { path, .. } | LoadError::UnsupportedFormat { path } | LoadError::Parse { path, .. } => path,
        }
    }

    /// Where in the file (`None` for I/O and format errors).
    pub fn location(&self) -> Option<&str> {
        match self {
            LoadError::Parse { location, .. } => Some(location),
            _ => None,
        }
    }
}
