//! Scalar ray/triangle intersection: Möller & Trumbore, "Fast, Minimum Storage Ray/Triangle
//! Intersection", JGT 1997. No back-face culling and no epsilon: a triangle is missed only
//! when the ray is parallel to its plane (`det == 0`) or outside its edges.

use crate::math::Vec3;

/// Intersects the ray `origin + t dir` with triangle `(v0, v1, v2)`.
///
/// Returns `(t, u, v)` with `p = (1-u-v) v0 + u v1 + v v2` when `t` lies in `[tnear, tfar]`
/// and `u, v >= 0`, `u + v <= 1`; `None` otherwise (and for degenerate triangles). A hit at
/// the origin is `t = +0.0`, never `-0.0` ([`crate::ray`]).
#[inline]
pub fn intersect_triangle(
    origin: Vec3,
    dir: Vec3,
    tnear: f32,
    tfar: f32,
    v0: Vec3,
    v1: Vec3,
    v2: Vec3,
) -> Option<(f32, f32, f32)> {
    intersect_triangle_edges(origin, dir, tnear, tfar, v0, v1 - v0, v2 - v0)
}

/// [`intersect_triangle`] for the triangle given as `v0` and its edges `e1 = v1 - v0`,
/// `e2 = v2 - v0` (the form SIMD leaf blocks store). Bit-identical to it.
#[inline]
pub fn intersect_triangle_edges(
    origin: Vec3,
    dir: Vec3,
    tnear: f32,
    tfar: f32,
    v0: Vec3,
    e1: Vec3,
    e2: Vec3,
) -> Option<(f32, f32, f32)> {
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv_det = 1.0 / det;
    let s = origin - v0;
    let u = s.dot(p) * inv_det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = dir.dot(q) * inv_det;
    // `!(v >= 0)` rather than `v < 0`: a NaN `v` (from an overflowing `dir · q`) is no hit.
    if !(v >= 0.0) || u + v > 1.0 {
        return None;
    }
    let mut t = e2.dot(q) * inv_det;
    if !t.is_finite() {
        t = t_f64(e2, q, inv_det);
    }
    // `+ 0.0` turns a `-0.0` (a hit exactly at the origin) into `+0.0` and leaves every other
    // value as it is.
    let t = t + 0.0;
    if t >= tnear && t <= tfar && t < f32::INFINITY { Some((t, u, v)) } else { None }
}

/// `e2 · q * inv_det` in double precision, rounded to `f32`: the fallback when the `f32` dot
/// product overflows (it grows with the cube of the distance between origin and triangle,
/// past `f32::MAX` beyond about 7e12 for a unit direction). The SIMD kernel uses the same.
#[inline]
pub fn t_f64(e2: Vec3, q: Vec3, inv_det: f32) -> f32 {
    (e2.as_dvec3().dot(q.as_dvec3()) * inv_det as f64) as f32
}

/// The unnormalised geometric normal `(v1 - v0) x (v2 - v0)`; its length is twice the area.
#[inline]
pub fn triangle_normal(v0: Vec3, v1: Vec3, v2: Vec3) -> Vec3 {
    (v1 - v0).cross(v2 - v0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const V0: Vec3 = Vec3::new(0.0, 0.0, 0.0);
    const V1: Vec3 = Vec3::new(1.0, 0.0, 0.0);
    const V2: Vec3 = Vec3::new(0.0, 1.0, 0.0);

    #[test]
    fn hits_from_both_sides_with_barycentrics() {
        let (t, u, v) = intersect_triangle(Vec3::new(0.25, 0.5, 1.0), -Vec3::Z, 0.0, 10.0, V0, V1, V2).unwrap();
        assert_eq!((t, u, v), (1.0, 0.25, 0.5));
        let (t, ..) = intersect_triangle(Vec3::new(0.25, 0.5, -2.0), Vec3::Z, 0.0, 10.0, V0, V1, V2).unwrap();
        assert_eq!(t, 2.0);
    }

    #[test]
    fn respects_interval_and_edges() {
        let o = Vec3::new(0.25, 0.25, 1.0);
        assert!(intersect_triangle(o, -Vec3::Z, 1.0, 10.0, V0, V1, V2).is_some(), "t == tnear is included");
        assert!(intersect_triangle(o, -Vec3::Z, 1.0f32.next_up(), 10.0, V0, V1, V2).is_none());
        assert!(intersect_triangle(o, -Vec3::Z, 0.0, 1.0, V0, V1, V2).is_some(), "t == tfar is included");
        assert!(intersect_triangle(o, -Vec3::Z, 0.0, 0.5, V0, V1, V2).is_none());
        assert!(intersect_triangle(Vec3::new(0.6, 0.6, 1.0), -Vec3::Z, 0.0, 9.0, V0, V1, V2).is_none());
        assert!(intersect_triangle(o, Vec3::X, 0.0, 9.0, V0, V1, V2).is_none(), "parallel ray");
        assert!(intersect_triangle(o, -Vec3::Z, 0.0, 9.0, V0, V1, V1).is_none(), "degenerate triangle");
    }

    #[test]
    fn a_ray_starting_on_the_triangle_hits_it_at_t_zero() {
        // From a point of the triangle, leaving it either way: t = +0.0 (tnear = 0 counts), with
        // the barycentrics of that point. Upward, `e2 . q * (1 / det)` is `0 * -1 = -0.0`.
        for d in [-Vec3::Z, Vec3::Z, Vec3::new(0.3, -0.2, 1.0)] {
            let (t, u, v) = intersect_triangle(Vec3::new(0.25, 0.5, 0.0), d, 0.0, 10.0, V0, V1, V2).unwrap();
            assert_eq!((t.to_bits(), u, v), (0.0f32.to_bits(), 0.25, 0.5), "{d}");
            assert!(intersect_triangle(Vec3::new(0.25, 0.5, 0.0), d, 1e-6, 10.0, V0, V1, V2).is_none());
        }
    }
}
