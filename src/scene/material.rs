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
