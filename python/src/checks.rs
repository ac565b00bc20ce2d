//! Checks the module makes before it starts work, in the CLI's words: `RAYPACK_ISA`
//! ([`raypack::Isa::env_report`]) and whether a render or a ray set fits in memory
//! ([`raypack::render::render_bytes`], the estimate behind `raypack render -r`), so that an impossible size
//! is a `MemoryError` at once instead of an abort of the interpreter.

use pyo3::exceptions::{PyMemoryError, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use raypack::render::RenderSettings;
use std::sync::atomic::{AtomicBool, Ordering};

/// Raises `RAYPACK_ISA`'s error as a `ValueError` (an unknown name or a value that is not
/// UTF-8), and warns once per process when it names a tier this CPU lacks (its best is used).
pub fn isa_env(py: Python<'_>) -> PyResult<()> {
    static WARNED: AtomicBool = AtomicBool::new(false);
    match raypack::Isa::env_report() {
        Err(e) => Err(PyValueError::new_err(e)),
        Ok(Some(w)) if !WARNED.swap(true, Ordering::Relaxed) => {
            let message = std::ffi::CString::new(w).unwrap_or_default();
            // Stack level 1: the caller's line (a native function has no frame of its own).
            PyErr::warn(py, &py.get_type::<PyUserWarning>(), &message, 1)
        }
        Ok(_) => Ok(()),
    }
}

/// Refuses a render whose buffers cannot fit: the CLI's estimate on `threads` threads (all
/// cores for `None`), plus the image the module returns (float32 RGB).
pub fn render_memory(settings: &RenderSettings, threads: Option<usize>) -> PyResult<()> {
    let (w, h) = (settings.width, settings.height);
    let threads = threads.unwrap_or_else(rayon::current_num_threads);
    let returned = 3 * std::mem::size_of::<f32>() as u64;
    let per_pixel = raypack::render::render_bytes_per_pixel(settings, false) + returned;
    let needed = raypack::render::render_bytes(settings, threads, false)
        .saturating_add((w as u64).saturating_mul(h as u64).saturating_mul(returned));
    fits("width, height", w, h, needed, per_pixel)
}

/// Refuses ray sets of `width × height` primary rays that are out of range or cannot fit:
/// the three sets, their reference hits, and the arrays returned (origins, directions and
/// `tfar` in float32 per ray of each set).
pub fn ray_sets_size(width: usize, height: usize) -> PyResult<()> {
    if width == 0 || height == 0 || width > 1 << 15 || height > 1 << 15 {
        return Err(PyValueError::new_err(format!(
            "width, height: expected 1 to 32768 rays each, got {width} x {height}"
        )));
    }
    let per_ray = raypack::raysets::BENCH_BYTES_PER_PIXEL + 3 * 7 * std::mem::size_of::<f32>() as u64;
    fits("width, height", width, height, (width * height) as u64 * per_ray, per_ray)
}

fn fits(names: &str, width: usize, height: usize, needed: u64, per_pixel: u64) -> PyResult<()> {
    raypack::system::check_fits(width, height, needed, per_pixel).map_err(|e| {
        let (w, h) = e.fits;
        PyMemoryError::new_err(format!(
            "{names}: {width} x {height}: {e}; use a smaller size, such as width={w}, height={h}"
        ))
    })
}

/// Reads a `threads=` argument: `None` (all cores) or an int from 1 to
/// [`raypack::system::max_threads`]. Anything else is an error naming the argument and the
/// range (a `TypeError` for a value that is not an int), never the int conversion's bare
/// `OverflowError`.
pub fn threads(value: &Bound<'_, PyAny>) -> PyResult<Option<usize>> {
    if value.is_none() {
        return Ok(None);
    }
    let max = raypack::system::max_threads();
    let message = || {
        let shown = value.repr().map_or_else(|_| "?".to_string(), |r| r.to_string());
        format!(
            "threads: expected None (all cores) or 1 to {max} threads ({} per logical CPU; this machine has {}), got {shown}",
            raypack::system::THREADS_PER_CPU,
            max / raypack::system::THREADS_PER_CPU
        )
    };
    if value.is_instance_of::<pyo3::types::PyBool>() || !value.is_instance_of::<pyo3::types::PyInt>() {
        return Err(pyo3::exceptions::PyTypeError::new_err(message()));
    }
    match value.extract::<i64>().ok().and_then(|n| usize::try_from(n).ok()) {
        Some(n) if (1..=max).contains(&n) => Ok(Some(n)),
        _ => Err(PyValueError::new_err(message())),
    }
}
