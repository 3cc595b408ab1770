//! PL-StVO over a stream of rectified stereo frames.
//!
//! [`Odometry`] per frame: dark images are stretched to the full grey range (a bounded
//! gain), ORB points and line segments (LSD, FLD or edgelines) are detected in both images and matched
//! stereo (segments with LBD or the ℓ1 matcher) and triangulated — point matches refined to
//! a fraction of a pixel, segments with look-alike partners (repetitive structure) left
//! out; the left image's features are matched to the previous frame's (points around where
//! the last motion puts them, segments kept only near the line it predicts). A tracked
//! feature is a landmark whose world position is fused over its stereo sightings (a
//! sighting whose disparity disagrees starts it over); each landmark seen again becomes an
//! observation, and the motion is estimated by `linetrack-stereo-vo` (a RANSAC start, then
//! Gauss–Newton on SE(3) in two passes). A frame with too few inliers, an ill-conditioned
//! problem or an estimate far from the prediction is reported as lost: its pose repeats
//! the last good motion, and its own triangulations start the landmarks afresh.
//!
//! The back end alone, [`MotionTracker`], takes segments matched elsewhere (the pipeline's
//! matcher stage) and does the rest. [`metrics`] (from `linetrack-trajectory`) scores
//! trajectories.
#![warn(missing_docs)]

mod landmarks;
pub use linetrack_trajectory::metrics;

use landmarks::{Geometry, Landmark, sighted};
use linetrack_geometry::{
    MatchCase, Point, Segment, SegmentFeatures, StereoRig, direction_angle, length_ratio, overlap,
};
use linetrack_l1_matcher::{GrayView, SegmentProfiles};
use linetrack_stereo_vo::motion::{line_residual, point_residual};
use linetrack_stereo_vo::{
    LineObservation, MotionConfig, PointObservation, TriangulationLimits, disparity_weight,
    estimate_motion, estimate_motion_near, triangulate_point, triangulate_segment,
};
use linetrack_vision::{
    AppearanceGates, DetectorKind, FeatureMatch, FrontendConfig, GrayImage, LineDetector,
    LineFeatures, MatcherKind, OrbExtractor, OrbOptions, OrbWorker, PointFeatures, PointMatcher,
    SegmentMatcher, VisionError, copy_image_into, create_detector, create_segment_matcher,
    refine_stereo_column, refine_track, stretch_contrast_into,
};
use nalgebra::{Isometry3, Point3};
use serde::{Deserialize, Serialize};
use std::time::Instant;

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
    /// Frame to frame once a motion is known, with a matcher that gains from it (LBD):
    /// match the last frame's segments at the positions the last motion predicts for them
    /// (each one with a 3-D position), not where they were, so LBD's displacement gate is
    /// centred on the prediction. The ℓ1 matcher compares segment geometry assuming a small
    /// motion and filters on a coherent flow; given predicted positions it lost frames
    /// (generated `lights-switching` seed 1, lines only: 2 lost, ATE 3.2 cm against none
    /// and 1.6 cm), so it gets the segments as they were.
    pub predicted_matching: bool,
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
                ..FrontendConfig::default()
            },
            motion: MotionConfig::default(),
            max_displacement_px: 60.0,
            predicted_window_px: 30.0,
            predicted_matching: true,
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
        }
    }
}

impl OdometryConfig {
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
        if !(self.min_line_angle_deg >= 0.0 && self.min_line_angle_deg < 90.0) {
            return Err(format!(
                "field `min_line_angle_deg` = {}: expected a number in [0, 90)",
                self.min_line_angle_deg
            ));
        }
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
        if m.max_iterations == 0 {
            return Err("field `motion.max_iterations` = 0: expected at least 1".to_string());
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
}

impl Default for LostLimits {
    fn default() -> Self {
        Self {
            departure_m: 0.1,
            departure_fraction: 0.25,
            departure_deg: 5.0,
        }
    }
}

/// What happened in one frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct FrameStats {
    /// Points detected left / right.
    pub points: [usize; 2],
    /// Segments detected left / right.
    pub segments: [usize; 2],
    /// Stereo matches triangulated: points, segments.
    pub triangulated: [usize; 2],
    /// Frame-to-frame observations used: points, segments.
    pub observations: [usize; 2],
    /// Inliers after the second pass: points, segments.
    pub inliers: [usize; 2],
    /// Gauss–Newton iterations.
    pub iterations: usize,
    /// Final RMS residual of the inliers, pixels.
    pub rms_px: f64,
    /// Conditioning of the final normal matrix (smallest over largest eigenvalue).
    pub conditioning: f64,
    /// How far the estimate departs from the prediction (the last motion): translation,
    /// metres, and rotation, degrees.
    pub departure: [f64; 2],
    /// Milliseconds: detection, description, stereo matching + triangulation, frame-to-frame
    /// matching, motion estimation.
    pub ms: [f64; 5],
}

/// The result of one frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameResult {
    /// Pose of the left camera in the world of the first frame.
    #[serde(skip)]
    pub pose: Isometry3<f64>,
    /// Whether tracking was lost in this frame (the pose is then a prediction).
    pub lost: bool,
    /// Why, when lost.
    pub reason: Option<String>,
    /// Counts and timings.
    pub stats: FrameStats,
}

/// Segments of one stereo frame, already matched: what the back end needs.
#[derive(Debug, Clone, Copy)]
pub struct MatchedLines<'a> {
    /// Segments of the left image.
    pub left: &'a [Segment],
    /// Segments of the right image.
    pub right: &'a [Segment],
    /// Stereo matches: `query` indexes `left`, `train` indexes `right`.
    pub stereo: &'a [FeatureMatch],
    /// Frame-to-frame matches against the previous frame given to the tracker: `query`
    /// indexes the previous frame's left segments, `train` this frame's; `None` when they
    /// were not matched against that frame (tracking then restarts from this frame).
    pub tracked: Option<&'a [FeatureMatch]>,
}

/// What [`MotionTracker::prepare`] made of a frame's images before its segments arrived.
#[derive(Debug, Clone, Default)]
pub struct PreparedImages {
    /// The left and right images stretched (`None`: the original is used as it is).
    stretched: [Option<GrayImage>; 2],
    /// The left image's stretch gain (1: not stretched).
    left_gain: f64,
    /// ORB points of the left and right image (empty when the odometry uses lines only).
    points: [PointFeatures; 2],
    /// Milliseconds it took, less the point work done ahead (counted with the stereo and
    /// frame-to-frame steps; the search ran beside the right image's corners, so this
    /// leaves out up to its time of the corners').
    ms: f64,
    /// Which preparation it is (unique in the process, from 1), to tell whether the point
    /// work [`Preparation::CornersAndPoints`] did is this frame's.
    serial: u64,
}

/// The last [`PreparedImages::serial`] given out.
static PREPARED_SERIAL: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// How much of a frame's work [`MotionTracker::prepare`] does before its segments arrive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Preparation {
    /// The images stretched and their corners found.
    Corners,
    /// Also the points' work that needs no segments: the left points searched for the last
    /// tracked frame's landmarks (while the right image's corners are being found), then
    /// stereo matched on the worker while those matches are refined. For the frame that
    /// follows the last one tracked:
    /// [`MotionTracker::update_prepared`] uses that work when no other frame was tracked in
    /// between, and does it again otherwise.
    CornersAndPoints,
}

/// The point work [`Preparation::CornersAndPoints`] did for a prepared frame.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PointsAhead {
    /// The preparation it was done for.
    serial: u64,
    /// Milliseconds: stereo matching, frame-to-frame matching.
    ms: [f64; 2],
}

/// A frame's images as tracking sees them (stretched where they were), with what was
/// prepared from them.
struct SeenImages<'a> {
    /// Left and right.
    images: (&'a GrayImage, &'a GrayImage),
    /// ORB points of the left and right image.
    points: [PointFeatures; 2],
    /// The left image's stretch gain (1: not stretched).
    left_gain: f64,
    /// The milliseconds of the frame's point work (stereo, frame to frame) when
    /// [`Preparation::CornersAndPoints`] did it for this frame and no frame was tracked
    /// since; `None`: it is done with the segments.
    points_ahead: Option<[f64; 2]>,
}

/// The landmark each left point of a frame stands for, if any.
type PointLandmarks = Vec<Option<Landmark<Point3<f64>>>>;
/// The landmark each left segment of a frame stands for, if any.
type LineLandmarks = Vec<Option<Landmark<[Point3<f64>; 2]>>>;

/// A frame's features as the next frame will look for them.
struct Reference {
    /// The frame's pose (camera to world).
    pose: Isometry3<f64>,
    points: PointFeatures,
    point_landmarks: PointLandmarks,
    line_landmarks: LineLandmarks,
}

/// A frame's fresh stereo triangulations (left camera frame) with their weights.
#[derive(Default)]
struct Triangulations {
    points: Vec<Option<(Point3<f64>, f64)>>,
    lines: Vec<Option<([Point3<f64>; 2], f64)>>,
}

