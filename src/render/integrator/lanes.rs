//! Shading eight paths at a time: [`Integrator::shade`] and [`Integrator::scatter`] for the
//! common case, a diffuse surface under light sampling, with the arithmetic in SIMD lanes on
//! the scene's ISA (dispatched as the tracing kernels are). The lanes call the one-path code's
//! own functions, written once over [`Lanes`] (the one-path code runs them on one lane,
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

use super::{Frame, Integrator, PathState, ROULETTE_START, throughput};
use crate::math::Vec3;
use crate::math::orthonormal_basis_lanes;
use crate::ray::{Hit, Ray};
use crate::render::light::SampledLight;
use crate::render::queue::{DirectQueue, DirectSample, LANE_OWNER, LanePoints, LaneSample, Rows};
use crate::render::sampler::SobolLanes;
use crate::render::sampling::concentric_disk_lanes;
use crate::render::spawn::{offset_origin_lanes, spawn_ray_to_lanes, toward_lanes};
use crate::scene::Bsdf;
use crate::scene::surface::SurfaceRows;
use crate::simd::isa::{IsaOp, dispatch};
use crate::simd::{IsaLanes, Lanes, Vec3x};
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
    samples: Vec<(u32, bool)>,
    /// Each sample's group's samples per point ([`Integrator::direct_total`]'s divisor).
    divisors: Vec<f32>,
    /// True when every sample is taken in the lanes.
    all_lanes: bool,
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

/// One direct-lighting sample of a step's eight points: its uniforms, and what the lanes
/// made of them.
#[derive(Clone, Copy, Debug, Default)]
pub struct SampleLanes {
    /// The two uniforms of each lane.
    u: Rows<2>,
    /// Lanes whose sample is queued (it carries light).
    keep: u32,
    /// Lanes whose sample has a shadow ray (the others touch the light: always visible).
    shadow: u32,
    /// Shadow ray origin, unit direction and end.
    origin: Rows<3>,
    dir: Rows<3>,
    tfar: [f32; STEP],
    /// `|cos θ| / pdf`.
    scale: [f32; STEP],
    /// Radiance arriving from the sample (point lights: `I / r²`).
    radiance: Rows<3>,
    /// What the sample adds if visible: `f · radiance · scale` ([`Integrator::direct_total`]).
    value: Rows<3>,
}

/// The rows of one step: what is read from the paths, and the continuation computed.
#[derive(Clone, Copy, Debug, Default)]
struct StepRows {
    /// Hit point, geometric normal, shading normal.
    p: Rows<3>,
    ng: Rows<3>,
    ns: Rows<3>,
    /// `z` of the direction back along the incoming ray, in the shading frame.
    wo_z: [f32; STEP],
    /// Uniforms of the BSDF sample.
    u: Rows<2>,
    /// Lanes that gather direct lighting.
    direct: u32,
    /// Lanes whose BSDF is not black (`albedo / π != 0`).
    reflects: u32,
    /// Lanes that scatter (in: the path goes on if its sample does; out: it does).
    scatter: u32,
    /// The continuation's origin and unit direction.
    origin: Rows<3>,
    dir: Rows<3>,
    /// Filled when the lanes end the step ([`finish_step`]): the paths' throughput (in: before
    /// the bounce; out: after the BSDF sample and Russian roulette), their albedo and radiance
    /// scaling, and the lanes whose path plays Russian roulette if it goes on.
    beta: Rows<3>,
    albedo: Rows<3>,
    eta_scale: [f32; STEP],
    roulette: u32,
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

impl Integrator<'_> {
    /// Adds the direct lighting of the lane points of `d` (their shadow rays traced) to their
    /// paths: per lane, [`Integrator::direct_total`] of its samples times its weight, the same
    /// sums bit for bit.
    pub fn add_direct_lanes(&self, d: &DirectQueue, paths: &mut [PathState]) {
        let Some(lights) = &self.lane_lights else { return };
        if d.lanes.is_empty() {
            return;
        }
        dispatch(self.scene.isa(), DirectLanes { d, paths, groups: &lights.samples, divisors: &lights.divisors });
    }
}

/// Direct lighting added in lanes, run on one ISA.
struct DirectLanes<'a> {
    d: &'a DirectQueue,
    paths: &'a mut [PathState],
    /// Each sample row's light (its group) and that group's samples per point.
    groups: &'a [(u32, bool)],
    divisors: &'a [f32],
}

