// Not split: the module's entry points (#[pyfunction]s and the Scene class) are registered together here; argument parsing, checks and tracing already live in args.rs, checks.rs and trace.rs.
//! `pyraypack._raypack`: the Python module. numpy in, numpy out, in the vocabulary of the Rust
//! API ([`raypack::Scene`], [`raypack::Hit`]) and of Embree.
//!
//! Every entry point checks its arguments under the GIL (errors name the argument, its shape
//! or dtype and what was expected), then traces with the GIL released, and turns a panic of
//! the library into a `RuntimeError` instead of unwinding into the interpreter.

mod args;
mod checks;
mod internal;
mod trace;

use args::RayArgs;
use numpy::{PyArray1, PyArray2, PyArray3, PyArrayMethods};
use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};
use raypack::io::LoadError;
use raypack::render::{IntegratorKind, RenderSettings, SamplerKind};
use raypack::{BuildOptions, BuildQuality, CommitReport, Material, Scene, SceneBuilder};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use trace::{HitArrays, Target};

pyo3::create_exception!(
    _raypack,
    SceneWarning,
    pyo3::exceptions::PyUserWarning,
    "A scene was loaded or committed with something left out (dropped faces, a BVH cache \
     that could not be used, loader warnings)."
);

/// Runs `f` with the GIL released on `threads` threads (all cores for `None`), turning a
/// panic into a `RuntimeError`.
fn run_detached<T: Send>(
    py: Python<'_>,
    pools: &PoolCache,
    threads: Option<usize>,
    f: impl FnOnce() -> T + Send,
) -> PyResult<T> {
    let pool = pools.get(threads)?;
    let result = py.detach(move || {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match pool {
            Some(pool) => pool.install(f),
            None => f(),
        }))
    });
    result.map_err(|panic| {
        let what = panic
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| panic.downcast_ref::<&str>().copied())
            .unwrap_or("unknown panic");
        PyRuntimeError::new_err(format!("raypack: internal error (please report it): {what}"))
    })
}

/// The rayon pool of the last `threads=` a scene was asked for (building one per call costs
/// a thread start per worker).
#[derive(Default)]
struct PoolCache(Mutex<Option<(usize, Arc<rayon::ThreadPool>)>>);

impl PoolCache {
    /// `None`: the global pool (all cores, or `RAYON_NUM_THREADS`).
    fn get(&self, threads: Option<usize>) -> PyResult<Option<Arc<rayon::ThreadPool>>> {
        let Some(n) = threads else { return Ok(None) };
        raypack::system::check_threads(n).map_err(|e| {
            PyValueError::new_err(format!(
                "threads: expected None (all cores) or 1 to {} threads ({} per logical CPU; this machine has {}), got {n}",
                e.max,
                raypack::system::THREADS_PER_CPU,
                e.cpus
            ))
        })?;
        let mut cached = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((m, pool)) = cached.as_ref()
            && *m == n
        {
            return Ok(Some(pool.clone()));
        }
        let pool = Arc::new(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| PyRuntimeError::new_err(format!("threads={n}: cannot start the threads: {e}")))?,
        );
        *cached = Some((n, pool.clone()));
        Ok(Some(pool))
    }
}

fn parse_quality(q: &str) -> PyResult<BuildQuality> {
    q.parse().map_err(|e| PyValueError::new_err(format!("quality: {e}")))
}

fn parse_integrator(name: &str) -> PyResult<IntegratorKind> {
    match name.parse::<IntegratorKind>() {
        // A picture of the traversal's cost, not radiance: the CLI's (`raypack render --integrator heatmap`).
        Ok(IntegratorKind::Heatmap) | Err(_) => Err(PyValueError::new_err(format!(
            "integrator: expected 'global', 'direct', 'direct-only', 'indirect-only', 'bounce' or 'normals', got '{name}'"
        ))),
        Ok(kind) => Ok(kind),
    }
}

fn load_error(e: LoadError) -> PyErr {
    match &e {
        LoadError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(e.to_string())
        }
        LoadError::Io { .. } => PyOSError::new_err(e.to_string()),
        LoadError::UnsupportedFormat { .. } | LoadError::Parse { .. } => PyValueError::new_err(e.to_string()),
    }
}

/// Issues a `SceneWarning` at the caller's line: a native function has no frame of its own,
/// so stack level 1 is the Python line that called it.
fn warn(py: Python<'_>, message: &str) -> PyResult<()> {
    let category = py.get_type::<SceneWarning>();
    PyErr::warn(py, &category, &std::ffi::CString::new(message).unwrap_or_default(), 1)
}

