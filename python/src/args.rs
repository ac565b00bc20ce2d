//! Reading numpy arguments: shapes and dtypes checked with errors that name the argument,
//! arrays of float32 / float64 read in place whatever their strides (others converted once).
//!
//! The caller's arrays are read only while the GIL is held. Any Python thread can free an
//! array's memory while the GIL is released (`ndarray.resize(refcheck=False)`, or
//! `__setstate__`, which nothing can block: neither an exported buffer nor a weak reference
//! stops it), so the queries copy the rays of each pass out under the GIL and trace the copy
//! without it (`trace::passes`), taking fresh views of the arrays for every pass.

use numpy::ndarray::{ArrayView1, ArrayView2, Ix1, Ix2};
use numpy::{PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyFloat, PyInt};
use raypack::{Ray, Vec3};

/// A numpy array of real numbers as the caller gave it (float32 or float64, any strides), or
/// converted once to float64 from another real dtype (integers, float16, other byte orders,
/// unaligned memory). Its memory is viewed only with the GIL held ([`RealArray::view`]).
pub enum RealArray<'py> {
    F32(Bound<'py, PyArrayDyn<f32>>),
    F64(Bound<'py, PyArrayDyn<f64>>),
}

/// The view of a [`RealArray`]'s elements, for as long as the GIL is held.
pub enum RealView<'a> {
    F32(numpy::ndarray::ArrayViewD<'a, f32>),
    F64(numpy::ndarray::ArrayViewD<'a, f64>),
}

/// `obj` as an array of real numbers; `name` names the argument in errors.
pub fn real_array<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<RealArray<'py>> {
    let arr = numpy_asarray(obj, name, "of real numbers")?;
    let dtype = arr.dtype();
    // Unaligned arrays (views into packed records) and other byte orders are converted.
    let native = dtype.is_native_byteorder() != Some(false) && arr.is_aligned();
    match (dtype.kind(), dtype.itemsize(), native) {
        (b'f', 4, true) => Ok(RealArray::F32(arr.cast::<PyArrayDyn<f32>>()?.clone())),
        (b'f', 8, true) => Ok(RealArray::F64(arr.cast::<PyArrayDyn<f64>>()?.clone())),
        (b'f' | b'i' | b'u', _, _) => {
            let converted = arr.call_method1("astype", ("float64",))?.cast_into::<PyArrayDyn<f64>>()?;
            Ok(RealArray::F64(converted))
        }
        _ => Err(PyTypeError::new_err(format!(
            "{name}: expected an array of real numbers (float32 or float64), got dtype {}",
            dtype.str()?
        ))),
    }
}

impl RealArray<'_> {
    pub fn shape(&self) -> &[usize] {
        match self {
            RealArray::F32(a) => a.shape(),
            RealArray::F64(a) => a.shape(),
        }
    }

    /// The array's elements as they are now. `&self` holds the GIL (the `'py` of the bound
    /// array), and the view lives no longer than this borrow: no Python code can run while it
    /// is used, so none can free or move the memory under it.
    pub fn view(&self) -> RealView<'_> {
        // SAFETY: a read-only view of a live array (held by `self`), used only while the GIL
        // is held (see above); raypack never writes the arrays it is given, and numpy's own
        // borrow flags are not needed, since nothing else in this process writes them either
        // while the GIL is held by this thread.
        unsafe {
            match self {
                RealArray::F32(a) => RealView::F32(a.as_array()),
                RealArray::F64(a) => RealView::F64(a.as_array()),
            }
        }
    }
}

/// `shape` as Python prints it: `(4, 3)`, `(3,)`, `()`.
pub fn shape_str(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!("({})", shape.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")),
    }
}

