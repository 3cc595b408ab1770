//! What the odometry is told, without OpenCV: its [`OdometryConfig`] (read from TOML,
//! every field defaulted) with the photometric check of stereo segments and the limits past
//! which a frame is lost.
//!
//! `linetrack-odometry` runs these settings (and re-exports every type here); this crate
//! holds them apart so that what only reads a configuration (`linetrack-pipeline-config`,
//! and through it the link and the ROS 2 bridge) builds without OpenCV.
#![warn(missing_docs)]

use linetrack_l1_matcher::{Gates as L1Gates, MatcherConfig as L1Config};
use linetrack_stereo_vo::MotionConfig;
use linetrack_vision_config::{DetectorKind, FrontendConfig, MatcherKind, OrbOptions};
use serde::{Deserialize, Serialize};

/// Which features the odometry uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Features {
    /// ORB points and line segments.
    PointsAndLines,
    /// Line segments only.
    LinesOnly,
}

/// The photometric check of stereo segment matches: on the image rows both segments cover,
/// the intensities across the two lines are compared by zero-normalised cross-correlation
/// (blind to any gain and bias between the cameras), also one pixel to either side. A match
/// is not triangulated when the correlation is low or its peak lies off the line: a
/// descriptor matched the right texture at the wrong edge, and the landmark would sit at a
/// wrong depth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StereoPhotometric {
    /// Switch.
    pub enabled: bool,
    /// Matches whose mean row correlation is below this are dropped.
    pub min_correlation: f64,
    /// Rows both segments must have a usable profile on for the correlation to count.
    pub min_rows: usize,
    /// Matches whose content sits farther than this from the right segment's line are
    /// dropped, pixels.
    pub max_offset_px: f64,
}

impl Default for StereoPhotometric {
    fn default() -> Self {
        Self {
            enabled: true,
            min_correlation: 0.7,
            min_rows: 3,
            max_offset_px: 1.0,
        }
    }
}

/// What moves the last frame's segments to where they are matched
/// ([`OdometryConfig::predicted_matching`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LinePrediction {
    /// The last measured motion (constant velocity).
    ConstantVelocity,
    /// With points: the frame's own motion estimated from its tracked points first (their
    /// matches need no segments), then the segments predicted with it; where the points
    /// give no believed motion, the last motion. Lines only: the last motion.
    PointsFirst,
}

/// Where the ℓ1 matcher narrows its gate around predicted segments to the frame's own
/// prediction error (`[frontend.l1.predicted] narrow_factor`;
/// [`OdometryConfig::tracking_frontend`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PredictedNarrowing {
    /// Never: the gate is `[frontend.l1.predicted] max_displacement_px` for every frame.
    Never,
    /// Lines only, where each segment match carries the motion; with points, the
    /// segments' matches change the estimate little and the narrower gate's lost matches
    /// were not made up (`highway` seed 3, ℓ1: drift 0.41 → 0.45 %).
    LinesOnly,
    /// With points too.
    Always,
}

