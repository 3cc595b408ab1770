//! numpy images as 8-bit grey views: a 2-D `uint8` array read in place (rows may be
//! strided, as in a crop `a[y0:y1, x0:x1]`), anything else that can be read copied once
//! (`uint16` scaled to 8 bits, v × 255 / 65535 rounded, as the Rust tools read 16-bit
//! files; columns not adjacent in memory, negative strides). Everything else is refused
//! with a message naming the argument, its shape or its dtype.

use crate::arrays;
use numpy::PyReadonlyArray2;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// The pixels of one image: borrowed from the array, or copied and packed.
pub enum Pixels<'py> {
    /// Read in place: rows `stride` bytes apart.
    Borrowed {
        /// Keeps the array alive and marked as read-only borrowed from Rust.
        array: PyReadonlyArray2<'py, u8>,
        /// Bytes from one row to the next.
        stride: usize,
    },
    /// Copied into tightly packed rows.
    Owned(Vec<u8>),
}

/// An image argument, checked: at least one pixel, 8 bits after conversion.
pub struct Image<'py> {
    pixels: Pixels<'py>,
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
}

impl Image<'_> {
    /// The pixels from the first row's start to the last row's end, and the stride.
    pub fn rows(&self) -> (&[u8], usize) {
        match &self.pixels {
            Pixels::Owned(pixels) => (pixels, self.width),
            Pixels::Borrowed { array, stride } => {
                let view = array.as_array();
                let len = (self.height - 1) * stride + self.width;
                // SAFETY: `view` is an (height, width) array of bytes with a column stride
                // of 1 and a row stride of `stride` >= width (checked in `from_array`), so
                // the `len` bytes from its first element to its last one lie in the one
                // buffer numpy allocated for it (a numpy array is always a window on one
                // block). The read-only borrow (`PyReadonlyArray2`) keeps Rust writers
                // away for as long as `self` lives; the caller is told not to write the
                // array from another Python thread during the call.
                #[allow(unsafe_code)]
                let bytes = unsafe { std::slice::from_raw_parts(view.as_ptr(), len) };
                (bytes, *stride)
            }
        }
    }

    /// The shape as numpy prints it.
    pub fn shape(&self) -> (usize, usize) {
        (self.height, self.width)
    }
}

/// Checks and reads the image argument `name`.
pub fn from_array<'py>(name: &str, object: &Bound<'py, PyAny>) -> PyResult<Image<'py>> {
    let described = arrays::describe(name, object, "(height, width) of uint8 or uint16")?;
    let shape = &described.shape;
    let (height, width) = match shape[..] {
        [height, width] => (height, width),
        [_, _, channels] => {
            return Err(PyValueError::new_err(format!(
                "{name} has shape {}: {channels} channels, expected a grey image \
                 (height, width); convert colour to grey first",
                arrays::shape_text(shape)
            )));
        }
        _ => {
            return Err(PyValueError::new_err(format!(
                "{name} has shape {}: expected a 2-D grey image (height, width)",
                arrays::shape_text(shape)
            )));
        }
    };
    if height == 0 || width == 0 {
        return Err(PyValueError::new_err(format!(
            "{name} has shape {}: an empty image",
            arrays::shape_text(shape)
        )));
    }
    let pixels = if described.is(b'u', 1) {
        let array = object.extract::<PyReadonlyArray2<'py, u8>>()?;
        let view = array.as_array();
        let strides = view.strides();
        let row_stride = usize::try_from(strides[0]).ok().filter(|&s| s >= width);
        match row_stride {
            Some(stride) if strides[1] == 1 || width == 1 => {
                // A single column is read with stride 1 whatever numpy says.
                Pixels::Borrowed { array, stride }
            }
            _ => Pixels::Owned(view.iter().copied().collect()),
        }
    } else if described.is(b'u', 2) {
        let array = object.extract::<PyReadonlyArray2<'py, u16>>()?;
        Pixels::Owned(array.as_array().iter().map(|&v| to_8_bits(v)).collect())
    } else {
        return Err(PyTypeError::new_err(format!(
            "{name} has dtype {}: expected uint8 or uint16",
            described.dtype
        )));
    };
    Ok(Image {
        pixels,
        width,
        height,
    })
}

/// A 16-bit sample at 8 bits: v × 255 / 65535 to the nearest (never a tie: 65535 = 255 × 257
/// and 257 is odd).
fn to_8_bits(v: u16) -> u8 {
    // At most 255 by construction: the cast is exact.
    ((u32::from(v) * 255 + 32767) / 65535) as u8
}
