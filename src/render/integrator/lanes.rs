//! Shading eight paths at a time: [`Integrator::shade`] and [`Integrator::scatter`] for the
//! common case, a diffuse surface under light sampling, with the arithmetic in SIMD lanes on
//! the scene's ISA (dispatched as the tracing kernels are). The lanes call the one-path code's
//! own functions, written once over [`crate::simd::Lanes`] (the one-path code runs them on one lane,
//! [`crate::simd::F32x1`]): `concentric_disk_lanes`, `orthonormal_basis_lanes`, `toward_lanes`,
//! `offset_origin_lanes`, `spawn_ray_to_lanes` and [`SampledLight::sample_lanes`] (rectangle
//! and point lights; other kinds are sampled one path at a time with the uniforms drawn for
//! them). Every path's radiance, random numbers, direct samples and rays are therefore
//! bit-identical to shading it alone (unit test on every ISA, and the same images).
//!
//! What stays one path at a time: reading its state into rows, its emission, drawing its
//! random numbers when they are not Sobol' (each path has its own generator, drawn in the order
//! of the one-path code: light samples, BSDF sample, roulette), and queueing its shadow rays and
//! continuation ray. The lanes compute the shading frame, the light samples and their shadow
//! rays, the cosine-weighted bounce direction and the continuation's origin. The surfaces come
//! in rows ([`SurfaceRows`]); when every light is sampled in the lanes, the step's direct
//! samples stay in rows too ([`LanePoints`], [`LaneSample`]) and their sum is taken in lanes
//! after the shadow rays are traced ([`Integrator::add_direct_lanes`]).

//!
//! The pieces: this module reads and writes the paths around a step; `lane_step` is the
//! step's arithmetic on one ISA; `lane_direct` adds the rows of direct samples up after the
//! shadow rays are traced.

use super::lane_step::{SampleLanes, Step, StepRows};
use super::{Frame, Integrator, PathState, ROULETTE_START};
use crate::math::Vec3;
use crate::ray::{Hit, Ray};
use crate::render::light::SampledLight;
use crate::render::queue::{DirectQueue, DirectSample, LANE_OWNER, LanePoints, LaneSample, Rows};
use crate::render::sampler::SobolLanes;
use crate::scene::Bsdf;
use crate::scene::surface::SurfaceRows;
use crate::simd::isa::dispatch;
use std::f32::consts::FRAC_1_PI;

/// Paths per step.
pub use crate::render::queue::STEP;

/// The direct-lighting samples of one shading point, in the order light sampling draws them:
/// each light (its index is the sample's group) as many times as it is sampled. The kinds
/// [`SampledLight::in_lanes`] names are sampled in the lanes; the others one path at a time,
/// with the uniforms drawn for them in their place.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LaneLights {
    /// Each sample's light (its group), and whether the lanes sample it.
    pub(super) samples: Vec<(u32, bool)>,
    /// Each sample's group's samples per point ([`Integrator::direct_total`]'s divisor).
    pub(super) divisors: Vec<f32>,
    /// True when every sample is taken in the lanes.
    pub(super) all_lanes: bool,
}

impl LaneLights {
    /// The samples of `lights` with `per_area` samples of each area light.
    pub(super) fn new(lights: &[SampledLight], per_area: u32) -> Self {
        let (mut samples, mut divisors) = (Vec::new(), Vec::new());
        for (group, light) in lights.iter().enumerate() {
            let n = light.samples_per_point(per_area);
            samples.extend(std::iter::repeat_n((group as u32, light.in_lanes()), n as usize));
            divisors.extend(std::iter::repeat_n(n as f32, n as usize));
        }
        let all_lanes = lights.iter().all(SampledLight::in_lanes);
        Self { samples, divisors, all_lanes }
    }

    /// Samples per shading point.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// True when there is no light to sample.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }
}

