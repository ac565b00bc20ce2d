//! The arithmetic of a step of eight diffuse hits in SIMD lanes, on one ISA ([`Step`]): the
//! light samples and their shadow rays, the cosine-weighted bounce and the continuation's
//! origin, then (when every lane draws Sobol' numbers) the end of the step, Russian roulette
//! included. The rows it reads and writes ([`StepRows`], [`SampleLanes`]) are filled and read
//! one path at a time by `lanes`.

use super::throughput;
use crate::math::orthonormal_basis_lanes;
use crate::render::light::SampledLight;
use crate::render::queue::{Rows, STEP};
use crate::render::sampler::SobolLanes;
use crate::render::sampling::concentric_disk_lanes;
use crate::render::spawn::{offset_origin_lanes, spawn_ray_to_lanes, toward_lanes};
use crate::simd::isa::IsaOp;
use crate::simd::{IsaLanes, Lanes, Vec3x};
use std::f32::consts::FRAC_1_PI;

/// One direct-lighting sample of a step's eight points: its uniforms, and what the lanes
/// made of them.
#[derive(Clone, Copy, Debug, Default)]
pub struct SampleLanes {
    /// The two uniforms of each lane.
    pub(super) u: Rows<2>,
    /// Lanes whose sample is queued (it carries light).
    pub(super) keep: u32,
    /// Lanes whose sample has a shadow ray (the others touch the light: always visible).
    pub(super) shadow: u32,
    /// Shadow ray origin, unit direction and end.
    pub(super) origin: Rows<3>,
    pub(super) dir: Rows<3>,
    pub(super) tfar: [f32; STEP],
    /// `|cos θ| / pdf`.
    pub(super) scale: [f32; STEP],
    /// Radiance arriving from the sample (point lights: `I / r²`).
    pub(super) radiance: Rows<3>,
    /// What the sample adds if visible: `f · radiance · scale` ([`super::Integrator::direct_total`]).
    pub(super) value: Rows<3>,
}

/// The rows of one step: what is read from the paths, and the continuation computed.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct StepRows {
    /// Hit point, geometric normal, shading normal.
    pub(super) p: Rows<3>,
    pub(super) ng: Rows<3>,
    pub(super) ns: Rows<3>,
    /// `z` of the direction back along the incoming ray, in the shading frame.
    pub(super) wo_z: [f32; STEP],
    /// Uniforms of the BSDF sample.
    pub(super) u: Rows<2>,
    /// Lanes that gather direct lighting.
    pub(super) direct: u32,
    /// Lanes whose BSDF is not black (`albedo / π != 0`).
    pub(super) reflects: u32,
    /// Lanes that scatter (in: the path goes on if its sample does; out: it does).
    pub(super) scatter: u32,
    /// The continuation's origin and unit direction.
    pub(super) origin: Rows<3>,
    pub(super) dir: Rows<3>,
    /// Filled when the lanes end the step ([`finish_step`]): the paths' throughput (in: before
    /// the bounce; out: after the BSDF sample and Russian roulette), their albedo and radiance
    /// scaling, and the lanes whose path plays Russian roulette if it goes on.
    pub(super) beta: Rows<3>,
    pub(super) albedo: Rows<3>,
    pub(super) eta_scale: [f32; STEP],
    pub(super) roulette: u32,
}

/// The lanes' part of a step, run on one ISA.
pub(super) struct Step<'a> {
    pub(super) rows: &'a mut StepRows,
    /// The integrator's lights, and each sample's light (and whether the lanes sample it).
    pub(super) lights: &'a [SampledLight],
    pub(super) groups: &'a [(u32, bool)],
    pub(super) samples: &'a mut [SampleLanes],
    /// The lanes (bits of `sobol_lanes`) whose uniforms `sobol` draws here, in the one-path
    /// order: each light sample, the BSDF sample, the unused lobe choice.
    pub(super) sobol: &'a mut SobolLanes,
    pub(super) sobol_lanes: u32,
    /// Whether the lanes end the step ([`finish_step`]; every lane's numbers are in `sobol`).
    pub(super) finish: bool,
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
    use crate::math::Vec3;
    use crate::render::sampler::Rng;
    use crate::render::sampling::cosine_hemisphere;
    use crate::render::spawn::{spawn_ray, spawn_ray_to};
    use crate::simd::isa::dispatch;

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
}
