// Not split: every kind of light's sampling in one place, with the unit tests that check each against closed forms.
//! Light sampling: every light of a scene as something that can be sampled from a shading
//! point: a direction, the distance to the light, the density of that direction per steradian
//! and the radiance arriving along it (pbrt-v4 `Light::SampleLi`; CS184 `SceneLight::sample_L`).
//!
//! The lights are the scene's [`Light`]s plus its emissive geometry, which counts as area
//! lights: emissive triangles grouped by material (one light per material, a triangle chosen
//! in proportion to its area, then a uniform point on it) and each emissive sphere (uniform in
//! the cone it subtends from outside, uniform over its area from inside; pbrt-v4 §6.2.4).
//! Emissive surfaces emit on both sides, as CS184's emission BSDF does.
//!
//! CS184's scenes model each rectangle light twice: a `Light::Area` for sampling and an
//! emissive quad so that the camera (and hemisphere sampling) can see it. Emissive triangles
//! lying in an area light's rectangle are that light's *stand-in*: they are not sampled again
//! (that would count the light twice) and they emit only on the side the light does. An area
//! light without such geometry is, as in CS184, found by light sampling only: camera rays and
//! hemisphere sampling cannot hit it.
//!
//! Point, spot and directional lights are deltas: only light sampling finds them, so a scene
//! lit by them alone renders black under uniform hemisphere sampling, as in CS184.

use super::frame::Frame;
use super::sampling::{cosine_hemisphere, uniform_sphere, uniform_triangle};
use crate::math::Vec3;
use crate::scene::{Light, Scene};
use crate::simd::{F32x1, Lanes, Vec3x};

/// Where direct lighting is wanted.
#[derive(Clone, Copy, Debug)]
pub struct LightContext {
    /// The shading point.
    pub p: Vec3,
    /// Unit shading normal on the side light is gathered from (the side of `wo` for
    /// reflection); lights may sample around it (the environment samples a cosine lobe).
    pub n: Vec3,
}

/// One sample of one light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// Unit direction from the shading point toward the light.
    pub wi: Vec3,
    /// The sampled point on the light (the shadow ray's end), or `None` for lights at infinity.
    pub point: Option<Vec3>,
    /// Radiance arriving along `-wi` if nothing is in the way (for delta lights: the factor
    /// that multiplies `f cos θ`, e.g. `I / r²`).
    pub radiance: Vec3,
    /// Density of `wi` per steradian; 1 for delta lights.
    pub pdf: f32,
}

/// Samples of a rectangle or point light, a lane each ([`SampledLight::sample_lanes`]): the
/// fields of [`LightSample`], meaningful in the lanes where `carries` is true.
#[derive(Clone, Copy, Debug)]
pub struct LightLanes<V> {
    /// Unit direction toward the light.
    pub wi: Vec3x<V>,
    /// The sampled point on the light.
    pub point: Vec3x<V>,
    /// Radiance arriving along `-wi` (points: `I / r²`).
    pub radiance: Vec3x<V>,
    /// Density of `wi` per steradian; 1 for points.
    pub pdf: V,
    /// True in the lanes whose sample carries light.
    pub carries: V,
}

