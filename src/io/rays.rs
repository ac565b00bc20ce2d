//! Ray files: a ray set on disk, so that anyone can trace the very same rays in raypack,
//! Embree or another tracer.
//!
//! Two layouts, chosen by extension:
//!
//! * **`.rays`** (raw): no header; ray after ray, each 8 little-endian IEEE-754 `f32`, 32
//!   bytes: `origin.x origin.y origin.z dir.x dir.y dir.z tnear tfar`. The file's length is a
//!   multiple of 32. (`numpy.asarray(a, "<f4").tofile(path)` writes one from an `(N, 8)` array.)
//! * **`.npy`**: a NumPy array of shape `(N, 8)`, dtype `<f4` (little-endian float32), C
//!   order, the same 8 values per row; format versions 1.0, 2.0 and 3.0 are read, 1.0 is
//!   written (`numpy.save(path, a.astype("<f4"))`).
//!
//! A ray covers `t ∈ [tnear, tfar]` in units of `|dir|` (`tfar` may be `+inf`, written as
//! the IEEE infinity). Every ray read must be valid ([`Ray::is_valid`]): finite origin and
//! direction, a non-zero direction, `0 <= tnear <= tfar`; a file with an invalid ray is an
//! error naming the ray's index, not a set in which some rays silently miss (the Python
//! module likewise raises a `ValueError` for a negative `tnear` or `tfar`).

use crate::math::Vec3;
use crate::ray::Ray;
use std::path::{Path, PathBuf};

/// Bytes per ray in both layouts.
pub const RAY_BYTES: usize = 32;
const NPY_MAGIC: &[u8] = b"\x93NUMPY";

/// Why a ray file cannot be read or written. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum RayFileError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The extension is neither `.rays` nor `.npy`.
    #[error("{path}: unknown ray file format (expected .rays, raw 8 x f32 per ray, or .npy, float32 (N, 8))")]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// The content is malformed.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where.
        message: String,
    },
}

/// The two layouts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RayFileFormat {
    /// Headerless little-endian `f32 × 8` per ray.
    Raw,
    /// NumPy `.npy`, float32 `(N, 8)`.
    Npy,
}

impl RayFileFormat {
    /// The layout named by the file's extension (`.rays` or `.npy`, case-insensitive).
    pub fn of(path: &Path) -> Option<Self> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "rays" => Some(RayFileFormat::Raw),
            "npy" => Some(RayFileFormat::Npy),
            _ => None,
        }
    }
}

/// Reads the rays of `path` (layout by extension), if it is a regular file of at most
/// [`crate::fs::input::MAX_RAY_FILE_BYTES`] (a FIFO or `/dev/zero` is an error, not a hang
/// or an endless read).
pub fn read_rays(path: &Path) -> Result<Vec<Ray>, RayFileError> {
    use crate::fs::input::{MAX_RAY_FILE_BYTES, read_regular};
    let format = RayFileFormat::of(path).ok_or_else(|| RayFileError::UnknownFormat { path: path.into() })?;
    let bytes = read_regular(path, MAX_RAY_FILE_BYTES, "ray files")
        .map_err(|source| RayFileError::Io { path: path.into(), source })?;
    parse_rays(&bytes, format, path)
}

/// Parses the bytes of a ray file of `format`; `path` names it in errors.
pub fn parse_rays(bytes: &[u8], format: RayFileFormat, path: &Path) -> Result<Vec<Ray>, RayFileError> {
    let err = |message: String| RayFileError::Format { path: path.into(), message };
    let data = match format {
        RayFileFormat::Raw => bytes,
        RayFileFormat::Npy => npy_data(bytes).map_err(err)?,
    };
    if data.len() % RAY_BYTES != 0 {
        return Err(err(format!(
            "{} bytes of ray data is not a whole number of rays ({RAY_BYTES} bytes, 8 x f32, each)",
            data.len()
        )));
    }
    let mut rays = Vec::with_capacity(data.len() / RAY_BYTES);
    for (i, chunk) in data.chunks_exact(RAY_BYTES).enumerate() {
        let f: [f32; 8] = std::array::from_fn(|k| f32::from_le_bytes(chunk[4 * k..4 * k + 4].try_into().unwrap()));
        let ray = Ray::segment(Vec3::new(f[0], f[1], f[2]), Vec3::new(f[3], f[4], f[5]), f[6], f[7]);
        if !ray.is_valid() {
            return Err(err(format!(
                "ray {i} (origin {:?}, dir {:?}, tnear {}, tfar {}) is invalid: need a finite origin and non-zero \
                 direction and 0 <= tnear <= tfar",
                [f[0], f[1], f[2]],
                [f[3], f[4], f[5]],
                f[6],
                f[7]
            )));
        }
        rays.push(ray);
    }
    Ok(rays)
}

