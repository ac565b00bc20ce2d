//! Integrators: the radiance a camera ray brings back (CS184 parts 3–4; pbrt-v4's
//! `PathIntegrator` without multiple importance sampling).
//!
//! A path advances one bounce at a time, in two steps the wavefront ([`super::wavefront`])
//! takes for each path of a batch in turn: [`Integrator::shade`] and [`Integrator::scatter`]
//! (for diffuse hits under light sampling, eight paths at a time in SIMD lanes with the same
//! results: [`Integrator::shade_lanes`], module `lanes`);
//! the rays they ask for are traced after the whole batch's bounce, many paths' at once. At each non-specular
//! hit, direct lighting is estimated either by sampling the lights (`-l` samples per area
//! light, one per delta light) and tracing shadow rays, or (`-H`) by tracing uniformly
//! distributed hemisphere rays and adding the emission they find (as many as light sampling
//! would trace). The path then continues in a direction drawn from the BSDF. Emission met by the continuation is counted only right after the
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
use super::queue::{DirectQueue, DirectSample};
use super::sampler::Sampler;
use super::sampling::{UNIFORM_HEMISPHERE_PDF, uniform_hemisphere};
use super::spawn::{spawn_ray, spawn_ray_infinite, spawn_ray_to};
use super::trace::Tracer;
use super::{Encoding, RenderSettings};
use crate::math::Vec3;
use crate::ray::{Hit, Ray};
use crate::scene::{Bsdf, Material, Scene, SurfaceHit};
use crate::simd::{F32x1, Lanes, Vec3x};

mod lane_direct;
mod lane_step;
mod lanes;
pub use lane_step::SampleLanes;
pub use lanes::{Entries, LaneLights, STEP};

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
    /// Not radiance: the traversal cost per pixel, a picture of the BVH kernel's work for one
    /// ray per pixel ([`super::heatmap`]; what it shows: [`super::RenderSettings::heatmap`]).
    Heatmap,
}

impl IntegratorKind {
    /// Every integrator.
    pub const ALL: [IntegratorKind; 7] = [
        IntegratorKind::Normals,
        IntegratorKind::Direct,
        IntegratorKind::Global,
        IntegratorKind::DirectOnly,
        IntegratorKind::IndirectOnly,
        IntegratorKind::Bounce,
        IntegratorKind::Heatmap,
    ];

    /// The name `--integrator` and Python's `integrator=` take (`direct-only`, …), which
    /// [`str::parse`] reads back.
    pub fn name(&self) -> &'static str {
        match self {
            IntegratorKind::Normals => "normals",
            IntegratorKind::Direct => "direct",
            IntegratorKind::Global => "global",
            IntegratorKind::DirectOnly => "direct-only",
            IntegratorKind::IndirectOnly => "indirect-only",
            IntegratorKind::Bounce => "bounce",
            IntegratorKind::Heatmap => "heatmap",
        }
    }

    /// What the integrator computes, in a line (the CLI's help for each choice).
    pub fn description(&self) -> &'static str {
        match self {
            IntegratorKind::Normals => "Shading normals as colours (CS184 parts 1-2)",
            IntegratorKind::Direct => "Emission plus direct lighting (CS184 part 3): bounces 0 and 1",
            IntegratorKind::Global => "Global illumination up to -m bounces (CS184 part 4)",
            IntegratorKind::DirectOnly => "Only direct lighting: bounce 1",
            IntegratorKind::IndirectOnly => "Only indirect lighting: bounces 2 to -m",
            IntegratorKind::Bounce => "Exactly -m bounces",
            IntegratorKind::Heatmap => {
                "Traversal cost per pixel: the BVH kernel's node visits or primitive tests for one ray per pixel \
                 (--heatmap, --heatmap-rays), coloured with viridis and a labelled colour bar"
            }
        }
    }

    /// The integrator of [`IntegratorKind::name`] (exactly that name).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// How the film of this integrator is encoded to 8 bits.
    pub fn encoding(&self) -> Encoding {
        match self {
            IntegratorKind::Normals | IntegratorKind::Heatmap => Encoding::Display,
            _ => Encoding::Srgb,
        }
    }

    /// The inclusive range of bounces counted with maximum depth `max_depth`; `None` for
    /// [`IntegratorKind::Normals`] and [`IntegratorKind::Heatmap`]. The range may be empty
    /// (`lo > hi`).
    pub fn bounces(&self, max_depth: u32) -> Option<(u32, u32)> {
        match self {
            IntegratorKind::Normals | IntegratorKind::Heatmap => None,
            IntegratorKind::Direct => Some((0, 1)),
            IntegratorKind::Global => Some((0, max_depth)),
            IntegratorKind::DirectOnly => Some((1, 1)),
            IntegratorKind::IndirectOnly => Some((2, max_depth)),
            IntegratorKind::Bounce => Some((max_depth, max_depth)),
        }
    }
}

