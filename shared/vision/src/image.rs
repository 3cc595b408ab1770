//! Checked 8-bit grayscale images and the photometric perturbation.

use crate::{OpenCvContext, VisionError};
use opencv::core::{self, Mat, MatTraitConst, MatTraitConstManual, Vector};
use opencv::{imgcodecs, imgproc};
use std::path::Path;

/// The paragraph on which images are read that ends the `--help` of every tool reading
/// images (a macro so that `concat!` can join it to a tool's own text).
#[macro_export]
macro_rules! images_help {
    () => {
        "IMAGES: grey or colour (colour converted to grey once, 0.299 R + 0.587 G + 0.114 B), 8- or
16-bit (scaled to 8 bits over the full range: v × 255 / 65535, or v × 255 / maxval for a
PGM/PPM); two-channel and floating-point images are refused naming the file."
    };
}

/// Largest image file read, bytes (512 MiB).
pub const MAX_FILE_BYTES: u64 = 512 << 20;

/// Largest image decoded, pixels (100 megapixels).
pub const MAX_PIXELS: u64 = 100_000_000;

/// An 8-bit, single-channel, non-empty image, with where it came from for error messages.
#[derive(Debug)]
pub struct GrayImage {
    mat: Mat,
    origin: String,
}

impl Clone for GrayImage {
    fn clone(&self) -> Self {
        Self {
            mat: self.mat.clone(),
            origin: self.origin.clone(),
        }
    }
}