/// How a scene is built: `quality=`, `watertight=`, `bvh_cache=`, `threads=`.
struct BuildArgs {
    opts: BuildOptions,
    cache: Option<PathBuf>,
    threads: Option<usize>,
}

impl BuildArgs {
    fn new(
        py: Python<'_>,
        quality: &str,
        watertight: bool,
        bvh_cache: Option<PathBuf>,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        checks::isa_env(py)?;
        let opts = BuildOptions { quality: parse_quality(quality)?, watertight, ..BuildOptions::default() };
        if bvh_cache.as_ref().is_some_and(|p| p.as_os_str().is_empty()) {
            return Err(PyValueError::new_err(
                "bvh_cache: expected a directory, got an empty path (give '.' for the current directory)",
            ));
        }
        Ok(Self { opts, cache: bvh_cache, threads })
    }
}

/// A committed scene: triangles (and the spheres of scene files) under raypack's BVH8.
///
/// ``Scene(vertices, faces, *, quality="medium", watertight=False, bvh_cache=None, threads=None)``
/// builds one from a ``(N, 3)`` array of vertex positions (any real dtype, rounded to float32)
/// and an ``(M, 3)`` integer array of vertex indices; ``pyraypack.load(path)`` reads a scene file.
/// Faces with NaN/Inf or huge coordinates, zero area or collinear corners cannot be traced:
/// they are dropped, counted in ``report`` and announced by a ``SceneWarning``; they are never
/// hit, and ``prim`` ids and ``Scene.faces`` stay those of the faces given (or the file holds).
#[pyclass(name = "Scene", module = "pyraypack", frozen)]
struct PyScene {
    scene: Scene,
    /// The options the BVH was built with (a pickle carries them: the snapshot's key covers
    /// them).
    opts: BuildOptions,
    /// The faces the commit dropped and where the kept ones were, when it dropped some.
    dropped: Option<Dropped>,
    report: CommitReport,
    /// The BVH cache file and whether the BVH came from it.
    cache: Option<(PathBuf, bool)>,
    pools: PoolCache,
}

impl PyScene {
    fn target(&self) -> Target<'_> {
        match &self.dropped {
            None => Target { scene: &self.scene, kept: None, given_triangles: self.scene.num_triangles() },
            Some(d) => Target { scene: &self.scene, kept: Some(&d.kept), given_triangles: d.given_len() },
        }
    }

    /// Commits `builder` as `build` says, warning about what was dropped or not cached.
    fn commit(py: Python<'_>, builder: SceneBuilder, build: &BuildArgs, what: &str) -> PyResult<Self> {
        let pools = PoolCache::default();
        // The faces as given, to number hits by them when the commit drops some.
        let given = builder.triangle_indices().to_vec();
        let (opts, cache_dir) = (&build.opts, build.cache.as_deref());
        let (scene, report, cache) = run_detached(py, &pools, build.threads, || match cache_dir {
            None => {
                let (s, r) = builder.commit(opts);
                (s, r, None)
            }
            Some(dir) => {
                let (s, r, c) = builder.commit_cached(opts, dir);
                (s, r, Some(c))
            }
        })?;
        let mut cache_info = None;
        if let Some(c) = cache {
            for w in c.warnings() {
                warn(py, &format!("{what}: {w}"))?;
            }
            cache_info = Some((c.path.clone(), c.loaded));
        }
        let dropped = if report.triangles < given.len() {
            let d = Dropped::new(&given, &scene.triangles.indices).ok_or_else(|| {
                PyRuntimeError::new_err(format!(
                    "{what}: internal error (please report it): the committed faces are not the given ones in order"
                ))
            })?;
            Some(d)
        } else {
            None
        };
        drop(given);
        Ok(PyScene { scene, opts: opts.clone(), dropped, report, cache: cache_info, pools })
    }

    /// The faces as given: the committed triangles with the dropped ones back in their places.
    fn given_faces(&self) -> std::borrow::Cow<'_, [[u32; 3]]> {
        let committed = &self.scene.triangles.indices;
        let Some(d) = &self.dropped else { return committed.as_slice().into() };
        let mut faces = Vec::with_capacity(d.given_len());
        let (mut kept, mut dropped) = (d.kept.iter().zip(committed).peekable(), d.faces.iter());
        for j in 0..d.given_len() {
            match kept.next_if(|(k, _)| **k as usize == j) {
                Some((_, f)) => faces.push(*f),
                None => faces.extend(dropped.next()),
            }
        }
        faces.into()
    }
}

