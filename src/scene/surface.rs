//! The local geometry of many hits at once ([`Scene::surfaces`], or as rows of eight hits:
//! [`Scene::surface_rows`]): eight triangle hits per step in SIMD lanes, with the operations of
//! [`Scene::surface`] in the same order, so every hit's [`SurfaceHit`] is bit-identical to the
//! one-at-a-time result.

use crate::math::Vec3;
use crate::ray::{Hit, Ray};
use crate::scene::store::{Scene, SurfaceHit, TrianglesSoa};
use crate::simd::isa::{IsaOp, dispatch};
use crate::simd::{IsaLanes, Lanes, Vec3x};

/// Hits per SIMD step (and per [`SurfaceRows`]).
pub const STEP: usize = 8;

/// The surfaces of a step of eight hits as rows (structure of arrays): lane `j` of each row is
/// hit `j`'s. Lanes of misses hold [`SurfaceRows::MISS`]'s values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceRows {
    /// Positions (`x`, `y`, `z` rows).
    pub position: [[f32; STEP]; 3],
    /// Unit geometric normals.
    pub geometric_normal: [[f32; STEP]; 3],
    /// Unit shading normals.
    pub shading_normal: [[f32; STEP]; 3],
    /// Material ids.
    pub material: [u32; STEP],
}

impl SurfaceRows {
    /// What a miss's lane holds: the origin, normals `+z`, material 0.
    pub const MISS: SurfaceHit =
        SurfaceHit { position: Vec3::ZERO, geometric_normal: Vec3::Z, shading_normal: Vec3::Z, material: 0 };

    /// Eight misses.
    pub const MISSES: Self = {
        let z = [[0.0; STEP], [0.0; STEP], [1.0; STEP]];
        Self { position: [[0.0; STEP]; 3], geometric_normal: z, shading_normal: z, material: [0; STEP] }
    };

    /// Lane `j`.
    #[inline]
    pub fn get(&self, j: usize) -> SurfaceHit {
        let l = |r: &[[f32; STEP]; 3]| Vec3::new(r[0][j], r[1][j], r[2][j]);
        SurfaceHit {
            position: l(&self.position),
            geometric_normal: l(&self.geometric_normal),
            shading_normal: l(&self.shading_normal),
            material: self.material[j],
        }
    }

    /// Sets lane `j` to `s`.
    #[inline]
    pub fn set(&mut self, j: usize, s: &SurfaceHit) {
        for (r, v) in [
            (&mut self.position, s.position),
            (&mut self.geometric_normal, s.geometric_normal),
            (&mut self.shading_normal, s.shading_normal),
        ] {
            (r[0][j], r[1][j], r[2][j]) = (v.x, v.y, v.z);
        }
        self.material[j] = s.material;
    }
}

impl Default for SurfaceRows {
    /// Eight misses.
    fn default() -> Self {
        Self::MISSES
    }
}

impl Scene {
    /// [`Scene::surface`] of every hit of `hits` (traced along `rays`) into `out`, leaving
    /// the entries of misses as they are. `rays`, `hits` and `out` must have the same length.
    /// Runs eight triangle hits at a time on the scene's ISA ([`Scene::isa`]); the results
    /// are those of [`Scene::surface`] bit for bit.
    pub fn surfaces(&self, rays: &[Ray], hits: &[Hit], out: &mut [SurfaceHit]) {
        assert!(rays.len() == hits.len() && hits.len() == out.len(), "rays, hits and out differ in length");
        let sink = HitSink { rows: SurfaceRows::MISSES, out };
        dispatch(self.isa, Surfaces { scene: self, rays, hits, sink })
    }

    /// [`Scene::surfaces`] as rows: `out[i]` gets hits `8 i .. 8 i + 8` (misses and lanes past
    /// the end: [`SurfaceRows::MISS`]). `rays` and `hits` must have the same length, `out`
    /// one entry per eight of them, rounded up.
    pub fn surface_rows(&self, rays: &[Ray], hits: &[Hit], out: &mut [SurfaceRows]) {
        assert!(rays.len() == hits.len() && hits.len().div_ceil(STEP) == out.len(), "rays, hits and out disagree");
        dispatch(self.isa, Surfaces { scene: self, rays, hits, sink: out })
    }
}

