//! Integrators: the radiance a camera ray brings back (CS184 parts 3–4; pbrt-v4's
//! `PathIntegrator` without multiple importance sampling).
//!
//! A path is traced iteratively. At each non-specular hit, direct lighting is estimated either
//! by sampling the lights (`-l` samples per area light, one per delta light) and tracing shadow
//! rays, or (`-H`) by tracing uniformly distributed hemisphere rays and adding the emission
//! they find (as many as light sampling would trace). The path then continues in a direction
//! drawn from the BSDF. Emission met by the continuation is counted only right after the
//! camera or a specular bounce (mirror, glass): everywhere else direct lighting has already
//! accounted for it. Light is split by bounces: `k` bounces is light scattered `k` times on
//! its way to the camera (0: emission seen directly; 1: direct lighting). Each integrator
//! keeps a range of bounces, so that `global` = `bounce -m 0` + `direct-only` + `indirect-only`.
//!
//! Russian roulette (from the second bounce on) continues a path with probability equal to
//! its throughput's largest component (divided by the radiance scaling of refraction, as
//! pbrt's `etaScale`) and divides the survivors by it, so that the estimate stays unbiased.

use super::bsdf;
use super::frame::Frame;
use super::light::{LightContext, LightSet, SampledLight};
use super::sampler::Rng;
use super::sampling::{UNIFORM_HEMISPHERE_PDF, uniform_hemisphere};
use super::spawn::{spawn_ray, spawn_ray_infinite, spawn_ray_to};
use super::stats::{RayKind, RayLog};
use super::trace::Tracer;
use super::{Encoding, RenderSettings};
use crate::math::Vec3;
use crate::ray::{Hit, Ray};
use crate::scene::{Bsdf, Material, Scene, SurfaceHit};

/// The quantity a render computes per camera ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum IntegratorKind {
    /// Shading normal mapped to colour, `n * 0.5 + 0.5`; black where nothing is hit.
    Normals,
    /// Emission seen directly plus direct lighting (CS184 part 3): bounces 0 and 1.
    Direct,
    /// Global illumination (CS184 part 4): bounces 0 to `-m`.
    #[default]
    Global,
    /// Only direct lighting: bounce 1 (no emission seen directly).
    DirectOnly,
    /// Only indirect lighting: bounces 2 to `-m`.
    IndirectOnly,
    /// Exactly `-m` bounces (CS184's per-bounce images).
    Bounce,
}

impl IntegratorKind {
    /// How the film of this integrator is encoded to 8 bits.
    pub fn encoding(&self) -> Encoding {
        match self {
            IntegratorKind::Normals => Encoding::Display,
            _ => Encoding::Srgb,
        }
    }

    /// The inclusive range of bounces counted with maximum depth `max_depth`; `None` for
    /// [`IntegratorKind::Normals`]. The range may be empty (`lo > hi`).
    pub fn bounces(&self, max_depth: u32) -> Option<(u32, u32)> {
        match self {
            IntegratorKind::Normals => None,
            IntegratorKind::Direct => Some((0, 1)),
            IntegratorKind::Global => Some((0, max_depth)),
            IntegratorKind::DirectOnly => Some((1, 1)),
            IntegratorKind::IndirectOnly => Some((2, max_depth)),
            IntegratorKind::Bounce => Some((max_depth, max_depth)),
        }
    }
}

/// Russian roulette starts at this many bounces.
const ROULETTE_START: u32 = 2;

/// An integrator bound to a scene and settings.
pub struct Integrator<'a> {
    scene: &'a Scene,
    settings: &'a RenderSettings,
    tracer: Tracer<'a>,
    lights: LightSet,
    bounces: Option<(u32, u32)>,
    /// Hemisphere rays per shading point under `-H`: the shadow rays light sampling would use.
    hemisphere_samples: u32,
}

impl<'a> Integrator<'a> {
    /// Prepares the integrator (and the scene's lights for sampling).
    pub fn new(scene: &'a Scene, settings: &'a RenderSettings) -> Self {
        let lights = LightSet::new(scene);
        let per_light = |l: &SampledLight| if l.is_delta() { 1 } else { settings.light_samples.max(1) };
        let hemisphere_samples = lights.lights.iter().map(per_light).sum();
        Self {
            scene,
            settings,
            tracer: Tracer::new(scene, settings.brute_force),
            lights,
            bounces: settings.integrator.bounces(settings.max_depth),
            hemisphere_samples,
        }
    }

