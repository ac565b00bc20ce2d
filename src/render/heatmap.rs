//! Traversal-cost heatmaps: each pixel coloured by the work the BVH8 kernel did for its ray.
//!
//! One ray per pixel, through the pixel's centre, traced by the single-ray kernels that
//! answer [`Scene::intersect1`] and [`Scene::occluded1`], each with its own
//! [`TraversalCounts`] ([`Scene::counting`]: its `intersect1`, `occluded1`). The
//! counts are therefore the real kernel's work, not a separate walk that could drift from it:
//! `nodes` is [`TraversalCounts::nodes`] (inner nodes visited, each an 8-box test) and `tests`
//! is [`TraversalCounts::blocks`] (primitive blocks tested, each up to M triangles or 4
//! spheres at once). The image maps a count linearly onto viridis, 0 to the largest count of
//! the view (or its logarithm, or up to a percentile: [`HeatmapScale`]), each half titled, with
//! a colour bar labelled with round counts and the mean below it ([`super::colorbar`]).
//!
//! It is a render mode: [`super::render`] with [`super::IntegratorKind::Heatmap`] returns it
//! ([`super::RenderOutput::heatmap`], made by [`render_window`] from
//! [`super::RenderSettings::heatmap`]); the CLI only chooses it and writes the picture.

use super::camera::CameraRays;
#[cfg(feature = "image")]
use super::colorbar;
use super::spawn::{spawn_ray, spawn_ray_to};
use super::window::PixelBounds;
use crate::bvh::TraversalCounts;
use crate::ray::Ray;
use crate::scene::{Camera, Light, Scene};
use rayon::prelude::*;

/// Which rays the heatmap counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HeatmapRays {
    /// The camera ray of each pixel (closest hit).
    #[default]
    Camera,
    /// From the point each camera ray hits, an occlusion ray toward the scene's first light
    /// (its position; area lights: their centre; directional: against their direction;
    /// environment: along the surface normal). Pixels whose camera ray misses count 0.
    Shadow,
}

/// Which counts the image shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HeatmapView {
    /// Inner nodes visited.
    #[default]
    Nodes,
    /// Primitive-block tests.
    Tests,
    /// Nodes on the left, tests on the right, each with its own colour bar.
    Both,
}

/// Why a heatmap cannot be made.
#[derive(Clone, Debug, thiserror::Error, PartialEq, Eq)]
pub enum HeatmapError {
    /// `--heatmap-rays shadow` on a scene without a light.
    #[error("shadow-ray heatmap: the scene has no light to cast shadow rays toward")]
    NoLight,
}

/// What a heatmap render ([`super::IntegratorKind::Heatmap`]) shows.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HeatmapSettings {
    /// The rays counted.
    pub rays: HeatmapRays,
    /// The counts drawn.
    pub view: HeatmapView,
    /// How counts map to colours.
    pub scale: HeatmapScale,
}

/// What a heatmap render makes: the counts of every pixel of its window and, with the cargo
/// feature `image`, their picture.
#[derive(Clone, Debug, PartialEq)]
pub struct Heatmap {
    /// The rays counted.
    pub rays: HeatmapRays,
    /// The kernel's work per pixel of the window.
    pub counts: HeatmapCounts,
    /// The picture of [`HeatmapSettings::view`] on [`HeatmapSettings::scale`].
    #[cfg(feature = "image")]
    pub image: HeatmapImage,
}

/// The heatmap of `window`'s pixels of the image `settings` describe, as `settings.heatmap`
/// asks: what [`super::render_window`] returns for [`super::IntegratorKind::Heatmap`].
pub fn render_window(
    scene: &Scene,
    camera: &Camera,
    settings: &super::RenderSettings,
    window: &PixelBounds,
) -> Result<Heatmap, HeatmapError> {
    let h = &settings.heatmap;
    let counts = trace_counts_window(scene, camera, settings.width, settings.height, window, h.rays)?;
    Ok(Heatmap {
        rays: h.rays,
        #[cfg(feature = "image")]
        image: counts.image_scaled(h.view, h.scale),
        counts,
    })
}

/// Per-pixel traversal work, row-major, top row first.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HeatmapCounts {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Inner nodes visited per pixel ([`TraversalCounts::nodes`]).
    pub nodes: Vec<u32>,
    /// Primitive blocks tested per pixel ([`TraversalCounts::blocks`]).
    pub tests: Vec<u32>,
}

