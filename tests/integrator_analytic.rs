//! The path tracer against closed-form answers: white furnaces, a closed emitting enclosure,
//! Lambert's formula for a rectangle light, bounce decomposition, Russian roulette, the
//! convergence rate, adaptive sampling, acne and thread-count independence.
//!
//! Scenes are built in code and rendered small, so that each test takes a fraction of a second.

use raypack::generate::uv_sphere;
use raypack::render::{self, IntegratorKind, RenderOutput, RenderSettings, SamplerKind};
use raypack::{BuildOptions, Camera, Light, Material, Scene, SceneBuilder, Vec3};

fn settings(w: usize, h: usize, integrator: IntegratorKind) -> RenderSettings {
    RenderSettings { width: w, height: h, integrator, ..RenderSettings::default() }
}

fn render(scene: &Scene, camera: &Camera, s: &RenderSettings) -> RenderOutput {
    render::render(scene, camera, s, &|_| {})
}

fn commit(b: SceneBuilder) -> Scene {
    let (scene, report) = b.commit(&BuildOptions::default());
    assert_eq!(report.dropped(), 0);
    scene
}

/// Mean and standard error of the mean of `xs`.
fn mean_se(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

fn luminance(out: &RenderOutput) -> Vec<f64> {
    out.film.pixels.iter().map(|p| p.x as f64).collect()
}

// ---------------------------------------------------------------------------------------------
// White furnace: a closed-form answer for every pixel.

const ENV: f32 = 0.7;

fn furnace(material: Material) -> (Scene, Camera) {
    let mut b = SceneBuilder::new();
    let m = b.add_material(material);
    b.add_sphere(Vec3::ZERO, 1.0, m).unwrap();
    b.add_light(Light::Environment { radiance: Vec3::splat(ENV) });
    let camera = Camera::look_at(Vec3::new(0.0, 0.5, 3.5), Vec3::ZERO, Vec3::Y, 40.0, 1.0, 0.01, 100.0);
    (commit(b), camera)
}

#[test]
fn white_furnace_light_sampling_is_exact_everywhere() {
    // Albedo 1 under uniform radiance L: every pixel, sphere or background, is L. Light sampling
    // of the environment (cosine-weighted) makes each sample exact, so any acne, missing π or
    // wrong density shows up as a pixel off by more than 1%.
    for (name, material, m) in [
        ("diffuse", Material::diffuse(Vec3::ONE), 3),
        ("mirror", Material::mirror(Vec3::ONE), 10),
        ("glass", Material::glass(1.5), 100),
    ] {
        let (scene, camera) = furnace(material);
        let mut s = settings(40, 40, IntegratorKind::Global);
        s.samples_per_pixel = 4;
        s.max_depth = m;
        let out = render(&scene, &camera, &s);
        for (i, p) in out.film.pixels.iter().enumerate() {
            assert!((*p - Vec3::splat(ENV)).abs().max_element() <= 0.01 * ENV, "{name}: pixel {i} is {p}, not {ENV}");
        }
    }
    // Albedo 0.5: the sphere reflects half (a convex object never sees itself).
    let (scene, camera) = furnace(Material::diffuse(Vec3::splat(0.5)));
    let out = render(&scene, &camera, &settings(20, 20, IntegratorKind::Direct));
    let centre = out.film.get(10, 10);
    assert!((centre.x - 0.5 * ENV).abs() < 1e-3 * ENV, "{centre}");
}

#[test]
fn clamping_scales_samples_above_the_limit_and_leaves_the_rest() {
    // In the diffuse white furnace every sample is exactly ENV (light sampling), so a limit
    // below ENV turns every pixel into the limit and counts every sample, and a limit above
    // ENV changes nothing.
    let (scene, camera) = furnace(Material::diffuse(Vec3::ONE));
    let mut s = settings(16, 16, IntegratorKind::Global);
    s.samples_per_pixel = 4;
    s.max_depth = 3;
    let free = render(&scene, &camera, &s);
    s.max_sample_value = Some(0.5 * ENV);
    let low = render(&scene, &camera, &s);
    assert_eq!(low.stats.clamped_samples, low.stats.samples);
    for (i, p) in low.film.pixels.iter().enumerate() {
        assert!((*p - Vec3::splat(0.5 * ENV)).abs().max_element() <= 0.01 * ENV, "pixel {i} is {p}, not {}", 0.5 * ENV);
    }
    s.max_sample_value = Some(1.5 * ENV);
    let high = render(&scene, &camera, &s);
    assert_eq!(high.stats.clamped_samples, 0);
    assert_eq!(high.film.pixels, free.film.pixels);
}

#[test]
fn white_furnace_hemisphere_sampling_is_unbiased() {
    let (scene, camera) = furnace(Material::diffuse(Vec3::ONE));
    let mut s = settings(32, 32, IntegratorKind::Global);
    s.hemisphere_sampling = true;
    s.samples_per_pixel = 32;
    s.light_samples = 4;
    s.max_depth = 3;
    let out = render(&scene, &camera, &s);
    let xs = luminance(&out);
    let (m, se) = mean_se(&xs);
    eprintln!("furnace -H: image mean {m} vs {ENV} (se {se})");
    assert!((m / ENV as f64 - 1.0).abs() < 0.01, "image mean {m} vs {ENV} (se {se})");
    assert!((m - ENV as f64).abs() < 4.0 * se + 1e-6, "image mean {m} vs {ENV}: more than 4 standard errors ({se})");
    // Per pixel: 4 · 32 uniform hemisphere rays, each 2 L cos θ: σ = L / √3 / √128 ≈ 0.051 L.
    let sigma = ENV as f64 / 3f64.sqrt() / 128f64.sqrt();
    for (i, x) in xs.iter().enumerate() {
        assert!((x - ENV as f64).abs() < 5.5 * sigma, "pixel {i}: {x} is more than 5.5σ from {ENV}");
    }
}

#[test]
fn microfacet_furnace_light_and_hemisphere_sampling_agree() {
    // A rough gold sphere under uniform light: its directional albedo has no closed form, but
    // it is at most 1, and light sampling and hemisphere sampling must agree on it.
    let gold = Material {
        name: "gold".into(),
        bsdf: raypack::Bsdf::Microfacet {
            eta: Vec3::new(0.21646, 0.42833, 1.3284),
            k: Vec3::new(3.2390, 2.4599, 1.8661),
            alpha: 0.3,
        },
        emission: Vec3::ZERO,
    };
    let (scene, camera) = furnace(gold);
    let mut means = Vec::new();
    for hemisphere in [false, true] {
        let mut s = settings(24, 24, IntegratorKind::Direct);
        s.samples_per_pixel = 64;
        s.light_samples = 4;
        s.hemisphere_sampling = hemisphere;
        let out = render(&scene, &camera, &s);
        // The central 12 x 12 pixels all see the sphere.
        let xs: Vec<f64> =
            (6..18).flat_map(|y| (6..18).map(move |x| (x, y))).map(|(x, y)| out.film.get(x, y).x as f64).collect();
        let (m, se) = mean_se(&xs);
        assert!(m <= ENV as f64 + 3.0 * se, "-H {hemisphere}: mean {m} (se {se}): reflects more than arrives");
        means.push(xs);
    }
    let diff: Vec<f64> = means[0].iter().zip(&means[1]).map(|(a, b)| a - b).collect();
    let (d, se) = mean_se(&diff);
    let (m, _) = mean_se(&means[0]);
    assert!(m > 0.5 * ENV as f64, "gold reflects most of the red: {m}");
    assert!(d.abs() < 3.0 * se, "light vs hemisphere sampling on the microfacet lobe: {d} (se {se})");
}

// ---------------------------------------------------------------------------------------------
// A closed emitting enclosure of albedo a: L = Le / (1 - a) everywhere, L_k = a^k Le per bounce.

const LE: f32 = 1.0;
const ALBEDO: f32 = 0.5;

fn enclosure(mesh: bool) -> (Scene, Camera) {
    let mut b = SceneBuilder::new();
    let mut mat = Material::diffuse(Vec3::splat(ALBEDO));
    mat.emission = Vec3::splat(LE);
    let m = b.add_material(mat);
    if mesh {
        let s = uv_sphere(12, 24).map_positions(|p| p * 2.0);
        b.add_mesh(&s.positions, &s.indices, m).unwrap();
    } else {
        b.add_sphere(Vec3::ZERO, 2.0, m).unwrap();
    }
    let camera = Camera::look_at(Vec3::new(0.3, -0.2, 0.5), Vec3::new(1.0, 0.4, -1.0), Vec3::Y, 60.0, 1.0, 1e-3, 100.0);
    (commit(b), camera)
}

#[test]
fn closed_enclosure_returns_le_over_one_minus_albedo() {
    let expect = (LE / (1.0 - ALBEDO)) as f64;
    for mesh in [false, true] {
        for hemisphere in [false, true] {
            let (scene, camera) = enclosure(mesh);
            let mut s = settings(24, 24, IntegratorKind::Global);
            s.samples_per_pixel = 32;
            s.max_depth = 100;
            s.hemisphere_sampling = hemisphere;
            let out = render(&scene, &camera, &s);
            let (m, se) = mean_se(&luminance(&out));
            let what = format!("mesh {mesh}, -H {hemisphere}: mean {m} vs {expect} (se {se})");
            eprintln!("enclosure {what}");
            assert!((m / expect - 1.0).abs() < 0.01, "{what}");
            assert!((m - expect).abs() < 4.0 * se + 1e-5, "{what}");
        }
    }
}

#[test]
fn bounce_views_split_the_enclosure_by_bounce() {
    let (scene, camera) = enclosure(false);
    let run = |kind: IntegratorKind, m: u32| {
        let mut s = settings(16, 16, kind);
        s.samples_per_pixel = 32;
        s.max_depth = m;
        mean_se(&luminance(&render(&scene, &camera, &s)))
    };
    let (le, a) = (LE as f64, ALBEDO as f64);
    let cases = [
        ("bounce 0", run(IntegratorKind::Bounce, 0), le),
        ("bounce 1", run(IntegratorKind::Bounce, 1), a * le),
        ("bounce 2", run(IntegratorKind::Bounce, 2), a * a * le),
        ("bounce 3", run(IntegratorKind::Bounce, 3), a.powi(3) * le),
        ("direct", run(IntegratorKind::Direct, 7), le + a * le),
        ("direct-only", run(IntegratorKind::DirectOnly, 7), a * le),
        ("indirect-only", run(IntegratorKind::IndirectOnly, 100), le * a * a / (1.0 - a)),
        ("global -m 2", run(IntegratorKind::Global, 2), le * (1.0 + a + a * a)),
    ];
    for (name, (m, se), expect) in cases {
        eprintln!("enclosure {name}: {m} vs {expect} (se {se})");
        assert!(
            (m / expect - 1.0).abs() < 0.01 && (m - expect).abs() < 4.0 * se + 1e-5,
            "{name}: {m} vs {expect} (se {se})"
        );
    }
}

#[test]
fn russian_roulette_leaves_the_mean_unchanged() {
    // With -m 8 both estimators are cut at the same depth: E = Le Σ_{k<=8} a^k either way.
    let (scene, camera) = enclosure(true);
    let expect = (LE as f64) * (1.0 - (ALBEDO as f64).powi(9)) / (1.0 - ALBEDO as f64);
    let mut s = settings(24, 24, IntegratorKind::Global);
    s.samples_per_pixel = 32;
    s.max_depth = 8;
    let with = render(&scene, &camera, &s);
    s.russian_roulette = false;
    let without = render(&scene, &camera, &s);
    assert!(with.stats.rays.bounce < without.stats.rays.bounce * 3 / 4, "roulette must end paths early");
    let (a, b) = (luminance(&with), luminance(&without));
    let diff: Vec<f64> = a.iter().zip(&b).map(|(x, y)| x - y).collect();
    let (d, se) = mean_se(&diff);
    eprintln!(
        "roulette: mean change {d} (se {se}); bounce rays {} with, {} without",
        with.stats.rays.bounce, without.stats.rays.bounce
    );
    assert!(d.abs() < 3.0 * se + 1e-6, "roulette changes the mean by {d} (se {se})");
    for (name, xs) in [("with", &a), ("without", &b)] {
        let (m, se) = mean_se(xs);
        assert!((m - expect).abs() < 3.5 * se + 1e-5 && (m / expect - 1.0).abs() < 0.01, "{name}: {m} vs {expect}");
    }
}

// ---------------------------------------------------------------------------------------------
// A rectangle light over a floor: Lambert's polygon formula gives each pixel's value.

const LIGHT_Y: f32 = 1.0;
const LIGHT_HALF: f32 = 0.6;
const LIGHT_L: f32 = 4.0;
const FLOOR_ALBEDO: f32 = 0.6;

fn lit_floor(stand_in: bool, area_light: bool) -> (Scene, Camera) {
    let mut b = SceneBuilder::new();
    let floor = b.add_material(Material::diffuse(Vec3::splat(FLOOR_ALBEDO)));
    // Large enough that every pixel sees it.
    let f = 30.0;
    let quad = [Vec3::new(-f, 0.0, -f), Vec3::new(-f, 0.0, f), Vec3::new(f, 0.0, f), Vec3::new(f, 0.0, -f)];
    b.add_mesh(&quad, &[[0, 1, 2], [0, 2, 3]], floor).unwrap();
    let h = LIGHT_HALF;
    if stand_in {
        let e = b.add_material(Material::emissive(Vec3::splat(LIGHT_L)));
        let q = [
            Vec3::new(-h, LIGHT_Y, -h),
            Vec3::new(h, LIGHT_Y, -h),
            Vec3::new(h, LIGHT_Y, h),
            Vec3::new(-h, LIGHT_Y, h),
        ];
        b.add_mesh(&q, &[[0, 1, 2], [0, 2, 3]], e).unwrap();
    }
    if area_light {
        b.add_light(Light::Area {
            radiance: Vec3::splat(LIGHT_L),
            position: Vec3::new(0.0, LIGHT_Y, 0.0),
            direction: -Vec3::Y,
            dim_x: Vec3::new(2.0 * h, 0.0, 0.0),
            dim_y: Vec3::new(0.0, 0.0, 2.0 * h),
        });
    }
    // Below the light, looking down at the floor: the light is out of view.
    let camera =
        Camera::look_at(Vec3::new(0.0, 0.8, 1.6), Vec3::new(0.0, 0.0, 0.2), Vec3::Y, 50.0, 4.0 / 3.0, 1e-3, 100.0);
    (commit(b), camera)
}

/// Lambert's formula: irradiance at `p` (normal +y) from the light's rectangle.
fn floor_irradiance(p: Vec3) -> f64 {
    let h = LIGHT_HALF;
    let poly =
        [Vec3::new(-h, LIGHT_Y, -h), Vec3::new(h, LIGHT_Y, -h), Vec3::new(h, LIGHT_Y, h), Vec3::new(-h, LIGHT_Y, h)];
    let mut e = 0.0f64;
    for i in 0..4 {
        let (a, b) = ((poly[i] - p).normalize(), (poly[(i + 1) % 4] - p).normalize());
        let theta = a.dot(b).clamp(-1.0, 1.0).acos() as f64;
        e += theta * Vec3::Y.dot(a.cross(b).normalize()) as f64;
    }
    0.5 * e.abs() * LIGHT_L as f64
}

/// Expected value of each pixel of a 1-sample-per-pixel (pixel centre) direct-only render.
fn expected_floor(camera: &Camera, w: usize, h: usize) -> Vec<f64> {
    let mut v = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let r = camera.generate_ray((x as f32 + 0.5) / w as f32, 1.0 - (y as f32 + 0.5) / h as f32);
            let p = r.origin + r.dir * (-r.origin.y / r.dir.y);
            assert!(r.dir.y < 0.0 && p.x.abs() < 30.0 && p.z.abs() < 30.0, "every pixel sees the floor");
            v.push(FLOOR_ALBEDO as f64 / std::f64::consts::PI * floor_irradiance(p));
        }
    }
    v
}