impl std::fmt::Display for IntegratorKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is no integrator's ([`IntegratorKind`]'s `FromStr`).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown integrator '{0}': expected {choices}", choices = IntegratorKind::choices())]
pub struct UnknownIntegrator(pub String);

impl IntegratorKind {
    /// The names, quoted and listed: `'normals', 'direct', … or 'heatmap'`.
    fn choices() -> String {
        let names: Vec<String> = Self::ALL.iter().map(|k| format!("'{}'", k.name())).collect();
        format!("{} or {}", names[..names.len() - 1].join(", "), names[names.len() - 1])
    }
}

impl std::str::FromStr for IntegratorKind {
    type Err = UnknownIntegrator;
    /// [`IntegratorKind::name`], in any case, with `_` for `-` (`direct_only`) and spaces
    /// around it allowed.
    fn from_str(s: &str) -> Result<Self, UnknownIntegrator> {
        let name = s.trim().to_ascii_lowercase().replace('_', "-");
        Self::from_name(&name).ok_or_else(|| UnknownIntegrator(s.to_string()))
    }
}

/// Russian roulette starts at this many bounces.
const ROULETTE_START: u32 = 2;

/// The throughput arithmetic of a path that scatters, over lanes (one path's on [`F32x1`],
/// eight in [`Integrator::shade_lanes`]): `beta * weight`; of the lanes of `goes`, those whose
/// product is zero end, and those of `plays` (their depth reached [`ROULETTE_START`]) with
/// `q = max(beta * eta_scale) < 1` play Russian roulette ([`Roulette::draws`]: draw their
/// uniforms, then [`Roulette::end`]).
#[inline(always)]
pub(super) fn throughput<V: Lanes>(beta: Vec3x<V>, weight: Vec3x<V>, eta_scale: V, goes: V, plays: V) -> Roulette<V> {
    let zero = V::splat(0.0);
    // glam's `max_element`: `max(x, max(y, z))` with `a > b ? a : b`, which is `vmax`.
    let max_element = |v: &Vec3x<V>| v.x.vmax(v.y.vmax(v.z));
    let beta = Vec3x { x: beta.x * weight.x, y: beta.y * weight.y, z: beta.z * weight.z };
    let goes = goes & !max_element(&beta).le(zero);
    let q = max_element(&(beta * eta_scale));
    Roulette { beta, goes, q, draws: goes & plays & q.lt(V::splat(1.0)) }
}

/// Paths after [`throughput`], before their roulette.
pub(super) struct Roulette<V: Lanes> {
    beta: Vec3x<V>,
    goes: V,
    q: V,
    /// The lanes that play Russian roulette: they draw a uniform.
    pub(super) draws: V,
}

impl<V: Lanes> Roulette<V> {
    /// The throughput and the lanes that go on, given the uniforms `u` of the lanes of
    /// `draws` (others ignored): a lane whose uniform is `>= q` ends, the others go on with
    /// `beta / q`.
    #[inline(always)]
    pub(super) fn end(self, u: V) -> (Vec3x<V>, V) {
        let Roulette { beta, goes, q, draws } = self;
        if draws.bitmask() == 0 {
            return (beta, goes);
        }
        (Vec3x::select(draws, beta / q, beta), goes & !(draws & u.ge(q)))
    }
}

/// The direct-lighting group of uniform hemisphere samples (`-H`); light sampling's groups
/// are the lights' indices.
pub const HEMISPHERE: u32 = u32::MAX;

/// Where a path scatters at a surface: the shading frame there and the direction toward
/// where the path came from, in that frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scatter {
    /// Shading frame (`z`: the shading normal).
    pub frame: Frame,
    /// Unit direction back along the incoming ray, local to `frame`.
    pub wo: Vec3,
}

