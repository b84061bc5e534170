//! numpy arrays in and out: (N, 3) inputs checked and read as rows, outputs built without a
//! copy.

use crate::errors::invalid;
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

/// The rows of an (N, 3) float array (C-contiguous; the Python layer makes it so), or a
/// `ValueError` naming `what` and the shape.
pub fn rows3(a: &PyReadonlyArray2<'_, f64>, what: &str) -> PyResult<Vec<[f64; 3]>> {
    let shape = a.shape();
    if shape[1] != 3 {
        return Err(invalid(format!(
            "{what} must have shape (N, 3), got ({}, {})",
            shape[0], shape[1]
        )));
    }
    let s = a
        .as_slice()
        .map_err(|_| invalid(format!("{what} must be a C-contiguous array")))?;
    Ok(s.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// An (N, 3) float array of rows.
pub fn f64_n3<'py>(py: Python<'py>, v: Vec<[f64; 3]>) -> Bound<'py, PyArray2<f64>> {
    let n = v.len();
    let flat: Vec<f64> = v.into_iter().flatten().collect();
    Array2::from_shape_vec((n, 3), flat)
        .expect("n rows of 3")
        .into_pyarray(py)
}

/// An (N, 3) integer array of rows.
pub fn i64_n3<'py>(py: Python<'py>, v: Vec<[i64; 3]>) -> Bound<'py, PyArray2<i64>> {
    let n = v.len();
    let flat: Vec<i64> = v.into_iter().flatten().collect();
    Array2::from_shape_vec((n, 3), flat)
        .expect("n rows of 3")
        .into_pyarray(py)
}

/// An (N, 3, 3) float array of matrices (row-major).
pub fn f64_n33<'py>(py: Python<'py>, v: Vec<[[f64; 3]; 3]>) -> Bound<'py, PyArray3<f64>> {
    let n = v.len();
    let flat: Vec<f64> = v.into_iter().flatten().flatten().collect();
    Array3::from_shape_vec((n, 3, 3), flat)
        .expect("n matrices of 3 x 3")
        .into_pyarray(py)
}

/// A 1-D array.
pub fn vec1<'py, T: numpy::Element>(py: Python<'py>, v: Vec<T>) -> Bound<'py, PyArray1<T>> {
    Array1::from_vec(v).into_pyarray(py)
}