/// What a commit dropped of the faces it was given, so that `prim` ids and `Scene.faces`
/// stay the given faces' (the library numbers the kept triangles `0..kept`).
struct Dropped {
    /// The given index of each committed triangle (increasing).
    kept: Vec<u32>,
    /// The dropped faces, in the order given.
    faces: Vec<[u32; 3]>,
}

impl Dropped {
    /// From the faces given and those the commit kept: the commit keeps faces in order and
    /// drops a face for its corners' positions only, so equal index triples share a fate and
    /// the kept faces match the given ones greedily. `None` if they are not a subsequence.
    fn new(given: &[[u32; 3]], kept_faces: &[[u32; 3]]) -> Option<Self> {
        let mut kept = Vec::with_capacity(kept_faces.len());
        let mut faces = Vec::with_capacity(given.len().saturating_sub(kept_faces.len()));
        let mut rest = given.iter().enumerate();
        for k in kept_faces {
            loop {
                let (j, g) = rest.next()?;
                if g == k {
                    kept.push(j as u32);
                    break;
                }
                faces.push(*g);
            }
        }
        faces.extend(rest.map(|(_, g)| *g));
        Some(Dropped { kept, faces })
    }

    /// How many faces were given.
    fn given_len(&self) -> usize {
        self.kept.len() + self.faces.len()
    }
}

#[pymethods]
impl PyScene {
    #[new]
    #[pyo3(signature = (vertices, faces, *, quality = "medium", watertight = false, bvh_cache = None, threads = None))]
    fn new(
        py: Python<'_>,
        vertices: &Bound<'_, PyAny>,
        faces: &Bound<'_, PyAny>,
        quality: &str,
        watertight: bool,
        bvh_cache: Option<PathBuf>,
        #[pyo3(from_py_with = checks::threads)] threads: Option<usize>,
    ) -> PyResult<Self> {
        let build = BuildArgs::new(py, quality, watertight, bvh_cache, threads)?;
        let positions = args::vertices(vertices)?;
        let indices = args::faces(faces, positions.len())?;
        // As a PLY file of these triangles loads: one default material, area-weighted vertex
        // normals for smooth shading, and the default light rig, so that it renders alike.
        let mut b = SceneBuilder::new();
        let material = b.add_material(Material::default());
        let normals = raypack::io::vertex_normals(&positions, &indices);
        b.add_mesh_with_normals(&positions, Some(&normals), &indices, material)
            .map_err(|e| PyValueError::new_err(format!("faces: {e}")))?;
        for light in raypack::io::default_light_rig(&b.bounds(), None) {
            b.add_light(light);
        }
        drop((positions, normals));
        let scene = Self::commit(py, b, &build, "pyraypack.Scene")?;
        let r = &scene.report;
        if r.dropped() > 0 {
            warn(
                py,
                &format!(
                    "pyraypack.Scene: dropped {} of {} faces ({} with NaN/Inf or huge coordinates, {} with zero area or collinear corners); they are never hit",
                    r.dropped(),
                    indices.len(),
                    r.dropped_non_finite,
                    r.dropped_degenerate
                ),
            )?;
        }
        Ok(scene)
    }

