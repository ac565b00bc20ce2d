//! `raypack render`: loads the scene, renders it with a progress bar, prints CS184's report
//! and writes the image (and the sample-rate image with `-a`) whole or not at all.

use crate::say;
use crate::{CliError, RenderArgs, check_memory, commit, load, print_warnings};
use raypack::math::Vec3;
use raypack::render::{self, RenderSettings};
use raypack::{BuildOptions, Camera, Scene};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `raypack render`: checks the flags, the output paths and the memory, then renders.
pub(crate) fn cmd_render(a: RenderArgs) -> Result<(), CliError> {
    let window_flag = window_flag(&a);
    let integrator = a.integrator;
    if integrator == render::IntegratorKind::Heatmap {
        if let Some(flag) = window_flag {
            return Err(CliError::Usage(format!(
                "{flag} with --integrator heatmap: the heatmap renders whole images only"
            )));
        }
        return crate::heatmap::cmd_heatmap(a);
    }
    check_ignored_flags(&a)?;
    let (width, height) = (a.resolution[0], a.resolution[1]);
    if width == 0 || height == 0 || width > 1 << 15 || height > 1 << 15 {
        return Err(CliError::Usage(format!("-r {width} {height}: width and height must be between 1 and 32768")));
    }
    let window = parse_window(&a, width, height)?;
    let adaptive = match a.adaptive.as_deref() {
        None => None,
        Some([batch, tol]) if *batch >= 1.0 && batch.fract() == 0.0 && *tol > 0.0 => Some((*batch as u32, *tol)),
        Some(v) => {
            return Err(CliError::Usage(format!("-a {v:?}: expected a whole batch size >= 1 and a tolerance > 0")));
        }
    };
    crate::check_threads(a.threads)?;
    let view = CameraFlags::parse(&a)?;
    let quiet = a.quiet;
    // Values raised to the least that works, said aloud (a warning, not a silent change).
    let defaults = SamplingDefaults::for_scene(a.scene.is_some());
    let samples = a.samples.unwrap_or(defaults.samples);
    let light_samples = a.light_samples.unwrap_or(defaults.light_samples);
    if let Some(v) = a.clamp.filter(|v| !(*v > 0.0)) {
        return Err(CliError::Usage(format!(
            "--clamp {v}: the largest sample value must be positive (`--clamp inf` keeps every sample)"
        )));
    }
    if samples == 0 {
        say::warning(format_args!("-s 0: rendering 1 sample per pixel (the least)"));
    }
    if light_samples == 0 {
        say::warning(format_args!("-l 0: taking 1 shadow ray per area light (the least)"));
    }
    if let Some((batch, _)) = adaptive.filter(|&(batch, _)| batch > samples.max(1)) {
        say::warning(format_args!(
            "-a {batch}: the batch is larger than the {} samples per pixel of -s; batches of {} are used",
            samples.max(1),
            samples.max(1)
        ));
    }
    let output = a.output.clone().unwrap_or_else(|| {
        let stem = a.scene.as_ref().and_then(|s| s.file_stem()).map(|s| s.to_string_lossy().into_owned());
        let stem = stem.as_deref().unwrap_or("cornell");
        match &window {
            // A part: named for its pixels, in the format `raypack merge` reads.
            Some(w) => PathBuf::from(format!("{stem}-{}-{}-{}-{}.exr", w.x0, w.x1, w.y0, w.y1)),
            None => PathBuf::from(format!("{stem}.png")),
        }
    });
    // The outputs are checked before anything is computed: `-` is standard output; otherwise
    // only a regular file that is not an input (or nothing, or a FIFO) may be written.
    let to_stdout = output == Path::new("-");
    if to_stdout && adaptive.is_some() {
        return Err(CliError::Usage("-f - with -a: the sample-rate image needs a file name (-f NAME.png)".into()));
    }
    let inputs: Vec<&Path> = [a.scene.as_deref(), a.camera.as_deref()].into_iter().flatten().collect();
    let out_opts = raypack::fs::output::OutputOptions::protecting(&inputs);
    let rate_path = adaptive.map(|_| render::adaptive::rate_path(&output));
    if !to_stdout {
        for p in std::iter::once(&output).chain(&rate_path) {
            raypack::fs::output::check_target(p, &out_opts)?;
        }
        if render::ImageFormat::for_path(&output).is_none() {
            let can: Vec<String> =
                render::ImageFormat::EXTENSIONS.iter().map(|(ext, what)| format!(".{ext} ({what})")).collect();
            let what = match output.extension() {
                Some(ext) => format!("raypack cannot write .{} images", ext.to_string_lossy()),
                None => "the name has no extension to say the format".into(),
            };
            return Err(CliError::Usage(format!(
                "-o {}: {what}; raypack writes {}",
                output.display(),
                can.join(" and ")
            )));
        }
    }
    if let (Some(flag), false) = (window_flag, render::ImageFormat::for_path(&output) == Some(render::ImageFormat::Exr))
    {
        return Err(CliError::Usage(format!(
            "{flag} renders a part of the image, written as OpenEXR with its place in the image for `raypack merge`: \
             name an .exr output (-o PART.exr), not {}",
            if to_stdout { "standard output".to_string() } else { output.display().to_string() }
        )));
    }
    let window = window.unwrap_or(render::PixelBounds::full(width, height));
    if let Some(p) = a.write_camera.as_deref().filter(|p| *p != Path::new("-")) {
        raypack::fs::output::check_target(p, &out_opts)?;
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .map_err(|e| CliError::Usage(e.to_string()))?;
    pool.install(|| {
        let mut settings = RenderSettings {
            width,
            height,
            samples_per_pixel: samples.max(1),
            light_samples: light_samples.max(1),
            max_depth: a.max_depth.unwrap_or(defaults.max_depth),
            hemisphere_sampling: a.hemisphere,
            adaptive,
            integrator,
            heatmap: Default::default(),
            seed: a.seed,
            sampler: a.sampler,
            brute_force: a.brute_force,
            russian_roulette: !a.no_russian_roulette,
            stream_order: None,
            max_sample_value: a.clamp.filter(|v| v.is_finite()),
            pixel_culling: true,
        };
        let format = render::ImageFormat::of(&output);
        let exr = format == render::ImageFormat::Exr;
        // The buffers that grow with the image hold the window's pixels.
        let sized = RenderSettings { width: window.width(), height: window.height(), ..settings.clone() };
        check_memory(
            window.width(),
            window.height(),
            raypack::render::render_bytes(&sized, rayon::current_num_threads(), exr),
            raypack::render::render_bytes_per_pixel(&sized, exr),
        )?;
        // Read before the scene: a bad camera file fails at once.
        let file_camera = a.camera.as_deref().map(raypack::io::camera_file::load_camera_file).transpose()?;
        if !quiet {
            say::start(format_args!("Collecting primitives... "));
        }
        let t = Instant::now();
        let (builder, warnings) = load(a.scene.as_deref(), a.max_primitives)?;
        let load_time = t.elapsed().as_secs_f64();
        if !quiet {
            say::done(format_args!("Done! ({load_time:.4} sec)"));
        }
        print_warnings(&warnings);
        let opts =
            BuildOptions { quality: a.quality, watertight: a.watertight, layout: a.layout, ..BuildOptions::default() };
        let t = Instant::now();
        let mut scene = commit(builder, &opts, a.bvh_cache.as_deref(), quiet);
        let setup_time = [("load", load_time), ("BVH build", t.elapsed().as_secs_f64())];
        if let Some(isa) = a.isa {
            scene.set_isa(isa).map_err(|e| CliError::Usage(e.to_string()))?;
        }
        if a.shadow_order.is_some() || a.bounce_order.is_some() {
            let default = render::StreamOrder::default();
            settings.stream_order = Some(render::StreamOrder {
                shadow: a.shadow_order.unwrap_or(default.shadow),
                bounce: a.bounce_order.unwrap_or(default.bounce),
            });
        }
        let aspect = width as f32 / height as f32;
        let camera =
            view.apply(file_camera.unwrap_or_else(|| scene.camera_or_framing(aspect)), aspect, &scene.bounds())?;
        if let Some(p) = &a.write_camera {
            let text = raypack::io::camera_file::format_camera_file(&camera, view.target(), (width, height));
            return write_camera(p, &text, &out_opts);
        }
        if let Some(why) = hemisphere_sees_no_light(&scene, &settings) {
            say::warning(format_args!("-H: {why}"));
        }
        let bar = if quiet { indicatif::ProgressBar::hidden() } else { progress_bar(render::tiles_in(&window)) };
        if !quiet {
            let part = if window.is_full(width, height) { String::new() } else { format!(" pixels {window} of") };
            say::line(format_args!(
                "Rendering{part} {width}x{height} with {} threads ({} kernels)...",
                rayon::current_num_threads(),
                scene.isa()
            ));
        }
        let out = render::render_window(&scene, &camera, &settings, &window, &|done| bar.set_position(done));
        bar.finish_and_clear();
        if !quiet {
            say::line(format_args!("Rendering... 100%! ({:.4}s)", out.stats.time.as_secs_f64()));
            report(&scene, &settings, &out, setup_time);
        } else if out.stats.invalid_samples > 0 {
            say::warning(format_args!(
                "{} samples were NaN or infinite and counted as black.",
                out.stats.invalid_samples
            ));
        }
        let t = Instant::now();
        let encode = |film: &render::Film, path: &Path, format, encoding| {
            film.encode(format, encoding).map_err(|message| render::ImageError::Encode { path: path.into(), message })
        };
        let image = if exr {
            // With its place in the image and what it was rendered from, so that parts merge
            // into this very file (`raypack merge`).
            let name = a.scene.as_deref().and_then(Path::file_name).map(|n| n.to_string_lossy().into_owned());
            let bvh = format!("quality={} watertight={}", a.quality.name(), a.watertight);
            let provenance = render::part::Provenance::new(
                name.as_deref().unwrap_or(crate::BUILT_IN_SCENE),
                &scene,
                &camera,
                &settings,
                &[("bvh", bvh)],
            );
            let part = render::part::ImagePart { width, height, window, film: out.film.clone(), provenance };
            part.encode_exr().map_err(|message| render::ImageError::Encode { path: output.clone(), message })?
        } else {
            encode(&out.film, &output, format, settings.integrator.encoding())?
        };
        if to_stdout {
            if !quiet {
                say::start(format_args!("Writing the image to standard output... "));
            }
            use std::io::Write;
            let mut stdout = std::io::stdout().lock();
            stdout
                .write_all(&image)
                .and_then(|()| stdout.flush())
                .map_err(|source| render::ImageError::Io { path: output.clone(), source })?;
        } else {
            use raypack::fs::output::{commit_all, stage};
            if !quiet {
                say::start(format_args!("Saving to file: {}... ", output.display()));
            }
            let mut files = vec![stage(&output, &out_opts, &mut |w| w.write_all(&image))?];
            if let (Some(rate), Some((batch, tol))) = (&rate_path, settings.adaptive) {
                let spp = settings.samples_per_pixel;
                let (w, h, rgb) =
                    render::adaptive::rate_image(&out.samples_per_pixel, window.width(), window.height(), spp);
                let bytes = render::film::encode_png(w, h, &rgb)
                    .map_err(|message| render::ImageError::Encode { path: rate.clone(), message })?;
                files.push(stage(rate, &out_opts, &mut |w| w.write_all(&bytes))?);
                if !quiet {
                    say::more(format_args!("(sample rate: {}, batch {batch}, tolerance {tol}) ", rate.display()));
                }
            }
            // The image and its sample-rate image: both or neither.
            commit_all(files)?;
        }
        if !quiet {
            say::done(format_args!("Done! ({:.4} sec)", t.elapsed().as_secs_f64()));
        }
        Ok(())
    })
}

/// The window flag given (`--crop-window`, `--pixel-bounds` or `--tile`), for messages.
fn window_flag(a: &RenderArgs) -> Option<&'static str> {
    if a.crop_window.is_some() {
        Some("--crop-window")
    } else if a.pixel_bounds.is_some() {
        Some("--pixel-bounds")
    } else if a.tile.is_some() {
        Some("--tile")
    } else {
        None
    }
}

