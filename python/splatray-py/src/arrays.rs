//! numpy arrays in, checked before any work: the dtype and shape asked
//! for, every value finite, at least one row; each failure a `TypeError`
//! or `ValueError` naming the argument. Arrays out: owned copies.

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// What `obj` is, for a message: `float32 array of shape (5, 2)`, or its
/// Python type.
fn describe(obj: &Bound<'_, PyAny>) -> String {
    if let Ok(a) = obj.cast::<numpy::PyUntypedArray>() {
        let shape: Vec<String> = a.shape().iter().map(|d| d.to_string()).collect();
        let shape = if shape.len() == 1 {
            format!("({},)", shape[0])
        } else {
            format!("({})", shape.join(", "))
        };
        format!(
            "{} array of shape {shape}",
            a.dtype()
                .str()
                .map_or_else(|_| "?".into(), |s| s.to_string())
        )
    } else {
        obj.get_type()
            .name()
            .map_or_else(|_| "an object".into(), |n| format!("a {n}"))
    }
}

/// A float dtype rows are read as; the other float dtype is converted.
pub trait Real: numpy::Element + Copy {
    /// The dtypes taken, this one first, for messages.
    const DTYPES: &'static str;
    /// The other float dtype.
    type Other: numpy::Element + Copy;
    /// `x` of the other dtype as this one.
    fn from_other(x: Self::Other) -> Self;
    /// Neither NaN nor infinite.
    fn finite(self) -> bool;
}

impl Real for f64 {
    const DTYPES: &'static str = "float64 or float32";
    type Other = f32;
    fn from_other(x: f32) -> f64 {
        f64::from(x)
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
}

impl Real for f32 {
    const DTYPES: &'static str = "float32 or float64";
    type Other = f64;
    #[allow(clippy::cast_possible_truncation)]
    fn from_other(x: f64) -> f32 {
        x as f32
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
}

/// The rows of an (N, `cols`) float64 or float32 array as `T`, row-major.
/// `empty_ok`: zero rows allowed.
pub fn rows<T: Real>(
    obj: &Bound<'_, PyAny>,
    name: &str,
    cols: usize,
    empty_ok: bool,
) -> PyResult<Vec<T>> {
    let v: Vec<T> = if let Ok(a) = obj.extract::<PyReadonlyArray2<'_, T>>() {
        check_cols(&a, obj, name, cols, T::DTYPES)?;
        match a.as_slice() {
            Ok(s) => s.to_vec(),
            Err(_) => a.as_array().iter().copied().collect(),
        }
    } else if let Ok(a) = obj.extract::<PyReadonlyArray2<'_, T::Other>>() {
        check_cols(&a, obj, name, cols, T::DTYPES)?;
        a.as_array().iter().map(|&x| T::from_other(x)).collect()
    } else {
        return Err(PyTypeError::new_err(format!(
            "{name} must be a {} numpy array of shape (N, {cols}), got {}",
            T::DTYPES,
            describe(obj)
        )));
    };
    finish(v, name, cols, empty_ok, T::finite)
}

fn check_cols<T: numpy::Element>(
    a: &PyReadonlyArray2<'_, T>,
    obj: &Bound<'_, PyAny>,
    name: &str,
    cols: usize,
    dtypes: &str,
) -> PyResult<()> {
    if a.shape()[1] != cols {
        return Err(PyValueError::new_err(format!(
            "{name} must be a {dtypes} array of shape (N, {cols}), got {}",
            describe(obj)
        )));
    }
    Ok(())
}

fn finish<T: Copy>(
    v: Vec<T>,
    name: &str,
    cols: usize,
    empty_ok: bool,
    ok: impl Fn(T) -> bool,
) -> PyResult<Vec<T>> {
    if v.is_empty() && !empty_ok {
        return Err(PyValueError::new_err(format!("{name} is empty: no rows")));
    }
    if let Some(i) = v.iter().position(|&x| !ok(x)) {
        return Err(PyValueError::new_err(format!(
            "{name}: row {} holds a NaN or infinite value",
            i / cols
        )));
    }
    Ok(v)
}

