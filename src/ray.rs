//! Rays and hit records.
//!
//! A [`Ray`] is valid for parameters `t` in the open-closed interval `(tnear, tfar]`, the same
//! convention Embree uses: a hit at exactly `tnear` is rejected, one at exactly `tfar` is kept.
//! Directions need not be normalised; `t` is measured in units of `|dir|`.

use crate::math::{Vec3, safe_recip3};

/// A ray `origin + t * dir` for `t` in `(tnear, tfar]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Direction (any length except zero; `t` is in units of its length).
    pub dir: Vec3,
    /// Hits at `t <= tnear` are ignored.
    pub tnear: f32,
    /// Hits at `t > tfar` are ignored; closest-hit queries shrink it to the hit found.
    pub tfar: f32,
}

impl Ray {
    /// A ray over `(0, +inf]`.
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self { origin, dir, tnear: 0.0, tfar: f32::INFINITY }
    }

    /// A ray over `(tnear, tfar]`.
    #[inline]
    pub fn segment(origin: Vec3, dir: Vec3, tnear: f32, tfar: f32) -> Self {
        Self { origin, dir, tnear, tfar }
    }

    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// True for rays a query can answer: finite origin and direction, non-zero direction,
    /// `tnear` not NaN, and a non-empty interval. Invalid rays always miss.
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.origin.is_finite()
            && self.dir.is_finite()
            && self.dir != Vec3::ZERO
            && self.tnear >= 0.0
            && self.tnear <= self.tfar
    }

    /// Per-ray constants for slab tests: the safe reciprocal direction.
    #[inline]
    pub fn inv_dir(&self) -> Vec3 {
        safe_recip3(self.dir)
    }
}

/// The closest (or any) intersection found along a ray.
///
/// `prim` numbers the scene's primitives: triangles first (`0 .. num_triangles`), then
/// spheres. `u`, `v` are the barycentric coordinates of `v1`, `v2` for triangles
/// (`p = (1-u-v) v0 + u v1 + v v2`) and spherical coordinates in `[0,1]` for spheres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit; `+inf` when nothing was hit.
    pub t: f32,
    /// First surface coordinate.
    pub u: f32,
    /// Second surface coordinate.
    pub v: f32,
    /// Primitive id, or [`Hit::NONE`].
    pub prim: u32,
}

impl Default for Hit {
    fn default() -> Self {
        Self::MISS
    }
}

impl Hit {
    /// The primitive id of a miss.
    pub const NONE: u32 = u32::MAX;
    /// A miss.
    pub const MISS: Hit = Hit { t: f32::INFINITY, u: 0.0, v: 0.0, prim: Hit::NONE };

    /// True when something was hit.
    #[inline]
    pub fn is_hit(&self) -> bool {
        self.prim != Hit::NONE
    }
}
