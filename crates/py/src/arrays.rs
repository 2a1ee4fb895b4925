//! Conversions between numpy arrays and the core's vectors, with shape checks that name the
//! argument.

use nalgebra::Vector3;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::errors::{raise, Kind};

/// An (n, 3) float64 array from 3-vectors.
pub fn vectors_to_py<'py>(py: Python<'py>, vectors: &[Vector3<f64>]) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((vectors.len(), 3), |(i, j)| vectors[i][j]).into_pyarray(py)
}

/// A (3,) float64 array.
pub fn vector_to_py<'py>(py: Python<'py>, v: &Vector3<f64>) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_slice(py, v.as_slice())
}

/// 3-vectors from an (n, 3) array; `n` must be `rows` when given.
pub fn vectors_from_py(
    name: &str,
    array: &PyReadonlyArray2<'_, f64>,
    rows: Option<usize>,
) -> PyResult<Vec<Vector3<f64>>> {
    let view = array.as_array();
    let shape = view.shape();
    if shape[1] != 3 || rows.is_some_and(|r| r != shape[0]) {
        let expected = rows.map_or("(n, 3)".to_string(), |r| format!("({r}, 3)"));
        return Err(raise(
            Kind::State,
            format!("`{name}` has shape {shape:?}, expected {expected}"),
        ));
    }
    Ok(view
        .rows()
        .into_iter()
        .map(|r| Vector3::new(r[0], r[1], r[2]))
        .collect())
}

/// A 3-vector from a (3,) array.
pub fn vector_from_py(name: &str, array: &PyReadonlyArray1<'_, f64>) -> PyResult<Vector3<f64>> {
    let view = array.as_array();
    if view.len() != 3 {
        return Err(raise(
            Kind::State,
            format!("`{name}` has length {}, expected 3", view.len()),
        ));
    }
    let v = Vector3::new(view[0], view[1], view[2]);
    if !v.iter().all(|x| x.is_finite()) {
        return Err(raise(
            Kind::State,
            format!("`{name}` = {:?} must be finite", v.as_slice()),
        ));
    }
    Ok(v)
}

/// A float vector of length `len` from a 1-D array.
pub fn floats_from_py(
    name: &str,
    array: &PyReadonlyArray1<'_, f64>,
    len: usize,
) -> PyResult<Vec<f64>> {
    let view = array.as_array();
    if view.len() != len {
        return Err(raise(
            Kind::State,
            format!("`{name}` has length {}, expected {len}", view.len()),
        ));
    }
    Ok(view.to_vec())
}
