//! Shared code of raypack's fuzz targets: the checks every loader target makes on what a
//! loader returns, and the byte encoding of the build + traverse target's input (decoded
//! by [`SceneInput::decode`], written by [`SceneInput::encode`] for the seed corpus).
//!
//! The decoding is total: every byte string is some scene, ray set and `BuildOptions`, and
//! missing bytes read as zero, so libFuzzer's mutations always reach the builder.

use raypack::io::{LoadError, SceneFormat, load_scene_from_bytes};
use raypack::{BuildOptions, BuildQuality, Hit, Ray, Scene, SceneBuilder, SplitMethod, Vec3};
use std::path::Path;

// ----- loaders ------------------------------------------------------------------------------

/// Loads `data` as `name` (whose extension names the format) and checks what comes back:
/// an error names the file first and, for parse errors, a location; a scene commits, and a
/// ray through its centre stays in range. Returns the builder's triangle count when it loaded.
pub fn load_and_check(data: &[u8], format: SceneFormat, name: &str) -> Option<usize> {
    match load_scene_from_bytes(data, format, Path::new(name)) {
        Ok(loaded) => {
            for w in &loaded.warnings {
                assert!(w.starts_with(name), "warning does not name the file: {w}");
            }
            Some(commit_and_trace(loaded.builder))
        }
        Err(e) => {
            check_error(&e, name);
            None
        }
    }
}

/// An error must name the file first, and a parse error must say where.
pub fn check_error(e: &LoadError, name: &str) {
    let text = e.to_string();
    assert!(text.starts_with(name), "error does not name the file first: {text}");
    if let LoadError::Parse { location, message, .. } = e {
        assert!(!location.is_empty(), "parse error without a location: {text}");
        assert!(!message.is_empty(), "parse error without a message: {text}");
    }
}

/// Commits a loaded scene and traces the camera's centre ray; returns the triangle count.
pub fn commit_and_trace(builder: SceneBuilder) -> usize {
    let n = builder.num_triangles();
    let (scene, report) = builder.commit(&BuildOptions::default());
    assert_eq!(report.triangles + report.dropped_non_finite + report.dropped_degenerate, n);
    assert_eq!(scene.num_triangles(), report.triangles);
    let camera = scene.camera_or_framing(4.0 / 3.0);
    for (x, y) in [(0.5, 0.5), (0.25, 0.75)] {
        let ray = camera.generate_ray(x, y);
        check_ray(&scene, &ray);
    }
    n
}

// ----- build + traverse ----------------------------------------------------------------------

/// Floats the decoder picks from by tag: the values that break geometry code.
pub const SPECIAL_FLOATS: [f32; 24] = [
    0.0,
    -0.0,
    1.0,
    -1.0,
    0.5,
    2.0,
    f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    1e18,
    -1e18,
    1.844e18,
    2e18,
    f32::MAX,
    f32::MIN,
    f32::MIN_POSITIVE,
    1e-45,
    1e-30,
    1e-7,
    -1e-7,
    0.1,
    1.0 + f32::EPSILON,
    1.0 - f32::EPSILON / 2.0,
    3.0,
];

/// A cursor over the fuzz input; reads past the end give zeros.
struct Bytes<'a> {
    data: &'a [u8],
    pos: usize,
}

impl Bytes<'_> {
    fn u8(&mut self) -> u8 {
        let b = self.data.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }

    /// A float: tag `< 24` picks from [`SPECIAL_FLOATS`], `24..128` a small multiple of 1/8
    /// (many coincident and coplanar values), `>= 128` the next four bytes as raw `f32` bits.
    fn f32(&mut self) -> f32 {
        let tag = self.u8();
        match tag {
            0..24 => SPECIAL_FLOATS[tag as usize],
            24..128 => (tag as f32 - 76.0) / 8.0,
            _ => f32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()]),
        }
    }

    fn vec3(&mut self) -> Vec3 {
        Vec3::new(self.f32(), self.f32(), self.f32())
    }
}

fn put_f32(out: &mut Vec<u8>, x: f32) {
    out.push(0x80);
    out.extend_from_slice(&x.to_le_bytes());
}

fn put_vec3(out: &mut Vec<u8>, v: Vec3) {
    for c in v.to_array() {
        put_f32(out, c);
    }
}

