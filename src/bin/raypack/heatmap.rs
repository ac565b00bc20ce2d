//! `raypack render --integrator heatmap`: the flags of the traversal-cost heatmap, which the
//! library renders ([`raypack::render::IntegratorKind::Heatmap`]), and its picture written as
//! a PNG whole or not at all.

use crate::say;
use crate::{CliError, RenderArgs, commit, load, print_warnings};
use clap::ValueEnum;
use raypack::BuildOptions;
use raypack::render::heatmap::{Heatmap, HeatmapRays, HeatmapScale, HeatmapSettings, HeatmapView};
use raypack::render::{IntegratorKind, RenderSettings};
use std::path::{Path, PathBuf};

/// `--heatmap`: which counts the image shows.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub(crate) enum ViewArg {
    /// Inner BVH nodes visited (each an 8-box test).
    Nodes,
    /// Primitive-block tests (each up to 8 triangles or 4 spheres at once).
    Tests,
    /// Nodes on the left, tests on the right.
    Both,
}

/// `--heatmap-rays`: which rays are counted.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub(crate) enum RaysArg {
    /// One camera ray per pixel (closest hit).
    Camera,
    /// From each camera ray's hit, an occlusion ray toward the scene's first light.
    Shadow,
}

/// Parses `--heatmap-scale`: `linear`, `log` or `pNN` (a percentile in (0, 100]).
pub(crate) fn parse_scale(s: &str) -> Result<HeatmapScale, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "linear" => Ok(HeatmapScale::Linear),
        "log" => Ok(HeatmapScale::Log),
        p if p.starts_with('p') => match p[1..].parse::<f64>() {
            Ok(v) if v > 0.0 && v <= 100.0 => Ok(HeatmapScale::Percentile(v)),
            _ => Err(format!("'{s}': a percentile is p followed by a number in (0, 100], e.g. p99")),
        },
        _ => Err(format!("'{s}': expected linear, log or pNN (a percentile, e.g. p99)")),
    }
}

/// Renders the heatmap `a` asks for. Sampling flags (-s, -l, -m, -a, -H) do not apply.
pub(crate) fn cmd_heatmap(a: RenderArgs) -> Result<(), CliError> {
    let (width, height) = (a.resolution[0], a.resolution[1]);
    if width == 0 || height == 0 || width > 1 << 15 || height > 1 << 15 {
        return Err(CliError::Usage(format!("-r {width} {height}: width and height must be between 1 and 32768")));
    }
    if a.brute_force {
        return Err(CliError::Usage("--integrator heatmap counts BVH traversal: --brute-force has none".into()));
    }
    crate::check_threads(a.threads)?;
    let output = a.output.clone().unwrap_or_else(|| {
        let stem = a.scene.as_ref().and_then(|s| s.file_stem()).map(|s| s.to_string_lossy().into_owned());
        PathBuf::from(format!("{}-heatmap.png", stem.as_deref().unwrap_or("cornell")))
    });
    if raypack::render::ImageFormat::for_path(&output) != Some(raypack::render::ImageFormat::Png)
        && output != Path::new("-")
    {
        return Err(CliError::Usage(format!("-f {}: a heatmap is written as .png", output.display())));
    }
    let inputs: Vec<&Path> = [a.scene.as_deref(), a.camera.as_deref()].into_iter().flatten().collect();
    let out_opts = raypack::fs::output::OutputOptions::protecting(&inputs);
    let to_stdout = output == Path::new("-");
    if !to_stdout {
        raypack::fs::output::check_target(&output, &out_opts)?;
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .map_err(|e| CliError::Usage(e.to_string()))?;
    pool.install(|| {
        let file_camera = a.camera.as_deref().map(raypack::io::camera_file::load_camera_file).transpose()?;
        let (builder, warnings) = load(a.scene.as_deref(), a.max_primitives)?;
        print_warnings(&warnings);
        let opts = BuildOptions { quality: a.quality, watertight: a.watertight, ..BuildOptions::default() };
        let mut scene = commit(builder, &opts, a.bvh_cache.as_deref(), a.quiet);
        if let Some(isa) = a.isa {
            scene.set_isa(isa).map_err(|e| CliError::Usage(e.to_string()))?;
        }
        let camera = file_camera.unwrap_or_else(|| scene.camera_or_framing(width as f32 / height as f32));
        let rays = a.heatmap_rays.unwrap_or(RaysArg::Camera);
        let heatmap = HeatmapSettings {
            rays: match rays {
                RaysArg::Camera => HeatmapRays::Camera,
                RaysArg::Shadow => HeatmapRays::Shadow,
            },
            view: match a.heatmap.unwrap_or(ViewArg::Nodes) {
                ViewArg::Nodes => HeatmapView::Nodes,
                ViewArg::Tests => HeatmapView::Tests,
                ViewArg::Both => HeatmapView::Both,
            },
            scale: a.heatmap_scale.unwrap_or_default(),
        };
        let settings =
            RenderSettings { width, height, integrator: IntegratorKind::Heatmap, heatmap, ..Default::default() };
        let out = raypack::render::render(&scene, &camera, &settings, &|_| {});
        let made = out.heatmap.expect("a heatmap render makes a heatmap");
        let Heatmap { counts, image, .. } = made.map_err(|e| CliError::Usage(e.to_string()))?;
        let stat = |v: &[u32]| {
            let max = v.iter().copied().max().unwrap_or(0);
            let mean = v.iter().map(|&c| c as f64).sum::<f64>() / v.len().max(1) as f64;
            format!("mean {mean:.2}, max {max}")
        };
        say::line(format_args!(
            "Heatmap of {} rays ({} kernels, {:.4} s): nodes visited {}; primitive-block tests {}",
            rays.to_possible_value().map_or("camera".into(), |v| v.get_name().to_owned()),
            scene.isa(),
            out.stats.time.as_secs_f64(),
            stat(&counts.nodes),
            stat(&counts.tests)
        ));
        let bytes = raypack::render::film::encode_png(image.width, image.height, &image.rgb)
            .map_err(|message| raypack::render::ImageError::Encode { path: output.clone(), message })?;
        if to_stdout {
            use std::io::Write;
            let mut stdout = std::io::stdout().lock();
            stdout
                .write_all(&bytes)
                .and_then(|()| stdout.flush())
                .map_err(|source| raypack::render::ImageError::Io { path: output.clone(), source })?;
        } else {
            raypack::fs::output::write_file_with(&output, &bytes, &out_opts)?;
            say::line(format_args!("Saved {}", output.display()));
        }
        Ok(())
    })
}
