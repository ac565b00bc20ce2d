//! The watertight ray/triangle test of Woop, Benthin and Wald, "Watertight Ray/Triangle
//! Intersection", JCGT 2(1), 2013: scalar reference and the SIMD core its block kernels use.
//!
//! The ray is made the `+z` axis of a sheared frame: `kz` is the axis of the direction's
//! largest magnitude, `kx`, `ky` the next two (swapped when `dir[kz] < 0`, which keeps the
//! winding), and the vertices, taken relative to the origin, are sheared by
//! `Sx = dx / dz`, `Sy = dy / dz`, `Sz = 1 / dz`. In that frame the hit test is three 2D
//! edge functions `U, V, W` at the origin, and each depends only on the two (exact) vertices
//! of its edge: the triangles sharing an edge compute exactly opposite values, so a ray
//! cannot slip between them. When a single-precision edge function is exactly 0 it is
//! recomputed in double precision (products of two `f32` are exact in `f64`), which gives the
//! true sign, as the paper does. Both faces are hit (no culling); a zero edge function counts
//! as inside, so a ray through a shared edge or vertex hits every triangle there.
//!
//! The vertices must be the exact input vertices: `v0 + (v1 - v0)` rounds, which is why
//! watertight leaf blocks store `v0, v1, v2` rather than edges
//! ([`crate::geometry::tri_block::TriangleTest`]).
//!
//! Every lane of [`watertight`] performs the operations of [`intersect_triangle_watertight`]
//! in the same order (no fused multiply-adds), so both are bit-identical.

use crate::math::Vec3;
use crate::simd::{Lanes, Vec3x};

/// The sheared frame of direction `dir`: axes `[kx, ky, kz]` and shear `[Sx, Sy, Sz]`.
#[inline]
pub fn shear_frame(dir: Vec3) -> ([usize; 3], [f32; 3]) {
    let a = dir.abs();
    let kz = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
    if dir[kz] < 0.0 {
        std::mem::swap(&mut kx, &mut ky);
    }
    let sz = 1.0 / dir[kz];
    ([kx, ky, kz], [dir[kx] / dir[kz], dir[ky] / dir[kz], sz])
}

/// The edge functions `(U, V, W)` of the sheared 2D vertices in double precision, rounded
/// back to `f32` (the sign is exact: each product of two `f32` is exact in `f64`, and the
/// difference is rounded once).
#[inline]
pub fn edge_functions_f64(ax: f32, ay: f32, bx: f32, by: f32, cx: f32, cy: f32) -> (f32, f32, f32) {
    let d = |x: f32| x as f64;
    let u = d(cx) * d(by) - d(cy) * d(bx);
    let v = d(ax) * d(cy) - d(ay) * d(cx);
    let w = d(bx) * d(ay) - d(by) * d(ax);
    (u as f32, v as f32, w as f32)
}