/// The window of `--crop-window`, `--pixel-bounds` or `--tile` in a `width × height` image;
/// `None` for the whole image.
fn parse_window(a: &RenderArgs, width: usize, height: usize) -> Result<Option<render::PixelBounds>, CliError> {
    let usage = |flag: &str, e: render::WindowError| CliError::Usage(format!("{flag}: {e}"));
    if let Some(c) = a.crop_window.as_deref() {
        let crop = [c[0], c[1], c[2], c[3]];
        return render::PixelBounds::from_crop_window(crop, width, height)
            .map(Some)
            .map_err(|e| usage("--crop-window", e));
    }
    if let Some(b) = a.pixel_bounds.as_deref() {
        let bounds = render::PixelBounds { x0: b[0], x1: b[1], y0: b[2], y1: b[3] };
        return bounds.within(width, height).map(Some).map_err(|e| usage("--pixel-bounds", e));
    }
    if let Some(t) = a.tile.as_deref() {
        let Some((i, n)) = render::window::parse_part(t) else {
            return Err(CliError::Usage(format!(
                "--tile {t}: expected I/N, part I (from 0) of N parts, such as --tile 0/4 \
                 (in a Slurm job array: --tile $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT with --array=0-(N-1))"
            )));
        };
        return render::PixelBounds::part(i, n, width, height).map(Some).map_err(|e| usage("--tile", e));
    }
    Ok(None)
}

