//! Scalar ray/sphere intersection, with the precision-preserving discriminant of Haines et
//! al., "Precision Improvements for Ray/Sphere Intersection" (Ray Tracing Gems, 2019).

use crate::math::Vec3;

/// Intersects the ray with the sphere `|p - center| = radius`.
///
/// Returns the nearest root `t` in `[tnear, tfar]` (the far root when the origin is inside),
/// or `None`. A root at the origin is `t = +0.0`, never `-0.0`.
#[inline]
pub fn intersect_sphere(origin: Vec3, dir: Vec3, tnear: f32, tfar: f32, center: Vec3, radius: f32) -> Option<f32> {
    let f = origin - center;
    let a = dir.dot(dir);
    let half_b = f.dot(dir);
    // Squared distance from the centre to the line, computed without cancellation.
    let l = f - dir * (half_b / a);
    let r2 = radius * radius;
    let disc = r2 - l.dot(l);
    if !(disc >= 0.0) {
        return None;
    }
    let sq = (a * disc).sqrt();
    let c = f.dot(f) - r2;
    let q = -(half_b + sq.copysign(half_b));
    let (mut t0, mut t1) = (c / q, q / a);
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    // `+ 0.0`: a root at the origin (`c = 0`) may come out as `-0.0`; made `+0.0`.
    let (t0, t1) = (t0 + 0.0, t1 + 0.0);
    // `t < inf`: `sqrt(a disc)` overflows when `|dir| radius` exceeds ~1.8e19, and the root
    // at infinity is no hit.
    if t0 >= tnear && t0 <= tfar && t0 < f32::INFINITY {
        Some(t0)
    } else if t1 >= tnear && t1 <= tfar && t1 < f32::INFINITY {
        Some(t1)
    } else {
        None
    }
}

/// Spherical surface coordinates `(u, v)` in `[0, 1]` of the unit direction `n` from the
/// centre: `u` is the azimuth around +z, `v` the polar angle from +z.
#[inline]
pub fn sphere_uv(n: Vec3) -> (f32, f32) {
    let u = (n.y.atan2(n.x) / std::f32::consts::TAU).rem_euclid(1.0);
    let v = n.z.clamp(-1.0, 1.0).acos() / std::f32::consts::PI;
    (u, v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_and_far_roots() {
        let c = Vec3::new(0.0, 0.0, 5.0);
        assert_eq!(intersect_sphere(Vec3::ZERO, Vec3::Z, 0.0, 100.0, c, 1.0), Some(4.0));
        // From inside only the far root counts.
        assert_eq!(intersect_sphere(c, Vec3::Z, 0.0, 100.0, c, 1.0), Some(1.0));
        assert_eq!(intersect_sphere(Vec3::ZERO, Vec3::Z, 4.5, 100.0, c, 1.0), Some(6.0));
        assert_eq!(intersect_sphere(Vec3::ZERO, Vec3::Z, 0.0, 3.9, c, 1.0), None);
        assert_eq!(intersect_sphere(Vec3::ZERO, Vec3::X, 0.0, 100.0, c, 1.0), None);
        // Roots at exactly tnear count.
        assert_eq!(intersect_sphere(Vec3::ZERO, Vec3::Z, 4.0, 100.0, c, 1.0), Some(4.0));
        assert_eq!(intersect_sphere(Vec3::ZERO, Vec3::Z, 4.0f32.next_up(), 100.0, c, 1.0), Some(6.0));
    }

    #[test]
    fn a_ray_starting_on_the_sphere_hits_it_at_t_zero() {
        // From the north pole: outward the root at the origin (t = +0.0, never -0.0); inward
        // the same root first, the far side beyond it with tnear > 0.
        let (c, north) = (Vec3::new(0.0, 0.0, 5.0), Vec3::new(0.0, 0.0, 6.0));
        for d in [Vec3::Z, -Vec3::Z, Vec3::new(1.0, 0.0, 0.5)] {
            let t = intersect_sphere(north, d, 0.0, 100.0, c, 1.0).map(f32::to_bits);
            assert_eq!(t, Some(0.0f32.to_bits()), "{d}");
        }
        assert_eq!(intersect_sphere(north, -Vec3::Z, 1e-6, 100.0, c, 1.0), Some(2.0));
        assert_eq!(intersect_sphere(north, Vec3::Z, 1e-6, 100.0, c, 1.0), None);
    }

    #[test]
    fn far_away_sphere_keeps_precision() {
        let c = Vec3::new(0.0, 0.0, 1.0e4);
        let t = intersect_sphere(Vec3::ZERO, Vec3::Z * 2.0, 0.0, f32::INFINITY, c, 0.01).unwrap();
        assert!((t * 2.0 - (1.0e4 - 0.01)).abs() < 1e-3, "t = {t}");
    }
}
