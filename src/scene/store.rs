//! The committed scene: flat arrays, one per attribute, and the BVH over them.
//!
//! Primitive ids are scene-wide: triangles `0 .. num_triangles()`, then spheres.

use crate::bvh::{Bvh2, Bvh8, BvhStats, NoCount, PrimShape, TreeLayout};
use crate::geometry::{
    MollerTrumboreKernel, TriangleKernel, TriangleTest, WatertightKernel, intersect_sphere, sphere::sphere_uv,
};
use crate::math::{Aabb, Vec3};
use crate::ray::{Hit, Ray};
use crate::scene::{Camera, Light, Material};
use crate::simd::{Isa, IsaError};

/// Triangle meshes, all merged, as structure of arrays.
#[derive(Clone, Debug, Default)]
pub struct TrianglesSoa {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals, parallel to `positions`, or empty when no mesh had any.
    /// A zero normal means "use the geometric normal".
    pub normals: Vec<Vec3>,
    /// Vertex indices of each triangle (all `< positions.len()`).
    pub indices: Vec<[u32; 3]>,
    /// Material id of each triangle.
    pub material: Vec<u32>,
}

impl TrianglesSoa {
    /// Number of triangles.
    #[inline]
    pub fn len(&self) -> usize {
        self.indices.len()
    }

    /// True when there are no triangles.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.indices.is_empty()
    }

    /// The three corners of triangle `i`.
    #[inline]
    pub fn vertices(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.indices[i];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }

    /// Starts fetching triangle `i`'s vertex indices into the cache: a hint with no effect on
    /// any result (nothing happens when `i` is out of range). See [`Scene::prefetch_hits`].
    #[inline(always)]
    pub(crate) fn prefetch_indices(&self, i: usize) {
        if let Some(t) = self.indices.get(i) {
            crate::bvh::bvh8::prefetch_line((t as *const [u32; 3]).cast());
        }
    }

    /// Starts fetching triangle `i`'s three corners (and their shading normals, when the
    /// mesh has them) into the cache; reads its indices, so fetch those first
    /// ([`TrianglesSoa::prefetch_indices`]). A hint with no effect on any result.
    #[inline(always)]
    pub(crate) fn prefetch_corners(&self, i: usize) {
        let Some(&corners) = self.indices.get(i) else { return };
        for v in corners {
            if let Some(p) = self.positions.get(v as usize) {
                crate::bvh::bvh8::prefetch_line((p as *const Vec3).cast());
            }
            if let Some(n) = self.normals.get(v as usize) {
                crate::bvh::bvh8::prefetch_line((n as *const Vec3).cast());
            }
        }
    }

    /// Bounds of triangle `i`.
    #[inline]
    pub fn bounds(&self, i: usize) -> Aabb {
        Aabb::of_triangle(self.vertices(i))
    }
}

/// Spheres as structure of arrays.
#[derive(Clone, Debug, Default)]
pub struct SpheresSoa {
    /// Centres.
    pub center: Vec<Vec3>,
    /// Radii (positive).
    pub radius: Vec<f32>,
    /// Material id of each sphere.
    pub material: Vec<u32>,
}

impl SpheresSoa {
    /// Number of spheres.
    #[inline]
    pub fn len(&self) -> usize {
        self.center.len()
    }

    /// True when there are no spheres.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.center.is_empty()
    }

    /// Bounds of sphere `i`.
    #[inline]
    pub fn bounds(&self, i: usize) -> Aabb {
        let r = Vec3::splat(self.radius[i]);
        Aabb { min: self.center[i] - r, max: self.center[i] + r }
    }
}

/// Local geometry at a hit point, for shading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// World-space position.
    pub position: Vec3,
    /// Unit geometric normal (triangles: `(v1-v0) x (v2-v0)` normalised; spheres: outward).
    pub geometric_normal: Vec3,
    /// Unit shading normal (interpolated vertex normals when present), on the same side as
    /// the geometric normal.
    pub shading_normal: Vec3,
    /// Material id.
    pub material: u32,
}

/// A committed, immutable scene that answers ray queries. Build one with
/// [`crate::SceneBuilder`].
///
/// A ray covers `t` in `[tnear, tfar]`, both ends included: a surface at exactly `t = tnear`
/// is hit, so a ray that starts on a surface with `tnear = 0` hits it at `t = 0` (as Embree's
/// robust mode and trimesh's ray engines count it); a secondary ray that must not see the
/// surface it leaves starts off it (the renderer offsets its origins) or sets `tnear > 0`.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Triangle meshes.
    pub triangles: TrianglesSoa,
    /// Spheres.
    pub spheres: SpheresSoa,
    /// Materials, indexed by material id.
    pub materials: Vec<Material>,
    /// Light sources (emissive surfaces are found from materials).
    pub lights: Vec<Light>,
    /// The camera from the scene file, if any.
    pub camera: Option<Camera>,
    pub(crate) bounds: Aabb,
    /// The binary BVH, when [`crate::BuildOptions::keep_bvh2`] kept it.
    pub(crate) bvh2: Option<Bvh2>,
    pub(crate) bvh8: Bvh8,
    /// The ISA tier the queries run on (always one the CPU supports).
    pub(crate) isa: Isa,
}