#[test]
fn light_and_hemisphere_sampling_agree_with_lamberts_formula() {
    let (w, h) = (32, 24);
    let mut renders = Vec::new();
    // The CS184 arrangement (area light + its emissive stand-in), and emissive triangles alone.
    for (stand_in, area) in [(true, true), (true, false)] {
        let (scene, camera) = lit_floor(stand_in, area);
        let expect = expected_floor(&camera, w, h);
        for hemisphere in [false, true] {
            let mut s = settings(w, h, IntegratorKind::DirectOnly);
            s.light_samples = 256;
            s.hemisphere_sampling = hemisphere;
            let out = render(&scene, &camera, &s);
            assert_eq!(
                out.stats.rays.of(if hemisphere { render::RayKind::Bounce } else { render::RayKind::Shadow }),
                (w * h) as u64 * s.light_samples as u64
            );
            let got = luminance(&out);
            let resid: Vec<f64> = got.iter().zip(&expect).map(|(g, e)| g - e).collect();
            let (d, se) = mean_se(&resid);
            let mean_expect = expect.iter().sum::<f64>() / expect.len() as f64;
            // 3 standard errors: a false alarm has odds of about 1 in 370 per comparison.
            let what = format!("area {area}, -H {hemisphere}: mean residual {d} (se {se}), mean {mean_expect}");
            eprintln!("Lambert {what}");
            assert!(d.abs() < 3.0 * se + 1e-6, "{what}");
            // Light sampling is precise enough (se ≈ 0.1%) to also hold it to 1%.
            assert!(hemisphere || d.abs() < 0.01 * mean_expect, "{what}");
            renders.push(got);
        }
    }
    // Light sampling and hemisphere sampling against each other, pixel by pixel.
    for pair in renders.chunks(2) {
        let diff: Vec<f64> = pair[0].iter().zip(&pair[1]).map(|(a, b)| a - b).collect();
        let (d, se) = mean_se(&diff);
        eprintln!("light vs hemisphere sampling: {d} (se {se})");
        assert!(d.abs() < 3.0 * se, "light vs hemisphere sampling: {d} (se {se})");
    }
}

