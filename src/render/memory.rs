//! The memory a render needs beyond its scene, estimated before it starts, so that a size
//! whose buffers cannot fit is refused up front ([`crate::system::check_fits`]). The estimate
//! counts the buffers that grow with the image; the scene and its BVH come on top, so an
//! estimate that barely fits may still fail.

use super::{PASS_SAMPLES, RenderSettings, TILE};

/// Bytes per pixel that a render keeps until its image is written: the tile results
/// ([`super::adaptive::PixelEstimate`]), the film (linear RGB), the sample counts and
/// the encoded output (8-bit RGB plus the PNG; an EXR needs twice the film), and the
/// sample-rate image with `-a`.
pub fn render_bytes_per_pixel(settings: &RenderSettings, exr: bool) -> u64 {
    let estimate = std::mem::size_of::<super::adaptive::PixelEstimate>();
    let film = std::mem::size_of::<crate::math::Vec3>();
    let output = if exr { 2 * film } else { 3 + 3 };
    let rate = if settings.adaptive.is_some() { film + 3 + 3 } else { 0 };
    (estimate + film + std::mem::size_of::<u32>() + output + rate) as u64
}

/// Bytes a render of `settings` on `threads` threads needs beyond the scene: every pixel
/// ([`render_bytes_per_pixel`]) plus each thread's tile and wavefront buffers (bounded by
/// [`PASS_SAMPLES`] and the wavefront's wave size, whatever the sample count; counted for the
/// light samples of one area light per shading point).
pub fn render_bytes(settings: &RenderSettings, threads: usize, exr: bool) -> u64 {
    let pixels = settings.width as u64 * settings.height as u64;
    let paths = TILE * TILE * PASS_SAMPLES.min(settings.samples_per_pixel.max(1)) as usize;
    let tile = super::wavefront::worker_bytes(paths, settings.light_samples.max(1) as usize)
        + (paths * std::mem::size_of::<u32>()) as u64;
    pixels.saturating_mul(render_bytes_per_pixel(settings, exr)).saturating_add((threads as u64).saturating_mul(tile))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_estimate_grows_with_pixels_not_samples() {
        let small = RenderSettings { width: 16, height: 16, samples_per_pixel: 1, ..RenderSettings::default() };
        let many = RenderSettings { samples_per_pixel: u32::MAX, adaptive: Some((u32::MAX, 0.05)), ..small.clone() };
        // Two workers' wavefronts of a 16-sample pass (4096 paths each): under 1 MB apiece.
        assert!(render_bytes(&many, 2, false) < 2 << 20, "{}", render_bytes(&many, 2, false));
        let huge = RenderSettings { width: 32768, height: 32768, ..small };
        let bytes = render_bytes(&huge, 2, false);
        assert!(bytes > 60_000_000_000 && bytes < 100_000_000_000, "{}", crate::system::human(bytes));
    }
}
