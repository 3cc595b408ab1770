//! Line segment detection: LSD, FLD and our own edge-drawing detector behind one trait.

use crate::{
    DetectorKind, EdgeLinesOptions, FldOptions, FrontendConfig, GrayImage, LineOptions, LsdOptions,
    LsdRefine, OpenCvContext, VisionError,
};
use linetrack_edge_lines::GrayView;
use linetrack_frontend_core::EdgeLinesSegments;
use linetrack_geometry::Segment;
use opencv::core::{Ptr, Vec4f, Vector};
use opencv::imgproc::{self, LineSegmentDetector, LineSegmentDetectorTrait};
use opencv::ximgproc::{self, FastLineDetector, FastLineDetectorTrait};

/// Images narrower or lower than this (pixels) have no segments worth detecting; the
/// detectors return none instead of asking OpenCV (FLD asserts on tiny images). The rule
/// of `linetrack-frontend-core`, which `edgelines` runs through.
pub const MIN_IMAGE_SIDE_PX: i32 = linetrack_frontend_core::MIN_IMAGE_SIDE_PX as i32;

/// A line segment detector.
pub trait LineDetector: Send {
    /// Short name: `lsd`, `fld` or `edgelines`.
    fn name(&self) -> &'static str;

    /// Detects segments in `image`, replacing the contents of `out` with the kept ones:
    /// clipped to the image, at least `min_length_px` long, at most `max_segments`,
    /// longest first. Images smaller than [`MIN_IMAGE_SIDE_PX`] give none.
    fn detect(&mut self, image: &GrayImage, out: &mut Vec<Segment>) -> Result<(), VisionError>;
}

/// Builds the detector `kind` with its options from `config`.
pub fn create_detector(
    kind: DetectorKind,
    config: &FrontendConfig,
) -> Result<Box<dyn LineDetector>, VisionError> {
    Ok(match kind {
        DetectorKind::Lsd => Box::new(LsdDetector::new(&config.lsd, config.lines)?),
        DetectorKind::Fld => Box::new(FldDetector::new(&config.fld, config.lines)?),
        DetectorKind::EdgeLines => {
            Box::new(EdgeLinesDetector::new(&config.edgelines, config.lines))
        }
    })
}

/// LSD through OpenCV's imgproc.
pub struct LsdDetector {
    lsd: Ptr<LineSegmentDetector>,
    lines: Vector<Vec4f>,
    keep: LineOptions,
}

impl LsdDetector {
    /// An LSD with `options`, keeping segments by `keep`.
    pub fn new(options: &LsdOptions, keep: LineOptions) -> Result<Self, VisionError> {
        let refine = match options.refine {
            LsdRefine::None => imgproc::LSD_REFINE_NONE,
            LsdRefine::Standard => imgproc::LSD_REFINE_STD,
            LsdRefine::Advanced => imgproc::LSD_REFINE_ADV,
        };
        let lsd = imgproc::create_line_segment_detector(
            refine,
            options.scale,
            options.sigma_scale,
            options.quant,
            options.angle_tolerance_deg,
            options.log_eps,
            options.density_threshold,
            options.bins,
        )
        .context("creating the LSD detector")?;
        Ok(Self {
            lsd,
            lines: Vector::new(),
            keep,
        })
    }
}

impl LineDetector for LsdDetector {
    fn name(&self) -> &'static str {
        "lsd"
    }

    fn detect(&mut self, image: &GrayImage, out: &mut Vec<Segment>) -> Result<(), VisionError> {
        let lsd = &mut self.lsd;
        detect_with(image, &mut self.lines, self.keep, out, |lines| {
            let (mut no_width, mut no_precision, mut no_nfa) = (
                opencv::core::no_array(),
                opencv::core::no_array(),
                opencv::core::no_array(),
            );
            lsd.detect(
                image.mat(),
                lines,
                &mut no_width,
                &mut no_precision,
                &mut no_nfa,
            )
            .context("LSD detection")
        })
    }
}

/// FLD through OpenCV's ximgproc.
pub struct FldDetector {
    fld: Ptr<FastLineDetector>,
    lines: Vector<Vec4f>,
    keep: LineOptions,
}