/// A light prepared for sampling.
#[derive(Clone, Debug, PartialEq)]
pub enum SampledLight {
    /// Isotropic point light.
    Point {
        /// Position.
        position: Vec3,
        /// Radiant intensity (W/sr).
        intensity: Vec3,
    },
    /// Spot light with pbrt's smoothstep falloff between the two cone angles.
    Spot {
        /// Position.
        position: Vec3,
        /// Unit axis (direction light travels).
        axis: Vec3,
        /// Intensity on the axis.
        intensity: Vec3,
        /// Cosine of the angle where the falloff starts.
        cos_inner: f32,
        /// Cosine of the angle beyond which nothing is emitted.
        cos_outer: f32,
    },
    /// Light from a direction at infinity.
    Directional {
        /// Unit direction toward the light (the negated travel direction).
        to_light: Vec3,
        /// Radiance (irradiance on a surface facing the light).
        radiance: Vec3,
    },
    /// One-sided parallelogram (CS184 `AreaLight`).
    Rect {
        /// Emitted radiance.
        radiance: Vec3,
        /// Centre.
        center: Vec3,
        /// Unit normal of the emitting side.
        normal: Vec3,
        /// Full first edge.
        dim_x: Vec3,
        /// Full second edge.
        dim_y: Vec3,
        /// Area.
        area: f32,
    },
    /// Emissive triangles of one material, sampled by area.
    Triangles {
        /// Emitted radiance (the material's emission).
        radiance: Vec3,
        /// Triangle ids.
        triangles: Vec<u32>,
        /// Cumulative areas, normalised so the last is 1.
        cdf: Vec<f32>,
        /// Total area.
        area: f32,
    },
    /// An emissive sphere.
    Sphere {
        /// Emitted radiance.
        radiance: Vec3,
        /// Centre.
        center: Vec3,
        /// Radius.
        radius: f32,
    },
    /// Constant radiance from every direction.
    Environment {
        /// Radiance.
        radiance: Vec3,
    },
}

impl SampledLight {
    /// True for lights only light sampling can find (points and directions).
    pub fn is_delta(&self) -> bool {
        matches!(self, SampledLight::Point { .. } | SampledLight::Spot { .. } | SampledLight::Directional { .. })
    }

    /// Samples of the light per shading point when each area light takes `per_area` (at least
    /// one): one for a delta light, whose every sample is the same.
    #[inline]
    pub fn samples_per_point(&self, per_area: u32) -> u32 {
        if self.is_delta() { 1 } else { per_area.max(1) }
    }

    /// True for the kinds [`SampledLight::sample_lanes`] samples (rectangles and points).
    pub fn in_lanes(&self) -> bool {
        matches!(self, SampledLight::Rect { .. } | SampledLight::Point { .. })
    }

    /// Samples a direction toward the light from `ctx` with the uniforms `u`; `None` when the
    /// sample carries no light (the light faces away, the point is outside the spot cone...).
    #[inline]
    pub fn sample(&self, scene: &Scene, ctx: &LightContext, u: (f32, f32)) -> Option<LightSample> {
        // Rectangles (CS184's area lights) are sampled where they are asked for, so that the
        // shading loop keeps the sample in registers (faster renders of the CS184 boxes;
        // points inlined as well gained nothing on the dragon; PERFORMANCE.md, "Smaller
        // measured choices"); the other kinds behind a call.
        let SampledLight::Rect { .. } = self else {
            return self.sample_not_rect(scene, ctx, u);
        };
        self.sample_one_lane(ctx.p, u)
    }

    /// [`SampledLight::sample_lanes`] on one lane, as a [`LightSample`].
    #[inline(always)]
    fn sample_one_lane(&self, p: Vec3, u: (f32, f32)) -> Option<LightSample> {
        let s = self.sample_lanes::<F32x1>(p.into(), F32x1(u.0), F32x1(u.1))?;
        (s.carries.bitmask() != 0).then(|| LightSample {
            wi: s.wi.into(),
            point: Some(s.point.into()),
            radiance: s.radiance.into(),
            pdf: s.pdf.0,
        })
    }