#[test]
fn delta_lights_are_black_under_hemisphere_sampling() {
    let mut b = SceneBuilder::new();
    let m = b.add_material(Material::diffuse(Vec3::splat(0.8)));
    let quad =
        [Vec3::new(-2.0, 0.0, -2.0), Vec3::new(-2.0, 0.0, 2.0), Vec3::new(2.0, 0.0, 2.0), Vec3::new(2.0, 0.0, -2.0)];
    b.add_mesh(&quad, &[[0, 1, 2], [0, 2, 3]], m).unwrap();
    b.add_light(Light::Point { position: Vec3::new(0.0, 1.0, 0.0), intensity: Vec3::splat(3.0) });
    b.add_light(Light::Directional { direction: Vec3::new(0.3, -1.0, 0.0).normalize(), radiance: Vec3::splat(1.0) });
    let scene = commit(b);
    let camera = Camera::look_at(Vec3::new(0.0, 1.5, 2.5), Vec3::ZERO, Vec3::Y, 50.0, 1.0, 1e-3, 100.0);
    let mut s = settings(16, 16, IntegratorKind::Global);
    s.max_depth = 3;
    let lit = render(&scene, &camera, &s);
    assert!(lit.film.mean().x > 0.1);
    // Point light straight above the centre at height 1: E = I / 1², plus the directional light.
    s.hemisphere_sampling = true;
    let dark = render(&scene, &camera, &s);
    assert!(dark.film.pixels.iter().all(|p| *p == Vec3::ZERO), "CS184's dragon: black under -H");
}