/// Refuses flags that this render would ignore: the heatmap's outside `--integrator
/// heatmap`, and an image name with `--write-camera` (which renders nothing).
fn check_ignored_flags(a: &RenderArgs) -> Result<(), CliError> {
    if a.heatmap.is_some() || a.heatmap_rays.is_some() || a.heatmap_scale.is_some() {
        let flag = if a.heatmap.is_some() {
            "--heatmap"
        } else if a.heatmap_rays.is_some() {
            "--heatmap-rays"
        } else {
            "--heatmap-scale"
        };
        return Err(CliError::Usage(format!("{flag} applies only with --integrator heatmap")));
    }
    if let (Some(out), Some(_)) = (&a.output, &a.write_camera) {
        return Err(CliError::Usage(format!(
            "-o {} with --write-camera: --write-camera writes the camera and renders nothing; drop -o, or render \
             from the camera file with -c",
            out.display()
        )));
    }
    Ok(())
}

/// Writes the camera file `text` to `path` (`-`: standard output, as for `-o -`).
fn write_camera(path: &Path, text: &str, opts: &raypack::fs::output::OutputOptions) -> Result<(), CliError> {
    if path == Path::new("-") {
        use std::io::Write;
        let mut stdout = std::io::stdout().lock();
        stdout
            .write_all(text.as_bytes())
            .and_then(|()| stdout.flush())
            .map_err(|source| raypack::render::ImageError::Io { path: path.into(), source })?;
        return Ok(());
    }
    raypack::fs::output::write_file_with(path, text.as_bytes(), opts)?;
    say::line(format_args!("Wrote the camera to {} (render from it with -c {0}); nothing rendered.", path.display()));
    Ok(())
}

