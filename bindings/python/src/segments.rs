//! Segments between numpy and Rust: `(N, 4)` arrays of `x0, y0, x1, y1` rows, float32 or
//! float64, any strides, into [`Segment`]s (refused when a coordinate is NaN or infinite,
//! naming the row); segments back as `(N, 4)` float32.

use crate::arrays;
use linetrack_geometry::Segment;
use numpy::ndarray::{Array2, ArrayView2};
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray2};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// Reads the segment array argument `name`.
pub fn from_array(name: &str, object: &Bound<'_, PyAny>) -> PyResult<Vec<Segment>> {
    let described = arrays::describe(name, object, "of shape (N, 4) (x0, y0, x1, y1 per row)")?;
    if described.shape.len() != 2 || described.shape[1] != 4 {
        return Err(PyValueError::new_err(format!(
            "{name} has shape {}: expected (N, 4), one segment x0, y0, x1, y1 per row",
            arrays::shape_text(&described.shape)
        )));
    }
    let segments = if described.is(b'f', 4) {
        collect(object.extract::<PyReadonlyArray2<f32>>()?.as_array())
    } else if described.is(b'f', 8) {
        collect(object.extract::<PyReadonlyArray2<f64>>()?.as_array())
    } else {
        return Err(PyTypeError::new_err(format!(
            "{name} has dtype {}: expected float32 or float64",
            described.dtype
        )));
    };
    if let Some((row, s)) = segments.iter().enumerate().find(|(_, s)| !s.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "{name}[{row}] = [{}, {}, {}, {}]: a coordinate is not finite",
            s.start.x, s.start.y, s.end.x, s.end.y
        )));
    }
    Ok(segments)
}

fn collect<T: Copy + Into<f64>>(rows: ArrayView2<'_, T>) -> Vec<Segment> {
    rows.rows()
        .into_iter()
        .map(|r| Segment::from_coords(r[0].into(), r[1].into(), r[2].into(), r[3].into()))
        .collect()
}

/// `segments` as an `(N, 4)` float32 array.
pub fn to_array<'py>(py: Python<'py>, segments: &[Segment]) -> Bound<'py, PyArray2<f32>> {
    let mut rows = Array2::<f32>::zeros((segments.len(), 4));
    for (mut row, s) in rows.rows_mut().into_iter().zip(segments) {
        // The detector's coordinates are f32 values to begin with (clipping to the image
        // leaves them as they are): the narrowing is exact.
        for (cell, value) in row.iter_mut().zip([s.start.x, s.start.y, s.end.x, s.end.y]) {
            *cell = value as f32;
        }
    }
    rows.into_pyarray(py)
}
