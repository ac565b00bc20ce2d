//! Writes a raypack scene as a Mitsuba 3 scene directory (`scene.xml` and one binary PLY per
//! material), so that both renderers draw the same image: tools/vs-mitsuba.py renders both and
//! compares means, noise and speed.
//!
//! The scene is read with raypack's own loader and committed as `raypack render` commits it; the
//! camera is the one `render` uses without camera flags (`Scene::camera_or_framing` for the
//! image's aspect) and the lights are the renderer's own light set (`render::light::LightSet`),
//! so stand-ins, dropped lights and the default light rig are what the renderer sees.
//!
//! The translation (docs/benchmarking.md, "raypack against Mitsuba 3"):
//! - sensor: `perspective`, vertical field of view (`fov_axis="y"`; raypack's horizontal one
//!   follows the aspect as Mitsuba's does), `to_world` the camera's frame (Mitsuba's camera
//!   looks down `+z` with `+x` to the left), `near_clip`/`far_clip` the camera's;
//!   film `hdrfilm` W×H with a `box` filter (raypack's film averages a pixel's samples
//!   with equal weights), `independent` sampler with `spp`;
//! - integrator: `path` with `max_depth = -m + 1` (raypack counts bounces, 0 being emission seen
//!   directly; Mitsuba counts path segments, 1 being emission seen directly), `rr_depth` given;
//! - triangles: one PLY per material with the scene's vertex normals when it has them (raypack
//!   interpolates them for shading), none when it has not (face normals);
//! - diffuse materials: `twosided` `diffuse` (raypack's Lambertian reflects on both sides);
//! - rectangle lights (CS184's area lights, one-sided): a `rectangle` with an `area` emitter on
//!   the light's side; its emissive stand-in triangles, which raypack shows to the camera but
//!   does not sample, are left out (the rectangle is both in Mitsuba);
//! - emissive triangles: an `area` emitter on their mesh. raypack's emit on both sides,
//!   Mitsuba's on the side of the winding's normal only: the scene must not show or light
//!   anything with the back side (the tool says so on stderr);
//! - point lights: `point` with the same intensity (radiance `I / r²` in both).
//!
//! Anything else (mirrors, glass, microfacets, spot, directional and environment lights,
//! emissive spheres, rectangle lights without stand-ins, which Mitsuba could not hide from
//! rays) is an error naming the element.
//!
//! `cargo run --release --features tools --bin mitsuba_scene -- SCENE|--default OUT_DIR -r W H -s SPP -m DEPTH [--rr-depth N]`

use raypack::math::Vec3;
use raypack::render::light::{LightSet, SampledLight};
use raypack::scene::{Bsdf, Scene};
use raypack::{BuildOptions, Camera};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

const USAGE: &str = "usage: mitsuba_scene SCENE|--default OUT_DIR -r W H -s SPP -m DEPTH [--rr-depth N]";

struct Args {
    scene: Option<PathBuf>,
    out: PathBuf,
    width: usize,
    height: usize,
    spp: u32,
    max_depth: u32,
    rr_depth: u32,
}

fn parse_args(args: &[String]) -> Result<Args, String> {
    let mut positional = Vec::new();
    let (mut size, mut spp, mut depth, mut rr_depth, mut default) = (None, None, None, 2, false);
    let mut it = args.iter();
    let num = |flag: &str, v: Option<&String>| -> Result<u32, String> {
        let v = v.ok_or_else(|| format!("{flag}: a value is missing"))?;
        v.parse::<u32>().map_err(|_| format!("{flag} {v}: expected a whole number"))
    };
    while let Some(a) = it.next() {
        match a.as_str() {
            "-r" => size = Some((num("-r", it.next())?, num("-r", it.next())?)),
            "-s" => spp = Some(num("-s", it.next())?),
            "-m" => depth = Some(num("-m", it.next())?),
            "--rr-depth" => rr_depth = num("--rr-depth", it.next())?,
            "--default" => default = true,
            s if s.starts_with('-') => return Err(format!("unknown flag {s}")),
            _ => positional.push(PathBuf::from(a)),
        }
    }
    let (scene, out) = match (default, positional.as_slice()) {
        (true, [out]) => (None, out.clone()),
        (false, [scene, out]) => (Some(scene.clone()), out.clone()),
        _ => return Err("expected a scene file (or --default) and an output directory".into()),
    };
    let ((w, h), spp, max_depth) = match (size, spp, depth) {
        (Some(r), Some(s), Some(m)) => (r, s, m),
        _ => return Err("-r W H, -s SPP and -m DEPTH are required".into()),
    };
    if w == 0 || h == 0 || spp == 0 {
        return Err("-r and -s must be positive".into());
    }
    Ok(Args { scene, out, width: w as usize, height: h as usize, spp, max_depth, rr_depth })
}

