//! Gathers geometry, materials, lights and a camera, then commits them into a [`Scene`].
//!
//! `add_*` calls check the buffers they are given (index ranges, material ids) and return
//! [`SceneError`] on malformed input. [`SceneBuilder::commit`] never fails: it drops
//! primitives that cannot be traced (NaN/Inf or absurdly large coordinates, zero-area or
//! collinear triangles, non-positive radii) and counts them in the [`CommitReport`], as Embree does.
//! An empty scene is legal: every ray misses.

use crate::bvh::TreeLayout;
use crate::bvh::{
    BuildOptions, BuildPrim, BuildQuality, Bvh2, Bvh8, SplitMethod, build_bvh2_kinds, build_bvh2_spatial, collapse_for,
};
use crate::geometry::TriangleTest;
use crate::math::{Aabb, Vec3};
use crate::scene::{Camera, Light, Material, MaterialId, Scene, SpheresSoa, TrianglesSoa};
use crate::simd::Isa;

/// Coordinates beyond this magnitude are rejected at commit (Embree's limit, `FLT_LARGE`).
pub const MAX_COORDINATE: f32 = 1.844e18;

/// Malformed input to a [`SceneBuilder`] call.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SceneError {
    /// A triangle refers to a vertex that does not exist.
    #[error("triangle {triangle} refers to vertex {index}, but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        /// Triangle number within the mesh.
        triangle: usize,
        /// The offending index.
        index: u32,
        /// Number of vertices given.
        vertices: usize,
    },
    /// A material id that was never added.
    #[error("material {0} does not exist")]
    UnknownMaterial(MaterialId),
    /// Normals were given but not one per vertex.
    #[error("{normals} normals given for {vertices} vertices")]
    NormalCount {
        /// Normals given.
        normals: usize,
        /// Vertices given.
        vertices: usize,
    },
    /// The scene would exceed `u32` primitive ids.
    #[error("too many primitives (more than 2^32 - 2)")]
    TooLarge,
}

/// What [`SceneBuilder::commit`] kept and dropped.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CommitReport {
    /// Triangles kept.
    pub triangles: usize,
    /// Spheres kept.
    pub spheres: usize,
    /// Triangles dropped for NaN/Inf or out-of-range coordinates.
    pub dropped_non_finite: usize,
    /// Triangles dropped for having zero area, or a normal lost in rounding (collinear
    /// corners; see [`is_degenerate`]).
    pub dropped_degenerate: usize,
    /// Spheres dropped (non-finite centre or radius, radius <= 0).
    pub dropped_spheres: usize,
}

impl CommitReport {
    /// Total primitives dropped.
    pub fn dropped(&self) -> usize {
        self.dropped_non_finite + self.dropped_degenerate + self.dropped_spheres
    }
}

impl std::fmt::Display for CommitReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} triangles, {} spheres", self.triangles, self.spheres)?;
        if self.dropped() > 0 {
            write!(
                f,
                " (dropped {} triangles with NaN/Inf/huge coordinates, {} zero-area or collinear triangles, {} invalid spheres)",
                self.dropped_non_finite, self.dropped_degenerate, self.dropped_spheres
            )?;
        }
        Ok(())
    }
}

/// Collects a scene; see the module docs.
#[derive(Clone, Debug, Default)]
pub struct SceneBuilder {
    triangles: TrianglesSoa,
    has_normals: bool,
    spheres: SpheresSoa,
    materials: Vec<Material>,
    lights: Vec<Light>,
    camera: Option<Camera>,
}

impl SceneBuilder {
    /// An empty builder.
    pub fn new() -> Self {
        Self::default()
    }

    /// A builder holding these arrays as they are (for a scene read back from bytes,
    /// [`crate::scene::snapshot`], whose caller has checked every index).
    pub(crate) fn from_parts(
        triangles: TrianglesSoa,
        spheres: SpheresSoa,
        materials: Vec<Material>,
        lights: Vec<Light>,
        camera: Option<Camera>,
    ) -> Self {
        let has_normals = !triangles.normals.is_empty();
        Self { triangles, has_normals, spheres, materials, lights, camera }
    }