/// Rows of three coordinates read in place (contiguous rows as slices, other layouts through
/// strided views), or one point standing for every row.
#[derive(Clone, Copy)]
pub enum Points<'a> {
    Same(Vec3),
    Rows32(&'a [f32]),
    Rows64(&'a [f64]),
    Strided32(ArrayView2<'a, f32>),
    Strided64(ArrayView2<'a, f64>),
}

impl Points<'_> {
    /// Row `i` (below the row count the caller checked), rounded to `f32`.
    #[inline(always)]
    pub fn get(&self, i: usize) -> Vec3 {
        match self {
            Points::Same(p) => *p,
            Points::Rows32(a) => Vec3::new(a[3 * i], a[3 * i + 1], a[3 * i + 2]),
            Points::Rows64(a) => Vec3::new(a[3 * i] as f32, a[3 * i + 1] as f32, a[3 * i + 2] as f32),
            Points::Strided32(a) => Vec3::new(a[[i, 0]], a[[i, 1]], a[[i, 2]]),
            Points::Strided64(a) => Vec3::new(a[[i, 0]] as f32, a[[i, 1]] as f32, a[[i, 2]] as f32),
        }
    }

    /// Rows, or `None` for one point.
    pub fn rows(&self) -> Option<usize> {
        match self {
            Points::Same(_) => None,
            Points::Rows32(a) => Some(a.len() / 3),
            Points::Rows64(a) => Some(a.len() / 3),
            Points::Strided32(a) => Some(a.nrows()),
            Points::Strided64(a) => Some(a.nrows()),
        }
    }
}

/// A `(K, 3)` array of points, or (with `one_allowed`) a single `(3,)` point for all rows.
pub fn points<'a>(arr: &'a RealArray<'_>, name: &str, one_allowed: bool) -> PyResult<Points<'a>> {
    let shape = arr.shape();
    let bad = || {
        let expected = if one_allowed { "(K, 3) or (3,)" } else { "(N, 3)" };
        PyValueError::new_err(format!("{name}: expected shape {expected}, got {}", shape_str(shape)))
    };
    match (shape, arr.view()) {
        // `to_slice`: only row-major (C-contiguous) arrays, not Fortran-ordered ones.
        ([_, 3], RealView::F32(a)) => Ok(match a.to_slice() {
            Some(rows) => Points::Rows32(rows),
            None => Points::Strided32(a.into_dimensionality::<Ix2>().map_err(|_| bad())?),
        }),
        ([_, 3], RealView::F64(a)) => Ok(match a.to_slice() {
            Some(rows) => Points::Rows64(rows),
            None => Points::Strided64(a.into_dimensionality::<Ix2>().map_err(|_| bad())?),
        }),
        ([3], RealView::F32(a)) if one_allowed => Ok(Points::Same(Vec3::new(a[[0]], a[[1]], a[[2]]))),
        ([3], RealView::F64(a)) if one_allowed => {
            Ok(Points::Same(Vec3::new(a[[0]] as f32, a[[1]] as f32, a[[2]] as f32)))
        }
        _ => Err(bad()),
    }
}

/// One value per ray read in place, or one value for all rays.
#[derive(Clone, Copy)]
pub enum Column<'a> {
    Same(f32),
    F32(ArrayView1<'a, f32>),
    F64(ArrayView1<'a, f64>),
}

impl Column<'_> {
    #[inline(always)]
    pub fn get(&self, i: usize) -> f32 {
        match self {
            Column::Same(x) => *x,
            Column::F32(a) => a[i],
            Column::F64(a) => a[i] as f32,
        }
    }

    /// Calls `set(&mut out[j], value start + j)` for every `j`, one loop per layout.
    #[inline(always)]
    pub fn fill<T>(&self, start: usize, out: &mut [T], set: impl Fn(&mut T, f32)) {
        let n = out.len();
        match self {
            Column::Same(x) => out.iter_mut().for_each(|o| set(o, *x)),
            Column::F32(a) => {
                out.iter_mut().zip(a.slice(numpy::ndarray::s![start..start + n])).for_each(|(o, &x)| set(o, x))
            }
            Column::F64(a) => {
                out.iter_mut().zip(a.slice(numpy::ndarray::s![start..start + n])).for_each(|(o, &x)| set(o, x as f32))
            }
        }
    }
}

/// A per-ray parameter given as a Python number or an array: `Number` or `Array`.
pub enum ColumnArg<'py> {
    Number(f32),
    Array(RealArray<'py>),
}

/// `obj` (a number, a 0-d array or a `(K,)` array) as a per-ray parameter.
pub fn column_arg<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<ColumnArg<'py>> {
    if obj.is_instance_of::<PyBool>() {
        return Err(PyTypeError::new_err(format!("{name}: expected a number or an array of numbers, got a bool")));
    }
    if obj.is_instance_of::<PyFloat>() || obj.is_instance_of::<PyInt>() {
        return Ok(ColumnArg::Number(obj.extract::<f64>()? as f32));
    }
    let arr = real_array(obj, name)?;
    if arr.shape().is_empty() {
        let x = match arr.view() {
            RealView::F32(a) => *a.first().expect("0-d array has one element"),
            RealView::F64(a) => *a.first().expect("0-d array has one element") as f32,
        };
        return Ok(ColumnArg::Number(x));
    }
    Ok(ColumnArg::Array(arr))
}

/// A `ValueError` naming `name` (and the ray) for the first value below zero as the tracer
/// sees it (rounded to `f32`, so `-0.0` and a `-1e-50` that rounds to it are zero): a ray
/// covers `t` in `[tnear, tfar]` from its origin, as the `--rays` reader requires of files
/// (`0 <= tnear <= tfar`); NaN stays a ray that misses.
fn not_negative(column: &Column<'_>, name: &str) -> PyResult<()> {
    let first = match column {
        Column::Same(x) => (*x < 0.0).then(|| format!("{x}")),
        Column::F32(a) => a.iter().position(|&x| x < 0.0).map(|i| format!("{} for ray {i}", a[i])),
        Column::F64(a) => a.iter().position(|&x| (x as f32) < 0.0).map(|i| format!("{} for ray {i}", a[i])),
    };
    match first {
        None => Ok(()),
        Some(got) => Err(PyValueError::new_err(format!(
            "{name}: expected values >= 0 (t is measured from each ray's origin over [tnear, tfar]), got {got}"
        ))),
    }
}

/// The column of `arg`, checked to have `rays` values when it is an array (its values are
/// checked by [`not_negative`], once per query: [`RayArgs::rays`]).
fn column_unchecked<'a>(arg: &'a ColumnArg<'_>, name: &str, rays: usize) -> PyResult<Column<'a>> {
    match arg {
        ColumnArg::Number(x) => Ok(Column::Same(*x)),
        ColumnArg::Array(arr) => {
            let bad = || {
                PyValueError::new_err(format!(
                    "{name}: expected a number or shape ({rays},) (one per ray), got {}",
                    shape_str(arr.shape())
                ))
            };
            if arr.shape() != [rays] {
                return Err(bad());
            }
            Ok(match arr.view() {
                RealView::F32(a) => Column::F32(a.into_dimensionality::<Ix1>().map_err(|_| bad())?),
                RealView::F64(a) => Column::F64(a.into_dimensionality::<Ix1>().map_err(|_| bad())?),
            })
        }
    }
}

/// The rays of one query: origins, directions and their `[tnear, tfar]` intervals.
#[derive(Clone, Copy)]
pub struct Rays<'a> {
    pub origins: Points<'a>,
    pub directions: Points<'a>,
    pub tnear: Column<'a>,
    pub tfar: Column<'a>,
    /// Number of rays.
    pub len: usize,
}

