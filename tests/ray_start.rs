//! Hits at the ray's start: a ray covers `t` in `[tnear, tfar]`, so a surface at exactly
//! `t = tnear` counts, and a ray that starts on a surface (`tnear = 0`) hits it at `t = +0.0`,
//! as Embree's robust mode and trimesh's ray engines do.
//!
//! The scene is the unit box `[-0.5, 0.5]^3` (two triangles per face) and a sphere of radius
//! 0.5 at `(3, 3, 3)`, far from the box. The answers are closed forms: a ray from a point of a
//! face hits that face's triangles at `t = 0` (the box's coordinates, the points and the
//! axis-aligned directions are exact in `f32`); from a pole of the sphere, the sphere at
//! `t = 0`; inward along an axis, with `tnear` just above 0, the opposite side at `t = 1`;
//! outward, nothing. Every kernel of the registry on every ISA tier must give them, with both
//! triangle tests.

mod common;

use common::every_kernel;
use raypack::generate::Mesh;
use raypack::kernels::Results;
use raypack::{BuildOptions, Hit, Ray, Scene, Vec3};

/// The unit box: face `f` (`f / 2` the axis, `f % 2 == 1` the + side) holds triangles
/// `2 f` and `2 f + 1`.
fn unit_box() -> Mesh {
    let mut m = Mesh::default();
    for axis in 0..3 {
        for side in [-0.5f32, 0.5] {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            let corner = |u: f32, v: f32| {
                let mut p = Vec3::ZERO;
                p[axis] = side;
                p[a] = u;
                p[b] = v;
                p
            };
            let base = m.positions.len() as u32;
            m.positions.extend([corner(-0.5, -0.5), corner(0.5, -0.5), corner(0.5, 0.5), corner(-0.5, 0.5)]);
            m.indices.extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
        }
    }
    m
}

const SPHERE: (Vec3, f32) = (Vec3::new(3.0, 3.0, 3.0), 0.5);
/// The sphere's primitive id: after the box's 12 triangles.
const SPHERE_PRIM: u32 = 12;

fn scene(watertight: bool) -> Scene {
    common::scene_of(&[&unit_box()], &[SPHERE], &BuildOptions { watertight, ..BuildOptions::default() })
}

/// A ray and the answer it must get: the primitives it may hit (both triangles of a face
/// where the point lies on their shared diagonal) and `t`, or `None` for a miss.
struct Case {
    what: String,
    ray: Ray,
    want: Option<(Vec<u32>, f32)>,
}

/// Rays from points of each face of the box and from the sphere's six poles, inward,
/// outward and oblique, with `tnear = 0` (the surface at the start counts) and with `tnear`
/// the smallest positive float (it does not: the next surface along the ray, or nothing).
fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    for face in 0..6u32 {
        let (axis, plus) = ((face / 2) as usize, face % 2 == 1);
        let normal = {
            let mut n = Vec3::ZERO;
            n[axis] = if plus { 1.0 } else { -1.0 };
            n
        };
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        for (u, v) in [(0.1f32, 0.3), (-0.25, 0.375), (0.0, 0.0), (0.25, -0.125)] {
            let mut p = Vec3::ZERO;
            p[axis] = normal[axis] * 0.5;
            p[a] = u;
            p[b] = v;
            let tris = vec![2 * face, 2 * face + 1];
            let mut oblique = -normal;
            oblique[a] = 0.25;
            for (name, dir) in [("inward", -normal), ("outward", normal), ("oblique inward", oblique)] {
                let what = format!("face {face} at {p}, {name}");
                out.push(Case { what: what.clone(), ray: Ray::new(p, dir), want: Some((tris.clone(), 0.0)) });
                // Past the start: inward along the axis the opposite face at t = 1; outward
                // nothing (the box is convex and the sphere is elsewhere). Oblique rays are
                // only checked at the start (where they leave the box is not exact).
                let next = match name {
                    "inward" => Some(((2 * (face ^ 1)..2 * (face ^ 1) + 2).collect(), 1.0)),
                    "outward" => None,
                    _ => continue,
                };
                let ray = Ray::segment(p, dir, f32::from_bits(1), f32::INFINITY);
                out.push(Case { what: format!("{what}, tnear 1e-45"), ray, want: next });
            }
        }
    }
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut n = Vec3::ZERO;
            n[axis] = sign;
            let pole = SPHERE.0 + n * SPHERE.1;
            for (name, dir) in [("inward", -n), ("outward", n)] {
                let what = format!("sphere pole {pole}, {name}");
                out.push(Case { what: what.clone(), ray: Ray::new(pole, dir), want: Some((vec![SPHERE_PRIM], 0.0)) });
                let next = (name == "inward").then(|| (vec![SPHERE_PRIM], 1.0));
                let ray = Ray::segment(pole, dir, f32::from_bits(1), f32::INFINITY);
                out.push(Case { what: format!("{what}, tnear 1e-45"), ray, want: next });
            }
        }
    }
    // A surface at exactly t = tnear away from the origin: the top face at t = 1 counts with
    // tnear = 1 and not with the next float above, which leaves the bottom face at t = 2.
    let from_above = Ray::new(Vec3::new(0.1, 0.2, 1.5), -Vec3::Z);
    out.push(Case {
        what: "top face at t = tnear = 1".into(),
        ray: Ray { tnear: 1.0, ..from_above },
        want: Some((vec![10, 11], 1.0)),
    });
    out.push(Case {
        what: "top face just before tnear".into(),
        ray: Ray { tnear: 1.0f32.next_up(), ..from_above },
        want: Some((vec![8, 9], 2.0)),
    });
    out.push(Case {
        what: "top face at t = tfar = 1".into(),
        ray: Ray { tfar: 1.0, ..from_above },
        want: Some((vec![10, 11], 1.0)),
    });
    out.push(Case {
        what: "tnear = tfar = 1 on the top face".into(),
        ray: Ray { tnear: 1.0, tfar: 1.0, ..from_above },
        want: Some((vec![10, 11], 1.0)),
    });
    out
}

