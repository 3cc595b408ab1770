//! A line segment detector in plain Rust, the front end's fastest: no OpenCV, the 8-bit
//! pixels read in place (a shared-memory frame is never copied), every buffer kept in the
//! detector and reused, so a warm detector allocates nothing per frame.
//!
//! The method follows edge drawing (EDLines, Akinlar & Topal 2011) with the line fitted
//! while the edge is drawn (ELSED, Suárez et al. 2022); the code is ours:
//!
//! 1. **Smoothing and gradient** ([`gradient`]): a 5×5 binomial blur, then Sobel; each
//!    pixel keeps `|gx| + |gy|` and whether its edge runs vertically (`|gx| ≥ |gy|`). Plain
//!    loops over whole rows in 16-bit integers, which the compiler vectorises.
//! 2. **Anchors**: pixels whose gradient exceeds both neighbours across the edge by
//!    `anchor_threshold`, looked for on every `scan_interval`-th row for edges running
//!    vertically and every `scan_interval`-th column for edges running horizontally (so no
//!    edge is missed for lying between scanned lines); visited strongest first (a counting
//!    sort).
//! 3. **Drawing** ([`draw`]): from each anchor, walk both ways along the gradient ridge,
//!    each step to the strongest of the three pixels ahead, until the gradient drops under
//!    `gradient_threshold` or the walk meets an edge already drawn.
//! 4. **Fitting** ([`fit`]): each pixel's position is refined across the edge (a parabola
//!    through the gradient), then least-squares lines are grown along the chain and cut
//!    where pixels leave the line by more than `max_fit_error_px` for longer than
//!    `max_outlier_run` pixels.
//! 5. **Validation**: a segment is kept when at least `min_aligned_fraction` of its pixels
//!    have a gradient across it (within 22.5°) of the same sign; that sign orients it
//!    (LSD's convention: walking from start to end, the darker side is on the right in
//!    image coordinates, i.e. the gradient points to the left).
//! 6. **Selection**: at least `min_length_px` long, the `max_segments` longest, longest
//!    first; endpoints are the end pixels projected onto the fitted line (sub-pixel).
//!
//! Pixel centres are at integer coordinates, as in OpenCV: a segment lies within
//! `[0, width − 1] × [0, height − 1]`. Nothing panics on any image: blank, saturated,
//! tiny (1×1, 2×N), noise (tested).

#![warn(missing_docs)]

mod draw;
mod fit;
mod gradient;

#[cfg(test)]
mod tests;

use thiserror::Error;

/// Largest image the detector takes, pixels (its pixel indices are 32-bit).
pub const MAX_PIXELS: usize = u32::MAX as usize;

/// Errors in describing an image to the detector.
#[derive(Debug, Clone, Error, PartialEq, Eq)]
pub enum EdgeLinesError {
    /// The pixel slice does not hold `height` rows of `stride` bytes (the last row `width`).
    #[error(
        "{len} bytes cannot hold a {width}×{height} image with rows {stride} bytes apart \
         (need a stride ≥ width and (height − 1) × stride + width bytes)"
    )]
    Size {
        /// Bytes given.
        len: usize,
        /// Width, pixels.
        width: usize,
        /// Height, pixels.
        height: usize,
        /// Bytes from one row to the next.
        stride: usize,
    },
    /// More pixels than [`MAX_PIXELS`].
    #[error("a {width}×{height} image has more than {MAX_PIXELS} pixels")]
    TooLarge {
        /// Width, pixels.
        width: usize,
        /// Height, pixels.
        height: usize,
    },
}

/// An 8-bit grayscale image the detector reads in place: `height` rows of `width` pixels,
/// rows `stride` bytes apart.
#[derive(Debug, Clone, Copy)]
pub struct GrayView<'a> {
    pixels: &'a [u8],
    width: usize,
    height: usize,
    stride: usize,
}

impl<'a> GrayView<'a> {
    /// A view of `pixels`, checked to hold the image and to have at most [`MAX_PIXELS`]
    /// pixels (an empty image, 0 wide or high, is allowed and has no segments).
    pub fn new(
        pixels: &'a [u8],
        width: usize,
        height: usize,
        stride: usize,
    ) -> Result<Self, EdgeLinesError> {
        let error = EdgeLinesError::Size {
            len: pixels.len(),
            width,
            height,
            stride,
        };
        if stride < width {
            return Err(error);
        }
        let needed = match height {
            0 => 0,
            h => (h - 1)
                .checked_mul(stride)
                .and_then(|n| n.checked_add(width))
                .ok_or(error.clone())?,
        };
        if pixels.len() < needed {
            return Err(error);
        }
        if width.checked_mul(height).is_none_or(|n| n > MAX_PIXELS) {
            return Err(EdgeLinesError::TooLarge { width, height });
        }
        Ok(Self {
            pixels,
            width,
            height,
            stride,
        })
    }