/// Observations of the previous frame's landmarks, and which previous (`.0`) and current
/// (`.1`) feature each came from.
#[derive(Default)]
struct Observations {
    points: Vec<PointObservation>,
    point_pairs: Vec<(usize, usize)>,
    lines: Vec<LineObservation>,
    line_pairs: Vec<(usize, usize)>,
}

impl Observations {
    fn clear(&mut self) {
        self.points.clear();
        self.point_pairs.clear();
        self.lines.clear();
        self.line_pairs.clear();
    }
}

/// The lists a frame's tracking fills, kept from frame to frame.
#[derive(Default)]
struct FrameLists {
    stereo_matches: Vec<FeatureMatch>,
    right_features: Vec<Option<SegmentFeatures>>,
    fresh: Triangulations,
    observations: Observations,
}

/// What frames done with leave for the next ones (images, point lists, landmark lists):
/// once warm, tracking a frame allocates none of them. `lists` also carries the point
/// work [`Preparation::CornersAndPoints`] did, from then until the frame's update.
#[derive(Default)]
struct Spares {
    images: Vec<GrayImage>,
    points: Vec<PointFeatures>,
    point_landmarks: Vec<PointLandmarks>,
    line_landmarks: Vec<LineLandmarks>,
    lists: FrameLists,
}

/// `spare` (or a new list) refilled with the landmarks of `triangulations` (camera frame
/// of `pose`).
fn sighted_all<P: Geometry>(
    spare: Option<Vec<Option<Landmark<P>>>>,
    triangulations: &[Option<(P, f64)>],
    pose: &Isometry3<f64>,
) -> Vec<Option<Landmark<P>>> {
    let mut landmarks = spare.unwrap_or_default();
    landmarks.clear();
    landmarks.extend(
        triangulations
            .iter()
            .map(|t| t.map(|(p, w)| sighted(pose, &p, w))),
    );
    landmarks
}

/// At most this many of each kind are kept (frames prepared ahead hold some).
const MAX_SPARES: usize = 4;

/// Keeps `item` in `spares` unless it holds [`MAX_SPARES`] already.
fn keep_spare<T>(spares: &mut Vec<T>, item: T) {
    if spares.len() < MAX_SPARES {
        spares.push(item);
    }
}

impl Spares {
    /// A frame's stretched images, done with, kept for the next frames' stretch.
    fn keep_images(&mut self, images: [Option<GrayImage>; 2]) {
        for image in images.into_iter().flatten() {
            keep_spare(&mut self.images, image);
        }
    }

    /// A frame's reference, its lists kept for the next frames.
    fn keep_reference(&mut self, reference: Reference) {
        keep_spare(&mut self.points, reference.points);
        keep_spare(&mut self.point_landmarks, reference.point_landmarks);
        keep_spare(&mut self.line_landmarks, reference.line_landmarks);
    }
}

/// The back end: given matched segments (and the images, for ORB points), triangulates,
/// finds the previous frame's 3-D features again and estimates the motion. [`Odometry`]
/// runs it after its own front end; the pipeline's pose stage runs it on the matcher
/// stage's output.
pub struct MotionTracker {
    config: OdometryConfig,
    rig: StereoRig,
    /// One ORB extractor per image: the two run at the same time, the right one on a
    /// thread of its own.
    orb_left: OrbExtractor,
    orb_right: OrbWorker,
    /// Stereo matching of the points.
    point_matcher: PointMatcher,
    /// Frame-to-frame matching of the points.
    tracking: PointTracking,
    reference: Option<Reference>,
    pose: Isometry3<f64>,
    last_motion: Isometry3<f64>,
    /// Whether `last_motion` was measured (not the identity of a fresh start).
    motion_known: bool,
    /// Row profiles across this frame's left and right segments (photometric check).
    profiles: [SegmentProfiles; 2],
    /// The reference frame's left image as its points were found in (stretched or not),
    /// for `subpixel_tracking`; its buffer is reused from frame to frame.
    reference_image: Option<GrayImage>,
    /// The point work done ahead for a prepared frame, if any. It was done against the
    /// reference frame, its image and the last motion, which the next update changes:
    /// any update uses it up, whichever frame it tracks.
    points_ahead: Option<PointsAhead>,
    /// Each left point's stereo partner this frame (right keypoint, weight of the two
    /// keypoints' pyramid levels).
    stereo_partners: Vec<Option<(Point, f64)>>,
    spares: Spares,
}

impl MotionTracker {
    /// A tracker starting at the identity pose.
    pub fn new(config: OdometryConfig, rig: StereoRig) -> Result<Self, OdometryError> {
        Ok(Self {
            orb_left: OrbExtractor::new(&config.frontend.orb)?,
            orb_right: OrbWorker::new(&config.frontend.orb)?,
            point_matcher: PointMatcher::new(),
            tracking: PointTracking::default(),
            reference: None,
            pose: Isometry3::identity(),
            last_motion: Isometry3::identity(),
            motion_known: false,
            profiles: Default::default(),
            reference_image: None,
            points_ahead: None,
            stereo_partners: Vec::new(),
            spares: Spares::default(),
            config,
            rig,
        })
    }

    /// Continues from `pose` (moving at `motion` per frame), as after a restart.
    pub fn resume_from(&mut self, pose: Isometry3<f64>, motion: Isometry3<f64>) {
        self.pose = pose;
        self.last_motion = motion;
        self.motion_known = true;
        self.reference = None;
        self.points_ahead = None;
    }

    /// Moves the pose on by `frames` times the last motion (frames nobody tracked, as
    /// across a restart); at most 1000.
    pub fn predict_frames(&mut self, frames: u64) {
        for _ in 0..frames.min(1000) {
            self.pose *= self.last_motion.inverse();
        }
    }

    /// The current pose.
    pub fn pose(&self) -> Isometry3<f64> {
        self.pose
    }

    /// The last frame-to-frame motion.
    pub fn last_motion(&self) -> Isometry3<f64> {
        self.last_motion
    }

    /// Where the last frame's left segments (`previous`, as given to the last update) should
    /// lie in the next frame: each one that stands for a landmark is lifted onto the
    /// landmark's 3-D line, moved by the last motion and projected; the others stay where
    /// they were. Returns false, leaving `out` empty, before a motion is known or without a
    /// last frame (nothing to predict with).
    pub fn predict_segments(&self, previous: &[Segment], out: &mut Vec<Segment>) -> bool {
        out.clear();
        let Some(reference) = self.reference.as_ref().filter(|_| self.motion_known) else {
            return false;
        };
        let to_previous = reference.pose.inverse();
        out.extend(previous.iter().enumerate().map(|(k, seen)| {
            reference
                .line_landmarks
                .get(k)
                .and_then(Option::as_ref)
                .and_then(|landmark| {
                    let line = landmark.world.transformed(&to_previous);
                    let lift = |p: &Point| self.lift_onto(p, &line);
                    let [a, b] = [lift(&seen.start)?, lift(&seen.end)?]
                        .map(|x| self.rig.project_left(&(self.last_motion * x)));
                    Some(Segment::new(a?, b?))
                })
                .unwrap_or(*seen)
        }));
        true
    }

    /// The point of the 3-D line through `line` (left camera frame) nearest to the ray
    /// through pixel `p`; `None` when the two are (nearly) parallel or it lies behind.
    fn lift_onto(&self, p: &Point, line: &[Point3<f64>; 2]) -> Option<Point3<f64>> {
        let rig = &self.rig;
        let ray = nalgebra::Vector3::new(
            (p.x - rig.cx_px) / rig.focal_px,
            (p.y - rig.cy_px) / rig.focal_px,
            1.0,
        );
        let direction = line[1] - line[0];
        let origin = line[0].coords;
        // Closest points of o + t·d (the line) and s·r (the ray).
        let (dd, dr, rr) = (
            direction.dot(&direction),
            direction.dot(&ray),
            ray.dot(&ray),
        );
        let (od, or) = (origin.dot(&direction), origin.dot(&ray));
        let det = dd * rr - dr * dr;
        if det <= 1e-9 * dd * rr {
            return None;
        }
        let t = (dr * or - rr * od) / det;
        let x = line[0] + direction * t;
        (x.z > 0.0).then_some(x)
    }

    /// How far from its previous position a feature is searched for in the next frame:
    /// the predicted window once a motion is known, else the full displacement.
    pub fn search_radius_px(&self) -> f64 {
        search_radius_px(&self.config, self.motion_known)
    }

    /// Tracks one frame: `lines` matched, `stats` already holding the front end's counts and
    /// timings. ORB points come from `images` (left, right) when the config uses points and
    /// the images are given; without them the frame is tracked on its lines.
    pub fn update(
        &mut self,
        images: Option<(&GrayImage, &GrayImage)>,
        lines: MatchedLines<'_>,
        stats: FrameStats,
    ) -> Result<FrameResult, OdometryError> {
        let prepared = match images {
            Some((left, right)) => {
                Some(self.prepare(left, right, Preparation::CornersAndPoints)?)
            }
            None => None,
        };
        self.update_prepared(images.zip(prepared), lines, stats)
    }