/// The camera ray through the centre of pixel `(x, y)`.
pub fn pixel_ray(rays: &CameraRays, x: usize, y: usize, width: usize, height: usize) -> Ray {
    rays.ray(x as f32 + 0.5, y as f32 + 0.5, width, height)
}

/// The shadow ray toward `light` from where `camera_ray` hits, if it hits.
pub fn shadow_ray(scene: &Scene, light: &Light, camera_ray: &Ray) -> Option<Ray> {
    let hit = scene.intersect1(camera_ray);
    if !hit.is_hit() {
        return None;
    }
    let s = scene.surface(camera_ray, &hit);
    let (p, ng) = (s.position, s.geometric_normal);
    match *light {
        Light::Point { position, .. } | Light::Spot { position, .. } | Light::Area { position, .. } => {
            spawn_ray_to(p, ng, position)
        }
        Light::Directional { direction, .. } => Some(spawn_ray(p, ng, -direction)),
        Light::Environment { .. } => Some(spawn_ray(p, ng, super::spawn::toward(ng, -camera_ray.dir))),
    }
}

/// Counts the kernel's work for one ray per pixel of a `width × height` image seen by
/// `camera` (in parallel over rows on the current rayon pool; the counts do not depend on it).
pub fn trace_counts(
    scene: &Scene,
    camera: &Camera,
    width: usize,
    height: usize,
    which: HeatmapRays,
) -> Result<HeatmapCounts, HeatmapError> {
    trace_counts_window(scene, camera, width, height, &PixelBounds::full(width, height), which)
}

/// [`trace_counts`] of the pixels of `window` only (inside the `width × height` image): each
/// pixel's counts are those it has in the whole image.
pub fn trace_counts_window(
    scene: &Scene,
    camera: &Camera,
    width: usize,
    height: usize,
    window: &PixelBounds,
    which: HeatmapRays,
) -> Result<HeatmapCounts, HeatmapError> {
    let light = match which {
        HeatmapRays::Camera => None,
        HeatmapRays::Shadow => Some(*scene.lights.first().ok_or(HeatmapError::NoLight)?),
    };
    let rays = CameraRays::new(camera);
    let rows: Vec<(Vec<u32>, Vec<u32>)> = (window.y0..window.y1)
        .into_par_iter()
        .map(|y| {
            let mut row = (Vec::with_capacity(window.width()), Vec::with_capacity(window.width()));
            for x in window.x0..window.x1 {
                let ray = pixel_ray(&rays, x, y, width, height);
                let mut c = TraversalCounts::default();
                match &light {
                    None => {
                        scene.counting(&mut c).intersect1(&ray);
                    }
                    Some(light) => {
                        if let Some(shadow) = shadow_ray(scene, light, &ray) {
                            scene.counting(&mut c).occluded1(&shadow);
                        }
                    }
                }
                row.0.push(saturate(c.nodes));
                row.1.push(saturate(c.blocks));
            }
            row
        })
        .collect();
    let mut out =
        HeatmapCounts { width: window.width(), height: window.height(), nodes: Vec::new(), tests: Vec::new() };
    for (n, t) in rows {
        out.nodes.extend(n);
        out.tests.extend(t);
    }
    Ok(out)
}

fn saturate(n: u64) -> u32 {
    n.min(u32::MAX as u64) as u32
}

/// A coloured heatmap (cargo feature `image`): 8-bit RGB, row-major, top row first.
#[cfg(feature = "image")]
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HeatmapImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels (the title's, the image's and the colour bar's).
    pub height: usize,
    /// `width × height × 3` bytes.
    pub rgb: Vec<u8>,
    /// The row at which the counts' pixels start (below the title).
    pub top: usize,
}

/// How counts map to colours.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum HeatmapScale {
    /// Linear from 0 to the largest count.
    #[default]
    Linear,
    /// `ln(1 + count)`: the many cheap pixels spread over the colours when a few are costly.
    Log,
    /// Linear from 0 to this percentile (in (0, 100]) of the nonzero counts ([`percentile`]);
    /// counts above it in the top colour.
    Percentile(f64),
}

/// The viridis colour of `count` on a scale from 0 to `max` (`max` 0: everything is 0).
#[cfg(feature = "image")]
pub fn colour(count: u32, max: u32) -> [u8; 3] {
    let f = if max == 0 { 0.0 } else { count as f64 / max as f64 };
    viridis(f)
}

