//! The traversal-cost heatmap counts the real kernel's work: each pixel's counts equal the
//! counters of the single-ray BVH8 kernels for the same ray traced directly, for camera and
//! shadow rays, on the built-in Cornell box and on third-party scenes (CBbunny, building).

mod common;

use raypack::bvh::TraversalCounts;
use raypack::render::camera::CameraRays;
use raypack::render::heatmap::{self, HeatmapRays, HeatmapScale, HeatmapView};
use raypack::{BuildOptions, Scene};

fn check(scene: &Scene, name: &str, width: usize, height: usize) {
    let camera = scene.camera_or_framing(width as f32 / height as f32);
    let rays = CameraRays::new(&camera);
    for which in [HeatmapRays::Camera, HeatmapRays::Shadow] {
        let counts = heatmap::trace_counts(scene, &camera, width, height, which).unwrap();
        assert_eq!((counts.nodes.len(), counts.tests.len()), (width * height, width * height));
        let light = scene.lights[0];
        let mut total = TraversalCounts::default();
        let mut hits = 0;
        for y in 0..height {
            for x in 0..width {
                let ray = heatmap::pixel_ray(&rays, x, y, width, height);
                let mut c = TraversalCounts::default();
                match which {
                    HeatmapRays::Camera => {
                        // The same hit as the uncounted query: the counted kernel is the one
                        // that traces.
                        let hit = scene.counting(&mut c).intersect1(&ray);
                        assert_eq!(hit, scene.intersect1(&ray));
                        // A hit was found by testing a block.
                        assert!(!hit.is_hit() || c.blocks >= 1, "{name} pixel ({x}, {y}): {c:?}");
                        hits += hit.is_hit() as usize;
                    }
                    HeatmapRays::Shadow => {
                        if let Some(s) = heatmap::shadow_ray(scene, &light, &ray) {
                            let occ = scene.counting(&mut c).occluded1(&s);
                            assert_eq!(occ, scene.occluded1(&s));
                            assert!(!occ || c.blocks >= 1, "{name} pixel ({x}, {y}): {c:?}");
                            hits += 1;
                        }
                    }
                }
                let i = y * width + x;
                assert_eq!(
                    (counts.nodes[i] as u64, counts.tests[i] as u64),
                    (c.nodes, c.blocks),
                    "{name} {which:?} pixel ({x}, {y})"
                );
                total += c;
            }
        }
        // The scene is in view (most camera rays hit, so most pixels cast a shadow ray), and
        // the rays did work.
        assert!(hits > width * height / 10, "{name} {which:?}: {hits} rays");
        assert!(total.nodes > 0 && total.blocks > 0, "{name} {which:?}: {total:?}");
        for view in [HeatmapView::Nodes, HeatmapView::Tests, HeatmapView::Both] {
            let img = counts.image(view);
            assert_eq!(img.rgb.len(), img.width * img.height * 3);
            assert!(img.height > height);
            // The pixel with the most work is drawn in viridis' top colour.
            let counts_of = if view == HeatmapView::Tests { &counts.tests } else { &counts.nodes };
            let max = *counts_of.iter().max().unwrap();
            let at = counts_of.iter().position(|&c| c == max).unwrap();
            let px = ((img.top + at / width) * img.width + at % width) * 3;
            assert_eq!(&img.rgb[px..][..3], &heatmap::colour(max, max));
            // Every scale draws the costliest pixel in the top colour and 0 in the bottom one.
            for scale in [HeatmapScale::Log, HeatmapScale::Percentile(90.0)] {
                let img = counts.image_scaled(view, scale);
                assert_eq!(&img.rgb[px..][..3], &heatmap::colour(max, max), "{scale:?}");
                if let Some(zero) = counts_of.iter().position(|&c| c == 0) {
                    let pz = ((img.top + zero / width) * img.width + zero % width) * 3;
                    assert_eq!(&img.rgb[pz..][..3], &heatmap::colour(0, max), "{scale:?}");
                }
            }
        }
    }
}

#[test]
fn heatmap_counts_equal_kernel_counters_on_the_cornell_box() {
    let (scene, _) = raypack::io::default_scene().commit(&BuildOptions::default());
    check(&scene, "cornell", 96, 72);
}

#[test]
fn heatmap_counts_equal_kernel_counters_on_third_party_scenes() {
    let Some(dir) = common::scenes_dir("heatmap_counts_equal_kernel_counters_on_third_party_scenes") else {
        return;
    };
    for rel in ["cs184/sky/CBbunny.dae", "cs184/keenan/building.dae"] {
        let builder = raypack::io::load_scene(&dir.join(rel)).unwrap().builder;
        let (scene, _) = builder.commit(&BuildOptions::default());
        check(&scene, rel, 64, 48);
    }
}