impl GrayImage {
    /// Reads and decodes an image file; every error names the file. Only a regular file of
    /// at most [`MAX_FILE_BYTES`] is read (not a device, a FIFO or a folder).
    pub fn load(path: &Path) -> Result<Self, VisionError> {
        let read_error = |reason| VisionError::Read {
            path: path.to_path_buf(),
            reason,
        };
        let metadata = std::fs::metadata(path).map_err(read_error)?;
        if !metadata.is_file() {
            return Err(read_error(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a regular file",
            )));
        }
        if metadata.len() > MAX_FILE_BYTES {
            return Err(VisionError::TooLarge {
                origin: path.display().to_string(),
                what: format!("{} bytes, more than {MAX_FILE_BYTES}", metadata.len()),
            });
        }
        let bytes = std::fs::read(path).map_err(read_error)?;
        Self::decode(&bytes, &path.display().to_string())
    }

    /// Decodes an encoded image (PNG, JPEG, PGM, …) held in memory. Colour images (BGR or
    /// BGRA) are converted to grey once, by OpenCV's luminance weights (0.299 R + 0.587 G +
    /// 0.114 B); 16-bit images are scaled to 8 bits over their full range (value × 255 /
    /// 65535: PNG and TIFF store 16-bit samples at full scale). A PGM or PPM says its own
    /// full scale (its maxval, e.g. 4095 for 12-bit data), which OpenCV does not apply: it
    /// is scaled by value × 255 / maxval instead, at 8 bits too. Other pixel formats
    /// (float, two channels) are refused naming what was found.
    pub fn decode(bytes: &[u8], origin: &str) -> Result<Self, VisionError> {
        if bytes.is_empty() {
            return Err(VisionError::Empty {
                origin: origin.to_string(),
            });
        }
        // Refuse an oversized image from its header, before decoding allocates it (for the
        // formats the header reader knows; OpenCV's own limit covers the others).
        if let Ok((width, height)) = image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|_| ())
            .and_then(|reader| reader.into_dimensions().map_err(|_| ()))
            && u64::from(width) * u64::from(height) > MAX_PIXELS
        {
            return Err(VisionError::TooLarge {
                origin: origin.to_string(),
                what: format!("{width}×{height} pixels, more than {MAX_PIXELS}"),
            });
        }
        if let Some(mat) = crate::png_gray::decode_gray8_png(bytes, origin)? {
            return Self::from_mat(mat, origin);
        }
        let buffer = Vector::<u8>::from_slice(bytes);
        // OpenCV reports some corrupt inputs as exceptions and others as an empty Mat.
        let mat = imgcodecs::imdecode(&buffer, imgcodecs::IMREAD_UNCHANGED).map_err(|_| {
            VisionError::Decode {
                origin: origin.to_string(),
            }
        })?;
        if mat.empty() {
            return Err(VisionError::Decode {
                origin: origin.to_string(),
            });
        }
        Self::from_mat(to_gray8(mat, pnm_maxval(bytes))?, origin)
    }

    /// Wraps a Mat after checking it is 8-bit, single-channel and not empty.
    pub fn from_mat(mat: Mat, origin: &str) -> Result<Self, VisionError> {
        if mat.empty() || mat.rows() == 0 || mat.cols() == 0 {
            return Err(VisionError::Empty {
                origin: origin.to_string(),
            });
        }
        if mat.channels() != 1 || mat.depth() != core::CV_8U {
            let depth = core::depth_to_string(mat.depth())
                .ok()
                .unwrap_or_else(|| "unknown depth".to_string());
            return Err(VisionError::Format {
                origin: origin.to_string(),
                channels: mat.channels(),
                depth,
            });
        }
        Ok(Self {
            mat,
            origin: origin.to_string(),
        })
    }

    /// An image from row-major 8-bit pixels.
    pub fn from_pixels(
        width: usize,
        height: usize,
        pixels: &[u8],
        origin: &str,
    ) -> Result<Self, VisionError> {
        if width == 0 || height == 0 || pixels.len() != width * height {
            return Err(VisionError::RawSize {
                origin: origin.to_string(),
                len: pixels.len(),
                width,
                height,
            });
        }
        let flat = Mat::from_slice(pixels).context("wrapping pixels")?;
        let rows = i32::try_from(height).map_err(|_| VisionError::RawSize {
            origin: origin.to_string(),
            len: pixels.len(),
            width,
            height,
        })?;
        let shaped = flat.reshape(1, rows).context("shaping pixels")?;
        let mut owned = Mat::default();
        shaped.copy_to(&mut owned).context("copying pixels")?;
        Self::from_mat(owned, origin)
    }

    /// A view of row-major 8-bit pixels that the image does not own (a shared-memory
    /// sample, say): read in place, never copied. The view cannot outlive `pixels`.
    pub fn borrow_pixels<'a>(
        width: usize,
        height: usize,
        pixels: &'a [u8],
        origin: &str,
    ) -> Result<BorrowedGray<'a>, VisionError> {
        let bad_size = || VisionError::RawSize {
            origin: origin.to_string(),
            len: pixels.len(),
            width,
            height,
        };
        if width == 0
            || height == 0
            || pixels.len() != width.checked_mul(height).ok_or_else(bad_size)?
        {
            return Err(bad_size());
        }
        let (rows, cols) = (
            i32::try_from(height).map_err(|_| bad_size())?,
            i32::try_from(width).map_err(|_| bad_size())?,
        );
        // SAFETY: the Mat header points at `pixels`, which hold exactly rows × cols bytes
        // (checked above) and outlive the returned view (its lifetime is `'a`). A header
        // built on foreign data has no reference count, so dropping it never frees
        // `pixels`. The view hands out only `&GrayImage`, through which OpenCV is given
        // the Mat as input only; a clone copies the pixels into a Mat of its own.
        #[allow(unsafe_code)]
        let mat = unsafe {
            Mat::new_rows_cols_with_data_unsafe_def(
                rows,
                cols,
                core::CV_8UC1,
                pixels.as_ptr().cast::<std::ffi::c_void>().cast_mut(),
            )
        }
        .context("wrapping borrowed pixels")?;
        Ok(BorrowedGray {
            image: Self::from_mat(mat, origin)?,
            _pixels: std::marker::PhantomData,
        })
    }

    /// Makes this image a copy of `other` (pixels and origin), reusing this image's buffer
    /// when the sizes agree: no allocation for a stream of same-sized frames.
    pub fn copy_from(&mut self, other: &GrayImage) -> Result<(), VisionError> {
        other
            .mat
            .copy_to(&mut self.mat)
            .context("copying an image")?;
        self.origin.clone_from(&other.origin);
        Ok(())
    }

    /// The underlying OpenCV matrix (CV_8UC1).
    pub fn mat(&self) -> &Mat {
        &self.mat
    }

    /// Where the image came from (file path or a description).
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// Width in pixels.
    pub fn width(&self) -> i32 {
        self.mat.cols()
    }

    /// Height in pixels.
    pub fn height(&self) -> i32 {
        self.mat.rows()
    }

    /// The pixels, row-major, when the matrix is continuous (it is for decoded images).
    pub fn pixels(&self) -> Option<&[u8]> {
        self.mat.data_bytes().ok()
    }

    /// The pixels, row-major and packed: the image's own when the matrix is continuous,
    /// else a copy made in `copy` (its buffer reused).
    pub fn packed_pixels<'a>(&'a self, copy: &'a mut Vec<u8>) -> Result<&'a [u8], VisionError> {
        if let Some(pixels) = self.pixels() {
            return Ok(pixels);
        }
        copy.clear();
        for row in 0..self.height() {
            let row = self
                .mat
                .at_row::<u8>(row)
                .context("reading a row of a non-continuous image")?;
            copy.extend_from_slice(row);
        }
        Ok(copy)
    }

    /// Errs unless `other` has the same size, naming both images.
    pub fn ensure_same_size(&self, other: &GrayImage) -> Result<(), VisionError> {
        if (self.width(), self.height()) == (other.width(), other.height()) {
            return Ok(());
        }
        Err(VisionError::SizeMismatch {
            first: self.origin.clone(),
            first_size: (self.width(), self.height()),
            second: other.origin.clone(),
            second_size: (other.width(), other.height()),
        })
    }
}