/// `--lookat`, `--up` and `--fov`, checked.
struct CameraFlags {
    /// Eye and target.
    lookat: Option<(Vec3, Vec3)>,
    up: Option<Vec3>,
    /// Vertical field of view, degrees.
    fov: Option<f32>,
}

impl CameraFlags {
    /// Refuses non-finite numbers, a field of view outside (0, 180) degrees, an eye on its
    /// target and a zero up vector; the up vector's angle to the view is checked in `apply`.
    fn parse(a: &RenderArgs) -> Result<Self, CliError> {
        let usage = |m: String| Err(CliError::Usage(m));
        let vec = |v: &[f32]| Vec3::new(v[0], v[1], v[2]);
        for (flag, v) in
            [("--lookat", a.lookat.as_deref()), ("--up", a.up.as_deref()), ("--fov", a.fov.as_slice().into())]
        {
            if let Some(x) = v.into_iter().flatten().find(|x| !x.is_finite()) {
                return usage(format!("{flag}: {x} is not a finite number"));
            }
        }
        if let Some(fov) = a.fov.filter(|f| !(*f > 0.0 && *f < 180.0)) {
            return usage(format!(
                "--fov {fov}: the vertical field of view must be between 0 and 180 degrees (exclusive)"
            ));
        }
        let lookat = a.lookat.as_deref().map(|v| (vec(&v[..3]), vec(&v[3..])));
        if let Some((eye, _)) =
            lookat.filter(|(e, t)| (*e - *t).length() <= 1e-6 * e.abs().max(t.abs()).max_element().max(1.0))
        {
            return usage(format!(
                "--lookat: the eye and the target are the same point ({} {} {}); the camera needs a direction to look in",
                eye.x, eye.y, eye.z
            ));
        }
        let up = a.up.as_deref().map(vec);
        if up.is_some_and(|u| u.length_squared() == 0.0) {
            return usage("--up 0 0 0: the up vector must not be zero".into());
        }
        if let (Some((eye, target)), Some(up)) = (lookat, up) {
            check_up(up, target - eye, "--up")?;
        }
        Ok(Self { lookat, up, fov: a.fov })
    }