/// The rows of an (N, `cols`) integer array (int32, int64, uint32 or
/// uint64) as `i64`, row-major (a uint64 beyond `i64::MAX` is read as
/// `i64::MAX`: out of any range). Zero rows are an error.
pub fn index_rows(obj: &Bound<'_, PyAny>, name: &str, cols: usize) -> PyResult<Vec<i64>> {
    const DTYPES: &str = "int32, int64, uint32 or uint64";
    fn read<T: numpy::Element + Copy>(
        obj: &Bound<'_, PyAny>,
        name: &str,
        cols: usize,
        to: impl Fn(T) -> i64,
    ) -> Option<PyResult<Vec<i64>>> {
        let a = obj.extract::<PyReadonlyArray2<'_, T>>().ok()?;
        Some(
            check_cols(&a, obj, name, cols, DTYPES)
                .map(|()| a.as_array().iter().map(|&x| to(x)).collect()),
        )
    }
    let v = read::<i64>(obj, name, cols, |x| x)
        .or_else(|| read::<i32>(obj, name, cols, i64::from))
        .or_else(|| read::<u32>(obj, name, cols, i64::from))
        .or_else(|| read::<u64>(obj, name, cols, |x| i64::try_from(x).unwrap_or(i64::MAX)))
        .unwrap_or_else(|| {
            Err(PyTypeError::new_err(format!(
                "{name} must be an {DTYPES} numpy array of shape (N, {cols}), got {}",
                describe(obj)
            )))
        })?;
    finish(v, name, cols, false, |_| true)
}

/// An (N, 3) array of vectors.
pub fn vec3s<'py>(
    py: Python<'py>,
    v: impl ExactSizeIterator<Item = [f32; 3]>,
) -> Bound<'py, PyAny> {
    let n = v.len();
    let flat: Vec<f32> = v.flatten().collect();
    Array2::from_shape_vec((n, 3), flat)
        .expect("n rows of 3")
        .into_pyarray(py)
        .into_any()
}

/// An (N, C) array.
pub fn matrix<'py, T: numpy::Element>(
    py: Python<'py>,
    cols: usize,
    flat: Vec<T>,
) -> Bound<'py, PyAny> {
    let n = flat.len() / cols.max(1);
    Array2::from_shape_vec((n, cols), flat)
        .expect("whole rows")
        .into_pyarray(py)
        .into_any()
}

/// An (H, W) image plane.
pub fn plane<'py, T: numpy::Element>(
    py: Python<'py>,
    h: usize,
    w: usize,
    flat: Vec<T>,
) -> Bound<'py, PyAny> {
    Array2::from_shape_vec((h, w), flat)
        .expect("h rows of w")
        .into_pyarray(py)
        .into_any()
}

/// An (H, W, 3) image.
pub fn image<'py>(py: Python<'py>, h: usize, w: usize, flat: Vec<f32>) -> Bound<'py, PyAny> {
    Array3::from_shape_vec((h, w, 3), flat)
        .expect("h rows of w pixels of 3")
        .into_pyarray(py)
        .into_any()
}

/// An (N,) array.
pub fn vector<'py, T: numpy::Element>(py: Python<'py>, v: Vec<T>) -> Bound<'py, PyAny> {
    Array1::from_vec(v).into_pyarray(py).into_any()
}

/// Three finite numbers (a viewpoint, a point), from any sequence.
pub fn point3(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 3]> {
    let v: Vec<f64> = obj.extract().map_err(|_| {
        PyTypeError::new_err(format!(
            "{name} must be three numbers, got {}",
            describe(obj)
        ))
    })?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(PyValueError::new_err(format!(
            "{name} must be three finite numbers, got {v:?}"
        ))),
    }
}