/// The scene as `raypack render` builds it: the file's loader (or the built-in box), committed.
fn load(path: Option<&Path>) -> Result<Scene, String> {
    let builder = match path {
        Some(p) => {
            let loaded = raypack::io::load_scene(p).map_err(|e| e.to_string())?;
            for w in &loaded.warnings {
                eprintln!("mitsuba_scene: raypack's loader: {w}");
            }
            loaded.builder
        }
        None => raypack::io::default_scene(),
    };
    Ok(builder.commit(&BuildOptions::default()).0)
}

fn rgb(v: Vec3) -> String {
    format!("{:e}, {:e}, {:e}", v.x, v.y, v.z)
}

/// A row-major 4×4 matrix with columns `x`, `y`, `z` and translation `t`, as Mitsuba reads it.
fn matrix(x: Vec3, y: Vec3, z: Vec3, t: Vec3) -> String {
    let rows = [[x.x, y.x, z.x, t.x], [x.y, y.y, z.y, t.y], [x.z, y.z, z.z, t.z], [0.0, 0.0, 0.0, 1.0]];
    rows.iter().flatten().map(|v| format!("{v:e}")).collect::<Vec<_>>().join(" ")
}

fn sensor(cam: &Camera, a: &Args) -> Result<String, String> {
    let aspect = a.width as f32 / a.height as f32;
    let (tx, ty) = ((cam.hfov_deg.to_radians() * 0.5).tan(), (cam.vfov_deg.to_radians() * 0.5).tan());
    if (tx - ty * aspect).abs() > 1e-4 * tx {
        return Err(format!(
            "the camera's fields of view ({} by {} degrees) do not follow the image's aspect {aspect}: Mitsuba \
             derives one from the other",
            cam.hfov_deg, cam.vfov_deg
        ));
    }
    // raypack's camera space: +x right, +y up, looking down -z; Mitsuba's: +x left, +y up, +z ahead.
    let (right, up, back) = (cam.c2w.x_axis, cam.c2w.y_axis, cam.c2w.z_axis);
    Ok(format!(
        r#"  <sensor type="perspective">
    <string name="fov_axis" value="y"/>
    <float name="fov" value="{fov:e}"/>
    <float name="near_clip" value="{near:e}"/>
    <float name="far_clip" value="{far:e}"/>
    <transform name="to_world"><matrix value="{m}"/></transform>
    <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    <film type="hdrfilm">
      <integer name="width" value="{w}"/>
      <integer name="height" value="{h}"/>
      <string name="pixel_format" value="rgb"/>
      <rfilter type="box"/>
    </film>
  </sensor>
"#,
        fov = cam.vfov_deg,
        near = cam.near,
        far = cam.far,
        m = matrix(-right, up, -back, cam.position),
        spp = a.spp,
        w = a.width,
        h = a.height,
    ))
}

fn twosided_diffuse(albedo: Vec3) -> String {
    format!(
        r#"<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="{}"/></bsdf></bsdf>"#,
        rgb(albedo)
    )
}