/// The array bytes of a `.npy` file holding float32 `(N, 8)` in C order.
fn npy_data(bytes: &[u8]) -> Result<&[u8], String> {
    if bytes.len() < 10 || &bytes[..6] != NPY_MAGIC {
        return Err("not a .npy file (no \\x93NUMPY magic)".into());
    }
    let (major, minor) = (bytes[6], bytes[7]);
    let (len, start) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize, 12),
        _ => return Err(format!(".npy format version {major}.{minor} is not supported (1.0, 2.0 and 3.0 are)")),
    };
    let header = bytes.get(start..start + len).ok_or("the .npy header runs past the end of the file")?;
    let header = std::str::from_utf8(header).map_err(|_| "the .npy header is not text")?;
    let value = |key: &str| -> Result<&str, String> {
        let at = header.find(&format!("'{key}'")).ok_or(format!("the .npy header has no '{key}': {header}"))?;
        let rest = header[at + key.len() + 2..].trim_start();
        Ok(rest.strip_prefix(':').ok_or(format!("the .npy header is malformed after '{key}': {header}"))?.trim_start())
    };
    let descr = value("descr")?;
    if !(descr.starts_with("'<f4'") || descr.starts_with("'float32'")) {
        let shown = descr.split([',', '}']).next().unwrap_or(descr);
        return Err(format!("dtype {shown}: ray arrays must be little-endian float32 ('<f4'); use a.astype('<f4')"));
    }
    if !value("fortran_order")?.starts_with("False") {
        return Err("the array is in Fortran order; save a C-ordered one (numpy.ascontiguousarray)".into());
    }
    let shape = value("shape")?;
    let inner = shape
        .strip_prefix('(')
        .and_then(|s| s.split(')').next())
        .ok_or(format!("the .npy shape is malformed: {header}"))?;
    let dims: Vec<&str> = inner.split(',').map(str::trim).filter(|s| !s.is_empty()).collect();
    let n = match dims.as_slice() {
        [n, "8"] => n.parse::<usize>().map_err(|_| format!("the .npy shape ({inner}) is malformed"))?,
        _ => return Err(format!("array shape ({inner}): ray arrays must have shape (N, 8)")),
    };
    let data = &bytes[start + len..];
    let want = n.checked_mul(RAY_BYTES).ok_or(format!("array shape ({inner}) is too large"))?;
    if data.len() != want {
        return Err(format!("shape ({inner}) needs {want} bytes of data, the file has {}", data.len()));
    }
    Ok(data)
}

/// The bytes of a ray file of `format` holding `rays`.
pub fn encode_rays(rays: &[Ray], format: RayFileFormat) -> Vec<u8> {
    let mut out = Vec::with_capacity(rays.len() * RAY_BYTES + 128);
    if format == RayFileFormat::Npy {
        let dict = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, 8), }}", rays.len());
        // Magic, version, u16 length, the header padded with spaces to a multiple of 64
        // bytes and ended by a newline (the .npy specification).
        let unpadded = NPY_MAGIC.len() + 4 + dict.len() + 1;
        let header_len = dict.len() + 1 + (64 - unpadded % 64) % 64;
        out.extend_from_slice(NPY_MAGIC);
        out.extend_from_slice(&[1, 0]);
        out.extend_from_slice(&(header_len as u16).to_le_bytes());
        out.extend_from_slice(dict.as_bytes());
        out.resize(NPY_MAGIC.len() + 4 + header_len - 1, b' ');
        out.push(b'\n');
    }
    for r in rays {
        for v in r.to_array() {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// Writes `rays` to `path` (layout by extension), whole or not at all.
pub fn write_rays(path: &Path, rays: &[Ray]) -> Result<(), RayFileError> {
    let format = RayFileFormat::of(path).ok_or_else(|| RayFileError::UnknownFormat { path: path.into() })?;
    crate::fs::output::write_file(path, &encode_rays(rays, format))
        .map_err(|e| RayFileError::Io { path: e.path, source: e.source })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn some_rays() -> Vec<Ray> {
        vec![
            Ray::new(Vec3::new(1.0, -2.0, 3.5), Vec3::new(0.0, 0.6, -0.8)),
            Ray::segment(Vec3::ZERO, Vec3::X, 0.25, 7.0),
            Ray::segment(Vec3::splat(-1e30), Vec3::new(1e-3, 0.0, 0.0), 0.0, 0.0),
        ]
    }

    #[test]
    fn both_layouts_round_trip_bit_for_bit() {
        for format in [RayFileFormat::Raw, RayFileFormat::Npy] {
            let bytes = encode_rays(&some_rays(), format);
            let back = parse_rays(&bytes, format, Path::new("x")).unwrap();
            let bits = |r: &[Ray]| r.iter().flat_map(|r| r.to_array().map(f32::to_bits)).collect::<Vec<_>>();
            assert_eq!(bits(&back), bits(&some_rays()), "{format:?}");
        }
        let npy = encode_rays(&some_rays(), RayFileFormat::Npy);
        // The header (magic to newline) is 64-byte aligned, as the specification asks.
        assert_eq!((npy.len() - 3 * RAY_BYTES) % 64, 0);
        assert_eq!(npy[npy.len() - 3 * RAY_BYTES - 1], b'\n');
    }

    #[test]
    fn bad_files_are_clear_errors() {
        let p = Path::new("set.npy");
        let msg = |bytes: &[u8], f| parse_rays(bytes, f, p).unwrap_err().to_string();
        assert!(msg(&[0; 33], RayFileFormat::Raw).contains("not a whole number of rays"));
        assert!(msg(b"hello world", RayFileFormat::Npy).contains("not a .npy file"));
        let npy = encode_rays(&some_rays(), RayFileFormat::Npy);
        let replace = |from: &str, to: &str| {
            let at = npy.windows(from.len()).position(|w| w == from.as_bytes()).unwrap();
            [&npy[..at], to.as_bytes(), &npy[at + from.len()..]].concat()
        };
        let f8 = replace("<f4", "<f8");
        assert!(msg(&f8, RayFileFormat::Npy).contains("float32"), "{}", msg(&f8, RayFileFormat::Npy));
        let shape = replace("(3, 8)", "(8, 3)");
        assert!(msg(&shape, RayFileFormat::Npy).contains("shape (N, 8)"));
        assert!(msg(&npy[..npy.len() - 4], RayFileFormat::Npy).contains("needs 96 bytes"));
        let mut bad = some_rays();
        bad[1].dir = Vec3::ZERO;
        let m = msg(&encode_rays(&bad, RayFileFormat::Raw), RayFileFormat::Raw);
        assert!(m.starts_with("set.npy: ray 1 ") && m.contains("invalid"), "{m}");
    }
}
