//! [`Odometry`], the whole PL-StVO over stereo frames: its own front end detects, describes
//! and matches the segments (stereo, and against the previous frame where the last motion
//! predicts them), and a [`MotionTracker`] does the rest.

use crate::stats::since;
use crate::{
    Features, FrameResult, FrameStats, LinePrediction, MatchedLines, MotionTracker, OdometryConfig,
    OdometryError, Preparation,
};
use linetrack_geometry::{MatchCase, Segment, StereoRig};
use linetrack_vision::{
    FeatureMatch, GrayImage, LineDetector, LineFeatures, MatcherKind, SegmentMatcher,
    create_detector, create_segment_matcher,
};
use nalgebra::Isometry3;
use std::time::Instant;

/// The odometry: feed frames in order with [`Odometry::track`].
pub struct Odometry {
    detector: Box<dyn LineDetector>,
    matcher: Box<dyn SegmentMatcher>,
    /// The same matcher with the frame-to-frame gate around predicted segments widened to
    /// `lost.rescue_window_px` and collinear pieces no rivals (`lost.rescue_collinear_px`),
    /// for frames that would be lost (lines only; `None`: both off).
    rescue_matcher: Option<Box<dyn SegmentMatcher>>,
    previous_lines: Option<LineFeatures>,
    segments: SegmentTracking,
    tracker: MotionTracker,
}

impl Odometry {
    /// An odometry for frames from `rig`.
    pub fn new(config: OdometryConfig, rig: StereoRig) -> Result<Self, OdometryError> {
        Ok(Self {
            detector: create_detector(config.detector, &config.frontend)?,
            matcher: create_segment_matcher(config.matcher, &config.tracking_frontend())?,
            rescue_matcher: rescue_matcher(&config, config.matcher)?,
            previous_lines: None,
            segments: SegmentTracking::default(),
            tracker: MotionTracker::new(config, rig)?,
        })
    }

    /// The stereo matches the last frame was triangulated from
    /// ([`MotionTracker::stereo_sightings`]).
    pub fn stereo_sightings(&self) -> Vec<crate::StereoSighting> {
        self.tracker.stereo_sightings()
    }

    /// Tracks one stereo frame (rectified, the rig's size).
    pub fn track(
        &mut self,
        left: &GrayImage,
        right: &GrayImage,
    ) -> Result<FrameResult, OdometryError> {
        let mut stats = FrameStats::default();
        // The pipeline's steps, one after the other: the images stretched, their corners
        // found and the points' work done (its time counted apart)…
        let prepared = self
            .tracker
            .prepare(left, right, Preparation::CornersAndPoints)?;
        // …then the segments detected (stretched once, for the detectors and the back
        // end's corners alike), described and matched.
        let started = Instant::now();
        let (seen_left, seen_right) = prepared.seen(left, right);
        let (mut lines_l, mut lines_r) = (LineFeatures::default(), LineFeatures::default());
        self.detector.detect(seen_left, &mut lines_l.segments)?;
        self.detector.detect(seen_right, &mut lines_r.segments)?;
        stats.detect_ms = since(started);
        let started = Instant::now();
        self.matcher.describe(seen_left, &mut lines_l)?;
        self.matcher.describe(seen_right, &mut lines_r)?;
        stats.describe_ms = since(started);
        stats.segments = [lines_l.segments.len(), lines_r.segments.len()];

        let started = Instant::now();
        let mut stereo = Vec::new();
        self.matcher
            .match_lines(MatchCase::Stereo, &lines_l, &lines_r, &mut stereo);
        stats.stereo_ms = since(started);
        // With points first, the frame's points give the motion its segments are predicted
        // with (timed as motion estimation).
        let started = Instant::now();
        if self.previous_lines.is_some()
            && self.tracker.config().line_prediction == LinePrediction::PointsFirst
        {
            self.tracker.predict_from_points(&prepared);
        }
        let points_first_ms = since(started);
        let started = Instant::now();
        let mut tracked = Vec::new();
        if let Some(previous) = &mut self.previous_lines {
            let (matcher, tracker) = (self.matcher.as_mut(), &mut self.tracker);
            if self
                .segments
                .match_predicted(matcher, tracker, previous, &lines_l, &mut tracked)
            {
                let wider = (self.rescue_matcher.as_mut())
                    .map(|m| -> &mut dyn SegmentMatcher { m.as_mut() });
                stats.rescued =
                    self.segments
                        .rescue(wider, tracker, previous, &lines_l, &mut tracked);
            } else {
                matcher.match_lines(MatchCase::FrameToFrame, previous, &lines_l, &mut tracked);
                self.segments
                    .rematch(matcher, tracker, previous, &lines_l, &mut tracked);
            }
        }
        stats.frame_to_frame_ms = since(started);
        stats.motion_ms = points_first_ms;
        let lines = MatchedLines {
            left: &lines_l.segments,
            right: &lines_r.segments,
            stereo: &stereo,
            tracked: self.previous_lines.as_ref().map(|_| tracked.as_slice()),
        };
        // (The preparation's milliseconds are added to `detect_ms`.)
        let result = self
            .tracker
            .update_prepared(Some(((left, right), prepared)), lines, stats);
        self.previous_lines = Some(lines_l);
        result
    }
}

