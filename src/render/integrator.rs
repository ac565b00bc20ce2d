//! Integrators: what a pixel's value is, given the scene.

use super::{RayCounts, RenderSettings, sampler::Rng};
use crate::math::Vec3;
use crate::scene::{Camera, Scene};

/// The quantity a render computes per camera ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum IntegratorKind {
    /// Shading normal mapped to colour, `n * 0.5 + 0.5`; black where nothing is hit.
    #[default]
    Normals,
}

impl IntegratorKind {
    /// How the film of this integrator is encoded to 8 bits.
    pub fn encoding(&self) -> super::Encoding {
        match self {
            IntegratorKind::Normals => super::Encoding::Display,
        }
    }
}

/// An integrator bound to a scene and settings.
pub struct Integrator<'a> {
    scene: &'a Scene,
    settings: &'a RenderSettings,
}

impl<'a> Integrator<'a> {
    /// Prepares the integrator.
    pub fn new(scene: &'a Scene, settings: &'a RenderSettings) -> Self {
        Self { scene, settings }
    }

    /// Estimates pixel `(x, y)` (row 0 at the top); returns the value and the samples taken.
    pub fn pixel(&self, camera: &Camera, x: usize, y: usize, rng: &mut Rng, rays: &mut RayCounts) -> (Vec3, u32) {
        let s = self.settings;
        let n = s.samples_per_pixel.max(1);
        let mut sum = Vec3::ZERO;
        for _ in 0..n {
            // One sample goes through the pixel centre; more are jittered uniformly.
            let (jx, jy) = if n == 1 { (0.5, 0.5) } else { rng.next_2d() };
            let u = (x as f32 + jx) / s.width as f32;
            let v = 1.0 - (y as f32 + jy) / s.height as f32;
            let ray = camera.generate_ray(u, v);
            rays.camera += 1;
            sum += match s.integrator {
                IntegratorKind::Normals => {
                    let hit = if s.brute_force {
                        self.scene.intersect1_brute_force(&ray)
                    } else {
                        self.scene.intersect1(&ray)
                    };
                    if hit.is_hit() { self.scene.surface(&ray, &hit).shading_normal * 0.5 + 0.5 } else { Vec3::ZERO }
                }
            };
        }
        (sum / n as f32, n)
    }
}