    /// Closest hit of each ray ``origin + t * direction`` over ``t`` in ``[tnear, tfar]``, as a
    /// ``Hits`` of arrays ``t, prim, u, v, normal``. Both ends count: a ray that starts on a
    /// surface (``tnear = 0``) hits it at ``t = 0``.
    ///
    /// ``origins`` and ``directions`` are ``(K, 3)`` real arrays (float32 and float64 are read
    /// in place whatever their strides; one ``(3,)`` point stands for all rays); ``tnear``
    /// (default 0) and ``tfar`` (default ``inf``) are numbers or ``(K,)`` arrays, and a value
    /// below zero is a ``ValueError`` naming the argument. Directions need not be unit length:
    /// ``t`` is measured in units of their length. Rays with a NaN/Inf component, a zero
    /// direction, a NaN ``tnear``/``tfar`` or ``tnear > tfar`` miss. Traced over ``threads``
    /// threads (default: all cores) with the GIL released, as 16-ray packets in the order
    /// given (keep coherent rays together).
    #[pyo3(signature = (origins, directions, tnear = None, tfar = None, *, threads = None))]
    fn intersect<'py>(
        &self,
        py: Python<'py>,
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        tnear: Option<&Bound<'py, PyAny>>,
        tfar: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = checks::threads)] threads: Option<usize>,
    ) -> PyResult<Hits> {
        let a = RayArgs::new(origins, directions, tnear, tfar)?;
        let k = a.rays()?.len;
        // SAFETY (all five): uninitialised numpy arrays (`np.empty`; zeroing them cost 4 ns per
        // ray), of which `trace::intersect` writes every element before Python can see them
        // (on an error or panic they are dropped unseen).
        let t = unsafe { PyArray1::<f32>::new(py, k, false) };
        let prim = unsafe { PyArray1::<i64>::new(py, k, false) };
        let u = unsafe { PyArray1::<f32>::new(py, k, false) };
        let v = unsafe { PyArray1::<f32>::new(py, k, false) };
        let normal = unsafe { PyArray2::<f32>::new(py, (k, 3), false) };
        {
            let (mut tw, mut pw, mut uw, mut vw, mut nw) =
                (t.readwrite(), prim.readwrite(), u.readwrite(), v.readwrite(), normal.readwrite());
            let mut out = HitArrays {
                t: tw.as_slice_mut()?,
                prim: pw.as_slice_mut()?,
                u: uw.as_slice_mut()?,
                v: vw.as_slice_mut()?,
                normal: nw.as_slice_mut()?,
            };
            let target = self.target();
            let each = &mut |start, rays: &[raypack::Ray]| trace::intersect(target, rays, out.range(start, rays.len()));
            trace::passes(py, &self.pools, threads, &a, k, each)?;
        }
        Ok(Hits {
            t: t.into_any().unbind(),
            prim: prim.into_any().unbind(),
            u: u.into_any().unbind(),
            v: v.into_any().unbind(),
            normal: normal.into_any().unbind(),
        })
    }

    /// Whether anything lies on each ray over ``[tnear, tfar]``: ``bool (K,)``. Arguments as
    /// for ``intersect``.
    #[pyo3(signature = (origins, directions, tnear = None, tfar = None, *, threads = None))]
    fn occluded<'py>(
        &self,
        py: Python<'py>,
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        tnear: Option<&Bound<'py, PyAny>>,
        tfar: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = checks::threads)] threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let a = RayArgs::new(origins, directions, tnear, tfar)?;
        let k = a.rays()?.len;
        // SAFETY: `np.empty`, every element written by `trace::occluded` (as in `intersect`).
        let out = unsafe { PyArray1::<bool>::new(py, k, false) };
        {
            let mut w = out.readwrite();
            let slice = w.as_slice_mut()?;
            let target = self.target();
            let each = &mut |start, rays: &[raypack::Ray]| {
                trace::occluded(target, rays, &mut slice[start..start + rays.len()])
            };
            trace::passes(py, &self.pools, threads, &a, k, each)?;
        }
        Ok(out)
    }

    /// Every hit along each ray, at most ``max_hits`` per ray: ``(ray, prim, t, u, v)`` arrays,
    /// ordered by ray, then by ``t``. After a hit at ``t`` the ray goes on from
    /// ``t + min_step / |direction|`` (``min_step`` is a distance), at least from the next
    /// float above ``t``; the first hit may be at ``t = tnear``.
    #[pyo3(signature = (origins, directions, tnear = None, tfar = None, *, max_hits = 100, min_step = 0.0, threads = None))]
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn intersect_all<'py>(
        &self,
        py: Python<'py>,
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        tnear: Option<&Bound<'py, PyAny>>,
        tfar: Option<&Bound<'py, PyAny>>,
        max_hits: usize,
        min_step: f64,
        #[pyo3(from_py_with = checks::threads)] threads: Option<usize>,
    ) -> PyResult<(
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<f32>>,
    )> {
        if !(min_step >= 0.0 && min_step.is_finite()) {
            return Err(PyValueError::new_err(format!("min_step: expected a finite distance >= 0, got {min_step}")));
        }
        let a = RayArgs::new(origins, directions, tnear, tfar)?;
        let k = a.rays()?.len;
        let target = self.target();
        let mut all = trace::AllHits::default();
        let each = &mut |start, rays: &[raypack::Ray]| {
            all.append(trace::intersect_all(target, rays, start, max_hits, min_step as f32))
        };
        trace::passes(py, &self.pools, threads, &a, k, each)?;
        Ok((
            PyArray1::from_vec(py, all.ray),
            PyArray1::from_vec(py, all.prim),
            PyArray1::from_vec(py, all.t),
            PyArray1::from_vec(py, all.u),
            PyArray1::from_vec(py, all.v),
        ))
    }

    /// Triangles the scene traces (after dropping the untraceable ones).
    #[getter]
    fn num_triangles(&self) -> usize {
        self.scene.num_triangles()
    }

    /// Spheres the scene traces (scene files only).
    #[getter]
    fn num_spheres(&self) -> usize {
        self.scene.num_spheres()
    }

    /// The scene's bounds as a ``(2, 3)`` float32 array ``[min, max]`` (NaN for an empty scene).
    #[getter]
    fn bounds<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        let b = self.scene.bounds();
        let rows = if b.is_valid() { [b.min.to_array(), b.max.to_array()] } else { [[f32::NAN; 3]; 2] };
        PyArray2::from_vec2(py, &[rows[0].to_vec(), rows[1].to_vec()]).expect("two rows of three")
    }

    /// What the commit kept and dropped: a dict of counts.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let r = &self.report;
        let d = PyDict::new(py);
        d.set_item("triangles", r.triangles)?;
        d.set_item("spheres", r.spheres)?;
        d.set_item("dropped_non_finite", r.dropped_non_finite)?;
        d.set_item("dropped_degenerate", r.dropped_degenerate)?;
        d.set_item("dropped_spheres", r.dropped_spheres)?;
        Ok(d)
    }

    /// The BVH cache file of this scene (``None`` without ``bvh_cache=``).
    #[getter]
    fn bvh_cache_file(&self) -> Option<PathBuf> {
        self.cache.as_ref().map(|(p, _)| p.clone())
    }

    /// True when the BVH was read from the cache rather than built.
    #[getter]
    fn bvh_cache_loaded(&self) -> bool {
        self.cache.as_ref().is_some_and(|(_, loaded)| *loaded)
    }

    /// The vertex positions ``(N, 3)`` float32 (a copy).
    #[getter]
    fn vertices<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        let p = &self.scene.triangles.positions;
        let flat: Vec<f32> = p.iter().flat_map(|v| v.to_array()).collect();
        PyArray1::from_vec(py, flat).reshape((p.len(), 3)).expect("3 floats per vertex")
    }

    /// The faces ``(M, 3)`` int64 (a copy) as given to ``Scene`` or as the file holds them
    /// (polygons as triangles), the dropped ones included: ``prim`` ids index these rows
    /// (a sphere's ``prim`` is ``M`` plus its index among the scene's spheres).
    #[getter]
    fn faces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        let f = self.given_faces();
        let flat: Vec<i64> = f.iter().flat_map(|t| t.map(|i| i as i64)).collect();
        PyArray1::from_vec(py, flat).reshape((f.len(), 3)).expect("3 indices per face")
    }

    fn __repr__(&self) -> String {
        format!(
            "<pyraypack.Scene: {} triangles, {} spheres, isa={}>",
            self.scene.num_triangles(),
            self.scene.num_spheres(),
            self.scene.isa()
        )
    }

    /// A token of the scene's contents for Dask (``dask.base.tokenize``): equal for scenes
    /// that trace and render alike, so that a scene sent to a cluster is found there again
    /// instead of being hashed through its pickle.
    fn __dask_tokenize__(&self) -> String {
        let s = &self.scene;
        let mut h = xxhash_rust::xxh3::Xxh3::new();
        h.update(&raypack::render::part::scene_digest(s).to_le_bytes());
        let dropped = self.dropped.as_ref();
        h.update(
            format!("{:?} {:?} {:?}", s.camera, self.opts, dropped.map(|d| (d.kept.len(), d.faces.len()))).as_bytes(),
        );
        if let Some(d) = dropped {
            h.update(&u32_bytes(&d.kept));
            h.update(&u32_bytes(d.faces.as_flattened()));
        }
        format!("pyraypack.Scene-{:032x}", h.digest128())
    }

    /// Pickling: the scene travels whole, BVH included, so that a process unpickling it
    /// (a Dask worker) never builds it again. The bytes are a snapshot in the BVH cache's
    /// layout (about the BVH's size plus the geometry's; `len(pickle.dumps(scene))`), checked
    /// on unpickling as strictly as a cache file from another user.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let scene = &self.scene;
        let opts = &self.opts;
        let bytes = run_detached(py, &self.pools, None, || scene.to_snapshot(opts))?;
        let kept = self.dropped.as_ref().map(|d| PyBytes::new(py, &u32_bytes(&d.kept)));
        let dropped = self.dropped.as_ref().map(|d| PyBytes::new(py, &u32_bytes(d.faces.as_flattened())));
        let r = &self.report;
        let report = (r.triangles, r.spheres, r.dropped_non_finite, r.dropped_degenerate, r.dropped_spheres);
        let rebuild = py.import("pyraypack._raypack")?.getattr("_scene_from_snapshot")?;
        let args = (PyBytes::new(py, &bytes), kept, report, dropped).into_pyobject(py)?;
        Ok((rebuild, args))
    }
}