    /// Adds a material and returns its id.
    pub fn add_material(&mut self, m: Material) -> MaterialId {
        self.materials.push(m);
        (self.materials.len() - 1) as MaterialId
    }

    /// The materials added so far.
    pub fn materials(&self) -> &[Material] {
        &self.materials
    }

    /// Adds a triangle mesh (positions already in world space).
    pub fn add_mesh(
        &mut self,
        positions: &[Vec3],
        indices: &[[u32; 3]],
        material: MaterialId,
    ) -> Result<(), SceneError> {
        self.add_mesh_with_normals(positions, None, indices, material)
    }

    /// Adds a triangle mesh with optional per-vertex shading normals.
    pub fn add_mesh_with_normals(
        &mut self,
        positions: &[Vec3],
        normals: Option<&[Vec3]>,
        indices: &[[u32; 3]],
        material: MaterialId,
    ) -> Result<(), SceneError> {
        self.check_material(material)?;
        if let Some(n) = normals
            && n.len() != positions.len()
        {
            return Err(SceneError::NormalCount { normals: n.len(), vertices: positions.len() });
        }
        for (t, tri) in indices.iter().enumerate() {
            if let Some(&index) = tri.iter().find(|&&i| i as usize >= positions.len()) {
                return Err(SceneError::IndexOutOfRange { triangle: t, index, vertices: positions.len() });
            }
        }
        let base = self.triangles.positions.len();
        if base + positions.len() > u32::MAX as usize || self.triangles.len() + indices.len() >= u32::MAX as usize - 1 {
            return Err(SceneError::TooLarge);
        }
        let t = &mut self.triangles;
        t.positions.extend_from_slice(positions);
        match normals {
            Some(n) => {
                if !self.has_normals {
                    t.normals.resize(base, Vec3::ZERO);
                    self.has_normals = true;
                }
                t.normals.extend_from_slice(n);
            }
            None if self.has_normals => t.normals.resize(base + positions.len(), Vec3::ZERO),
            None => {}
        }
        let b = base as u32;
        t.indices.extend(indices.iter().map(|&[x, y, z]| [x + b, y + b, z + b]));
        t.material.resize(t.indices.len(), material);
        Ok(())
    }

    /// Adds a sphere.
    pub fn add_sphere(&mut self, center: Vec3, radius: f32, material: MaterialId) -> Result<(), SceneError> {
        self.check_material(material)?;
        self.spheres.center.push(center);
        self.spheres.radius.push(radius);
        self.spheres.material.push(material);
        Ok(())
    }

    /// Adds a light.
    pub fn add_light(&mut self, light: Light) {
        self.lights.push(light);
    }

    /// The lights added so far.
    pub fn lights(&self) -> &[Light] {
        &self.lights
    }

    /// Sets the camera.
    pub fn set_camera(&mut self, camera: Camera) {
        self.camera = Some(camera);
    }

    /// The camera set so far.
    pub fn camera(&self) -> Option<&Camera> {
        self.camera.as_ref()
    }

    /// Triangles added so far.
    pub fn num_triangles(&self) -> usize {
        self.triangles.len()
    }

    /// The vertex indices of the triangles added so far, in the order added (before
    /// [`SceneBuilder::commit`] drops the untraceable ones): what a front end needs to
    /// number hits by the faces its caller or file gave.
    pub fn triangle_indices(&self) -> &[[u32; 3]] {
        &self.triangles.indices
    }

    /// Spheres added so far.
    pub fn num_spheres(&self) -> usize {
        self.spheres.len()
    }