    /// The ray queries this integrator uses.
    pub fn tracer(&self) -> &Tracer<'a> {
        &self.tracer
    }

    /// The lights as sampled.
    pub fn lights(&self) -> &LightSet {
        &self.lights
    }

    /// Radiance arriving along camera ray `ray` whose closest hit is `hit`; random numbers
    /// from `rng`; rays traced are logged in `log`.
    pub fn radiance(&self, ray: &Ray, hit: &Hit, rng: &mut Rng, log: &mut RayLog) -> Vec3 {
        let Some((lo, hi)) = self.bounces else {
            return if hit.is_hit() { self.scene.surface(ray, hit).shading_normal * 0.5 + 0.5 } else { Vec3::ZERO };
        };
        if lo > hi {
            return Vec3::ZERO;
        }
        let counted = |k: u32| lo <= k && k <= hi;
        let mut l = Vec3::ZERO;
        let mut beta = Vec3::ONE;
        let mut eta_scale = 1.0f32;
        let (mut ray, mut hit) = (*ray, *hit);
        let mut depth = 0u32; // scattering events so far
        let mut sees_emission = true; // camera ray or a specular bounce
        loop {
            if !hit.is_hit() {
                if sees_emission && counted(depth) {
                    l += beta * self.lights.environment;
                }
                break;
            }
            let s = self.scene.surface(&ray, &hit);
            let mat = self.material(hit.prim);
            if sees_emission && counted(depth) {
                l += beta * self.lights.emitted(hit.prim, mat.emission, ray.dir);
            }
            let delta = bsdf::is_delta(&mat.bsdf);
            let frame = Frame::from_normal(s.shading_normal);
            let wo = frame.to_local(-ray.dir);
            // Direct lighting here is light with one more bounce.
            if !delta && counted(depth + 1) && wo.z != 0.0 {
                l += beta * self.direct(&s, &mat.bsdf, &frame, wo, rng, log);
            }
            // The continuation only brings light with at least this many bounces.
            let next = if delta { depth + 1 } else { depth + 2 };
            if next > hi {
                break;
            }
            let Some(bs) = bsdf::sample_f(&mat.bsdf, wo, rng.next_2d(), rng.next_f32()) else {
                break;
            };
            beta *= bs.weight;
            eta_scale *= bs.eta_scale;
            if beta.max_element() <= 0.0 {
                break;
            }
            depth += 1;
            sees_emission = bs.delta;
            if self.settings.russian_roulette && depth >= ROULETTE_START {
                let q = (beta * eta_scale).max_element();
                if q < 1.0 {
                    if rng.next_f32() >= q {
                        break;
                    }
                    beta /= q;
                }
            }
            ray = spawn_ray(s.position, s.geometric_normal, frame.to_world(bs.wi));
            log.record(RayKind::Bounce, &ray);
            hit = self.tracer.closest(&ray);
        }
        l
    }

    #[inline]
    fn material(&self, prim: u32) -> &'a Material {
        let nt = self.scene.triangles.len();
        let p = prim as usize;
        let id = if p < nt { self.scene.triangles.material[p] } else { self.scene.spheres.material[p - nt] };
        &self.scene.materials[id as usize]
    }

    /// Direct lighting toward `wo` (local to `frame`) at the non-specular surface `s`.
    fn direct(&self, s: &SurfaceHit, b: &Bsdf, frame: &Frame, wo: Vec3, rng: &mut Rng, log: &mut RayLog) -> Vec3 {
        if self.settings.hemisphere_sampling {
            self.direct_hemisphere(s, b, frame, wo, rng, log)
        } else {
            self.direct_lights(s, b, frame, wo, rng, log)
        }
    }

    /// CS184 `estimate_direct_lighting_importance`: `-l` samples of each area light, one of
    /// each delta light, one shadow ray each.
    fn direct_lights(
        &self,
        s: &SurfaceHit,
        b: &Bsdf,
        frame: &Frame,
        wo: Vec3,
        rng: &mut Rng,
        log: &mut RayLog,
    ) -> Vec3 {
        let ctx = LightContext { p: s.position, n: frame.z * wo.z.signum() };
        let mut total = Vec3::ZERO;
        for light in &self.lights.lights {
            let n = if light.is_delta() { 1 } else { self.settings.light_samples.max(1) };
            let mut sum = Vec3::ZERO;
            for _ in 0..n {
                let u = rng.next_2d();
                let Some(ls) = light.sample(self.scene, &ctx, u) else { continue };
                let wi = frame.to_local(ls.wi);
                let f = bsdf::f(b, wo, wi);
                if f == Vec3::ZERO || !(ls.pdf > 0.0) {
                    continue;
                }
                let shadow = match ls.point {
                    Some(q) => spawn_ray_to(s.position, s.geometric_normal, q),
                    None => Some(spawn_ray_infinite(s.position, s.geometric_normal, ls.wi)),
                };
                if let Some(r) = shadow {
                    log.record(RayKind::Shadow, &r);
                    if self.tracer.occluded(&r) {
                        continue;
                    }
                }
                sum += f * ls.radiance * (wi.z.abs() / ls.pdf);
            }
            total += sum / n as f32;
        }
        total
    }

    /// CS184 `estimate_direct_lighting_hemisphere`: uniform directions on the hemisphere of
    /// `wo`, each traced to whatever it hits, adding that surface's (or the environment's)
    /// emission.
    fn direct_hemisphere(
        &self,
        s: &SurfaceHit,
        b: &Bsdf,
        frame: &Frame,
        wo: Vec3,
        rng: &mut Rng,
        log: &mut RayLog,
    ) -> Vec3 {
        let n = self.hemisphere_samples;
        if n == 0 {
            return Vec3::ZERO;
        }
        let mut sum = Vec3::ZERO;
        for _ in 0..n {
            let mut wi = uniform_hemisphere(rng.next_2d());
            wi.z = wi.z.copysign(wo.z);
            let f = bsdf::f(b, wo, wi);
            if f == Vec3::ZERO {
                continue;
            }
            let dir = frame.to_world(wi);
            let r = spawn_ray(s.position, s.geometric_normal, dir);
            log.record(RayKind::Bounce, &r);
            let h = self.tracer.closest(&r);
            let le = if h.is_hit() {
                self.lights.emitted(h.prim, self.material(h.prim).emission, dir)
            } else {
                self.lights.environment
            };
            sum += f * le * (wi.z.abs() / UNIFORM_HEMISPHERE_PDF);
        }
        sum / n as f32
    }
}
