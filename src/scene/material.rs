//! Materials as the CS184 / CMU462 scenes describe them. Plain data: the renderer's BSDF
//! code interprets them.

use crate::math::Vec3;

/// Index of a material in [`crate::Scene::materials`].
pub type MaterialId = u32;

/// The scattering model of a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bsdf {
    /// Lambertian reflection with the given albedo (each channel in `[0, 1]`).
    Diffuse {
        /// Reflectance.
        albedo: Vec3,
    },
    /// Perfect specular reflection.
    Mirror {
        /// Reflectance.
        reflectance: Vec3,
    },
    /// Dielectric interface with Fresnel reflection and refraction.
    Glass {
        /// Tint of reflected light.
        reflectance: Vec3,
        /// Tint of transmitted light.
        transmittance: Vec3,
        /// Index of refraction of the inside (outside is 1).
        ior: f32,
        /// Surface roughness (0 = smooth; stored, shaded as smooth).
        roughness: f32,
    },
    /// Microfacet conductor (CS184 part 5): Beckmann roughness `alpha`, complex index `eta + i k`.
    Microfacet {
        /// Real part of the index of refraction, per channel.
        eta: Vec3,
        /// Imaginary part (absorption), per channel.
        k: Vec3,
        /// Beckmann roughness.
        alpha: f32,
    },
}

/// A surface material: a BSDF plus emitted radiance.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name from the scene file (for messages).
    pub name: String,
    /// How the surface scatters light.
    pub bsdf: Bsdf,
    /// Emitted radiance (W / (m² sr)), zero for non-emitters.
    pub emission: Vec3,
}

impl Material {
    /// A Lambertian material.
    pub fn diffuse(albedo: Vec3) -> Self {
        Self { name: String::new(), bsdf: Bsdf::Diffuse { albedo }, emission: Vec3::ZERO }
    }

    /// A black emitter of radiance `radiance` (CS184's emission BSDF).
    pub fn emissive(radiance: Vec3) -> Self {
        Self { name: String::new(), bsdf: Bsdf::Diffuse { albedo: Vec3::ZERO }, emission: radiance }
    }

    /// A perfect mirror.
    pub fn mirror(reflectance: Vec3) -> Self {
        Self { name: String::new(), bsdf: Bsdf::Mirror { reflectance }, emission: Vec3::ZERO }
    }

    /// Smooth glass.
    pub fn glass(ior: f32) -> Self {
        Self {
            name: String::new(),
            bsdf: Bsdf::Glass { reflectance: Vec3::ONE, transmittance: Vec3::ONE, ior, roughness: 0.0 },
            emission: Vec3::ZERO,
        }
    }

    /// Sets the name.
    pub fn named(mut self, name: impl Into<String>) -> Self {
        self.name = name.into();
        self
    }

    /// True when the surface emits light.
    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }
}

impl Default for Material {
    /// CS184's default: diffuse grey 0.5.
    fn default() -> Self {
        Self::diffuse(Vec3::splat(0.5)).named("default")
    }
}

/// Checks a colour that scales reflected or transmitted light: finite and in `[0, 1]` per
/// channel (more would create energy; a reflectance of 1e30 makes every path's throughput
/// overflow to a black or NaN image).
pub fn check_reflectance(what: &str, c: Vec3) -> Result<(), String> {
    if !(c.is_finite() && c.min_element() >= 0.0 && c.max_element() <= 1.0) {
        return Err(format!("{what} {} {} {} must be finite and in [0, 1]", c.x, c.y, c.z));
    }
    Ok(())
}

/// Checks an emitted radiance or intensity: finite and non-negative per channel (negative
/// light is silently black in the estimators).
pub fn check_radiance(what: &str, c: Vec3) -> Result<(), String> {
    if !(c.is_finite() && c.min_element() >= 0.0) {
        return Err(format!("{what} {} {} {} must be finite and non-negative", c.x, c.y, c.z));
    }
    Ok(())
}

/// Largest Beckmann roughness accepted: the RMS slope of the microfacets is then 45°; far
/// beyond it the lobe is flat and [`crate::render::bsdf`] returns next to nothing.
pub const MAX_MICROFACET_ALPHA: f32 = 1.0;

impl Bsdf {
    /// Why these parameters describe no physical surface, if they do not: reflectances in
    /// `[0, 1]`, a positive finite index of refraction, a Beckmann `alpha` in
    /// `(0, MAX_MICROFACET_ALPHA]`, a positive `eta` and a non-negative `k`.
    pub fn check(&self) -> Result<(), String> {
        match *self {
            Bsdf::Diffuse { albedo } => check_reflectance("albedo", albedo),
            Bsdf::Mirror { reflectance } => check_reflectance("reflectance", reflectance),
            Bsdf::Glass { reflectance, transmittance, ior, roughness } => {
                check_reflectance("reflectance", reflectance)?;
                check_reflectance("transmittance", transmittance)?;
                if !(ior.is_finite() && ior > 0.0) {
                    return Err(format!("index of refraction {ior} must be positive"));
                }
                if !(roughness.is_finite() && roughness >= 0.0) {
                    return Err(format!("roughness {roughness} must be finite and non-negative"));
                }
                Ok(())
            }
            Bsdf::Microfacet { eta, k, alpha } => {
                if !(alpha > 0.0 && alpha <= MAX_MICROFACET_ALPHA) {
                    return Err(format!("alpha {alpha} must be in (0, {MAX_MICROFACET_ALPHA}]"));
                }
                if !(eta.is_finite() && eta.min_element() > 0.0) {
                    return Err(format!("eta {} {} {} must be finite and positive", eta.x, eta.y, eta.z));
                }
                if !(k.is_finite() && k.min_element() >= 0.0) {
                    return Err(format!("k {} {} {} must be finite and non-negative", k.x, k.y, k.z));
                }
                Ok(())
            }
        }
    }
}

impl Material {
    /// Why the material is physically meaningless, if it is ([`Bsdf::check`], and a finite
    /// non-negative emission).
    pub fn check(&self) -> Result<(), String> {
        self.bsdf.check()?;
        check_radiance("emission", self.emission)
    }
}
