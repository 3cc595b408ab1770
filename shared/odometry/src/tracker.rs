//! The back end, [`MotionTracker`]: a frame's matched features triangulated, the previous
//! frame's landmarks observed in it, the motion estimated and judged, and the landmarks
//! handed on. Its parts: [`prepare`] (what needs only the images: the stretch, the corners
//! and the points' work done ahead), [`points`] (stereo partners, frame-to-frame search
//! and triangulation of the ORB points) and [`segments`] (stereo segments checked and
//! triangulated, their landmarks observed and predicted).

mod points;
mod prepare;
mod segments;

pub use prepare::{Preparation, PreparedImages};

use crate::disparity_offset::DisparityOffset;
use crate::landmarks::{Geometry, Landmark, sighted};
use crate::stats::since;
use crate::{FrameResult, FrameStats, LostKind, OdometryConfig, OdometryError};
use linetrack_geometry::{Point, Segment, SegmentFeatures, StereoRig};
use linetrack_l1_matcher::SegmentProfiles;
use linetrack_stereo_vo::observation::{line_residual, normalised_line, point_residual};
use linetrack_stereo_vo::{
    LineObservation, MotionError, MotionEstimate, PointObservation, TriangulationLimits,
    estimate_motion, estimate_motion_near,
};
use linetrack_vision::{
    FeatureMatch, GrayImage, OrbWorker, PointExtractor, PointFeatures, PointMatcher, RowSearch,
};
use nalgebra::{Isometry3, Point3};
use points::{PointTracking, PointWorkMs, search_radius_px};
use prepare::PointsAhead;
use std::time::Instant;

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

/// A frame's images as tracking sees them (stretched where they were), with what was
/// prepared from them.
struct SeenImages<'a> {
    /// Left and right.
    images: (&'a GrayImage, &'a GrayImage),
    /// ORB points of the left and right image (with `[orb] stereo = "row-search"`, the
    /// right ones are the left points' partners, found with the stereo matches).
    points: [PointFeatures; 2],
    /// The left image's stretch gain (1: not stretched).
    left_gain: f64,
    /// The milliseconds of the frame's point work when
    /// [`Preparation::CornersAndPoints`] did it for this frame and no frame was tracked
    /// since; `None`: it is done with the segments.
    points_ahead: Option<PointWorkMs>,
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
    /// The disparity offset its fresh features were triangulated with, pixels.
    disparity_offset_px: f64,
}

/// Gives each segment observation the line of its current left segment's stereo partner
/// in the right image, where that match was triangulated this frame (so it passed the
/// photometric and look-alike checks).
fn observe_right_lines(
    observations: &mut Observations,
    fresh: &Triangulations,
    lines: &MatchedLines<'_>,
) {
    for (obs, &(_, j)) in observations.lines.iter_mut().zip(&observations.line_pairs) {
        obs.right_line = None;
        if !matches!(fresh.lines.get(j), Some(Some(_))) {
            continue;
        }
        obs.right_line = lines
            .stereo
            .iter()
            .find(|m| m.query == j)
            .and_then(|m| lines.right.get(m.train))
            .and_then(normalised_line);
    }
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

/// What a [`StereoSighting`] is of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SightingKind {
    /// A stereo point match (ORB).
    Point,
    /// One endpoint of a stereo segment match.
    SegmentEndpoint,
}

/// A stereo match the tracker triangulated: where it is in the left image and the
/// disparity its depth came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoSighting {
    /// Point or segment endpoint.
    pub kind: SightingKind,
    /// Its pixel in the left image.
    pub left: Point,
    /// Its disparity, pixels (the depth is focal × baseline over it).
    pub disparity_px: f64,
}