/// Every lane of a step.
const ALL: u32 = (1 << STEP) - 1;

/// Where [`Surfaces`] puts each step's rows.
trait Sink {
    /// The rows of step `k`, to be filled.
    fn rows(&mut self, k: usize) -> &mut SurfaceRows;
    /// Step `k` is filled; its hits are the bits of `hit`.
    fn done(&mut self, k: usize, hit: u32);
}

/// Rows in place.
impl Sink for &mut [SurfaceRows] {
    #[inline(always)]
    fn rows(&mut self, k: usize) -> &mut SurfaceRows {
        &mut self[k]
    }
    #[inline(always)]
    fn done(&mut self, _: usize, _: u32) {}
}

/// One hit per entry, misses left as they are.
struct HitSink<'a> {
    rows: SurfaceRows,
    out: &'a mut [SurfaceHit],
}

impl Sink for HitSink<'_> {
    #[inline(always)]
    fn rows(&mut self, _: usize) -> &mut SurfaceRows {
        &mut self.rows
    }
    #[inline(always)]
    fn done(&mut self, k: usize, hit: u32) {
        for j in crate::simd::bits(hit) {
            self.out[k * STEP + j] = self.rows.get(j);
        }
    }
}

/// The surfaces of `hits`, step by step, into `sink`.
struct Surfaces<'a, S> {
    scene: &'a Scene,
    rays: &'a [Ray],
    hits: &'a [Hit],
    sink: S,
}

impl<S: Sink> IsaOp for Surfaces<'_, S> {
    type Output = ();
    #[inline(always)]
    fn run<I: IsaLanes>(self) {
        let (scene, rays, hits, mut sink) = (self.scene, self.rays, self.hits, self.sink);
        let nt = scene.triangles.len();
        for (k, (r, h)) in rays.chunks(STEP).zip(hits.chunks(STEP)).enumerate() {
            // The last step padded with misses.
            let mut step = [Hit::MISS; STEP];
            step[..h.len()].copy_from_slice(h);
            // Misses carry `Hit::NONE` (past every triangle), spheres ids from `nt` on.
            let (mut triangles, mut hit) = (0u32, 0u32);
            for (j, h) in step.iter().enumerate() {
                triangles |= (((h.prim as usize) < nt) as u32) << j;
                hit |= (h.is_hit() as u32) << j;
            }
            let rows = sink.rows(k);
            if triangles != ALL {
                // Lanes the triangle kernel leaves as they are.
                *rows = SurfaceRows::MISSES;
            }
            if triangles != 0 {
                triangle_surfaces::<I::F8>(&scene.triangles, &step, triangles, rows);
            }
            for j in crate::simd::bits(hit & !triangles) {
                rows.set(j, &scene.surface(&r[j], &step[j]));
            }
            sink.done(k, hit);
        }
    }
}

