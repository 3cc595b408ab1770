//! ORB points (OpenCV features2d) and their stereo / frame-to-frame matching.

use crate::{
    AppearanceGates, BinaryDescriptors, FeatureMatch, GrayImage, HammingMatcher, OpenCvContext,
    OrbOptions, VisionError,
};
use linetrack_geometry::{MatchCase, Point};
use opencv::core::{KeyPoint, KeyPointTraitConst, Mat, MatTraitConst, Ptr, Vector};
use opencv::features2d::{Feature2DTrait, ORB, ORB_ScoreType};

/// Points of one image with their descriptors (row k for `points[k]`).
#[derive(Debug, Clone, Default)]
pub struct PointFeatures {
    /// Keypoint positions, pixels.
    pub points: Vec<Point>,
    /// Pyramid level each point was detected at (0: full resolution); its position is
    /// quantised to that level's pixel, `scale_factor^level` full-resolution pixels.
    pub levels: Vec<u8>,
    /// ORB descriptors.
    pub descriptors: BinaryDescriptors,
}

/// ORB detection and description; keeps its buffers.
pub struct OrbExtractor {
    orb: Ptr<ORB>,
    keypoints: Vector<KeyPoint>,
    raw: Mat,
}

impl OrbExtractor {
    /// An ORB extractor with `options`.
    pub fn new(options: &OrbOptions) -> Result<Self, VisionError> {
        let orb = ORB::create(
            options.features,
            options.scale_factor,
            options.levels,
            options.edge_threshold,
            0,
            2,
            ORB_ScoreType::HARRIS_SCORE,
            31,
            options.fast_threshold,
        )
        .context("creating the ORB extractor")?;
        Ok(Self {
            orb,
            keypoints: Vector::new(),
            raw: Mat::default(),
        })
    }

    /// Detects and describes points in `image` into `out`.
    pub fn extract(
        &mut self,
        image: &GrayImage,
        out: &mut PointFeatures,
    ) -> Result<(), VisionError> {
        self.keypoints.clear();
        let no_mask = Mat::default();
        self.orb
            .detect_and_compute(
                image.mat(),
                &no_mask,
                &mut self.keypoints,
                &mut self.raw,
                false,
            )
            .context("ORB detection")?;
        out.points.clear();
        out.points.extend(
            self.keypoints
                .iter()
                .map(|k| Point::new(f64::from(k.pt().x), f64::from(k.pt().y))),
        );
        out.levels.clear();
        out.levels.extend(
            self.keypoints
                .iter()
                .map(|k| u8::try_from(k.octave().max(0)).unwrap_or(u8::MAX)),
        );
        let row_bytes = usize::try_from(self.raw.cols()).unwrap_or(0);
        out.descriptors.reset(out.points.len(), row_bytes);
        for k in 0..out
            .points
            .len()
            .min(usize::try_from(self.raw.rows()).unwrap_or(0))
        {
            out.descriptors.set_from_mat(k, &self.raw, k as i32)?;
        }
        Ok(())
    }
}

/// Matches points: mutual best Hamming distance with the ratio test, among pairs on the
/// same rows within the disparity range (stereo) or within the displacement (frame to frame).
pub fn match_points(
    hamming: &mut HammingMatcher,
    case: MatchCase,
    first: &PointFeatures,
    second: &PointFeatures,
    gates: &AppearanceGates,
    min_ratio: f64,
    out: &mut Vec<FeatureMatch>,
) {
    let admit = |i: usize, j: usize| {
        let (a, b) = (first.points[i], second.points[j]);
        match case {
            MatchCase::Stereo => {
                let disparity = a.x - b.x;
                (a.y - b.y).abs() <= gates.max_row_difference_px
                    && disparity >= gates.min_disparity_px
                    && disparity <= gates.max_disparity_px
            }
            MatchCase::FrameToFrame => (a - b).norm() <= gates.max_displacement_px,
        }
    };
    hamming.match_mutual(
        &first.descriptors,
        &second.descriptors,
        min_ratio,
        admit,
        out,
    );
}