/// The `kind` matcher of `lost.rescue_window_px` and `lost.rescue_collinear_px` for
/// [`SegmentTracking::rescue`] (lines only), if either is on for it: the one `config`
/// tracks with, its frame-to-frame gate around a predicted segment widened to the window
/// and (ℓ1) pieces of one edge no rivals.
pub fn rescue_matcher(
    config: &OdometryConfig,
    kind: MatcherKind,
) -> Result<Option<Box<dyn SegmentMatcher>>, OdometryError> {
    let lost = &config.lost;
    let collinear = lost.rescue_collinear_px > 0.0 && kind == MatcherKind::L1;
    if (lost.rescue_window_px <= 0.0 && !collinear) || config.features != Features::LinesOnly {
        return Ok(None);
    }
    let mut frontend = config.tracking_frontend();
    if lost.rescue_window_px > 0.0 {
        frontend.l1.predicted.max_displacement_px = lost.rescue_window_px;
        frontend.appearance_gates.max_displacement_px = lost.rescue_window_px;
    }
    if collinear {
        frontend.l1.predicted.collinear_px = lost.rescue_collinear_px;
    }
    Ok(Some(create_segment_matcher(kind, &frontend)?))
}

/// Frame-to-frame segment matching guided by the motion: the last frame's segments looked
/// for where the predicted motion puts them, and a frame matched without a prediction
/// matched again where its own segments' motion puts them (`rematch_passes`). Both front
/// ends use it: [`Odometry`] for every frame, the pipeline's pose estimator for the frames
/// the matcher stage matched with the ℓ1 matcher (it alone knows the motion).
#[derive(Debug, Default)]
pub struct SegmentTracking {
    /// Where the motion moves the previous frame's segments (kept between frames).
    predicted: Vec<Segment>,
    /// Which of `predicted` were moved by the motion (the others have no landmark).
    moved: Vec<bool>,
}

/// Whether the odometry tracks lines only and `tracked` (matches of the last frame's
/// segments with `current`'s) would lose the frame: when the rescues act.
fn lines_only_and_lost(
    tracker: &MotionTracker,
    current: &LineFeatures,
    tracked: &[FeatureMatch],
) -> bool {
    tracker.config().features == Features::LinesOnly
        && tracker
            .loss_on_lines(&current.segments, tracked, None)
            .is_some()
}

impl SegmentTracking {
    /// `matcher`'s matches of `previous`'s segments, at the positions last predicted for
    /// them, with `current`'s, into `out` (`previous` is left as it was).
    fn match_at_predicted(
        &mut self,
        matcher: &mut dyn SegmentMatcher,
        previous: &mut LineFeatures,
        current: &LineFeatures,
        out: &mut Vec<FeatureMatch>,
    ) {
        std::mem::swap(&mut previous.segments, &mut self.predicted);
        matcher.match_predicted(previous, &self.moved, current, out);
        std::mem::swap(&mut previous.segments, &mut self.predicted);
    }

    /// Replaces `tracked` by the matches of `previous`'s segments (the frame the tracker
    /// tracked last) to `current`'s at the positions the predicted motion gives them, and
    /// returns true; returns false, leaving `tracked` alone, when the config or the
    /// matcher does not match predicted positions or no motion is known yet.
    pub fn match_predicted(
        &mut self,
        matcher: &mut dyn SegmentMatcher,
        tracker: &MotionTracker,
        previous: &mut LineFeatures,
        current: &LineFeatures,
        tracked: &mut Vec<FeatureMatch>,
    ) -> bool {
        let predicting = tracker.config().predicted_matching
            && matcher.matches_predicted_positions()
            && tracker.predict_segments(&previous.segments, &mut self.predicted, &mut self.moved);
        if predicting {
            self.match_at_predicted(matcher, previous, current, tracked);
        }
        predicting
    }