fn check(scene: &Scene, cases: &[Case]) -> usize {
    let rays: Vec<Ray> = cases.iter().map(|c| c.ray).collect();
    let test = scene.triangle_test().name();
    let mut checked = 0;
    for (kernel, results) in every_kernel(scene, &rays) {
        for (i, c) in cases.iter().enumerate() {
            let what = format!("{test} {kernel}: {}", c.what);
            match &results {
                Results::Hits(h) => {
                    let h: &Hit = &h[i];
                    match &c.want {
                        Some((prims, t)) => {
                            assert!(h.is_hit(), "{what}: missed, expected a hit at t = {t} on {prims:?}");
                            assert!(prims.contains(&h.prim), "{what}: hit {}, expected one of {prims:?}", h.prim);
                            assert_eq!(h.t.to_bits(), t.to_bits(), "{what}: t = {:e}, expected {t:e}", h.t);
                        }
                        None => assert!(!h.is_hit(), "{what}: hit {h:?}, expected a miss"),
                    }
                }
                Results::Occluded(o) => assert_eq!(o[i], c.want.is_some(), "{what}: occlusion"),
            }
            checked += 1;
        }
    }
    checked
}

#[test]
fn a_surface_at_the_rays_start_is_hit_at_t_zero_in_every_kernel() {
    for watertight in [false, true] {
        let checked = check(&scene(watertight), &cases());
        assert!(checked > 1000, "{checked} answers checked");
        eprintln!(
            "ray start ({}): {checked} answers checked",
            if watertight { "watertight" } else { "moller-trumbore" }
        );
    }
}

/// Embree built with `RTC_SCENE_FLAG_ROBUST` (the watertight test raypack's watertight mode
/// is checked against, and the mode trimesh's embreex engine uses) gives the same answers on
/// the same rays: hits at `t = tnear` count there too. (Embree documents no guarantee at
/// exactly `tnear`; its default Möller–Trumbore test in Embree 3 leaves them out.)
#[cfg(feature = "embree")]
#[test]
fn robust_embree_counts_hits_at_the_rays_start_too() {
    use raypack::embree::{EmbreeOptions, EmbreeScene};
    // The box alone (raypack's Embree bridge takes triangles only): its triangle ids are the
    // scene's, and no box case reaches the sphere.
    let b = unit_box();
    let embree =
        EmbreeScene::from_mesh(&b.positions, &b.indices, EmbreeOptions { robust: true, ..EmbreeOptions::default() })
            .expect("Embree accepts the box");
    let cases: Vec<Case> = cases().into_iter().filter(|c| !c.what.starts_with("sphere")).collect();
    let rays: Vec<Ray> = cases.iter().map(|c| c.ray).collect();
    let mut hits = vec![Hit::MISS; rays.len()];
    embree.intersect1(&rays, &mut hits);
    let mut occluded = vec![false; rays.len()];
    embree.occluded1(&rays, &mut occluded);
    for ((c, h), o) in cases.iter().zip(&hits).zip(&occluded) {
        let what = format!("Embree {} robust: {}", embree.version(), c.what);
        match &c.want {
            Some((prims, t)) => {
                assert!(h.is_hit() && prims.contains(&h.prim), "{what}: {h:?}, expected one of {prims:?}");
                // Embree reports a hit at the origin as -0.0 where raypack gives +0.0.
                assert_eq!(h.t, *t, "{what}: t = {:e}", h.t);
            }
            None => assert!(!h.is_hit(), "{what}: {h:?}, expected a miss"),
        }
        assert_eq!(*o, c.want.is_some(), "{what}: occlusion");
    }
}