/// Configuration of the odometry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OdometryConfig {
    /// Line detector.
    pub detector: DetectorKind,
    /// Segment matcher, stereo and frame to frame.
    pub matcher: MatcherKind,
    /// Points and lines, or lines only.
    pub features: Features,
    /// Detection, description and matching options.
    pub frontend: FrontendConfig,
    /// Gauss–Newton options.
    pub motion: MotionConfig,
    /// Frame to frame: largest image motion of a feature, pixels (wider than the stereo
    /// front end's default: the camera moves between frames).
    pub max_displacement_px: f64,
    /// Frame to frame once a motion is known: previous features with a 3-D position are
    /// searched for within this of where the last motion (constant velocity) projects
    /// them, pixels.
    pub predicted_window_px: f64,
    /// Frame to frame once a motion is known: match the last frame's segments at the
    /// positions the last motion predicts for them (each one with a 3-D position), not
    /// where they were, so the matcher's displacement gate is centred on the prediction
    /// (LBD), or (ℓ1) its gates and flow filter are those of a predicted query
    /// (`[frontend.l1.predicted]`). KITTI raw drive, ℓ1 lines only: frames lost after the
    /// start 13 → 0 (the old positions' flow filter assumed a coherent flow, which a
    /// forward motion's is not).
    pub predicted_matching: bool,
    /// What predicts the segments' positions for `predicted_matching`.
    pub line_prediction: LinePrediction,
    /// When the ℓ1 matcher narrows its gate around predicted segments to the frame's own
    /// prediction error (`[frontend.l1.predicted] narrow_factor`, which sets how much).
    pub predicted_narrowing: PredictedNarrowing,
    /// Frames whose segments were matched without a prediction (the first, and the one
    /// after a loss) are matched again, at most this many times, where the motion their
    /// matches give puts them; the pass whose motion keeps the most segments within
    /// `motion.outlier_px` is kept (0: never). Before a motion is known the segments are
    /// looked for around their old positions, and on a fast forward motion those that
    /// move least are found first: far ones, and ones the motion slides along themselves,
    /// which also fit a shorter step. Needs `predicted_matching` and a matcher that matches
    /// predicted positions.
    pub rematch_passes: usize,
    /// Frame to frame, ORB points: the second-best Hamming distance must be at least this
    /// times the best (the stereo ratio is the front end's `orb.min_distance_ratio`).
    pub frame_to_frame_ratio: f64,
    /// Leave a stereo segment match untriangulated when another right segment looks just
    /// like its partner at another disparity (repetitive structure).
    pub reject_look_alikes: bool,
    /// Refine stereo point matches to a fraction of a pixel (keypoints sit on whole pixels,
    /// which biases the depth of every point of a surface the same way).
    pub subpixel_stereo: bool,
    /// Refine frame-to-frame point matches to a fraction of a pixel: the previous frame's
    /// window around the point is looked for around its match (`refine_track`), so the
    /// motion is measured against where the landmark's own point went, not against another
    /// keypoint rounded to its pyramid level's pixel. A refined point is weighted as a
    /// full-resolution one (its level's rounding is gone), and it stays where it was
    /// tracked: triangulated there and looked for from there in the next frame, so its
    /// landmark follows one physical point.
    pub subpixel_tracking: bool,
    /// Follow features as landmarks: the motion is measured against positions fused over
    /// every stereo sighting of a tracked feature (placed with their frames' poses), not
    /// against the previous frame's triangulation alone (PL-StVO).
    pub landmarks: bool,
    /// A new stereo sighting joins its landmark when their disparities differ by at most
    /// this, pixels; otherwise the landmark starts over from the sighting.
    pub landmark_disparity_px: f64,
    /// Stretch dark or flat images to the full grey range before detection, with a gain of
    /// at most this (1: never): detectors threshold absolute gradients, so a dimmed scene
    /// otherwise loses most of its features. Each image is stretched on its own. The gain
    /// amplifies noise too: on the generated `lights-switching` sequence (seed 1, LBD,
    /// points and lines; measured before the motion prior) a gain of up to 4 gave ATE
    /// 4.4 cm, up to 8 or 16 let noise corners carry the point matches and gave 58 cm, none
    /// lost 21 frames and gave 20 cm.
    pub max_contrast_gain: f64,
    /// Point observations of a stretched image weighted by 1 / gain²: the stretch
    /// multiplies the sensor's noise with the contrast, so a corner found in a dimmed scene
    /// is that much less certain than one in a well-exposed image (in image units its
    /// noise is `gain` times larger relative to the edges it sits on). Segments are fitted
    /// over tens of pixels, which averages the noise, and keep their weight.
    pub points_weighted_by_gain: bool,
    /// Photometric check of stereo segment matches before they are triangulated.
    pub stereo_photometric: StereoPhotometric,
    /// When an estimate is not believed.
    pub lost: LostLimits,
    /// Segments closer than this to horizontal are not triangulated, degrees: an
    /// endpoint's disparity is read off the right segment's line at the same row, so its
    /// error grows as 1 / tan(angle).
    pub min_line_angle_deg: f64,
    /// The rig's disparity offset: a constant error in every measured disparity, known or
    /// estimated as the frames go.
    pub disparity_offset: DisparityOffsetConfig,
}