/// `u32`s as their little-endian bytes.
fn u32_bytes(v: &[u32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Little-endian bytes as `u32`s, if they are whole.
fn u32s_of(b: &[u8]) -> Option<Vec<u32>> {
    b.len().is_multiple_of(4).then(|| b.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
}

/// Unpickles a `Scene` (see `Scene.__reduce__`): the snapshot is checked before use, and a
/// damaged or forged one raises `ValueError`. Not part of the public API.
#[pyfunction]
#[pyo3(signature = (snapshot, kept, report, dropped = None))]
fn _scene_from_snapshot(
    py: Python<'_>,
    snapshot: &[u8],
    kept: Option<&[u8]>,
    report: (usize, usize, usize, usize, usize),
    dropped: Option<&[u8]>,
) -> PyResult<PyScene> {
    let pools = PoolCache::default();
    let (scene, opts) = run_detached(py, &pools, None, || Scene::from_snapshot(snapshot))?
        .map_err(|e| PyValueError::new_err(format!("pyraypack.Scene: cannot unpickle: {e}")))?;
    let dropped = match (kept, dropped) {
        (None, None) => None,
        (Some(k), d) => {
            let kept = u32s_of(k);
            let faces = u32s_of(d.unwrap_or_default())
                .filter(|f| f.len().is_multiple_of(3))
                .map(|f| f.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect::<Vec<_>>());
            // The given indices of the kept faces: increasing, one per triangle, all below the
            // number of faces given; the dropped faces' corners among the scene's vertices.
            let vertices = scene.triangles.positions.len();
            let fits = |kept: &[u32], faces: &[[u32; 3]]| {
                kept.len() == scene.num_triangles()
                    && kept.windows(2).all(|w| w[0] < w[1])
                    && kept.last().is_none_or(|&k| (k as usize) < kept.len() + faces.len())
                    && faces.iter().flatten().all(|&i| (i as usize) < vertices)
            };
            match (kept, faces) {
                (Some(kept), Some(faces)) if fits(&kept, &faces) => Some(Dropped { kept, faces }),
                _ => {
                    return Err(PyValueError::new_err(
                        "pyraypack.Scene: cannot unpickle: the face map does not fit the scene's triangles",
                    ));
                }
            }
        }
        (None, Some(_)) => {
            return Err(PyValueError::new_err("pyraypack.Scene: cannot unpickle: dropped faces without a face map"));
        }
    };
    let (triangles, spheres, dropped_non_finite, dropped_degenerate, dropped_spheres) = report;
    if (triangles, spheres) != (scene.num_triangles(), scene.num_spheres()) {
        return Err(PyValueError::new_err("pyraypack.Scene: cannot unpickle: the report does not fit the scene"));
    }
    let report = CommitReport { triangles, spheres, dropped_non_finite, dropped_degenerate, dropped_spheres };
    Ok(PyScene { scene, opts, dropped, report, cache: None, pools })
}

/// The closest hits of a ray query, one entry per ray: ``t`` (float32, ``inf`` on a miss),
/// ``prim`` (int64, ``-1`` on a miss), ``u``, ``v`` (float32 barycentrics of the second and
/// third vertex, 0 on a miss) and ``normal`` (float32 ``(K, 3)``, unit geometric normal
/// ``(v1 - v0) x (v2 - v0)``, zero on a miss). Unpacks as ``t, prim, u, v, normal = hits``.
#[pyclass(name = "Hits", module = "pyraypack", frozen)]
struct Hits {
    #[pyo3(get)]
    t: Py<PyAny>,
    #[pyo3(get)]
    prim: Py<PyAny>,
    #[pyo3(get)]
    u: Py<PyAny>,
    #[pyo3(get)]
    v: Py<PyAny>,
    #[pyo3(get)]
    normal: Py<PyAny>,
}

#[pymethods]
impl Hits {
    fn __iter__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let items = (&self.t, &self.prim, &self.u, &self.v, &self.normal).into_pyobject(py)?;
        Ok(items.into_any().try_iter()?.into_any())
    }

    fn __len__(&self) -> usize {
        5
    }

    /// Whether each ray hit something: ``prim >= 0``.
    #[getter]
    fn hit<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.prim.bind(py).call_method1("__ge__", (0,))
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let n = self.t.bind(py).len()?;
        let hits: usize = self.hit(py)?.call_method0("sum")?.extract()?;
        Ok(format!("<pyraypack.Hits: {hits} of {n} rays hit>"))
    }
}

/// Loads a scene file (``.dae``, ``.obj``, ``.ply``) and commits it. A file without lights
/// gets the CLI's default light rig for ``render`` without a warning (ray casting does not
/// use lights; ``render(path)`` says so).
#[pyfunction]
#[pyo3(signature = (path, *, quality = "medium", watertight = false, bvh_cache = None, threads = None))]
fn load(
    py: Python<'_>,
    path: PathBuf,
    quality: &str,
    watertight: bool,
    bvh_cache: Option<PathBuf>,
    #[pyo3(from_py_with = checks::threads)] threads: Option<usize>,
) -> PyResult<PyScene> {
    let build = BuildArgs::new(py, quality, watertight, bvh_cache, threads)?;
    load_path(py, &path, &build, false)
}

/// `load` for a render elsewhere (`pyraypack.dask.render(path)`): also warns when the file
/// has no lights, as `render(path)` does.
#[pyfunction]
#[pyo3(signature = (path, *, quality = "medium", watertight = false, bvh_cache = None))]
fn _load_for_render(
    py: Python<'_>,
    path: PathBuf,
    quality: &str,
    watertight: bool,
    bvh_cache: Option<PathBuf>,
) -> PyResult<PyScene> {
    let build = BuildArgs::new(py, quality, watertight, bvh_cache, None)?;
    load_path(py, &path, &build, true)
}

/// Loads and commits a scene file; `for_render`: also warn when the file has no lights (the
/// default light rig is added either way).
fn load_path(py: Python<'_>, path: &Path, build: &BuildArgs, for_render: bool) -> PyResult<PyScene> {
    let (builder, mut warnings, synthesized) = {
        let p = path.to_path_buf();
        run_detached(py, &PoolCache::default(), build.threads, move || {
            raypack::io::load_scene(&p).map(|l| (l.builder, l.warnings, l.synthesized))
        })?
        .map_err(load_error)?
    };
    let lights_added = synthesized.iter().any(|s| matches!(s, raypack::io::Synthesized::DefaultLights { .. }));
    if lights_added && !for_render {
        // The loader's last warning is the one that announces the rig.
        warnings.pop();
    }
    for w in warnings {
        warn(py, &w)?;
    }
    let scene = PyScene::commit(py, builder, build, &path.display().to_string())?;
    if scene.report.dropped() > 0 {
        warn(py, &format!("{}: {}", path.display(), scene.report))?;
    }
    Ok(scene)
}

/// Renders a scene (a ``Scene`` or a scene file's path) with the path tracer and returns the
/// linear HDR image as float32 ``(height, width, 3)``, top row first.
///
/// ``crop_window=(x0, x1, y0, y1)`` (fractions of the image, as pbrt's ``--cropwindow``) or
/// ``pixel_bounds=(x0, x1, y0, y1)`` (pixels, ends exclusive) render only that window of the
/// ``width x height`` image and return its pixels, ``(y1 - y0, x1 - x0, 3)``: each has, bit for
/// bit, its value in the whole image, whatever the window and the thread count
/// (``pyraypack.tile_bounds`` gives the windows of ``raypack render --tile``).
#[pyfunction]
#[pyo3(signature = (scene, *, spp = 1, max_depth = 1, light_samples = 1, width = 480, height = 360, seed = 0,
    sampler = "sobol", integrator = "global", hemisphere = false, russian_roulette = true, threads = None, quality = "medium",
    watertight = false, bvh_cache = None, crop_window = None, pixel_bounds = None))]