    /// The part of a frame's work that needs only its images, not its segments: dark images
    /// stretched (for the corner detector as for the segment detector), their ORB points
    /// found, and with [`Preparation::CornersAndPoints`] the points' work. The pipeline's
    /// pose stage does it while the frame's segments are still being detected and matched;
    /// [`MotionTracker::update_prepared`] finishes the frame.
    pub fn prepare(
        &mut self,
        left: &GrayImage,
        right: &GrayImage,
        preparation: Preparation,
    ) -> Result<PreparedImages, OdometryError> {
        let ahead = preparation == Preparation::CornersAndPoints;
        let started = Instant::now();
        let (stretched, left_gain) = stretch_pair(
            left,
            right,
            self.config.max_contrast_gain,
            &mut self.spares.images,
        )?;
        let mut prepared = self.prepare_stretched(stretched, left_gain, left, right, ahead)?;
        // (Less the point work, counted apart.)
        let ahead_ms: f64 = self
            .points_ahead
            .iter()
            .filter(|a| a.serial == prepared.serial)
            .flat_map(|a| a.ms)
            .sum();
        prepared.ms = (since(started) - ahead_ms).max(0.0);
        Ok(prepared)
    }

    /// [`MotionTracker::prepare`] after the stretch: finds the points in the
    /// stretched images (or the originals, `None` where not stretched), and does the point
    /// work when `ahead`.
    fn prepare_stretched(
        &mut self,
        [left_stretched, right_stretched]: [Option<GrayImage>; 2],
        left_gain: f64,
        left: &GrayImage,
        right: &GrayImage,
        ahead: bool,
    ) -> Result<PreparedImages, OdometryError> {
        // (Without the point work, that of a frame prepared before stays for its update.)
        if ahead {
            self.points_ahead = None;
        }
        let serial = PREPARED_SERIAL.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        let mut points = [PointFeatures::default(), PointFeatures::default()];
        let uses_points = self.config.features == Features::PointsAndLines;
        let (mut stereo_ms, mut tracking_ms) = (0.0, 0.0);
        if uses_points {
            points = [(); 2].map(|()| self.spares.points.pop().unwrap_or_default());
            // Left and right at the same time: a frame's corners are its pose's longest step.
            let [points_l, points_r] = &mut points;
            let (image_l, image_r) = (
                left_stretched.as_ref().unwrap_or(left),
                right_stretched.as_ref().unwrap_or(right),
            );
            let orb_left = &mut self.orb_left;
            // Ahead, the left points are then matched with the reference's landmarks while
            // the right image's corners are still being found.
            let search = PointSearch::of(
                self.reference.as_ref().filter(|_| ahead),
                self.reference_image.as_ref(),
                (&self.rig, &self.config),
                (self.last_motion, self.motion_known),
                left_gain,
            );
            let tracking = &mut self.tracking;
            let (right_side, left_side) = self.orb_right.extract_while(image_r, points_r, || {
                orb_left.extract(image_l, points_l)?;
                let started = Instant::now();
                if ahead {
                    tracking.find(search.as_ref(), points_l);
                }
                Ok::<_, VisionError>(since(started))
            });
            tracking_ms = left_side?;
            right_side?;
            if ahead {
                // Then the stereo matches are found on the worker while the landmarks'
                // matches are refined here.
                let lists = &mut self.spares.lists;
                let gates = &self.config.frontend.appearance_gates;
                let ratio = self.config.frontend.orb.min_distance_ratio;
                let both_started = Instant::now();
                let (stereo, refine_ms) = self.orb_right.match_stereo_while(
                    [points_l, points_r],
                    gates,
                    ratio,
                    &mut lists.stereo_matches,
                    || {
                        let started = Instant::now();
                        tracking.observe_found(
                            search.as_ref(),
                            points_l,
                            image_l,
                            &mut lists.observations,
                        );
                        since(started)
                    },
                );
                stereo?;
                // The stereo matching's share is the time waited beyond the refinement (its
                // own time on the worker overlaps the refinement's).
                stereo_ms = (since(both_started) - refine_ms).max(0.0);
                tracking_ms += refine_ms;
            }
        }
        let prepared = PreparedImages {
            stretched: [left_stretched, right_stretched],
            left_gain,
            points,
            // (Set by the caller, which times the stretch too.)
            ms: 0.0,
            serial,
        };
        if ahead && uses_points {
            let started = Instant::now();
            let [points_l, points_r] = &prepared.points;
            let matches = std::mem::take(&mut self.spares.lists.stereo_matches);
            self.set_stereo_partners(&matches, [points_l, points_r]);
            self.spares.lists.stereo_matches = matches;
            self.points_ahead = Some(PointsAhead {
                serial: prepared.serial,
                ms: [stereo_ms + since(started), tracking_ms],
            });
        }
        Ok(prepared)
    }

    /// The milliseconds of the point work done ahead for preparation `serial`, if it was
    /// (and no frame was tracked since: tracking one uses it up).
    fn take_points_ahead(&mut self, serial: u64) -> Option<[f64; 2]> {
        self.points_ahead
            .take()
            .filter(|a| a.serial == serial)
            .map(|a| a.ms)
    }

    /// A frame's point work that needs no segments, into `lists` and the tracker's
    /// per-frame state: the stereo partners of `points_l` among `points_r` and, when there
    /// is a reference frame and `observe` says so, their observations of its landmarks.
    /// Returns its milliseconds: stereo, frame to frame.
    fn track_points(
        &mut self,
        lists: &mut FrameLists,
        [points_l, points_r]: [&PointFeatures; 2],
        left_image: &GrayImage,
        left_gain: f64,
        observe: bool,
    ) -> [f64; 2] {
        let stereo_ms = self.match_stereo(lists, [points_l, points_r]);
        let started = Instant::now();
        let search = PointSearch::of(
            self.reference.as_ref().filter(|_| observe),
            self.reference_image.as_ref(),
            (&self.rig, &self.config),
            (self.last_motion, self.motion_known),
            left_gain,
        );
        self.tracking.observe(
            search.as_ref(),
            points_l,
            left_image,
            &mut lists.observations,
        );
        [stereo_ms, since(started)]
    }

    /// The stereo partners of `points_l` among `points_r`; returns its milliseconds.
    fn match_stereo(
        &mut self,
        lists: &mut FrameLists,
        [points_l, points_r]: [&PointFeatures; 2],
    ) -> f64 {
        let started = Instant::now();
        self.point_matcher.match_points(
            MatchCase::Stereo,
            points_l,
            points_r,
            &self.config.frontend.appearance_gates,
            self.config.frontend.orb.min_distance_ratio,
            &mut lists.stereo_matches,
        );
        self.set_stereo_partners(&lists.stereo_matches, [points_l, points_r]);
        since(started)
    }

    /// Each of `points_l`'s stereo partner among `points_r`, from their `matches`, with
    /// the weight of the two keypoints' levels.
    fn set_stereo_partners(
        &mut self,
        matches: &[FeatureMatch],
        [points_l, points_r]: [&PointFeatures; 2],
    ) {
        self.stereo_partners.clear();
        self.stereo_partners.resize(points_l.points.len(), None);
        for m in matches {
            let weight = level_weight(&self.config, points_l, m.query)
                * level_weight(&self.config, points_r, m.train);
            self.stereo_partners[m.query] = Some((points_r.points[m.train], weight));
        }
    }

    /// Tracks one frame whose images were [prepared](MotionTracker::prepare) (`images`:
    /// the originals, with what was prepared from them); without images the frame is
    /// tracked on its lines.
    pub fn update_prepared(
        &mut self,
        images: Option<((&GrayImage, &GrayImage), PreparedImages)>,
        lines: MatchedLines<'_>,
        mut stats: FrameStats,
    ) -> Result<FrameResult, OdometryError> {
        let Some(((left, right), prepared)) = images else {
            return self.update_stretched(None, lines, stats);
        };
        let PreparedImages {
            stretched: [left_stretched, right_stretched],
            left_gain,
            points,
            ms,
            serial,
        } = prepared;
        stats.ms[0] += ms;
        let seen = SeenImages {
            images: (
                left_stretched.as_ref().unwrap_or(left),
                right_stretched.as_ref().unwrap_or(right),
            ),
            points,
            left_gain,
            points_ahead: self.take_points_ahead(serial),
        };
        let result = self.update_stretched(Some(seen), lines, stats);
        self.spares.keep_images([left_stretched, right_stretched]);
        result
    }

    /// [`MotionTracker::update`] on images already stretched, with their points.
    fn update_stretched(
        &mut self,
        images: Option<SeenImages<'_>>,
        lines: MatchedLines<'_>,
        stats: FrameStats,
    ) -> Result<FrameResult, OdometryError> {
        let mut lists = std::mem::take(&mut self.spares.lists);
        let result = self.track_frame(&mut lists, images, lines, stats);
        self.spares.lists = lists;
        // Point work done ahead for another frame is stale now.
        self.points_ahead = None;
        result
    }

