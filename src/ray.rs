//! Rays and hit records.
//!
//! A [`Ray`] covers the parameters `t` in the closed interval `[tnear, tfar]`: a hit at exactly
//! `tnear` counts, and so does one at exactly `tfar`. A ray that starts on a surface with
//! `tnear = 0` hits it at `t = 0`, as trimesh's ray engines and Embree's robust mode (its
//! watertight test, `RTC_SCENE_FLAG_ROBUST`) count it; Embree documents the interval as
//! `[tnear, tfar]` without a guarantee at its ends, and its default test in Embree 3 leaves a
//! hit at exactly `tnear` out. Hit distances are never `-0.0` (a hit at the origin is `+0.0`).
//! Directions need not be normalised; `t` is measured in units of `|dir|`.

use crate::math::{Vec3, safe_recip3};

/// A ray `origin + t * dir` for `t` in `[tnear, tfar]`.
///
/// `repr(C)`: eight consecutive `f32` (origin, direction, `tnear`, `tfar`), so that packet
/// kernels can transpose rays into lanes with vector shuffles ([`transpose_rays`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Direction (any length except zero; `t` is in units of its length).
    pub dir: Vec3,
    /// Hits at `t < tnear` are ignored (`t = tnear` counts).
    pub tnear: f32,
    /// Hits at `t > tfar` are ignored; closest-hit queries shrink it to the hit found.
    pub tfar: f32,
}

impl Ray {
    /// A ray over `[0, +inf]`: from its origin on, a surface there included.
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self { origin, dir, tnear: 0.0, tfar: f32::INFINITY }
    }

    /// A ray over `[tnear, tfar]`.
    #[inline]
    pub fn segment(origin: Vec3, dir: Vec3, tnear: f32, tfar: f32) -> Self {
        Self { origin, dir, tnear, tfar }
    }

    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// True for rays a query can answer: finite origin and direction, a direction with some
    /// component of magnitude at least [`Ray::MIN_DIRECTION`], `tnear >= 0` and
    /// `tnear <= tfar` (neither NaN). Invalid rays always miss.
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.origin.is_finite()
            && self.dir.is_finite()
            && self.dir.abs().max_element() >= Self::MIN_DIRECTION
            && self.tnear >= 0.0
            && self.tnear <= self.tfar
    }

    /// The smallest largest-component of a valid direction: the slab tests' reciprocal
    /// clamp ([`crate::math::safe_recip`]). A direction shorter than this on every axis has
    /// no exact reciprocal on any axis, so box tests would cut its (huge) hit distances short;
    /// such rays count as having no direction, like a zero one.
    pub const MIN_DIRECTION: f32 = crate::math::SAFE_RECIP_TINY;

    /// The eight floats `origin, dir, tnear, tfar`.
    #[inline(always)]
    pub fn to_array(&self) -> [f32; 8] {
        let (o, d) = (self.origin, self.dir);
        [o.x, o.y, o.z, d.x, d.y, d.z, self.tnear, self.tfar]
    }

    /// Per-ray constants for slab tests: the safe reciprocal direction.
    #[inline]
    pub fn inv_dir(&self) -> Vec3 {
        safe_recip3(self.dir)
    }
}

const _: () = assert!(std::mem::size_of::<Ray>() == 32 && std::mem::align_of::<Ray>() == 4);

/// The rows `origin.x, origin.y, origin.z, dir.x, dir.y, dir.z, tnear, tfar` of up to 16
/// rays (lanes past `rays.len()` repeat the first ray), by 8 x 8 transposes (one for 8 rays).
#[inline]
pub fn transpose_rays(rays: &[Ray]) -> [[f32; 16]; 8] {
    transpose_rays_in::<crate::simd::F32x8>(rays)
}