/// The back end: given matched segments (and the images, for ORB points), triangulates,
/// finds the previous frame's 3-D features again and estimates the motion.
/// [`Odometry`](crate::Odometry) runs it after its own front end; the pipeline's pose stage
/// runs it on the matcher stage's output.
pub struct MotionTracker {
    config: OdometryConfig,
    rig: StereoRig,
    /// One ORB extractor per image: the two run at the same time, the right one on a
    /// thread of its own.
    orb_left: PointExtractor,
    orb_right: OrbWorker,
    /// Stereo matching of the points by descriptor (`[orb] stereo = "descriptors"`)…
    point_matcher: PointMatcher,
    /// …or along the right image's rows (`"row-search"`: the right image is not extracted).
    row_search: RowSearch,
    /// Frame-to-frame matching of the points.
    tracking: PointTracking,
    reference: Option<Reference>,
    pose: Isometry3<f64>,
    last_motion: Isometry3<f64>,
    /// Whether `last_motion` was measured (not the identity of a fresh start) and is still
    /// trusted to predict the next frame.
    motion_known: bool,
    /// Frames lost in a row since the last estimate that was believed.
    losses_in_row: u32,
    /// The motion this frame's segments are predicted with when it is not `last_motion`
    /// ([`LinePrediction::PointsFirst`](crate::LinePrediction)): set before the frame's
    /// segments are matched, used up by its update.
    segment_motion: Option<Isometry3<f64>>,
    /// How many inliers this frame's estimate needs under the prior when it is not
    /// `motion.min_inliers_with_prior` (a rescued frame, `lost.rescue_min_inliers`): set
    /// before the frame is tracked, used up by its update.
    min_inliers_now: Option<usize>,
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
    /// The rig's disparity offset, subtracted before triangulating.
    disparity_offset: DisparityOffset,
    spares: Spares,
}