    /// [`MotionTracker::update_stretched`] with the frame's lists (cleared here, but for
    /// the points' stereo matches and observations when they were made ahead).
    fn track_frame(
        &mut self,
        lists: &mut FrameLists,
        images: Option<SeenImages<'_>>,
        lines: MatchedLines<'_>,
        mut stats: FrameStats,
    ) -> Result<FrameResult, OdometryError> {
        let limits = TriangulationLimits {
            min_sin_from_horizontal: self.config.min_line_angle_deg.to_radians().sin(),
            ..TriangulationLimits::default()
        };
        let stereo_images = images.as_ref().map(|seen| seen.images);
        let (images, [mut points_l, points_r]) = match images {
            Some(seen) if self.config.features == Features::PointsAndLines => {
                // Stereo partners, and observations of the reference's landmarks when this
                // frame continues from it, unless done ahead (points are triangulated once
                // they are where they were tracked).
                let ms = match seen.points_ahead {
                    Some(ms) => ms,
                    None => self.track_points(
                        lists,
                        [&seen.points[0], &seen.points[1]],
                        seen.images.0,
                        seen.left_gain,
                        lines.tracked.is_some(),
                    ),
                };
                stats.ms[2] += ms[0];
                stats.ms[3] += ms[1];
                (Some(seen.images), seen.points)
            }
            _ => {
                self.stereo_partners.clear();
                self.tracking.refined.clear();
                lists.observations.clear();
                (None, Default::default())
            }
        };
        let use_points = images.is_some();
        stats.points = [points_l.points.len(), points_r.points.len()];

        let started = Instant::now();
        keep_spare(&mut self.spares.points, points_r);
        let verified = self.photometric_profiles(stereo_images, &lines);
        let fresh = &mut lists.fresh;
        fresh.points.clear();
        fresh.lines.clear();
        fresh.lines.resize(lines.left.len(), None);
        let right_features = &mut lists.right_features;
        right_features.clear();
        right_features.extend(lines.right.iter().map(|s| SegmentFeatures::new(s).ok()));
        for m in lines.stereo {
            let (Some(l), Some(r)) = (lines.left.get(m.query), lines.right.get(m.train)) else {
                continue;
            };
            if verified && !self.photometric_agreement(m.query, m.train) {
                continue;
            }
            if self.config.reject_look_alikes
                && has_look_alike(l, r, right_features, &self.config.frontend.appearance_gates)
            {
                continue;
            }
            if let Some((a, b)) = triangulate_segment(&self.rig, l, r, &limits) {
                let weight =
                    0.5 * (disparity_weight(a.disparity_px) + disparity_weight(b.disparity_px));
                fresh.lines[m.query] = Some(([a.position, b.position], weight));
            }
        }
        stats.triangulated[1] = fresh.lines.iter().flatten().count();
        stats.ms[2] += since(started);

        let left_image = images.map(|(left, _)| left);
        let Some(previous) = self.reference.take().filter(|_| lines.tracked.is_some()) else {
            // First frame, or not matched against the previous one: start again from here.
            self.triangulate_points(images, &points_l, fresh, &limits, &mut stats);
            self.reference = Some(self.fresh_reference(self.pose, points_l, fresh));
            self.keep_reference_image(left_image);
            return Ok(FrameResult {
                pose: self.pose,
                lost: false,
                reason: None,
                stats,
            });
        };

        // Previous landmarks seen again now (the points' observations are made).
        let started = Instant::now();
        let observations = &mut lists.observations;
        observations.lines.clear();
        observations.line_pairs.clear();
        if use_points && self.config.subpixel_tracking {
            self.anchor_refined_points(&mut points_l);
        }
        // This frame is the next one's reference whatever the estimate gives.
        self.keep_reference_image(left_image);
        self.observe_lines(
            &previous,
            lines.left,
            lines.tracked.unwrap_or_default(),
            observations,
        );
        stats.observations = [observations.points.len(), observations.lines.len()];
        stats.ms[3] += since(started);
        self.triangulate_points(images, &points_l, fresh, &limits, &mut stats);

        let started = Instant::now();
        // The constant-velocity prior only once a motion was measured.
        let estimate = if self.motion_known {
            estimate_motion_near
        } else {
            estimate_motion
        }(
            &self.rig,
            &observations.points,
            &observations.lines,
            &self.last_motion,
            &self.config.motion,
        );
        stats.ms[4] = since(started);
        let prediction = self.last_motion;
        let verdict = estimate.map_err(|why| why.to_string()).and_then(|e| {
            let change = prediction.inverse() * e.motion;
            stats.inliers = [e.inlier_points, e.inlier_lines];
            stats.iterations = e.iterations;
            stats.rms_px = e.rms_px;
            stats.conditioning = e.relative_eigenvalue;
            stats.departure = [
                change.translation.vector.norm(),
                change.rotation.angle().to_degrees(),
            ];
            match self.departs_sharply(&prediction, stats.departure) {
                Some(why) if self.motion_known => Err(why),
                _ => Ok(e),
            }
        });
        match verdict {
            Ok(e) => {
                self.last_motion = e.motion;
                self.motion_known = true;
                self.pose *= e.motion.inverse();
                let mut current = self.fresh_reference(self.pose, points_l, fresh);
                if self.config.landmarks {
                    self.carry_landmarks(&previous, &mut current, fresh, observations, &e.motion);
                }
                self.reference = Some(current);
                self.spares.keep_reference(previous);
                Ok(FrameResult {
                    pose: self.pose,
                    lost: false,
                    reason: None,
                    stats,
                })
            }
            Err(why) => {
                // Predict with the last good motion; this frame is the new reference. The
                // next frame is searched over the full window and its estimate is not held
                // to the prediction, which may be what went wrong.
                self.pose *= self.last_motion.inverse();
                self.motion_known = false;
                self.reference = Some(self.fresh_reference(self.pose, points_l, fresh));
                self.spares.keep_reference(previous);
                Ok(FrameResult {
                    pose: self.pose,
                    lost: true,
                    reason: Some(why),
                    stats,
                })
            }
        }
    }

    /// Takes the row profiles across the segments of both images, when the check is on and
    /// the images are given; whether it did.
    fn photometric_profiles(
        &mut self,
        images: Option<(&GrayImage, &GrayImage)>,
        lines: &MatchedLines<'_>,
    ) -> bool {
        let Some((left, right)) = images.filter(|_| self.config.stereo_photometric.enabled) else {
            return false;
        };
        let min_angle = self.config.min_line_angle_deg;
        for ((image, segments), profiles) in [(left, lines.left), (right, lines.right)]
            .into_iter()
            .zip(self.profiles.iter_mut())
        {
            let (width, height) = (image.width() as usize, image.height() as usize);
            let Some(view) = image
                .pixels()
                .and_then(|p| GrayView::new(p, width, height, width).ok())
            else {
                return false;
            };
            profiles.extract(view, segments, min_angle);
        }
        true
    }

    /// Whether left segment `i` and right segment `j` look alike across their lines (or
    /// cannot be compared).
    fn photometric_agreement(&self, i: usize, j: usize) -> bool {
        let check = &self.config.stereo_photometric;
        let [left, right] = &self.profiles;
        if let Some(s) = left.similarity(i, right, j, check.min_rows)
            && s.correlation < check.min_correlation
        {
            return false;
        }
        left.offset_px(i, right, j)
            .is_none_or(|offset| offset.abs() <= check.max_offset_px)
    }

    /// A reference whose landmarks are this frame's fresh triangulations placed at `pose`.
    fn fresh_reference(
        &mut self,
        pose: Isometry3<f64>,
        points: PointFeatures,
        fresh: &Triangulations,
    ) -> Reference {
        Reference {
            pose,
            points,
            point_landmarks: sighted_all(self.spares.point_landmarks.pop(), &fresh.points, &pose),
            line_landmarks: sighted_all(self.spares.line_landmarks.pop(), &fresh.lines, &pose),
        }
    }

    /// Hands the previous frame's landmarks on to the current features that observed them
    /// and fit `motion` (residual within `motion.outlier_px`), fused with their fresh
    /// triangulations.
    fn carry_landmarks(
        &self,
        previous: &Reference,
        current: &mut Reference,
        fresh: &Triangulations,
        observations: &Observations,
        motion: &Isometry3<f64>,
    ) {
        let gate = self.config.landmark_disparity_px;
        let outlier = self.config.motion.outlier_px;
        let pose = current.pose;
        for (obs, &(k, j)) in observations.points.iter().zip(&observations.point_pairs) {
            let fits =
                point_residual(&self.rig, motion, obs).is_some_and(|(r, _)| r.norm() <= outlier);
            if let (true, Some(Some(landmark))) = (fits, previous.point_landmarks.get(k)) {
                let seen = fresh.points[j].as_ref().map(|(p, w)| (p, *w));
                current.point_landmarks[j] =
                    Some(landmark.seen_again(&pose, seen, &self.rig, gate));
            }
        }
        for (obs, &(k, j)) in observations.lines.iter().zip(&observations.line_pairs) {
            let fits =
                line_residual(&self.rig, motion, obs).is_some_and(|(r, _)| r.amax() <= outlier);
            if let (true, Some(Some(landmark))) = (fits, previous.line_landmarks.get(k)) {
                let seen = fresh.lines[j].as_ref().map(|(p, w)| (p, *w));
                current.line_landmarks[j] = Some(landmark.seen_again(&pose, seen, &self.rig, gate));
            }
        }
    }

