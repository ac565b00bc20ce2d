//! The wavefront renderer: the order in which a bounce's shadow and continuation rays are
//! traced (and so which rays share a packet, and the order paths are shaded in) never changes
//! the image, bit for bit, nor the rays traced; and every phase's time is accounted for.

use raypack::generate::uv_sphere;
use raypack::render::{self, IntegratorKind, RayOrder, RenderOutput, RenderSettings, StreamOrder};
use raypack::{BuildOptions, Camera, Light, Material, Scene, SceneBuilder, Vec3};

/// A closed diffuse room with glass, mirror, rough metal, an emissive sphere, a rectangle
/// light and a point light: every kind of BSDF and light, several shadow rays per point.
fn room() -> (Scene, Camera) {
    let mut b = SceneBuilder::new();
    let white = b.add_material(Material::diffuse(Vec3::splat(0.7)));
    let glass = b.add_material(Material::glass(1.5));
    let mirror = b.add_material(Material::mirror(Vec3::splat(0.9)));
    let metal = b.add_material(Material {
        name: "metal".into(),
        bsdf: raypack::Bsdf::Microfacet { eta: Vec3::splat(0.2), k: Vec3::splat(3.0), alpha: 0.3 },
        emission: Vec3::ZERO,
    });
    let light = b.add_material(Material::emissive(Vec3::splat(6.0)));
    let s = uv_sphere(8, 16).map_positions(|p| p * 3.0);
    let inverted: Vec<[u32; 3]> = s.indices.iter().map(|&[a, b, c]| [a, c, b]).collect();
    b.add_mesh(&s.positions, &inverted, white).unwrap();
    b.add_sphere(Vec3::new(-0.8, -0.5, 0.0), 0.7, glass).unwrap();
    b.add_sphere(Vec3::new(0.9, -0.6, -0.4), 0.6, mirror).unwrap();
    b.add_sphere(Vec3::new(0.2, 0.6, -0.9), 0.5, metal).unwrap();
    b.add_sphere(Vec3::new(0.0, 2.2, 0.0), 0.4, light).unwrap();
    b.add_light(Light::Point { position: Vec3::new(1.0, 1.0, 1.0), intensity: Vec3::splat(0.5) });
    b.add_light(Light::Area {
        radiance: Vec3::splat(3.0),
        position: Vec3::new(0.0, 2.5, 0.5),
        direction: -Vec3::Y,
        dim_x: Vec3::new(0.5, 0.0, 0.0),
        dim_y: Vec3::new(0.0, 0.0, 0.5),
    });
    let (scene, report) = b.commit(&BuildOptions::default());
    assert_eq!(report.dropped(), 0);
    let camera = Camera::look_at(Vec3::new(0.0, 0.0, 2.5), Vec3::ZERO, Vec3::Y, 70.0, 1.5, 1e-3, 100.0);
    (scene, camera)
}

fn bits(out: &RenderOutput) -> Vec<[u32; 3]> {
    out.film.pixels.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
}

#[test]
fn ray_order_never_changes_the_image() {
    let (scene, camera) = room();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    // The last case queues more direct samples per bounce than the wavefront holds at once
    // (64 per area light), so that shading stops to trace them part way.
    for (integrator, hemisphere, adaptive, light_samples) in [
        (IntegratorKind::Global, false, None, 2),
        (IntegratorKind::Global, true, None, 2),
        (IntegratorKind::IndirectOnly, false, Some((4, 0.2)), 2),
        (IntegratorKind::Direct, false, None, 64),
    ] {
        let mut s = RenderSettings {
            width: 30,
            height: 20,
            samples_per_pixel: 8,
            light_samples,
            max_depth: 6,
            hemisphere_sampling: hemisphere,
            adaptive,
            integrator,
            seed: 5,
            ..RenderSettings::default()
        };
        let mut render = |order: StreamOrder| {
            s.stream_order = Some(order);
            pool.install(|| render::render(&scene, &camera, &s, &|_| {}))
        };
        let reference = render(StreamOrder { shadow: RayOrder::Queued, bounce: RayOrder::Queued });
        let mean = reference.film.mean();
        assert!(mean.is_finite() && mean.max_element() > 0.01, "{integrator:?} -H {hemisphere}: mean {mean}");
        assert!(reference.stats.rays.shadow > 0 || hemisphere);
        for shadow in RayOrder::ALL {
            for bounce in RayOrder::ALL {
                let out = render(StreamOrder { shadow, bounce });
                let what = format!("{integrator:?} -H {hemisphere}, shadow {shadow:?}, bounce {bounce:?}");
                assert!(bits(&out) == bits(&reference), "{what}: the image differs");
                assert_eq!(out.stats.rays, reference.stats.rays, "{what}");
                assert_eq!(out.samples_per_pixel, reference.samples_per_pixel, "{what}");
            }
        }
    }
}