    /// Bounds of everything added so far (before dropping invalid primitives).
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in &self.triangles.positions {
            if p.is_finite() {
                b.grow(*p);
            }
        }
        for i in 0..self.spheres.len() {
            let sb = self.spheres.bounds(i);
            if sb.is_valid() && sb.min.is_finite() && sb.max.is_finite() {
                b = b.union(&sb);
            }
        }
        b
    }

    fn check_material(&self, m: MaterialId) -> Result<(), SceneError> {
        if (m as usize) < self.materials.len() { Ok(()) } else { Err(SceneError::UnknownMaterial(m)) }
    }

    /// Drops untraceable primitives, builds the acceleration structure and returns the
    /// scene with a report of what was kept.
    pub fn commit(self, opts: &BuildOptions) -> (Scene, CommitReport) {
        let mut prims = Vec::new();
        let (kept, report) = self.filter_into(Some(&mut prims));
        (kept.build_over(prims, opts), report)
    }

    /// The triangles [`SceneBuilder::commit`] keeps, and how many spheres it keeps, without
    /// building anything: what another tracer builds over to compare with raypack (as
    /// `raypack info --against embree` does with Embree).
    pub fn into_kept_triangles(self) -> (TrianglesSoa, usize) {
        let (kept, _) = self.filter();
        (kept.triangles, kept.spheres.len())
    }

    /// The first half of [`SceneBuilder::commit`]: drops the primitives that cannot be traced.
    pub(crate) fn filter(self) -> (Filtered, CommitReport) {
        self.filter_into(None)
    }

    /// [`SceneBuilder::filter`], also making the kept primitives' build references
    /// ([`Filtered::build_prims`]) into `prims` when asked, in the same pass over the vertices.
    fn filter_into(self, mut prims: Option<&mut Vec<BuildPrim>>) -> (Filtered, CommitReport) {
        let mut report = CommitReport::default();
        let SceneBuilder { mut triangles, spheres: in_spheres, mut materials, lights, camera, .. } = self;
        if materials.is_empty() {
            materials.push(Material::default());
        }

        let ok = |p: Vec3| p.is_finite() && p.abs().max_element() <= MAX_COORDINATE;
        // The checks run in parallel (the degeneracy test is the costly part of loading a
        // mesh from the BVH cache); the compaction after them keeps the input order.
        #[derive(Clone, Copy, PartialEq)]
        enum Verdict {
            Keep,
            NonFinite,
            Degenerate,
        }
        let verdict = |[a, b, c]: [Vec3; 3]| {
            if !(ok(a) && ok(b) && ok(c)) {
                Verdict::NonFinite
            } else if is_degenerate(a, b, c) {
                Verdict::Degenerate
            } else {
                Verdict::Keep
            }
        };
        let mut verdicts: Vec<Verdict> = Vec::new();
        {
            use rayon::prelude::*;
            let t = &triangles;
            let all = (0..t.indices.len()).into_par_iter();
            match prims.as_deref_mut() {
                None => all.map(|i| verdict(t.vertices(i))).collect_into_vec(&mut verdicts),
                Some(prims) => {
                    *prims = crate::system::huge_page_vec(t.len() + in_spheres.len());
                    all.map(|i| {
                        let v = t.vertices(i);
                        (verdict(v), BuildPrim::new(Aabb::of_triangle(v), i as u32))
                    })
                    .unzip_into_vecs(&mut verdicts, prims);
                }
            }
        }
        // Triangles before the first dropped one stay where they are (usually all of them).
        let first_dropped = verdicts.iter().position(|&v| v != Verdict::Keep).unwrap_or(verdicts.len());
        let mut keep = first_dropped;
        for (i, &v) in verdicts.iter().enumerate().skip(first_dropped) {
            match v {
                Verdict::NonFinite => report.dropped_non_finite += 1,
                Verdict::Degenerate => report.dropped_degenerate += 1,
                Verdict::Keep => {
                    triangles.indices[keep] = triangles.indices[i];
                    triangles.material[keep] = triangles.material[i];
                    if let Some(prims) = prims.as_deref_mut() {
                        let b = prims[i].bounds();
                        prims[keep] = BuildPrim::new(b, keep as u32);
                    }
                    keep += 1;
                }
            }
        }
        triangles.indices.truncate(keep);
        triangles.material.truncate(keep);
        if let Some(prims) = prims.as_deref_mut() {
            prims.truncate(keep);
        }

        let mut spheres = SpheresSoa::default();
        for i in 0..in_spheres.len() {
            let (c, r) = (in_spheres.center[i], in_spheres.radius[i]);
            if ok(c)
                && r.is_finite()
                && r > 0.0
                && r <= MAX_COORDINATE
                && ok(c + Vec3::splat(r))
                && ok(c - Vec3::splat(r))
            {
                spheres.center.push(c);
                spheres.radius.push(r);
                spheres.material.push(in_spheres.material[i]);
            } else {
                report.dropped_spheres += 1;
            }
        }
        report.triangles = triangles.len();
        report.spheres = spheres.len();
        if let Some(prims) = prims {
            let nt = triangles.len();
            prims.extend((0..spheres.len()).map(|i| BuildPrim::new(spheres.bounds(i), (nt + i) as u32)));
        }
        (Filtered { triangles, spheres, materials, lights, camera }, report)
    }
}

