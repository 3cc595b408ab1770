//! LBD descriptors (OpenCV line_descriptor) computed on segments found by any detector.

use crate::{BinaryDescriptors, GrayImage, OpenCvContext, VisionError};
use linetrack_geometry::Segment;
use opencv::core::{Mat, MatTraitConst, Point2f, Ptr, Vector};
use opencv::line_descriptor::{BinaryDescriptor, BinaryDescriptorTraitConst, KeyLine};

/// Bytes of one LBD descriptor (256 bits).
pub const LBD_BYTES: usize = 32;

/// Computes LBD descriptors for given segments; keeps its buffers.
pub struct LbdExtractor {
    descriptor: Ptr<BinaryDescriptor>,
    keylines: Vector<KeyLine>,
    raw: Mat,
}

impl LbdExtractor {
    /// An extractor with OpenCV's default LBD parameters.
    pub fn new() -> Result<Self, VisionError> {
        let descriptor =
            BinaryDescriptor::create_binary_descriptor().context("creating the LBD descriptor")?;
        Ok(Self {
            descriptor,
            keylines: Vector::new(),
            raw: Mat::default(),
        })
    }

    /// Fills `out` with one descriptor per segment (row k for `segments[k]`). Segments that
    /// are degenerate or leave the image after clipping get no descriptor.
    pub fn compute(
        &mut self,
        image: &GrayImage,
        segments: &[Segment],
        out: &mut BinaryDescriptors,
    ) -> Result<(), VisionError> {
        self.compute_some(image, segments, |_| true, out)
    }

    /// [`LbdExtractor::compute`] for the segments `k` where `wanted(k)`; the others get no
    /// descriptor. A segment's descriptor depends on the image and that segment alone, so
    /// each one computed is the one [`LbdExtractor::compute`] gives (tested).
    pub fn compute_some(
        &mut self,
        image: &GrayImage,
        segments: &[Segment],
        wanted: impl Fn(usize) -> bool,
        out: &mut BinaryDescriptors,
    ) -> Result<(), VisionError> {
        out.reset(segments.len(), LBD_BYTES);
        self.keylines.clear();
        let (w, h) = (image.width() as f32, image.height() as f32);
        for (k, segment) in segments.iter().enumerate() {
            if !wanted(k) {
                continue;
            }
            if let Some(keyline) = keyline_for(segment, k, w, h) {
                self.keylines.push(keyline);
            }
        }
        if self.keylines.is_empty() {
            return Ok(());
        }
        self.descriptor
            .compute(image.mat(), &mut self.keylines, &mut self.raw, false)
            .context("computing LBD descriptors")?;
        // OpenCV may drop keylines; each descriptor row belongs to the keyline at the same
        // position, whose class_id is the segment index.
        let rows = self
            .raw
            .rows()
            .min(i32::try_from(self.keylines.len()).unwrap_or(i32::MAX));
        for row in 0..rows {
            let keyline = self
                .keylines
                .get(row as usize)
                .context("reading a keyline")?;
            let Ok(segment_index) = usize::try_from(keyline.class_id) else {
                continue;
            };
            out.set_from_mat(segment_index, &self.raw, row)?;
        }
        Ok(())
    }
}

/// The octave-0 KeyLine of a segment clipped to the image, tagged with its index.
fn keyline_for(segment: &Segment, index: usize, width: f32, height: f32) -> Option<KeyLine> {
    if !segment.is_finite() {
        return None;
    }
    let clamp = |v: f64, max: f32| (v as f32).clamp(0.0, max - 1.0);
    let (sx, sy) = (
        clamp(segment.start.x, width),
        clamp(segment.start.y, height),
    );
    let (ex, ey) = (clamp(segment.end.x, width), clamp(segment.end.y, height));
    let (dx, dy) = (ex - sx, ey - sy);
    let length = (dx * dx + dy * dy).sqrt();
    if length < 2.0 {
        return None;
    }
    Some(KeyLine {
        angle: dy.atan2(dx),
        class_id: i32::try_from(index).ok()?,
        octave: 0,
        pt: Point2f::new((sx + ex) / 2.0, (sy + ey) / 2.0),
        response: length / width.max(height),
        size: (dx * dy).abs(),
        start_point_x: sx,
        start_point_y: sy,
        end_point_x: ex,
        end_point_y: ey,
        s_point_in_octave_x: sx,
        s_point_in_octave_y: sy,
        e_point_in_octave_x: ex,
        e_point_in_octave_y: ey,
        line_length: length,
        num_of_pixels: dx.abs().max(dy.abs()).round() as i32 + 1,
    })
}
