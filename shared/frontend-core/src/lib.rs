//! The OpenCV-free half of the front end, one code path for two callers: the OpenCV front
//! end (`linetrack-vision`, behind every tool and pipeline stage) and the Python bindings
//! (`bindings/python`), which cannot link OpenCV. What both run here gives the same
//! segments for the same pixels by construction:
//!
//! - [`LineOptions`] and [`EdgeLinesOptions`]: the `[lines]` and `[edgelines]` tables of
//!   `configs/frontend.toml`, with their range checks ([`InvalidField`]);
//! - [`EdgeLinesSegments`]: `linetrack-edge-lines` on an 8-bit view, its segments clipped
//!   to the pixel centres' range as [`Segment`]s, nothing for images under
//!   [`MIN_IMAGE_SIDE_PX`].
//!
//! The ℓ1 matcher's image step (row profiles) is `L1Matcher::describe` in
//! `linetrack-l1-matcher`, shared the same way.
#![warn(missing_docs)]

mod options;

#[cfg(test)]
mod tests;

pub use linetrack_edge_lines::{EdgeLinesError, GrayView};
pub use options::{EdgeLinesOptions, InvalidField, LineOptions};

use linetrack_edge_lines::{EdgeLineDetector, LineSegment};
use linetrack_geometry::Segment;

/// Images narrower or lower than this (pixels) have no segments worth detecting; the
/// detectors return none (OpenCV's FLD asserts on tiny images, so every detector of the
/// front end keeps this rule).
pub const MIN_IMAGE_SIDE_PX: usize = 8;

/// The `edgelines` detector with its buffers, giving clipped [`Segment`]s.
#[derive(Debug)]
pub struct EdgeLinesSegments {
    detector: EdgeLineDetector,
    found: Vec<LineSegment>,
}

impl EdgeLinesSegments {
    /// The detector with `options`, keeping segments by `keep`.
    pub fn new(options: &EdgeLinesOptions, keep: LineOptions) -> Self {
        Self {
            detector: EdgeLineDetector::new(options.params(keep)),
            found: Vec::new(),
        }
    }

    /// The detector's parameters.
    pub fn params(&self) -> &linetrack_edge_lines::Params {
        self.detector.params()
    }

    /// Replaces `out` with the segments of `image`: longest first, clipped to
    /// `[0, width − 1] × [0, height − 1]`, finite. None when a side is under
    /// [`MIN_IMAGE_SIDE_PX`].
    pub fn detect(&mut self, image: GrayView<'_>, out: &mut Vec<Segment>) {
        out.clear();
        self.found.clear();
        let (width, height) = (image.width(), image.height());
        if width < MIN_IMAGE_SIDE_PX || height < MIN_IMAGE_SIDE_PX {
            return;
        }
        self.detector.detect(image, &mut self.found);
        let bounds = ((width - 1) as f64, (height - 1) as f64);
        out.extend(
            self.found
                .iter()
                .map(|s| {
                    Segment::from_coords(
                        f64::from(s.start[0]),
                        f64::from(s.start[1]),
                        f64::from(s.end[0]),
                        f64::from(s.end[1]),
                    )
                })
                .filter_map(|s| s.clipped_to(bounds.0, bounds.1))
                .filter(|s| s.is_finite()),
        );
    }
}