    /// Observations of `previous`'s segment landmarks among this frame's `left` segments.
    /// Once a motion is known, a match whose segment lies farther from the line the last
    /// motion predicts than `predicted_window_px` is not believed (a look-alike).
    fn observe_lines(
        &self,
        previous: &Reference,
        left: &[Segment],
        tracked: &[FeatureMatch],
        observations: &mut Observations,
    ) {
        let to_previous = previous.pose.inverse();
        for m in tracked {
            let (Some(Some(landmark)), Some(seen)) =
                (previous.line_landmarks.get(m.query), left.get(m.train))
            else {
                continue;
            };
            let endpoints = landmark.world.transformed(&to_previous);
            if self.motion_known && !self.near_prediction(&endpoints, seen) {
                continue;
            }
            if let Some(obs) = LineObservation::new(endpoints, seen, landmark.observation_weight())
            {
                observations.lines.push(obs);
                observations.line_pairs.push((m.query, m.train));
            }
        }
    }

    /// Whether both endpoints of `seen` lie within `predicted_window_px` of the line on
    /// which the last motion projects `endpoints` (previous camera frame); true when the
    /// prediction leaves the image.
    fn near_prediction(&self, endpoints: &[Point3<f64>; 2], seen: &Segment) -> bool {
        let [Some(a), Some(b)] = endpoints.map(|x| self.rig.project_left(&(self.last_motion * x)))
        else {
            return true;
        };
        let Some(predicted) = LineObservation::new(*endpoints, &Segment::new(a, b), 1.0) else {
            return true;
        };
        [seen.start, seen.end].iter().all(|p| {
            predicted
                .line
                .dot(&nalgebra::Vector3::new(p.x, p.y, 1.0))
                .abs()
                <= self.config.predicted_window_px
        })
    }

    /// Why an estimate that departs from the prediction by `departure` (metres, degrees)
    /// is not believed, if it is not.
    fn departs_sharply(&self, prediction: &Isometry3<f64>, departure: [f64; 2]) -> Option<String> {
        let limits = &self.config.lost;
        let max_m =
            limits.departure_m + limits.departure_fraction * prediction.translation.vector.norm();
        if departure[0] > max_m {
            return Some(format!(
                "the estimate departs {:.3} m from the prediction (at most {max_m:.3} m)",
                departure[0]
            ));
        }
        (departure[1] > limits.departure_deg).then(|| {
            format!(
                "the estimate turns {:.2}° away from the prediction (at most {:.2}°)",
                departure[1], limits.departure_deg
            )
        })
    }

    /// Triangulates each of `points` (this frame's left points, where they were tracked)
    /// with its stereo partner into `fresh`, the partner's column refined to a fraction of
    /// a pixel around it when `subpixel_stereo` is on; weighted by disparity and by the two
    /// keypoints' pyramid levels.
    fn triangulate_points(
        &self,
        images: Option<(&GrayImage, &GrayImage)>,
        points: &PointFeatures,
        fresh: &mut Triangulations,
        limits: &TriangulationLimits,
        stats: &mut FrameStats,
    ) {
        let started = Instant::now();
        fresh.points.clear();
        fresh.points.resize(points.points.len(), None);
        if let Some((left_image, right_image)) = images {
            for ((position, &left), partner) in fresh
                .points
                .iter_mut()
                .zip(&points.points)
                .zip(&self.stereo_partners)
            {
                let Some((mut right, level_weight)) = *partner else {
                    continue;
                };
                if self.config.subpixel_stereo
                    && let Some(x) = refine_stereo_column(left_image, right_image, left, right)
                {
                    right.x = x;
                }
                *position = triangulate_point(&self.rig, left, right, limits)
                    .map(|t| (t.position, disparity_weight(t.disparity_px) * level_weight));
            }
        }
        stats.triangulated[0] = fresh.points.iter().flatten().count();
        stats.ms[2] += since(started);
    }

    /// Moves this frame's left points that were tracked to a fraction of a pixel onto their
    /// tracked positions, where they are then triangulated. A landmark so fuses sightings
    /// of one physical point, the one first seen, instead of whichever pixel each frame's
    /// detector rounded the corner to (up to a pixel of its pyramid level apart), and the
    /// next frame's tracking starts from there too. The stereo weight stays that of the
    /// keypoints' levels (counting the tracked left point as exact did no better on the
    /// generated sequences).
    fn anchor_refined_points(&self, points: &mut PointFeatures) {
        for &(j, pixel) in &self.tracking.refined {
            if let Some(point) = points.points.get_mut(j) {
                *point = pixel;
            }
        }
    }

    /// Keeps `image` (this frame's left image, as its points were found in) for the next
    /// frame's sub-pixel tracking, in the buffer of the last one.
    fn keep_reference_image(&mut self, image: Option<&GrayImage>) {
        let kept = match image.filter(|_| self.config.subpixel_tracking) {
            Some(image) => copy_image_into(&mut self.reference_image, image).is_ok(),
            None => false,
        };
        if !kept {
            self.reference_image = None;
        }
    }
}

/// Weight of point `k` of `features` for its pyramid level: the inverse variance of its
/// position, `scale_factor^(−2·level)` (1 at full resolution).
fn level_weight(config: &OdometryConfig, features: &PointFeatures, k: usize) -> f64 {
    let level = features.levels.get(k).copied().unwrap_or(0);
    f64::from(config.frontend.orb.scale_factor).powi(-2 * i32::from(level))
}

/// [`MotionTracker::search_radius_px`] for `config`, once a motion is known or before.
fn search_radius_px(config: &OdometryConfig, motion_known: bool) -> f64 {
    if motion_known {
        config.predicted_window_px
    } else {
        config.max_displacement_px
    }
}

/// The weight of a frame's point observations for its left image's stretch `gain` (the
/// noise grows with it), when the config says so.
fn noise_weight(config: &OdometryConfig, gain: f64) -> f64 {
    if config.points_weighted_by_gain {
        gain.powi(-2)
    } else {
        1.0
    }
}

/// What a frame's points are searched for and where: the reference frame's landmarks,
/// moved by the last motion.
struct PointSearch<'a> {
    reference: &'a Reference,
    /// The reference's left image for sub-pixel tracking (`None`: not refined).
    reference_image: Option<&'a GrayImage>,
    rig: &'a StereoRig,
    config: &'a OdometryConfig,
    last_motion: Isometry3<f64>,
    /// How far from its prediction a landmark is searched for, pixels.
    radius_px: f64,
    /// Weight factor of this frame's observations.
    noise_weight: f64,
}

impl<'a> PointSearch<'a> {
    /// The search for `reference`'s landmarks (none without it; `reference_image`: its left
    /// image, used when the config refines to a fraction of a pixel) from a rig and config,
    /// the last motion and whether it was measured, and this frame's left stretch gain.
    fn of(
        reference: Option<&'a Reference>,
        reference_image: Option<&'a GrayImage>,
        (rig, config): (&'a StereoRig, &'a OdometryConfig),
        (last_motion, motion_known): (Isometry3<f64>, bool),
        left_gain: f64,
    ) -> Option<Self> {
        Some(Self {
            reference: reference?,
            reference_image: reference_image.filter(|_| config.subpixel_tracking),
            rig,
            config,
            last_motion,
            radius_px: search_radius_px(config, motion_known),
            noise_weight: noise_weight(config, left_gain),
        })
    }
}

/// Frame-to-frame tracking of the points: its results and buffers, kept from frame to
/// frame.
#[derive(Default)]
struct PointTracking {
    matcher: PointMatcher,
    /// The reference frame's left points moved to where the last motion predicts them (the
    /// search's centres).
    predicted: Vec<Point>,
    /// The frame's matches.
    matches: Vec<FeatureMatch>,
    /// This frame's left points tracked to a fraction of a pixel (index, position).
    refined: Vec<(usize, Point)>,
}

impl PointTracking {
    /// Replaces `observations` with those of `search`'s point landmarks among `current`
    /// (this frame's left points, found in `current_image`), searched for around where
    /// the last motion moves them; none without a search.
    fn observe(
        &mut self,
        search: Option<&PointSearch<'_>>,
        current: &PointFeatures,
        current_image: &GrayImage,
        observations: &mut Observations,
    ) {
        self.find(search, current);
        self.observe_found(search, current, current_image, observations);
    }