    /// A view of tightly packed rows (`stride = width`).
    pub fn packed(pixels: &'a [u8], width: usize, height: usize) -> Result<Self, EdgeLinesError> {
        Self::new(pixels, width, height, width)
    }

    /// Width, pixels.
    #[inline]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height, pixels.
    #[inline]
    pub fn height(&self) -> usize {
        self.height
    }

    /// Bytes from one row to the next.
    #[inline]
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The pixels: `height` rows `stride` bytes apart (the last one `width` long at least).
    #[inline]
    pub fn pixels(&self) -> &'a [u8] {
        self.pixels
    }

    /// Row `y` (its `width` pixels). Panics unless `y < height`.
    #[inline]
    pub fn row(&self, y: usize) -> &'a [u8] {
        &self.pixels[y * self.stride..y * self.stride + self.width]
    }
}

/// A detected segment, pixel coordinates (pixel centres at integers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineSegment {
    /// First endpoint `[x, y]`.
    pub start: [f32; 2],
    /// Second endpoint `[x, y]`; from `start` to `end` the gradient points to the left.
    pub end: [f32; 2],
}

impl LineSegment {
    /// Length, pixels.
    pub fn length(&self) -> f32 {
        (self.end[0] - self.start[0]).hypot(self.end[1] - self.start[1])
    }
}

/// The detector's parameters. Gradient thresholds are in the units of a 3×3 Sobel
/// (`|gx| + |gy|`, at most 2040) on the smoothed 8-bit image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Pixels whose gradient is below this are not edges.
    pub gradient_threshold: u16,
    /// An anchor's gradient exceeds both neighbours across the edge by at least this.
    pub anchor_threshold: u16,
    /// Anchors of vertical edges are looked for on every this-th row, of horizontal edges
    /// on every this-th column (0 counts as 1).
    pub scan_interval: usize,
    /// A pixel further than this from the fitted line is an outlier, pixels.
    pub max_fit_error_px: f32,
    /// A segment ends after more than this many outliers in a row.
    pub max_outlier_run: usize,
    /// Segments shorter than this are dropped, pixels.
    pub min_length_px: f32,
    /// At most this many segments are kept, the longest.
    pub max_segments: usize,
    /// A segment is kept when at least this fraction of its pixels have a gradient across it
    /// (within 22.5°) with the majority's sign.
    pub min_aligned_fraction: f32,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            gradient_threshold: 16,
            anchor_threshold: 8,
            scan_interval: 2,
            max_fit_error_px: 1.0,
            max_outlier_run: 3,
            min_length_px: 15.0,
            max_segments: 100,
            min_aligned_fraction: 0.7,
        }
    }
}

/// The detector: its parameters and every buffer, reused from frame to frame.
#[derive(Debug, Default)]
pub struct EdgeLineDetector {
    params: Params,
    /// Gradient planes of the last image.
    planes: gradient::Planes,
    /// Anchors and chains.
    drawing: draw::Drawing,
    /// Chain points and the fitted segments.
    fitting: fit::Fitting,
}

impl EdgeLineDetector {
    /// A detector with `params`.
    pub fn new(params: Params) -> Self {
        Self {
            params,
            ..Self::default()
        }
    }

    /// The parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Detects segments in `image`, replacing the contents of `out`: at least
    /// `min_length_px` long, at most `max_segments`, longest first. Images under 3 pixels
    /// wide or high have none.
    pub fn detect(&mut self, image: GrayView<'_>, out: &mut Vec<LineSegment>) {
        out.clear();
        if image.width < gradient::MIN_SIDE_PX || image.height < gradient::MIN_SIDE_PX {
            return;
        }
        self.planes.compute(image);
        let candidates = &mut self.fitting.candidates;
        candidates.clear();
        self.drawing.anchors(&self.planes, &self.params);
        let Self {
            params,
            planes,
            drawing,
            fitting,
        } = self;
        drawing.draw_all(planes, params, |planes, chain| {
            fitting.fit_chain(planes, params, chain)
        });
        fitting.keep_longest(params, out);
    }
}
