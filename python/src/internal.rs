//! The module's functions that are not part of its public API: for the tests that compare it
//! with the Rust API, the benchmark scripts, and `pyraypack.trimesh`'s float64 hit points.

use crate::args::RayArgs;
use crate::{PoolCache, PyScene, checks, run_detached, trace};
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// How many BVHs this process has built (loading one from a cache file or a pickle does not
/// count). Not part of the public API: for the tests and benchmarks that check that a scene
/// was not rebuilt.
#[pyfunction]
pub fn _bvh_builds() -> u64 {
    raypack::scene::bvh_builds()
}

/// The ray sets of `raypack bench` (`raypack::raysets`) at `width x height`: a dict
/// `{"camera" | "diffuse" | "shadow": (origins, directions, tfar)}` of float32 arrays, for the
/// benchmark script and the tests (not part of the public API).
#[pyfunction]
#[pyo3(signature = (scene, width, height, seed = 1))]
pub fn _ray_sets<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    width: usize,
    height: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    use raypack::raysets;
    checks::ray_sets_size(width, height)?;
    let s = &scene.get().scene;
    let sets = run_detached(py, &scene.get().pools, None, || {
        let camera = raysets::primary_for_scene(s, width, height);
        let mut hits = vec![raypack::Hit::MISS; camera.len()];
        s.intersect_stream(&camera, &mut hits, &raypack::StreamOptions::POOL);
        let diffuse = raysets::diffuse_bounces(s, &camera, &hits, seed);
        let shadow = raysets::shadow_rays(s, &camera, &hits, raysets::light_above(&s.bounds()));
        [("camera", camera), ("diffuse", diffuse), ("shadow", shadow)]
    })?;
    let d = PyDict::new(py);
    for (name, rays) in sets {
        let k = rays.len();
        let o: Vec<f32> = rays.iter().flat_map(|r| r.origin.to_array()).collect();
        let dir: Vec<f32> = rays.iter().flat_map(|r| r.dir.to_array()).collect();
        let tfar: Vec<f32> = rays.iter().map(|r| r.tfar).collect();
        let o = PyArray1::from_vec(py, o).reshape((k, 3))?;
        let dir = PyArray1::from_vec(py, dir).reshape((k, 3))?;
        d.set_item(name, (o, dir, PyArray1::from_vec(py, tfar)))?;
    }
    Ok(d)
}

/// The rays of `Scene.intersect`'s arguments collected into one `Vec<Ray>` and traced by the
/// library's `Scene::intersect_stream`, as a Rust caller would: `(t, prim, u, v)`, the
/// committed scene's primitive ids numbered as `Scene.intersect` numbers them. For the tests that compare the module with the Rust API
/// (not part of the public API).
#[pyfunction]
#[pyo3(signature = (scene, origins, directions, tnear = 0.0, tfar = f64::INFINITY))]
#[allow(clippy::type_complexity)]
pub fn _intersect_stream<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    origins: &Bound<'py, PyAny>,
    directions: &Bound<'py, PyAny>,
    tnear: f64,
    tfar: f64,
) -> PyResult<(
    Bound<'py, PyArray1<f32>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<f32>>,
    Bound<'py, PyArray1<f32>>,
)> {
    let (tn, tf) = (tnear.into_pyobject(py)?.into_any(), tfar.into_pyobject(py)?.into_any());
    let a = RayArgs::new(origins, directions, Some(&tn), Some(&tf))?;
    let rays = a.rays()?;
    let rays: Vec<raypack::Ray> = (0..rays.len).map(|i| rays.get(i)).collect();
    let mut hits = vec![raypack::Hit::MISS; rays.len()];
    let target = scene.get().target();
    target.scene.intersect_stream(&rays, &mut hits, &raypack::StreamOptions::POOL);
    let prim = hits.iter().map(|h| if h.is_hit() { target.caller_prim(h.prim) } else { -1 }).collect();
    Ok((
        PyArray1::from_iter(py, hits.iter().map(|h| h.t)),
        PyArray1::from_vec(py, prim),
        PyArray1::from_iter(py, hits.iter().map(|h| h.u)),
        PyArray1::from_iter(py, hits.iter().map(|h| h.v)),
    ))
}

/// Hit locations in float64 for `pyraypack.trimesh` (see `trace::plane_points`): `vertices`
/// `(N, 3)` float64 and `faces` `(M, 3)` int64 of the caller's mesh, per hit its triangle,
/// ray and `t`, and the rays `(n, 3)` float64. Not part of the public API.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub fn _plane_points<'py>(
    py: Python<'py>,
    vertices: numpy::PyReadonlyArray2<'py, f64>,
    faces: numpy::PyReadonlyArray2<'py, i64>,
    tri: numpy::PyReadonlyArray1<'py, i64>,
    ray: numpy::PyReadonlyArray1<'py, i64>,
    t: numpy::PyReadonlyArray1<'py, f32>,
    origins: numpy::PyReadonlyArray2<'py, f64>,
    directions: numpy::PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let m = tri.len()?;
    if ray.len()? != m || t.len()? != m {
        return Err(PyValueError::new_err("tri, ray, t: expected the same length"));
    }
    // SAFETY: `np.empty`, every element written by `plane_points` before Python sees it.
    let out = unsafe { PyArray2::<f64>::new(py, (m, 3), false) };
    {
        let mut w = out.readwrite();
        let o = w.as_slice_mut()?;
        // Copied with the GIL held, and the arrays released before it is not (see `args`).
        let (v, f, tr, r, tt, or, di) = (
            vertices.as_slice()?.to_vec(),
            faces.as_slice()?.to_vec(),
            tri.as_slice()?.to_vec(),
            ray.as_slice()?.to_vec(),
            t.as_slice()?.to_vec(),
            origins.as_slice()?.to_vec(),
            directions.as_slice()?.to_vec(),
        );
        drop((vertices, faces, tri, ray, t, origins, directions));
        run_detached(py, &PoolCache::default(), None, move || {
            trace::plane_points(&v, &f, (&tr, &r, &tt), (&or, &di), o)
        })?
        .map_err(PyValueError::new_err)?;
    }
    Ok(out)
}