/// [`transpose_rays`] in the 8 lanes `V` of some ISA (the packet kernels use their own).
#[inline(always)]
pub fn transpose_rays_in<V: crate::simd::Transpose8>(rays: &[Ray]) -> [[f32; 16]; 8] {
    let n = rays.len().min(16);
    if n == 16 {
        return transpose16::<V>(rays[..16].try_into().expect("16 rays"));
    }
    if n == 8 {
        // An 8-ray packet: one transpose, the other half the first ray broadcast.
        let rays: &[Ray; 8] = rays[..8].try_into().expect("8 rays");
        let lo = V::transpose8(std::array::from_fn(|i| V::load(&rays[i].to_array())));
        let a = rays[0].to_array();
        let mut rows = [[0.0f32; 16]; 8];
        for (k, (out, l)) in rows.iter_mut().zip(lo).enumerate() {
            l.store(&mut out[..8]);
            V::splat(a[k]).store(&mut out[8..]);
        }
        return rows;
    }
    let mut full = [rays.first().copied().unwrap_or(Ray::new(Vec3::ZERO, Vec3::X)); 16];
    full[..n].copy_from_slice(&rays[..n]);
    transpose16::<V>(&full)
}

#[inline(always)]
fn transpose16<V: crate::simd::Transpose8>(rays: &[Ray; 16]) -> [[f32; 16]; 8] {
    let mut lo = [V::splat(0.0); 8];
    let mut hi = [V::splat(0.0); 8];
    for i in 0..8 {
        lo[i] = V::load(&rays[i].to_array());
        hi[i] = V::load(&rays[i + 8].to_array());
    }
    let (lo, hi) = (V::transpose8(lo), V::transpose8(hi));
    let mut rows = [[0.0f32; 16]; 8];
    for ((out, a), b) in rows.iter_mut().zip(lo).zip(hi) {
        a.store(&mut out[..8]);
        b.store(&mut out[8..]);
    }
    rows
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

/// A packet of K rays and their hits in SoA rows ([`RayPacket8`], [`RayPacket16`]), as the
/// packet queries read and write it.
pub trait RayPacket {
    /// Rays per packet.
    const K: usize;
    /// K lanes of the ISA `I`.
    type Lanes<I: crate::simd::IsaLanes>: crate::simd::Lanes;
    /// The rows `org_x, org_y, org_z`, `dir_x, dir_y, dir_z`, `tnear`, `tfar`.
    #[allow(clippy::type_complexity)] // the four rows, named in the line above
    fn ray_rows(&self) -> ([&[f32]; 3], [&[f32]; 3], &[f32], &[f32]);
    /// Writes lane `i`'s result: `tfar = t`, `u`, `v`, `prim` for a hit, `prim = Hit::NONE`
    /// (and nothing else) for a miss.
    fn set_result(&mut self, i: usize, hit: &Hit);
}

macro_rules! ray_packet {
    ($(#[$doc:meta])* $name:ident, $k:expr, $mask:ty, $lanes:ident) => {
        $(#[$doc])*
        ///
        /// Structure of arrays, one row per component, in Embree's `RTCRayHitN` style: the
        /// queries read the ray rows of the lanes set in the `valid` mask they are given and
        /// write the hit rows of those lanes; `intersect*` also shrinks `tfar` to the hit
        /// distance. Lanes outside the mask are neither read nor written.
        #[repr(C, align(64))]
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct $name {
            /// Origin x per lane.
            pub org_x: [f32; $k],
            /// Origin y per lane.
            pub org_y: [f32; $k],
            /// Origin z per lane.
            pub org_z: [f32; $k],
            /// Direction x per lane.
            pub dir_x: [f32; $k],
            /// Direction y per lane.
            pub dir_y: [f32; $k],
            /// Direction z per lane.
            pub dir_z: [f32; $k],
            /// Start of the interval (exclusive) per lane.
            pub tnear: [f32; $k],
            /// End of the interval (inclusive) per lane; the hit distance after `intersect*`.
            pub tfar: [f32; $k],
            /// First surface coordinate of the hit (see [`Hit`]).
            pub u: [f32; $k],
            /// Second surface coordinate of the hit.
            pub v: [f32; $k],
            /// Primitive id of the hit, [`Hit::NONE`] for a miss.
            pub prim: [u32; $k],
        }

        impl Default for $name {
            fn default() -> Self {
                Self {
                    org_x: [0.0; $k],
                    org_y: [0.0; $k],
                    org_z: [0.0; $k],
                    dir_x: [0.0; $k],
                    dir_y: [0.0; $k],
                    dir_z: [0.0; $k],
                    tnear: [0.0; $k],
                    tfar: [0.0; $k],
                    u: [0.0; $k],
                    v: [0.0; $k],
                    prim: [Hit::NONE; $k],
                }
            }
        }

        impl $name {
            /// Rays per packet.
            pub const K: usize = $k;
            /// The mask with every lane set.
            pub const ALL: $mask = <$mask>::MAX;

            /// A packet holding `rays` (at most K) in lanes `0 .. rays.len()`, and the mask of
            /// those lanes.
            pub fn from_rays(rays: &[Ray]) -> (Self, $mask) {
                assert!(rays.len() <= $k, "at most {} rays per packet", $k);
                let rows = transpose_rays(rays);
                let row = |k: usize| -> [f32; $k] { rows[k][..$k].try_into().expect("K lanes") };
                let p = Self {
                    org_x: row(0),
                    org_y: row(1),
                    org_z: row(2),
                    dir_x: row(3),
                    dir_y: row(4),
                    dir_z: row(5),
                    tnear: row(6),
                    tfar: row(7),
                    u: [0.0; $k],
                    v: [0.0; $k],
                    prim: [Hit::NONE; $k],
                };
                let mask = if rays.len() == $k { Self::ALL } else { ((1u32 << rays.len()) - 1) as $mask };
                (p, mask)
            }

            /// Stores `r` in lane `i` and clears its hit.
            #[inline]
            pub fn set_ray(&mut self, i: usize, r: &Ray) {
                self.org_x[i] = r.origin.x;
                self.org_y[i] = r.origin.y;
                self.org_z[i] = r.origin.z;
                self.dir_x[i] = r.dir.x;
                self.dir_y[i] = r.dir.y;
                self.dir_z[i] = r.dir.z;
                self.tnear[i] = r.tnear;
                self.tfar[i] = r.tfar;
                self.prim[i] = Hit::NONE;
            }

            /// The ray in lane `i`.
            #[inline]
            pub fn ray(&self, i: usize) -> Ray {
                Ray {
                    origin: Vec3::new(self.org_x[i], self.org_y[i], self.org_z[i]),
                    dir: Vec3::new(self.dir_x[i], self.dir_y[i], self.dir_z[i]),
                    tnear: self.tnear[i],
                    tfar: self.tfar[i],
                }
            }

            /// The hit in lane `i` after `intersect*` ([`Hit::MISS`] when nothing was hit).
            #[inline]
            pub fn hit(&self, i: usize) -> Hit {
                if self.prim[i] == Hit::NONE {
                    Hit::MISS
                } else {
                    Hit { t: self.tfar[i], u: self.u[i], v: self.v[i], prim: self.prim[i] }
                }
            }
        }

        impl RayPacket for $name {
            const K: usize = $k;
            type Lanes<I: crate::simd::IsaLanes> = I::$lanes;

            #[inline(always)]
            fn ray_rows(&self) -> ([&[f32]; 3], [&[f32]; 3], &[f32], &[f32]) {
                ([&self.org_x, &self.org_y, &self.org_z], [&self.dir_x, &self.dir_y, &self.dir_z], &self.tnear, &self.tfar)
            }

            #[inline(always)]
            fn set_result(&mut self, i: usize, hit: &Hit) {
                self.prim[i] = hit.prim;
                if hit.is_hit() {
                    (self.tfar[i], self.u[i], self.v[i]) = (hit.t, hit.u, hit.v);
                }
            }
        }
    };
}

ray_packet!(
    /// Eight rays and their hits (AVX2 width).
    RayPacket8,
    8,
    u8,
    F8
);
ray_packet!(
    /// Sixteen rays and their hits (AVX-512 width).
    RayPacket16,
    16,
    u16,
    F16
);
const _: () = assert!(std::mem::size_of::<RayPacket8>() == 11 * 32 + 32);
const _: () = assert!(std::mem::size_of::<RayPacket16>() == 11 * 64);
