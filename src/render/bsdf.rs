//! Scattering functions of the scene's [`Bsdf`]s, written in the local shading frame
//! ([`super::frame::Frame`]: `+z` is the shading normal).
//!
//! * Lambertian diffuse: `f = albedo / π`, sampled cosine-weighted.
//! * Mirror: perfect specular reflection (a delta distribution).
//! * Glass: a smooth dielectric; Fresnel reflectance by Schlick's approximation (as CS184),
//!   taken at the angle in the outside medium, refraction by Snell's law, total internal
//!   reflection; the transmitted radiance is scaled by `1/η²` (radiance transport, pbrt-v4
//!   §9.5.2). The reflect/refract choice is sampled in proportion to the Fresnel terms.
//! * Microfacet conductor (CS184 part 5; Walter et al., "Microfacet Models for Refraction
//!   through Rough Surfaces", EGSR 2007): Beckmann distribution, Smith shadowing with Walter's
//!   rational approximation of Λ, air–conductor Fresnel for the complex index `η + ik`,
//!   importance sampling of the half vector by the Beckmann distribution.
//!
//! Diffuse, mirror and microfacet surfaces reflect on both sides (`wo` may have `z < 0`); glass
//! is oriented: `+z` points outside.

use super::sampling::{cosine_hemisphere, cosine_hemisphere_pdf};
use crate::math::Vec3;
use crate::scene::Bsdf;
use std::f32::consts::{FRAC_1_PI, PI, TAU};

/// A direction drawn from a BSDF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    /// Incident direction (local, unit).
    pub wi: Vec3,
    /// `f(wo, wi) |cos θi| / pdf`: what the path throughput is multiplied by.
    pub weight: Vec3,
    /// Density of `wi` per steradian (for delta lobes: the probability of choosing the lobe).
    pub pdf: f32,
    /// True for specular (delta) lobes, which light sampling cannot reach.
    pub delta: bool,
    /// Factor by which the sample scales radiance for crossing an interface (`η²` of the
    /// crossing, 1 for reflection); Russian roulette divides it out, as pbrt's `etaScale`.
    pub eta_scale: f32,
}

/// True when the BSDF is made only of delta lobes (light sampling is useless there).
#[inline]
pub fn is_delta(bsdf: &Bsdf) -> bool {
    matches!(bsdf, Bsdf::Mirror { .. } | Bsdf::Glass { .. })
}

/// `f(wo, wi)`, zero for delta lobes.
#[inline]
pub fn f(bsdf: &Bsdf, wo: Vec3, wi: Vec3) -> Vec3 {
    match *bsdf {
        Bsdf::Diffuse { albedo } => {
            if wo.z * wi.z > 0.0 {
                albedo * FRAC_1_PI
            } else {
                Vec3::ZERO
            }
        }
        Bsdf::Mirror { .. } | Bsdf::Glass { .. } => Vec3::ZERO,
        Bsdf::Microfacet { eta, k, alpha } => {
            let s = wo.z.signum();
            microfacet_f(wo * Vec3::new(1.0, 1.0, s), wi * Vec3::new(1.0, 1.0, s), eta, k, alpha)
        }
    }
}

/// Density with which [`sample_f`] returns `wi` given `wo` (zero for delta lobes).
#[inline]
pub fn pdf(bsdf: &Bsdf, wo: Vec3, wi: Vec3) -> f32 {
    match *bsdf {
        Bsdf::Diffuse { .. } => {
            if wo.z * wi.z > 0.0 {
                cosine_hemisphere_pdf(wi.z.abs())
            } else {
                0.0
            }
        }
        Bsdf::Mirror { .. } | Bsdf::Glass { .. } => 0.0,
        Bsdf::Microfacet { alpha, .. } => {
            if wo.z * wi.z <= 0.0 {
                return 0.0;
            }
            let s = wo.z.signum();
            let (wo, wi) = (wo * Vec3::new(1.0, 1.0, s), wi * Vec3::new(1.0, 1.0, s));
            let h = (wo + wi).normalize_or_zero();
            beckmann_d(h, alpha_of(alpha)) * h.z / (4.0 * wi.dot(h).abs())
        }
    }
}