    /// [`SampledLight::sample`] from the points `p` with the uniforms `(u0, u1)`, a lane each,
    /// for the kinds [`SampledLight::in_lanes`] names (`None` for the others). The context's
    /// normal is not needed: these kinds do not sample around it.
    #[inline(always)]
    pub fn sample_lanes<V: Lanes>(&self, p: Vec3x<V>, u0: V, u1: V) -> Option<LightLanes<V>> {
        let zero = V::splat(0.0);
        match *self {
            SampledLight::Rect { radiance, center, normal, dim_x, dim_y, area } => {
                let half = V::splat(0.5);
                let q = Vec3x::splat(center) + Vec3x::splat(dim_x) * (u0 - half) + Vec3x::splat(dim_y) * (u1 - half);
                let d = q - p;
                let d2 = d.dot(d);
                let wi = d / d2.sqrt();
                let cos_l = -wi.dot(Vec3x::splat(normal));
                Some(LightLanes {
                    wi,
                    point: q,
                    radiance: Vec3x::splat(radiance),
                    pdf: d2 / (V::splat(area) * cos_l),
                    carries: cos_l.gt(zero) & d2.gt(zero),
                })
            }
            SampledLight::Point { position, intensity } => {
                let q = Vec3x::splat(position);
                let d = q - p;
                let d2 = d.dot(d);
                Some(LightLanes {
                    wi: d / d2.sqrt(),
                    point: q,
                    radiance: Vec3x::splat(intensity) / d2,
                    pdf: V::splat(1.0),
                    carries: d2.gt(zero),
                })
            }
            _ => None,
        }
    }

    /// [`SampledLight::sample`] of the kinds other than [`SampledLight::Rect`].
    #[inline(never)]
    fn sample_not_rect(&self, scene: &Scene, ctx: &LightContext, u: (f32, f32)) -> Option<LightSample> {
        let p = ctx.p;
        match self {
            SampledLight::Point { .. } => self.sample_one_lane(p, u),
            SampledLight::Spot { position, axis, intensity, cos_inner, cos_outer } => {
                let d = *position - p;
                let d2 = d.length_squared();
                if d2 <= 0.0 {
                    return None;
                }
                let wi = d / d2.sqrt();
                let falloff = smoothstep(*cos_outer, *cos_inner, (-wi).dot(*axis));
                (falloff > 0.0).then(|| LightSample {
                    wi,
                    point: Some(*position),
                    radiance: *intensity * (falloff / d2),
                    pdf: 1.0,
                })
            }
            SampledLight::Directional { to_light, radiance } => {
                Some(LightSample { wi: *to_light, point: None, radiance: *radiance, pdf: 1.0 })
            }
            SampledLight::Rect { .. } => self.sample(scene, ctx, u),
            SampledLight::Triangles { radiance, triangles, cdf, area } => {
                // Pick a triangle by area, then reuse the rescaled uniform for the point.
                let i = cdf.partition_point(|&c| c <= u.0).min(cdf.len() - 1);
                let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
                let u0 = ((u.0 - lo) / (cdf[i] - lo)).clamp(0.0, 1.0);
                let [a, b, c] = scene.triangles.vertices(triangles[i] as usize);
                let (b1, b2) = uniform_triangle((u0, u.1));
                let q = a * (1.0 - b1 - b2) + b * b1 + c * b2;
                let n = (b - a).cross(c - a).normalize_or_zero();
                let d = q - p;
                let d2 = d.length_squared();
                let wi = d / d2.sqrt();
                let cos_l = wi.dot(n).abs();
                (cos_l > 0.0 && d2 > 0.0).then(|| LightSample {
                    wi,
                    point: Some(q),
                    radiance: *radiance,
                    pdf: d2 / (area * cos_l),
                })
            }
            SampledLight::Sphere { radiance, center, radius } => sample_sphere(*center, *radius, *radiance, p, u),
            SampledLight::Environment { radiance } => {
                // Cosine-weighted around the receiver's normal: only directions a reflecting
                // surface can use (pbrt-v4 passes the normal in its LightSampleContext too).
                let local = cosine_hemisphere(u);
                (local.z > 0.0).then(|| LightSample {
                    wi: Frame::from_normal(ctx.n).to_world(local),
                    point: None,
                    radiance: *radiance,
                    pdf: local.z * std::f32::consts::FRAC_1_PI,
                })
            }
        }
    }
}