#[test]
fn shadow_heatmap_needs_a_light() {
    let mesh = raypack::generate::grid(4, 4);
    let scene = common::scene_of(&[&mesh], &[], &BuildOptions::default());
    let camera = scene.camera_or_framing(1.0);
    assert_eq!(
        heatmap::trace_counts(&scene, &camera, 8, 8, HeatmapRays::Shadow).unwrap_err(),
        heatmap::HeatmapError::NoLight
    );
    assert!(heatmap::trace_counts(&scene, &camera, 8, 8, HeatmapRays::Camera).is_ok());
}

/// The log scale and a percentile spread counts that a linear scale draws in nearly one
/// colour: counts 1..=100 but one pixel at 10,000.
#[test]
fn log_and_percentile_scales_spread_a_skewed_image() {
    let (width, height) = (101, 1);
    let mut tests: Vec<u32> = (1..=100).collect();
    tests.push(10_000);
    let counts = heatmap::HeatmapCounts { width, height, nodes: tests.clone(), tests };
    let distinct = |scale| {
        let img = counts.image_scaled(HeatmapView::Tests, scale);
        let row = &img.rgb[img.top * img.width * 3..(img.top + 1) * img.width * 3];
        let mut colours: Vec<&[u8]> = row.chunks(3).collect();
        colours.sort();
        colours.dedup();
        colours.len()
    };
    let (linear, log, p99) =
        (distinct(HeatmapScale::Linear), distinct(HeatmapScale::Log), distinct(HeatmapScale::Percentile(99.0)));
    assert!(linear < 15, "linear: {linear} colours");
    assert!(log > 40 && p99 > 80, "log {log}, p99 {p99} colours");
    assert_eq!(heatmap::percentile(&counts.tests, 99.0), 100);
    assert_eq!(heatmap::percentile(&counts.tests, 100.0), 10_000);
    // Of the pixels that did work: zeros (rays that hit nothing) do not pull it down.
    assert_eq!(heatmap::percentile(&[0, 0, 0, 0, 0, 0, 0, 0, 3, 5], 90.0), 5);
    assert_eq!(heatmap::percentile(&[0, 0], 90.0), 0);
}

/// `render` with `IntegratorKind::Heatmap` is the heatmap mode: its picture is the one drawn
/// from `trace_counts` with the settings' view and scale, a window's counts are those pixels'
/// counts in the whole image, and a shadow heatmap without a light is the error, not a picture.
#[test]
fn render_in_heatmap_mode_returns_the_heatmap() {
    use raypack::render::heatmap::HeatmapSettings;
    use raypack::render::{IntegratorKind, PixelBounds, RenderSettings};
    let (scene, _) = raypack::io::default_scene().commit(&BuildOptions::default());
    let (width, height) = (48, 36);
    let camera = scene.camera_or_framing(width as f32 / height as f32);
    let heatmap = HeatmapSettings { rays: HeatmapRays::Shadow, view: HeatmapView::Both, scale: HeatmapScale::Log };
    let settings = RenderSettings { width, height, integrator: IntegratorKind::Heatmap, heatmap, ..Default::default() };
    let out = raypack::render::render(&scene, &camera, &settings, &|_| {});
    let made = out.heatmap.expect("a heatmap").expect("the box has lights");
    let counts = heatmap::trace_counts(&scene, &camera, width, height, HeatmapRays::Shadow).unwrap();
    assert_eq!(made.counts, counts);
    assert_eq!(made.image, counts.image_scaled(HeatmapView::Both, HeatmapScale::Log));
    assert_eq!((out.film.width, out.film.height), (width, height));

    let window = PixelBounds { x0: 5, x1: 30, y0: 7, y1: 20 };
    let part = raypack::render::render_window(&scene, &camera, &settings, &window, &|_| {});
    let part = part.heatmap.unwrap().unwrap().counts;
    assert_eq!((part.width, part.height), (25, 13));
    for y in 7..20 {
        for x in 5..30 {
            let (i, j) = ((y - 7) * 25 + x - 5, y * width + x);
            assert_eq!((part.nodes[i], part.tests[i]), (counts.nodes[j], counts.tests[j]), "pixel ({x}, {y})");
        }
    }

    let dark = common::scene_of(&[&raypack::generate::grid(4, 4)], &[], &BuildOptions::default());
    let out = raypack::render::render(&dark, &dark.camera_or_framing(1.0), &settings, &|_| {});
    assert_eq!(out.heatmap, Some(Err(heatmap::HeatmapError::NoLight)));
    let path = RenderSettings { integrator: IntegratorKind::Global, ..settings };
    assert!(raypack::render::render(&scene, &camera, &path, &|_| {}).heatmap.is_none());
}