    /// The first half of [`PointTracking::observe`]: matches `search`'s point landmarks
    /// with `current`'s points, around where the last motion moves them (no matches
    /// without a search).
    fn find(&mut self, search: Option<&PointSearch<'_>>, current: &PointFeatures) {
        self.matches.clear();
        let Some(search) = search else {
            return;
        };
        let previous = search.reference;
        let gates = AppearanceGates {
            max_displacement_px: search.radius_px,
            ..search.config.frontend.appearance_gates
        };
        let to_previous = previous.pose.inverse();
        self.predicted.clear();
        self.predicted.extend(
            previous
                .points
                .points
                .iter()
                .zip(&previous.point_landmarks)
                .map(|(&point, landmark)| {
                    landmark
                        .and_then(|l| {
                            search
                                .rig
                                .project_left(&(search.last_motion * (to_previous * l.world)))
                        })
                        .unwrap_or(point)
                }),
        );
        // Only points with a landmark are looked for: the others could not be observed.
        let landmarks = &previous.point_landmarks;
        let wanted = |k: usize| landmarks.get(k).is_some_and(Option::is_some);
        self.matcher.match_points_of(
            MatchCase::FrameToFrame,
            (&self.predicted, &previous.points.descriptors),
            wanted,
            current,
            &gates,
            search.config.frame_to_frame_ratio,
            &mut self.matches,
        );
    }

    /// The second half of [`PointTracking::observe`]: replaces `observations` with those
    /// the matches [`PointTracking::find`] made for the same `search` and `current`
    /// give, each refined to a fraction of a pixel when the config says so.
    fn observe_found(
        &mut self,
        search: Option<&PointSearch<'_>>,
        current: &PointFeatures,
        current_image: &GrayImage,
        observations: &mut Observations,
    ) {
        observations.clear();
        self.refined.clear();
        let Some(search) = search else {
            return;
        };
        let previous = search.reference;
        let to_previous = previous.pose.inverse();
        let found = &previous.points.points;
        for m in &self.matches {
            // (Matches of another `current` would be out of range: left out.)
            if let (Some(Some(landmark)), Some(&to)) = (
                previous.point_landmarks.get(m.query),
                current.points.get(m.train),
            ) {
                let refined = search
                    .reference_image
                    .zip(found.get(m.query))
                    .and_then(|(before, &from)| refine_track(before, current_image, from, to));
                // A refined position no longer carries the keypoint's level's rounding.
                let (pixel, level_weight) = match refined {
                    Some(pixel) => {
                        self.refined.push((m.train, pixel));
                        (pixel, 1.0)
                    }
                    None => (to, level_weight(search.config, current, m.train)),
                };
                observations.points.push(PointObservation {
                    position: to_previous * landmark.world,
                    pixel,
                    weight: landmark.observation_weight() * level_weight * search.noise_weight,
                });
                observations.point_pairs.push((m.query, m.train));
            }
        }
    }
}

/// Whether several other right segments could stand in for `right` as `left`'s stereo
/// partner: as parallel (within 5°), overlapping `left`'s rows by 70 %, of comparable
/// length (within a factor 1.5) and near it (3–25 px away) inside the disparity range. On
/// a repetitive structure (stripes, railings, tiles) a matcher picks one of these by a
/// small margin and a wrong pick is consistent with its neighbours' wrong picks, so a
/// robust loss cannot reject it: such a segment is better not triangulated. A single
/// alternative (the two edges of a frame or a pole) is common in man-made scenes and is
/// left to the matcher.
fn has_look_alike(
    left: &Segment,
    right: &Segment,
    candidates: &[Option<SegmentFeatures>],
    gates: &AppearanceGates,
) -> bool {
    const MAX_ANGLE_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;
    const MIN_OVERLAP: f64 = 0.7;
    const MAX_LENGTH_RATIO: f64 = 1.5;
    const MIN_SEPARATION_PX: f64 = 3.0;
    const MAX_SEPARATION_PX: f64 = 25.0;
    const MIN_LOOK_ALIKES: usize = 2;
    let (Ok(l), Ok(r)) = (SegmentFeatures::new(left), SegmentFeatures::new(right)) else {
        return false;
    };
    // The x of a segment's line at the row of `l`'s midpoint.
    let x_at_mid_row = |s: &SegmentFeatures| {
        (s.dir.y.abs() > 1e-6).then(|| s.mid.x + (l.mid.y - s.mid.y) * s.dir.x / s.dir.y)
    };
    let Some(matched_x) = x_at_mid_row(&r) else {
        return false;
    };
    let look_alikes = candidates.iter().flatten().filter(|c| {
        let Some(x) = x_at_mid_row(c) else {
            return false;
        };
        let disparity = l.mid.x - x;
        (MIN_SEPARATION_PX..=MAX_SEPARATION_PX).contains(&(x - matched_x).abs())
            && disparity >= gates.min_disparity_px
            && disparity <= gates.max_disparity_px
            && direction_angle(&l, c) <= MAX_ANGLE_RAD
            && overlap(&l, c, MatchCase::Stereo) >= MIN_OVERLAP
            && length_ratio(&l, c) <= MAX_LENGTH_RATIO
    });
    look_alikes.count() >= MIN_LOOK_ALIKES
}

/// The odometry: feed frames in order with [`Odometry::track`].
pub struct Odometry {
    detector: Box<dyn LineDetector>,
    matcher: Box<dyn SegmentMatcher>,
    previous_lines: Option<LineFeatures>,
    /// Where the last motion moves the previous frame's segments (kept between frames).
    predicted: Vec<Segment>,
    tracker: MotionTracker,
}

/// Errors that stop the odometry (bad configuration; per-frame problems are `lost`).
#[derive(Debug, thiserror::Error)]
pub enum OdometryError {
    /// The front end could not be built or failed on an image.
    #[error(transparent)]
    Vision(#[from] VisionError),
}

/// Both images of a stereo pair through [`stretch_contrast`] (`None`: keep the original),
/// and the gain the left one was stretched by (1: not stretched).
fn stretch_pair(
    left: &GrayImage,
    right: &GrayImage,
    max_gain: f64,
    spares: &mut Vec<GrayImage>,
) -> Result<([Option<GrayImage>; 2], f64), VisionError> {
    let mut stretch = |image: &GrayImage| {
        let mut out = spares.pop();
        let gain = stretch_contrast_into(image, max_gain, &mut out)?;
        if gain.is_some() {
            Ok((out, gain))
        } else {
            if let Some(unused) = out {
                keep_spare(spares, unused);
            }
            Ok((None, None))
        }
    };
    let (left, left_gain) = stretch(left)?;
    let (right, _) = stretch(right)?;
    Ok(([left, right], left_gain.unwrap_or(1.0)))
}

fn since(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}

impl Odometry {
    /// An odometry for frames from `rig`.
    pub fn new(config: OdometryConfig, rig: StereoRig) -> Result<Self, OdometryError> {
        Ok(Self {
            detector: create_detector(config.detector, &config.frontend)?,
            matcher: create_segment_matcher(config.matcher, &config.frontend)?,
            previous_lines: None,
            predicted: Vec::new(),
            tracker: MotionTracker::new(config, rig)?,
        })
    }

    /// Tracks one stereo frame (rectified, the rig's size).
    pub fn track(
        &mut self,
        left: &GrayImage,
        right: &GrayImage,
    ) -> Result<FrameResult, OdometryError> {
        let mut stats = FrameStats::default();
        let started = Instant::now();
        let (stretched, left_gain) = stretch_pair(
            left,
            right,
            self.tracker.config.max_contrast_gain,
            &mut self.tracker.spares.images,
        )?;
        // The pipeline's steps, one after the other.
        let mut prepared = self
            .tracker
            .prepare_stretched(stretched, left_gain, left, right, true)?;
        let points_ahead = self.tracker.take_points_ahead(prepared.serial);
        // Stretched once, for the detectors and the back end's corners alike.
        let seen_left = prepared.stretched[0].as_ref().unwrap_or(left);
        let seen_right = prepared.stretched[1].as_ref().unwrap_or(right);
        let (mut lines_l, mut lines_r) = (LineFeatures::default(), LineFeatures::default());
        self.detector.detect(seen_left, &mut lines_l.segments)?;
        self.detector.detect(seen_right, &mut lines_r.segments)?;
        // (Less the point work, counted apart.)
        stats.ms[0] = (since(started) - points_ahead.iter().flatten().sum::<f64>()).max(0.0);
        let started = Instant::now();
        self.matcher.describe(seen_left, &mut lines_l)?;
        self.matcher.describe(seen_right, &mut lines_r)?;
        stats.ms[1] = since(started);
        stats.segments = [lines_l.segments.len(), lines_r.segments.len()];

        let started = Instant::now();
        let mut stereo = Vec::new();
        self.matcher
            .match_lines(MatchCase::Stereo, &lines_l, &lines_r, &mut stereo);
        stats.ms[2] = since(started);
        let started = Instant::now();
        let mut tracked = Vec::new();
        if let Some(previous) = &mut self.previous_lines {
            // Matched where the last motion puts them, when it is known.
            let predicted = &mut self.predicted;
            let moved = self.tracker.config.predicted_matching
                && self.matcher.matches_predicted_positions()
                && self.tracker.predict_segments(&previous.segments, predicted);
            if moved {
                std::mem::swap(&mut previous.segments, predicted);
            }
            self.matcher
                .match_lines(MatchCase::FrameToFrame, previous, &lines_l, &mut tracked);
            if moved {
                std::mem::swap(&mut previous.segments, predicted);
            }
        }
        stats.ms[3] = since(started);
        let lines = MatchedLines {
            left: &lines_l.segments,
            right: &lines_r.segments,
            stereo: &stereo,
            tracked: self.previous_lines.as_ref().map(|_| tracked.as_slice()),
        };
        let seen = SeenImages {
            images: (seen_left, seen_right),
            points: std::mem::take(&mut prepared.points),
            left_gain,
            points_ahead,
        };
        let result = self.tracker.update_stretched(Some(seen), lines, stats);
        let [left_stretched, right_stretched] = prepared.stretched;
        self.tracker
            .spares
            .keep_images([left_stretched, right_stretched]);
        self.previous_lines = Some(lines_l);
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Segments left out: the frames are tracked on their points alone.
    const NO_LINES: MatchedLines<'static> = MatchedLines {
        left: &[],
        right: &[],
        stereo: &[],
        tracked: Some(&[]),
    };