/// A scene after [`SceneBuilder::commit`]'s filtering, before its acceleration structure
/// exists: either built ([`Filtered::build`]) or loaded from the BVH cache
/// ([`crate::scene::cache`]).
pub(crate) struct Filtered {
    pub(crate) triangles: TrianglesSoa,
    pub(crate) spheres: SpheresSoa,
    pub(crate) materials: Vec<Material>,
    pub(crate) lights: Vec<Light>,
    pub(crate) camera: Option<Camera>,
}

/// BVH builds this process has started (see [`bvh_builds`]).
static BVH_BUILDS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// How many BVHs this process has built: commits count, scenes whose BVH came from the cache
/// or a snapshot ([`crate::scene::snapshot`]) do not. For checking that a scene was not
/// rebuilt.
pub fn bvh_builds() -> u64 {
    BVH_BUILDS.load(std::sync::atomic::Ordering::Relaxed)
}

impl Filtered {
    /// Builds the binary BVH and collapses it into the 8-wide one (keeping the binary one
    /// only with [`BuildOptions::keep_bvh2`]).
    pub(crate) fn build(self, opts: &BuildOptions) -> Scene {
        let prims = self.build_prims();
        self.build_over(prims, opts)
    }

    /// The build references of the primitives: triangles first (id = index), then spheres
    /// (id = triangle count + index).
    fn build_prims(&self) -> Vec<BuildPrim> {
        let (triangles, spheres) = (&self.triangles, &self.spheres);
        let nt = triangles.len();
        let mut prims: Vec<BuildPrim> = crate::system::huge_page_vec(nt + spheres.len());
        use rayon::prelude::*;
        (0..nt)
            .into_par_iter()
            .map(|i| BuildPrim::new(triangles.bounds(i), i as u32))
            .chain((0..spheres.len()).into_par_iter().map(|i| BuildPrim::new(spheres.bounds(i), (nt + i) as u32)))
            .collect_into_vec(&mut prims);
        prims
    }

    /// [`Filtered::build`] over `prims`, [`Filtered::build_prims`] made by the caller.
    fn build_over(self, mut prims: Vec<BuildPrim>, opts: &BuildOptions) -> Scene {
        BVH_BUILDS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let Filtered { triangles, spheres, materials, lights, camera } = self;
        let nt = triangles.len();
        debug_assert_eq!(prims.len(), nt + spheres.len());
        // High quality cuts triangles that overlap badly (spatial splits, `bvh::build::spatial`).
        let spatial =
            opts.quality == BuildQuality::High && opts.spatial_split_budget > 0.0 && opts.split == SplitMethod::Sah;
        // The builder finds the union of the primitives' boxes, the scene's bounds.
        let (bvh2, bounds) = if spatial {
            let corners = |id: u32| triangles.vertices(id as usize);
            build_bvh2_spatial(prims, opts, nt as u32, opts.spatial_split_budget, &corners)
        } else {
            let built = build_bvh2_kinds(&mut prims, opts, nt as u32);
            drop(prims);
            built
        };
        let mut scene = Scene {
            triangles,
            spheres,
            materials,
            lights,
            camera,
            bounds,
            bvh2: None,
            bvh8: Bvh8::default(),
            isa: Isa::default_for_process(),
        };
        let test = TriangleTest::from_watertight(opts.watertight);
        scene.bvh8 = collapse_for(&bvh2, |id| scene.prim_shape(id), nt as u32, &opts.collapse, test);
        if opts.layout == TreeLayout::Compact {
            scene.bvh8 = std::mem::take(&mut scene.bvh8).into_compact();
        }
        scene.bvh2 = opts.keep_bvh2.then_some(bvh2);
        scene
    }

