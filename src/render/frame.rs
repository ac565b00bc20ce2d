//! Orthonormal shading frames: world ↔ local coordinates with the normal as local `+z`, the
//! convention of pbrt and CS184's `make_coord_space`, in which BSDFs are written.

use crate::math::{Vec3, orthonormal_basis};

/// An orthonormal basis `(x, y, z)`; `z` is the surface normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// First tangent.
    pub x: Vec3,
    /// Second tangent.
    pub y: Vec3,
    /// Normal.
    pub z: Vec3,
}

impl Frame {
    /// A frame around the unit normal `n` (tangents from Duff et al. 2017).
    #[inline]
    pub fn from_normal(n: Vec3) -> Self {
        let (x, y) = orthonormal_basis(n);
        Self { x, y, z: n }
    }

    /// World direction `v` in local coordinates.
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.x), v.dot(self.y), v.dot(self.z))
    }

    /// Local direction `v` in world coordinates.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.x * v.x + self.y * v.y + self.z * v.z
    }

    /// The same frame seen from the other side (`z` negated, still right-handed).
    #[inline]
    pub fn flipped(&self) -> Self {
        Self { x: self.y, y: self.x, z: -self.z }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_handedness() {
        for n in [Vec3::Z, -Vec3::Z, Vec3::new(0.3, -0.5, 0.8).normalize(), Vec3::X] {
            for f in [Frame::from_normal(n), Frame::from_normal(n).flipped()] {
                assert!((f.x.cross(f.y) - f.z).length() < 1e-5);
                let v = Vec3::new(0.2, 0.7, -0.4);
                assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
            }
        }
        assert_eq!(Frame::from_normal(Vec3::Y).to_local(Vec3::Y), Vec3::Z);
    }
}