// ---------------------------------------------------------------------------------------------
// Convergence, adaptive sampling, acne, determinism.

/// The slope of log RMSE against log spp on the furnace under -H (every pixel's expected
/// value is exactly L, also at the sphere's silhouette, where jittered samples mix sphere and
/// background), with `sampler`'s numbers.
fn furnace_error_slope(sampler: SamplerKind) -> (f64, Vec<(f64, f64)>) {
    let (scene, camera) = furnace(Material::diffuse(Vec3::ONE));
    let mut pts = Vec::new();
    for spp in [1u32, 4, 16, 64] {
        let mut s = settings(24, 24, IntegratorKind::Direct);
        s.hemisphere_sampling = true;
        s.samples_per_pixel = spp;
        s.sampler = sampler;
        let out = render(&scene, &camera, &s);
        let mse =
            out.film.pixels.iter().map(|p| ((p.x - ENV) as f64).powi(2)).sum::<f64>() / out.film.pixels.len() as f64;
        pts.push(((spp as f64).ln(), mse.sqrt().ln()));
    }
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let slope =
        pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>() / pts.iter().map(|p| (p.0 - mx).powi(2)).sum::<f64>();
    (slope, pts)
}

#[test]
fn error_falls_like_one_over_root_spp() {
    let (slope, pts) = furnace_error_slope(SamplerKind::Independent);
    assert!((slope + 0.5).abs() < 0.05, "log RMSE vs log spp slope {slope}, expected -0.5 ({pts:?})");
}

