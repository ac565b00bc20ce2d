//! The parallel loops behind `Scene.intersect` / `occluded`: rays are copied from the numpy
//! arrays a pass at a time with the GIL held ([`passes`]: no whole copy of the rays, and no
//! Python thread can free an array while it is read), traced with the GIL released by the
//! scene's streams (`Scene::intersect_stream` / `occluded_stream`, chunk by chunk over the
//! library's one parallel loop, `par_for_each_chunk_of`) and written
//! straight into the output arrays (which no Python code can reach before they are returned).

use crate::args::RayArgs;
use crate::{PoolCache, run_detached};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rayon::prelude::*;
use raypack::bvh::NoCount;
use raypack::scene::par_for_each_chunk_of;
use raypack::{Hit, Ray, Scene, StreamOptions, Vec3};

/// Rays per rayon task (the library's own streams').
pub const CHUNK: usize = raypack::scene::STREAM_CHUNK;

/// Rays per pass: copied from the caller's arrays with the GIL held, then traced without it.
/// 2 MiB of rays: the copy adds that to a query's memory, and a pass is long enough that
/// taking the GIL back between passes costs nothing measurable.
pub const PASS: usize = 1 << 16;

/// Runs `each(start, rays)` on the rays of `args` (`len` of them) pass by pass: each pass's
/// rays are copied out of the arrays with the GIL held (in parallel on the pool of `threads`),
/// then `each` runs with the GIL released on that pool, panics turned into `RuntimeError`.
/// The arrays are viewed afresh for every pass: one that another thread resized meanwhile is
/// a `ValueError`, never a read of freed memory.
pub fn passes(
    py: Python<'_>,
    pools: &PoolCache,
    threads: Option<usize>,
    args: &RayArgs<'_>,
    len: usize,
    each: &mut (dyn FnMut(usize, &[Ray]) + Send),
) -> PyResult<()> {
    let pool = pools.get(threads)?;
    let mut buf = vec![Ray::new(Vec3::ZERO, Vec3::X); PASS.min(len)];
    for start in (0..len).step_by(PASS) {
        let n = PASS.min(len - start);
        let resized = |now: String| {
            PyValueError::new_err(format!(
                "origins, directions, tnear, tfar: an array was resized while the query ran ({len} rays at the start; \
                 now {now})"
            ))
        };
        let rays = args.rays_of_pass().map_err(|e| resized(e.to_string()))?;
        if rays.len != len {
            return Err(resized(format!("{} rays", rays.len)));
        }
        let fill = |pass: &mut [Ray]| {
            pass.par_chunks_mut(CHUNK).enumerate().for_each(|(k, c)| rays.fill(start + k * CHUNK, c))
        };
        match &pool {
            Some(pool) => pool.install(|| fill(&mut buf[..n])),
            None => fill(&mut buf[..n]),
        }
        let pass = &buf[..n];
        run_detached(py, pools, threads, || each(start, pass))?;
    }
    Ok(())
}

/// The output arrays of a closest-hit query, one entry (three for `normal`) per ray.
pub struct HitArrays<'a> {
    pub t: &'a mut [f32],
    pub prim: &'a mut [i64],
    pub u: &'a mut [f32],
    pub v: &'a mut [f32],
    pub normal: &'a mut [f32],
}

impl HitArrays<'_> {
    /// The entries of rays `start .. start + n`.
    pub fn range(&mut self, start: usize, n: usize) -> HitArrays<'_> {
        let r = start..start + n;
        HitArrays {
            t: &mut self.t[r.clone()],
            prim: &mut self.prim[r.clone()],
            u: &mut self.u[r.clone()],
            v: &mut self.v[r],
            normal: &mut self.normal[3 * start..3 * (start + n)],
        }
    }
}

/// A scene and how its primitive ids map to the ids the caller knows: the index of the face
/// among those given (or held by the file), spheres after them.
#[derive(Clone, Copy)]
pub struct Target<'a> {
    pub scene: &'a Scene,
    /// The given face index of each committed triangle, when the commit dropped some.
    pub kept: Option<&'a [u32]>,
    /// How many faces were given (the committed triangles plus the dropped ones).
    pub given_triangles: usize,
}

