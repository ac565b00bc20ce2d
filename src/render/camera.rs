//! Camera rays for the renderer: [`Camera::generate_ray`] with the per-camera constants (the
//! half-angle tangents of the fields of view) computed once instead of per ray. The rays are
//! bit-for-bit those of [`Camera::generate_ray`].

use crate::math::{Mat3, Vec3};
use crate::ray::Ray;
use crate::scene::Camera;

/// Generates camera rays through pixel positions.
#[derive(Clone, Copy, Debug)]
pub struct CameraRays {
    position: Vec3,
    c2w: Mat3,
    tan_x: f32,
    tan_y: f32,
    near: f32,
    far: f32,
    /// The unnormalised direction through image position `(px, py)` is
    /// `cone_base + px / w * cone_x + py / h * cone_y` (in f64, for [`CameraRays::pixels_cone`]).
    cone_base: glam::DVec3,
    cone_x: glam::DVec3,
    cone_y: glam::DVec3,
}

impl CameraRays {
    /// Prepares `camera`.
    pub fn new(camera: &Camera) -> Self {
        let tan_x = (camera.hfov_deg.to_radians() * 0.5).tan();
        let tan_y = (camera.vfov_deg.to_radians() * 0.5).tan();
        let [cx, cy, cz] = [camera.c2w.x_axis, camera.c2w.y_axis, camera.c2w.z_axis].map(|a| a.as_dvec3());
        let (tx, ty) = (tan_x as f64, tan_y as f64);
        Self {
            position: camera.position,
            c2w: camera.c2w,
            tan_x,
            tan_y,
            near: camera.near,
            far: camera.far,
            // (2 px / w - 1) tan_x cx + (1 - 2 py / h) tan_y cy - cz
            cone_base: cy * ty - cx * tx - cz,
            cone_x: cx * (2.0 * tx),
            cone_y: cy * (-2.0 * ty),
        }
    }

    /// The ray through image position `(px, py)` in pixels, `(0, 0)` being the top-left
    /// corner of the image (pixel `(x, y)` spans `[x, x + 1) × [y, y + 1)`).
    #[inline]
    pub fn ray(&self, px: f32, py: f32, width: usize, height: usize) -> Ray {
        // Same expressions as `Camera::generate_ray(px / w, 1 - py / h)`.
        let x = px / width as f32;
        let y = 1.0 - py / height as f32;
        let d = Vec3::new((2.0 * x - 1.0) * self.tan_x, (2.0 * y - 1.0) * self.tan_y, -1.0);
        Ray::segment(self.position, (self.c2w * d).normalize(), self.near, self.far)
    }

    /// The cone of every ray [`CameraRays::ray`] gives through the pixels `x0..x1` ×
    /// `y0..y1`: the camera's position and a box of directions such that each of those rays
    /// runs along a positive multiple of a vector in the box (for
    /// [`crate::Scene::cone_may_hit`]).
    ///
    /// The unnormalised direction `c2w * ((2 px / w - 1) tan_x, (2 (1 - py / h) - 1) tan_y, -1)`
    /// is affine in the image position, so over a rectangle it ranges between its values at
    /// the corners. They are taken, in f64, at the corners of the rectangle grown by 1/16 of
    /// a pixel on every side, and the box is grown by 2^-18 of its largest component: far more
    /// than the roundings that move a ray computed in f32 off its exact direction.
    pub fn pixels_cone(
        &self,
        (x0, x1): (usize, usize),
        (y0, y1): (usize, usize),
        size: (usize, usize),
    ) -> (Vec3, Vec3, Vec3) {
        const GROW: f64 = 1.0 / 16.0;
        // v(px, py) = base + px ax + py ay, whose range over a rectangle is the sum of its
        // terms' ranges.
        let (ax, ay, base) = (self.cone_x / size.0 as f64, self.cone_y / size.1 as f64, self.cone_base);
        let (xa, xb) = (ax * (x0 as f64 - GROW), ax * (x1 as f64 + GROW));
        let (ya, yb) = (ay * (y0 as f64 - GROW), ay * (y1 as f64 + GROW));
        let lo = base + xa.min(xb) + ya.min(yb);
        let hi = base + xa.max(xb) + ya.max(yb);
        let pad = glam::DVec3::splat(lo.abs().max(hi.abs()).max_element() / (1 << 18) as f64);
        (self.position, (lo - pad).as_vec3(), (hi + pad).as_vec3())
    }