impl Default for OdometryConfig {
    fn default() -> Self {
        Self {
            detector: DetectorKind::Lsd,
            matcher: MatcherKind::Lbd,
            features: Features::PointsAndLines,
            // More points than the stereo front end's 600: measured on the KITTI raw
            // drive (LBD, before the sub-pixel refinement), ATE 0.56 m with 600, 0.19 m
            // with 1500.
            frontend: FrontendConfig {
                orb: OrbOptions {
                    features: 1500,
                    ..OrbOptions::default()
                },
                // The ℓ1 matcher's segments before a motion is known (the first frame,
                // after a loss) are looked for as far as the points are
                // (`max_displacement_px`). KITTI raw drive (~1.3 m per frame), ℓ1 lines
                // only: with 40 px its first five frames were lost (too few matches for a
                // constrained motion), drift 6.8 %; with 60 or 80 px none, 0.73 %.
                l1: L1Config {
                    gates: L1Gates {
                        max_displacement_px: 60.0,
                        ..L1Gates::default()
                    },
                    ..L1Config::default()
                },
                ..FrontendConfig::default()
            },
            motion: MotionConfig::default(),
            max_displacement_px: 60.0,
            predicted_window_px: 30.0,
            predicted_matching: true,
            line_prediction: LinePrediction::ConstantVelocity,
            predicted_narrowing: PredictedNarrowing::LinesOnly,
            rematch_passes: 0,
            frame_to_frame_ratio: 1.5,
            reject_look_alikes: true,
            subpixel_stereo: true,
            subpixel_tracking: true,
            landmarks: true,
            landmark_disparity_px: 1.0,
            max_contrast_gain: 4.0,
            points_weighted_by_gain: true,
            stereo_photometric: StereoPhotometric::default(),
            lost: LostLimits::default(),
            min_line_angle_deg: 10.0,
            disparity_offset: DisparityOffsetConfig::default(),
        }
    }
}

/// The most `rematch_passes` accepted: each pass matches the frame's segments once more.
const MAX_REMATCH_PASSES: usize = 10;
/// The most `lost.coast_frames` accepted: a constant velocity held longer predicts little.
const MAX_COAST_FRAMES: u32 = 10;

impl OdometryConfig {
    /// The front end's settings as the odometry matches with them: `frontend`, with the ℓ1
    /// matcher's narrowing of predicted gates turned off where `predicted_narrowing`
    /// leaves it out for these `features`.
    pub fn tracking_frontend(&self) -> FrontendConfig {
        let mut frontend = self.frontend.clone();
        let narrows = match self.predicted_narrowing {
            PredictedNarrowing::Never => false,
            PredictedNarrowing::LinesOnly => self.features == Features::LinesOnly,
            PredictedNarrowing::Always => true,
        };
        if !narrows {
            frontend.l1.predicted.narrow_factor = 0.0;
        }
        frontend
    }

    /// Reads a TOML file of these settings (missing keys take their defaults) and checks it;
    /// errors name the file and the field.
    pub fn from_file(path: &std::path::Path) -> Result<Self, String> {
        let origin = path.display();
        let text =
            std::fs::read_to_string(path).map_err(|e| format!("{origin}: cannot read: {e}"))?;
        let config: Self = toml::from_str(&text).map_err(|e| format!("{origin}: {e}"))?;
        config.validate().map_err(|e| format!("{origin}: {e}"))?;
        Ok(config)
    }

