//! Spawning secondary rays from surfaces without self-intersection ("acne").
//!
//! The origin is pushed off the surface along the geometric normal by a distance that scales
//! with the magnitude of the hit point: a fixed number of units in the last place of each
//! coordinate, or a tiny absolute step near the origin. This is Wächter and Binder, "A Fast
//! and Robust Method for Avoiding Self-Intersection" (Ray Tracing Gems, ch. 6, 2019). It
//! assumes the hit point was computed from the primitive (barycentric interpolation, sphere
//! reprojection), not as `o + t d`, which [`crate::Scene::surface`] guarantees.

use crate::math::Vec3;
use crate::ray::Ray;

/// Coordinates smaller than this in magnitude move by an absolute step.
pub(crate) const ORIGIN: f32 = 1.0 / 32.0;
/// The absolute step along the normal, near the origin.
pub(crate) const FLOAT_SCALE: f32 = 1.0 / 65536.0;
/// Units in the last place stepped along the normal, away from the origin.
pub(crate) const INT_SCALE: f32 = 256.0;

/// `p` moved off its surface along the unit normal `n` (toward the side `n` points to).
#[inline]
pub fn offset_origin(p: Vec3, n: Vec3) -> Vec3 {
    #[inline]
    fn one(p: f32, n: f32) -> f32 {
        if p.abs() < ORIGIN {
            return p + FLOAT_SCALE * n;
        }
        // Step `INT_SCALE * n` units in the last place, away from or toward zero as `n` says.
        let of_i = (INT_SCALE * n) as i32;
        let step = if p < 0.0 { -of_i } else { of_i };
        f32::from_bits((p.to_bits() as i32).wrapping_add(step) as u32)
    }
    Vec3::new(one(p.x, n.x), one(p.y, n.y), one(p.z, n.z))
}

/// The geometric normal `ng` turned to the side of direction `dir`.
#[inline]
pub fn toward(ng: Vec3, dir: Vec3) -> Vec3 {
    if ng.dot(dir) < 0.0 { -ng } else { ng }
}

/// A ray leaving the surface point `p` (geometric normal `ng`) in unit direction `dir`.
#[inline]
pub fn spawn_ray(p: Vec3, ng: Vec3, dir: Vec3) -> Ray {
    Ray::new(offset_origin(p, toward(ng, dir)), dir)
}

/// A shadow ray from surface point `p` (geometric normal `ng`) to the point `target`, ending
/// just short of it so that the surface `target` lies on does not occlude it. `None` when
/// `target` is closer than the offset can resolve (the points touch: nothing can lie between).
#[inline]
pub fn spawn_ray_to(p: Vec3, ng: Vec3, target: Vec3) -> Option<Ray> {
    let origin = offset_origin(p, toward(ng, target - p));
    let d = target - origin;
    let dist = d.length();
    // Shorten by a relative 1e-4 (pbrt's ShadowEpsilon) and by 64 units in the last place of
    // the target's largest coordinate (its own rounding error is a few).
    let margin = (dist * 1e-4).max(target.abs().max_element() * (64.0 / 8_388_608.0));
    if !(dist > 2.0 * margin) {
        return None;
    }
    Some(Ray::segment(origin, d / dist, 0.0, dist - margin))
}

/// A shadow ray from `p` in unit direction `dir` to infinity (directional and environment
/// lights).
#[inline]
pub fn spawn_ray_infinite(p: Vec3, ng: Vec3, dir: Vec3) -> Ray {
    spawn_ray(p, ng, dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offset_moves_to_the_normal_side_at_any_magnitude() {
        let n = Vec3::new(0.0, 0.0, 1.0);
        for z in [0.0f32, 1e-3, -1e-3, 0.5, -0.5, 1.0e4, -1.0e4, 3.0e7] {
            let p = Vec3::new(1.0, -2.0, z);
            let q = offset_origin(p, n);
            assert!(q.z > p.z, "z = {z}: {} !> {}", q.z, p.z);
            assert!(offset_origin(p, -n).z < p.z);
            assert_eq!((q.x, q.y), (p.x, p.y));
            // The step is small relative to the magnitude.
            assert!((q.z - p.z).abs() <= p.abs().max_element().max(1.0) * 1e-4);
        }
    }

    #[test]
    fn shadow_ray_stops_short_of_target() {
        let p = Vec3::new(1.0e3, 0.0, 0.0);
        let target = Vec3::new(1.0e3, 0.0, 2.0);
        let r = spawn_ray_to(p, Vec3::Z, target).unwrap();
        // 64 ulps of 1000 is 0.0076.
        assert!(r.origin.z > 0.0 && r.tfar < 2.0 && r.tfar > 1.99, "{r:?}");
        assert!(spawn_ray_to(p, Vec3::Z, p).is_none());
    }
}