    /// [`CameraRays::ray`] through each image position of `positions` (`[px, py]`), in order,
    /// appended to `out`: computed four at a time in SIMD lanes, the same rays bit for bit.
    /// Generating rays one at a time was a chain of two divisions, a square root and a
    /// reciprocal per ray (PERFORMANCE.md, "Camera rays four at a time").
    #[inline]
    pub fn rays_into(&self, positions: &[[f32; 2]], width: usize, height: usize, out: &mut Vec<Ray>) {
        out.reserve(positions.len());
        for four in positions.chunks(4) {
            // Lanes past the end of `positions` go through the first pixel's centre, unused.
            let (mut px, mut py) = ([0.5f32; 4], [0.5f32; 4]);
            for (k, p) in four.iter().enumerate() {
                (px[k], py[k]) = (p[0], p[1]);
            }
            out.extend_from_slice(&self.rays4(px, py, width, height)[..four.len()]);
        }
    }

    /// [`CameraRays::ray`] through four image positions at once, in SIMD lanes: the same
    /// operations in the same order (glam's `Mat3 * Vec3` and `normalize`), each correctly
    /// rounded, so the same rays bit for bit.
    #[inline]
    fn rays4(&self, px: [f32; 4], py: [f32; 4], width: usize, height: usize) -> [Ray; 4] {
        use wide::f32x4;
        let s = f32x4::splat;
        let one = s(1.0);
        let x = f32x4::new(px) / s(width as f32);
        let y = one - f32x4::new(py) / s(height as f32);
        let dx = (s(2.0) * x - one) * s(self.tan_x);
        let dy = (s(2.0) * y - one) * s(self.tan_y);
        let dz = s(-1.0);
        let [cx, cy, cz] = [self.c2w.x_axis, self.c2w.y_axis, self.c2w.z_axis];
        // Mat3 * Vec3 as glam computes it: x_axis * d.x, then + y_axis * d.y, then + z_axis * d.z.
        let v = [0, 1, 2].map(|k| s(cx[k]) * dx + s(cy[k]) * dy + s(cz[k]) * dz);
        // Vec3::normalize: v * (1 / sqrt((x x + y y) + z z)).
        let r = one / (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let [nx, ny, nz] = [v[0] * r, v[1] * r, v[2] * r].map(|l| l.to_array());
        std::array::from_fn(|i| Ray::segment(self.position, Vec3::new(nx[i], ny[i], nz[i]), self.near, self.far))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_rays_as_the_camera() {
        let cam = Camera::look_at(Vec3::new(1.0, 2.0, 3.0), Vec3::ZERO, Vec3::Y, 47.0, 1.5, 0.01, 50.0);
        let (w, h) = (37, 23);
        let rays = CameraRays::new(&cam);
        for (px, py) in [(0.0, 0.0), (0.5, 0.5), (36.999, 22.5), (12.25, 7.75)] {
            let a = rays.ray(px, py, w, h);
            let b = cam.generate_ray(px / w as f32, 1.0 - py / h as f32);
            assert_eq!(a, b);
        }
    }

    /// Is `d` a positive multiple of a vector of the box `[lo, hi]`? (In f64: the multiples
    /// `l` with `lo <= l d <= hi` form an interval per axis; they must share a positive `l`.)
    fn in_cone(d: Vec3, lo: Vec3, hi: Vec3) -> bool {
        let (mut a, mut b) = (0.0f64, f64::INFINITY);
        for k in 0..3 {
            let (d, lo, hi) = (d[k] as f64, lo[k] as f64, hi[k] as f64);
            if d == 0.0 {
                if lo > 0.0 || hi < 0.0 {
                    return false;
                }
                continue;
            }
            let (p, q) = if d > 0.0 { (lo / d, hi / d) } else { (hi / d, lo / d) };
            (a, b) = (a.max(p), b.min(q));
        }
        a <= b && b > 0.0
    }

    #[test]
    fn pixel_cones_hold_their_pixels_rays() {
        let mut rng = crate::render::sampler::Rng::new(5, 6);
        let (mut inside, mut outside) = (0, 0);
        for k in 0..3000 {
            let from = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 10.0 - 5.0;
            let up = if k % 7 == 0 { Vec3::X } else { Vec3::Y };
            let fov = [0.5, 10.0, 60.0, 120.0, 170.0][k % 5];
            let cam = Camera::look_at(from, Vec3::ZERO, up, fov, 0.3 + 2.0 * rng.next_f32(), 0.01, 50.0);
            let (w, h) = (1 + (k * 13) % 4000, 1 + (k * 7) % 3000);
            let rays = CameraRays::new(&cam);
            let x0 = (rng.next_f32() * w as f32) as usize % w;
            let y0 = (rng.next_f32() * h as f32) as usize % h;
            let (x1, y1) = ((x0 + 1 + k % 3).min(w), (y0 + 1 + k % 2).min(h));
            let (o, lo, hi) = rays.pixels_cone((x0, x1), (y0, y1), (w, h));
            assert_eq!(o, cam.position);
            // The rays through the rectangle's corners (the largest jitter is just below 1)
            // and through random points of it are in its cone.
            let below_one = 1.0 - f32::EPSILON / 2.0;
            let mut through = vec![[x0 as f32, y0 as f32], [(x1 - 1) as f32 + below_one, (y1 - 1) as f32 + below_one]];
            through.push([x0 as f32, (y1 - 1) as f32 + below_one]);
            through.push([(x1 - 1) as f32 + below_one, y0 as f32]);
            for _ in 0..8 {
                let (px, py) =
                    (x0 as f32 + rng.next_f32() * (x1 - x0) as f32, y0 as f32 + rng.next_f32() * (y1 - y0) as f32);
                through.push([px, py]);
            }
            let mut out = Vec::new();
            rays.rays_into(&through, w, h, &mut out);
            for (r, p) in out.iter().zip(&through) {
                assert!(
                    in_cone(r.dir, lo, hi),
                    "ray through {p:?} of {w} x {h}, pixels {x0}..{x1} x {y0}..{y1}, fov {fov}"
                );
                inside += 1;
            }
            // A ray a few pixels away is not (so the check can fail).
            if x1 + 3 < w {
                let r = rays.ray(x1 as f32 + 3.0, y0 as f32, w, h);
                outside += !in_cone(r.dir, lo, hi) as usize;
            }
        }
        assert!(inside > 30_000 && outside > 1000, "{inside} inside, {outside} outside");
    }

    #[test]
    fn four_at_once_are_the_same_rays() {
        let mut rng = crate::render::sampler::Rng::new(3, 4);
        for k in 0..2000 {
            let from = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 10.0 - 5.0;
            let up = if k % 7 == 0 { Vec3::X } else { Vec3::Y };
            let cam = Camera::look_at(from, Vec3::ZERO, up, 10.0 + 150.0 * rng.next_f32(), 1.5, 0.01, 50.0);
            let (w, h) = (1 + k % 1000, 1 + (k * 7) % 700);
            let rays = CameraRays::new(&cam);
            let px: [f32; 4] = std::array::from_fn(|_| rng.next_f32() * w as f32);
            let py: [f32; 4] = std::array::from_fn(|_| rng.next_f32() * h as f32);
            let positions: Vec<[f32; 2]> = (0..3 + k % 3).map(|i| [px[i % 4], py[i % 4]]).collect();
            // One ray already there: `rays_into` appends.
            let mut through = vec![Ray::new(Vec3::ZERO, Vec3::X)];
            rays.rays_into(&positions, w, h, &mut through);
            let through = &through[1..];
            assert_eq!(through.len(), positions.len());
            for (r, p) in through.iter().zip(&positions) {
                assert_eq!(
                    r.dir.to_array().map(f32::to_bits),
                    rays.ray(p[0], p[1], w, h).dir.to_array().map(f32::to_bits)
                );
            }
            let four = rays.rays4(px, py, w, h);
            for i in 0..4 {
                let one = rays.ray(px[i], py[i], w, h);
                assert_eq!(
                    (four[i].dir.to_array().map(f32::to_bits), four[i].origin, four[i].tnear, four[i].tfar),
                    (one.dir.to_array().map(f32::to_bits), one.origin, one.tnear, one.tfar),
                    "camera {k}, lane {i}"
                );
            }
        }
    }
}
