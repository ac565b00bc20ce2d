//! Shared helpers for integration tests: scene construction, ray generators, scene paths.
#![allow(dead_code)]

use raypack::generate::Mesh;
use raypack::kernels::{KERNELS, Kernel, Results};
use raypack::rng::Rng;
use raypack::{BuildOptions, Isa, Material, Ray, Scene, SceneBuilder, Vec3};
use std::path::{Path, PathBuf};

pub mod child;

/// Commits `meshes` (and `spheres`: centre, radius) into a scene with one diffuse material.
/// Keeps the binary BVH whatever `opts` say: tests compare the kernels with its reference
/// traversal.
pub fn scene_of(meshes: &[&Mesh], spheres: &[(Vec3, f32)], opts: &BuildOptions) -> Scene {
    let mut b = SceneBuilder::new();
    let m = b.add_material(Material::diffuse(Vec3::splat(0.5)));
    for mesh in meshes {
        b.add_mesh(&mesh.positions, &mesh.indices, m).expect("valid mesh");
    }
    for &(c, r) in spheres {
        b.add_sphere(c, r, m).expect("valid sphere");
    }
    b.commit(&BuildOptions { keep_bvh2: true, ..opts.clone() }).0
}

/// `n` rays with origins in the box grown by half its size and directions uniform on the
/// sphere, aimed so that most of them pass through the box.
pub fn random_rays(scene: &Scene, n: usize, seed: u64) -> Vec<Ray> {
    let b = scene.bounds();
    let (c, e) = (b.center(), b.extent().max(Vec3::splat(1e-3)));
    let mut rng = Rng::new(seed, 0xA11CE);
    (0..n)
        .map(|_| {
            let mut r3 = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5;
            let origin = c + r3() * e * 2.0;
            let target = c + r3() * e;
            Ray::new(origin, (target - origin).normalize_or(Vec3::X))
        })
        .collect()
}

/// The root of the third-party scenes (`RAYPACK_SCENES`), or `None` with a loud notice.
pub fn scenes_dir(test: &str) -> Option<PathBuf> {
    match std::env::var_os("RAYPACK_SCENES") {
        Some(d) if !d.is_empty() => Some(PathBuf::from(d)),
        _ => {
            eprintln!(
                "SKIPPED {test}: RAYPACK_SCENES is not set (e.g. RAYPACK_SCENES=../shared/scenes); third-party scenes not tested"
            );
            None
        }
    }
}

/// Loads `bytes` as a file called `name` (its extension picks the format): the builder and
/// the loader's warnings.
pub fn load_named(bytes: &[u8], name: &str) -> Result<(SceneBuilder, Vec<String>), raypack::io::LoadError> {
    use raypack::io::{SceneFormat, load_scene_from_bytes};
    let path = std::path::Path::new(name);
    load_scene_from_bytes(bytes, SceneFormat::from_path(path).expect("known extension"), path)
        .map(|l| (l.builder, l.warnings))
}

/// Loads `bytes` as `name`, expects an error naming the file first and `location`, and
/// returns its text.
pub fn expect_error(bytes: &[u8], name: &str, location: &str) -> String {
    let e = match load_named(bytes, name) {
        Ok(_) => panic!("{name}: loaded, but an error naming {location:?} was expected"),
        Err(e) => e,
    };
    let text = e.to_string();
    assert!(text.starts_with(name), "error does not name the file first: {text}");
    assert!(e.location().is_some_and(|l| l.contains(location)), "error does not name {location:?}: {text}");
    text
}

/// The scene on every ISA tier this process may run ([`Isa::available`]: the CPU's tiers up
/// to `RAYPACK_ISA`), as copies set to each.
pub fn on_every_isa(scene: &Scene) -> Vec<(Isa, Scene)> {
    Isa::available()
        .map(|isa| {
            let mut s = scene.clone();
            s.set_isa(isa).expect("available tiers are supported");
            (isa, s)
        })
        .collect()
}

/// Every kernel of the registry on `rays`: the scalar references once, each SIMD kernel on
/// every ISA tier of [`on_every_isa`] and in every tree layout (`raypack::TreeLayout::ALL`). Returns
/// `(name [isa], results)`, with `, compact` after the ISA for the compact tree.
pub fn every_kernel(scene: &Scene, rays: &[Ray]) -> Vec<(String, Results)> {
    every_kernel_where(scene, rays, |_| true)
}

/// [`every_kernel`] restricted to the kernels `keep` accepts.
pub fn every_kernel_where(scene: &Scene, rays: &[Ray], keep: impl Fn(&Kernel) -> bool) -> Vec<(String, Results)> {
    let run = |s: &Scene, k: &Kernel| {
        let mut out = Results::for_kernel(k, rays.len());
        k.run(s, rays, &mut out);
        out
    };
    let mut out: Vec<(String, Results)> =
        KERNELS.iter().filter(|k| !k.simd && keep(k)).map(|k| (k.name.to_string(), run(scene, k))).collect();
    for layout in raypack::TreeLayout::ALL {
        let scene = scene.with_layout(layout);
        let tag = if layout == raypack::TreeLayout::Default { String::new() } else { format!(", {layout}") };
        for (isa, s) in on_every_isa(&scene) {
            out.extend(
                raypack::kernels::simd_kernels()
                    .filter(|k| keep(k))
                    .map(|k| (format!("{} [{isa}{tag}]", k.name), run(&s, k))),
            );
        }
    }
    out
}

/// `n` long thin triangles, each from near one side of the cube [-1, 1]^3 to near the
/// opposite side, in random directions: the boxes of any object split overlap, which is
/// where a builder's spatial splits (`BuildQuality::High`) cut triangles.
pub fn slivers(n: usize, seed: u64) -> Mesh {
    let mut rng = Rng::new(seed, 0x511_7E25);
    let mut m = Mesh::default();
    for i in 0..n as u32 {
        let mut r3 = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
        let a = r3();
        let b = -a + r3() * 0.1;
        let c = a + r3() * 0.05;
        m.positions.extend([a, b, c]);
        m.indices.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    m
}

/// The `.rs` files below each of `dirs`, sorted.
pub fn rust_sources(dirs: &[&Path]) -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let p = entry.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|e| e == "rs") {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    for d in dirs {
        walk(d, &mut out);
    }
    out.sort();
    out
}
