//! Math vocabulary: `glam` re-exports and the axis-aligned bounding box.
//!
//! Conventions used crate-wide: right-handed coordinates, distances in scene units,
//! angles in degrees at API boundaries (as COLLADA and CS184 use them) and radians inside.

pub use glam::{Mat3, Mat4, Vec2, Vec3, Vec3A, Vec4};

use crate::simd::{F32x1, Lanes, Vec3x};

/// An axis-aligned bounding box. [`Aabb::EMPTY`] has `min = +inf`, `max = -inf`, so it
/// is the identity of [`Aabb::union`] and no ray's slab test can ever hit it.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3,
    /// Upper corner.
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The empty box (`+inf` / `-inf`): the identity of union, never hit.
    pub const EMPTY: Aabb = Aabb { min: Vec3::splat(f32::INFINITY), max: Vec3::splat(f32::NEG_INFINITY) };

    /// A box from two corners (min/max taken per axis).
    #[inline]
    pub fn new(a: Vec3, b: Vec3) -> Self {
        Self { min: a.min(b), max: a.max(b) }
    }

    /// The degenerate box holding one point.
    #[inline]
    pub fn from_point(p: Vec3) -> Self {
        Self { min: p, max: p }
    }

    /// The smallest box holding the three corners of a triangle.
    #[inline]
    pub fn of_triangle([a, b, c]: [Vec3; 3]) -> Self {
        Self { min: a.min(b).min(c), max: a.max(b).max(c) }
    }

    /// True when `min <= max` on every axis.
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.min.cmple(self.max).all()
    }

    /// Grows the box to hold `p`.
    #[inline]
    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// The smallest box holding both.
    #[inline]
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb { min: self.min.min(o.min), max: self.max.max(o.max) }
    }

    /// `max - min` (negative for the empty box).
    #[inline]
    pub fn extent(&self) -> Vec3 {
        self.max - self.min
    }

    /// The centre point.
    #[inline]
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Half the surface area (the SAH only needs ratios); 0 for empty or flat boxes.
    #[inline]
    pub fn half_area(&self) -> f32 {
        let e = self.extent().max(Vec3::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }

    /// The axis (0 = x, 1 = y, 2 = z) of largest extent.
    #[inline]
    pub fn largest_axis(&self) -> usize {
        let e = self.extent();
        if e.x >= e.y && e.x >= e.z {
            0
        } else if e.y >= e.z {
            1
        } else {
            2
        }
    }

    /// True when `p` lies inside or on the box.
    #[inline]
    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// True when `o` lies inside or on the box.
    #[inline]
    pub fn contains_box(&self, o: &Aabb) -> bool {
        o.min.cmpge(self.min).all() && o.max.cmple(self.max).all()
    }
}

/// True when every component is finite (not NaN, not ±inf).
#[inline]
pub fn is_finite3(v: Vec3) -> bool {
    v.is_finite()
}

/// `1/x` that maps `±0` to a huge value of the same sign instead of `±inf`, so that slab
/// tests never compute `0 * inf = NaN` for rays parallel to a slab.
#[inline]
pub fn safe_recip(x: f32) -> f32 {
    if x.abs() < SAFE_RECIP_TINY { (1.0 / SAFE_RECIP_TINY).copysign(x) } else { 1.0 / x }
}

/// The magnitude below which [`safe_recip`] clamps (its lane version in the kernels,
/// `bvh::traverse1::safe_recip_lanes`, and `Ray::MIN_DIRECTION` share it).
pub(crate) const SAFE_RECIP_TINY: f32 = 1e-18;

/// [`safe_recip`] per component.
#[inline]
pub fn safe_recip3(v: Vec3) -> Vec3 {
    Vec3::new(safe_recip(v.x), safe_recip(v.y), safe_recip(v.z))
}

/// An orthonormal basis `(t, b)` completing the unit vector `n` (Duff et al. 2017):
/// [`orthonormal_basis_lanes`] on one lane.
#[inline]
pub fn orthonormal_basis(n: Vec3) -> (Vec3, Vec3) {
    let (t, b) = orthonormal_basis_lanes::<F32x1>(n.into());
    (t.into(), b.into())
}

/// [`orthonormal_basis`] of every lane of `n`.
#[inline(always)]
pub fn orthonormal_basis_lanes<V: Lanes>(n: Vec3x<V>) -> (Vec3x<V>, Vec3x<V>) {
    let sign = V::splat(1.0).copysign(n.z);
    let a = V::splat(-1.0) / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3x { x: V::splat(1.0) + sign * n.x * n.x * a, y: sign * b, z: -sign * n.x },
        Vec3x { x: b, y: sign + n.y * n.y * a, z: -n.y },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_box_is_union_identity() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        assert_eq!(Aabb::EMPTY.union(&b), b);
        assert!(!Aabb::EMPTY.is_valid());
        assert_eq!(Aabb::EMPTY.half_area(), 0.0);
        assert_eq!(b.half_area(), 3.0);
    }

    #[test]
    fn safe_recip_keeps_sign_of_zero() {
        assert!(safe_recip(0.0) > 1e17);
        assert!(safe_recip(-0.0) < -1e17);
        assert_eq!(safe_recip(2.0), 0.5);
    }

    #[test]
    fn basis_is_orthonormal() {
        for n in [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::Z, Vec3::new(1.0, 2.0, -3.0).normalize()] {
            let (t, b) = orthonormal_basis(n);
            assert!((t.length() - 1.0).abs() < 1e-5 && (b.length() - 1.0).abs() < 1e-5);
            assert!(t.dot(n).abs() < 1e-5 && b.dot(n).abs() < 1e-5 && t.dot(b).abs() < 1e-5);
        }
    }
}