    /// After [`SegmentTracking::match_predicted`], lines only (with points it returns false
    /// at once): when the frame would be lost with `tracked`, replaces it by `wider`'s
    /// matches at the same predicted positions if those give a believed estimate; failing that, with `lost.rescue_min_inliers`, by
    /// the first of the two match sets (`wider`'s, then `tracked`) believed with that many
    /// inliers, and lets the update accept it so. Leaves `tracked` and the tracker alone
    /// when the frame would not be lost or nothing rescues it; returns whether it rescued.
    pub fn rescue(
        &mut self,
        wider: Option<&mut dyn SegmentMatcher>,
        tracker: &mut MotionTracker,
        previous: &mut LineFeatures,
        current: &LineFeatures,
        tracked: &mut Vec<FeatureMatch>,
    ) -> bool {
        let min_inliers = tracker.config().lost.rescue_min_inliers;
        if (wider.is_none() && min_inliers == 0) || !lines_only_and_lost(tracker, current, tracked)
        {
            return false;
        }
        let mut widened = Vec::new();
        if let Some(matcher) = wider {
            self.match_at_predicted(matcher, previous, current, &mut widened);
            if tracker
                .loss_on_lines(&current.segments, &widened, None)
                .is_none()
            {
                *tracked = widened;
                return true;
            }
        }
        if min_inliers == 0 {
            return false;
        }
        let believed = |matches: &[FeatureMatch]| {
            tracker
                .loss_on_lines(&current.segments, matches, Some(min_inliers))
                .is_none()
        };
        if !widened.is_empty() && believed(&widened) {
            *tracked = widened;
        } else if !believed(tracked) {
            return false;
        }
        tracker.accept_with_inliers(min_inliers);
        true
    }

    /// Lines only: when `tracked` (another matcher's matches of `previous`'s segments with
    /// `current`'s, made around their old positions) would lose the frame, matches them
    /// again with `l1` where the motion predicts them, and with `rescue` (the matcher of
    /// [`rescue_matcher`]) if that would lose it too, and replaces `tracked` by the first
    /// of those that gives a believed estimate; returns whether it did. `previous` and
    /// `current` are described for `l1`. Leaves `tracked` alone otherwise (with points, a
    /// frame that would not be lost, no motion known yet, or no believed estimate).
    pub fn fall_back_to_l1(
        &mut self,
        l1: &mut dyn SegmentMatcher,
        rescue: Option<&mut dyn SegmentMatcher>,
        tracker: &mut MotionTracker,
        previous: &mut LineFeatures,
        current: &LineFeatures,
        tracked: &mut Vec<FeatureMatch>,
    ) -> bool {
        if !lines_only_and_lost(tracker, current, tracked) {
            return false;
        }
        let mut matches = Vec::new();
        if !self.match_predicted(l1, tracker, previous, current, &mut matches) {
            return false;
        }
        let believed = tracker
            .loss_on_lines(&current.segments, &matches, None)
            .is_none()
            || self.rescue(rescue, tracker, previous, current, &mut matches);
        if believed {
            *tracked = matches;
        }
        believed
    }

    /// Replaces `tracked` (`previous` → `current` matches made around the old positions)
    /// by the pass whose motion has the most inlying segments, and predicts the frame's
    /// segments with that motion; leaves both as they were when no pass gives a motion,
    /// and does nothing with `rematch_passes = 0` or a matcher that does not match
    /// predicted positions.
    pub fn rematch(
        &mut self,
        matcher: &mut dyn SegmentMatcher,
        tracker: &mut MotionTracker,
        previous: &mut LineFeatures,
        current: &LineFeatures,
        tracked: &mut Vec<FeatureMatch>,
    ) {
        let passes = tracker.config().rematch_passes;
        if passes == 0
            || !tracker.config().predicted_matching
            || !matcher.matches_predicted_positions()
        {
            return;
        }
        let mut best: Option<(usize, Isometry3<f64>, Vec<FeatureMatch>)> = None;
        let mut pass = tracked.clone();
        for done in 0..=passes {
            let Some((motion, inliers)) = tracker.segments_motion(&current.segments, &pass) else {
                break;
            };
            if best.as_ref().is_none_or(|(most, ..)| inliers >= *most) {
                best = Some((inliers, motion, pass.clone()));
            }
            tracker.predict_segments_with(motion);
            if done == passes
                || !tracker.predict_segments(
                    &previous.segments,
                    &mut self.predicted,
                    &mut self.moved,
                )
            {
                break;
            }
            pass.clear();
            self.match_at_predicted(matcher, previous, current, &mut pass);
        }
        if let Some((_, motion, matches)) = best {
            tracker.predict_segments_with(motion);
            *tracked = matches;
        }
    }
}