fn sample_sphere(center: Vec3, radius: f32, radiance: Vec3, p: Vec3, u: (f32, f32)) -> Option<LightSample> {
    let to_c = center - p;
    let dc2 = to_c.length_squared();
    let r2 = radius * radius;
    // Inside (or on) the sphere: uniform over its area, converted to solid angle.
    if dc2 <= r2 * (1.0 + 1e-3) {
        let n = uniform_sphere(u);
        let q = center + n * radius;
        let d = q - p;
        let d2 = d.length_squared();
        let wi = d / d2.sqrt();
        let cos_l = wi.dot(n).abs();
        let area = 4.0 * std::f32::consts::PI * r2;
        return (cos_l > 0.0 && d2 > 0.0).then(|| LightSample {
            wi,
            point: Some(q),
            radiance,
            pdf: d2 / (area * cos_l),
        });
    }
    // Outside: uniform in the subtended cone, then the point where that direction meets the
    // sphere, found from the angle at the centre (pbrt-v4's construction, stable for small
    // and distant spheres, with its small-angle series below sin² = sin²(1.5°)).
    let sin2_max = r2 / dc2;
    let sin_max = sin2_max.sqrt();
    let cos_max = (1.0 - sin2_max).max(0.0).sqrt();
    let (mut cos_t, mut sin2_t) = {
        let c = 1.0 - u.0 * (1.0 - cos_max);
        (c, (1.0 - c * c).max(0.0))
    };
    let mut one_minus_cos_max = 1.0 - cos_max;
    if sin2_max < 0.000_685_23 {
        sin2_t = sin2_max * u.0;
        cos_t = (1.0 - sin2_t).sqrt();
        one_minus_cos_max = 0.5 * sin2_max;
    }
    let cos_a = sin2_t / sin_max + cos_t * (1.0 - sin2_t / sin2_max).max(0.0).sqrt();
    let sin_a = (1.0 - cos_a * cos_a).max(0.0).sqrt();
    let phi = std::f32::consts::TAU * u.1;
    let frame = Frame::from_normal(to_c / dc2.sqrt());
    let n = frame.to_world(Vec3::new(-sin_a * phi.cos(), -sin_a * phi.sin(), -cos_a));
    let q = center + n * radius;
    let d = q - p;
    let d2 = d.length_squared();
    (d2 > 0.0).then(|| LightSample {
        wi: d / d2.sqrt(),
        point: Some(q),
        radiance,
        pdf: 1.0 / (std::f32::consts::TAU * one_minus_cos_max),
    })
}