    /// Checks the ranges; the message names the first bad field.
    pub fn validate(&self) -> Result<(), String> {
        self.frontend
            .validate()
            .map_err(|e| format!("frontend: {e}"))?;
        let positive = [
            ("max_displacement_px", self.max_displacement_px),
            ("predicted_window_px", self.predicted_window_px),
            ("frame_to_frame_ratio", self.frame_to_frame_ratio),
            ("motion.huber_px", self.motion.huber_px),
            ("motion.outlier_px", self.motion.outlier_px),
            (
                "motion.ransac_threshold_px",
                self.motion.ransac_threshold_px,
            ),
            ("landmark_disparity_px", self.landmark_disparity_px),
            ("lost.departure_m", self.lost.departure_m),
            ("lost.departure_deg", self.lost.departure_deg),
        ];
        for (field, value) in positive {
            if !(value > 0.0 && value.is_finite()) {
                return Err(format!(
                    "field `{field}` = {value}: expected a finite number > 0"
                ));
            }
        }
        if !(self.max_contrast_gain >= 1.0 && self.max_contrast_gain <= 255.0) {
            return Err(format!(
                "field `max_contrast_gain` = {}: expected a number in [1, 255]",
                self.max_contrast_gain
            ));
        }
        if self.rematch_passes > MAX_REMATCH_PASSES {
            return Err(format!(
                "field `rematch_passes` = {}: expected at most {MAX_REMATCH_PASSES}",
                self.rematch_passes
            ));
        }
        if !(self.min_line_angle_deg >= 0.0 && self.min_line_angle_deg < 90.0) {
            return Err(format!(
                "field `min_line_angle_deg` = {}: expected a number in [0, 90)",
                self.min_line_angle_deg
            ));
        }
        self.disparity_offset
            .validate()
            .map_err(|e| format!("disparity_offset.{e}"))?;
        let photometric = &self.stereo_photometric;
        if !(-1.0..=1.0).contains(&photometric.min_correlation) {
            return Err(format!(
                "field `stereo_photometric.min_correlation` = {}: expected a number in [-1, 1]",
                photometric.min_correlation
            ));
        }
        if !(photometric.max_offset_px > 0.0) {
            return Err(format!(
                "field `stereo_photometric.max_offset_px` = {}: expected a number > 0 (inf: off)",
                photometric.max_offset_px
            ));
        }
        if photometric.min_rows == 0 {
            return Err("field `stereo_photometric.min_rows` = 0: expected at least 1".to_string());
        }
        let m = &self.motion;
        if !(m.min_relative_eigenvalue >= 0.0 && m.min_relative_eigenvalue < 1.0) {
            return Err(format!(
                "field `motion.min_relative_eigenvalue` = {}: expected a number in [0, 1)",
                m.min_relative_eigenvalue
            ));
        }
        if self.lost.coast_frames > MAX_COAST_FRAMES {
            return Err(format!(
                "field `lost.coast_frames` = {}: expected at most {MAX_COAST_FRAMES}",
                self.lost.coast_frames
            ));
        }
        let rescue = &self.lost;
        if !(rescue.rescue_window_px.is_finite() && rescue.rescue_window_px >= 0.0) {
            return Err(format!(
                "field `lost.rescue_window_px` = {}: expected a finite number ≥ 0 (0: off)",
                rescue.rescue_window_px
            ));
        }
        if !(rescue.rescue_collinear_px.is_finite() && rescue.rescue_collinear_px >= 0.0) {
            return Err(format!(
                "field `lost.rescue_collinear_px` = {}: expected a finite number ≥ 0 (0: off)",
                rescue.rescue_collinear_px
            ));
        }
        if rescue.rescue_min_inliers != 0
            && !(3..=m.min_inliers).contains(&rescue.rescue_min_inliers)
        {
            return Err(format!(
                "field `lost.rescue_min_inliers` = {}: expected 0 (off) or 3 to `motion.min_inliers` ({})",
                rescue.rescue_min_inliers, m.min_inliers
            ));
        }
        if !(3..=m.min_inliers).contains(&m.min_inliers_with_prior) {
            return Err(format!(
                "field `motion.min_inliers_with_prior` = {}: expected 3 to `motion.min_inliers` ({})",
                m.min_inliers_with_prior, m.min_inliers
            ));
        }
        if m.max_iterations == 0 {
            return Err("field `motion.max_iterations` = 0: expected at least 1".to_string());
        }
        if !(0.0..=1.0).contains(&m.offset_evidence_prior) {
            return Err(format!(
                "field `motion.offset_evidence_prior` = {}: expected a number in [0, 1]",
                m.offset_evidence_prior
            ));
        }
        Ok(())
    }
}