#[test]
fn phases_add_up_to_the_thread_time() {
    let (scene, camera) = room();
    let s = RenderSettings { width: 32, height: 32, samples_per_pixel: 4, max_depth: 4, ..RenderSettings::default() };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let out = pool.install(|| render::render(&scene, &camera, &s, &|_| {}));
    let p = out.stats.phases;
    // On one thread the phases partition (most of) the render's wall-clock time.
    assert!(p.total() <= out.stats.time, "{p:?} vs {:?}", out.stats.time);
    assert!(out.stats.rays.camera == 32 * 32 * 4 && out.stats.rays.bounce > 0 && out.stats.rays.shadow > 0);
}

/// Pixels whose camera rays cannot hit the scene are given a miss's value without tracing:
/// the image, the samples per pixel and the rays traced beside them are what tracing every
/// camera ray gives, bit for bit, for every integrator view, with an environment light
/// (misses are not black), adaptive sampling, a clamp, and sample counts that cull single
/// pixels (16), 2 x 2 blocks (4) and 4 x 4 blocks (1).
#[test]
fn culled_pixels_get_the_value_their_rays_would() {
    let mut b = SceneBuilder::new();
    let white = b.add_material(Material::diffuse(Vec3::splat(0.7)));
    let glass = b.add_material(Material::glass(1.5));
    let s = uv_sphere(8, 16).map_positions(|p| p * 0.6 + Vec3::new(-0.5, 0.0, 0.0));
    b.add_mesh(&s.positions, &s.indices, white).unwrap();
    b.add_sphere(Vec3::new(0.7, 0.2, 0.0), 0.4, glass).unwrap();
    b.add_light(Light::Point { position: Vec3::new(1.0, 2.0, 1.0), intensity: Vec3::splat(2.0) });
    b.add_light(Light::Environment { radiance: Vec3::new(0.3, 0.4, 0.5) });
    let (scene, _) = b.commit(&BuildOptions::default());
    let camera = Camera::look_at(Vec3::new(0.0, 0.5, 4.0), Vec3::ZERO, Vec3::Y, 50.0, 1.5, 1e-3, 100.0);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let kinds = [
        IntegratorKind::Normals,
        IntegratorKind::Direct,
        IntegratorKind::Global,
        IntegratorKind::DirectOnly,
        IntegratorKind::IndirectOnly,
        IntegratorKind::Bounce,
    ];
    for (case, integrator) in kinds.into_iter().enumerate() {
        for spp in [16, 4, 1] {
            let mut s = RenderSettings {
                width: 45,
                height: 30,
                samples_per_pixel: spp,
                max_depth: 3,
                integrator,
                adaptive: (case % 2 == 0 && spp > 1).then_some((2, 0.05)),
                max_sample_value: (case == 2).then_some(0.35),
                seed: case as u64,
                ..RenderSettings::default()
            };
            let mut render = |culling: bool| {
                s.pixel_culling = culling;
                pool.install(|| render::render(&scene, &camera, &s, &|_| {}))
            };
            let (all, culled) = (render(false), render(true));
            let what = format!("{integrator:?}, {spp} spp");
            assert!(bits(&culled) == bits(&all), "{what}: the image differs");
            assert_eq!(culled.samples_per_pixel, all.samples_per_pixel, "{what}");
            assert_eq!(all.stats.culled_samples, 0, "{what}");
            assert!(culled.stats.culled_samples > all.stats.samples / 4, "{what}: {:?}", culled.stats.culled_samples);
            assert_eq!(culled.stats.samples, all.stats.samples, "{what}");
            assert_eq!(culled.stats.rays.camera + culled.stats.culled_samples, all.stats.rays.camera, "{what}");
            assert_eq!(culled.stats.clamped_samples, all.stats.clamped_samples, "{what}");
            // (Exactly three bounces off this open scene is too rare for 1 sample per pixel.)
            let lit = all.film.mean().max_element();
            assert!(lit > 0.0 || integrator == IntegratorKind::Bounce, "{what}: black image");
        }
    }
}
