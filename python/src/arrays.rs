//! numpy arrays in and out. Inputs: float64 or float32, 1-D (one channel)
//! or 2-D (samples × channels), any memory order; they are read in place
//! (no copy of the array) straight into the kernel's f32 inputs, the one
//! conversion `dynocomp compensate` also makes. Anything else is refused
//! with a message that says what to pass.

use numpy::ndarray::{Array2, ArrayViewD, Axis, ShapeBuilder};
use numpy::{
    PyArray1, PyArray2, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// A read-only borrow of a float64 or float32 array.
pub(crate) enum Samples<'py> {
    F64(PyReadonlyArrayDyn<'py, f64>),
    F32(PyReadonlyArrayDyn<'py, f32>),
}

/// A view of [`Samples`], which may cross into code that runs without
/// the GIL.
pub(crate) enum View<'a> {
    F64(ArrayViewD<'a, f64>),
    F32(ArrayViewD<'a, f32>),
}

impl<'py> Samples<'py> {
    /// Borrow `x` (named `what` in messages) as samples of force (N).
    pub(crate) fn borrow(x: &Bound<'py, PyAny>, what: &str) -> PyResult<Self> {
        if let Ok(a) = x.cast::<PyArrayDyn<f64>>() {
            return Samples::F64(a.readonly()).checked(what);
        }
        if let Ok(a) = x.cast::<PyArrayDyn<f32>>() {
            return Samples::F32(a.readonly()).checked(what);
        }
        if let Ok(a) = x.cast::<PyUntypedArray>() {
            let dtype = a.dtype().str().map(|s| s.to_string()).unwrap_or_else(|_| "?".into());
            return Err(PyTypeError::new_err(format!(
                "{what}: numpy array of dtype {dtype}; pass float64 or float32 (N), e.g. {what}.astype(numpy.float64)"
            )));
        }
        let ty = x.get_type().name().map(|s| s.to_string()).unwrap_or_else(|_| "?".into());
        Err(PyTypeError::new_err(format!(
            "{what}: a {ty}, not a numpy array; pass a float64 or float32 numpy array (N), \
             e.g. numpy.asarray({what}, dtype=float)"
        )))
    }

    fn checked(self, what: &str) -> PyResult<Self> {
        let shape = self.view().shape().to_vec();
        match shape.as_slice() {
            [_] => Ok(self),
            [_, k] if (1..=3).contains(k) => Ok(self),
            _ => Err(PyValueError::new_err(format!(
                "{what}: shape {shape:?}; pass (n,) for one channel \
                 or (n, k) with k = 1..3 channels (columns fx, fy, fz)"
            ))),
        }
    }

    pub(crate) fn view(&self) -> View<'_> {
        match self {
            Samples::F64(a) => View::F64(a.as_array()),
            Samples::F32(a) => View::F32(a.as_array()),
        }
    }
}

impl View<'_> {
    pub(crate) fn shape(&self) -> &[usize] {
        match self {
            View::F64(a) => a.shape(),
            View::F32(a) => a.shape(),
        }
    }

    /// Samples per channel.
    pub(crate) fn len(&self) -> usize {
        self.shape()[0]
    }

    /// Channels (1 for a 1-D array).
    pub(crate) fn channels(&self) -> usize {
        self.shape().get(1).copied().unwrap_or(1)
    }

    /// Each channel as the kernel's input (f32), with room for `extra`
    /// more samples.
    pub(crate) fn columns_f32(&self, extra: usize) -> Vec<Vec<f32>> {
        match self {
            View::F64(a) => columns(a, extra, |v| v as f32),
            View::F32(a) => columns(a, extra, |v| v),
        }
    }

    /// Each channel in f64.
    pub(crate) fn columns_f64(&self) -> Vec<Vec<f64>> {
        match self {
            View::F64(a) => columns(a, 0, |v| v),
            View::F32(a) => columns(a, 0, f64::from),
        }
    }
}

/// The channels of `a` (1-D: one), converted by `conv`, each with room for
/// `extra` more samples; a contiguous channel is read as a slice.
fn columns<T: Copy, U>(a: &ArrayViewD<'_, T>, extra: usize, conv: impl Fn(T) -> U) -> Vec<Vec<U>> {
    let n = a.shape()[0];
    let one = |col: numpy::ndarray::ArrayView1<'_, T>| {
        let mut v = Vec::with_capacity(n + extra);
        match col.as_slice() {
            Some(s) => v.extend(s.iter().map(|&x| conv(x))),
            None => v.extend(col.iter().map(|&x| conv(x))),
        }
        v
    };
    if a.ndim() == 1 {
        let col = a.view().into_dimensionality::<numpy::ndarray::Ix1>().expect("1-D");
        return vec![one(col)];
    }
    a.axis_iter(Axis(1)).map(|c| one(c.into_dimensionality().expect("2-D"))).collect()
}

/// Channels of `n` samples as an (n, k) float64 array in Fortran order
/// (each channel contiguous, one copy), or (n,) when `one_d`.
pub(crate) fn channels_to_array<'py>(py: Python<'py>, cols: &[Vec<f64>], n: usize, one_d: bool) -> Bound<'py, PyAny> {
    if one_d && cols.len() == 1 {
        return PyArray1::from_slice(py, &cols[0][..n]).into_any();
    }
    let refs: Vec<&[f64]> = cols.iter().map(|c| &c[..n]).collect();
    columns_to_array(py, &refs, n).into_any()
}

/// [`channels_to_array`] on borrowed channels, always 2-D.
pub(crate) fn columns_to_array<'py>(py: Python<'py>, cols: &[&[f64]], n: usize) -> Bound<'py, PyArray2<f64>> {
    let mut flat = Vec::with_capacity(n * cols.len());
    for c in cols {
        flat.extend_from_slice(&c[..n]);
    }
    let a = Array2::from_shape_vec((n, cols.len()).f(), flat).expect("n x k samples");
    PyArray2::from_owned_array(py, a)
}