/// Intersects the ray `origin + t dir` with triangle `(v0, v1, v2)`, watertight.
///
/// Returns `(t, u, v)` with `p = (1-u-v) v0 + u v1 + v v2` when `t` lies in `[tnear, tfar]`
/// and the ray passes inside or on the edges; `None` otherwise (and for triangles degenerate
/// as seen along the ray). A hit at the origin is `t = +0.0`, never `-0.0`.
#[inline]
pub fn intersect_triangle_watertight(
    origin: Vec3,
    dir: Vec3,
    tnear: f32,
    tfar: f32,
    v0: Vec3,
    v1: Vec3,
    v2: Vec3,
) -> Option<(f32, f32, f32)> {
    let ([kx, ky, kz], [sx, sy, sz]) = shear_frame(dir);
    let (a, b, c) = (v0 - origin, v1 - origin, v2 - origin);
    let (ax, ay) = (a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
    let (bx, by) = (b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
    let (cx, cy) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        (u, v, w) = edge_functions_f64(ax, ay, bx, by, cx, cy);
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let (az, bz, cz) = (sz * a[kz], sz * b[kz], sz * c[kz]);
    let tt = u * az + v * bz + w * cz;
    let inv_det = 1.0 / det;
    let mut t = tt * inv_det;
    if !t.is_finite() {
        t = t_f64([u, v, w], [az, bz, cz], inv_det);
    }
    let t = t + 0.0; // `-0.0` (a hit at the origin) made `+0.0`, as Möller–Trumbore does
    let ok = inv_det.is_finite() && t < f32::INFINITY;
    if ok && t >= tnear && t <= tfar { Some((t, v * inv_det, w * inv_det)) } else { None }
}

/// `(U Az + V Bz + W Cz) * inv_det` in double precision, rounded to `f32`: the fallback when
/// the `f32` sum overflows (it grows with the cube of the distance between origin and
/// triangle). The SIMD kernel uses the same.
#[inline]
pub fn t_f64(uvw: [f32; 3], z: [f32; 3], inv_det: f32) -> f32 {
    let d = |x: f32| x as f64;
    ((d(uvw[0]) * d(z[0]) + d(uvw[1]) * d(z[1]) + d(uvw[2]) * d(z[2])) * d(inv_det)) as f32
}

/// The watertight test on lanes: `a`, `b`, `c` are the three vertices relative to the ray
/// origin, permuted to `[kx, ky, kz]`, and `s` the shear `[Sx, Sy, Sz]` (any lane may be a
/// broadcast). Returns `(hit mask, t, u, v)` as [`intersect_triangle_watertight`] does, lane
/// by lane. `live()` gives the lanes that hold real triangles, the only ones worth the
/// double-precision recomputation (padding lanes' edge functions are always 0); it runs only
/// when an edge function is exactly 0, and must be scalar code (a closure holding SIMD code
/// would not be inlined into the ISA's kernel).
#[inline(always)]
pub fn watertight<V: Lanes>(
    a: [V; 3],
    b: [V; 3],
    c: [V; 3],
    s: [V; 3],
    tnear: V,
    tfar: V,
    live: impl FnOnce() -> u32,
) -> (V, V, V, V) {
    let zero = V::splat(0.0);
    let (ax, ay) = (a[0] - s[0] * a[2], a[1] - s[1] * a[2]);
    let (bx, by) = (b[0] - s[0] * b[2], b[1] - s[1] * b[2]);
    let (cx, cy) = (c[0] - s[0] * c[2], c[1] - s[1] * c[2]);
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    let zeros = (u.eq(zero) | v.eq(zero) | w.eq(zero)).bitmask();
    if zeros != 0 {
        let redo = zeros & live();
        if redo != 0 {
            let rows = |x: V| {
                let mut r = [0.0f32; 16];
                x.store(&mut r);
                r
            };
            let (xa, ya, xb, yb, xc, yc) = (rows(ax), rows(ay), rows(bx), rows(by), rows(cx), rows(cy));
            let (mut ur, mut vr, mut wr) = (rows(u), rows(v), rows(w));
            for i in crate::simd::bits(redo) {
                (ur[i], vr[i], wr[i]) = edge_functions_f64(xa[i], ya[i], xb[i], yb[i], xc[i], yc[i]);
            }
            (u, v, w) = (V::load(&ur), V::load(&vr), V::load(&wr));
        }
    }
    let outside = (u.lt(zero) | v.lt(zero) | w.lt(zero)) & (u.gt(zero) | v.gt(zero) | w.gt(zero));
    let det = u + v + w;
    let maybe = !outside & !det.eq(zero) & det.is_finite();
    if maybe.bitmask() == 0 {
        return (zero, zero, zero, zero);
    }
    let (az, bz, cz) = (s[2] * a[2], s[2] * b[2], s[2] * c[2]);
    let tt = u * az + v * bz + w * cz;
    let inv_det = V::splat(1.0) / det;
    let mut t = tt * inv_det;
    let overflow = (maybe & !t.is_finite()).bitmask();
    if overflow != 0 {
        t = redo_t_f64(t, overflow, [u, v, w], [az, bz, cz], inv_det);
    }
    let t = t + zero;
    let valid = maybe & inv_det.is_finite() & t.lt(V::splat(f32::INFINITY)) & t.ge(tnear) & t.le(tfar);
    (valid, t, v * inv_det, w * inv_det)
}

/// `t` with the lanes of `lanes` recomputed by [`t_f64`].
#[cold]
#[inline(never)]
fn redo_t_f64<V: Lanes>(t: V, lanes: u32, uvw: [V; 3], z: [V; 3], inv_det: V) -> V {
    let mut out = [0.0f32; 16];
    t.store(&mut out);
    for i in crate::simd::bits(lanes) {
        out[i] = t_f64(uvw.map(|x| x.lane(i)), z.map(|x| x.lane(i)), inv_det.lane(i));
    }
    V::load(&out)
}

/// Per-lane sheared frames of K rays (for one triangle against a packet): lane masks that
/// select `kz` and the `kx`/`ky` swap, and the shear.
#[derive(Clone, Copy, Debug)]
pub struct ShearLanes<V> {
    /// Lanes whose `kz` is x.
    z_is_x: V,
    /// Lanes whose `kz` is y.
    z_is_y: V,
    /// Lanes whose `kx`, `ky` are swapped (`dir[kz] < 0`).
    swap: V,
    /// Origins.
    pub org: Vec3x<V>,
    /// `[Sx, Sy, Sz]`.
    pub shear: [V; 3],
}

impl<V: Lanes> ShearLanes<V> {
    /// The frames of rays `org + t dir`, lane by lane as [`shear_frame`] computes them.
    #[inline(always)]
    pub fn new(org: &Vec3x<V>, dir: &Vec3x<V>) -> Self {
        let (ax, ay, az) = (dir.x.abs(), dir.y.abs(), dir.z.abs());
        let z_is_x = ax.ge(ay) & ax.ge(az);
        let z_is_y = !z_is_x & ay.ge(az);
        let dz = z_is_x.select(dir.x, z_is_y.select(dir.y, dir.z));
        let mut me = Self { z_is_x, z_is_y, swap: dz.lt(V::splat(0.0)), org: *org, shear: [dz; 3] };
        let [dx, dy, dz] = me.permute(dir);
        me.shear = [dx / dz, dy / dz, V::splat(1.0) / dz];
        me
    }

    /// `p` permuted to `[kx, ky, kz]`, lane by lane.
    #[inline(always)]
    pub fn permute(&self, p: &Vec3x<V>) -> [V; 3] {
        let (zx, zy) = (self.z_is_x, self.z_is_y);
        let kz = zx.select(p.x, zy.select(p.y, p.z));
        let kx = zx.select(p.y, zy.select(p.z, p.x));
        let ky = zx.select(p.z, zy.select(p.x, p.y));
        [self.swap.select(ky, kx), self.swap.select(kx, ky), kz]
    }

    /// The K rays against one triangle `(v0, v1, v2)` (broadcast).
    #[inline(always)]
    pub fn intersect(&self, tri: &[Vec3; 3], tnear: V, tfar: V) -> (V, V, V, V) {
        let a = self.permute(&(Vec3x::splat(tri[0]) - self.org));
        let b = self.permute(&(Vec3x::splat(tri[1]) - self.org));
        let c = self.permute(&(Vec3x::splat(tri[2]) - self.org));
        watertight(a, b, c, self.shear, tnear, tfar, || u32::MAX)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simd::{F32x8, F32x16};

    const V0: Vec3 = Vec3::new(0.0, 0.0, 0.0);
    const V1: Vec3 = Vec3::new(1.0, 0.0, 0.0);
    const V2: Vec3 = Vec3::new(0.0, 1.0, 0.0);

    #[test]
    fn hits_with_barycentrics_and_interval() {
        let o = Vec3::new(0.25, 0.5, 1.0);
        assert_eq!(intersect_triangle_watertight(o, -Vec3::Z, 0.0, 10.0, V0, V1, V2), Some((1.0, 0.25, 0.5)));
        let (t, ..) = intersect_triangle_watertight(Vec3::new(0.25, 0.5, -2.0), Vec3::Z, 0.0, 9.0, V0, V1, V2).unwrap();
        assert_eq!(t, 2.0);
        assert!(intersect_triangle_watertight(o, -Vec3::Z, 1.0, 10.0, V0, V1, V2).is_some(), "t == tnear");
        assert!(intersect_triangle_watertight(o, -Vec3::Z, 1.0f32.next_up(), 10.0, V0, V1, V2).is_none());
        // From a point of the triangle, either way: t = +0.0.
        for d in [-Vec3::Z, Vec3::Z, Vec3::new(0.3, -0.2, 1.0)] {
            let h = intersect_triangle_watertight(Vec3::new(0.25, 0.5, 0.0), d, 0.0, 9.0, V0, V1, V2);
            assert_eq!(h.map(|(t, ..)| t.to_bits()), Some(0.0f32.to_bits()), "{d}");
        }
        assert!(intersect_triangle_watertight(o, -Vec3::Z, 0.0, 1.0, V0, V1, V2).is_some(), "t == tfar");
        assert!(intersect_triangle_watertight(Vec3::new(0.6, 0.6, 1.0), -Vec3::Z, 0.0, 9.0, V0, V1, V2).is_none());
        assert!(intersect_triangle_watertight(o, Vec3::X, 0.0, 9.0, V0, V1, V2).is_none(), "parallel");
        assert!(intersect_triangle_watertight(o, -Vec3::Z, 0.0, 9.0, V0, V1, V1).is_none(), "degenerate");
    }

    #[test]
    fn shared_edge_and_vertex_hit_both_triangles() {
        // Two triangles sharing the diagonal of the unit square; rays exactly at the diagonal
        // and at the shared corner hit both (edge functions exactly 0).
        let v3 = Vec3::new(1.0, 1.0, 0.0);
        let d = Vec3::new(0.1, -0.05, -1.0);
        for k in 1..100 {
            let p = Vec3::new(k as f32 / 100.0, 1.0 - k as f32 / 100.0, 0.0);
            let o = p - d * 2.0;
            let a = intersect_triangle_watertight(o, d, 0.0, 9.0, V1, V2, V0);
            let b = intersect_triangle_watertight(o, d, 0.0, 9.0, V2, V1, v3);
            assert!(a.is_some() || b.is_some(), "ray at {p} slipped through the shared edge");
        }
        // Exactly through the shared vertex V1, from straight above: both triangles hit.
        let o = Vec3::new(1.0, 0.0, 1.0);
        assert!(intersect_triangle_watertight(o, -Vec3::Z, 0.0, 9.0, V1, V2, V0).is_some());
        assert!(intersect_triangle_watertight(o, -Vec3::Z, 0.0, 9.0, V2, V1, v3).is_some());
    }

    #[test]
    fn lanes_match_scalar_bit_for_bit() {
        let mut rng = crate::rng::Rng::new(7, 1);
        let mut r3 = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
        for _ in 0..2000 {
            let tri = [r3(), r3(), r3()];
            let rays: Vec<(Vec3, Vec3)> = (0..16)
                .map(|i| {
                    // Half the rays aim exactly at a vertex, the others at random points.
                    let target = if i % 2 == 0 { tri[i % 3] } else { r3() };
                    let o = r3() * 3.0;
                    (o, target - o)
                })
                .collect();
            let lanes = |f: &dyn Fn(&(Vec3, Vec3)) -> f32| F32x16::new(std::array::from_fn(|i| f(&rays[i])));
            let org = Vec3x { x: lanes(&|r| r.0.x), y: lanes(&|r| r.0.y), z: lanes(&|r| r.0.z) };
            let dir = Vec3x { x: lanes(&|r| r.1.x), y: lanes(&|r| r.1.y), z: lanes(&|r| r.1.z) };
            let sh = ShearLanes::new(&org, &dir);
            let (m, t, u, v) = sh.intersect(&tri, F32x16::splat(0.0), F32x16::splat(f32::INFINITY));
            for (i, r) in rays.iter().enumerate() {
                let s = intersect_triangle_watertight(r.0, r.1, 0.0, f32::INFINITY, tri[0], tri[1], tri[2]);
                let lane = (m.bitmask() >> i & 1 != 0).then(|| (t.lane(i), u.lane(i), v.lane(i)));
                assert_eq!(
                    s.map(|x| (x.0.to_bits(), x.1.to_bits(), x.2.to_bits())),
                    lane.map(|x| (x.0.to_bits(), x.1.to_bits(), x.2.to_bits()))
                );
            }
            // One ray against eight triangles (the block direction), by the same core.
            let (o, d) = rays[0];
            let ([kx, ky, kz], s) = shear_frame(d);
            let tris: Vec<[Vec3; 3]> = (0..8).map(|k| if k == 0 { tri } else { [r3(), r3(), r3()] }).collect();
            let row = |j: usize, ax: usize| F32x8::new(std::array::from_fn(|k| tris[k][j][ax])) - F32x8::splat(o[ax]);
            let rel = |j: usize| [row(j, kx), row(j, ky), row(j, kz)];
            let (m, t, ..) = watertight(
                rel(0),
                rel(1),
                rel(2),
                s.map(F32x8::splat),
                F32x8::splat(0.0),
                F32x8::splat(f32::INFINITY),
                || 0xFF,
            );
            for (k, tr) in tris.iter().enumerate() {
                let s = intersect_triangle_watertight(o, d, 0.0, f32::INFINITY, tr[0], tr[1], tr[2]);
                assert_eq!(s.map(|x| x.0.to_bits()), (m.bitmask() >> k & 1 != 0).then(|| t.lane(k).to_bits()));
            }
        }
    }
}
