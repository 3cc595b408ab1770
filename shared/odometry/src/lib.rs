//! PL-StVO over a stream of rectified stereo frames.
//!
//! [`Odometry`] per frame: ORB points and line segments (LSD or FLD) are detected in both images and
//! matched stereo (segments with LBD or the ℓ1 matcher) and triangulated; the left image's
//! features are matched to the previous frame's (same matchers, frame-to-frame case); each
//! previous 3-D feature seen again becomes an observation, and the motion is estimated by
//! `linetrack-stereo-vo` (Gauss–Newton on SE(3), two passes), starting from the previous
//! motion (constant velocity). A frame with too few inliers or degenerate geometry is
//! reported as lost: its pose repeats the last motion, and it becomes the new reference so
//! tracking resumes on the next good frame instead of diverging.
//!
//! The back end alone, [`MotionTracker`], takes segments matched elsewhere (the pipeline's
//! matcher stage) and does the rest.
#![warn(missing_docs)]

pub mod metrics;

use linetrack_geometry::{MatchCase, Point, Segment, StereoRig};
use linetrack_stereo_vo::{
    LineObservation, MotionConfig, PointObservation, TriangulationLimits, disparity_weight,
    estimate_motion, triangulate_point, triangulate_segment,
};
use linetrack_vision::{
    AppearanceGates, DetectorKind, FeatureMatch, FrontendConfig, GrayImage, HammingMatcher,
    LineDetector, LineFeatures, MatcherKind, OrbExtractor, PointFeatures, SegmentMatcher,
    VisionError, create_detector, create_segment_matcher, match_points,
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
    /// Frame to frame, ORB points: the second-best Hamming distance must be at least this
    /// times the best (the stereo ratio is the front end's `orb.min_distance_ratio`).
    pub frame_to_frame_ratio: f64,
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
            frontend: FrontendConfig::default(),
            motion: MotionConfig::default(),
            max_displacement_px: 60.0,
            predicted_window_px: 30.0,
            frame_to_frame_ratio: 2.0,
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
            ("motion.ransac_threshold_px", self.motion.ransac_threshold_px),
        ];
        for (field, value) in positive {
            if !(value > 0.0 && value.is_finite()) {
                return Err(format!("field `{field}` = {value}: expected a finite number > 0"));
            }
        }
        if !(self.min_line_angle_deg >= 0.0 && self.min_line_angle_deg < 90.0) {
            return Err(format!(
                "field `min_line_angle_deg` = {}: expected a number in [0, 90)",
                self.min_line_angle_deg
            ));
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

/// The previous frame's 3-D features.
struct Reference {
    points: PointFeatures,
    point_positions: Vec<Option<(Point3<f64>, f64)>>,
    line_positions: Vec<Option<([Point3<f64>; 2], f64)>>,
}

/// The back end: given matched segments (and the images, for ORB points), triangulates,
/// finds the previous frame's 3-D features again and estimates the motion. [`Odometry`]
/// runs it after its own front end; the pipeline's pose stage runs it on the matcher
/// stage's output.
pub struct MotionTracker {
    config: OdometryConfig,
    rig: StereoRig,
    orb: OrbExtractor,
    hamming: HammingMatcher,
    reference: Option<Reference>,
    pose: Isometry3<f64>,
    last_motion: Isometry3<f64>,
    /// Whether `last_motion` was measured (not the identity of a fresh start).
    motion_known: bool,
}

impl MotionTracker {
    /// A tracker starting at the identity pose.
    pub fn new(config: OdometryConfig, rig: StereoRig) -> Result<Self, OdometryError> {
        Ok(Self {
            orb: OrbExtractor::new(&config.frontend.orb)?,
            hamming: HammingMatcher::new(),
            reference: None,
            pose: Isometry3::identity(),
            last_motion: Isometry3::identity(),
            motion_known: false,
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
    }

    /// The current pose.
    pub fn pose(&self) -> Isometry3<f64> {
        self.pose
    }

    /// The last frame-to-frame motion.
    pub fn last_motion(&self) -> Isometry3<f64> {
        self.last_motion
    }

    /// How far from its previous position a feature is searched for in the next frame:
    /// the predicted window once a motion is known, else the full displacement.
    pub fn search_radius_px(&self) -> f64 {
        if self.motion_known {
            self.config.predicted_window_px
        } else {
            self.config.max_displacement_px
        }
    }

    /// Where the previous frame's left segments are expected in the next frame: each
    /// triangulated one is moved by the last motion (constant velocity) and projected;
    /// the others stay where they were. `previous` are the segments given to the last
    /// [`MotionTracker::update`].
    pub fn predict_segments(&self, previous: &[Segment]) -> Vec<Segment> {
        let positions = self.reference.as_ref().map(|r| &r.line_positions);
        previous
            .iter()
            .enumerate()
            .map(|(k, segment)| {
                let Some(Some(([a, b], _))) = positions.and_then(|p| p.get(k)) else {
                    return *segment;
                };
                let project = |p: &Point3<f64>| self.rig.project_left(&(self.last_motion * p));
                match (project(a), project(b)) {
                    (Some(a), Some(b)) => Segment::new(a, b),
                    _ => *segment,
                }
            })
            .collect()
    }

    /// Tracks one frame: `lines` matched, `stats` already holding the front end's counts and
    /// timings. ORB points come from `images` (left, right) when the config uses points and
    /// the images are given; without them the frame is tracked on its lines.
    pub fn update(
        &mut self,
        images: Option<(&GrayImage, &GrayImage)>,
        lines: MatchedLines<'_>,
        mut stats: FrameStats,
    ) -> Result<FrameResult, OdometryError> {
        let limits = TriangulationLimits {
            min_sin_from_horizontal: self.config.min_line_angle_deg.to_radians().sin(),
            ..TriangulationLimits::default()
        };
        let images = images.filter(|_| self.config.features == Features::PointsAndLines);
        let use_points = images.is_some();

        let started = Instant::now();
        let (mut points_l, mut points_r) = (PointFeatures::default(), PointFeatures::default());
        if let Some((left, right)) = images {
            self.orb.extract(left, &mut points_l)?;
            self.orb.extract(right, &mut points_r)?;
        }
        stats.ms[0] += since(started);
        stats.points = [points_l.points.len(), points_r.points.len()];

        // Stereo triangulation.
        let started = Instant::now();
        let mut matches = Vec::new();
        let mut point_positions = vec![None; points_l.points.len()];
        if use_points {
            let gates = &self.config.frontend.appearance_gates;
            match_points(
                &mut self.hamming,
                MatchCase::Stereo,
                &points_l,
                &points_r,
                gates,
                self.config.frontend.orb.min_distance_ratio,
                &mut matches,
            );
            for m in &matches {
                if let Some(t) = triangulate_point(
                    &self.rig,
                    points_l.points[m.query],
                    points_r.points[m.train],
                    &limits,
                ) {
                    let weight = disparity_weight(t.disparity_px)
                        * self.level_weight(&points_l, m.query)
                        * self.level_weight(&points_r, m.train);
                    point_positions[m.query] = Some((t.position, weight));
                }
            }
        }
        let mut line_positions = vec![None; lines.left.len()];
        for m in lines.stereo {
            let (Some(l), Some(r)) = (lines.left.get(m.query), lines.right.get(m.train)) else {
                continue;
            };
            if let Some((a, b)) = triangulate_segment(&self.rig, l, r, &limits) {
                let weight =
                    0.5 * (disparity_weight(a.disparity_px) + disparity_weight(b.disparity_px));
                line_positions[m.query] = Some(([a.position, b.position], weight));
            }
        }
        stats.triangulated = [
            point_positions.iter().flatten().count(),
            line_positions.iter().flatten().count(),
        ];
        stats.ms[2] += since(started);

        let current = Reference {
            points: points_l,
            point_positions,
            line_positions,
        };
        let (Some(previous), Some(tracked)) = (self.reference.take(), lines.tracked) else {
            // First frame, or not matched against the previous one: start again from here.
            self.reference = Some(current);
            return Ok(FrameResult {
                pose: self.pose,
                lost: false,
                reason: None,
                stats,
            });
        };

        // Previous 3-D features seen again now.
        let started = Instant::now();
        let point_obs = if use_points {
            self.point_observations(&previous, &current, &mut matches)
        } else {
            Vec::new()
        };
        let line_obs = line_observations(&previous, lines.left, tracked);
        self.reference = Some(current);
        stats.observations = [point_obs.len(), line_obs.len()];
        stats.ms[3] += since(started);

        let started = Instant::now();
        let estimate = estimate_motion(
            &self.rig,
            &point_obs,
            &line_obs,
            &self.last_motion,
            &self.config.motion,
        );
        stats.ms[4] = since(started);
        match estimate {
            Ok(e) => {
                let prediction = self.last_motion;
                self.last_motion = e.motion;
                self.motion_known = true;
                self.pose *= e.motion.inverse();
                stats.inliers = [e.inlier_points, e.inlier_lines];
                stats.iterations = e.iterations;
                stats.rms_px = e.rms_px;
                stats.conditioning = e.relative_eigenvalue;
                let change = prediction.inverse() * e.motion;
                stats.departure = [
                    change.translation.vector.norm(),
                    change.rotation.angle().to_degrees(),
                ];
                Ok(FrameResult {
                    pose: self.pose,
                    lost: false,
                    reason: None,
                    stats,
                })
            }
            Err(why) => {
                // Predict with the last motion; this frame is the new reference.
                self.pose *= self.last_motion.inverse();
                Ok(FrameResult {
                    pose: self.pose,
                    lost: true,
                    reason: Some(why.to_string()),
                    stats,
                })
            }
        }
    }

    /// Weight of point `k` for its pyramid level: the inverse variance of its position,
    /// `scale_factor^(−2·level)` (1 at full resolution).
    fn level_weight(&self, features: &PointFeatures, k: usize) -> f64 {
        let level = features.levels.get(k).copied().unwrap_or(0);
        f64::from(self.config.frontend.orb.scale_factor).powi(-2 * i32::from(level))
    }

    /// Observations of `previous`'s triangulated points in `current`'s left image, searched
    /// for around where the last motion moves them.
    fn point_observations(
        &mut self,
        previous: &Reference,
        current: &Reference,
        scratch: &mut Vec<FeatureMatch>,
    ) -> Vec<PointObservation> {
        let mut points = Vec::new();
        if self.config.features == Features::PointsAndLines {
            let gates = AppearanceGates {
                max_displacement_px: self.search_radius_px(),
                ..self.config.frontend.appearance_gates
            };
            let mut predicted = previous.points.clone();
            for (point, position) in predicted.points.iter_mut().zip(&previous.point_positions) {
                if let Some(p) = position.and_then(|(x, _)| self.rig.project_left(&(self.last_motion * x))) {
                    *point = p;
                }
            }
            match_points(
                &mut self.hamming,
                MatchCase::FrameToFrame,
                &predicted,
                &current.points,
                &gates,
                self.config.frame_to_frame_ratio,
                scratch,
            );
            for m in scratch.iter() {
                if let Some(&Some((position, weight))) = previous.point_positions.get(m.query) {
                    let pixel: Point = current.points.points[m.train];
                    points.push(PointObservation {
                        position,
                        pixel,
                        weight: weight * self.level_weight(&current.points, m.train),
                    });
                }
            }
        }
        points
    }
}

/// Observations of `previous`'s triangulated segments among this frame's `left` segments.
fn line_observations(
    previous: &Reference,
    left: &[Segment],
    tracked: &[FeatureMatch],
) -> Vec<LineObservation> {
    let mut lines = Vec::new();
    for m in tracked {
        let (Some(&Some((endpoints, weight))), Some(seen)) =
            (previous.line_positions.get(m.query), left.get(m.train))
        else {
            continue;
        };
        if let Some(obs) = LineObservation::new(endpoints, seen, weight) {
            lines.push(obs);
        }
    }
    lines
}

/// The odometry: feed frames in order with [`Odometry::track`].
pub struct Odometry {
    detector: Box<dyn LineDetector>,
    matcher: Box<dyn SegmentMatcher>,
    previous_lines: Option<LineFeatures>,
    tracker: MotionTracker,
}

/// Errors that stop the odometry (bad configuration; per-frame problems are `lost`).
#[derive(Debug, thiserror::Error)]
pub enum OdometryError {
    /// The front end could not be built or failed on an image.
    #[error(transparent)]
    Vision(#[from] VisionError),
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
        let (mut lines_l, mut lines_r) = (LineFeatures::default(), LineFeatures::default());
        self.detector.detect(left, &mut lines_l.segments)?;
        self.detector.detect(right, &mut lines_r.segments)?;
        stats.ms[0] = since(started);
        let started = Instant::now();
        self.matcher.describe(left, &mut lines_l)?;
        self.matcher.describe(right, &mut lines_r)?;
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
            // Search around where the last motion moves the previous segments (within
            // the matcher's own frame-to-frame window).
            previous.segments = self.tracker.predict_segments(&previous.segments);
            self.matcher
                .match_lines(MatchCase::FrameToFrame, previous, &lines_l, &mut tracked);
        }
        stats.ms[3] = since(started);
        let lines = MatchedLines {
            left: &lines_l.segments,
            right: &lines_r.segments,
            stereo: &stereo,
            tracked: self.previous_lines.as_ref().map(|_| tracked.as_slice()),
        };
        let result = self.tracker.update(Some((left, right)), lines, stats);
        self.previous_lines = Some(lines_l);
        result
    }
}