    /// Real EuRoC frames (a parked vehicle: small motion, many corners) and their rig.
    fn euroc_frames(indices: &[usize]) -> (Vec<linetrack_datasets::StereoFrame>, StereoRig) {
        let dir = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
        let sequence = linetrack_datasets::StereoSequence::open(&dir).unwrap();
        let frames = indices
            .iter()
            .map(|&i| sequence.load_frame(i).unwrap())
            .collect();
        (frames, sequence.rig)
    }

    /// A frame's result without its timings (measured, so never the same twice).
    fn untimed(mut result: FrameResult) -> FrameResult {
        result.stats.ms = [0.0; 5];
        result
    }

    /// Tracks `frame` as the pose stage does: prepared, then updated.
    fn track_prepared(
        tracker: &mut MotionTracker,
        frame: &linetrack_datasets::StereoFrame,
        preparation: Preparation,
    ) -> FrameResult {
        let prepared = tracker
            .prepare(&frame.left, &frame.right, preparation)
            .unwrap();
        let images = Some(((&frame.left, &frame.right), prepared));
        untimed(
            tracker
                .update_prepared(images, NO_LINES, FrameStats::default())
                .unwrap(),
        )
    }

    /// EuRoC frames 0, 4 and 8, and two trackers that tracked frame 0.
    fn two_trackers_past_frame_0() -> (Vec<linetrack_datasets::StereoFrame>, [MotionTracker; 2]) {
        let (frames, rig) = euroc_frames(&[0, 4, 8]);
        let trackers = [(); 2].map(|()| {
            let mut tracker = MotionTracker::new(OdometryConfig::default(), rig).unwrap();
            track_prepared(&mut tracker, &frames[0], Preparation::CornersAndPoints);
            tracker
        });
        (frames, trackers)
    }

    #[test]
    fn point_work_done_ahead_tracks_a_frame_as_it_does_with_the_segments() {
        let (frames, rig) = euroc_frames(&[0, 4, 8, 12, 16]);
        // The frames as they are, and darkened to a quarter: those are stretched first,
        // and their points weighted by the gain.
        let dark: Vec<_> = frames.iter().map(darkened).collect();
        let new = || MotionTracker::new(OdometryConfig::default(), rig).unwrap();
        for frames in [&frames, &dark] {
            let (mut ahead, mut along) = (new(), new());
            for frame in frames {
                let a = track_prepared(&mut ahead, frame, Preparation::CornersAndPoints);
                let b = track_prepared(&mut along, frame, Preparation::Corners);
                // (The pose included.)
                assert_eq!(a, b, "frame {}", frame.index);
                if frame.index > 0 {
                    assert!(a.stats.observations[0] > 100, "{:?}", a.stats);
                }
            }
        }
        let stretched = new()
            .prepare(&dark[0].left, &dark[0].right, Preparation::Corners)
            .unwrap();
        assert!(stretched.left_gain > 2.0, "gain {}", stretched.left_gain);
        let mut ahead = new();
        track_prepared(&mut ahead, &frames[0], Preparation::CornersAndPoints);
        // The update takes what was done ahead instead of doing it again: observations
        // emptied after the preparation stay empty…
        let frame = &frames[0];
        let prepared = ahead
            .prepare(&frame.left, &frame.right, Preparation::CornersAndPoints)
            .unwrap();
        ahead.spares.lists.observations.clear();
        let images = Some(((&frame.left, &frame.right), prepared));
        let result = ahead
            .update_prepared(images, NO_LINES, FrameStats::default())
            .unwrap();
        assert_eq!(result.stats.observations[0], 0, "{:?}", result.stats);
        // …and it is used up: the next update of the same frame looks again.
        let again = track_prepared(&mut ahead, frame, Preparation::Corners);
        assert!(again.stats.observations[0] > 100, "{:?}", again.stats);
        // A restart lets it go too.
        ahead
            .prepare(&frame.left, &frame.right, Preparation::CornersAndPoints)
            .unwrap();
        assert!(ahead.points_ahead.is_some());
        ahead.resume_from(ahead.pose(), ahead.last_motion());
        assert!(ahead.points_ahead.is_none());
    }

    /// `frame` with its pixels divided by 4.
    fn darkened(frame: &linetrack_datasets::StereoFrame) -> linetrack_datasets::StereoFrame {
        let darken = |image: &GrayImage| {
            let pixels: Vec<u8> = image.pixels().unwrap().iter().map(|p| p / 4).collect();
            let (width, height) = (image.width() as usize, image.height() as usize);
            GrayImage::from_pixels(width, height, &pixels, "darkened").unwrap()
        };
        linetrack_datasets::StereoFrame {
            left: darken(&frame.left),
            right: darken(&frame.right),
            ..frame.clone()
        }
    }

    #[test]
    fn point_work_done_ahead_for_another_frame_is_not_used() {
        // As in the pose stage when a frame's segments never arrive: frame 4 is prepared
        // with its point work, then frame 8 is tracked.
        let (frames, [mut skipped, mut direct]) = two_trackers_past_frame_0();
        skipped
            .prepare(
                &frames[1].left,
                &frames[1].right,
                Preparation::CornersAndPoints,
            )
            .unwrap();
        let a = track_prepared(&mut skipped, &frames[2], Preparation::Corners);
        let b = track_prepared(&mut direct, &frames[2], Preparation::Corners);
        assert!(a.stats.observations[0] > 100, "{:?}", a.stats);
        assert_eq!(a, b);
    }

    #[test]
    fn a_frame_prepared_while_another_waits_leaves_it_its_point_work() {
        // As in the pose stage when frame 8's images arrive before frame 4's segments.
        let (frames, [mut queued, mut direct]) = two_trackers_past_frame_0();
        let [f4, f8] = [&frames[1], &frames[2]];
        let p4 = queued
            .prepare(&f4.left, &f4.right, Preparation::CornersAndPoints)
            .unwrap();
        let p8 = queued
            .prepare(&f8.left, &f8.right, Preparation::Corners)
            .unwrap();
        assert_eq!(queued.points_ahead.map(|a| a.serial), Some(p4.serial));
        for (frame, prepared) in [(f4, p4), (f8, p8)] {
            let images = Some(((&frame.left, &frame.right), prepared));
            let a = queued
                .update_prepared(images, NO_LINES, FrameStats::default())
                .unwrap();
            let b = track_prepared(&mut direct, frame, Preparation::CornersAndPoints);
            assert!(a.stats.observations[0] > 100, "{:?}", a.stats);
            assert_eq!(untimed(a), b, "frame {}", frame.index);
        }
    }