impl IsaOp for DirectLanes<'_> {
    type Output = ();
    #[inline(always)]
    fn run<I: IsaLanes>(self) {
        for (i, points) in self.d.lanes.iter().enumerate() {
            let add = direct_lanes::<I::F8>(points, self.d.lane_samples_of(i), self.groups, self.divisors);
            for j in crate::simd::bits(points.mask) {
                self.paths[points.path[j] as usize].l += add.lane(j);
            }
        }
    }
}

/// `weight · direct_total(samples)` of each lane of `points`: each group's visible values
/// summed in draw order and divided by its divisor, where the lane queued any sample of it.
#[inline(always)]
fn direct_lanes<V: Lanes>(
    points: &LanePoints,
    rows: &[LaneSample],
    groups: &[(u32, bool)],
    divisors: &[f32],
) -> Vec3x<V> {
    let zero = Vec3x::<V>::splat(Vec3::ZERO);
    let mut total = zero;
    let mut i = 0;
    while i < rows.len() {
        let group = groups[i].0;
        let (mut sum, mut queued) = (zero, 0);
        let divisor = V::splat(divisors[i]);
        while i < rows.len() && groups[i].0 == group {
            let r = &rows[i];
            sum = Vec3x::select(V::from_bitmask(r.visible), sum + Vec3x::load_rows(&r.value), sum);
            queued |= r.kept;
            i += 1;
        }
        total = Vec3x::select(V::from_bitmask(queued), total + sum / divisor, total);
    }
    let w = Vec3x::<V>::load_rows(&points.weight);
    Vec3x { x: w.x * total.x, y: w.y * total.y, z: w.z * total.z }
}

/// The lanes' part of a step, run on one ISA.
struct Step<'a> {
    rows: &'a mut StepRows,
    /// The integrator's lights, and each sample's light (and whether the lanes sample it).
    lights: &'a [SampledLight],
    groups: &'a [(u32, bool)],
    samples: &'a mut [SampleLanes],
    /// The lanes (bits of `sobol_lanes`) whose uniforms `sobol` draws here, in the one-path
    /// order: each light sample, the BSDF sample, the unused lobe choice.
    sobol: &'a mut SobolLanes,
    sobol_lanes: u32,
    /// Whether the lanes end the step ([`finish_step`]; every lane's numbers are in `sobol`).
    finish: bool,
}

impl IsaOp for Step<'_> {
    type Output = ();
    #[inline(always)]
    fn run<I: IsaLanes>(self) {
        if self.sobol_lanes != 0 {
            let direct = self.rows.direct & self.sobol_lanes;
            if direct != 0 {
                for s in self.samples.iter_mut() {
                    self.sobol.next_2d(direct, &mut s.u);
                }
            }
            let scatter = self.rows.scatter & self.sobol_lanes;
            self.sobol.next_2d(scatter, &mut self.rows.u);
            self.sobol.skip(scatter);
        }
        step::<I::F8>(self.rows, self.lights, self.groups, self.samples);
        if self.finish {
            finish_step::<I::F8>(self.rows, self.sobol);
        }
    }
}

/// `Integrator::continue_path` of the lanes of `rows.scatter` (weight `albedo`, radiance
/// scaling 1, not delta; [`throughput`]), the roulette's uniforms drawn by `sobol`:
/// `rows.beta` becomes the throughput after it and `rows.scatter` keeps the lanes that go on.
#[inline(always)]
fn finish_step<V: Lanes>(rows: &mut StepRows, sobol: &mut SobolLanes) {
    let r = throughput(
        Vec3x::<V>::load_rows(&rows.beta),
        Vec3x::load_rows(&rows.albedo),
        // `eta_scale * 1.0` is `eta_scale`.
        V::load(&rows.eta_scale),
        V::from_bitmask(rows.scatter),
        V::from_bitmask(rows.roulette),
    );
    let mut u = [0.0f32; STEP];
    let draws = r.draws.bitmask();
    if draws != 0 {
        sobol.next_1d(draws, &mut u);
    }
    let (beta, goes) = r.end(V::load(&u));
    beta.store_rows(&mut rows.beta);
    rows.scatter = goes.bitmask();
}