impl Scene {
    /// Number of triangles.
    pub fn num_triangles(&self) -> usize {
        self.triangles.len()
    }

    /// Number of spheres.
    pub fn num_spheres(&self) -> usize {
        self.spheres.len()
    }

    /// Number of primitives (triangles + spheres).
    pub fn num_prims(&self) -> usize {
        self.triangles.len() + self.spheres.len()
    }

    /// Bounds of all geometry ([`Aabb::EMPTY`] for an empty scene).
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The camera from the file, or one framing the geometry.
    pub fn camera_or_framing(&self, aspect: f32) -> Camera {
        match self.camera {
            Some(mut c) => {
                c.set_aspect(aspect);
                c
            }
            None => Camera::framing(&self.bounds, aspect),
        }
    }

    /// The binary BVH (the scalar reference structure), when the build kept it
    /// ([`crate::BuildOptions::keep_bvh2`]).
    pub fn bvh2(&self) -> Option<&Bvh2> {
        self.bvh2.as_ref()
    }

    /// The 8-wide BVH the SIMD kernels traverse.
    pub fn bvh8(&self) -> &Bvh8 {
        &self.bvh8
    }

    /// How the BVH8 stores its triangle blocks.
    pub fn layout(&self) -> TreeLayout {
        self.bvh8.layout()
    }

    /// The scene with its BVH8 in `layout`: the same nodes and leaves, the triangle blocks
    /// stored ([`TreeLayout::Default`]) or as primitive ids ([`TreeLayout::Compact`]); every
    /// query answers the same, bit for bit.
    pub fn with_layout(&self, layout: TreeLayout) -> Scene {
        let mut s = self.clone();
        if layout != self.layout() {
            s.bvh8 = match layout {
                TreeLayout::Compact => s.bvh8.into_compact(),
                TreeLayout::Default => {
                    let tris = crate::scene::cache::stored_blocks(self).into_owned();
                    Bvh8 { tris: tris.into(), ids: Default::default(), ..s.bvh8 }
                }
            };
        }
        s
    }

    /// The instruction-set tier the queries run on: [`Isa::default_for_process`] (the CPU's
    /// best, or lower under `RAYPACK_ISA`) unless [`Scene::set_isa`] chose another.
    pub fn isa(&self) -> Isa {
        self.isa
    }

