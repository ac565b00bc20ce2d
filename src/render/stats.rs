//! Traversal statistics in the manner of CS184's "intersection tests per ray".

use super::RenderSettings;
use crate::scene::{Camera, Scene};

/// Mean primitive intersection tests per camera ray through pixel centres, measured with
/// the scalar reference traversal on every 4th pixel of every 4th row (or `num_prims` with
/// brute force).
pub fn intersection_tests_per_ray(scene: &Scene, camera: &Camera, s: &RenderSettings) -> f64 {
    if s.brute_force {
        return scene.num_prims() as f64;
    }
    let (mut rays, mut tests) = (0u64, 0u64);
    for y in (0..s.height).step_by(4) {
        for x in (0..s.width).step_by(4) {
            let ray = camera.generate_ray((x as f32 + 0.5) / s.width as f32, 1.0 - (y as f32 + 0.5) / s.height as f32);
            scene.bvh2().intersect(&ray, |prim, tfar| {
                tests += 1;
                scene.intersect_prim(prim, &ray, tfar)
            });
            rays += 1;
        }
    }
    tests as f64 / rays.max(1) as f64
}