/// When a frame's estimate is not believed and the frame is declared lost (its pose is then
/// the prediction). Ill-conditioned problems are caught by
/// `motion.min_relative_eigenvalue`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LostLimits {
    /// The estimate's translation may differ from the prediction's (the last motion) by
    /// this much plus `departure_fraction` of the predicted step, metres.
    pub departure_m: f64,
    /// See `departure_m`.
    pub departure_fraction: f64,
    /// The estimate's rotation may differ from the prediction's by this much, degrees.
    pub departure_deg: f64,
    /// After a lost frame, this many more frames are still matched where the last good
    /// motion puts the features and estimated near it (with the constant-velocity prior and
    /// the limits above), before the tracker searches the whole window without a prior.
    /// 0: the frame after a loss is searched without a prediction.
    pub coast_frames: u32,
    /// Lines only, a frame matched around the prediction whose segments would be lost
    /// (too few inliers, or an estimate far from the prediction) is matched again with the
    /// frame-to-frame gate around each predicted segment widened to this many pixels (ℓ1:
    /// `[frontend.l1.predicted] max_displacement_px`; LBD: its displacement gate), and
    /// those matches are kept if they give a believed estimate. 0: never. A frame that
    /// would not be lost is tracked exactly as without it.
    pub rescue_window_px: f64,
    /// Lines only (ℓ1), a frame matched around the prediction whose segments would be lost
    /// is also matched again with `[frontend.l1.predicted] collinear_px` at this many pixels
    /// (with the window above if that is on): a candidate on the best one's line, a piece of
    /// the same edge cut elsewhere by the detector, is then no rival in the ratio test.
    /// Kept if that gives a believed estimate. 0: never. A frame that would not be lost is
    /// tracked exactly as without it.
    pub rescue_collinear_px: f64,
    /// Lines only, a frame still lost after the rescue above is accepted with this many
    /// inlying segments under the constant-velocity prior (3 to `motion.min_inliers`; 0:
    /// never). Unlike `motion.min_inliers_with_prior` it acts on such frames alone.
    pub rescue_min_inliers: usize,
}

impl Default for LostLimits {
    fn default() -> Self {
        Self {
            departure_m: 0.1,
            departure_fraction: 0.25,
            departure_deg: 5.0,
            coast_frames: 0,
            rescue_window_px: 0.0,
            rescue_collinear_px: 1.0,
            rescue_min_inliers: 0,
        }
    }
}