/// The surfaces of the hits of `hits` whose bit is set in `triangles` (triangle hits), in
/// lanes `V` (of eight); the other lanes of `out` are left as they are.
#[inline(always)]
fn triangle_surfaces<V: Lanes>(tris: &TrianglesSoa, hits: &[Hit; STEP], triangles: u32, out: &mut SurfaceRows) {
    debug_assert_eq!(V::LANES, STEP);
    // Rows (x, y, z each): the corners a, b, c, then their normals; lanes of other hits
    // stay zero and their results are dropped.
    let mut rows = [[[0.0f32; STEP]; 3]; 6];
    let (mut u, mut v) = ([0.0f32; STEP], [0.0f32; STEP]);
    let smooth = !tris.normals.is_empty();
    for j in crate::simd::bits(triangles) {
        let h = &hits[j];
        let corners = tris.indices[h.prim as usize];
        for (c, &i) in corners.iter().enumerate() {
            let p = tris.positions[i as usize];
            (rows[c][0][j], rows[c][1][j], rows[c][2][j]) = (p.x, p.y, p.z);
            if smooth {
                let n = tris.normals[i as usize];
                (rows[3 + c][0][j], rows[3 + c][1][j], rows[3 + c][2][j]) = (n.x, n.y, n.z);
            }
        }
        (u[j], v[j]) = (h.u, h.v);
    }
    let (a, b, c) = (Vec3x::<V>::load_rows(&rows[0]), Vec3x::load_rows(&rows[1]), Vec3x::load_rows(&rows[2]));
    let (u, v) = (V::load(&u), V::load(&v));
    let w = V::splat(1.0) - u - v;
    let position = barycentric(a, b, c, w, u, v);
    let (ng, ng_ok) = normalized((b - a).cross(c - a));
    let ng = Vec3x::select(ng_ok, ng, Vec3x::splat(Vec3::Z));
    let mut ns = ng;
    if smooth {
        let (na, nb, nc) = (Vec3x::load_rows(&rows[3]), Vec3x::load_rows(&rows[4]), Vec3x::load_rows(&rows[5]));
        let (i, i_ok) = normalized(barycentric(na, nb, nc, w, u, v));
        let i = Vec3x::select(i.dot(ng).lt(V::splat(0.0)), -i, i);
        ns = Vec3x::select(i_ok, i, ng);
    }
    if triangles == ALL {
        position.store_rows(&mut out.position);
        ng.store_rows(&mut out.geometric_normal);
        ns.store_rows(&mut out.shading_normal);
    } else {
        let others = V::from_bitmask(!triangles);
        Vec3x::select(others, Vec3x::load_rows(&out.position), position).store_rows(&mut out.position);
        Vec3x::select(others, Vec3x::load_rows(&out.geometric_normal), ng).store_rows(&mut out.geometric_normal);
        Vec3x::select(others, Vec3x::load_rows(&out.shading_normal), ns).store_rows(&mut out.shading_normal);
    }
    for j in crate::simd::bits(triangles) {
        out.material[j] = tris.material[hits[j].prim as usize];
    }
}

/// `a w + b u + c v`, summed in the order of `Scene::surface`.
#[inline(always)]
fn barycentric<V: Lanes>(a: Vec3x<V>, b: Vec3x<V>, c: Vec3x<V>, w: V, u: V, v: V) -> Vec3x<V> {
    Vec3x { x: a.x * w + b.x * u + c.x * v, y: a.y * w + b.y * u + c.y * v, z: a.z * w + b.z * u + c.z * v }
}

/// `v` scaled to unit length as `glam::Vec3::try_normalize` does (`v * (1 / |v|)`), and the
/// lanes where that succeeds (a finite, positive reciprocal length).
#[inline(always)]
fn normalized<V: Lanes>(v: Vec3x<V>) -> (Vec3x<V>, V) {
    let rcp = V::splat(1.0) / v.dot(v).sqrt();
    let ok = rcp.is_finite() & rcp.gt(V::splat(0.0));
    (Vec3x { x: v.x * rcp, y: v.y * rcp, z: v.z * rcp }, ok)
}

#[cfg(test)]
mod tests {
    use super::{STEP, SurfaceRows};
    use crate::math::Vec3;
    use crate::ray::{Hit, Ray};
    use crate::rng::Rng;
    use crate::scene::{Material, SceneBuilder, SurfaceHit};
    use crate::{BuildOptions, Isa};

    const UNTOUCHED: SurfaceHit = SurfaceHit {
        position: Vec3::splat(-7.0),
        geometric_normal: Vec3::ZERO,
        shading_normal: Vec3::ZERO,
        material: 99,
    };

    const UNTOUCHED_ROWS: SurfaceRows = SurfaceRows {
        position: [[-7.0; STEP]; 3],
        geometric_normal: [[0.0; STEP]; 3],
        shading_normal: [[0.0; STEP]; 3],
        material: [99; STEP],
    };