    /// The scene with acceleration structures that were built for exactly this geometry.
    pub(crate) fn with_accel(self, bounds: Aabb, bvh2: Option<Bvh2>, bvh8: Bvh8) -> Scene {
        let Filtered { triangles, spheres, materials, lights, camera } = self;
        Scene { triangles, spheres, materials, lights, camera, bounds, bvh2, bvh8, isa: Isa::default_for_process() }
    }
}

/// True when triangle `(a, b, c)` has no usable plane: its `f32` cross product vanishes (or
/// underflows), or its corners are collinear within rounding — the sine of the angle at `a`
/// is at most `4 f32::EPSILON`, the size of the rounding error of the edges' cross product
/// relative to their lengths (computed in `f64`, so that 1e18 coordinates do not overflow).
/// On such a triangle both triangle tests divide by a determinant made of rounding error and
/// report hits at arbitrary distances, outside the triangle's box (where no BVH would look).
pub fn is_degenerate(a: Vec3, b: Vec3, c: Vec3) -> bool {
    let (f1, f2) = (b - a, c - a);
    let n = f1.cross(f2);
    if n == Vec3::ZERO {
        return true;
    }
    // Most triangles are far from the limit: decided in `f32` with a factor-4 margin (far
    // above `f32` rounding of these products) whenever no product overflows or underflows.
    let limit = 4.0 * f32::EPSILON;
    let (lhs, rhs) = (n.length_squared(), limit * limit * f1.length_squared() * f2.length_squared());
    if lhs.is_normal() && rhs.is_normal() && lhs > 4.0 * rhs {
        return false;
    }
    let (e1, e2) = (f1.as_dvec3(), f2.as_dvec3());
    let limit = 4.0 * f32::EPSILON as f64;
    e1.cross(e2).length_squared() <= limit * limit * e1.length_squared() * e2.length_squared()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degeneracy_fast_path_agrees_with_the_f64_test() {
        let reference = |a: Vec3, b: Vec3, c: Vec3| {
            let (e1, e2) = ((b - a).as_dvec3(), (c - a).as_dvec3());
            let limit = 4.0 * f32::EPSILON as f64;
            (b - a).cross(c - a) == Vec3::ZERO
                || e1.cross(e2).length_squared() <= limit * limit * e1.length_squared() * e2.length_squared()
        };
        let mut seed = 1u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        let (mut degenerate, mut checked) = (0, 0);
        for i in 0..200_000 {
            let scale = [1e-30f32, 1e-6, 1.0, 1e6, 1e17][i % 5];
            let a = Vec3::new(rnd(), rnd(), rnd()) * scale;
            let d = Vec3::new(rnd(), rnd(), rnd()) * scale;
            // c near the line through a and b: from collinear to clearly off it.
            let off = [0.0, 1e-9, 1e-7, 3e-7, 1e-6, 1e-3, 1.0][i % 7];
            let b = a + d;
            let c = a + d * rnd() * 3.0 + Vec3::new(rnd(), rnd(), rnd()) * scale * off;
            assert_eq!(is_degenerate(a, b, c), reference(a, b, c), "{a} {b} {c}");
            degenerate += reference(a, b, c) as usize;
            checked += 1;
        }
        assert!(degenerate > 10_000 && checked - degenerate > 10_000, "{degenerate} of {checked}");
    }

    #[test]
    fn commit_finds_the_exact_bounds_and_renumbers_kept_primitives_at_every_quality() {
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::default());
        // Long thin triangles, which High quality's spatial splits cut, every tenth of them
        // degenerate (dropped, so the ones after it move), and a few spheres.
        let mut points = Vec::new();
        for i in 0..3000 {
            let a = Vec3::new(rnd(), rnd(), rnd()) * 20.0;
            let b = a + Vec3::new(rnd(), rnd(), rnd()) * 15.0;
            let c = if i % 10 == 0 { a } else { a + Vec3::new(rnd(), rnd(), rnd()) * 0.1 };
            points.extend([a, b, c]);
        }
        let tris: Vec<[u32; 3]> = (0..points.len() as u32 / 3).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
        b.add_mesh(&points, &tris, m).unwrap();
        for _ in 0..20 {
            b.add_sphere(Vec3::new(rnd(), rnd(), rnd()) * 30.0, 1.0 + rnd(), m).unwrap();
        }
        for quality in [BuildQuality::Fast, BuildQuality::Medium, BuildQuality::High] {
            let (scene, _) = b.clone().commit(&BuildOptions { quality, ..BuildOptions::default() });
            let mut union = Aabb::EMPTY;
            for i in 0..scene.triangles.len() {
                union = union.union(&scene.triangles.bounds(i));
            }
            for i in 0..scene.spheres.len() {
                union = union.union(&scene.spheres.bounds(i));
            }
            assert_eq!(scene.bounds(), union, "{quality:?}");
            assert_eq!(scene.triangles.len(), 2700);
            // The tree refers to the kept primitives by their new indices.
            for _ in 0..2000 {
                let o = Vec3::new(rnd(), rnd(), rnd()) * 60.0;
                let ray = crate::Ray::new(o, (Vec3::new(rnd(), rnd(), rnd()) * 20.0 - o).normalize());
                let (bvh, brute) = (scene.intersect1(&ray), scene.intersect1_brute_force(&ray));
                assert_eq!((bvh.prim, bvh.t), (brute.prim, brute.t), "{quality:?} {ray:?}");
            }
        }
        let (empty, _) = SceneBuilder::new().commit(&BuildOptions::default());
        assert_eq!(empty.bounds(), Aabb::EMPTY);
    }

    #[test]
    fn rejects_bad_indices_and_materials() {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::default());
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        assert_eq!(
            b.add_mesh(&p, &[[0, 1, 3]], m),
            Err(SceneError::IndexOutOfRange { triangle: 0, index: 3, vertices: 3 })
        );
        assert_eq!(b.add_mesh(&p, &[[0, 1, 2]], 7), Err(SceneError::UnknownMaterial(7)));
        assert!(b.add_mesh(&p, &[[0, 1, 2]], m).is_ok());
    }

    #[test]
    fn commit_drops_and_counts_bad_primitives() {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::default());
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::new(2.0, 0.0, 0.0)];
        b.add_mesh(&p, &[[0, 1, 2], [0, 1, 3], [0, 1, 4], [2, 2, 1]], m).unwrap();
        // Before the commit the builder holds every face as given.
        assert_eq!(b.triangle_indices(), &[[0, 1, 2], [0, 1, 3], [0, 1, 4], [2, 2, 1]]);
        b.add_sphere(Vec3::ZERO, -1.0, m).unwrap();
        b.add_sphere(Vec3::ZERO, 1.0, m).unwrap();
        let (scene, report) = b.commit(&BuildOptions::default());
        assert_eq!(report.triangles, 1);
        assert_eq!(report.dropped_non_finite, 1);
        assert_eq!(report.dropped_degenerate, 2);
        assert_eq!(report.dropped_spheres, 1);
        assert_eq!(scene.num_prims(), 2);
    }

    #[test]
    fn empty_scene_misses_everything() {
        let (scene, report) = SceneBuilder::new().commit(&BuildOptions::default());
        assert_eq!(report.triangles + report.spheres, 0);
        let r = crate::Ray::new(Vec3::ZERO, Vec3::X);
        assert!(!scene.intersect1(&r).is_hit());
        assert!(!scene.occluded1(&r));
    }
}