/// The maxval of a PGM or PPM file (its samples' full scale), `None` for other formats and
/// for bitmaps (PBM, which OpenCV already reads as 0 and 255).
fn pnm_maxval(bytes: &[u8]) -> Option<u32> {
    use image::codecs::pnm::{PnmDecoder, PnmSubtype};
    if !bytes.starts_with(b"P") {
        return None;
    }
    let decoder = PnmDecoder::new(std::io::Cursor::new(bytes)).ok()?;
    let header = decoder.header();
    match header.subtype() {
        PnmSubtype::Graymap(_) | PnmSubtype::Pixmap(_) => Some(header.maximal_sample()),
        PnmSubtype::Bitmap(_) | PnmSubtype::ArbitraryMap => None,
    }
}

/// The order of a colour image's channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelOrder {
    /// Blue, green, red (OpenCV's, image files').
    Bgr,
    /// Red, green, blue (ROS `rgb8`).
    Rgb,
}

/// `mat` as 8-bit grey: colour converted by luminance, 16 bits scaled to 8 (over
/// `full_scale` when the file gives one, else over 65535), 8 bits with a smaller full scale
/// stretched to 255; anything else (float pixels, two channels) is returned unchanged for
/// [`GrayImage::from_mat`] to refuse.
fn to_gray8(mat: Mat, full_scale: Option<u32>) -> Result<Mat, VisionError> {
    to_gray8_ordered(mat, full_scale, ChannelOrder::Bgr)
}

/// [`to_gray8`] for colour channels in `order` (the conversion of every input: files,
/// ROS image messages).
pub fn to_gray8_ordered(
    mat: Mat,
    full_scale: Option<u32>,
    order: ChannelOrder,
) -> Result<Mat, VisionError> {
    let scale = match (mat.depth(), full_scale) {
        (core::CV_8U, Some(full)) if (1..255).contains(&full) => Some(255.0 / f64::from(full)),
        (core::CV_8U, _) => None,
        (core::CV_16U, Some(full)) if full >= 1 => Some(255.0 / f64::from(full)),
        (core::CV_16U, _) => Some(255.0 / 65535.0),
        _ => return Ok(mat),
    };
    let eight_bit = match scale {
        Some(scale) => {
            let mut scaled = Mat::default();
            mat.convert_to(&mut scaled, core::CV_8U, scale, 0.0)
                .context("scaling the image to 8 bits")?;
            scaled
        }
        None => mat,
    };
    let code = match (eight_bit.channels(), order) {
        (3, ChannelOrder::Bgr) => imgproc::COLOR_BGR2GRAY,
        (3, ChannelOrder::Rgb) => imgproc::COLOR_RGB2GRAY,
        (4, ChannelOrder::Bgr) => imgproc::COLOR_BGRA2GRAY,
        (4, ChannelOrder::Rgb) => imgproc::COLOR_RGBA2GRAY,
        _ => return Ok(eight_bit),
    };
    let mut gray = Mat::default();
    imgproc::cvt_color_def(&eight_bit, &mut gray, code)
        .context("converting a colour image to grey")?;
    Ok(gray)
}

/// A [`GrayImage`] reading pixels it does not own; see [`GrayImage::borrow_pixels`].
#[derive(Debug)]
pub struct BorrowedGray<'a> {
    image: GrayImage,
    _pixels: std::marker::PhantomData<&'a [u8]>,
}

impl std::ops::Deref for BorrowedGray<'_> {
    type Target = GrayImage;

    fn deref(&self) -> &GrayImage {
        &self.image
    }
}

/// The photometric perturbation of the paper's evaluation: `I' = clamp(gain·I + bias)` to
/// [0, 255], rounding to the nearest level.
pub fn perturb(image: &GrayImage, gain: f64, bias: f64) -> Result<GrayImage, VisionError> {
    if !(gain.is_finite() && gain >= 0.0) {
        return Err(VisionError::Perturbation(format!(
            "gain must be finite and >= 0, got {gain}"
        )));
    }
    if !bias.is_finite() {
        return Err(VisionError::Perturbation(format!(
            "bias must be finite, got {bias}"
        )));
    }
    let mut out = Mat::default();
    // convert_to with the same depth saturates, which is the clamp.
    image
        .mat
        .convert_to(&mut out, -1, gain, bias)
        .context("applying gain and bias")?;
    Ok(GrayImage {
        mat: out,
        origin: format!("{} (gain {gain}, bias {bias})", image.origin),
    })
}

