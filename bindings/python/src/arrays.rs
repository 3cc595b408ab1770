//! What every array argument goes through first: it is a numpy array, and its dtype is in
//! this machine's byte order. Errors name the argument.

use numpy::{PyArrayDescrMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;

/// An array argument's shape and dtype (its kind character, item size and name).
pub struct Described {
    /// The shape.
    pub shape: Vec<usize>,
    /// numpy's kind character: `b'u'` unsigned, `b'f'` floating point, …
    pub kind: u8,
    /// Bytes per item.
    pub itemsize: usize,
    /// The dtype as numpy prints it.
    pub dtype: String,
}

impl Described {
    /// Whether the items are of `kind` and `itemsize` bytes.
    pub fn is(&self, kind: u8, itemsize: usize) -> bool {
        self.kind == kind && self.itemsize == itemsize
    }
}

/// The argument `name`, refused unless a numpy array (`what` says which in the message) in
/// native byte order.
pub fn describe(name: &str, object: &Bound<'_, PyAny>, what: &str) -> PyResult<Described> {
    let array = object.cast::<PyUntypedArray>().map_err(|_| {
        let type_name = object
            .get_type()
            .name()
            .map_or_else(|_| "?".to_string(), |n| n.to_string());
        PyTypeError::new_err(format!(
            "{name} must be a numpy.ndarray {what}, got {type_name}"
        ))
    })?;
    let dtype = array.dtype();
    let described = Described {
        shape: array.shape().to_vec(),
        kind: dtype.kind(),
        itemsize: dtype.itemsize(),
        dtype: dtype
            .str()
            .map_or_else(|_| "?".to_string(), |s| s.to_string()),
    };
    if dtype.is_native_byteorder() == Some(false) {
        return Err(PyTypeError::new_err(format!(
            "{name} has dtype {}, not in this machine's byte order: convert it first \
             (a.astype(a.dtype.newbyteorder('=')))",
            described.dtype
        )));
    }
    Ok(described)
}

/// A shape as numpy prints it: `(480, 752)`, `(10,)`.
pub fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}