/// How a ray of the input is made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RaySpec {
    /// Taken as is.
    Free(Ray),
    /// From `origin` towards the point with barycentric weights `(1 - u - v, u, v)` of
    /// triangle `tri` (modulo the triangle count), over `[tnear, tfar]`: rays that hit
    /// vertices, edges and interiors exactly.
    Aimed {
        /// Ray origin.
        origin: Vec3,
        /// Triangle index (wrapped).
        tri: u8,
        /// Barycentric weight of the second vertex.
        u: f32,
        /// Barycentric weight of the third vertex.
        v: f32,
        /// Interval start.
        tnear: f32,
        /// Interval end.
        tfar: f32,
    },
}

/// The decoded input of the build + traverse target.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneInput {
    /// Build options (every field from the input).
    pub options: BuildOptions,
    /// Mesh vertices.
    pub positions: Vec<Vec3>,
    /// Triangles; indices may be out of range (then `add_mesh` must refuse the mesh).
    pub triangles: Vec<[u32; 3]>,
    /// Spheres.
    pub spheres: Vec<(Vec3, f32)>,
    /// Rays to trace.
    pub rays: Vec<RaySpec>,
}

/// Barycentric weights aimed rays choose from: vertices, edge midpoints, centroid, outside.
const AIM_WEIGHTS: [(f32, f32); 8] =
    [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.5, 0.0), (0.5, 0.5), (0.0, 0.5), (1.0 / 3.0, 1.0 / 3.0), (0.6, 0.6)];

impl SceneInput {
    /// Decodes any byte string.
    pub fn decode(data: &[u8]) -> Self {
        let mut b = Bytes { data, pos: 0 };
        let flags = b.u8();
        let options = BuildOptions {
            max_leaf_size: (b.u8() % 20) as usize,
            bins: match b.u8() {
                0 => None,
                x => Some(x as usize * 3 - 3),
            },
            quality: [BuildQuality::Fast, BuildQuality::Medium, BuildQuality::High][(flags % 3) as usize],
            split: if flags & 4 != 0 { SplitMethod::Median } else { SplitMethod::Sah },
            watertight: flags & 8 != 0,
            traversal_cost: if flags & 16 != 0 { b.f32() } else { 1.0 },
            // The reference traversal the kernels are compared with.
            keep_bvh2: true,
            ..BuildOptions::default()
        };
        let (nv, nt, ns, nr) = (b.u8() % 65, b.u8() % 129, b.u8() % 9, b.u8() % 33);
        let positions = (0..nv).map(|_| b.vec3()).collect::<Vec<_>>();
        let wrap = |i: u8| if nv == 0 || i == 255 { i as u32 } else { (i % nv) as u32 };
        let triangles = (0..nt).map(|_| [wrap(b.u8()), wrap(b.u8()), wrap(b.u8())]).collect();
        let spheres = (0..ns).map(|_| (b.vec3(), b.f32())).collect();
        let rays = (0..nr)
            .map(|_| {
                let mode = b.u8();
                let origin = b.vec3();
                if mode & 1 == 0 {
                    let dir = b.vec3();
                    let (tnear, tfar) = if mode & 2 == 0 { (0.0, f32::INFINITY) } else { (b.f32(), b.f32()) };
                    RaySpec::Free(Ray::segment(origin, dir, tnear, tfar))
                } else {
                    let tri = b.u8();
                    let (u, v) = if mode & 4 == 0 { AIM_WEIGHTS[(mode >> 3) as usize % 8] } else { (b.f32(), b.f32()) };
                    let (tnear, tfar) = if mode & 2 == 0 { (0.0, f32::INFINITY) } else { (b.f32(), b.f32()) };
                    RaySpec::Aimed { origin, tri, u, v, tnear, tfar }
                }
            })
            .collect();
        SceneInput { options, positions, triangles, spheres, rays }
    }