impl Rays<'_> {
    /// Rays `start .. start + out.len()` into `out`. Contiguous and single-point origins and
    /// directions are read in one fused loop per layout pair (writing whole rays); other
    /// layouts and per-ray intervals are filled in a pass of their own.
    pub fn fill(&self, start: usize, out: &mut [Ray]) {
        let n = out.len();
        let (tnear, tfar) = match (self.tnear, self.tfar) {
            (Column::Same(a), Column::Same(b)) => (a, b),
            _ => (0.0, f32::INFINITY),
        };
        match (self.origins, self.directions) {
            (Points::Rows32(o), Points::Rows32(d)) => {
                let (o, d) = (&o[3 * start..3 * (start + n)], &d[3 * start..3 * (start + n)]);
                for ((r, o), d) in out.iter_mut().zip(o.chunks_exact(3)).zip(d.chunks_exact(3)) {
                    *r = Ray { origin: Vec3::new(o[0], o[1], o[2]), dir: Vec3::new(d[0], d[1], d[2]), tnear, tfar };
                }
            }
            (Points::Same(p), Points::Rows32(d)) => {
                let d = &d[3 * start..3 * (start + n)];
                for (r, d) in out.iter_mut().zip(d.chunks_exact(3)) {
                    *r = Ray { origin: p, dir: Vec3::new(d[0], d[1], d[2]), tnear, tfar };
                }
            }
            (Points::Rows64(o), Points::Rows64(d)) => {
                let (o, d) = (&o[3 * start..3 * (start + n)], &d[3 * start..3 * (start + n)]);
                for ((r, o), d) in out.iter_mut().zip(o.chunks_exact(3)).zip(d.chunks_exact(3)) {
                    let (o, d) = (
                        Vec3::new(o[0] as f32, o[1] as f32, o[2] as f32),
                        Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32),
                    );
                    *r = Ray { origin: o, dir: d, tnear, tfar };
                }
            }
            (o, d) => {
                for (j, r) in out.iter_mut().enumerate() {
                    *r = Ray { origin: o.get(start + j), dir: d.get(start + j), tnear, tfar };
                }
            }
        }
        if !matches!((self.tnear, self.tfar), (Column::Same(_), Column::Same(_))) {
            self.tnear.fill(start, out, |r, t| r.tnear = t);
            self.tfar.fill(start, out, |r, t| r.tfar = t);
        }
    }

    /// Ray `i`.
    #[inline(always)]
    pub fn get(&self, i: usize) -> Ray {
        Ray::segment(self.origins.get(i), self.directions.get(i), self.tnear.get(i), self.tfar.get(i))
    }
}