    fn bits(s: &SurfaceHit) -> [u32; 10] {
        let [p, g, n] = [s.position, s.geometric_normal, s.shading_normal].map(|v| v.to_array().map(f32::to_bits));
        [p[0], p[1], p[2], g[0], g[1], g[2], n[0], n[1], n[2], s.material]
    }

    /// A soup of random triangles (smooth or flat, some vertex normals zero or pointing
    /// away) and spheres, hit by random rays: the batch equals `surface` bit for bit on
    /// every ISA, for every batch length (whole steps, remainders, steps mixing spheres and
    /// misses).
    #[test]
    fn batches_equal_one_at_a_time_on_every_isa() {
        let mut rng = Rng::new(3, 7);
        let mut r3 = |s: f32| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * s - s * 0.5;
        for smooth in [false, true] {
            let mut b = SceneBuilder::new();
            let m = b.add_material(Material::default());
            let mut positions = Vec::new();
            let mut normals = Vec::new();
            let mut indices = Vec::new();
            for t in 0..400u32 {
                let c = r3(8.0);
                for k in 0..3 {
                    positions.push(c + r3(1.0));
                    normals.push(match (t + k) % 7 {
                        0 => Vec3::ZERO,
                        1 => -r3(2.0),
                        _ => r3(2.0),
                    });
                }
                indices.push([3 * t, 3 * t + 1, 3 * t + 2]);
            }
            if smooth {
                b.add_mesh_with_normals(&positions, Some(&normals), &indices, m).unwrap();
            } else {
                b.add_mesh(&positions, &indices, m).unwrap();
            }
            for _ in 0..40 {
                b.add_sphere(r3(8.0), 0.3, m).unwrap();
            }
            let (mut scene, _) = b.commit(&BuildOptions::default());
            // Triangle hits first (whole SIMD steps), then rays in any order (steps that mix
            // triangles, spheres and misses).
            let mut rays: Vec<Ray> = (0..3000)
                .map(|_| {
                    let o = r3(14.0);
                    Ray::new(o, r3(4.0) - o)
                })
                .collect();
            let nt = scene.num_triangles();
            rays.sort_by_key(|r| (scene.intersect1(r).prim as usize) >= nt);
            let hits: Vec<Hit> = rays.iter().map(|r| scene.intersect1(r)).collect();
            let count = |f: &dyn Fn(&Hit) -> bool| hits.iter().filter(|h| f(h)).count();
            let kinds = [
                count(&|h| (h.prim as usize) < nt),
                count(&|h| h.is_hit() && h.prim as usize >= nt),
                count(&|h| !h.is_hit()),
            ];
            assert!(kinds[0] > 800 && kinds[1] > 20 && kinds[2] > 100, "triangle, sphere hits and misses: {kinds:?}");
            let want: Vec<_> = rays.iter().zip(&hits).map(|(r, h)| h.is_hit().then(|| scene.surface(r, h))).collect();
            for isa in Isa::available() {
                scene.set_isa(isa).unwrap();
                for len in [hits.len(), 8, 13, 3, kinds[0] + 5] {
                    let mut out = vec![UNTOUCHED; len];
                    scene.surfaces(&rays[..len], &hits[..len], &mut out);
                    for (k, (got, want)) in out.iter().zip(&want).enumerate() {
                        assert_eq!(
                            bits(got),
                            bits(&want.unwrap_or(UNTOUCHED)),
                            "{isa}, hit {k} of {len}: {:?}",
                            hits[k]
                        );
                    }
                    // The same as rows, misses and the lanes past the end as `MISS`.
                    let mut rows = vec![UNTOUCHED_ROWS; len.div_ceil(STEP)];
                    scene.surface_rows(&rays[..len], &hits[..len], &mut rows);
                    for k in 0..rows.len() * STEP {
                        let want = want[..len].get(k).copied().flatten().unwrap_or(SurfaceRows::MISS);
                        assert_eq!(bits(&rows[k / STEP].get(k % STEP)), bits(&want), "{isa}, rows, hit {k} of {len}");
                    }
                }
            }
        }
    }
}