    /// Encodes a scene for the seed corpus (options: defaults except those named by the
    /// arguments; at most 64 vertices, 128 triangles, 8 spheres and 32 rays are kept).
    pub fn encode(&self) -> Vec<u8> {
        let o = &self.options;
        let quality = match o.quality {
            BuildQuality::Fast => 0,
            BuildQuality::Medium => 1,
            BuildQuality::High => 2,
        };
        let flags =
            quality | if o.split == SplitMethod::Median { 4 } else { 0 } | if o.watertight { 8 } else { 0 } | 16;
        let mut out = vec![flags, o.max_leaf_size.min(19) as u8, o.bins.map_or(0, |b| (b / 3 + 1).min(255) as u8)];
        put_f32(&mut out, o.traversal_cost);
        let (nv, nt, ns, nr) = (
            self.positions.len().min(64),
            self.triangles.len().min(128),
            self.spheres.len().min(8),
            self.rays.len().min(32),
        );
        out.extend_from_slice(&[nv as u8, nt as u8, ns as u8, nr as u8]);
        for p in &self.positions[..nv] {
            put_vec3(&mut out, *p);
        }
        for t in &self.triangles[..nt] {
            out.extend(t.map(|i| i.min(254) as u8));
        }
        for (c, r) in &self.spheres[..ns] {
            put_vec3(&mut out, *c);
            put_f32(&mut out, *r);
        }
        for r in &self.rays[..nr] {
            match *r {
                RaySpec::Free(ray) => {
                    out.push(2);
                    put_vec3(&mut out, ray.origin);
                    put_vec3(&mut out, ray.dir);
                    put_f32(&mut out, ray.tnear);
                    put_f32(&mut out, ray.tfar);
                }
                RaySpec::Aimed { origin, tri, u, v, tnear, tfar } => {
                    out.push(1 | 2 | 4);
                    put_vec3(&mut out, origin);
                    out.push(tri);
                    put_f32(&mut out, u);
                    put_f32(&mut out, v);
                    put_f32(&mut out, tnear);
                    put_f32(&mut out, tfar);
                }
            }
        }
        out
    }

    /// The ray a [`RaySpec`] stands for, given the input's triangles.
    pub fn ray(&self, spec: &RaySpec) -> Ray {
        match *spec {
            RaySpec::Free(r) => r,
            RaySpec::Aimed { origin, tri, u, v, tnear, tfar } => {
                let target = match self.triangles.get(tri as usize % self.triangles.len().max(1)) {
                    Some(t) => {
                        let p = |k: usize| self.positions.get(t[k] as usize).copied().unwrap_or(Vec3::ZERO);
                        p(0) * (1.0 - u - v) + p(1) * u + p(2) * v
                    }
                    None => Vec3::ZERO,
                };
                Ray::segment(origin, target - origin, tnear, tfar)
            }
        }
    }

    /// Builds the scene and checks every ray (see [`check_ray`]); also that the builder
    /// refuses out-of-range indices and that the commit report adds up.
    pub fn run(&self) {
        let mut builder = SceneBuilder::new();
        let m = builder.add_material(raypack::Material::default());
        let bad_index = self.triangles.iter().flatten().any(|&i| i as usize >= self.positions.len());
        let added = builder.add_mesh(&self.positions, &self.triangles, m);
        assert_eq!(added.is_err(), bad_index, "add_mesh: {added:?}");
        for &(c, r) in &self.spheres {
            builder.add_sphere(c, r, m).expect("material exists");
        }
        let tris_in = builder.num_triangles();
        let (scene, report) = builder.commit(&self.options);
        assert_eq!(report.triangles + report.dropped_non_finite + report.dropped_degenerate, tris_in);
        assert_eq!(report.spheres + report.dropped_spheres, self.spheres.len());
        assert_eq!((scene.num_triangles(), scene.num_spheres()), (report.triangles, report.spheres));
        let bounds: Vec<_> = (0..scene.num_prims() as u32).map(|p| scene.prim_bounds(p)).collect();
        if let Err(e) = raypack::bvh::validate::validate_bvh2(scene.bvh2().expect("kept"), &bounds) {
            panic!("invalid BVH2 for {:?}: {e}", self.options);
        }
        for spec in &self.rays {
            check_ray(&scene, &self.ray(spec));
        }
    }
}

/// Relative slack allowed between a BVH traversal and brute force: the reference slab test
/// is not padded against the rounding of the primitive tests (no `1 + 2γ` factor as in Ize,
/// "Robust BVH Ray Traversal", JCGT 2013), so a box can be culled when a hit lies within a few
/// ulps of `tnear`, `tfar` or the current closest hit. Differences within this slack pass;
/// with `RAYPACK_FUZZ_EXACT=1` none is allowed (to check a conservative traversal).
pub fn slack() -> f32 {
    static SLACK: std::sync::OnceLock<f32> = std::sync::OnceLock::new();
    *SLACK.get_or_init(|| if std::env::var_os("RAYPACK_FUZZ_EXACT").is_some_and(|v| v == "1") { 0.0 } else { 4e-6 })
}

