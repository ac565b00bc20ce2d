//! Reading numpy arguments: shapes and dtypes checked with errors that name the argument,
//! arrays of float32 / float64 read in place whatever their strides (others converted once).

use numpy::ndarray::{ArrayView1, ArrayView2, Ix1, Ix2};
use numpy::{
    PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyFloat, PyInt};
use raypack::{Ray, Vec3};

/// A numpy array of real numbers as the caller gave it (float32 or float64, any strides), or
/// converted once to float64 from another real dtype (integers, float16, other byte orders,
/// unaligned memory).
pub enum RealArray<'py> {
    F32(PyReadonlyArrayDyn<'py, f32>),
    F64(PyReadonlyArrayDyn<'py, f64>),
}

/// `obj` as an array of real numbers; `name` names the argument in errors.
pub fn real_array<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<RealArray<'py>> {
    let arr = numpy_asarray(obj, name, "of real numbers")?;
    let dtype = arr.dtype();
    // Unaligned arrays (views into packed records) and other byte orders are converted.
    let native = dtype.is_native_byteorder() != Some(false) && arr.is_aligned();
    match (dtype.kind(), dtype.itemsize(), native) {
        (b'f', 4, true) => Ok(RealArray::F32(arr.cast::<PyArrayDyn<f32>>()?.readonly())),
        (b'f', 8, true) => Ok(RealArray::F64(arr.cast::<PyArrayDyn<f64>>()?.readonly())),
        (b'f' | b'i' | b'u', _, _) => {
            let converted = arr.call_method1("astype", ("float64",))?.cast_into::<PyArrayDyn<f64>>()?;
            Ok(RealArray::F64(converted.readonly()))
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
    match shape {
        [_, 3] => Ok(match arr {
            // `to_slice`: only row-major (C-contiguous) arrays, not Fortran-ordered ones.
            RealArray::F32(a) => match a.as_array().to_slice() {
                Some(rows) => Points::Rows32(rows),
                None => Points::Strided32(a.as_array().into_dimensionality::<Ix2>().map_err(|_| bad())?),
            },
            RealArray::F64(a) => match a.as_array().to_slice() {
                Some(rows) => Points::Rows64(rows),
                None => Points::Strided64(a.as_array().into_dimensionality::<Ix2>().map_err(|_| bad())?),
            },
        }),
        [3] if one_allowed => {
            let p = match arr {
                RealArray::F32(a) => {
                    let a = a.as_array();
                    Vec3::new(a[[0]], a[[1]], a[[2]])
                }
                RealArray::F64(a) => {
                    let a = a.as_array();
                    Vec3::new(a[[0]] as f32, a[[1]] as f32, a[[2]] as f32)
                }
            };
            Ok(Points::Same(p))
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
        let x = match &arr {
            RealArray::F32(a) => *a.as_array().first().expect("0-d array has one element"),
            RealArray::F64(a) => *a.as_array().first().expect("0-d array has one element") as f32,
        };
        return Ok(ColumnArg::Number(x));
    }
    Ok(ColumnArg::Array(arr))
}

/// The column of `arg`, checked to have `rays` values when it is an array and no value below
/// zero ([`not_negative`]).
pub fn column<'a>(arg: &'a ColumnArg<'_>, name: &str, rays: usize) -> PyResult<Column<'a>> {
    let column = column_unchecked(arg, name, rays)?;
    not_negative(&column, name)?;
    Ok(column)
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
            Ok(match arr {
                RealArray::F32(a) => Column::F32(a.as_array().into_dimensionality::<Ix1>().map_err(|_| bad())?),
                RealArray::F64(a) => Column::F64(a.as_array().into_dimensionality::<Ix1>().map_err(|_| bad())?),
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

/// The arguments of a ray query, owned (borrowed from Python) until the query returns.
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

    /// The rays, with every count checked against the others.
    pub fn rays(&self) -> PyResult<Rays<'_>> {
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
        let tnear = column(&self.tnear, "tnear", len)?;
        let tfar = column(&self.tfar, "tfar", len)?;
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