/// The arguments of a ray query, held (references to the caller's arrays) until the query
/// returns; their memory is read only through [`RayArgs::rays`], with the GIL held.
pub struct RayArgs<'py> {
    origins: RealArray<'py>,
    directions: RealArray<'py>,
    tnear: ColumnArg<'py>,
    tfar: ColumnArg<'py>,
}

impl<'py> RayArgs<'py> {
    /// The arguments of a query; `tnear` defaults to 0, `tfar` to infinity.
    pub fn new(
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        tnear: Option<&Bound<'py, PyAny>>,
        tfar: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Self> {
        Ok(Self {
            origins: real_array(origins, "origins")?,
            directions: real_array(directions, "directions")?,
            tnear: tnear.map_or(Ok(ColumnArg::Number(0.0)), |t| column_arg(t, "tnear"))?,
            tfar: tfar.map_or(Ok(ColumnArg::Number(f32::INFINITY)), |t| column_arg(t, "tfar"))?,
        })
    }

    /// The rays, with every count checked against the others and no `tnear` or `tfar` below
    /// zero: views of the arrays as they are now, for as long as this borrow (and the GIL)
    /// lasts.
    pub fn rays(&self) -> PyResult<Rays<'_>> {
        let rays = self.rays_of_pass()?;
        not_negative(&rays.tnear, "tnear")?;
        not_negative(&rays.tfar, "tfar")?;
        Ok(rays)
    }