impl Target<'_> {
    #[inline(always)]
    pub fn caller_prim(&self, prim: u32) -> i64 {
        let p = prim as usize;
        let committed = self.scene.num_triangles();
        if p >= committed {
            (p - committed + self.given_triangles) as i64
        } else {
            self.kept.and_then(|map| map.get(p)).map_or(prim as i64, |&g| g as i64)
        }
    }

    /// The unit geometric normal at `hit` (triangles: `(v1 - v0) x (v2 - v0)`; spheres: outward).
    #[inline(always)]
    fn normal(&self, ray: &Ray, hit: &Hit) -> Vec3 {
        let s = self.scene;
        if (hit.prim as usize) < s.num_triangles() {
            let [a, b, c] = s.triangles.vertices(hit.prim as usize);
            // `+ 0.0` turns -0 into +0 (axis-aligned faces otherwise print as [-0, 0, 1]).
            (b - a).cross(c - a).normalize_or(Vec3::Z) + Vec3::ZERO
        } else {
            s.surface(ray, hit).geometric_normal
        }
    }
}

/// Closest hits of `rays` into `out` (misses: `t = inf`, `prim = -1`, `u = v = 0`, normal 0),
/// chunk by chunk over the current pool: each chunk's stream on its thread, then its outputs.
pub fn intersect(target: Target<'_>, rays: &[Ray], out: HitArrays<'_>) {
    let HitArrays { t, prim, u, v, normal } = out;
    let outs = (
        t.par_chunks_mut(CHUNK),
        prim.par_chunks_mut(CHUNK),
        u.par_chunks_mut(CHUNK),
        v.par_chunks_mut(CHUNK),
        normal.par_chunks_mut(3 * CHUNK),
    )
        .into_par_iter();
    par_for_each_chunk_of(rays, outs, &mut NoCount, |ray_buf, (t, prim, u, v, normal), _| {
        // The stream writes every hit of the chunk.
        let mut hit_buf = [Hit::MISS; CHUNK];
        let hit_buf = &mut hit_buf[..ray_buf.len()];
        target.scene.intersect_stream(ray_buf, hit_buf, &StreamOptions::CALLER);
        // The normals below read each hit triangle's corners: fetched for the whole chunk
        // first (PERFORMANCE.md, "Hit geometry prefetch").
        target.scene.prefetch_hits(hit_buf);
        let outs =
            t.iter_mut().zip(prim.iter_mut()).zip(u.iter_mut()).zip(v.iter_mut()).zip(normal.chunks_exact_mut(3));
        for (((((t, prim), u), v), normal), (ray, hit)) in outs.zip(ray_buf.iter().zip(hit_buf.iter())) {
            *t = hit.t; // inf on a miss
            if hit.is_hit() {
                (*u, *v) = (hit.u, hit.v);
                *prim = target.caller_prim(hit.prim);
                normal.copy_from_slice(&target.normal(ray, hit).to_array());
            } else {
                (*u, *v, *prim) = (0.0, 0.0, -1);
                normal.fill(0.0);
            }
        }
    });
}

/// Whether anything blocks each of `rays` over `[tnear, tfar]`, into `out`.
pub fn occluded(target: Target<'_>, rays: &[Ray], out: &mut [bool]) {
    target.scene.occluded_stream(rays, out, &StreamOptions::POOL);
}

/// All hits along each ray, nearest first, at most `max_hits` per ray.
#[derive(Default)]
pub struct AllHits {
    pub ray: Vec<i64>,
    pub prim: Vec<i64>,
    pub t: Vec<f32>,
    pub u: Vec<f32>,
    pub v: Vec<f32>,
}

impl AllHits {
    /// Appends `other`'s hits (of later rays).
    pub fn append(&mut self, mut other: AllHits) {
        self.ray.append(&mut other.ray);
        self.prim.append(&mut other.prim);
        self.t.append(&mut other.t);
        self.u.append(&mut other.u);
        self.v.append(&mut other.v);
    }
}