/// Stratified samples converge faster than independent ones on a smooth integrand: the Sobol'
/// sampler's error falls more steeply than `1 / sqrt(spp)`, and is lower at every count past 1.
#[test]
fn sobol_error_falls_faster_than_one_over_root_spp() {
    let (slope, pts) = furnace_error_slope(SamplerKind::Sobol);
    let (_, independent) = furnace_error_slope(SamplerKind::Independent);
    assert!(slope < -0.65, "log RMSE vs log spp slope {slope}, expected steeper than -0.5 ({pts:?})");
    for (s, i) in pts.iter().zip(&independent).skip(1) {
        assert!(s.1 < i.1, "at spp {:.0}: log RMSE {} (sobol) against {} (independent)", s.0.exp(), s.1, i.1);
    }
}

#[test]
fn adaptive_sampling_stops_early_only_where_flat() {
    let (w, h) = (24, 24);
    let mut b = SceneBuilder::new();
    let floor = b.add_material(Material::diffuse(Vec3::splat(0.6)));
    let q =
        [Vec3::new(-4.0, 0.0, -4.0), Vec3::new(-4.0, 0.0, 4.0), Vec3::new(4.0, 0.0, 4.0), Vec3::new(4.0, 0.0, -4.0)];
    b.add_mesh(&q, &[[0, 1, 2], [0, 2, 3]], floor).unwrap();
    let e = b.add_material(Material::emissive(Vec3::splat(5.0)));
    // A small light high above, out of view: under -H the floor below is very noisy.
    let l =
        [Vec3::new(-0.3, 3.0, -0.3), Vec3::new(0.3, 3.0, -0.3), Vec3::new(0.3, 3.0, 0.3), Vec3::new(-0.3, 3.0, 0.3)];
    b.add_mesh(&l, &[[0, 1, 2], [0, 2, 3]], e).unwrap();
    b.add_light(Light::Environment { radiance: Vec3::splat(0.2) });
    let scene = commit(b);
    // Horizon across the middle of the image: sky (flat) above, floor (noisy under -H) below.
    let camera = Camera::look_at(Vec3::new(0.0, 0.5, 3.0), Vec3::new(0.0, 0.5, 0.0), Vec3::Y, 40.0, 1.0, 1e-3, 100.0);
    let mut s = settings(w, h, IntegratorKind::Direct);
    s.hemisphere_sampling = true;
    s.samples_per_pixel = 512;
    s.adaptive = Some((32, 0.05));
    let out = render(&scene, &camera, &s);
    let (mut sky, mut ground) = (Vec::new(), Vec::new());
    for y in 0..h {
        for x in 0..w {
            let r = camera.generate_ray((x as f32 + 0.5) / w as f32, 1.0 - (y as f32 + 0.5) / h as f32);
            let n = out.samples_per_pixel[y * w + x];
            assert!((32..=512).contains(&n) && n.is_multiple_of(32), "samples come in whole batches: {n}");
            if r.dir.y > 0.02 {
                sky.push(n);
                assert!((out.film.get(x, y).x - 0.2).abs() < 1e-6, "the mean of the samples taken");
            } else if r.dir.y < -0.1 {
                ground.push(n);
            }
        }
    }
    assert!(!sky.is_empty() && !ground.is_empty());
    eprintln!(
        "adaptive: sky pixels {} (max {:?} samples), floor mean {:.1} samples",
        sky.len(),
        sky.iter().max(),
        ground.iter().map(|&n| n as f64).sum::<f64>() / ground.len() as f64
    );
    assert!(sky.iter().all(|&n| n == 32), "flat sky stops after the first batch: {sky:?}");
    let mean_ground = ground.iter().map(|&n| n as f64).sum::<f64>() / ground.len() as f64;
    assert!(mean_ground > 400.0, "the noisy floor keeps sampling: {mean_ground}");
    assert_eq!(out.stats.samples, out.samples_per_pixel.iter().map(|&n| n as u64).sum::<u64>());
}