/// The light samples of `rows.direct`'s lanes (into `samples`, one per entry of `groups`, the
/// index of its light in `lights`) and the bounce of `rows.scatter`'s lanes; `rows.scatter`
/// keeps the lanes whose bounce carries light. The one-path code's functions, on lanes.
#[inline(always)]
fn step<V: Lanes>(rows: &mut StepRows, lights: &[SampledLight], groups: &[(u32, bool)], samples: &mut [SampleLanes]) {
    debug_assert_eq!(V::LANES, STEP);
    let (p, ng, ns) = (Vec3x::<V>::load_rows(&rows.p), Vec3x::load_rows(&rows.ng), Vec3x::load_rows(&rows.ns));
    let wo_z = V::load(&rows.wo_z);
    let (zero, one) = (V::splat(0.0), V::splat(1.0));
    if rows.direct != 0 {
        let gathers = V::from_bitmask(rows.direct) & V::from_bitmask(rows.reflects);
        // `bsdf::f` of a diffuse BSDF.
        let f = Vec3x::<V>::load_rows(&rows.albedo) * V::splat(FRAC_1_PI);
        for (&(group, _), s) in groups.iter().zip(samples.iter_mut()) {
            let (u0, u1) = (V::load(&s.u[0]), V::load(&s.u[1]));
            let Some(ls) = lights[group as usize].sample_lanes(p, u0, u1) else { continue };
            // `Frame::to_local(wi).z`, `bsdf::f` not zero, and a positive density.
            let wi_z = ls.wi.dot(ns);
            let keep = ls.carries & gathers & (wo_z * wi_z).gt(zero) & ls.pdf.gt(zero);
            s.keep = keep.bitmask();
            let scale = wi_z.abs() / ls.pdf;
            scale.store(&mut s.scale);
            ls.radiance.store_rows(&mut s.radiance);
            // `DirectSample`'s `f · radiance · scale`, in its order.
            let r = ls.radiance;
            (Vec3x { x: f.x * r.x, y: f.y * r.y, z: f.z * r.z } * scale).store_rows(&mut s.value);
            let shadow = spawn_ray_to_lanes(p, ng, ls.point);
            s.shadow = (keep & shadow.ok).bitmask();
            shadow.origin.store_rows(&mut s.origin);
            shadow.dir.store_rows(&mut s.dir);
            shadow.tfar.store(&mut s.tfar);
        }
    }
    if rows.scatter != 0 {
        // `bsdf::sample_f` of a diffuse BSDF: `cosine_hemisphere`, then the side of `wo`.
        let (x, y) = concentric_disk_lanes(V::load(&rows.u[0]), V::load(&rows.u[1]));
        let z = (one - x * x - y * y).vmax(zero).sqrt();
        let goes = V::from_bitmask(rows.scatter) & !wo_z.eq(zero) & !z.eq(zero);
        rows.scatter = goes.bitmask();
        let z = z.copysign(wo_z);
        // `Frame::to_world` in the frame of `orthonormal_basis(ns)`, then `spawn_ray`.
        let (tx, ty) = orthonormal_basis_lanes(ns);
        let dir = tx * x + ty * y + ns * z;
        offset_origin_lanes(p, toward_lanes(ng, dir)).store_rows(&mut rows.origin);
        dir.store_rows(&mut rows.dir);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampler::Rng;
    use crate::render::sampling::cosine_hemisphere;
    use crate::render::spawn::{spawn_ray, spawn_ray_to};

    fn bits3(v: Vec3) -> [u32; 3] {
        v.to_array().map(f32::to_bits)
    }

    /// The lanes' pieces against the one-path functions, bit for bit, on random points,
    /// normals and uniforms, on every ISA.
    #[test]
    fn lanes_equal_the_one_path_functions_on_every_isa() {
        let mut rng = Rng::new(11, 5);
        let r3 = |rng: &mut Rng, s: f32| {
            let mut v = || (rng.next_f32() - 0.5) * s;
            Vec3::new(v(), v(), v())
        };
        let sampled = [
            SampledLight::Rect {
                radiance: Vec3::new(5.0, 4.0, 3.0),
                center: Vec3::new(0.0, 1.9, 0.0),
                normal: Vec3::NEG_Y,
                dim_x: Vec3::new(0.5, 0.0, 0.0),
                dim_y: Vec3::new(0.0, 0.0, 0.4),
                area: 0.2,
            },
            SampledLight::Point { position: Vec3::new(0.3, 1.2, -0.4), intensity: Vec3::new(2.0, 1.0, 0.5) },
        ];
        let scene = crate::scene::SceneBuilder::new().commit(&crate::BuildOptions::default()).0;
        for isa in crate::Isa::available() {
            for round in 0..200 {
                let mut rows = StepRows { direct: 0xFF, scatter: 0xFF, reflects: 0xFF, ..Default::default() };
                let mut samples = [SampleLanes::default(); 2];
                let mut want = Vec::new();
                for j in 0..STEP {
                    // Points near and far from the origin (both branches of the offset), some on the light.
                    let scale = [0.01, 1.0, 3.0, 1e4][(round + j) % 4];
                    let p = if round % 17 == 3 && j == 2 { Vec3::new(0.0, 1.9, 0.0) } else { r3(&mut rng, scale) };
                    let ng = r3(&mut rng, 2.0).normalize();
                    let ns = if j % 3 == 0 { ng } else { (ng + r3(&mut rng, 0.6)).normalize() };
                    let dir = r3(&mut rng, 2.0).normalize();
                    let wo_z = (-dir).dot(ns);
                    for c in 0..3 {
                        (rows.p[c][j], rows.ng[c][j], rows.ns[c][j]) = (p[c], ng[c], ns[c]);
                    }
                    rows.wo_z[j] = wo_z;
                    let frame = crate::render::frame::Frame::from_normal(ns);
                    assert_eq!(frame.to_local(-dir).z.to_bits(), wo_z.to_bits());
                    let ub = (rng.next_f32(), rng.next_f32());
                    (rows.u[0][j], rows.u[1][j]) = ub;
                    let mut per_light = Vec::new();
                    for (i, light) in sampled.iter().enumerate() {
                        let u = (rng.next_f32(), rng.next_f32());
                        (samples[i].u[0][j], samples[i].u[1][j]) = u;
                        let ctx = crate::render::light::LightContext { p, n: ns };
                        per_light.push(light.sample(&scene, &ctx, u).and_then(|ls| {
                            let wi_z = frame.to_local(ls.wi).z;
                            (wo_z * wi_z > 0.0 && ls.pdf > 0.0).then(|| {
                                let shadow = spawn_ray_to(p, ng, ls.point.expect("a point"));
                                (wi_z.abs() / ls.pdf, ls.radiance, shadow)
                            })
                        }));
                    }
                    let bounce = (wo_z != 0.0)
                        .then(|| {
                            let mut wi = cosine_hemisphere(ub);
                            (wi.z != 0.0).then(|| {
                                wi.z = wi.z.copysign(wo_z);
                                spawn_ray(p, ng, frame.to_world(wi))
                            })
                        })
                        .flatten();
                    want.push((per_light, bounce));
                }
                let step = Step {
                    rows: &mut rows,
                    lights: &sampled,
                    groups: &[(0, true), (1, true)],
                    samples: &mut samples,
                    sobol: &mut SobolLanes::default(),
                    sobol_lanes: 0,
                    finish: false,
                };
                dispatch(isa, step);
                let lane3 = |r: &Rows<3>, j: usize| Vec3::new(r[0][j], r[1][j], r[2][j]);
                for (j, (per_light, bounce)) in want.iter().enumerate() {
                    for (i, w) in per_light.iter().enumerate() {
                        let s = &samples[i];
                        assert_eq!(s.keep >> j & 1 != 0, w.is_some(), "{isa:?} round {round} lane {j} light {i}");
                        let Some((scale, radiance, shadow)) = w else { continue };
                        assert_eq!(s.scale[j].to_bits(), scale.to_bits(), "{isa:?} round {round} lane {j}");
                        if matches!(sampled[i], SampledLight::Point { .. }) {
                            assert_eq!(bits3(lane3(&s.radiance, j)), bits3(*radiance));
                        }
                        assert_eq!(s.shadow >> j & 1 != 0, shadow.is_some(), "{isa:?} round {round} lane {j}");
                        if let Some(r) = shadow {
                            assert_eq!(bits3(lane3(&s.origin, j)), bits3(r.origin), "{isa:?} round {round} lane {j}");
                            assert_eq!(bits3(lane3(&s.dir, j)), bits3(r.dir));
                            assert_eq!(s.tfar[j].to_bits(), r.tfar.to_bits());
                        }
                    }
                    assert_eq!(rows.scatter >> j & 1 != 0, bounce.is_some(), "{isa:?} round {round} lane {j}");
                    if let Some(r) = bounce {
                        assert_eq!(bits3(lane3(&rows.origin, j)), bits3(r.origin), "{isa:?} round {round} lane {j}");
                        assert_eq!(bits3(lane3(&rows.dir, j)), bits3(r.dir), "{isa:?} round {round} lane {j}");
                    }
                }
            }
        }
    }

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