/// The traversal oracle for one ray: the public kernels (`intersect1`, `occluded1`) and the
/// reference BVH2 traversal answer what testing every primitive answers (within a [`slack`]
/// tolerance); `intersect1` and the reference report the same `t` bits when they report the
/// same primitive (kernel twins agree); a hit lies in `[tnear, tfar]` with finite `t`, `u`,
/// `v`; invalid rays miss.
pub fn check_ray(scene: &Scene, ray: &Ray) {
    let got = scene.intersect1(ray);
    let reference = scene.intersect1_reference(ray);
    let brute = scene.intersect1_brute_force(ray);
    let occluded = scene.occluded1(ray);
    let occluded_reference = scene.occluded1_reference(ray);
    if !ray.is_valid() {
        assert!(!got.is_hit() && !reference.is_hit() && !occluded && !occluded_reference, "invalid ray hit: {ray:?}");
        return;
    }
    if got.prim == reference.prim && got.is_hit() {
        assert_eq!(got.t.to_bits(), reference.t.to_bits(), "intersect1 vs reference, same prim: {ray:?}");
    }
    for hit in [&got, &reference] {
        if hit.is_hit() {
            assert!(
                hit.t >= ray.tnear && hit.t <= ray.tfar,
                "t {} outside [{}, {}]: {ray:?}",
                hit.t,
                ray.tnear,
                ray.tfar
            );
            assert!(hit.t.is_finite() || nonfinite_tolerated(), "hit at t = {}: {ray:?} {hit:?}", hit.t);
            assert!(
                hit.u.is_finite() && hit.v.is_finite() || nonfinite_tolerated(),
                "non-finite u, v: {ray:?} {hit:?}"
            );
        }
    }
    if ![&brute, &reference, &got].iter().all(|h| in_own_box(scene, ray, h)) {
        return;
    }
    let tol = Tolerance::of(scene, ray);
    agrees(scene, ray, &tol, &reference, &brute, "reference BVH2 vs brute force");
    agrees(scene, ray, &tol, &got, &brute, "intersect1 vs brute force");
    // The hit that decides an any-hit query is the closest one; at the interval's ends the
    // traversal may cull within the tolerance.
    if !(brute.is_hit() && tol.near_end(ray, brute.t)) {
        assert_eq!(occluded_reference, brute.is_hit(), "occluded1_reference vs brute force: {ray:?} {brute:?}");
        assert_eq!(occluded, brute.is_hit(), "occluded1 vs brute force: {ray:?} {brute:?}");
    }
    if got.is_hit() && got.t.is_finite() && !tol.close(got.t, ray.tnear) {
        // A ray stopping just past the closest hit is blocked; one stopping just short of it
        // is blocked exactly when brute force finds something there.
        let past = Ray { tfar: got.t + 2.0 * tol.at(got.t), ..*ray };
        assert!(scene.occluded1(&past), "hit at t = {} but not occluded over [tnear, t]: {ray:?}", got.t);
        let short = Ray { tfar: got.t - 2.0 * tol.at(got.t), ..*ray };
        if short.is_valid() {
            let b = scene.intersect1_brute_force(&short);
            if !(b.is_hit() && tol.near_end(&short, b.t)) {
                assert_eq!(scene.occluded1(&short), b.is_hit(), "short ray {short:?}: brute {b:?}");
            }
        }
    }
}

/// How far apart two `t` of one ray may be and still count as the same: [`slack`] relative
/// to `t`, plus the slack relative to the coordinates' magnitude divided by `|dir|` (a
/// primitive test's `t` is only as precise as the coordinates it subtracts), plus `1e-30`
/// (products of coordinates below `1e-19` are denormal).
struct Tolerance {
    /// The coordinate term, in units of `t`.
    base: f32,
}

impl Tolerance {
    fn of(scene: &Scene, ray: &Ray) -> Self {
        let m = |v: Vec3| v.abs().max_element();
        let b = scene.bounds();
        let geometry = if b.is_valid() { m(b.min).max(m(b.max)) } else { 0.0 };
        let scale = m(ray.origin).max(geometry);
        // Matches `in_own_box`'s tolerance on points, which is `4 slack` relative.
        let base = if slack() > 0.0 { 8.0 * slack() * scale / m(ray.dir) + 1e-30 } else { 0.0 };
        Tolerance { base }
    }

    fn at(&self, t: f32) -> f32 {
        slack() * t.abs() + self.base
    }

    fn close(&self, a: f32, b: f32) -> bool {
        a == b || (a - b).abs() <= self.at(a.abs().max(b.abs()))
    }