/// A dark or flat image stretched to the full grey range, as an automatic gain would:
/// `I' = clamp(gain·(I − low))` with `low` the 0.5th percentile and `gain` mapping the 99.5th
/// to 255, at most `max_gain`; with the gain it applied. `None` when the image already
/// spans the range (gain below 1.1) or `max_gain` is at most 1: the caller then keeps the
/// original.
///
/// Detectors threshold absolute gradients (LSD's gradient magnitude, FAST's intensity
/// difference), so a scene with its lights dimmed loses most of its segments and corners
/// although its edges are all still there; the stretch is affine, so geometry-based
/// matching is unaffected by it and descriptors see a more similar image.
pub fn stretch_contrast(
    image: &GrayImage,
    max_gain: f64,
) -> Result<Option<(GrayImage, f64)>, VisionError> {
    let mut out = None;
    let gain = stretch_contrast_into(image, max_gain, &mut out)?;
    Ok(out.zip(gain))
}

/// [`stretch_contrast`] into `out`, whose pixels are reused when it holds an image of the
/// same size (none is allocated then): the gain, or `None` where the image is kept as it is
/// (`out` is then left as it was).
pub fn stretch_contrast_into(
    image: &GrayImage,
    max_gain: f64,
    out: &mut Option<GrayImage>,
) -> Result<Option<f64>, VisionError> {
    let Some((gain, low)) = stretch_gain(image, max_gain)? else {
        return Ok(None);
    };
    let stretched = out.get_or_insert_with(|| GrayImage {
        mat: Mat::default(),
        origin: String::new(),
    });
    if let Err(e) = image
        .mat
        .convert_to(&mut stretched.mat, -1, gain, -gain * low)
        .context("stretching the contrast")
    {
        // Whatever the failed call left is not an image.
        *out = None;
        return Err(e);
    }
    stretched.origin.clear();
    stretched.origin.push_str(&image.origin);
    Ok(Some(gain))
}

/// [`stretch_contrast`] into a buffer kept from one call to the next: a stage stretching
/// every frame allocates no image for it once warm.
#[derive(Debug, Default)]
pub struct ContrastStretch {
    stretched: Option<GrayImage>,
}

impl ContrastStretch {
    /// A stretch with no buffer yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// `image` stretched as [`stretch_contrast`] does, in the kept buffer, or `image`
    /// itself where that returns `None`.
    pub fn apply<'a>(
        &'a mut self,
        image: &'a GrayImage,
        max_gain: f64,
    ) -> Result<&'a GrayImage, VisionError> {
        Ok(
            match stretch_contrast_into(image, max_gain, &mut self.stretched)? {
                Some(_) => self.stretched.as_ref().unwrap_or(image),
                None => image,
            },
        )
    }
}

/// The gain and the low level of [`stretch_contrast`], `None` where it keeps the image.
fn stretch_gain(image: &GrayImage, max_gain: f64) -> Result<Option<(f64, f64)>, VisionError> {
    const TAIL: f64 = 0.005;
    const MIN_GAIN: f64 = 1.1;
    if !(max_gain > 1.0) {
        return Ok(None);
    }
    // Four histograms filled in turn, summed after: runs of equal pixels (flat image
    // regions) then do not wait on one counter's previous increment.
    let mut partial = [[0usize; 256]; 4];
    let mut total = 0usize;
    for row in 0..image.mat.rows() {
        let pixels = image.mat.at_row::<u8>(row).context("reading a row")?;
        let mut quads = pixels.chunks_exact(4);
        for q in &mut quads {
            for (h, &v) in partial.iter_mut().zip(q) {
                h[usize::from(v)] += 1;
            }
        }
        for &v in quads.remainder() {
            partial[0][usize::from(v)] += 1;
        }
        total += pixels.len();
    }
    let mut histogram = [0usize; 256];
    for (level, count) in histogram.iter_mut().enumerate() {
        *count = partial.iter().map(|h| h[level]).sum();
    }
    let tail = (TAIL * total as f64) as usize;
    let percentile = |from_top: bool| {
        let mut seen = 0;
        for k in 0..256 {
            let level = if from_top { 255 - k } else { k };
            seen += histogram[level];
            if seen > tail {
                return level as f64;
            }
        }
        if from_top { 0.0 } else { 255.0 }
    };
    let (low, high) = (percentile(false), percentile(true));
    let gain = (255.0 / (high - low).max(1.0)).min(max_gain);
    if gain < MIN_GAIN {
        return Ok(None);
    }
    Ok(Some((gain, low)))
}
