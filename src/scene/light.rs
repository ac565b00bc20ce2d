//! Light sources (plain data; sampling lives in the renderer).
//!
//! Units: `intensity` is radiant intensity (W/sr) for point and spot lights, `radiance` is
//! W/(m² sr) for area, directional and environment lights, as in CS184.

use crate::math::Vec3;

/// A light source.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Isotropic point light.
    Point {
        /// Position.
        position: Vec3,
        /// Radiant intensity.
        intensity: Vec3,
    },
    /// Light from infinitely far away.
    Directional {
        /// Unit direction the light travels in (from the light toward the scene).
        direction: Vec3,
        /// Radiance arriving along `-direction`.
        radiance: Vec3,
    },
    /// Point light restricted to a cone.
    Spot {
        /// Position.
        position: Vec3,
        /// Unit axis of the cone (direction the light travels).
        direction: Vec3,
        /// Radiant intensity on the axis.
        intensity: Vec3,
        /// Cone half-angle where the falloff starts, degrees.
        inner_angle_deg: f32,
        /// Cone half-angle beyond which no light leaves, degrees.
        outer_angle_deg: f32,
    },
    /// One-sided emitting parallelogram (CS184's `AreaLight`): centre `position`, spanning
    /// `position ± dim_x/2 ± dim_y/2`, emitting into the half-space of `direction`.
    Area {
        /// Emitted radiance.
        radiance: Vec3,
        /// Centre.
        position: Vec3,
        /// Unit normal of the emitting side.
        direction: Vec3,
        /// Full edge along the first axis.
        dim_x: Vec3,
        /// Full edge along the second axis.
        dim_y: Vec3,
    },
    /// Constant radiance from every direction (CS184's `InfiniteHemisphereLight`, here the
    /// whole sphere), also what COLLADA ambient lights become.
    Environment {
        /// Radiance from every direction.
        radiance: Vec3,
    },
}

impl Light {
    /// True for lights a hemisphere sampler can never hit (points and directions).
    pub fn is_delta(&self) -> bool {
        matches!(self, Light::Point { .. } | Light::Directional { .. } | Light::Spot { .. })
    }
}

impl Light {
    /// Why the light is meaningless, if it is: its intensity or radiance must be finite and
    /// non-negative ([`crate::scene::material::check_radiance`]).
    pub fn check(&self) -> Result<(), String> {
        use crate::scene::material::check_radiance;
        match *self {
            Light::Point { intensity, .. } | Light::Spot { intensity, .. } => check_radiance("intensity", intensity),
            Light::Directional { radiance, .. } | Light::Area { radiance, .. } | Light::Environment { radiance } => {
                check_radiance("radiance", radiance)
            }
        }
    }
}
