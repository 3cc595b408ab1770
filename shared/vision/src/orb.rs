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

/// Refines the right image's column of a stereo point match to a fraction of a pixel.
///
/// Detected keypoints sit on whole pixels (of their pyramid level), so disparities come in
/// whole pixels too, and every point of a surface at one depth is rounded the same way:
/// a depth bias that averaging cannot remove. Here an 11 × 11 window around `left` is
/// compared with windows of the right image on the same row, up to 3 px either side of
/// `right`, by the sum of absolute differences after removing each window's mean (so a
/// gain offset between the cameras does not matter), and a parabola through the best
/// shift and its two neighbours gives the fraction. `None` when a window leaves an image
/// or the best shift is at the end of the search (the match is then left as it was).
pub fn refine_stereo_column(
    left_image: &GrayImage,
    right_image: &GrayImage,
    left: Point,
    right: Point,
) -> Option<f64> {
    const HALF: i64 = 5;
    const SEARCH: i64 = 3;
    let (lp, rp) = (left_image.pixels()?, right_image.pixels()?);
    let width = i64::from(left_image.width());
    let height = i64::from(left_image.height());
    if (
        i64::from(right_image.width()),
        i64::from(right_image.height()),
    ) != (width, height)
    {
        return None;
    }
    let (ul, v) = (left.x.round() as i64, left.y.round() as i64);
    let ur = right.x.round() as i64;
    let inside = |u: i64| u - HALF >= 0 && u + HALF < width;
    let rows_inside = v - HALF >= 0 && v + HALF < height;
    if !(rows_inside && inside(ul) && inside(ur - SEARCH) && inside(ur + SEARCH)) {
        return None;
    }
    let window = |pixels: &[u8], u: i64| -> Vec<i32> {
        let mut values = Vec::with_capacity(((2 * HALF + 1) * (2 * HALF + 1)) as usize);
        for y in v - HALF..=v + HALF {
            let row = (y * width) as usize;
            values.extend(
                pixels[row + (u - HALF) as usize..=row + (u + HALF) as usize]
                    .iter()
                    .map(|&p| i32::from(p)),
            );
        }
        let mean = values.iter().sum::<i32>() / values.len() as i32;
        values.iter_mut().for_each(|p| *p -= mean);
        values
    };
    let reference = window(lp, ul);
    let costs: Vec<f64> = (-SEARCH..=SEARCH)
        .map(|shift| {
            let candidate = window(rp, ur + shift);
            reference
                .iter()
                .zip(&candidate)
                .map(|(a, b)| f64::from((a - b).abs()))
                .sum()
        })
        .collect();
    let best = (0..costs.len()).min_by(|&a, &b| costs[a].total_cmp(&costs[b]))?;
    if best == 0 || best == costs.len() - 1 {
        return None;
    }
    let (before, at, after) = (costs[best - 1], costs[best], costs[best + 1]);
    let curvature = before - 2.0 * at + after;
    let fraction = if curvature > 0.0 {
        (0.5 * (before - after) / curvature).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    Some((ur + best as i64 - SEARCH) as f64 + fraction)
}
