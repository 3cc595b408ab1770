//! Our own points (`linetrack-corners`: oriented FAST corners, steered binary descriptor,
//! no OpenCV) behind the same output as OpenCV's ORB, and [`PointExtractor`], the
//! extractor chosen by name.

use super::OrbExtractor;
use crate::{GrayImage, OrbOptions, PointExtractorKind, PointFeatures, VisionError};
use linetrack_corners::{CornerExtractor, Corners, GrayView};
use linetrack_geometry::Point;

/// Our own oriented FAST corners and their descriptors, written as [`PointFeatures`];
/// keeps its buffers.
pub struct FastBriefExtractor {
    extractor: CornerExtractor,
    corners: Corners,
    /// The pixels of a non-continuous image, packed.
    copy: Vec<u8>,
}

impl FastBriefExtractor {
    /// An extractor with the settings of `options`.
    pub fn new(options: &OrbOptions) -> Result<Self, VisionError> {
        let params = options
            .fast_brief_params()
            .map_err(|source| VisionError::Corners {
                origin: "[orb] settings".to_string(),
                source,
            })?;
        let extractor = CornerExtractor::new(params).map_err(|source| VisionError::Corners {
            origin: "[orb] settings".to_string(),
            source,
        })?;
        Ok(Self {
            extractor,
            corners: Corners::default(),
            copy: Vec::new(),
        })
    }

    /// Detects and describes points in `image` into `out`.
    pub fn extract(
        &mut self,
        image: &GrayImage,
        out: &mut PointFeatures,
    ) -> Result<(), VisionError> {
        // A GrayImage is never empty: the casts are exact.
        let (width, height) = (image.width() as usize, image.height() as usize);
        let pixels = image.packed_pixels(&mut self.copy)?;
        let view =
            GrayView::packed(pixels, width, height).map_err(|source| VisionError::PointImage {
                origin: image.origin().to_string(),
                source,
            })?;
        self.extractor.extract(view, &mut self.corners);
        let corners = &self.corners;
        out.points.clear();
        out.points.extend(
            corners
                .corners
                .iter()
                .map(|c| Point::new(f64::from(c.x), f64::from(c.y))),
        );
        out.levels.clear();
        out.levels.extend(corners.corners.iter().map(|c| c.level));
        out.descriptors
            .reset(corners.len(), linetrack_corners::DESCRIPTOR_BYTES);
        for (row, descriptor) in corners.descriptors.iter().enumerate() {
            out.descriptors.set_row(row, descriptor);
        }
        Ok(())
    }
}

/// The point extractor chosen by [`OrbOptions::extractor`].
pub enum PointExtractor {
    /// OpenCV's ORB.
    OrbOpenCv(OrbExtractor),
    /// Our own corners (`linetrack-corners`).
    FastBrief(Box<FastBriefExtractor>),
}

impl PointExtractor {
    /// The extractor `options` name, with its settings.
    pub fn new(options: &OrbOptions) -> Result<Self, VisionError> {
        Ok(match options.extractor {
            PointExtractorKind::OrbOpenCv => Self::OrbOpenCv(OrbExtractor::new(options)?),
            PointExtractorKind::FastBrief => {
                Self::FastBrief(Box::new(FastBriefExtractor::new(options)?))
            }
        })
    }

    /// Which extractor this is.
    pub fn kind(&self) -> PointExtractorKind {
        match self {
            Self::OrbOpenCv(_) => PointExtractorKind::OrbOpenCv,
            Self::FastBrief(_) => PointExtractorKind::FastBrief,
        }
    }

    /// Detects and describes points in `image` into `out`.
    pub fn extract(
        &mut self,
        image: &GrayImage,
        out: &mut PointFeatures,
    ) -> Result<(), VisionError> {
        match self {
            Self::OrbOpenCv(orb) => orb.extract(image, out),
            Self::FastBrief(ours) => ours.extract(image, out),
        }
    }
}