#[cfg(feature = "image")]
fn viridis(f: f64) -> [u8; 3] {
    colorous::VIRIDIS.eval_continuous(f.clamp(0.0, 1.0)).as_array()
}

/// The `p`-th percentile of the nonzero `counts` (nearest rank; 0 when there are none): of
/// the pixels whose ray did any work, so that the pixels that see nothing (no block tests
/// where the camera ray misses) do not pull it to 0.
pub fn percentile(counts: &[u32], p: f64) -> u32 {
    let mut sorted: Vec<u32> = counts.iter().copied().filter(|&c| c > 0).collect();
    if sorted.is_empty() {
        return 0;
    }
    let rank = ((p.clamp(0.0, 100.0) / 100.0 * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    *sorted.select_nth_unstable(rank - 1).1
}

#[cfg(feature = "image")]
impl HeatmapCounts {
    /// The image of `view` on a linear scale ([`HeatmapCounts::image_scaled`]).
    pub fn image(&self, view: HeatmapView) -> HeatmapImage {
        self.image_scaled(view, HeatmapScale::Linear)
    }

    /// The image of `view`: each half with its title above ("nodes visited", "primitive-block
    /// tests") and its colour bar beneath, labelled with round values, the mean marked on it.
    pub fn image_scaled(&self, view: HeatmapView, scale: HeatmapScale) -> HeatmapImage {
        match view {
            HeatmapView::Nodes => self.one(&self.nodes, "NODES VISITED", scale),
            HeatmapView::Tests => self.one(&self.tests, "PRIMITIVE-BLOCK TESTS", scale),
            HeatmapView::Both => {
                let (a, b) =
                    (self.one(&self.nodes, "NODES VISITED", scale), self.one(&self.tests, "BLOCK TESTS", scale));
                let gap = 4;
                let width = a.width + gap + b.width;
                let mut rgb = vec![255u8; width * a.height * 3];
                for y in 0..a.height {
                    let row = &mut rgb[y * width * 3..(y + 1) * width * 3];
                    row[..a.width * 3].copy_from_slice(&a.rgb[y * a.width * 3..(y + 1) * a.width * 3]);
                    row[(a.width + gap) * 3..].copy_from_slice(&b.rgb[y * b.width * 3..(y + 1) * b.width * 3]);
                }
                HeatmapImage { width, height: a.height, rgb, top: a.top }
            }
        }
    }

    fn one(&self, counts: &[u32], title: &str, scale: HeatmapScale) -> HeatmapImage {
        let max = counts.iter().copied().max().unwrap_or(0) as f64;
        let bar_scale = match scale {
            HeatmapScale::Linear => colorbar::Scale::Linear { max },
            HeatmapScale::Log => colorbar::Scale::Log { max },
            HeatmapScale::Percentile(p) => {
                colorbar::Scale::Clipped { top: percentile(counts, p) as f64, percentile: p }
            }
        };
        let mean = counts.iter().map(|&c| c as f64).sum::<f64>() / counts.len().max(1) as f64;
        let (title_h, bar_h) = (colorbar::title_height(), colorbar::height());
        let (w, h) = (self.width, title_h + self.height + bar_h);
        let mut rgb = vec![255u8; w * h * 3];
        colorbar::draw_title(&mut rgb[..w * title_h * 3], w, title, &bar_scale);
        let image = &mut rgb[w * title_h * 3..w * (title_h + self.height) * 3];
        for (i, &c) in counts.iter().enumerate() {
            image[i * 3..i * 3 + 3].copy_from_slice(&viridis(bar_scale.fraction(c as f64)));
        }
        colorbar::draw(&mut rgb[w * (title_h + self.height) * 3..], w, &bar_scale, Some(mean), viridis);
        HeatmapImage { width: w, height: h, rgb, top: title_h }
    }
}

#[cfg(all(test, feature = "image"))]
mod tests {
    use super::*;

    #[test]
    fn viridis_ends() {
        assert_eq!(colour(0, 10), [68, 1, 84]);
        assert_eq!(colour(10, 10), colorous::VIRIDIS.eval_continuous(1.0).as_array());
        assert_eq!(colour(5, 0), colour(0, 1));
    }
}