impl MotionTracker {
    /// A tracker starting at the identity pose.
    pub fn new(config: OdometryConfig, rig: StereoRig) -> Result<Self, OdometryError> {
        Ok(Self {
            orb_left: PointExtractor::new(&config.frontend.orb)?,
            orb_right: OrbWorker::new(&config.frontend.orb)?,
            point_matcher: PointMatcher::new(),
            row_search: RowSearch::new(),
            tracking: PointTracking::default(),
            reference: None,
            pose: Isometry3::identity(),
            last_motion: Isometry3::identity(),
            motion_known: false,
            losses_in_row: 0,
            segment_motion: None,
            min_inliers_now: None,
            profiles: Default::default(),
            reference_image: None,
            points_ahead: None,
            stereo_partners: Vec::new(),
            disparity_offset: DisparityOffset::new(config.disparity_offset),
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
        self.losses_in_row = 0;
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

    /// Every point and segment endpoint the last frame tracked was triangulated from (its
    /// fresh stereo matches, before they are fused with landmarks), with the disparity each
    /// depth came from: for checking disparities against a ground truth.
    pub fn stereo_sightings(&self) -> Vec<StereoSighting> {
        let rig = &self.rig;
        let sighting = |kind, p: &Point3<f64>| StereoSighting {
            kind,
            left: Point::new(
                rig.focal_px * p.x / p.z + rig.cx_px,
                rig.focal_px * p.y / p.z + rig.cy_px,
            ),
            disparity_px: rig.focal_px * rig.baseline_m / p.z,
        };
        let fresh = &self.spares.lists.fresh;
        let points = fresh
            .points
            .iter()
            .flatten()
            .map(|(p, _)| sighting(SightingKind::Point, p));
        let endpoints = fresh.lines.iter().flatten().flat_map(|(ends, _)| {
            ends.iter()
                .map(|p| sighting(SightingKind::SegmentEndpoint, p))
        });
        points.chain(endpoints).collect()
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

    /// The config it was built with.
    pub(crate) fn config(&self) -> &OdometryConfig {
        &self.config
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
        self.segment_motion = None;
        self.min_inliers_now = None;
        // Point work done ahead for another frame is stale now.
        self.points_ahead = None;
        result
    }

    /// [`MotionTracker::update_stretched`] with the frame's lists (cleared here, but for
    /// the points' stereo matches and observations when they were made ahead): the frame's
    /// stereo matches triangulated, then, when it continues from the reference frame, the
    /// reference's landmarks observed, the motion estimated and judged.
    fn track_frame(
        &mut self,
        lists: &mut FrameLists,
        images: Option<SeenImages<'_>>,
        lines: MatchedLines<'_>,
        mut stats: FrameStats,
    ) -> Result<FrameResult, OdometryError> {
        let limits = TriangulationLimits {
            min_sin_from_horizontal: self.config.min_line_angle_deg.to_radians().sin(),
            disparity_offset_px: self.disparity_offset.value_px(),
            ..TriangulationLimits::default()
        };
        stats.disparity_offset_px = limits.disparity_offset_px;
        let stereo_images = images.as_ref().map(|seen| seen.images);
        let (images, [mut points_l, points_r]) =
            self.frame_points(lists, images, lines.tracked.is_some(), &mut stats);
        stats.points = [points_l.points.len(), points_r.points.len()];
        keep_spare(&mut self.spares.points, points_r);
        self.triangulate_segments(lists, stereo_images, &lines, &limits, &mut stats);

        let left_image = images.map(|(left, _)| left);
        let Some(previous) = self.reference.take().filter(|_| lines.tracked.is_some()) else {
            // First frame, or not matched against the previous one: start again from here.
            self.triangulate_points(images, &points_l, &mut lists.fresh, &limits, &mut stats);
            self.reference = Some(self.fresh_reference(self.pose, points_l, &lists.fresh));
            self.keep_reference_image(left_image);
            return Ok(self.result(None, stats));
        };
        self.observe_landmarks(
            &previous,
            &lines,
            &mut points_l,
            left_image,
            &mut lists.observations,
            &mut stats,
        );
        self.triangulate_points(images, &points_l, &mut lists.fresh, &limits, &mut stats);
        if self.config.motion.stereo_reprojection {
            self.observe_right_columns(&mut lists.observations, &lists.fresh);
            observe_right_lines(&mut lists.observations, &lists.fresh, &lines);
        }
        let verdict = self.estimate(&lists.observations, self.min_inliers_now, &mut stats);
        Ok(self.conclude(verdict, previous, points_l, lists, stats))
    }

    /// Observations of `previous`'s landmarks in this frame (its points' are made already):
    /// this frame's `points_l` tracked to a fraction of a pixel moved to where they were
    /// tracked, and its segments' observations added. `left_image` (the images' left one,
    /// `None` when tracked without points) is kept as the next frame's reference.
    fn observe_landmarks(
        &mut self,
        previous: &Reference,
        lines: &MatchedLines<'_>,
        points_l: &mut PointFeatures,
        left_image: Option<&GrayImage>,
        observations: &mut Observations,
        stats: &mut FrameStats,
    ) {
        // Previous landmarks seen again now (the points' observations are made).
        let started = Instant::now();
        observations.lines.clear();
        observations.line_pairs.clear();
        if left_image.is_some() && self.config.subpixel_tracking {
            self.anchor_refined_points(points_l);
        }
        // This frame is the next one's reference whatever the estimate gives.
        self.keep_reference_image(left_image);
        self.observe_lines(
            previous,
            lines.left,
            lines.tracked.unwrap_or_default(),
            observations,
        );
        stats.observations = [observations.points.len(), observations.lines.len()];
        stats.frame_to_frame_ms += since(started);
    }

    /// Gives each point observation the right image's column of its current stereo
    /// partner, where the point was triangulated this frame (the refined column when
    /// `subpixel_stereo` is on: the triangulation's own).
    fn observe_right_columns(&self, observations: &mut Observations, fresh: &Triangulations) {
        let rig = &self.rig;
        for (obs, &(_, j)) in observations
            .points
            .iter_mut()
            .zip(&observations.point_pairs)
        {
            obs.right_x = fresh
                .points
                .get(j)
                .copied()
                .flatten()
                .map(|(p, _)| rig.focal_px * (p.x - rig.baseline_m) / p.z + rig.cx_px);
        }
    }

    /// The motion from `observations` (the constant-velocity prior only once a motion was
    /// measured; under it `min_inliers` inliers are enough when given, else
    /// `motion.min_inliers_with_prior`), its figures written to `stats`; `Err` says why
    /// there is none or why it is not believed.
    fn estimate(
        &self,
        observations: &Observations,
        min_inliers: Option<usize>,
        stats: &mut FrameStats,
    ) -> Result<MotionEstimate, (LostKind, String)> {
        let started = Instant::now();
        let mut config = self.config.motion;
        if let Some(n) = min_inliers {
            config.min_inliers_with_prior = n;
        }
        let (rig, config) = (&self.rig, &config);
        let (points, lines) = (&observations.points, &observations.lines);
        let estimate = if self.motion_known {
            estimate_motion_near(rig, points, lines, &self.last_motion, config)
        } else {
            estimate_motion(rig, points, lines, &self.start_of_estimate(), config)
        };
        stats.motion_ms += since(started);
        let prediction = self.last_motion;
        let kind = |why: &MotionError| match why {
            MotionError::TooFewInliers { .. } => LostKind::TooFewInliers,
            MotionError::Degenerate { .. } => LostKind::Degenerate,
        };
        estimate
            .map_err(|why| (kind(&why), why.to_string()))
            .and_then(|e| {
                stats.inliers = [e.inlier_points, e.inlier_lines];
                stats.iterations = e.iterations;
                stats.rms_px = e.rms_px;
                stats.conditioning = e.relative_eigenvalue;
                stats.departure = departure(&prediction, &e.motion);
                match self.departs_sharply(&prediction, stats.departure) {
                    Some(why) if self.motion_known => Err((LostKind::Departed, why)),
                    _ => Ok(e),
                }
            })
    }

    /// Moves on by the `verdict`'s motion, the frame's features (`points_l` and the fresh
    /// triangulations in `lists`) becoming the reference with the landmarks of `previous`
    /// they observed; or, when the estimate is not believed, reports the frame lost.
    fn conclude(
        &mut self,
        verdict: Result<MotionEstimate, (LostKind, String)>,
        previous: Reference,
        points_l: PointFeatures,
        lists: &FrameLists,
        stats: FrameStats,
    ) -> FrameResult {
        let (fresh, observations) = (&lists.fresh, &lists.observations);
        let step_covariance = verdict.as_ref().ok().and_then(|e| e.covariance);
        let reason = match verdict {
            Ok(e) => {
                self.last_motion = e.motion;
                self.motion_known = true;
                self.losses_in_row = 0;
                self.pose *= e.motion.inverse();
                let mut current = self.fresh_reference(self.pose, points_l, fresh);
                if self.config.landmarks {
                    self.carry_landmarks(&previous, &mut current, fresh, observations, &e.motion);
                }
                self.reference = Some(current);
                // After this frame's reference took the offset its features were
                // triangulated with.
                self.disparity_offset
                    .update(previous.disparity_offset_px, e.disparity_offset);
                self.reference_to_offset();
                None
            }
            Err(why) => {
                // Predict with the last good motion; this frame is the new reference. For
                // `lost.coast_frames` frames the next one is still matched and estimated
                // near that motion (a vehicle does not stop because a frame was lost);
                // after that it is searched over the full window and its estimate is not
                // held to the prediction, which may be what went wrong.
                self.pose *= self.last_motion.inverse();
                self.losses_in_row = self.losses_in_row.saturating_add(1);
                self.motion_known &= self.losses_in_row <= self.config.lost.coast_frames;
                self.reference = Some(self.fresh_reference(self.pose, points_l, fresh));
                Some(why)
            }
        };
        self.spares.keep_reference(previous);
        FrameResult {
            step_covariance,
            ..self.result(reason, stats)
        }
    }

    /// Moves the reference's landmarks to the disparity offset now applied, when it
    /// changed since they were triangulated (and fused): the next frame's evidence then
    /// measures what is still missing from that offset, not again the change.
    fn reference_to_offset(&mut self) {
        let now = self.disparity_offset.value_px();
        let Some(reference) = self.reference.as_mut() else {
            return;
        };
        // Subtracting `now` instead of the old offset grows each disparity by the difference.
        let more_px = reference.disparity_offset_px - now;
        if more_px == 0.0 {
            return;
        }
        let (pose, rig) = (reference.pose, &self.rig);
        for landmark in reference.point_landmarks.iter_mut() {
            *landmark = landmark.and_then(|l| l.with_disparities_grown(&pose, more_px, rig));
        }
        for landmark in reference.line_landmarks.iter_mut() {
            *landmark = landmark.and_then(|l| l.with_disparities_grown(&pose, more_px, rig));
        }
        reference.disparity_offset_px = now;
    }

    /// The frame's result at the current pose: lost when there is a `reason`.
    fn result(&self, reason: Option<(LostKind, String)>, mut stats: FrameStats) -> FrameResult {
        stats.disparity_offset_estimate_px = self.disparity_offset.estimate_px();
        let (lost_kind, reason) = reason.unzip();
        FrameResult {
            pose: self.pose,
            lost: reason.is_some(),
            reason,
            lost_kind,
            stats,
            step_covariance: None,
        }
    }

    /// A reference whose landmarks are this frame's fresh triangulations placed at `pose`.
    fn fresh_reference(
        &mut self,
        pose: Isometry3<f64>,
        points: PointFeatures,
        fresh: &Triangulations,
    ) -> Reference {
        Reference {
            disparity_offset_px: self.disparity_offset.value_px(),
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
}

/// How far `motion` lies from `prediction`: translation (metres) and rotation (degrees) of
/// the change between them.
fn departure(prediction: &Isometry3<f64>, motion: &Isometry3<f64>) -> [f64; 2] {
    let change = prediction.inverse() * motion;
    [
        change.translation.vector.norm(),
        change.rotation.angle().to_degrees(),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// Frames with nothing to track (no segments, no images) after a known motion: how
    /// far the next frame is searched after each lost frame, for `coast_frames`.
    fn search_radii_after_losses(coast_frames: u32) -> Vec<f64> {
        let mut config = OdometryConfig::default();
        config.lost.coast_frames = coast_frames;
        let mut tracker = MotionTracker::new(config, StereoRig::default()).unwrap();
        tracker.resume_from(
            Isometry3::identity(),
            Isometry3::translation(0.0, 0.0, -0.05),
        );
        let nothing = |tracked| MatchedLines {
            left: &[],
            right: &[],
            stereo: &[],
            tracked,
        };
        // Not matched against a previous frame: it becomes the reference, not lost.
        let first = tracker.update(None, nothing(None), FrameStats::default());
        assert!(!first.unwrap().lost);
        (0..3)
            .map(|_| {
                let result = tracker.update(None, nothing(Some(&[])), FrameStats::default());
                assert!(result.unwrap().lost);
                tracker.search_radius_px()
            })
            .collect()
    }

    #[test]
    fn after_a_loss_the_last_motion_predicts_for_the_coasting_frames_only() {
        let config = OdometryConfig::default();
        let (near, wide) = (config.predicted_window_px, config.max_displacement_px);
        assert!(near < wide);
        assert_eq!(search_radii_after_losses(0), [wide, wide, wide]);
        assert_eq!(search_radii_after_losses(1), [near, wide, wide]);
        assert_eq!(search_radii_after_losses(2), [near, near, wide]);
    }
}