/// Writes the triangles `tris` of `scene` as a binary little-endian PLY, with the scene's vertex
/// normals when `normals`.
fn write_ply(path: &Path, scene: &Scene, tris: &[u32], normals: bool) -> Result<(), String> {
    let t = &scene.triangles;
    let mut local = std::collections::HashMap::new();
    let mut verts: Vec<u32> = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::with_capacity(tris.len());
    for &i in tris {
        faces.push(t.indices[i as usize].map(|v| {
            *local.entry(v).or_insert_with(|| {
                verts.push(v);
                verts.len() as u32 - 1
            })
        }));
    }
    let mut out = format!("ply\nformat binary_little_endian 1.0\nelement vertex {}\n", verts.len());
    out += "property float x\nproperty float y\nproperty float z\n";
    if normals {
        out += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    let _ = write!(out, "element face {}\nproperty list uchar int vertex_indices\nend_header\n", faces.len());
    let mut bytes = out.into_bytes();
    for &v in &verts {
        let p = t.positions[v as usize];
        let mut vals = vec![p.x, p.y, p.z];
        if normals {
            let n = t.normals[v as usize];
            vals.extend([n.x, n.y, n.z]);
        }
        vals.iter().for_each(|x| bytes.extend(x.to_le_bytes()));
    }
    for f in &faces {
        bytes.push(3);
        f.iter().for_each(|i| bytes.extend(i.to_le_bytes()));
    }
    std::fs::write(path, bytes).map_err(|e| format!("{}: {e}", path.display()))
}

fn translate(scene: &Scene, a: &Args) -> Result<String, String> {
    let lights = LightSet::new(scene);
    let mut xml = String::from("<scene version=\"3.0.0\">\n");
    let _ = writeln!(
        xml,
        "  <integrator type=\"path\"><integer name=\"max_depth\" value=\"{}\"/><integer name=\"rr_depth\" value=\"{}\"/></integrator>",
        a.max_depth + 1,
        a.rr_depth
    );
    xml += &sensor(&scene.camera_or_framing(a.width as f32 / a.height as f32), a)?;
    let mut rect_normals = Vec::new();
    for (i, l) in lights.lights.iter().enumerate() {
        match l {
            SampledLight::Point { position, intensity } => {
                let _ = writeln!(
                    xml,
                    "  <emitter type=\"point\"><point name=\"position\" x=\"{:e}\" y=\"{:e}\" z=\"{:e}\"/><rgb name=\"intensity\" value=\"{}\"/></emitter>",
                    position.x,
                    position.y,
                    position.z,
                    rgb(*intensity)
                );
            }
            SampledLight::Rect { radiance, center, normal, dim_x, dim_y, .. } => {
                if dim_x.dot(*dim_y).abs() > 1e-4 * dim_x.length() * dim_y.length() {
                    return Err(format!("light {i}: a parallelogram, not a rectangle; Mitsuba's is a rectangle"));
                }
                // Mitsuba's rectangle spans [-1, 1]² of its local xy plane and faces its local +z.
                let (hx, hy) = (*dim_x * 0.5, *dim_y * 0.5);
                let (hx, hy) = if hx.cross(hy).dot(*normal) >= 0.0 { (hx, hy) } else { (hy, hx) };
                rect_normals.push(*normal);
                let _ = writeln!(
                    xml,
                    "  <shape type=\"rectangle\"><transform name=\"to_world\"><matrix value=\"{}\"/></transform>{}<emitter type=\"area\"><rgb name=\"radiance\" value=\"{}\"/></emitter></shape>",
                    matrix(hx, hy, *normal, *center),
                    twosided_diffuse(Vec3::ZERO),
                    rgb(*radiance)
                );
            }
            SampledLight::Triangles { .. } => {} // written with their material's mesh below
            other => return Err(format!("light {i}: {other:?} is not translated (only points and rectangles)")),
        }
    }
    // Stand-ins: raypack hides their emission on the light's side (`LightSet::emitted`).
    let is_stand_in = |t: u32, emission: Vec3| {
        emission != Vec3::ZERO && rect_normals.iter().any(|&n| lights.emitted(t, emission, n) == Vec3::ZERO)
    };
    let mut per_material: Vec<Vec<u32>> = vec![Vec::new(); scene.materials.len()];
    let mut stand_ins = 0usize;
    for t in 0..scene.triangles.len() as u32 {
        let m = scene.triangles.material[t as usize];
        if is_stand_in(t, scene.materials[m as usize].emission) {
            stand_ins += 1;
        } else {
            per_material[m as usize].push(t);
        }
    }
    let rects = rect_normals.len();
    if rects > 0 && stand_ins == 0 {
        return Err(format!(
            "{rects} rectangle light(s) without emissive stand-in triangles: raypack's are invisible to rays, \
             Mitsuba's rectangle would be seen and would block light"
        ));
    }
    for (m, tris) in per_material.iter().enumerate().filter(|(_, t)| !t.is_empty()) {
        let mat = &scene.materials[m];
        let Bsdf::Diffuse { albedo } = mat.bsdf else {
            return Err(format!("material {m} ({:?}): {:?} is not translated (only diffuse)", mat.name, mat.bsdf));
        };
        let normals = !scene.triangles.normals.is_empty() && !mat.is_emissive();
        if normals {
            let zero = tris.iter().flat_map(|&t| scene.triangles.indices[t as usize]);
            if zero.into_iter().any(|v| scene.triangles.normals[v as usize] == Vec3::ZERO) {
                return Err(format!(
                    "material {m} ({:?}): some vertices have no normal (raypack shades those faces flat), \
                     not translated",
                    mat.name
                ));
            }
        }
        let file = format!("mesh_{m}.ply");
        write_ply(&a.out.join(&file), scene, tris, normals)?;
        let emitter = if mat.is_emissive() {
            eprintln!(
                "mitsuba_scene: material {m} ({:?}) emits: raypack's emissive triangles emit on both sides, \
                 Mitsuba's on the side of their winding's normal only; the scene must keep the back sides dark",
                mat.name
            );
            format!("<emitter type=\"area\"><rgb name=\"radiance\" value=\"{}\"/></emitter>", rgb(mat.emission))
        } else {
            String::new()
        };
        let _ = writeln!(
            xml,
            "  <shape type=\"ply\" id=\"material_{m}\"><string name=\"filename\" value=\"{file}\"/><boolean name=\"face_normals\" value=\"{}\"/>{}{emitter}</shape>",
            !normals,
            twosided_diffuse(albedo)
        );
    }
    let sp = &scene.spheres;
    for s in 0..sp.len() {
        let mat = &scene.materials[sp.material[s] as usize];
        let Bsdf::Diffuse { albedo } = mat.bsdf else {
            return Err(format!(
                "sphere {s}: material {:?} is {:?}, not translated (only diffuse)",
                mat.name, mat.bsdf
            ));
        };
        if mat.is_emissive() {
            return Err(format!("sphere {s}: material {:?} emits; emissive spheres are not translated", mat.name));
        }
        let c = sp.center[s];
        let _ = writeln!(
            xml,
            "  <shape type=\"sphere\"><point name=\"center\" x=\"{:e}\" y=\"{:e}\" z=\"{:e}\"/><float name=\"radius\" value=\"{:e}\"/>{}</shape>",
            c.x,
            c.y,
            c.z,
            sp.radius[s],
            twosided_diffuse(albedo)
        );
    }
    xml += "</scene>\n";
    Ok(xml)
}

fn run(args: &[String]) -> Result<(), String> {
    let a = parse_args(args)?;
    let scene = load(a.scene.as_deref())?;
    std::fs::create_dir_all(&a.out).map_err(|e| format!("{}: {e}", a.out.display()))?;
    let xml = translate(&scene, &a)?;
    let path = a.out.join("scene.xml");
    std::fs::write(&path, xml).map_err(|e| format!("{}: {e}", path.display()))?;
    println!("{}", path.display());
    Ok(())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("mitsuba_scene: {e}\n{USAGE}");
            ExitCode::from(2)
        }
    }
}