/// A path between two bounces: the light it has gathered and what it carries on.
#[derive(Clone, Debug)]
pub struct PathState {
    /// Radiance gathered so far.
    pub l: Vec3,
    /// Throughput: what light arriving along the path's next ray is multiplied by.
    pub beta: Vec3,
    /// Product of the radiance scalings of the interfaces crossed (pbrt's `etaScale`).
    pub eta_scale: f32,
    /// Scattering events so far.
    pub depth: u32,
    /// True after the camera or a specular bounce: emission met next is counted.
    pub sees_emission: bool,
    /// The path's own random numbers.
    pub rng: Sampler,
}

impl PathState {
    /// A path leaving the camera, drawing from `rng`.
    #[inline]
    pub fn new(rng: Sampler) -> Self {
        Self { l: Vec3::ZERO, beta: Vec3::ONE, eta_scale: 1.0, depth: 0, sees_emission: true, rng }
    }
}

/// An integrator bound to a scene and settings.
pub struct Integrator<'a> {
    scene: &'a Scene,
    settings: &'a RenderSettings,
    tracer: Tracer<'a>,
    lights: LightSet,
    bounces: Option<(u32, u32)>,
    /// Hemisphere rays per shading point under `-H`: the shadow rays light sampling would use.
    hemisphere_samples: u32,
    /// The lights as the lanes sample them ([`Integrator::shade_lanes`]); `None` when the
    /// lanes cannot shade for this integrator.
    lane_lights: Option<LaneLights>,
}