#[test]
fn no_acne_far_from_the_origin() {
    // A plane and a sphere translated far away, lit by a grazing directional light: every lit
    // pixel of the plane has the closed-form value; self-shadowing would blacken some.
    let off = Vec3::new(1.5e3, -1.0e3, 0.7e3);
    let mut b = SceneBuilder::new();
    let m = b.add_material(Material::diffuse(Vec3::splat(0.5)));
    let f = 50.0;
    let quad =
        [Vec3::new(-f, 0.0, -f), Vec3::new(-f, 0.0, f), Vec3::new(f, 0.0, f), Vec3::new(f, 0.0, -f)].map(|p| p + off);
    b.add_mesh(&quad, &[[0, 1, 2], [0, 2, 3]], m).unwrap();
    b.add_sphere(off + Vec3::new(0.0, 3.0, 0.0), 2.0, m).unwrap();
    let dir = Vec3::new(1.0, -0.2, 0.3).normalize();
    b.add_light(Light::Directional { direction: dir, radiance: Vec3::splat(2.0) });
    let scene = commit(b);
    let camera =
        Camera::look_at(off + Vec3::new(0.0, 6.0, 12.0), off + Vec3::new(0.0, 1.0, 0.0), Vec3::Y, 60.0, 1.0, 1e-2, 1e3);
    let (w, h) = (48, 48);
    let out = render(&scene, &camera, &settings(w, h, IntegratorKind::Direct));
    let plane_value = 0.5 / std::f32::consts::PI * 2.0 * (-dir).dot(Vec3::Y);
    let (mut plane_lit, mut sphere_lit) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let ray = camera.generate_ray((x as f32 + 0.5) / w as f32, 1.0 - (y as f32 + 0.5) / h as f32);
            let hit = scene.intersect1(&ray);
            if !hit.is_hit() {
                continue;
            }
            let s = scene.surface(&ray, &hit);
            let v = out.film.get(x, y).x;
            if hit.prim < 2 {
                // Plane pixels clearly outside the sphere's shadow: test the shadow ray
                // ourselves from above the plane, where offsetting is no issue.
                let probe = |h: f32| scene.occluded1(&raypack::Ray::new(s.position + Vec3::Y * h, -dir));
                if !probe(0.02) && !probe(0.2) {
                    assert!((v - plane_value).abs() < 1e-3, "plane pixel ({x},{y}) = {v}, expected {plane_value}");
                    plane_lit += 1;
                }
            } else if s.geometric_normal.dot(-dir) > 0.1 {
                let expect = 0.5 / std::f32::consts::PI * 2.0 * s.geometric_normal.dot(-dir);
                assert!((v - expect).abs() < 2e-3, "sphere pixel ({x},{y}) = {v}, expected {expect}");
                sphere_lit += 1;
            }
        }
    }
    assert!(plane_lit > 500 && sphere_lit > 30, "{plane_lit} {sphere_lit}");
}