/// A constant error in the rig's disparities: the measured disparity minus the true one,
/// the same over the whole image. A small yaw between the two cameras or a principal point
/// off by a fraction of a pixel in the calibration gives one. It changes a feature's depth
/// by the fraction `offset / disparity`, so far features (small disparity) are placed too
/// far or too near by much more than near ones, and the step, fitted to both, comes out
/// too long or too short: the KITTI raw drive with its right images moved by one pixel
/// (disparities one pixel short) drifts 9.5 % with every step 9 % too long.
///
/// With `estimate` on, each frame's motion estimate also says how much the disparities of
/// the points it was fitted to are off (near points fix the step; far ones whose depths
/// are off by a common fraction then no longer fit it), and the offset is their running,
/// information-weighted mean. Triangulation subtracts it from every disparity, points and
/// segments alike. Lines only gives no evidence.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DisparityOffsetConfig {
    /// Estimate the offset from the frames as they come.
    pub estimate: bool,
    /// The offset at the start, pixels (measured minus true disparity): a rig known to be
    /// off can say so here; with `estimate` off it stays this.
    pub initial_px: f64,
    /// How sure that start is, one standard deviation, pixels: the first frame's evidence
    /// moves the estimate by at most `initial_sigma_px² / (initial_sigma_px² +
    /// frame_sigma_px²)` of its own figure (0.39 with the defaults). With 0.2 a rig one
    /// pixel off is corrected from frame 3 of the KITTI raw drive, half a pixel from frame
    /// 4–7. The start only decides when the offset is applied: what is applied is the
    /// frames' own mean, without it. With 0.3, when segments still bore on the evidence, the generated presets' nil
    /// offset wandered as far as 0.63 px (0.48 with 0.2; docs/odometry.md, "The rig's
    /// disparity offset").
    pub initial_sigma_px: f64,
    /// A frame's evidence counts with at least this spread, pixels, however well its own
    /// fit pins it: a frame's residuals are not independent (a landmark's depth, a
    /// matched edge's position err alike for a while), so the fit's own variance is
    /// optimistic.
    pub frame_sigma_px: f64,
    /// The estimate is never held surer than this, pixels: it keeps following a rig whose
    /// offset changes (warming up, a knock) and does not freeze on its first frames.
    pub floor_sigma_px: f64,
    /// The estimate is used only once it departs from `initial_px` by more than this many
    /// of its standard deviations; until then `initial_px` is. On data whose offset is nil
    /// the estimate wanders by a few hundredths of a pixel, which would move every step by
    /// a few tenths of a percent for nothing.
    pub departure_sigmas: f64,
    /// …and by more than this, pixels, however sure it is. The frames' evidence is not
    /// free of the scene: on the generated presets, whose offset is nil, it wandered as far
    /// as ±0.31 px for tens of frames (24 sequences, points and lines, both matchers), well
    /// outside the noise it reckons for itself; on the KITTI raw drive to 0.18 px.
    pub min_px: f64,
    /// Largest offset believed, pixels, either sign; one frame moves the estimate by at
    /// most a pixel of evidence.
    pub max_px: f64,
}

impl Default for DisparityOffsetConfig {
    fn default() -> Self {
        Self {
            estimate: true,
            initial_px: 0.0,
            initial_sigma_px: 0.2,
            frame_sigma_px: 0.25,
            floor_sigma_px: 0.03,
            departure_sigmas: 3.0,
            min_px: 0.4,
            max_px: 3.0,
        }
    }
}

