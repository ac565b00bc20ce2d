//! `raypack render`: loads the scene, renders it with a progress bar, prints CS184's report
//! and writes the image (and the sample-rate image with `-a`) whole or not at all.

use crate::{CliError, RenderArgs, check_memory, commit, load, print_warnings};
use raypack::render::{self, RenderSettings};
use raypack::{BuildOptions, Scene};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `raypack render`: checks the flags, the output paths and the memory, then renders.
pub(crate) fn cmd_render(a: RenderArgs) -> Result<(), CliError> {
    let Some(integrator) = a.integrator.kind() else { return crate::heatmap::cmd_heatmap(a) };
    let (width, height) = (a.resolution[0], a.resolution[1]);
    if width == 0 || height == 0 || width > 1 << 15 || height > 1 << 15 {
        return Err(CliError::Usage(format!("-r {width} {height}: width and height must be between 1 and 32768")));
    }
    let adaptive = match a.adaptive.as_deref() {
        None => None,
        Some([batch, tol]) if *batch >= 1.0 && batch.fract() == 0.0 && *tol > 0.0 => Some((*batch as u32, *tol)),
        Some(v) => {
            return Err(CliError::Usage(format!("-a {v:?}: expected a whole batch size >= 1 and a tolerance > 0")));
        }
    };
    if a.threads == Some(0) {
        return Err(CliError::Usage("-t 0: need at least one thread".into()));
    }
    let output = a.output.clone().unwrap_or_else(|| {
        let stem = a.scene.as_ref().and_then(|s| s.file_stem()).map(|s| s.to_string_lossy().into_owned());
        PathBuf::from(format!("{}.png", stem.as_deref().unwrap_or("cornell")))
    });
    // The outputs are checked before anything is computed: `-` is standard output; otherwise
    // only a regular file that is not an input (or nothing, or a FIFO) may be written.
    let to_stdout = output == Path::new("-");
    if to_stdout && adaptive.is_some() {
        return Err(CliError::Usage("-f - with -a: the sample-rate image needs a file name (-f NAME.png)".into()));
    }
    let inputs: Vec<&Path> = [a.scene.as_deref(), a.camera.as_deref()].into_iter().flatten().collect();
    let out_opts = raypack::io::output::OutputOptions::protecting(&inputs);
    let rate_path = adaptive.map(|_| render::adaptive::rate_path(&output));
    if !to_stdout {
        for p in std::iter::once(&output).chain(&rate_path) {
            raypack::io::output::check_target(p, &out_opts)?;
        }
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .map_err(|e| CliError::Usage(e.to_string()))?;
    let defaults = SamplingDefaults::for_scene(a.scene.is_some());
    pool.install(|| {
        let mut settings = RenderSettings {
            width,
            height,
            samples_per_pixel: a.samples.unwrap_or(defaults.samples).max(1),
            light_samples: a.light_samples.unwrap_or(defaults.light_samples).max(1),
            max_depth: a.max_depth.unwrap_or(defaults.max_depth),
            hemisphere_sampling: a.hemisphere,
            adaptive,
            integrator,
            seed: a.seed,
            brute_force: a.brute_force,
            russian_roulette: !a.no_russian_roulette,
            stream_order: None,
        };
        let format = render::ImageFormat::of(&output);
        let exr = format == render::ImageFormat::Exr;
        check_memory(
            width,
            height,
            raypack::memory::render_bytes(&settings, rayon::current_num_threads(), exr),
            raypack::memory::render_bytes_per_pixel(&settings, exr),
        )?;
        // Read before the scene: a bad camera file fails at once.
        let file_camera = a.camera.as_deref().map(raypack::io::camera_file::load_camera_file).transpose()?;
        eprint!("[raypack] Collecting primitives... ");
        let t = Instant::now();
        let (builder, warnings) = load(a.scene.as_deref(), a.max_primitives)?;
        let load_time = t.elapsed().as_secs_f64();
        eprintln!("Done! ({load_time:.4} sec)");
        print_warnings(&warnings);
        let opts = BuildOptions { quality: a.quality.into(), watertight: a.watertight, ..BuildOptions::default() };
        let t = Instant::now();
        let mut scene = commit(builder, &opts, a.bvh_cache.as_deref());
        let setup_time = [("load", load_time), ("BVH build", t.elapsed().as_secs_f64())];
        if let Some(isa) = a.isa {
            scene.set_isa(isa).map_err(|e| CliError::Usage(e.to_string()))?;
        }
        if a.shadow_order.is_some() || a.bounce_order.is_some() {
            let default = render::StreamOrder::default_for(scene.isa());
            settings.stream_order = Some(render::StreamOrder {
                shadow: a.shadow_order.map_or(default.shadow, Into::into),
                bounce: a.bounce_order.map_or(default.bounce, Into::into),
            });
        }
        let aspect = width as f32 / height as f32;
        let camera = file_camera.unwrap_or_else(|| scene.camera_or_framing(aspect));
        let bar = progress_bar(width.div_ceil(render::TILE) * height.div_ceil(render::TILE));
        eprintln!(
            "[raypack] Rendering {width}x{height} with {} threads ({} kernels)...",
            rayon::current_num_threads(),
            scene.isa()
        );
        let out = render::render(&scene, &camera, &settings, &|done| bar.set_position(done));
        bar.finish_and_clear();
        eprintln!("[raypack] Rendering... 100%! ({:.4}s)", out.stats.time.as_secs_f64());
        report(&scene, &settings, &out, setup_time);
        let t = Instant::now();
        let encode = |film: &render::Film, path: &Path, format, encoding| {
            film.encode(format, encoding).map_err(|message| render::ImageError::Encode { path: path.into(), message })
        };
        let image = encode(&out.film, &output, format, settings.integrator.encoding())?;
        if to_stdout {
            eprint!("[raypack] Writing the image to standard output... ");
            use std::io::Write;
            let mut stdout = std::io::stdout().lock();
            stdout
                .write_all(&image)
                .and_then(|()| stdout.flush())
                .map_err(|source| render::ImageError::Io { path: output.clone(), source })?;
        } else {
            use raypack::io::output::{commit_all, stage};
            eprint!("[raypack] Saving to file: {}... ", output.display());
            let mut files = vec![stage(&output, &out_opts, &mut |w| w.write_all(&image))?];
            if let (Some(rate), Some((batch, tol))) = (&rate_path, settings.adaptive) {
                let spp = settings.samples_per_pixel;
                let film = render::adaptive::rate_film(&out.samples_per_pixel, width, height, spp);
                let bytes = encode(&film, rate, render::ImageFormat::Png, render::Encoding::Display)?;
                files.push(stage(rate, &out_opts, &mut |w| w.write_all(&bytes))?);
                eprint!("(sample rate: {}, batch {batch}, tolerance {tol}) ", rate.display());
            }
            // The image and its sample-rate image: both or neither.
            commit_all(files)?;
        }
        eprintln!("Done! ({:.4} sec)", t.elapsed().as_secs_f64());
        Ok(())
    })
}

/// What `-s`, `-l` and `-m` default to.
struct SamplingDefaults {
    samples: u32,
    light_samples: u32,
    max_depth: u32,
}

impl SamplingDefaults {
    /// CS184's flag defaults (1 sample, 1 light sample, depth 1) for a scene file; for the
    /// built-in Cornell box, what makes the README's first render a converged-looking image
    /// with global illumination, soft shadows, a mirror and a glass sphere in a few seconds on
    /// 2 cores (128 samples, 2 light samples, depth 5).
    fn for_scene(file: bool) -> Self {
        if file {
            Self { samples: 1, light_samples: 1, max_depth: 1 }
        } else {
            Self { samples: 128, light_samples: 2, max_depth: 5 }
        }
    }
}

/// The end-of-render report: CS184's lines (rays traced, Mrays/s, tests per ray), per kind of
/// ray, then samples per second and time per phase.
fn report(scene: &Scene, settings: &RenderSettings, out: &render::RenderOutput, setup: [(&str, f64); 2]) {
    let s = &out.stats;
    let secs = s.time.as_secs_f64().max(1e-9);
    let rays = s.rays;
    eprintln!("[raypack] BVH traced {} rays.", rays.total());
    eprintln!("[raypack] Average speed {:.4} million rays per second.", rays.total() as f64 / secs / 1e6);
    for kind in render::RayKind::ALL {
        let n = rays.of(kind);
        let tests = render::stats::tests_per_ray(scene, &s.sampled_rays[kind as usize], kind, settings.brute_force);
        let tests = tests.map_or("-".into(), |t| format!("{t:.3}"));
        eprintln!(
            "[raypack]   {:<6} {:>12} rays, {:>9.4} Mrays/s, {} intersection tests per ray",
            kind.name(),
            n,
            n as f64 / secs / 1e6,
            tests
        );
    }
    let px = (settings.width * settings.height) as f64;
    eprintln!(
        "[raypack] {} samples ({:.1} per pixel), {:.4} million samples per second.",
        s.samples,
        s.samples as f64 / px,
        s.samples as f64 / secs / 1e6
    );
    if s.invalid_samples > 0 {
        eprintln!("[raypack] warning: {} samples were NaN or infinite and counted as black.", s.invalid_samples);
    }
    eprintln!(
        "[raypack] Time: {} {:.4}s, {} {:.4}s, render {:.4}s.",
        setup[0].0, setup[0].1, setup[1].0, setup[1].1, secs
    );
    let p = &s.phases;
    let total = p.total().as_secs_f64().max(1e-9);
    let phase = |name: &str, d: std::time::Duration| {
        format!("{name} {:.4}s ({:.1}%)", d.as_secs_f64(), 100.0 * d.as_secs_f64() / total)
    };
    eprintln!(
        "[raypack] Thread time by phase: {}, {}, {}, {}, {}, {}, {}, {}.",
        phase("generate", p.generate),
        phase("trace camera", p.trace[0]),
        phase("trace shadow", p.trace[1]),
        phase("trace bounce", p.trace[2]),
        phase("shade", p.shade),
        phase("sort", p.sort),
        phase("compact", p.compact),
        phase("film", p.film)
    );
}

fn progress_bar(len: usize) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("[raypack] {bar:40} {percent:>3}% tiles {pos}/{len} eta {eta}")
            .expect("valid template"),
    );
    bar
}