/// Every hit along each of `rays` (up to `max_hits`), ray `i` numbered `first + i`: after a
/// hit at `t` the ray goes on from `t + min_step / |dir|`, so surfaces closer than `min_step`
/// (a distance) behind a hit, such as the neighbour of a shared edge, are not reported twice.
/// Ordered by ray, then `t`.
pub fn intersect_all(target: Target<'_>, rays: &[Ray], first: usize, max_hits: usize, min_step: f32) -> AllHits {
    let mut parts: Vec<AllHits> = (0..rays.len().div_ceil(CHUNK)).map(|_| AllHits::default()).collect();
    // Chunk by chunk: a chunk's rounds run on its rays alone, which stay in the cache.
    par_for_each_chunk_of(rays, parts.par_iter_mut().enumerate(), &mut NoCount, |chunk, (k, out), _| {
        let start = first + k * CHUNK;
        // Every hit as (ray within the chunk, hit), pass by pass: nearest first per ray.
        let mut hits: Vec<(u32, Hit)> = Vec::new();
        // The rays still going, as (index within the chunk, ray).
        let mut live: Vec<(u32, Ray)> = chunk.iter().enumerate().map(|(i, r)| (i as u32, *r)).collect();
        let mut batch: Vec<Ray> = Vec::with_capacity(live.len());
        let mut found: Vec<Hit> = Vec::with_capacity(live.len());
        for _ in 0..max_hits {
            if live.is_empty() {
                break;
            }
            batch.clear();
            batch.extend(live.iter().map(|(_, r)| *r));
            found.clear();
            found.resize(batch.len(), Hit::MISS);
            target.scene.intersect_stream(&batch, &mut found, &StreamOptions::CALLER);
            let mut next = 0;
            for idx in 0..live.len() {
                let hit = found[idx];
                if !hit.is_hit() {
                    continue;
                }
                let (j, mut ray) = live[idx];
                hits.push((j, hit));
                let step = min_step / ray.dir.length();
                // At least the next float above t: the interval [tnear, tfar] holds tnear.
                ray.tnear = (hit.t + step).max(hit.t.next_up());
                if ray.tnear.is_finite() && ray.tnear <= ray.tfar {
                    live[next] = (j, ray);
                    next += 1;
                }
            }
            live.truncate(next);
        }
        // Ray-major; the stable sort keeps each ray's hits nearest first.
        hits.sort_by_key(|&(j, _)| j);
        for (j, h) in hits {
            out.ray.push((start + j as usize) as i64);
            out.prim.push(target.caller_prim(h.prim));
            out.t.push(h.t);
            out.u.push(h.u);
            out.v.push(h.v);
        }
    });
    let mut all = AllHits::default();
    let total: usize = parts.iter().map(|p| p.ray.len()).sum();
    all.ray.reserve_exact(total);
    all.prim.reserve_exact(total);
    all.t.reserve_exact(total);
    all.u.reserve_exact(total);
    all.v.reserve_exact(total);
    for p in parts {
        all.ray.extend(p.ray);
        all.prim.extend(p.prim);
        all.t.extend(p.t);
        all.u.extend(p.u);
        all.v.extend(p.v);
    }
    all
}

/// Where each hit ray meets the plane of its triangle, in float64 (as trimesh computes hit
/// locations): `origin + s * direction` with `s` from the plane equation of the float64
/// triangle, or `origin + t * direction` where the ray runs along the plane.
pub fn plane_points(
    vertices: &[f64],
    faces: &[i64],
    hits: (&[i64], &[i64], &[f32]),
    rays: (&[f64], &[f64]),
    out: &mut [f64],
) -> Result<(), String> {
    let (tri, ray, t) = hits;
    let (origins, directions) = rays;
    let row = |a: &[f64], i: usize| -> Option<[f64; 3]> { a.get(3 * i..3 * i + 3).map(|r| [r[0], r[1], r[2]]) };
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let cross =
        |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    out.par_chunks_mut(3).enumerate().try_for_each(|(k, p)| {
        let bad = || format!("hit {k}: triangle {} or ray {} out of range", tri[k], ray[k]);
        let f = row_i64(faces, tri[k] as usize).ok_or_else(bad)?;
        let [a, b, c] = f.map(|i| row(vertices, i as usize));
        let (Some(a), Some(b), Some(c)) = (a, b, c) else { return Err(bad()) };
        let (o, d) =
            (row(origins, ray[k] as usize).ok_or_else(bad)?, row(directions, ray[k] as usize).ok_or_else(bad)?);
        let n = cross(sub(b, a), sub(c, a));
        let denom = dot(n, d);
        let along = denom.abs() <= 1e-12 * dot(d, d).sqrt() * dot(n, n).sqrt();
        let s = if along { t[k] as f64 } else { dot(n, sub(a, o)) / denom };
        p.copy_from_slice(&[o[0] + s * d[0], o[1] + s * d[1], o[2] + s * d[2]]);
        Ok(())
    })
}

fn row_i64(a: &[i64], i: usize) -> Option<[i64; 3]> {
    a.get(3 * i..3 * i + 3).map(|r| [r[0], r[1], r[2]])
}
