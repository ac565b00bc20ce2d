//! SoA leaf blocks of four spheres and the SIMD form of the scalar sphere test
//! ([`intersect_sphere`]: Haines et al., "Precision Improvements for Ray/Sphere
//! Intersection", Ray Tracing Gems 2019).
//!
//! [`sphere_lanes`] performs the scalar reference's operations in its order (true division
//! and square root, both correctly rounded), so every lane is bit-identical to
//! [`intersect_sphere`], its scalar twin. Padding lanes have a NaN radius: their
//! discriminant is NaN and fails the `>= 0` test, so they never hit.

use crate::geometry::sphere::intersect_sphere;
use crate::math::Vec3;
use crate::simd::{Lanes, Vec3x};

/// Rays against spheres lane by lane (either side may be a broadcast): `(hit mask, t)`.
/// The nearest root in `[tnear, tfar]`, the far one when the near one is outside it; a root
/// at the origin is `+0.0`.
#[inline(always)]
pub fn sphere_lanes<V: Lanes>(
    origin: &Vec3x<V>,
    dir: &Vec3x<V>,
    tnear: V,
    tfar: V,
    center: &Vec3x<V>,
    radius: V,
) -> (V, V) {
    let f = *origin - *center;
    let a = dir.dot(*dir);
    let half_b = f.dot(*dir);
    let s = half_b / a;
    let l = Vec3x { x: f.x - dir.x * s, y: f.y - dir.y * s, z: f.z - dir.z * s };
    let r2 = radius * radius;
    let disc = r2 - l.dot(l);
    let disc_ok = disc.ge(V::splat(0.0));
    let sq = (a * disc).sqrt();
    let c = f.dot(f) - r2;
    let q = -(half_b + sq.copysign(half_b));
    let (t0, t1) = (c / q, q / a);
    let swap = t0.gt(t1);
    let zero = V::splat(0.0);
    let (near, far) = (swap.select(t1, t0) + zero, swap.select(t0, t1) + zero);
    let inf = V::splat(f32::INFINITY);
    let near_ok = near.ge(tnear) & near.le(tfar) & near.lt(inf);
    let far_ok = far.ge(tnear) & far.le(tfar) & far.lt(inf);
    let t = near_ok.select(near, far);
    (disc_ok & (near_ok | far_ok), t)
}

/// Four spheres, structure of arrays: 80 bytes.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Sphere4 {
    /// Centres as rows `[x; 4], [y; 4], [z; 4]`.
    pub center: [[f32; 4]; 3],
    /// Radii; NaN in padding lanes.
    pub radius: [f32; 4],
    /// Scene primitive ids; `u32::MAX` in padding lanes.
    pub prim: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<Sphere4>() == 80);

impl Sphere4 {
    /// Spheres per block.
    pub const M: usize = 4;
    /// A block of padding lanes.
    pub const EMPTY: Sphere4 = Sphere4 { center: [[0.0; 4]; 3], radius: [f32::NAN; 4], prim: [u32::MAX; 4] };

    /// Stores a sphere in `lane`.
    pub fn set(&mut self, lane: usize, center: Vec3, radius: f32, prim: u32) {
        for a in 0..3 {
            self.center[a][lane] = center[a];
        }
        self.radius[lane] = radius;
        self.prim[lane] = prim;
    }

    /// Centres as lanes (`V` must have 4 lanes).
    #[inline(always)]
    pub fn centers<V: Lanes>(&self) -> Vec3x<V> {
        Vec3x { x: V::load(&self.center[0]), y: V::load(&self.center[1]), z: V::load(&self.center[2]) }
    }

    /// Centre of `lane`.
    #[inline(always)]
    pub fn center(&self, lane: usize) -> Vec3 {
        Vec3::new(self.center[0][lane], self.center[1][lane], self.center[2][lane])
    }

    /// One ray against the four spheres, in lanes `V` of 4: `(hit mask bits, t)`.
    #[inline(always)]
    pub fn intersect1<V: Lanes>(&self, origin: Vec3, dir: Vec3, tnear: f32, tfar: f32) -> (u32, V) {
        let (m, t) = sphere_lanes(
            &Vec3x::splat(origin),
            &Vec3x::splat(dir),
            V::splat(tnear),
            V::splat(tfar),
            &self.centers(),
            V::load(&self.radius),
        );
        (m.bitmask(), t)
    }

    /// Scalar twin of [`Sphere4::intersect1`].
    pub fn intersect1_scalar(&self, origin: Vec3, dir: Vec3, tnear: f32, tfar: f32) -> [Option<f32>; 4] {
        std::array::from_fn(|i| intersect_sphere(origin, dir, tnear, tfar, self.center(i), self.radius[i]))
    }
}
