//! Warps from the unit square to directions and points, each with its density, as in pbrt-v4
//! (Pharr, Jakob, Humphreys, *Physically Based Rendering*, 4th ed., §A.5) and CS184's
//! `sampler.cpp`. Directions are in a local frame whose `+z` is the surface normal.

use crate::math::Vec3;
use crate::simd::{F32x1, Lanes};
use std::f32::consts::{FRAC_1_PI, FRAC_PI_4, PI, TAU};

/// Uniform direction on the `z >= 0` hemisphere; density [`UNIFORM_HEMISPHERE_PDF`].
#[inline]
pub fn uniform_hemisphere(u: (f32, f32)) -> Vec3 {
    let z = u.0;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = TAU * u.1;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`uniform_hemisphere`] per steradian.
pub const UNIFORM_HEMISPHERE_PDF: f32 = 1.0 / TAU;

/// Uniform direction on the unit sphere; density `1 / 4π`.
#[inline]
pub fn uniform_sphere(u: (f32, f32)) -> Vec3 {
    let z = 1.0 - 2.0 * u.0;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = TAU * u.1;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`uniform_sphere`] per steradian.
pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Shirley–Chiu concentric map of the unit square onto the unit disk:
/// [`concentric_disk_lanes`] on one lane.
#[inline]
pub fn concentric_disk(u: (f32, f32)) -> (f32, f32) {
    let (x, y) = concentric_disk_lanes(F32x1(u.0), F32x1(u.1));
    (x.0, y.0)
}

/// [`concentric_disk`] of every lane of `(u0, u1)`.
#[inline(always)]
pub fn concentric_disk_lanes<V: Lanes>(u0: V, u1: V) -> (V, V) {
    let (two, one, zero) = (V::splat(2.0), V::splat(1.0), V::splat(0.0));
    let (a, b) = (two * u0 - one, two * u1 - one);
    // θ = π/4 · b/a when |a| > |b|, else π/2 − π/4 · a/b (whose cosine and sine are the sine
    // and cosine of π/4 · a/b): both from one angle in [−π/4, π/4].
    let wide_a = a.abs().gt(b.abs());
    let r = wide_a.select(a, b);
    let (sin, cos) = sin_cos_quarter_lanes(V::splat(FRAC_PI_4) * (wide_a.select(b, a) / r));
    let x = r * wide_a.select(cos, sin);
    let y = r * wide_a.select(sin, cos);
    // The centre, where the ratio is 0 / 0.
    let centre = a.eq(zero) & b.eq(zero);
    (centre.select(zero, x), centre.select(zero, y))
}

/// `(sin x, cos x)` for `|x| <= π/4` by their Taylor polynomials to x⁹ and x¹⁰ (truncation
/// error below 3e-9 there, so the result is within about 2 ulp of the exact values): on this
/// interval, several times cheaper than the library's `sin_cos`, which a cosine-weighted
/// bounce otherwise pays for at every diffuse hit (PERFORMANCE.md, "Smaller measured
/// choices"). [`sin_cos_quarter_lanes`] on one lane.
#[inline]
pub fn sin_cos_quarter(x: f32) -> (f32, f32) {
    debug_assert!(x.abs() <= FRAC_PI_4 * (1.0 + 1e-6) || !x.is_finite());
    let (sin, cos) = sin_cos_quarter_lanes(F32x1(x));
    (sin.0, cos.0)
}

/// [`sin_cos_quarter`] of every lane of `x`.
#[inline(always)]
pub fn sin_cos_quarter_lanes<V: Lanes>(x: V) -> (V, V) {
    let c = V::splat;
    let x2 = x * x;
    let sin =
        x * (c(1.0) + x2 * (c(-1.0 / 6.0) + x2 * (c(1.0 / 120.0) + x2 * (c(-1.0 / 5040.0) + x2 * c(1.0 / 362_880.0)))));
    let cos = c(1.0)
        + x2 * (c(-0.5)
            + x2 * (c(1.0 / 24.0) + x2 * (c(-1.0 / 720.0) + x2 * (c(1.0 / 40_320.0) + x2 * c(-1.0 / 3_628_800.0)))));
    (sin, cos)
}

/// Cosine-weighted direction on the `z >= 0` hemisphere (Malley's method); density
/// [`cosine_hemisphere_pdf`].
#[inline]
pub fn cosine_hemisphere(u: (f32, f32)) -> Vec3 {
    let (x, y) = concentric_disk(u);
    Vec3::new(x, y, (1.0 - x * x - y * y).max(0.0).sqrt())
}

/// Density of [`cosine_hemisphere`] for a direction with `cos θ = cos_theta`.
#[inline]
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * FRAC_1_PI
}

/// Uniform direction in the cone of half-angle `acos(cos_max)` around `+z`; density
/// [`uniform_cone_pdf`].
#[inline]
pub fn uniform_cone(u: (f32, f32), cos_max: f32) -> Vec3 {
    let z = 1.0 - u.0 * (1.0 - cos_max);
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = TAU * u.1;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`uniform_cone`].
#[inline]
pub fn uniform_cone_pdf(cos_max: f32) -> f32 {
    1.0 / (TAU * (1.0 - cos_max))
}