    #[test]
    fn segments_are_predicted_where_the_last_motion_moves_their_landmarks() {
        let rig = StereoRig::default();
        let mut tracker = MotionTracker::new(OdometryConfig::default(), rig).unwrap();
        // A 3-D segment 3 m ahead, seen by a camera at a pose off the origin; the left
        // image shows only its middle half (the landmark keeps its first sighting's extent).
        let pose = Isometry3::translation(0.2, -0.1, 0.5);
        let local = [Point3::new(-0.4, -0.3, 3.0), Point3::new(0.3, 0.4, 3.6)];
        let at = |t: f64| local[0] + (local[1] - local[0]) * t;
        let project = |x: Point3<f64>| rig.project_left(&x).unwrap();
        let seen = Segment::new(project(at(0.25)), project(at(0.75)));
        let elsewhere = Segment::new(Point::new(10.0, 10.0), Point::new(40.0, 12.0));
        tracker.reference = Some(Reference {
            pose,
            points: PointFeatures::default(),
            point_landmarks: Vec::new(),
            line_landmarks: vec![Some(sighted(&pose, &local, 1.0)), None],
        });
        let previous = [seen, elsewhere];
        let mut out = Vec::new();
        // No motion measured yet: nothing to predict with.
        assert!(!tracker.predict_segments(&previous, &mut out));
        assert!(out.is_empty());

        let motion = Isometry3::from_parts(
            nalgebra::Translation3::new(0.05, 0.0, -0.1),
            nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.02, 0.01),
        );
        tracker.last_motion = motion;
        tracker.motion_known = true;
        assert!(tracker.predict_segments(&previous, &mut out));
        let expected = [at(0.25), at(0.75)].map(|x| project(motion * x));
        assert!((out[0].start - expected[0]).norm() < 1e-9, "{:?}", out[0]);
        assert!((out[0].end - expected[1]).norm() < 1e-9, "{:?}", out[0]);
        // Without a landmark a segment stays where it was.
        assert_eq!(out[1], elsewhere);
    }

    #[test]
    fn a_resumed_tracker_predicts_across_the_frames_it_missed() {
        use nalgebra::{Translation3, UnitQuaternion};
        let mut tracker =
            MotionTracker::new(OdometryConfig::default(), StereoRig::default()).unwrap();
        let pose = Isometry3::from_parts(
            Translation3::new(1.0, 0.0, 2.0),
            UnitQuaternion::from_euler_angles(0.0, 0.3, 0.0),
        );
        // Points come 5 cm nearer per frame: the camera moves 5 cm forward.
        let motion = Isometry3::translation(0.0, 0.0, -0.05);
        tracker.resume_from(pose, motion);
        tracker.predict_frames(3);
        let expected = pose * Isometry3::translation(0.0, 0.0, 0.15);
        assert!((tracker.pose().translation.vector - expected.translation.vector).norm() < 1e-12);
        // Absurd gaps are capped rather than looped over.
        tracker.predict_frames(u64::MAX);
        assert!(
            tracker
                .pose()
                .translation
                .vector
                .iter()
                .all(|v| v.is_finite())
        );
    }

    #[test]
    fn stereo_segments_on_the_wrong_edge_fail_the_photometric_check() {
        // Left: a textured bar with a slanted edge at x = 100 + 0.3 y. Right: the same
        // scene 20 px further left, under another gain and bias; a second edge of the bar
        // lies 3 px to the right of the true partner.
        let (width, height) = (240usize, 120usize);
        let scene = |x: f64, y: f64| -> f64 {
            let u = x - 0.3 * y;
            let texture = 30.0 * ((0.7 * y).sin() + 0.5 * (1.3 * y).cos());
            if u < 100.0 {
                40.0
            } else if u < 103.0 {
                200.0 + texture
            } else {
                90.0 + 0.5 * texture
            }
        };
        let render = |shift: f64, gain: f64, bias: f64| {
            let pixels: Vec<u8> = (0..height)
                .flat_map(|y| (0..width).map(move |x| (x, y)))
                .map(|(x, y)| {
                    // 4 × 4 supersampling: anti-aliased edges.
                    let mut sum = 0.0;
                    for k in 0..16 {
                        let (dx, dy) = ((k % 4) as f64 / 4.0, (k / 4) as f64 / 4.0);
                        sum += scene(x as f64 + dx + shift, y as f64 + dy);
                    }
                    (gain * sum / 16.0 + bias).clamp(0.0, 255.0) as u8
                })
                .collect();
            GrayImage::from_pixels(width, height, &pixels, "test").unwrap()
        };
        let left = render(0.0, 1.0, 0.0);
        let right = render(20.0, 0.6, 25.0);
        let edge = |x0: f64| Segment::new(Point::new(x0 + 6.0, 20.0), Point::new(x0 + 27.0, 90.0));
        let left_segments = [edge(100.0)];
        let right_segments = [edge(80.0), edge(83.0), edge(81.5)];
        let mut tracker =
            MotionTracker::new(OdometryConfig::default(), StereoRig::default()).unwrap();
        let lines = MatchedLines {
            left: &left_segments,
            right: &right_segments,
            stereo: &[],
            tracked: None,
        };
        assert!(tracker.photometric_profiles(Some((&left, &right)), &lines));
        assert!(tracker.photometric_agreement(0, 0), "the true partner");
        assert!(!tracker.photometric_agreement(0, 1), "the bar's other edge");
        assert!(!tracker.photometric_agreement(0, 2), "1.5 px off the edge");
        // Switched off, nothing is checked.
        tracker.config.stereo_photometric.enabled = false;
        assert!(!tracker.photometric_profiles(Some((&left, &right)), &lines));
    }

    #[test]
    fn a_tracked_point_is_triangulated_where_it_was_tracked() {
        // A smooth texture; the right image sees it 12.4 px further left.
        let (width, height) = (200usize, 120usize);
        let scene = |x: f64, y: f64| {
            128.0
                + 40.0 * (0.31 * x + 0.17 * y).sin()
                + 30.0 * (0.23 * y - 0.11 * x).cos()
                + 20.0 * (0.53 * x).sin() * (0.41 * y).cos()
        };
        let render = |shift: f64| {
            let pixels: Vec<u8> = (0..height)
                .flat_map(|y| (0..width).map(move |x| (x as f64, y as f64)))
                .map(|(x, y)| scene(x + shift, y).clamp(0.0, 255.0) as u8)
                .collect();
            GrayImage::from_pixels(width, height, &pixels, "test").unwrap()
        };
        let (left, right) = (render(0.0), render(12.4));
        let rig = StereoRig::default();
        let mut tracker = MotionTracker::new(OdometryConfig::default(), rig).unwrap();
        // The detector put the corner on (101, 61) of a coarse level; tracking found the
        // previous frame's point at (100.3, 60.7). Its stereo partner was detected at
        // (88, 61).
        let tracked = Point::new(100.3, 60.7);
        let mut points = PointFeatures {
            points: vec![Point::new(101.0, 61.0), Point::new(150.0, 30.0)],
            levels: vec![3, 0],
            ..PointFeatures::default()
        };
        let mut fresh = Triangulations {
            points: Vec::new(),
            lines: Vec::new(),
        };
        tracker.tracking.refined = vec![(0, tracked)];
        tracker.stereo_partners = vec![Some((Point::new(88.0, 61.0), 0.35)), None];
        tracker.anchor_refined_points(&mut points);
        let mut stats = FrameStats::default();
        let limits = TriangulationLimits::default();
        tracker.triangulate_points(
            Some((&left, &right)),
            &points,
            &mut fresh,
            &limits,
            &mut stats,
        );
        // The point is where it was tracked, for the next frame's tracking too…
        assert_eq!(points.points[0], tracked);
        assert_eq!(points.points[1], Point::new(150.0, 30.0));
        // …and triangulated there, at the texture's disparity.
        let (position, weight) = fresh.points[0].expect("triangulated");
        let seen = rig.project_left(&position).unwrap();
        assert!((seen - tracked).norm() < 1e-9, "{seen:?}");
        let disparity = rig.focal_px * rig.baseline_m / position.z;
        assert!((disparity - 12.4).abs() < 0.1, "disparity {disparity}");
        assert!(weight > 0.0 && weight <= 0.35 + 1e-12, "weight {weight}");
        // A point without a stereo partner is not triangulated.
        assert_eq!(fresh.points[1], None);
        assert_eq!(stats.triangulated[0], 1);
    }

    #[test]
    fn the_documented_config_file_holds_the_defaults() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/odometry.toml");
        let config = OdometryConfig::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(config, OdometryConfig::default());
    }

    #[test]
    fn look_alikes_are_several_parallel_partners_nearby() {
        let gates = AppearanceGates::default();
        let left = Segment::from_coords(300.0, 100.0, 300.0, 200.0);
        let right = Segment::from_coords(280.0, 100.0, 280.0, 200.0);
        let stripe = |x: f64| SegmentFeatures::new(&Segment::from_coords(x, 101.0, x, 199.0)).ok();
        // One other parallel edge (a door frame's second side) is not enough…
        let one = [stripe(280.0), stripe(268.0)];
        assert!(!has_look_alike(&left, &right, &one, &gates));
        // …two are: a stripe pattern.
        let stripes = [stripe(292.0), stripe(280.0), stripe(268.0)];
        assert!(has_look_alike(&left, &right, &stripes, &gates));
        // Tilted, short or far ones do not count.
        let unlike = [
            SegmentFeatures::new(&Segment::from_coords(268.0, 100.0, 290.0, 200.0)).ok(),
            SegmentFeatures::new(&Segment::from_coords(292.0, 140.0, 292.0, 160.0)).ok(),
            stripe(200.0),
        ];
        assert!(!has_look_alike(&left, &right, &unlike, &gates));
    }
}