#[allow(clippy::too_many_arguments)]
fn render<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    spp: u32,
    max_depth: u32,
    light_samples: u32,
    width: usize,
    height: usize,
    seed: u64,
    sampler: &str,
    integrator: &str,
    hemisphere: bool,
    russian_roulette: bool,
    #[pyo3(from_py_with = checks::threads)] threads: Option<usize>,
    quality: &str,
    watertight: bool,
    bvh_cache: Option<PathBuf>,
    crop_window: Option<(f64, f64, f64, f64)>,
    pixel_bounds: Option<(usize, usize, usize, usize)>,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    use raypack::render::PixelBounds;
    if width == 0 || height == 0 || width > 1 << 15 || height > 1 << 15 {
        return Err(PyValueError::new_err(format!(
            "width, height: expected 1 to 32768 pixels each, got {width} x {height}"
        )));
    }
    let window = match (crop_window, pixel_bounds) {
        (Some(_), Some(_)) => {
            return Err(PyValueError::new_err("crop_window, pixel_bounds: give one of them, not both"));
        }
        (Some((x0, x1, y0, y1)), None) => PixelBounds::from_crop_window([x0, x1, y0, y1], width, height)
            .map_err(|e| PyValueError::new_err(format!("crop_window: {e}")))?,
        (None, Some((x0, x1, y0, y1))) => PixelBounds { x0, x1, y0, y1 }
            .within(width, height)
            .map_err(|e| PyValueError::new_err(format!("pixel_bounds: {e}")))?,
        (None, None) => PixelBounds::full(width, height),
    };
    if spp == 0 || light_samples == 0 {
        return Err(PyValueError::new_err(format!(
            "spp, light_samples: expected at least 1 each, got spp={spp}, light_samples={light_samples}"
        )));
    }
    let settings = RenderSettings {
        width,
        height,
        samples_per_pixel: spp,
        light_samples,
        max_depth,
        hemisphere_sampling: hemisphere,
        adaptive: None,
        integrator: parse_integrator(integrator)?,
        heatmap: Default::default(),
        seed,
        sampler: sampler.parse::<SamplerKind>().map_err(|e| PyValueError::new_err(format!("sampler: {e}")))?,
        brute_force: false,
        russian_roulette,
        stream_order: None,
        max_sample_value: None,
        pixel_culling: true,
    };
    let build_given = (quality, watertight, bvh_cache.is_some()) != ("medium", false, false);
    let build = BuildArgs::new(py, quality, watertight, bvh_cache, threads)?;
    checks::render_memory(&settings, threads)?;
    let loaded;
    let bound;
    let s: &PyScene = if let Ok(s) = scene.cast::<PyScene>() {
        if build_given {
            return Err(PyValueError::new_err(
                "quality, watertight, bvh_cache: they build a scene from a file; this pyraypack.Scene is built \
                 already (give them to pyraypack.Scene or pyraypack.load)",
            ));
        }
        bound = s.clone();
        bound.get()
    } else if let Ok(path) = scene.extract::<PathBuf>() {
        loaded = load_path(py, &path, &build, true)?;
        &loaded
    } else {
        return Err(PyTypeError::new_err(format!(
            "scene: expected a pyraypack.Scene or a path to a scene file, got {}",
            scene.get_type().name()?
        )));
    };
    let film = run_detached(py, &s.pools, threads, || {
        let camera = s.scene.camera_or_framing(width as f32 / height as f32);
        raypack::render::render_window(&s.scene, &camera, &settings, &window, &|_| {}).film
    })?;
    let flat: Vec<f32> = film.pixels.iter().flat_map(|p| p.to_array()).collect();
    PyArray1::from_vec(py, flat).reshape((window.height(), window.width(), 3))
}