/// Draws `wi` given `wo` from two uniforms `u` (direction) and `uc` (lobe choice).
/// `None` when the sample carries no energy.
#[inline]
pub fn sample_f(bsdf: &Bsdf, wo: Vec3, u: (f32, f32), uc: f32) -> Option<BsdfSample> {
    if wo.z == 0.0 {
        return None;
    }
    match *bsdf {
        Bsdf::Diffuse { albedo } => {
            let mut wi = cosine_hemisphere(u);
            if wi.z == 0.0 {
                return None;
            }
            wi.z = wi.z.copysign(wo.z);
            let pdf = cosine_hemisphere_pdf(wi.z.abs());
            Some(BsdfSample { wi, weight: albedo, pdf, delta: false, eta_scale: 1.0 })
        }
        Bsdf::Mirror { reflectance } => Some(BsdfSample {
            wi: Vec3::new(-wo.x, -wo.y, wo.z),
            weight: reflectance,
            pdf: 1.0,
            delta: true,
            eta_scale: 1.0,
        }),
        Bsdf::Glass { reflectance, transmittance, ior, .. } => sample_glass(wo, uc, reflectance, transmittance, ior),
        Bsdf::Microfacet { eta, k, alpha } => {
            let s = wo.z.signum();
            let flip = Vec3::new(1.0, 1.0, s);
            let wo = wo * flip;
            let a = alpha_of(alpha);
            // CS184 part 5: tan²θh = -α² ln(1 - u), φh = 2π u'.
            let tan2 = -a * a * (1.0 - u.0).ln();
            let cos_h = 1.0 / (1.0 + tan2).sqrt();
            let sin_h = (1.0 - cos_h * cos_h).max(0.0).sqrt();
            let phi = TAU * u.1;
            let h = Vec3::new(sin_h * phi.cos(), sin_h * phi.sin(), cos_h);
            let wi = -wo + h * (2.0 * wo.dot(h));
            if wi.z <= 0.0 {
                return None;
            }
            let pdf = beckmann_d(h, a) * h.z / (4.0 * wi.dot(h).abs());
            let fv = microfacet_f(wo, wi, eta, k, alpha);
            if !(pdf > 0.0) || fv == Vec3::ZERO {
                return None;
            }
            Some(BsdfSample { wi: wi * flip, weight: fv * wi.z / pdf, pdf, delta: false, eta_scale: 1.0 })
        }
    }
}

/// Schlick's approximation of the dielectric Fresnel reflectance for `cos θ` measured in the
/// less dense medium and relative index `ior`.
#[inline]
pub fn schlick(cos_theta: f32, ior: f32) -> f32 {
    let r0 = ((1.0 - ior) / (1.0 + ior)).powi(2);
    r0 + (1.0 - r0) * (1.0 - cos_theta).clamp(0.0, 1.0).powi(5)
}

/// The refracted direction of `wo` through the local `z = 0` interface (`+z` outside, index
/// `ior` inside), or `None` on total internal reflection. Also returns `cos θt`.
#[inline]
pub fn refract(wo: Vec3, ior: f32) -> Option<(Vec3, f32)> {
    // η = η_incident / η_transmitted.
    let eta = if wo.z > 0.0 { 1.0 / ior } else { ior };
    let cos_i = wo.z.abs();
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((Vec3::new(-eta * wo.x, -eta * wo.y, -cos_t.copysign(wo.z)), cos_t))
}

fn sample_glass(wo: Vec3, uc: f32, reflectance: Vec3, transmittance: Vec3, ior: f32) -> Option<BsdfSample> {
    let reflect = Vec3::new(-wo.x, -wo.y, wo.z);
    let Some((refracted, cos_t)) = refract(wo, ior) else {
        // Total internal reflection.
        return Some(BsdfSample { wi: reflect, weight: reflectance, pdf: 1.0, delta: true, eta_scale: 1.0 });
    };
    let entering = wo.z > 0.0;
    let r = schlick(if entering { wo.z } else { cos_t }, ior);
    if uc < r {
        Some(BsdfSample { wi: reflect, weight: reflectance, pdf: r, delta: true, eta_scale: 1.0 })
    } else {
        // η' = η_wi-side / η_wo-side; radiance arriving from the wi side is scaled by 1/η'².
        let etap = if entering { ior } else { 1.0 / ior };
        let eta2 = etap * etap;
        Some(BsdfSample { wi: refracted, weight: transmittance / eta2, pdf: 1.0 - r, delta: true, eta_scale: eta2 })
    }
}

#[inline]
fn alpha_of(alpha: f32) -> f32 {
    // Below this the lobe is a mirror in all but name and its density overflows.
    alpha.max(1e-3)
}

/// Beckmann normal distribution `D(h)` (per steradian of `h`, `∫ D cos θh dω = 1`).
#[inline]
fn beckmann_d(h: Vec3, alpha: f32) -> f32 {
    let cos2 = h.z * h.z;
    if cos2 <= 0.0 {
        return 0.0;
    }
    let tan2 = (1.0 - cos2) / cos2;
    let a2 = alpha * alpha;
    (-tan2 / a2).exp() / (PI * a2 * cos2 * cos2)
}