impl<'a> Integrator<'a> {
    /// Prepares the integrator (and the scene's lights for sampling).
    pub fn new(scene: &'a Scene, settings: &'a RenderSettings) -> Self {
        let lights = LightSet::new(scene);
        let hemisphere_samples = lights.lights.iter().map(|l| l.samples_per_point(settings.light_samples)).sum();
        let bounces = settings.integrator.bounces(settings.max_depth);
        let lane_lights = match bounces {
            Some(_) if !settings.hemisphere_sampling => Some(LaneLights::new(&lights.lights, settings.light_samples)),
            _ => None,
        };
        Self {
            scene,
            settings,
            tracer: Tracer::new(scene, settings.brute_force),
            lights,
            bounces,
            hemisphere_samples,
            lane_lights,
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

    /// The range of bounces counted, `None` for [`IntegratorKind::Normals`].
    pub fn bounces(&self) -> Option<(u32, u32)> {
        self.bounces
    }

    /// Most direct-lighting samples (so shadow or hemisphere rays) one shading point queues.
    pub fn direct_samples_per_point(&self) -> u32 {
        self.hemisphere_samples
    }

    /// True when direct lighting traces uniform hemisphere rays (`-H`) rather than shadow rays.
    pub fn hemisphere_sampling(&self) -> bool {
        self.settings.hemisphere_sampling
    }

    /// True when camera rays start paths to [`Integrator::shade`]; false when the camera ray's
    /// hit alone decides ([`Integrator::camera_only`]).
    pub fn traces_paths(&self) -> bool {
        matches!(self.bounces, Some((lo, hi)) if lo <= hi)
    }

    /// The value of a camera sample whose ray hits nothing: the environment's radiance when
    /// the integrator counts the emission a camera ray sees, black otherwise — what
    /// [`Integrator::shade`] (or [`Integrator::camera_only`]) gives a camera ray's miss, bit
    /// for bit. It does not depend on the ray (the environment is uniform).
    pub fn camera_miss(&self) -> Vec3 {
        match self.bounces {
            // Bounce 0 counted (`hi >= 0` always): a fresh path's `l + beta * environment`.
            Some((0, _)) => Vec3::ZERO + Vec3::ONE * self.lights.environment,
            _ => Vec3::ZERO,
        }
    }

    /// The value of camera ray `ray` with closest hit `hit` when no path is traced from it:
    /// the normal map for [`IntegratorKind::Normals`], black when no bounce is counted.
    pub fn camera_only(&self, ray: &Ray, hit: &Hit) -> Vec3 {
        if self.bounces.is_none() && hit.is_hit() {
            self.scene.surface(ray, hit).shading_normal * 0.5 + 0.5
        } else {
            Vec3::ZERO
        }
    }

    /// The first half of one step of `path`, whose last ray `ray` found `hit`: adds the
    /// emission seen there and queues the hit's direct-lighting samples in `direct` (traced and
    /// added later: [`Integrator::direct_total`]). Returns where the path scatters next, or
    /// `None` when it ends here. [`Integrator::scatter`] is the second half.
    ///
    /// `surface` is [`Scene::surface`] at `hit` (ignored for a miss): the wavefront computes it
    /// for a whole batch first, where the loads of many hits overlap. Random numbers are drawn
    /// from the path's own generator in a fixed order (light samples, then BSDF, then
    /// roulette), so a path's value does not depend on which paths are shaded with it.
    #[inline]
    pub fn shade(
        &self,
        path: &mut PathState,
        ray: &Ray,
        hit: &Hit,
        surface: &SurfaceHit,
        direct: &mut DirectQueue,
        id: u32,
    ) -> Option<Scatter> {
        let (lo, hi) = self.bounces?;
        let counted = |k: u32| lo <= k && k <= hi;
        if !hit.is_hit() {
            if path.sees_emission && counted(path.depth) {
                path.l += path.beta * self.lights.environment;
            }
            return None;
        }
        let s = surface;
        let mat = &self.scene.materials[s.material as usize];
        if path.sees_emission && counted(path.depth) {
            path.l += path.beta * self.lights.emitted(hit.prim, mat.emission, ray.dir);
        }
        let delta = bsdf::is_delta(&mat.bsdf);
        let frame = Frame::from_normal(s.shading_normal);
        let wo = frame.to_local(-ray.dir);
        // Direct lighting here is light with one more bounce.
        if !delta && counted(path.depth + 1) && wo.z != 0.0 {
            direct.begin(id, path.beta);
            if self.settings.hemisphere_sampling {
                self.queue_hemisphere(s, &mat.bsdf, &frame, wo, &mut path.rng, direct);
            } else {
                self.queue_lights(s, &mat.bsdf, &frame, wo, &mut path.rng, direct);
            }
        }
        // The continuation only brings light with at least this many bounces.
        let next = if delta { path.depth + 1 } else { path.depth + 2 };
        (next <= hi).then_some(Scatter { frame, wo })
    }

    /// The second half of a step ([`Integrator::shade`]): samples the BSDF at `surface` and
    /// plays Russian roulette. Returns the continuation ray, or `None` when the path ends.
    #[inline]
    pub fn scatter(&self, path: &mut PathState, surface: &SurfaceHit, at: &Scatter) -> Option<Ray> {
        let (s, Scatter { frame, wo }) = (surface, *at);
        let rng = &mut path.rng;
        let bsdf = &self.scene.materials[s.material as usize].bsdf;
        let bs = bsdf::sample_f(bsdf, wo, rng.next_2d(), rng.next_f32())?;
        if !self.continue_path(path, bs.weight, bs.eta_scale, bs.delta) {
            return None;
        }
        Some(spawn_ray(s.position, s.geometric_normal, frame.to_world(bs.wi)))
    }

    /// The end of a scattering step once the BSDF sample (weight `weight`, radiance scaling
    /// `eta_scale`, `delta` for a specular lobe) is drawn: multiplies `path`'s throughput,
    /// counts the bounce and plays Russian roulette. False when the path ends here.
    #[inline]
    fn continue_path(&self, path: &mut PathState, weight: Vec3, eta_scale: f32, delta: bool) -> bool {
        path.eta_scale *= eta_scale;
        let plays = self.settings.russian_roulette && path.depth + 1 >= ROULETTE_START;
        let lane = |b: bool| F32x1::from_bitmask(b as u32);
        let r = throughput(path.beta.into(), weight.into(), F32x1::splat(path.eta_scale), lane(true), lane(plays));
        let u = if r.draws.bitmask() != 0 { path.rng.next_f32() } else { 0.0 };
        let (beta, goes) = r.end(F32x1::splat(u));
        path.beta = beta.into();
        if goes.bitmask() == 0 {
            return false;
        }
        path.depth += 1;
        path.sees_emission = delta;
        true
    }

    /// The direct lighting of one shading point from its samples `samples`, in the order
    /// [`Integrator::shade`] queued them, once their rays are answered: each light's (or the
    /// hemisphere's) visible samples summed and divided by its sample count, summed over lights.
    #[inline]
    pub fn direct_total(&self, samples: &[DirectSample]) -> Vec3 {
        let mut total = Vec3::ZERO;
        let mut i = 0;
        while i < samples.len() {
            let group = samples[i].group;
            let mut sum = Vec3::ZERO;
            while i < samples.len() && samples[i].group == group {
                let d = &samples[i];
                if d.visible {
                    sum += d.f * d.radiance * d.scale;
                }
                i += 1;
            }
            total += sum / self.group_samples(group) as f32;
        }
        total
    }

    /// Radiance a hemisphere ray of direction `dir` brings from its closest hit `hit`.
    #[inline]
    pub fn probe_radiance(&self, hit: &Hit, dir: Vec3) -> Vec3 {
        if hit.is_hit() {
            self.lights.emitted(hit.prim, self.material(hit.prim).emission, dir)
        } else {
            self.lights.environment
        }
    }

    /// Samples per shading point of direct-lighting group `group` (a light's index, or
    /// [`HEMISPHERE`]).
    #[inline]
    fn group_samples(&self, group: u32) -> u32 {
        match self.lights.lights.get(group as usize) {
            Some(l) => l.samples_per_point(self.settings.light_samples),
            None => self.hemisphere_samples,
        }
    }

    #[inline]
    fn material(&self, prim: u32) -> &'a Material {
        let nt = self.scene.triangles.len();
        let p = prim as usize;
        let id = if p < nt { self.scene.triangles.material[p] } else { self.scene.spheres.material[p - nt] };
        &self.scene.materials[id as usize]
    }

    /// CS184 `estimate_direct_lighting_importance`: `-l` samples of each area light, one of
    /// each delta light, each with a shadow ray (none when the light touches the point).
    #[inline]
    fn queue_lights(
        &self,
        s: &SurfaceHit,
        b: &Bsdf,
        frame: &Frame,
        wo: Vec3,
        rng: &mut Sampler,
        out: &mut DirectQueue,
    ) {
        for (group, light) in self.lights.lights.iter().enumerate() {
            for _ in 0..light.samples_per_point(self.settings.light_samples) {
                self.queue_light_sample(light, group as u32, s, b, frame, wo, rng.next_2d(), out);
            }
        }
    }

    /// One sample of `light` (group `group`) at `s` with the uniforms `u`, queued in `out`
    /// when it carries light.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn queue_light_sample(
        &self,
        light: &SampledLight,
        group: u32,
        s: &SurfaceHit,
        b: &Bsdf,
        frame: &Frame,
        wo: Vec3,
        u: (f32, f32),
        out: &mut DirectQueue,
    ) {
        let ctx = LightContext { p: s.position, n: frame.z * wo.z.signum() };
        let Some(ls) = light.sample(self.scene, &ctx, u) else { return };
        let wi = frame.to_local(ls.wi);
        let f = bsdf::f(b, wo, wi);
        if f == Vec3::ZERO || !(ls.pdf > 0.0) {
            return;
        }
        let shadow = match ls.point {
            Some(q) => spawn_ray_to(s.position, s.geometric_normal, q),
            None => Some(spawn_ray_infinite(s.position, s.geometric_normal, ls.wi)),
        };
        let sample = DirectSample { f, radiance: ls.radiance, scale: wi.z.abs() / ls.pdf, group, visible: true };
        out.push_light(sample, shadow);
    }