/// A wave's entries to shade: entry `k` is ray `rays[k]` of path `owner[k]`, which found
/// `hits[k]` at lane `k % STEP` of `surfaces[k / STEP]`; `alive[k]` is set when its path goes
/// on (its continuation then replaces `rays[k]`).
pub struct Entries<'w> {
    /// Every path of the batch.
    pub paths: &'w mut [PathState],
    /// The rays shaded, replaced by continuations.
    pub rays: &'w mut [Ray],
    /// Their owners.
    pub owner: &'w [u32],
    /// Their closest hits.
    pub hits: &'w [Hit],
    /// The surfaces at the hits, in rows of [`STEP`].
    pub surfaces: &'w [SurfaceRows],
    /// Whether each entry's path goes on.
    pub alive: &'w mut [bool],
}

impl Integrator<'_> {
    /// The entries `k0 + j` of `e` that the lanes can shade (`j < 8`, `k0 + j` in range): a
    /// hit on a diffuse surface, when the integrator samples its lights through the lanes.
    #[inline]
    pub fn lane_entries(&self, e: &Entries<'_>, k0: usize) -> u32 {
        if self.lane_lights.is_none() {
            return 0;
        }
        let mut mask = 0;
        let surfaces = &e.surfaces[k0 / STEP];
        for (j, k) in (k0..e.hits.len().min(k0 + STEP)).enumerate() {
            let diffuse = matches!(self.scene.materials[surfaces.material[j] as usize].bsdf, Bsdf::Diffuse { .. });
            mask |= ((e.hits[k].is_hit() && diffuse) as u32) << j;
        }
        mask
    }

    /// [`Integrator::shade`] then [`Integrator::scatter`] of the entries `k0 + j` of `e` for
    /// the bits `j` of `mask` (from [`Integrator::lane_entries`]), with the same results bit
    /// for bit; their direct samples go to `direct` in the order of the entries. `scratch`
    /// is reused from step to step.
    pub fn shade_lanes(
        &self,
        e: &mut Entries<'_>,
        k0: usize,
        mask: u32,
        direct: &mut DirectQueue,
        scratch: &mut Vec<SampleLanes>,
    ) {
        let Some(lights) = &self.lane_lights else { return };
        let Some((lo, hi)) = self.bounces else { return };
        let counted = |k: u32| lo <= k && k <= hi;
        scratch.resize(lights.len(), SampleLanes::default());
        let mut rows = StepRows::default();
        let mut albedos = [Vec3::ZERO; STEP];
        // The lanes of Sobol' paths draw their numbers together in the step; the others here.
        let mut sobol = SobolLanes::default();
        let mut sobol_lanes = 0;
        let surfaces = &e.surfaces[k0 / STEP];
        for j in crate::simd::bits(mask) {
            let k = k0 + j;
            let (ray, hit) = (&e.rays[k], &e.hits[k]);
            let path = &mut e.paths[e.owner[k] as usize];
            let mat = &self.scene.materials[surfaces.material[j] as usize];
            let Bsdf::Diffuse { albedo } = mat.bsdf else { unreachable!("lane_entries takes diffuse hits only") };
            if path.sees_emission && counted(path.depth) {
                path.l += path.beta * self.lights.emitted(hit.prim, mat.emission, ray.dir);
            }
            // `Frame::to_local(-ray.dir).z`.
            let ns = &surfaces.shading_normal;
            let wo_z = (-ray.dir).dot(Vec3::new(ns[0][j], ns[1][j], ns[2][j]));
            let in_sobol = sobol.load(j, &path.rng);
            sobol_lanes |= (in_sobol as u32) << j;
            if counted(path.depth + 1) && wo_z != 0.0 {
                rows.direct |= 1 << j;
                for sample in scratch.iter_mut().filter(|_| !in_sobol) {
                    (sample.u[0][j], sample.u[1][j]) = path.rng.next_2d();
                }
            }
            if path.depth + 2 <= hi {
                rows.scatter |= 1 << j;
                if !in_sobol {
                    (rows.u[0][j], rows.u[1][j]) = path.rng.next_2d();
                    // The lobe choice, which a diffuse BSDF draws and does not use.
                    path.rng.next_f32();
                }
            }
            albedos[j] = albedo;
            rows.reflects |= ((albedo * FRAC_1_PI != Vec3::ZERO) as u32) << j;
            rows.roulette |= ((self.settings.russian_roulette && path.depth + 1 >= ROULETTE_START) as u32) << j;
            rows.eta_scale[j] = path.eta_scale;
            for (r, v) in [(&mut rows.beta, path.beta), (&mut rows.albedo, albedo)] {
                (r[0][j], r[1][j], r[2][j]) = (v.x, v.y, v.z);
            }
            rows.wo_z[j] = wo_z;
        }
        (rows.p, rows.ng, rows.ns) = (surfaces.position, surfaces.geometric_normal, surfaces.shading_normal);
        // With every path's numbers in the lanes, the lanes end the step too.
        let finish = sobol_lanes == mask;
        // The throughput at the points, before the lanes' Russian roulette changes it.
        let weight = rows.beta;
        let step = Step {
            rows: &mut rows,
            lights: &self.lights.lights,
            groups: &lights.samples,
            samples: scratch,
            sobol: &mut sobol,
            sobol_lanes,
            finish,
        };
        dispatch(self.scene.isa(), step);
        // With every light sampled in the lanes, the points' samples stay in rows.
        let in_rows = lights.all_lanes && rows.direct != 0;
        let first_row = direct.lane_samples.len();
        if in_rows {
            let mut path = [0; STEP];
            for j in crate::simd::bits(rows.direct) {
                path[j] = e.owner[k0 + j];
            }
            direct.lanes.push(LanePoints { path, mask: rows.direct, weight, start: first_row as u32 });
            let rows = scratch.iter().map(|s| LaneSample { value: s.value, kept: s.keep, visible: s.keep });
            direct.lane_samples.extend(rows);
        }
        let lane3 = |r: &Rows<3>, j: usize| Vec3::new(r[0][j], r[1][j], r[2][j]);
        for j in crate::simd::bits(mask) {
            let k = k0 + j;
            let id = e.owner[k];
            let path = &mut e.paths[id as usize];
            if sobol_lanes >> j & 1 != 0 {
                sobol.store(j, &mut path.rng);
            }
            let albedo = albedos[j];
            if in_rows && rows.direct >> j & 1 != 0 {
                for (i, sample) in scratch.iter().enumerate().filter(|(_, s)| s.shadow >> j & 1 != 0) {
                    let ray = Ray::segment(lane3(&sample.origin, j), lane3(&sample.dir, j), 0.0, sample.tfar[j]);
                    direct.shadow.push(ray, LANE_OWNER | ((first_row + i) * STEP + j) as u32);
                }
            } else if rows.direct >> j & 1 != 0 {
                direct.begin(id, path.beta);
                // The frame of the lights sampled one path at a time.
                let at = (!lights.all_lanes).then(|| {
                    let s = surfaces.get(j);
                    let frame = Frame::from_normal(s.shading_normal);
                    (s, frame, frame.to_local(-e.rays[k].dir))
                });
                for (sample, &(group, in_lanes)) in scratch.iter().zip(&lights.samples) {
                    if !in_lanes {
                        let light = &self.lights.lights[group as usize];
                        let (s, frame, wo) = at.as_ref().expect("a frame for the lights of other kinds");
                        let u = (sample.u[0][j], sample.u[1][j]);
                        let b = &Bsdf::Diffuse { albedo };
                        self.queue_light_sample(light, group, s, b, frame, *wo, u, direct);
                        continue;
                    }
                    if sample.keep >> j & 1 == 0 {
                        continue;
                    }
                    let radiance = lane3(&sample.radiance, j);
                    let shadow = (sample.shadow >> j & 1 != 0)
                        .then(|| Ray::segment(lane3(&sample.origin, j), lane3(&sample.dir, j), 0.0, sample.tfar[j]));
                    let f = albedo * FRAC_1_PI;
                    direct
                        .push_light(DirectSample { f, radiance, scale: sample.scale[j], group, visible: true }, shadow);
                }
            }
            // `Integrator::scatter` after `bsdf::sample_f` (weight `albedo`, not delta).
            let alive = if finish {
                let alive = rows.scatter >> j & 1 != 0;
                if alive {
                    // `continue_path`'s changes to a path that goes on.
                    path.beta = lane3(&rows.beta, j);
                    path.depth += 1;
                    path.sees_emission = false;
                }
                alive
            } else {
                rows.scatter >> j & 1 != 0 && self.continue_path(path, albedo, 1.0, false)
            };
            if alive {
                e.rays[k] = Ray::new(lane3(&rows.origin, j), lane3(&rows.dir, j));
            }
            e.alive[k] = alive;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampler::Rng;

    /// Whole batches through the wavefront with the lanes and without (every hit one path at
    /// a time): the same radiance bit for bit, in the built-in Cornell box (diffuse walls
    /// beside a mirror and a glass sphere, so steps mix lanes and single paths) lit by its
    /// area light and a point light, with and without an emissive triangle (sampled one path
    /// at a time; without it every light is sampled in the lanes and the points' direct
    /// lighting is added in rows), with several light samples, every integrator view, Russian
    /// roulette on and off, and both samplers (the Sobol' lanes draw their numbers together).
    #[test]
    fn wavefront_radiance_is_the_same_without_lanes() {
        for glow in [true, false] {
            radiance_is_the_same_without_lanes(glow);
        }
    }

    fn radiance_is_the_same_without_lanes(glow: bool) {
        use crate::render::sampler::{SamplerKind, SamplerSource};
        use crate::render::stats::RayLog;
        use crate::render::wavefront::{PhaseTimes, StreamOrder, Wavefront};
        use crate::render::{IntegratorKind, RenderSettings};
        let mut builder = crate::testing::cornell_box();
        let centre = builder.bounds().center();
        builder.add_light(crate::scene::Light::Point { position: centre + Vec3::Y * 0.3, intensity: Vec3::splat(0.4) });
        if glow {
            let glow = builder.add_material(crate::Material::emissive(Vec3::splat(2.0)));
            let tri = [Vec3::new(-0.3, -0.2, -0.98), Vec3::new(0.3, -0.2, -0.98), Vec3::new(0.0, 0.3, -0.98)];
            builder.add_mesh(&tri, &[[0, 1, 2]], glow).unwrap();
        }
        let (scene, _) = builder.commit(&crate::BuildOptions::default());
        let kinds =
            [IntegratorKind::Global, IntegratorKind::Direct, IntegratorKind::IndirectOnly, IntegratorKind::Bounce];
        for (case, kind) in kinds.into_iter().enumerate() {
            let settings = RenderSettings {
                integrator: kind,
                max_depth: 6,
                light_samples: 1 + case as u32 % 3,
                russian_roulette: case != 3,
                ..Default::default()
            };
            let radiance = |lanes: bool, sampler: SamplerKind| {
                let mut integrator = Integrator::new(&scene, &settings);
                let kinds =
                    integrator.lane_lights.as_ref().map(|l| l.samples.iter().map(|&(_, in_lanes)| in_lanes).collect());
                // The area light and the point light in the lanes, the emissive triangle not.
                assert_eq!(kinds.map(|k: Vec<bool>| (k.contains(&true), k.contains(&false))), Some((true, glow)));
                if !lanes {
                    integrator.lane_lights = None;
                }
                let mut wf = Wavefront::new();
                wf.reserve(3000, &integrator);
                let mut dirs = Rng::new(case as u64, 1);
                let source = SamplerSource::new(sampler, 7);
                wf.push_samples((0..3000).map(|i| source.sampler(i / 16, i as u32 % 16)));
                wf.set_camera_rays(|rays| {
                    rays.extend((0..3000).map(|_| {
                        let d = Vec3::new(dirs.next_f32() - 0.5, dirs.next_f32() - 0.5, dirs.next_f32() - 0.5);
                        Ray::new(centre, d)
                    }))
                });
                let (mut log, mut times) = (RayLog::default(), PhaseTimes::default());
                wf.run(&integrator, StreamOrder::default(), &mut log, &mut times);
                wf.radiance().map(|l| l.to_array().map(f32::to_bits)).collect::<Vec<_>>()
            };
            for sampler in SamplerKind::ALL {
                let (with, without) = (radiance(true, sampler), radiance(false, sampler));
                assert!(with.iter().filter(|l| **l != [0; 3]).count() > 300, "{kind:?}: many paths bring light");
                assert_eq!(with, without, "{kind:?}, {sampler} sampler, glow {glow}");
            }
        }
    }
}
