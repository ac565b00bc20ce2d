//! Traversal-cost heatmaps: each pixel coloured by the work the BVH8 kernel did for its ray.
//!
//! One ray per pixel, through the pixel's centre, traced by the single-ray kernels that
//! answer [`Scene::intersect1`] and [`Scene::occluded1`], each with its own
//! [`TraversalCounts`] ([`Scene::intersect1_counted`], [`Scene::occluded1_counted`]). The
//! counts are therefore the real kernel's work, not a separate walk that could drift from it:
//! `nodes` is [`TraversalCounts::nodes`] (inner nodes visited, each an 8-box test) and `tests`
//! is [`TraversalCounts::blocks`] (primitive blocks tested, each up to M triangles or 4
//! spheres at once). The image maps a count linearly onto viridis, 0 to the largest count of
//! the view, with a colour bar labelled with the counts below it ([`super::colorbar`]).

use super::camera::CameraRays;
#[cfg(feature = "image")]
use super::colorbar;
use super::spawn::{spawn_ray, spawn_ray_to};
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
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum HeatmapError {
    /// `--heatmap-rays shadow` on a scene without a light.
    #[error("shadow-ray heatmap: the scene has no light to cast shadow rays toward")]
    NoLight,
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
    let light = match which {
        HeatmapRays::Camera => None,
        HeatmapRays::Shadow => Some(*scene.lights.first().ok_or(HeatmapError::NoLight)?),
    };
    let rays = CameraRays::new(camera);
    let rows: Vec<(Vec<u32>, Vec<u32>)> = (0..height)
        .into_par_iter()
        .map(|y| {
            let mut row = (Vec::with_capacity(width), Vec::with_capacity(width));
            for x in 0..width {
                let ray = pixel_ray(&rays, x, y, width, height);
                let mut c = TraversalCounts::default();
                match &light {
                    None => {
                        scene.intersect1_counted(&ray, &mut c);
                    }
                    Some(light) => {
                        if let Some(shadow) = shadow_ray(scene, light, &ray) {
                            scene.occluded1_counted(&shadow, &mut c);
                        }
                    }
                }
                row.0.push(saturate(c.nodes));
                row.1.push(saturate(c.blocks));
            }
            row
        })
        .collect();
    let mut out = HeatmapCounts { width, height, nodes: Vec::new(), tests: Vec::new() };
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
    /// Height in pixels (the image's plus the colour bar's).
    pub height: usize,
    /// `width × height × 3` bytes.
    pub rgb: Vec<u8>,
}

/// The viridis colour of `count` on a scale from 0 to `max` (`max` 0: everything is 0).
#[cfg(feature = "image")]
pub fn colour(count: u32, max: u32) -> [u8; 3] {
    let f = if max == 0 { 0.0 } else { count as f64 / max as f64 };
    colorous::VIRIDIS.eval_continuous(f.clamp(0.0, 1.0)).as_array()
}

#[cfg(feature = "image")]
impl HeatmapCounts {
    /// The image of `view`: counts coloured by [`colour`] with a labelled colour bar beneath.
    pub fn image(&self, view: HeatmapView) -> HeatmapImage {
        match view {
            HeatmapView::Nodes => self.one(&self.nodes),
            HeatmapView::Tests => self.one(&self.tests),
            HeatmapView::Both => {
                let (a, b) = (self.one(&self.nodes), self.one(&self.tests));
                let gap = 4;
                let width = a.width + gap + b.width;
                let mut rgb = vec![255u8; width * a.height * 3];
                for y in 0..a.height {
                    let row = &mut rgb[y * width * 3..(y + 1) * width * 3];
                    row[..a.width * 3].copy_from_slice(&a.rgb[y * a.width * 3..(y + 1) * a.width * 3]);
                    row[(a.width + gap) * 3..].copy_from_slice(&b.rgb[y * b.width * 3..(y + 1) * b.width * 3]);
                }
                HeatmapImage { width, height: a.height, rgb }
            }
        }
    }

    fn one(&self, counts: &[u32]) -> HeatmapImage {
        let max = counts.iter().copied().max().unwrap_or(0);
        let bar_h = colorbar::height();
        let (w, h) = (self.width, self.height + bar_h);
        let mut rgb = vec![255u8; w * h * 3];
        for (i, &c) in counts.iter().enumerate() {
            rgb[i * 3..i * 3 + 3].copy_from_slice(&colour(c, max));
        }
        colorbar::draw(&mut rgb[self.width * self.height * 3..], w, max, |f| {
            colorous::VIRIDIS.eval_continuous(f).as_array()
        });
        HeatmapImage { width: w, height: h, rgb }
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