    /// The target of `--lookat`, for `--write-camera`.
    fn target(&self) -> Option<Vec3> {
        self.lookat.map(|(_, t)| t)
    }

    /// `camera` with the flags applied over it; `aspect` (width / height) gives the horizontal
    /// field of view when `--fov` sets the vertical one. A moved eye keeps the camera's near
    /// clip distance, and its far one grows to reach all of `bounds`.
    fn apply(&self, camera: Camera, aspect: f32, bounds: &raypack::math::Aabb) -> Result<Camera, CliError> {
        let mut cam = camera;
        if self.lookat.is_some() || self.up.is_some() {
            let (eye, target) = self.lookat.unwrap_or((cam.position, cam.position + cam.view_dir()));
            let up = self.up.unwrap_or(cam.c2w.y_axis);
            check_up(up, target - eye, if self.up.is_some() { "--up" } else { "the camera's up vector (give --up)" })?;
            let mut placed = Camera::look_at(eye, target, up, cam.vfov_deg, aspect, cam.near, cam.far);
            placed.hfov_deg = cam.hfov_deg;
            if bounds.is_valid() {
                let reach = (eye - bounds.center()).length() + bounds.extent().length() * 0.5;
                placed.far = placed.far.max(reach * 1.01);
            }
            cam = placed;
        }
        if let Some(fov) = self.fov {
            cam.vfov_deg = fov;
            cam.set_aspect(aspect);
        }
        Ok(cam)
    }
}

/// Refuses an up vector parallel to the view direction `view` (nonzero): the camera's roll
/// would be undefined.
fn check_up(up: Vec3, view: Vec3, which: &str) -> Result<(), CliError> {
    let (u, v) = (up.normalize(), view.normalize());
    if u.cross(v).length() >= 1e-4 {
        return Ok(());
    }
    let show = |w: Vec3| format!("({:.3} {:.3} {:.3})", w.x + 0.0, w.y + 0.0, w.z + 0.0);
    Err(CliError::Usage(format!(
        "{which} {} is parallel to the view direction {}; the camera's roll is undefined",
        show(up),
        show(v)
    )))
}