    /// Runs the queries on `isa`'s kernels from now on (all tiers give the same hits).
    /// Fails, and changes nothing, when the CPU lacks `isa`.
    ///
    /// ```
    /// # use raypack::{BuildOptions, Isa, Ray, SceneBuilder, Vec3, Material};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
    /// let (mut scene, _) = b.commit(&BuildOptions::default());
    /// let ray = Ray::new(Vec3::new(0.3, 0.2, 5.0), -Vec3::Z);
    /// let best = scene.intersect1(&ray);
    /// scene.set_isa(Isa::Baseline)?; // SSE2: every x86-64 CPU has it
    /// assert_eq!(scene.intersect1(&ray), best);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn set_isa(&mut self, isa: Isa) -> Result<(), IsaError> {
        self.isa = isa.check()?;
        Ok(())
    }

    /// The shape of primitive `prim`, as the BVH8 collapse needs it.
    pub fn prim_shape(&self, prim: u32) -> PrimShape {
        let nt = self.triangles.len();
        let p = prim as usize;
        if p < nt {
            PrimShape::Triangle(self.triangles.vertices(p))
        } else {
            PrimShape::Sphere(self.spheres.center[p - nt], self.spheres.radius[p - nt])
        }
    }

    /// True when the scene holds spheres (whose hits need [`Scene::finish_hit`]).
    #[inline(always)]
    pub(crate) fn has_spheres(&self) -> bool {
        !self.spheres.is_empty()
    }

    /// Fills in the surface coordinates of a sphere hit (the SIMD kernels leave them 0).
    #[inline]
    pub(crate) fn finish_hit(&self, ray: &Ray, hit: &mut Hit) {
        let nt = self.triangles.len() as u32;
        if hit.prim != Hit::NONE && hit.prim >= nt {
            let center = self.spheres.center[(hit.prim - nt) as usize];
            // `normalize_or`: a hit point that rounds onto the centre has no direction.
            (hit.u, hit.v) = sphere_uv((ray.at(hit.t) - center).normalize_or(Vec3::Z));
        }
    }

    /// Quality figures of the reference BVH, when the build kept it.
    pub fn bvh_stats(&self) -> Option<BvhStats> {
        self.bvh2.as_ref().map(BvhStats::of_bvh2)
    }

    /// Bounds of primitive `prim`.
    pub fn prim_bounds(&self, prim: u32) -> Aabb {
        let nt = self.triangles.len();
        let p = prim as usize;
        if p < nt { self.triangles.bounds(p) } else { self.spheres.bounds(p - nt) }
    }

    /// The triangle test of the scene's kernels (and of its scalar reference and brute force).
    pub fn triangle_test(&self) -> TriangleTest {
        self.bvh8.test
    }

    /// Intersects one primitive over `[ray.tnear, tfar]` with the scene's triangle test:
    /// `(t, u, v)` or `None`.
    #[inline]
    pub fn intersect_prim(&self, prim: u32, ray: &Ray, tfar: f32) -> Option<(f32, f32, f32)> {
        let nt = self.triangles.len();
        let p = prim as usize;
        if p < nt {
            let [a, b, c] = self.triangles.vertices(p);
            match self.bvh8.test {
                TriangleTest::MollerTrumbore => MollerTrumboreKernel::scalar(ray, tfar, a, b, c),
                TriangleTest::Watertight => WatertightKernel::scalar(ray, tfar, a, b, c),
            }
        } else {
            let s = p - nt;
            let center = self.spheres.center[s];
            let t = intersect_sphere(ray.origin, ray.dir, ray.tnear, tfar, center, self.spheres.radius[s])?;
            // `normalize_or`, as in `surface`: a hit point that rounds onto the centre (huge
            // coordinates, tiny radius) has no direction (found by fuzzing).
            let (u, v) = sphere_uv((ray.at(t) - center).normalize_or(Vec3::Z));
            Some((t, u, v))
        }
    }

    /// Closest hit along `ray` (scalar reference traversal of the binary BVH). Without a
    /// binary BVH ([`crate::BuildOptions::keep_bvh2`] off) it tests every primitive, as
    /// [`Scene::intersect1_brute_force`] does: always right, slow on large scenes.
    pub fn intersect1_reference(&self, ray: &Ray) -> Hit {
        match &self.bvh2 {
            Some(bvh2) => bvh2.intersect(ray, |prim, tfar| self.intersect_prim(prim, ray, tfar)),
            None => self.intersect1_brute_force(ray),
        }
    }

    /// True when anything lies in `[ray.tnear, ray.tfar]` (scalar reference traversal; every
    /// primitive without a binary BVH, as [`Scene::intersect1_reference`]).
    pub fn occluded1_reference(&self, ray: &Ray) -> bool {
        match &self.bvh2 {
            Some(bvh2) => bvh2.occluded(ray, |prim| self.intersect_prim(prim, ray, ray.tfar).is_some()),
            None => (0..self.num_prims() as u32).any(|prim| self.intersect_prim(prim, ray, ray.tfar).is_some()),
        }
    }

    /// Closest hit by testing every primitive: the oracle for tests and the CS184
    /// "without BVH" timing. Ties in `t` keep the lowest primitive id.
    pub fn intersect1_brute_force(&self, ray: &Ray) -> Hit {
        let mut hit = Hit::MISS;
        if !ray.is_valid() {
            return hit;
        }
        let mut tfar = ray.tfar;
        for prim in 0..self.num_prims() as u32 {
            if let Some((t, u, v)) = self.intersect_prim(prim, ray, tfar)
                && (t < tfar || !hit.is_hit())
            {
                tfar = t;
                hit = Hit { t, u, v, prim };
            }
        }
        hit
    }

    /// Starts fetching into the cache the geometry of every triangle `hits` hit (index
    /// triples first, then corners and shading normals), for a loop that reads it next
    /// ([`Scene::surface`], normals, ...). A hint with no effect on any result. On meshes
    /// larger than the cache each hit's geometry costs two dependent misses; fetched this way
    /// for a whole batch first, the misses overlap instead of being waited for one by one.
    ///
    /// ```
    /// # use raypack::{BuildOptions, Hit, Material, Ray, SceneBuilder, Vec3};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_mesh(&[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]], m)?;
    /// b.add_sphere(Vec3::new(5.0, 0.0, 0.0), 1.0, m)?;
    /// let (scene, _) = b.commit(&BuildOptions::default());
    /// let rays = [Ray::new(Vec3::new(0.25, 0.25, 2.0), -Vec3::Z), Ray::new(Vec3::new(5.0, 0.0, 3.0), -Vec3::Z)];
    /// let mut hits = [Hit::MISS; 3]; // the last one stays a miss
    /// scene.intersect_stream(&rays, &mut hits[..2], &raypack::StreamOptions::POOL);
    /// scene.prefetch_hits(&hits); // misses and spheres are skipped
    /// let normals: Vec<Vec3> = rays.iter().zip(&hits).map(|(r, h)| scene.surface(r, h).geometric_normal).collect();
    /// assert_eq!(normals, [Vec3::Z, Vec3::Z]);
    /// # Ok::<(), raypack::SceneError>(())
    /// ```
    pub fn prefetch_hits(&self, hits: &[Hit]) {
        for h in hits {
            self.triangles.prefetch_indices(h.prim as usize); // misses and spheres: out of range
        }
        for h in hits {
            self.triangles.prefetch_corners(h.prim as usize);
        }
    }

    /// Closest hit along `ray` (the BVH8 single-ray kernel). Invalid rays
    /// ([`Ray::is_valid`]) miss.
    ///
    /// ```
    /// # use raypack::{BuildOptions, Material, Ray, SceneBuilder, Vec3};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_mesh(&[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]], m)?;
    /// let (scene, _) = b.commit(&BuildOptions::default());
    /// let hit = scene.intersect1(&Ray::new(Vec3::new(0.25, 0.25, 2.0), -Vec3::Z));
    /// assert_eq!((hit.prim, hit.t, hit.u, hit.v), (0, 2.0, 0.25, 0.25));
    /// # Ok::<(), raypack::SceneError>(())
    /// ```
    #[inline]
    pub fn intersect1(&self, ray: &Ray) -> Hit {
        self.counting(&mut NoCount).intersect1(ray)
    }

    /// True when anything blocks `ray` over `[tnear, tfar]` (the BVH8 any-hit kernel).
    /// Invalid rays are never occluded.
    ///
    /// ```
    /// # use raypack::{BuildOptions, Material, Ray, SceneBuilder, Vec3};
    /// let mut b = SceneBuilder::new();
    /// let m = b.add_material(Material::default());
    /// b.add_sphere(Vec3::ZERO, 1.0, m)?;
    /// let (scene, _) = b.commit(&BuildOptions::default());
    /// let from = Vec3::new(0.0, 0.0, 5.0);
    /// assert!(scene.occluded1(&Ray::segment(from, -Vec3::Z, 0.0, 10.0)));
    /// assert!(!scene.occluded1(&Ray::segment(from, -Vec3::Z, 0.0, 3.9))); // stops short
    /// # Ok::<(), raypack::SceneError>(())
    /// ```
    #[inline]
    pub fn occluded1(&self, ray: &Ray) -> bool {
        self.counting(&mut NoCount).occluded1(ray)
    }

    /// Local geometry at `hit` (which must be a hit of `ray` on this scene).
    pub fn surface(&self, ray: &Ray, hit: &Hit) -> SurfaceHit {
        let nt = self.triangles.len();
        let p = hit.prim as usize;
        if p < nt {
            let [a, b, c] = self.triangles.vertices(p);
            // From the barycentrics, not `o + t d`: the error is then relative to the vertices'
            // magnitude, which is what robust ray offsetting assumes.
            let position = a * (1.0 - hit.u - hit.v) + b * hit.u + c * hit.v;
            let ng = (b - a).cross(c - a).normalize_or(Vec3::Z);
            let mut ns = ng;
            if !self.triangles.normals.is_empty() {
                let [ia, ib, ic] = self.triangles.indices[p];
                let n = &self.triangles.normals;
                let w = 1.0 - hit.u - hit.v;
                let interp = n[ia as usize] * w + n[ib as usize] * hit.u + n[ic as usize] * hit.v;
                if let Some(i) = interp.try_normalize() {
                    ns = if i.dot(ng) < 0.0 { -i } else { i };
                }
            }
            // Interpolated vertex normals may face away from the geometric normal's side;
            // keep them consistent so that shading and offsetting agree.
            SurfaceHit { position, geometric_normal: ng, shading_normal: ns, material: self.triangles.material[p] }
        } else {
            let s = p - nt;
            let (center, radius) = (self.spheres.center[s], self.spheres.radius[s]);
            let n = (ray.at(hit.t) - center).normalize_or(Vec3::Z);
            // Reprojected onto the sphere, as pbrt does, for the same reason.
            let position = center + n * radius;
            SurfaceHit { position, geometric_normal: n, shading_normal: n, material: self.spheres.material[s] }
        }
    }
}
