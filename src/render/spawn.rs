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
use crate::simd::{F32x1, Lanes, Vec3x};

/// Coordinates smaller than this in magnitude move by an absolute step.
pub(crate) const ORIGIN: f32 = 1.0 / 32.0;
/// The absolute step along the normal, near the origin.
pub(crate) const FLOAT_SCALE: f32 = 1.0 / 65536.0;
/// Units in the last place stepped along the normal, away from the origin.
pub(crate) const INT_SCALE: f32 = 256.0;

/// `p` moved off its surface along the unit normal `n` (toward the side `n` points to):
/// [`offset_origin_lanes`] on one lane.
#[inline]
pub fn offset_origin(p: Vec3, n: Vec3) -> Vec3 {
    offset_origin_lanes::<F32x1>(p.into(), n.into()).into()
}

/// [`offset_origin`] of every lane.
#[inline(always)]
pub fn offset_origin_lanes<V: Lanes>(p: Vec3x<V>, n: Vec3x<V>) -> Vec3x<V> {
    #[inline(always)]
    fn one<V: Lanes>(p: V, n: V) -> V {
        let near = p.abs().lt(V::splat(ORIGIN));
        // Step `INT_SCALE * n` units in the last place, away from or toward zero as `n` says.
        // `-k` where `p` is negative: the sign bit flipped.
        let k = V::splat(INT_SCALE) * n;
        let stepped = p.add_ulps(k ^ (p.lt(V::splat(0.0)) & V::splat(-0.0)));
        near.select(p + V::splat(FLOAT_SCALE) * n, stepped)
    }
    Vec3x { x: one(p.x, n.x), y: one(p.y, n.y), z: one(p.z, n.z) }
}

/// The geometric normal `ng` turned to the side of direction `dir`: [`toward_lanes`] on one
/// lane.
#[inline]
pub fn toward(ng: Vec3, dir: Vec3) -> Vec3 {
    toward_lanes::<F32x1>(ng.into(), dir.into()).into()
}

/// [`toward`] of every lane.
#[inline(always)]
pub fn toward_lanes<V: Lanes>(ng: Vec3x<V>, dir: Vec3x<V>) -> Vec3x<V> {
    // `-ng` where the dot product is negative: the sign bits flipped.
    let flip = ng.dot(dir).lt(V::splat(0.0)) & V::splat(-0.0);
    Vec3x { x: ng.x ^ flip, y: ng.y ^ flip, z: ng.z ^ flip }
}

/// A ray leaving the surface point `p` (geometric normal `ng`) in unit direction `dir`.
#[inline]
pub fn spawn_ray(p: Vec3, ng: Vec3, dir: Vec3) -> Ray {
    Ray::new(offset_origin(p, toward(ng, dir)), dir)
}

/// A shadow ray from surface point `p` (geometric normal `ng`) to the point `target`, ending
/// just short of it so that the surface `target` lies on does not occlude it. `None` when
/// `target` is closer than the offset can resolve (the points touch: nothing can lie between).
/// [`spawn_ray_to_lanes`] on one lane.
#[inline]
pub fn spawn_ray_to(p: Vec3, ng: Vec3, target: Vec3) -> Option<Ray> {
    let r = spawn_ray_to_lanes::<F32x1>(p.into(), ng.into(), target.into());
    (r.ok.bitmask() != 0).then(|| Ray::segment(r.origin.into(), r.dir.into(), 0.0, r.tfar.0))
}

/// Shadow rays of [`spawn_ray_to_lanes`], a lane each.
#[derive(Clone, Copy, Debug)]
pub struct SegmentLanes<V> {
    /// Origin.
    pub origin: Vec3x<V>,
    /// Unit direction.
    pub dir: Vec3x<V>,
    /// End (the start is 0).
    pub tfar: V,
    /// True in the lanes that have a ray ([`spawn_ray_to`] is not `None`).
    pub ok: V,
}

/// [`spawn_ray_to`] of every lane.
#[inline(always)]
pub fn spawn_ray_to_lanes<V: Lanes>(p: Vec3x<V>, ng: Vec3x<V>, target: Vec3x<V>) -> SegmentLanes<V> {
    let origin = offset_origin_lanes(p, toward_lanes(ng, target - p));
    let d = target - origin;
    let dist = d.dot(d).sqrt();
    // Shorten by a relative 1e-4 (pbrt's ShadowEpsilon) and by 64 units in the last place of
    // the target's largest coordinate (its own rounding error is a few).
    let largest = target.x.abs().vmax(target.y.abs().vmax(target.z.abs()));
    let margin = (dist * V::splat(1e-4)).vmax(largest * V::splat(64.0 / 8_388_608.0));
    SegmentLanes { origin, dir: d / dist, tfar: dist - margin, ok: dist.gt(V::splat(2.0) * margin) }
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