/// The pixel bounds ``(x0, x1, y0, y1)`` (ends exclusive) of the ``count`` parts of a
/// ``width x height`` image, in the order ``raypack render --tile I/N`` numbers them: a grid of
/// nearly square cells, row by row from the top left. Pass one to ``render(pixel_bounds=)``.
#[pyfunction]
fn tile_bounds(count: usize, width: usize, height: usize) -> PyResult<Vec<(usize, usize, usize, usize)>> {
    let parts = raypack::render::PixelBounds::parts(count, width, height)
        .map_err(|e| PyValueError::new_err(format!("count, width, height: {e}")))?;
    Ok(parts.into_iter().map(|b| (b.x0, b.x1, b.y0, b.y1)).collect())
}

/// The instruction set the kernels run on in this process: ``"avx512"``, ``"avx2"`` or
/// ``"sse2"`` (``"portable"`` off x86-64), the CPU's best unless ``RAYPACK_ISA`` names a lower
/// tier (read once, when the first scene is made). Every ``Scene``'s ``repr`` shows it too.
#[pyfunction]
fn isa(py: Python<'_>) -> PyResult<&'static str> {
    checks::isa_env(py)?;
    Ok(raypack::Isa::default_for_process().name())
}

/// raypack: a SIMD ray tracer (BVH8, ray packets) for numpy rays.
#[pymodule]
fn _raypack(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScene>()?;
    m.add_class::<Hits>()?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(tile_bounds, m)?)?;
    m.add_function(wrap_pyfunction!(isa, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(internal::_bvh_builds, m)?)?;
    m.add_function(wrap_pyfunction!(_load_for_render, m)?)?;
    m.add_function(wrap_pyfunction!(_scene_from_snapshot, m)?)?;
    m.add_function(wrap_pyfunction!(internal::_ray_sets, m)?)?;
    m.add_function(wrap_pyfunction!(internal::_intersect_stream, m)?)?;
    m.add_function(wrap_pyfunction!(internal::_plane_points, m)?)?;
    m.add("SceneWarning", m.py().get_type::<SceneWarning>())?;
    Ok(())
}