    /// CS184 `estimate_direct_lighting_hemisphere`: uniform directions on the hemisphere of
    /// `wo`, each traced to whatever it hits, whose (or the environment's) emission it brings.
    fn queue_hemisphere(
        &self,
        s: &SurfaceHit,
        b: &Bsdf,
        frame: &Frame,
        wo: Vec3,
        rng: &mut Sampler,
        out: &mut DirectQueue,
    ) {
        for _ in 0..self.hemisphere_samples {
            let mut wi = uniform_hemisphere(rng.next_2d());
            wi.z = wi.z.copysign(wo.z);
            let f = bsdf::f(b, wo, wi);
            if f == Vec3::ZERO {
                continue;
            }
            let ray = spawn_ray(s.position, s.geometric_normal, frame.to_world(wi));
            let scale = wi.z.abs() / UNIFORM_HEMISPHERE_PDF;
            out.push_probe(DirectSample { f, radiance: Vec3::ZERO, scale, group: HEMISPHERE, visible: true }, ray);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_unknown_names_list_the_choices() {
        for kind in IntegratorKind::ALL {
            assert_eq!(kind.name().parse::<IntegratorKind>(), Ok(kind));
            assert_eq!(kind.to_string(), kind.name());
            assert_eq!(IntegratorKind::from_name(kind.name()), Some(kind));
        }
        assert_eq!(" Direct_Only ".parse::<IntegratorKind>(), Ok(IntegratorKind::DirectOnly));
        let err = "photons".parse::<IntegratorKind>().unwrap_err();
        assert_eq!(
            err.to_string(),
            "unknown integrator 'photons': expected 'normals', 'direct', 'global', 'direct-only', 'indirect-only', \
             'bounce' or 'heatmap'"
        );
    }
}