/// Why `-H` renders black, when it will: uniform hemisphere sampling finds light only by
/// hitting an emitter, and a point, directional or spot light cannot be hit.
fn hemisphere_sees_no_light(scene: &Scene, settings: &RenderSettings) -> Option<String> {
    let lit = !matches!(settings.integrator, render::IntegratorKind::Normals);
    let only_deltas = scene.lights.iter().all(|l| l.is_delta()) && !scene.materials.iter().any(|m| m.is_emissive());
    (settings.hemisphere_sampling && lit && only_deltas).then(|| {
        "this scene's only lights are point, directional or spot lights, which hemisphere sampling can never hit, \
         so the image is black (as in CS184); drop -H to sample the lights"
            .to_string()
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
    /// 2 cores (128 samples, 2 light samples, depth 5). No clamp: with its lamp sampled once
    /// (radiance 3), none of its 22 million camera samples exceeds 10, where one in 10^5 did
    /// while the lamp counted twice (then the default was `--clamp 10`, against white specks).
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
    say::line(format_args!("BVH traced {} rays.", rays.total()));
    say::line(format_args!("Average speed {:.4} million rays per second.", rays.total() as f64 / secs / 1e6));
    for kind in render::RayKind::ALL {
        let n = rays.of(kind);
        let tests = render::stats::tests_per_ray(scene, &s.sampled_rays[kind as usize], kind, settings.brute_force);
        let tests = tests.map_or("-".into(), |t| format!("{t:.3}"));
        say::line(format_args!(
            "  {:<6} {:>12} rays, {:>9.4} Mrays/s, {} intersection tests per ray",
            kind.name(),
            n,
            n as f64 / secs / 1e6,
            tests
        ));
    }
    let px = out.window.area() as f64;
    say::line(format_args!(
        "{} samples ({:.1} per pixel), {:.4} million samples per second.",
        s.samples,
        s.samples as f64 / px,
        s.samples as f64 / secs / 1e6
    ));
    if s.culled_samples > 0 {
        say::line(format_args!(
            "{} samples ({:.1}%) of pixels whose cone of camera rays misses the scene took a miss's value without tracing.",
            s.culled_samples,
            100.0 * s.culled_samples as f64 / s.samples.max(1) as f64
        ));
    }
    if s.invalid_samples > 0 {
        say::warning(format_args!("{} samples were NaN or infinite and counted as black.", s.invalid_samples));
    }
    if let Some(max) = settings.max_sample_value {
        say::line(format_args!("{} samples were scaled down to the --clamp value {max}.", s.clamped_samples));
    }
    say::line(format_args!(
        "Time: {} {:.4}s, {} {:.4}s, render {:.4}s.",
        setup[0].0, setup[0].1, setup[1].0, setup[1].1, secs
    ));
    let p = &s.phases;
    let total = p.total().as_secs_f64().max(1e-9);
    let phase = |name: &str, d: std::time::Duration| {
        format!("{name} {:.4}s ({:.1}%)", d.as_secs_f64(), 100.0 * d.as_secs_f64() / total)
    };
    say::line(format_args!(
        "Thread time by phase: {}, {}, {}, {}, {}, {}, {}, {}.",
        phase("generate", p.generate),
        phase("trace camera", p.trace[0]),
        phase("trace shadow", p.trace[1]),
        phase("trace bounce", p.trace[2]),
        phase("shade", p.shade),
        phase("sort", p.sort),
        phase("compact", p.compact),
        phase("film", p.film)
    ));
}

fn progress_bar(len: usize) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("[raypack] {bar:40} {percent:>3}% tiles {pos}/{len} eta {eta}")
            .expect("valid template"),
    );
    bar
}