#[test]
fn same_seed_same_image_with_one_or_two_threads() {
    let mut b = SceneBuilder::new();
    let white = b.add_material(Material::diffuse(Vec3::splat(0.7)));
    let glass = b.add_material(Material::glass(1.5));
    let mirror = b.add_material(Material::mirror(Vec3::splat(0.9)));
    let light = b.add_material(Material::emissive(Vec3::splat(8.0)));
    let s = uv_sphere(8, 16).map_positions(|p| p * 3.0);
    let inverted: Vec<[u32; 3]> = s.indices.iter().map(|&[a, b, c]| [a, c, b]).collect();
    b.add_mesh(&s.positions, &inverted, white).unwrap();
    b.add_sphere(Vec3::new(-0.8, -0.5, 0.0), 0.7, glass).unwrap();
    b.add_sphere(Vec3::new(0.9, -0.6, -0.4), 0.6, mirror).unwrap();
    b.add_sphere(Vec3::new(0.0, 2.2, 0.0), 0.4, light).unwrap();
    b.add_light(Light::Point { position: Vec3::new(1.0, 1.0, 1.0), intensity: Vec3::splat(0.5) });
    let scene = commit(b);
    let camera = Camera::look_at(Vec3::new(0.0, 0.0, 2.5), Vec3::ZERO, Vec3::Y, 70.0, 1.5, 1e-3, 100.0);
    let mut s = settings(45, 30, IntegratorKind::Global);
    s.samples_per_pixel = 64;
    s.adaptive = Some((8, 0.1));
    s.max_depth = 6;
    s.seed = 42;
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| render(&scene, &camera, &s))
    };
    let (one, two) = (run(1), run(2));
    assert!(
        one.film
            .pixels
            .iter()
            .zip(&two.film.pixels)
            .all(|(a, b)| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits))
    );
    assert_eq!(one.samples_per_pixel, two.samples_per_pixel);
    assert_eq!(one.stats.rays, two.stats.rays);
    // A different seed gives a different image (the seed is really used).
    s.seed = 43;
    assert_ne!(render(&scene, &camera, &s).film.pixels, one.film.pixels);
}
