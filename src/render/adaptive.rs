//! Adaptive sampling (CS184 part 5) and its sample-rate image.
//!
//! Per pixel, the sums `s1 = Σ x` and `s2 = Σ x²` of the samples' illuminance `x` are kept.
//! After every batch, with `n` samples taken, the mean `μ = s1 / n` and variance
//! `σ² = (s2 - s1² / n) / (n - 1)` give the 95% confidence half-width `I = 1.96 σ / √n`; the
//! pixel stops once `I ≤ tol · μ`. Its value is the mean over the samples actually taken.

use super::film::Film;
use crate::math::Vec3;
use glam::DVec3;
use std::path::{Path, PathBuf};

/// Illuminance of a linear RGB radiance (Rec. 709 luminance weights, CS184's `illum()`).
#[inline]
pub fn illuminance(v: Vec3) -> f32 {
    0.2126 * v.x + 0.7152 * v.y + 0.0722 * v.z
}

/// A pixel's running estimate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PixelEstimate {
    /// Sum of the sample radiances.
    pub sum: DVec3,
    /// Sum of the sample illuminances.
    pub s1: f64,
    /// Sum of the squared sample illuminances.
    pub s2: f64,
    /// Samples taken.
    pub n: u32,
    /// True once the pixel needs no more samples.
    pub done: bool,
}

impl PixelEstimate {
    /// Adds one sample.
    #[inline]
    pub fn add(&mut self, radiance: Vec3) {
        let x = illuminance(radiance) as f64;
        self.sum += radiance.as_dvec3();
        self.s1 += x;
        self.s2 += x * x;
        self.n += 1;
    }

    /// The mean radiance of the samples taken (black before any).
    pub fn mean(&self) -> Vec3 {
        if self.n == 0 { Vec3::ZERO } else { (self.sum / self.n as f64).as_vec3() }
    }

    /// CS184's test: `1.96 σ / √n ≤ tol μ` (needs at least two samples).
    pub fn converged(&self, tolerance: f32) -> bool {
        if self.n < 2 {
            return false;
        }
        let n = self.n as f64;
        let mean = self.s1 / n;
        let var = ((self.s2 - self.s1 * self.s1 / n) / (n - 1.0)).max(0.0);
        1.96 * (var / n).sqrt() <= tolerance as f64 * mean
    }
}

/// CS184's sample-rate colour: `ratio` in `[0, 1]` (samples taken / maximum) from blue
/// through green to red.
pub fn rate_colour(ratio: f32) -> Vec3 {
    let t = ratio.clamp(0.0, 1.0);
    if t <= 0.5 { Vec3::new(0.0, 2.0 * t, 1.0 - 2.0 * t) } else { Vec3::new(2.0 * t - 1.0, 2.0 - 2.0 * t, 0.0) }
}

/// The sample-rate image of per-pixel sample counts `spp` (row-major, `width` wide), relative
/// to `max_samples`; encode it with [`super::Encoding::Display`].
pub fn rate_film(spp: &[u32], width: usize, height: usize, max_samples: u32) -> Film {
    let mut film = Film::new(width, height);
    for (p, &n) in film.pixels.iter_mut().zip(spp) {
        *p = rate_colour(n as f32 / max_samples.max(1) as f32);
    }
    film
}

/// The sample-rate image as 8-bit RGB with its legend beneath (cargo feature `image`): the
/// pixels of [`rate_film`] and a colour bar drawn with the same [`rate_colour`] from 0 to
/// `max_samples` samples per pixel, labelled with round counts and the mean count. Returns
/// the width, the height and the bytes; the image's rows come first, so that its pixels line
/// up with the render's.
#[cfg(feature = "image")]
pub fn rate_image(spp: &[u32], width: usize, height: usize, max_samples: u32) -> (usize, usize, Vec<u8>) {
    use super::colorbar;
    let film = rate_film(spp, width, height, max_samples);
    let (title_h, bar_h) = (colorbar::title_height(), colorbar::height());
    let h = height + title_h + bar_h;
    let mut rgb = film.to_rgb8(super::Encoding::Display);
    rgb.resize(width * h * 3, 255);
    let scale = colorbar::Scale::Linear { max: max_samples as f64 };
    let mean = spp.iter().map(|&n| n as f64).sum::<f64>() / spp.len().max(1) as f64;
    let to_rgb = |c: Vec3| [c.x, c.y, c.z].map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
    colorbar::draw_title(
        &mut rgb[width * height * 3..width * (height + title_h) * 3],
        width,
        "SAMPLES PER PIXEL",
        &scale,
    );
    colorbar::draw(&mut rgb[width * (height + title_h) * 3..], width, &scale, Some(mean), |f| {
        to_rgb(rate_colour(f as f32))
    });
    (width, h, rgb)
}

/// `<out>_rate.png` beside the image `out` (CS184's name for the rate image).
pub fn rate_path(out: &Path) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    out.with_file_name(format!("{stem}_rate.png"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_samples_converge_at_once_and_noise_does_not() {
        let mut flat = PixelEstimate::default();
        let mut noisy = PixelEstimate::default();
        for i in 0..64 {
            flat.add(Vec3::splat(0.5));
            noisy.add(Vec3::splat(if i % 2 == 0 { 0.0 } else { 1.0 }));
        }
        assert!(flat.converged(0.05));
        assert_eq!(flat.mean(), Vec3::splat(0.5));
        // σ ≈ 0.5, μ = 0.5: I = 1.96 · 0.5 / 8 ≈ 0.12 > 0.05 · 0.5.
        assert!(!noisy.converged(0.05));
        assert!(noisy.converged(0.5));
        // Black pixels (μ = σ = 0) are converged too, as in CS184.
        let mut black = PixelEstimate::default();
        black.add(Vec3::ZERO);
        black.add(Vec3::ZERO);
        assert!(black.converged(0.05));
    }

    #[test]
    fn rate_colours_and_path() {
        assert_eq!(rate_colour(0.0), Vec3::new(0.0, 0.0, 1.0));
        assert_eq!(rate_colour(0.5), Vec3::new(0.0, 1.0, 0.0));
        assert_eq!(rate_colour(1.0), Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(rate_path(Path::new("out/cb.png")), PathBuf::from("out/cb_rate.png"));
        assert_eq!(rate_path(Path::new("cb.exr")), PathBuf::from("cb_rate.png"));
    }
}
