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
}

impl CameraRays {
    /// Prepares `camera`.
    pub fn new(camera: &Camera) -> Self {
        Self {
            position: camera.position,
            c2w: camera.c2w,
            tan_x: (camera.hfov_deg.to_radians() * 0.5).tan(),
            tan_y: (camera.vfov_deg.to_radians() * 0.5).tan(),
            near: camera.near,
            far: camera.far,
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
}