impl FldDetector {
    /// An FLD with `options`, keeping segments by `keep`.
    pub fn new(options: &FldOptions, keep: LineOptions) -> Result<Self, VisionError> {
        let fld = ximgproc::create_fast_line_detector(
            options.length_threshold_px,
            options.distance_threshold_px,
            options.canny_low,
            options.canny_high,
            options.canny_aperture,
            options.merge,
        )
        .context("creating the FLD detector")?;
        Ok(Self {
            fld,
            lines: Vector::new(),
            keep,
        })
    }
}

impl LineDetector for FldDetector {
    fn name(&self) -> &'static str {
        "fld"
    }

    fn detect(&mut self, image: &GrayImage, out: &mut Vec<Segment>) -> Result<(), VisionError> {
        let fld = &mut self.fld;
        detect_with(image, &mut self.lines, self.keep, out, |lines| {
            fld.detect(image.mat(), lines).context("FLD detection")
        })
    }
}

/// Our own detector (`linetrack-edge-lines`): no OpenCV call, the pixels read in place,
/// through `linetrack-frontend-core` (the Python bindings' code path too).
pub struct EdgeLinesDetector {
    detector: EdgeLinesSegments,
    /// Rows copied out of a non-continuous image (a region of a larger one); unused for
    /// decoded and borrowed images, which are continuous.
    copy: Vec<u8>,
}

impl EdgeLinesDetector {
    /// The detector with `options`, keeping segments by `keep`.
    pub fn new(options: &EdgeLinesOptions, keep: LineOptions) -> Self {
        Self {
            detector: EdgeLinesSegments::new(options, keep),
            copy: Vec::new(),
        }
    }
}

impl LineDetector for EdgeLinesDetector {
    fn name(&self) -> &'static str {
        "edgelines"
    }

    fn detect(&mut self, image: &GrayImage, out: &mut Vec<Segment>) -> Result<(), VisionError> {
        out.clear();
        // A GrayImage is never empty: the casts are exact.
        let (width, height) = (image.width() as usize, image.height() as usize);
        let pixels = image.packed_pixels(&mut self.copy)?;
        let view =
            GrayView::packed(pixels, width, height).map_err(|source| VisionError::EdgeLines {
                origin: image.origin().to_string(),
                source,
            })?;
        self.detector.detect(view, out);
        Ok(())
    }
}

/// What every detector does around its OpenCV call `run`: start empty, skip images under
/// [`MIN_IMAGE_SIDE_PX`], then keep the longest segments clipped to the pixel centres'
/// range [0, width − 1] × [0, height − 1].
fn detect_with(
    image: &GrayImage,
    lines: &mut Vector<Vec4f>,
    keep: LineOptions,
    out: &mut Vec<Segment>,
    run: impl FnOnce(&mut Vector<Vec4f>) -> Result<(), VisionError>,
) -> Result<(), VisionError> {
    lines.clear();
    out.clear();
    if image.width() < MIN_IMAGE_SIDE_PX || image.height() < MIN_IMAGE_SIDE_PX {
        return Ok(());
    }
    run(lines)?;
    let bounds = (f64::from(image.width() - 1), f64::from(image.height() - 1));
    keep_longest(lines, keep, bounds, out);
    Ok(())
}

/// Converts OpenCV's `(x0, y0, x1, y1)` lines into `out`: clipped to [0, max_x] × [0, max_y],
/// at least `min_length_px` long, longest first, at most `max_segments`. Reuses `out`'s
/// allocation.
pub fn keep_longest(
    lines: &Vector<Vec4f>,
    keep: LineOptions,
    (max_x, max_y): (f64, f64),
    out: &mut Vec<Segment>,
) {
    out.clear();
    out.extend(
        lines
            .iter()
            .map(|l| {
                Segment::from_coords(
                    f64::from(l[0]),
                    f64::from(l[1]),
                    f64::from(l[2]),
                    f64::from(l[3]),
                )
            })
            .filter_map(|s| s.clipped_to(max_x, max_y))
            .filter(|s| s.is_finite() && s.length() >= keep.min_length_px),
    );
    let longest_first = |a: &Segment, b: &Segment| b.length().total_cmp(&a.length());
    if out.len() > keep.max_segments {
        if keep.max_segments == 0 {
            out.clear();
            return;
        }
        out.select_nth_unstable_by(keep.max_segments - 1, longest_first);
        out.truncate(keep.max_segments);
    }
    out.sort_by(longest_first);
}