/// Smith's Λ for Beckmann, Walter et al.'s rational approximation.
#[inline]
fn beckmann_lambda(w: Vec3, alpha: f32) -> f32 {
    let cos = w.z.abs();
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    if sin == 0.0 {
        return 0.0;
    }
    let a = cos / (alpha * sin);
    if a >= 1.6 { 0.0 } else { (1.0 - 1.259 * a + 0.396 * a * a) / (3.535 * a + 2.181 * a * a) }
}

/// Fresnel reflectance of an air–conductor interface, per channel (CS184 part 5).
#[inline]
pub fn fresnel_conductor(cos_i: f32, eta: Vec3, k: Vec3) -> Vec3 {
    let c = cos_i.clamp(0.0, 1.0);
    let c2 = Vec3::splat(c * c);
    let e2k2 = eta * eta + k * k;
    let two_eta_c = eta * (2.0 * c);
    let rs = (e2k2 - two_eta_c + c2) / (e2k2 + two_eta_c + c2);
    let rp = (e2k2 * c2 - two_eta_c + Vec3::ONE) / (e2k2 * c2 + two_eta_c + Vec3::ONE);
    ((rs + rp) * 0.5).clamp(Vec3::ZERO, Vec3::ONE)
}

/// The microfacet BRDF for `wo.z > 0`.
#[inline]
fn microfacet_f(wo: Vec3, wi: Vec3, eta: Vec3, k: Vec3, alpha: f32) -> Vec3 {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return Vec3::ZERO;
    }
    let a = alpha_of(alpha);
    let h = (wo + wi).normalize_or_zero();
    if h == Vec3::ZERO {
        return Vec3::ZERO;
    }
    let g = 1.0 / (1.0 + beckmann_lambda(wo, a) + beckmann_lambda(wi, a));
    fresnel_conductor(wi.dot(h), eta, k) * (g * beckmann_d(h, a) / (4.0 * wo.z * wi.z))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampler::Rng;
    use crate::render::sampling::{UNIFORM_SPHERE_PDF, uniform_sphere};

    fn dir(theta_deg: f32, phi_deg: f32) -> Vec3 {
        let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
        Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
    }

    /// Directional albedo ∫ f |cos θi| dω two ways: by the BSDF's own sampling and by uniform
    /// sphere sampling; both must agree (this checks `f`, `pdf` and `sample_f` together).
    fn albedo_two_ways(b: &Bsdf, wo: Vec3, n: usize) -> (f32, f32) {
        let mut rng = Rng::new(11, 4);
        let (mut by_bsdf, mut by_sphere) = (0.0f64, 0.0f64);
        for _ in 0..n {
            if let Some(s) = sample_f(b, wo, rng.next_2d(), rng.next_f32()) {
                by_bsdf += s.weight.x as f64;
                if !s.delta {
                    let p = pdf(b, wo, s.wi);
                    assert!((p - s.pdf).abs() <= 1e-3 * s.pdf.max(1.0), "pdf() {p} vs sample {}", s.pdf);
                    let w = f(b, wo, s.wi).x * s.wi.z.abs() / s.pdf;
                    assert!((w - s.weight.x).abs() <= 1e-3 * w.max(1.0));
                }
            }
            let wi = uniform_sphere(rng.next_2d());
            by_sphere += (f(b, wo, wi).x * wi.z.abs() / UNIFORM_SPHERE_PDF) as f64;
        }
        ((by_bsdf / n as f64) as f32, (by_sphere / n as f64) as f32)
    }

    #[test]
    fn lambertian_albedo_and_reciprocity() {
        let b = Bsdf::Diffuse { albedo: Vec3::splat(0.6) };
        for wo in [dir(10.0, 0.0), dir(70.0, 30.0), -dir(40.0, 100.0)] {
            let (s, u) = albedo_two_ways(&b, wo, 100_000);
            assert!((s - 0.6).abs() < 1e-5, "importance sampling is exact: {s}");
            assert!((u - 0.6).abs() < 0.01, "{u}");
        }
        assert_eq!(f(&b, dir(10.0, 0.0), -dir(10.0, 0.0)), Vec3::ZERO, "no transmission");
    }

    #[test]
    fn microfacet_sampling_matches_evaluation() {
        // Gold-like conductor; a smooth and a rough lobe, near-normal and grazing views.
        let eta = Vec3::new(0.21646, 0.42833, 1.3284);
        let k = Vec3::new(3.2390, 2.4599, 1.8661);
        for alpha in [0.05f32, 0.25, 0.5] {
            let b = Bsdf::Microfacet { eta, k, alpha };
            for wo in [dir(5.0, 0.0), dir(60.0, 45.0), -dir(30.0, 0.0)] {
                let (s, u) = albedo_two_ways(&b, wo, 400_000);
                assert!(s <= 1.0 && u <= 1.0, "energy: {s} {u}");
                // Uniform sampling of a peaked lobe is noisy: allow for it at small alpha.
                let tol = if alpha < 0.1 { 0.06 } else { 0.02 };
                assert!((s - u).abs() < tol * s.max(0.1), "alpha {alpha} wo {wo}: sampled {s} vs uniform {u}");
                let (a, b2) = (dir(20.0, 10.0), dir(50.0, 200.0));
                assert!((f(&b, a, b2) - f(&b, b2, a)).abs().max_element() < 1e-4, "reciprocity");
            }
        }
    }

    #[test]
    fn fresnel_conductor_limits() {
        // Perfect conductor (k -> inf) reflects everything; normal incidence has the textbook value.
        let f0 = fresnel_conductor(1.0, Vec3::splat(1.5), Vec3::ZERO).x;
        assert!((f0 - 0.04).abs() < 1e-4, "{f0}");
        assert!(fresnel_conductor(0.3, Vec3::ONE, Vec3::splat(1e4)).x > 0.999);
        assert!((fresnel_conductor(0.0, Vec3::splat(1.5), Vec3::splat(2.0)).x - 1.0).abs() < 1e-4);
    }

    #[test]
    fn mirror_reflects() {
        let b = Bsdf::Mirror { reflectance: Vec3::splat(0.9) };
        let wo = dir(30.0, 60.0);
        let s = sample_f(&b, wo, (0.3, 0.3), 0.5).unwrap();
        assert!((s.wi - Vec3::new(-wo.x, -wo.y, wo.z)).length() < 1e-6);
        assert_eq!((s.weight, s.delta), (Vec3::splat(0.9), true));
        assert_eq!(f(&b, wo, s.wi), Vec3::ZERO);
    }

    #[test]
    fn glass_obeys_snell_and_conserves_energy() {
        let ior = 1.5;
        let b = Bsdf::Glass { reflectance: Vec3::ONE, transmittance: Vec3::ONE, ior, roughness: 0.0 };
        for wo in [dir(0.0, 0.0), dir(45.0, 30.0), dir(80.0, 0.0), -dir(20.0, 10.0), -dir(60.0, 0.0)] {
            let mut rng = Rng::new(2, 2);
            let (mut reflected, mut sum) = (0usize, 0.0f64);
            let n = 20_000;
            for _ in 0..n {
                let s = sample_f(&b, wo, rng.next_2d(), rng.next_f32()).unwrap();
                // Undoing the radiance scaling, every sample carries exactly the energy it should.
                sum += (s.weight.x * s.eta_scale) as f64;
                if s.wi.z * wo.z > 0.0 {
                    reflected += 1;
                } else {
                    // Snell: η_i sin θi = η_t sin θt.
                    let (ni, nt) = if wo.z > 0.0 { (1.0, ior) } else { (ior, 1.0) };
                    let sin = |w: Vec3| (1.0 - w.z * w.z).max(0.0).sqrt();
                    assert!((ni * sin(wo) - nt * sin(s.wi)).abs() < 1e-4);
                    // Reversibility: refracting back gives wo.
                    let (back, _) = refract(s.wi, ior).unwrap();
                    assert!((back - wo).length() < 1e-4);
                }
            }
            assert!((sum / n as f64 - 1.0).abs() < 1e-5);
            let frac = reflected as f32 / n as f32;
            let cos_outside = if wo.z > 0.0 { wo.z } else { refract(wo, ior).map(|r| r.1).unwrap_or(0.0) };
            let expect = if refract(wo, ior).is_none() { 1.0 } else { schlick(cos_outside, ior) };
            assert!((frac - expect).abs() < 0.015, "wo {wo}: reflected {frac}, Schlick {expect}");
        }
        // Beyond the critical angle (41.8° for 1.5) inside: total internal reflection.
        let s = sample_f(&b, -dir(60.0, 0.0), (0.5, 0.5), 0.99).unwrap();
        assert!(s.wi.z < 0.0 && s.weight == Vec3::ONE);
        assert!((schlick(1.0, ior) - 0.04).abs() < 1e-6);
    }
}