#[inline]
fn smoothstep(lo: f32, hi: f32, x: f32) -> f32 {
    if lo == hi {
        return if x >= hi { 1.0 } else { 0.0 };
    }
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// All lights of a scene, prepared for sampling, and what emission a hit or a miss sees.
#[derive(Clone, Debug, Default)]
pub struct LightSet {
    /// The lights, scene lights first, then emissive triangle groups, then emissive spheres.
    pub lights: Vec<SampledLight>,
    /// Sum of the environment lights' radiance: what a ray that leaves the scene sees.
    pub environment: Vec3,
    /// Stand-in triangles (sorted ids) and the emitting normal of their area light.
    stand_ins: Vec<(u32, Vec3)>,
}

impl LightSet {
    /// Prepares the lights of `scene`.
    pub fn new(scene: &Scene) -> Self {
        let mut set = LightSet::default();
        let mut rects = Vec::new();
        for light in &scene.lights {
            set.lights.push(match *light {
                Light::Point { position, intensity } => SampledLight::Point { position, intensity },
                Light::Spot { position, direction, intensity, inner_angle_deg, outer_angle_deg } => {
                    let outer = outer_angle_deg.max(inner_angle_deg);
                    SampledLight::Spot {
                        position,
                        axis: direction.normalize_or(Vec3::NEG_Y),
                        intensity,
                        cos_inner: inner_angle_deg.to_radians().cos(),
                        cos_outer: outer.to_radians().cos(),
                    }
                }
                Light::Directional { direction, radiance } => {
                    SampledLight::Directional { to_light: -direction.normalize_or(Vec3::NEG_Y), radiance }
                }
                Light::Area { radiance, position, direction, dim_x, dim_y } => {
                    let area = dim_x.cross(dim_y).length();
                    let normal = direction.normalize_or(Vec3::NEG_Y);
                    rects.push((position, normal, dim_x, dim_y));
                    SampledLight::Rect { radiance, center: position, normal, dim_x, dim_y, area }
                }
                Light::Environment { radiance } => {
                    set.environment += radiance;
                    SampledLight::Environment { radiance }
                }
            });
        }
        // A light that can never deliver anything is dropped (it would only cost shadow rays).
        set.lights.retain(|l| match l {
            SampledLight::Rect { area, radiance, .. } => *area > 0.0 && radiance.max_element() > 0.0,
            _ => true,
        });

        // Emissive triangles, grouped by material; stand-ins of area lights set aside.
        let tris = &scene.triangles;
        let mut groups: Vec<(u32, Vec<u32>)> = Vec::new();
        for t in 0..tris.len() {
            let m = tris.material[t];
            if !scene.materials[m as usize].is_emissive() {
                continue;
            }
            let v = tris.vertices(t);
            if let Some(&(_, n, ..)) = rects.iter().find(|r| is_stand_in(&v, r)) {
                set.stand_ins.push((t as u32, n));
                continue;
            }
            match groups.iter_mut().find(|g| g.0 == m) {
                Some(g) => g.1.push(t as u32),
                None => groups.push((m, vec![t as u32])),
            }
        }
        for (m, triangles) in groups {
            let mut cdf = Vec::with_capacity(triangles.len());
            let mut total = 0.0f64;
            for &t in &triangles {
                let [a, b, c] = tris.vertices(t as usize);
                total += 0.5 * (b - a).cross(c - a).length() as f64;
                cdf.push(total);
            }
            if total > 0.0 {
                let cdf = cdf.iter().map(|&c| (c / total) as f32).collect();
                let radiance = scene.materials[m as usize].emission;
                set.lights.push(SampledLight::Triangles { radiance, triangles, cdf, area: total as f32 });
            }
        }
        let sp = &scene.spheres;
        for s in 0..sp.len() {
            let m = &scene.materials[sp.material[s] as usize];
            if m.is_emissive() {
                set.lights.push(SampledLight::Sphere {
                    radiance: m.emission,
                    center: sp.center[s],
                    radius: sp.radius[s],
                });
            }
        }
        set
    }

    /// Number of emissive triangles recognised as the visible stand-ins of area lights.
    pub fn num_stand_ins(&self) -> usize {
        self.stand_ins.len()
    }

    /// Radiance emitted by primitive `prim` (material emission `emission`) toward a viewer in
    /// direction `-ray_dir`: both sides, except stand-ins, which emit only where their area
    /// light does.
    #[inline]
    pub fn emitted(&self, prim: u32, emission: Vec3, ray_dir: Vec3) -> Vec3 {
        if emission == Vec3::ZERO || self.stand_ins.is_empty() {
            return emission;
        }
        match self.stand_ins.binary_search_by_key(&prim, |s| s.0) {
            Ok(i) if ray_dir.dot(self.stand_ins[i].1) >= 0.0 => Vec3::ZERO,
            _ => emission,
        }
    }
}

/// True when triangle `v` lies in the rectangle light `(centre, normal, dim_x, dim_y)`: in its
/// plane and inside its circumscribed disc (with 2% slack, since scene files round the two
/// descriptions differently). "In its plane" allows a gap behind the light of up to 1% of its
/// size (a lamp quad put just above its light, against the ceiling, as the built-in box's once
/// was: otherwise the lamp is sampled twice, as the light and as an emitter), but none in
/// front of it, where the quad would block the light's own shadow rays.
fn is_stand_in(v: &[Vec3; 3], &(c, n, dx, dy): &(Vec3, Vec3, Vec3, Vec3)) -> bool {
    let size = dx.length() + dy.length();
    let radius = 0.5 * (dx + dy).length().max((dx - dy).length()) * 1.02;
    v.iter().all(|&p| {
        let d = p - c;
        let h = d.dot(n);
        (-1e-2 * size..=1e-3 * size).contains(&h) && (d - n * h).length() <= radius
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampler::Rng;
    use crate::{BuildOptions, Material, SceneBuilder};

    /// E[radiance cos θ / pdf] over light samples is the irradiance at `p` (normal `n`), which
    /// for a uniform emitter of radiance L is `L` times the projected solid angle.
    fn irradiance(scene: &Scene, l: &SampledLight, p: Vec3, n: Vec3, count: usize) -> f64 {
        let mut rng = Rng::new(9, 9);
        let ctx = LightContext { p, n };
        let mut sum = 0.0f64;
        for _ in 0..count {
            if let Some(s) = l.sample(scene, &ctx, rng.next_2d()) {
                assert!((s.wi.length() - 1.0).abs() < 1e-4);
                if let Some(q) = s.point {
                    assert!(((q - p).normalize() - s.wi).length() < 1e-3, "wi points at the sampled point");
                }
                sum += (s.radiance.x * s.wi.dot(n).max(0.0) / s.pdf) as f64;
            }
        }
        sum / count as f64
    }

    fn empty_scene() -> Scene {
        SceneBuilder::new().commit(&BuildOptions::default()).0
    }

    #[test]
    fn sphere_light_irradiance_from_outside_and_inside() {
        let scene = empty_scene();
        // A sphere of radius r at distance d straight above: E = π L (r/d)².
        let (r, d) = (0.5f32, 2.0f32);
        let l = SampledLight::Sphere { radiance: Vec3::ONE, center: Vec3::new(0.0, 0.0, d), radius: r };
        let e = irradiance(&scene, &l, Vec3::ZERO, Vec3::Z, 200_000);
        let expect = std::f64::consts::PI * (r as f64 / d as f64).powi(2);
        assert!((e / expect - 1.0).abs() < 0.01, "{e} vs {expect}");
        // Inside a sphere every direction sees it: E = π L.
        let l = SampledLight::Sphere { radiance: Vec3::ONE, center: Vec3::ZERO, radius: 1.0 };
        let e = irradiance(&scene, &l, Vec3::new(0.3, 0.0, 0.1), Vec3::Z, 200_000);
        assert!((e / std::f64::consts::PI - 1.0).abs() < 0.01, "{e}");
    }

    /// Irradiance at `p` (normal `n`) from a uniform polygon of radiance 1, by Lambert's
    /// formula: E = 1/2 Σ θ_i (n · unit(v_i × v_{i+1})) over the polygon's edges.
    fn polygon_irradiance(p: Vec3, n: Vec3, poly: &[Vec3]) -> f64 {
        let mut e = 0.0f64;
        for i in 0..poly.len() {
            let (a, b) = ((poly[i] - p).normalize(), (poly[(i + 1) % poly.len()] - p).normalize());
            let theta = a.dot(b).clamp(-1.0, 1.0).acos();
            e += (theta * n.dot(a.cross(b).normalize())) as f64;
        }
        0.5 * e.abs()
    }

    /// The corners, in order around it, of the rectangle of centre `c` and sides `dx`, `dy`.
    fn rect_corners(c: Vec3, dx: Vec3, dy: Vec3) -> [Vec3; 4] {
        [c - dx * 0.5 - dy * 0.5, c + dx * 0.5 - dy * 0.5, c + dx * 0.5 + dy * 0.5, c - dx * 0.5 + dy * 0.5]
    }

    #[test]
    fn rect_and_triangle_lights_match_the_polygon_formula() {
        let (c, dx, dy) = (Vec3::new(0.2, 0.1, 1.0), Vec3::new(0.8, 0.0, 0.0), Vec3::new(0.0, 0.6, 0.0));
        let corners = rect_corners(c, dx, dy);
        let p = Vec3::new(0.5, -0.3, 0.0);
        let expect = polygon_irradiance(p, Vec3::Z, &corners);
        let scene = empty_scene();
        let rect =
            SampledLight::Rect { radiance: Vec3::ONE, center: c, normal: -Vec3::Z, dim_x: dx, dim_y: dy, area: 0.48 };
        let e = irradiance(&scene, &rect, p, Vec3::Z, 200_000);
        assert!((e / expect - 1.0).abs() < 0.01, "rect {e} vs {expect}");
        // Facing away: nothing.
        let away =
            SampledLight::Rect { radiance: Vec3::ONE, center: c, normal: Vec3::Z, dim_x: dx, dim_y: dy, area: 0.48 };
        assert_eq!(irradiance(&scene, &away, p, Vec3::Z, 100), 0.0);

        // The same rectangle as two emissive triangles of a scene.
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::emissive(Vec3::ONE));
        b.add_mesh(&corners, &[[0, 1, 2], [0, 2, 3]], m).unwrap();
        let (scene, _) = b.commit(&BuildOptions::default());
        let set = LightSet::new(&scene);
        assert_eq!(set.lights.len(), 1);
        let e = irradiance(&scene, &set.lights[0], p, Vec3::Z, 200_000);
        assert!((e / expect - 1.0).abs() < 0.01, "triangles {e} vs {expect}");
    }

    /// The built-in Cornell box has one lamp: an area light with a visible quad of the same
    /// size and radiance (`scenes/README.md`). Light sampling must see it once: the
    /// irradiance its lights give a point of the floor is the lamp's by Lambert's formula.
    #[test]
    fn built_in_lamp_lights_the_floor_once() {
        let (scene, _) = crate::testing::cornell_box().commit(&BuildOptions::default());
        let set = LightSet::new(&scene);
        assert_eq!(set.num_stand_ins(), 2, "the lamp quad's two triangles stand in for the area light");
        let Some(SampledLight::Rect { center, dim_x, dim_y, radiance, .. }) = set.lights.first() else {
            panic!("the area light comes first: {:?}", set.lights)
        };
        let (c, dx, dy) = (*center, *dim_x, *dim_y);
        let lamp = rect_corners(c, dx, dy);
        for p in [Vec3::new(0.0, -1.0, 0.0), Vec3::new(0.6, -1.0, -0.7)] {
            let expect = radiance.x as f64 * polygon_irradiance(p, Vec3::Y, &lamp);
            let e: f64 = set.lights.iter().map(|l| irradiance(&scene, l, p, Vec3::Y, 200_000)).sum();
            assert!((e / expect - 1.0).abs() < 0.01, "at {p}: {e} from {} lights vs {expect}", set.lights.len());
        }
    }

    #[test]
    fn environment_and_delta_lights() {
        let scene = empty_scene();
        let env = SampledLight::Environment { radiance: Vec3::splat(2.0) };
        let n = Vec3::new(0.3, 0.4, 0.5).normalize();
        // E = π L for any normal, and every cosine-weighted sample gives it exactly.
        let e = irradiance(&scene, &env, Vec3::ZERO, n, 1000);
        assert!((e - 2.0 * std::f64::consts::PI).abs() < 1e-3, "{e}");
        let pt = SampledLight::Point { position: Vec3::new(0.0, 0.0, 2.0), intensity: Vec3::splat(4.0) };
        assert!(pt.is_delta());
        assert!((irradiance(&scene, &pt, Vec3::ZERO, Vec3::Z, 1) - 1.0).abs() < 1e-6);
        let spot = SampledLight::Spot {
            position: Vec3::new(0.0, 0.0, 2.0),
            axis: -Vec3::Z,
            intensity: Vec3::splat(4.0),
            cos_inner: 20f32.to_radians().cos(),
            cos_outer: 30f32.to_radians().cos(),
        };
        assert!((irradiance(&scene, &spot, Vec3::ZERO, Vec3::Z, 1) - 1.0).abs() < 1e-6);
        assert_eq!(irradiance(&scene, &spot, Vec3::new(5.0, 0.0, 0.0), Vec3::Z, 1), 0.0, "outside the cone");
    }

    #[test]
    fn stand_in_quads_are_not_sampled_twice() {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::emissive(Vec3::splat(10.0)));
        // CS184 CBspheres: the quad is 0.8 x 0.6, the light's dims are 0.6 x 0.8.
        let y = 0.0043;
        let q = [
            Vec3::new(0.4, -0.3 + y, 1.49),
            Vec3::new(0.4, 0.3 + y, 1.49),
            Vec3::new(-0.4, 0.3 + y, 1.49),
            Vec3::new(-0.4, -0.3 + y, 1.49),
        ];
        b.add_mesh(&q, &[[0, 1, 2], [0, 2, 3]], m).unwrap();
        b.add_mesh(&q.map(|p| p - Vec3::Z), &[[0, 1, 2]], m).unwrap();
        b.add_light(Light::Area {
            radiance: Vec3::splat(10.0),
            position: Vec3::new(0.0, 0.0, 1.49),
            direction: -Vec3::Z,
            dim_x: Vec3::new(0.6, 0.0, 0.0),
            dim_y: Vec3::new(0.0, 0.8, 0.0),
        });
        let (scene, _) = b.commit(&BuildOptions::default());
        let set = LightSet::new(&scene);
        assert_eq!(set.num_stand_ins(), 2);
        assert_eq!(set.lights.len(), 2, "the rectangle and the other (lower) triangle");
        // The stand-in emits downward only; the other emitter both ways.
        assert_eq!(set.emitted(0, Vec3::ONE, Vec3::Z), Vec3::ONE, "seen from below");
        assert_eq!(set.emitted(0, Vec3::ONE, -Vec3::Z), Vec3::ZERO, "seen from above");
        assert_eq!(set.emitted(2, Vec3::ONE, -Vec3::Z), Vec3::ONE);
    }

    /// A quad 1 cm behind its 1 m light (the built-in box's lamp as it once was) stands in
    /// for it; 1 cm in front of it (where it would shade the light) or 5 cm behind, not.
    #[test]
    fn stand_ins_may_sit_just_behind_their_light() {
        let stand_ins = |quad_y: f32| {
            let mut b = SceneBuilder::new();
            let m = b.add_material(Material::emissive(Vec3::splat(3.0)));
            let q = [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)].map(|(x, z)| Vec3::new(x, quad_y, z));
            b.add_mesh(&q, &[[0, 1, 2], [0, 2, 3]], m).unwrap();
            b.add_light(Light::Area {
                radiance: Vec3::splat(3.0),
                position: Vec3::new(0.0, 0.98, 0.0),
                direction: -Vec3::Y,
                dim_x: Vec3::X,
                dim_y: Vec3::Z,
            });
            let (scene, _) = b.commit(&BuildOptions::default());
            let set = LightSet::new(&scene);
            let expect = if set.num_stand_ins() == 2 { 1 } else { 2 };
            assert_eq!(set.lights.len(), expect, "the quad is a stand-in or a light of its own");
            set.num_stand_ins()
        };
        assert_eq!(stand_ins(0.98), 2, "in the plane");
        assert_eq!(stand_ins(0.99), 2, "1 cm behind");
        assert_eq!(stand_ins(0.97), 0, "1 cm in front");
        assert_eq!(stand_ins(1.03), 0, "5 cm behind");
    }
}