    /// [`RayArgs::rays`] without the scan of `tnear` and `tfar` for values below zero: the
    /// views a query's later passes take afresh (`trace::passes`), once [`RayArgs::rays`]
    /// checked the values at its start.
    pub fn rays_of_pass(&self) -> PyResult<Rays<'_>> {
        let origins = points(&self.origins, "origins", true)?;
        let directions = points(&self.directions, "directions", true)?;
        let len = match (origins.rows(), directions.rows()) {
            (Some(a), Some(b)) if a != b => {
                return Err(PyValueError::new_err(format!(
                    "origins and directions: expected as many rows, got {a} origins and {b} directions"
                )));
            }
            (Some(n), _) | (None, Some(n)) => n,
            (None, None) => 1,
        };
        let tnear = column_unchecked(&self.tnear, "tnear", len)?;
        let tfar = column_unchecked(&self.tfar, "tfar", len)?;
        Ok(Rays { origins, directions, tnear, tfar, len })
    }
}

/// Vertices `(N, 3)` of real numbers, rounded to `f32`.
pub fn vertices(obj: &Bound<'_, PyAny>) -> PyResult<Vec<Vec3>> {
    let arr = real_array(obj, "vertices")?;
    let p = points(&arr, "vertices", false)?;
    Ok((0..p.rows().unwrap_or(0)).map(|i| p.get(i)).collect())
}

/// Faces `(M, 3)` of integers, each in `0 .. vertices`.
pub fn faces(obj: &Bound<'_, PyAny>, vertices: usize) -> PyResult<Vec<[u32; 3]>> {
    let arr = numpy_asarray(obj, "faces", "of integers")?;
    let dtype = arr.dtype();
    if !matches!(dtype.kind(), b'i' | b'u') {
        return Err(PyTypeError::new_err(format!("faces: expected an array of integers, got dtype {}", dtype.str()?)));
    }
    let shape = arr.shape().to_vec();
    if !matches!(shape.as_slice(), [_, 3]) {
        return Err(PyValueError::new_err(format!("faces: expected shape (M, 3), got {}", shape_str(&shape))));
    }
    // Indices are read as int64 (a copy only for other integer dtypes); uint64 above
    // i64::MAX wraps negative and is reported out of range below.
    let arr = match arr.cast::<PyArrayDyn<i64>>() {
        Ok(a) => a.clone(),
        Err(_) => arr.call_method1("astype", ("int64",))?.cast_into::<PyArrayDyn<i64>>()?,
    };
    let ro = arr.readonly();
    let view = ro.as_array().into_dimensionality::<Ix2>().expect("checked (M, 3)");
    let mut out = Vec::with_capacity(view.nrows());
    for (m, row) in view.rows().into_iter().enumerate() {
        let mut tri = [0u32; 3];
        for (k, &i) in row.iter().enumerate() {
            if i < 0 || i as u64 >= vertices as u64 {
                return Err(PyValueError::new_err(format!(
                    "faces[{m}] = [{}, {}, {}]: index {i} out of range for {vertices} vertices",
                    row[0], row[1], row[2]
                )));
            }
            tri[k] = i as u32;
        }
        out.push(tri);
    }
    Ok(out)
}

/// `obj` as a numpy array (no copy when it is one); `what` says what the array should hold.
fn numpy_asarray<'py>(obj: &Bound<'py, PyAny>, name: &str, what: &str) -> PyResult<Bound<'py, PyUntypedArray>> {
    if let Ok(a) = obj.cast::<PyUntypedArray>() {
        return Ok(a.clone());
    }
    let np = obj.py().import("numpy")?;
    np.call_method1("asarray", (obj,))
        .map_err(|e| PyTypeError::new_err(format!("{name}: expected an array {what} ({e})")))?
        .cast_into::<PyUntypedArray>()
        .map_err(|_| PyTypeError::new_err(format!("{name}: expected an array {what}")))
}