impl DisparityOffsetConfig {
    /// `Err` names the first field out of range.
    pub fn validate(&self) -> Result<(), String> {
        for (field, value) in [
            ("initial_sigma_px", self.initial_sigma_px),
            ("frame_sigma_px", self.frame_sigma_px),
            ("floor_sigma_px", self.floor_sigma_px),
            ("departure_sigmas", self.departure_sigmas),
            ("min_px", self.min_px),
            ("max_px", self.max_px),
        ] {
            if !(value > 0.0 && value.is_finite()) {
                return Err(format!("{field} = {value}: expected a finite number > 0"));
            }
        }
        if !(self.initial_px.is_finite() && self.initial_px.abs() <= self.max_px) {
            return Err(format!(
                "initial_px = {}: expected a finite number within ± max_px ({})",
                self.initial_px, self.max_px
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_documented_config_file_holds_the_defaults() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/odometry.toml");
        let config = OdometryConfig::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(config, OdometryConfig::default());
    }

    #[test]
    fn the_predicted_gate_narrows_for_the_features_the_setting_names() {
        let factor = |narrowing: PredictedNarrowing, features: Features| {
            let config = OdometryConfig {
                predicted_narrowing: narrowing,
                features,
                ..OdometryConfig::default()
            };
            config.tracking_frontend().l1.predicted.narrow_factor
        };
        let on = OdometryConfig::default()
            .frontend
            .l1
            .predicted
            .narrow_factor;
        assert!(on > 0.0, "the matcher narrows by default: {on}");
        let (lines, both) = (Features::LinesOnly, Features::PointsAndLines);
        assert_eq!(factor(PredictedNarrowing::LinesOnly, lines), on);
        assert_eq!(factor(PredictedNarrowing::LinesOnly, both), 0.0);
        assert_eq!(factor(PredictedNarrowing::Always, both), on);
        assert_eq!(factor(PredictedNarrowing::Never, lines), 0.0);
        // Everything else is the front end as configured.
        let config = OdometryConfig::default();
        let mut frontend = config.tracking_frontend();
        frontend.l1.predicted.narrow_factor = on;
        assert_eq!(frontend, config.frontend);
    }

    #[test]
    fn the_rescue_settings_are_checked() {
        let with = |window: f64, inliers: usize| {
            let mut config = OdometryConfig::default();
            config.lost.rescue_window_px = window;
            config.lost.rescue_min_inliers = inliers;
            config.validate()
        };
        assert!(with(0.0, 0).is_ok());
        assert!(with(30.0, 4).is_ok());
        assert!(with(30.0, 6).is_ok());
        for (window, inliers, field) in [
            (-1.0, 0, "rescue_window_px"),
            (f64::NAN, 0, "rescue_window_px"),
            (30.0, 2, "rescue_min_inliers"),
            (30.0, 7, "rescue_min_inliers"),
        ] {
            let error = with(window, inliers).unwrap_err();
            assert!(error.contains(field), "{error}");
        }
        for share in [-0.1, 1.5, f64::NAN] {
            let mut config = OdometryConfig::default();
            config.motion.offset_evidence_prior = share;
            let error = config.validate().unwrap_err();
            assert!(error.contains("motion.offset_evidence_prior"), "{error}");
        }
        let mut none = OdometryConfig::default();
        none.motion.offset_evidence_prior = 0.0;
        assert_eq!(none.validate(), Ok(()));
        for collinear_px in [-0.5, f64::NAN, f64::INFINITY] {
            let mut config = OdometryConfig::default();
            config.lost.rescue_collinear_px = collinear_px;
            let error = config.validate().unwrap_err();
            assert!(error.contains("rescue_collinear_px"), "{error}");
        }
    }

    #[test]
    fn the_disparity_offset_settings_are_checked_and_named() {
        let bad = [
            (
                "frame_sigma_px",
                DisparityOffsetConfig {
                    frame_sigma_px: f64::NAN,
                    ..Default::default()
                },
            ),
            (
                "floor_sigma_px",
                DisparityOffsetConfig {
                    floor_sigma_px: 0.0,
                    ..Default::default()
                },
            ),
            (
                "min_px",
                DisparityOffsetConfig {
                    min_px: -1.0,
                    ..Default::default()
                },
            ),
            (
                "initial_px",
                DisparityOffsetConfig {
                    initial_px: 4.0,
                    ..Default::default()
                },
            ),
            (
                "initial_px",
                DisparityOffsetConfig {
                    initial_px: f64::INFINITY,
                    ..Default::default()
                },
            ),
        ];
        for (field, disparity_offset) in bad {
            let config = OdometryConfig {
                disparity_offset,
                ..OdometryConfig::default()
            };
            let error = config.validate().unwrap_err();
            assert!(
                error.contains(&format!("disparity_offset.{field}")),
                "{error}"
            );
        }
        let known = OdometryConfig {
            disparity_offset: DisparityOffsetConfig {
                estimate: false,
                initial_px: -0.4,
                ..Default::default()
            },
            ..OdometryConfig::default()
        };
        assert_eq!(known.validate(), Ok(()));
    }
}
