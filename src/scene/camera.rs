//! The pinhole camera of CS184: a sensor plane at `z = -1` in camera space spanning
//! `±tan(hFov/2)` by `±tan(vFov/2)`, rotated to world space by `c2w`; near and far clip
//! planes become the ray's `t` interval (rays have unit-length directions, so `t` is distance).

use crate::math::{Aabb, Mat3, Vec3};
use crate::ray::Ray;

/// A pinhole camera looking down its local `-z` axis with `+y` up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position in world space.
    pub position: Vec3,
    /// Camera-to-world rotation: columns are the camera's right, up and backward axes.
    pub c2w: Mat3,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f32,
    /// Vertical field of view, degrees.
    pub vfov_deg: f32,
    /// Near clip distance (the rays' `tnear`).
    pub near: f32,
    /// Far clip distance (the rays' `tfar`).
    pub far: f32,
}

impl Camera {
    /// A camera at `position` looking at `target` with the given up hint, vertical field of
    /// view (degrees) and aspect ratio (width / height).
    pub fn look_at(position: Vec3, target: Vec3, up: Vec3, vfov_deg: f32, aspect: f32, near: f32, far: f32) -> Self {
        let back = (position - target).normalize();
        let mut right = up.cross(back);
        if right.length_squared() < 1e-12 {
            // Looking along the up hint: pick any perpendicular.
            right = crate::math::orthonormal_basis(back).0;
        }
        let right = right.normalize();
        let up = back.cross(right);
        let mut cam = Self { position, c2w: Mat3::from_cols(right, up, back), hfov_deg: 0.0, vfov_deg, near, far };
        cam.set_aspect(aspect);
        cam
    }

    /// A camera that frames `bounds` from the front (looking down `-z`, slightly from above),
    /// for files that carry no camera.
    pub fn framing(bounds: &Aabb, aspect: f32) -> Self {
        let (center, radius) = if bounds.is_valid() {
            (bounds.center(), (bounds.extent().length() * 0.5).max(1e-6))
        } else {
            (Vec3::ZERO, 1.0)
        };
        let vfov = 35.0f32;
        let half = (vfov.to_radians() * 0.5).tan().min((vfov.to_radians() * 0.5 * aspect).tan());
        let dist = radius / half.atan().sin();
        let dir = Vec3::new(0.0, 0.35, 1.0).normalize();
        let position = center + dir * dist;
        Self::look_at(
            position,
            center,
            Vec3::Y,
            vfov,
            aspect,
            (dist - radius).max(dist * 1e-4) * 0.5,
            (dist + radius) * 2.0,
        )
    }

    /// Keeps the vertical field of view and recomputes the horizontal one for an image of
    /// the given aspect ratio (width / height), as CS184's `set_screen_size` does.
    pub fn set_aspect(&mut self, aspect: f32) {
        let half_v = (self.vfov_deg.to_radians() * 0.5).tan();
        self.hfov_deg = (2.0 * (half_v * aspect).atan()).to_degrees();
    }

    /// The camera's viewing direction (unit).
    pub fn view_dir(&self) -> Vec3 {
        -self.c2w.z_axis
    }

    /// The ray through normalised image coordinates `(x, y)` in `[0,1]²`, `(0,0)` being the
    /// bottom-left corner of the image. Its direction has unit length and its interval is
    /// `(near, far]`.
    #[inline]
    pub fn generate_ray(&self, x: f32, y: f32) -> Ray {
        let tx = (self.hfov_deg.to_radians() * 0.5).tan();
        let ty = (self.vfov_deg.to_radians() * 0.5).tan();
        let d = Vec3::new((2.0 * x - 1.0) * tx, (2.0 * y - 1.0) * ty, -1.0);
        Ray::segment(self.position, (self.c2w * d).normalize(), self.near, self.far)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_ray_looks_at_target_and_corners_span_fov() {
        let cam = Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y, 60.0, 2.0, 0.1, 100.0);
        let r = cam.generate_ray(0.5, 0.5);
        assert!((r.dir - -Vec3::Z).length() < 1e-6);
        assert_eq!((r.tnear, r.tfar), (0.1, 100.0));
        let top = cam.generate_ray(0.5, 1.0).dir;
        assert!((top.angle_between(-Vec3::Z).to_degrees() - 30.0).abs() < 1e-3);
        let right = cam.generate_ray(1.0, 0.5).dir;
        assert!((right.angle_between(-Vec3::Z).to_degrees() - cam.hfov_deg * 0.5).abs() < 1e-3);
        assert!(right.x > 0.0 && top.y > 0.0);
        // hFov follows the aspect: tan(h/2) = aspect * tan(v/2).
        let expect = (2.0 * (2.0 * 30f32.to_radians().tan()).atan()).to_degrees();
        assert!((cam.hfov_deg - expect).abs() < 1e-3);
    }

    #[test]
    fn framing_camera_sees_the_box() {
        let b = Aabb::new(Vec3::new(-1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0));
        let cam = Camera::framing(&b, 4.0 / 3.0);
        let r = cam.generate_ray(0.5, 0.5);
        let to_center = (b.center() - cam.position).normalize();
        assert!(r.dir.dot(to_center) > 0.9999);
        assert!(cam.near > 0.0 && cam.far > (b.center() - cam.position).length());
    }
}