/// Barycentric coordinates `(b1, b2)` of a uniform point on a triangle
/// (`p = (1 - b1 - b2) v0 + b1 v1 + b2 v2`), by the square-root warp.
#[inline]
pub fn uniform_triangle(u: (f32, f32)) -> (f32, f32) {
    let s = u.0.sqrt();
    (u.1 * s, 1.0 - s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampler::Rng;

    #[test]
    fn quarter_sin_cos_is_within_rounding_of_the_exact_values() {
        let mut worst = 0.0f64;
        for i in -100_000..=100_000 {
            let x = FRAC_PI_4 * i as f32 / 100_000.0;
            let (s, c) = sin_cos_quarter(x);
            let (es, ec) = (x as f64).sin_cos();
            worst = worst.max((s as f64 - es).abs()).max((c as f64 - ec).abs());
        }
        // 2 ulp of 1.0 (the largest value either takes).
        assert!(worst <= 2.0 * f32::EPSILON as f64, "worst error {worst:e}");
    }

    #[test]
    fn concentric_disk_matches_the_angle_form() {
        let mut rng = Rng::new(3, 7);
        for _ in 0..100_000 {
            let u = (rng.next_f32(), rng.next_f32());
            let (a, b) = (2.0 * u.0 as f64 - 1.0, 2.0 * u.1 as f64 - 1.0);
            let (r, theta) = if a.abs() > b.abs() {
                (a, std::f64::consts::FRAC_PI_4 * (b / a))
            } else {
                (b, std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (a / b))
            };
            let (x, y) = concentric_disk(u);
            assert!((x as f64 - r * theta.cos()).abs() < 1e-6 && (y as f64 - r * theta.sin()).abs() < 1e-6, "{u:?}");
            assert!(x * x + y * y <= 1.0 + 4.0 * f32::EPSILON);
        }
        assert_eq!(concentric_disk((0.5, 0.5)), (0.0, 0.0));
    }

    /// Monte Carlo check that a warp's density is right: the mean of `g(w) / pdf(w)` over
    /// its samples estimates the integral of `g` over the warp's support.
    fn integral(n: usize, mut warp: impl FnMut((f32, f32)) -> (Vec3, f32), g: impl Fn(Vec3) -> f32) -> f64 {
        let mut rng = Rng::new(3, 9);
        let mut sum = 0.0f64;
        for _ in 0..n {
            let (w, pdf) = warp(rng.next_2d());
            assert!((w.length() - 1.0).abs() < 1e-4, "unit directions");
            sum += (g(w) / pdf) as f64;
        }
        sum / n as f64
    }

    #[test]
    fn densities_integrate_known_functions() {
        let n = 200_000;
        // ∫_H cos θ dω = π; ∫_S z² dω = 4π/3; ∫_H dω = 2π.
        let cos = |w: Vec3| w.z.max(0.0);
        let hemi = integral(n, |u| (uniform_hemisphere(u), UNIFORM_HEMISPHERE_PDF), cos);
        assert!((hemi - PI as f64).abs() < 0.01, "{hemi}");
        let cosw = integral(n, |u| (cosine_hemisphere(u), cosine_hemisphere_pdf(cosine_hemisphere(u).z)), |_| 1.0);
        assert!((cosw - TAU as f64).abs() < 0.05, "{cosw}");
        let sph = integral(n, |u| (uniform_sphere(u), UNIFORM_SPHERE_PDF), |w| w.z * w.z);
        assert!((sph - 4.0 * PI as f64 / 3.0).abs() < 0.02, "{sph}");
        let cm = 0.8;
        let cone = integral(n, |u| (uniform_cone(u, cm), uniform_cone_pdf(cm)), |_| 1.0);
        assert!((cone - (TAU * (1.0 - cm)) as f64).abs() < 1e-3, "{cone}");
        // Every cone sample lies inside the cone.
        let mut rng = Rng::new(1, 1);
        assert!((0..1000).all(|_| uniform_cone(rng.next_2d(), cm).z >= cm - 1e-6));
    }

    #[test]
    fn triangle_warp_is_uniform() {
        let mut rng = Rng::new(5, 5);
        let n = 100_000;
        let (mut inside_sub, mut mean) = (0usize, (0.0f64, 0.0f64));
        for _ in 0..n {
            let (b1, b2) = uniform_triangle(rng.next_2d());
            assert!(b1 >= 0.0 && b2 >= 0.0 && b1 + b2 <= 1.0 + 1e-6);
            // The sub-triangle b1 + b2 <= 1/2 holds a quarter of the area.
            inside_sub += (b1 + b2 <= 0.5) as usize;
            mean.0 += b1 as f64;
            mean.1 += b2 as f64;
        }
        assert!((inside_sub as f64 / n as f64 - 0.25).abs() < 0.005);
        assert!((mean.0 / n as f64 - 1.0 / 3.0).abs() < 0.005 && (mean.1 / n as f64 - 1.0 / 3.0).abs() < 0.005);
    }
}