    fn near_end(&self, ray: &Ray, t: f32) -> bool {
        self.close(t, ray.tnear) || self.close(t, ray.tfar)
    }
}

/// Known issue, reported (not fixed here: src/geometry is another task's): the primitive
/// tests can return a hit with non-finite `t`, `u` or `v`, which reads like a miss (`t = inf`)
/// or poisons shading (NaN). Causes the fuzzer found:
/// * Möller–Trumbore's `v < 0.0 || u + v > 1.0` lets a NaN `v` through when
///   `dir · ((o - v0) × e1)` overflows;
/// * its `t > tnear && t <= tfar` accepts `t = inf` when `1 / det` overflows (huge sliver
///   triangles) or when `distance / |dir|` does (denormal directions);
/// * the sphere test's `sqrt(a · disc)` with `a = |dir|²` overflows when `|dir| · radius >
///   1.8e19`, and the far root becomes a hit at `t = inf`.
///
/// The fix is one guard in each test (`t.is_finite()`, `!(v >= 0.0)`), as Embree's robust
/// mode rejects such hits. Tolerated unless `RAYPACK_FUZZ_EXACT=1`.
fn nonfinite_tolerated() -> bool {
    slack() != 0.0
}

/// True for a miss, or a hit whose point lies in its primitive's bounding box (up to
/// [`slack`]): only such hits can a BVH promise to find, since its boxes are all it knows.
/// A primitive test can report a point outside the box when `f32` cancels catastrophically:
/// Möller–Trumbore on a 5e-7 sliver reports `t = 0.99977` for a ray that passes its vertex
/// at `t = 1`; a ray from `z = 1e18` "hits" a unit triangle at `z = 5e17`. Rays with such
/// hits are only checked for staying in range, missing when invalid, and not panicking or
/// hanging: brute force is no oracle for them.
fn in_own_box(scene: &Scene, ray: &Ray, hit: &Hit) -> bool {
    if !hit.is_hit() {
        return true;
    }
    if !hit.t.is_finite() {
        return false;
    }
    let b = scene.prim_bounds(hit.prim);
    let t = hit.t as f64;
    (0..3).all(|k| {
        let (o, d) = (ray.origin[k] as f64, ray.dir[k] as f64);
        let p = o + d * t;
        let (lo, hi) = (b.min[k] as f64, b.max[k] as f64);
        // Relative to the point and the origin, not to the box: the box is exact (the
        // vertices' min and max), only the test's `t` is rounded.
        let tol = 4.0 * slack() as f64 * o.abs().max(p.abs()) + 1e-30;
        // Slab tests take `1 / d` as `±1e18` for `|d| < 1e-18` (`math::safe_recip`, as
        // Embree's `rcp_safe`): then the slab is only seen as reaching `t` when the origin lies
        // at least `1e-18 t` inside it.
        let resolvable = d.abs() >= 1e-18 || (hi - o >= 2e-18 * t && o - lo >= 2e-18 * t);
        p >= lo - tol && p <= hi + tol && resolvable
    })
}

/// `got` answers what brute force (`want`) answers, allowing the traversal to miss a hit
/// within the tolerance of `tnear` or `tfar` and to find one within it of the closest.
fn agrees(scene: &Scene, ray: &Ray, tol: &Tolerance, got: &Hit, want: &Hit, what: &str) {
    match (got.is_hit(), want.is_hit()) {
        (false, false) => {}
        (true, false) => panic!("{what}: {ray:?}: phantom hit {got:?}"),
        (false, true) => assert!(tol.near_end(ray, want.t), "{what}: {ray:?}: missed {want:?}"),
        (true, true) => {
            // Either the same distance, or the closest hit sat at `tnear` and was culled.
            assert!(
                tol.close(got.t, want.t) || tol.close(want.t, ray.tnear),
                "{what}: {ray:?}: t {} vs {} ({got:?} vs {want:?})",
                got.t,
                want.t
            );
            // The reported primitive is really hit there.
            let again = scene.intersect_prim(got.prim, ray, ray.tfar);
            assert!(
                again.is_some_and(|(t, ..)| t.to_bits() == got.t.to_bits()),
                "{what}: {ray:?}: prim {} reported at t {} but its test gives {again:?}",
                got.prim,
                got.t
            );
        }
    }
}

/// The format of a fuzz target's input by file name.
pub fn format_of(name: &str) -> SceneFormat {
    SceneFormat::from_path(Path::new(name)).expect("a .dae, .obj or .ply name")
}
