//! The segments' part of tracking a frame: stereo matches checked (photometrically, and
//! for look-alike partners on repetitive structure) and triangulated, the reference
//! frame's segment landmarks observed near the line the last motion predicts, and the
//! last frame's segments predicted for the front end's frame-to-frame matching.

use super::{FrameLists, MatchedLines, MotionTracker, Observations, Reference};
use crate::FrameStats;
use crate::landmarks::Geometry;
use crate::stats::since;
use linetrack_geometry::{
    MatchCase, Point, Segment, SegmentFeatures, direction_angle, length_ratio, overlap,
};
use linetrack_l1_matcher::GrayView;
use linetrack_stereo_vo::{
    LineObservation, TriangulationLimits, disparity_weight, estimate_motion, estimate_motion_near,
    triangulate_segment,
};
use linetrack_vision::{AppearanceGates, FeatureMatch, GrayImage};
use nalgebra::{Isometry3, Point3};
use std::time::Instant;

impl MotionTracker {
    /// Where the last frame's left segments (`previous`, as given to the last update) should
    /// lie in the next frame: each one that stands for a landmark is lifted onto the
    /// landmark's 3-D line, moved by the predicted motion (the last one, or the points'
    /// of [`MotionTracker::predict_from_points`]) and projected (and flagged in `moved`);
    /// the others stay where they were. Returns false, leaving `out` and `moved` empty,
    /// without a predicted motion (before one is known) or without a last frame.
    pub fn predict_segments(
        &self,
        previous: &[Segment],
        out: &mut Vec<Segment>,
        moved: &mut Vec<bool>,
    ) -> bool {
        out.clear();
        moved.clear();
        let Some((reference, motion)) = self.reference.as_ref().zip(self.segment_prediction())
        else {
            return false;
        };
        let to_previous = reference.pose.inverse();
        for (k, seen) in previous.iter().enumerate() {
            let predicted = reference
                .line_landmarks
                .get(k)
                .and_then(Option::as_ref)
                .and_then(|landmark| {
                    let line = landmark.world.transformed(&to_previous);
                    let lift = |p: &Point| self.lift_onto(p, &line);
                    let [a, b] = [lift(&seen.start)?, lift(&seen.end)?]
                        .map(|x| self.rig.project_left(&(motion * x)));
                    Some(Segment::new(a?, b?))
                });
            out.push(predicted.unwrap_or(*seen));
            moved.push(predicted.is_some());
        }
        true
    }

    /// The motion this frame's segments give on their own, and how many of them are
    /// inliers of it: the reference's segment landmarks observed by `tracked` (previous
    /// segment → this frame's `left` segment), near the current prediction when there is
    /// one, the estimate started from that prediction (and held near the last motion
    /// once one is known). `None` without a reference or an estimate.
    pub fn segments_motion(
        &self,
        left: &[Segment],
        tracked: &[FeatureMatch],
    ) -> Option<(Isometry3<f64>, usize)> {
        let reference = self.reference.as_ref()?;
        let mut observations = Observations::default();
        self.observe_lines(reference, left, tracked, &mut observations);
        let (rig, lines, config) = (&self.rig, &observations.lines, &self.config.motion);
        let estimate = if self.motion_known {
            estimate_motion_near(rig, &[], lines, &self.last_motion, config)
        } else {
            estimate_motion(rig, &[], lines, &self.start_of_estimate(), config)
        };
        estimate.ok().map(|e| (e.motion, e.inlier_lines))
    }

    /// Why this frame would be lost if it were tracked on its segments alone with `tracked`
    /// (previous segment → this frame's `left` segment), `min_inliers` being enough under
    /// the prior when given: the update's own observations, estimate and judgement, so on
    /// lines only its own verdict. `None` when it would not be lost, or without a
    /// reference frame.
    pub fn loss_on_lines(
        &self,
        left: &[Segment],
        tracked: &[FeatureMatch],
        min_inliers: Option<usize>,
    ) -> Option<String> {
        let reference = self.reference.as_ref()?;
        let mut observations = Observations::default();
        self.observe_lines(reference, left, tracked, &mut observations);
        self.estimate(&observations, min_inliers, &mut FrameStats::default())
            .err()
            .map(|(_, why)| why)
    }

    /// This frame's estimate is believed with `min_inliers` inliers under the prior (a
    /// rescued frame's, `lost.rescue_min_inliers`); the next update uses it up.
    pub fn accept_with_inliers(&mut self, min_inliers: usize) {
        self.min_inliers_now = Some(min_inliers);
    }

    /// Predicts this frame's segments with `motion` from now on (as
    /// [`MotionTracker::predict_from_points`] does with the points').
    pub fn predict_segments_with(&mut self, motion: Isometry3<f64>) {
        self.segment_motion = Some(motion);
    }

    /// Where an estimate without a prior starts: the motion the segments are predicted
    /// with, else the last one.
    pub(super) fn start_of_estimate(&self) -> Isometry3<f64> {
        self.segment_motion.unwrap_or(self.last_motion)
    }

    /// The motion the frame's segments are predicted with, if any: the points' of
    /// [`MotionTracker::predict_from_points`], else the last motion once one is known.
    pub(super) fn segment_prediction(&self) -> Option<Isometry3<f64>> {
        self.segment_motion
            .or_else(|| self.motion_known.then_some(self.last_motion))
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

    /// Triangulates the frame's stereo segment matches into `lists.fresh.lines` (by left
    /// segment), leaving out those that fail the photometric check on `images` or have
    /// look-alike partners; clears `lists.fresh.points` (the points are triangulated
    /// later, where they were tracked).
    pub(super) fn triangulate_segments(
        &mut self,
        lists: &mut FrameLists,
        images: Option<(&GrayImage, &GrayImage)>,
        lines: &MatchedLines<'_>,
        limits: &TriangulationLimits,
        stats: &mut FrameStats,
    ) {
        let started = Instant::now();
        let verified = self.photometric_profiles(images, lines);
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
            if let Some((a, b)) = triangulate_segment(&self.rig, l, r, limits) {
                let weight =
                    0.5 * (disparity_weight(a.disparity_px) + disparity_weight(b.disparity_px));
                fresh.lines[m.query] = Some(([a.position, b.position], weight));
            }
        }
        stats.triangulated[1] = fresh.lines.iter().flatten().count();
        stats.stereo_ms += since(started);
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

    /// Observations of `previous`'s segment landmarks among this frame's `left` segments.
    /// With a predicted motion, a match whose segment lies farther from the line it
    /// predicts than `predicted_window_px` is not believed (a look-alike).
    pub(super) fn observe_lines(
        &self,
        previous: &Reference,
        left: &[Segment],
        tracked: &[FeatureMatch],
        observations: &mut Observations,
    ) {
        let to_previous = previous.pose.inverse();
        let prediction = self.segment_prediction();
        for m in tracked {
            let (Some(Some(landmark)), Some(seen)) =
                (previous.line_landmarks.get(m.query), left.get(m.train))
            else {
                continue;
            };
            let endpoints = landmark.world.transformed(&to_previous);
            if prediction.is_some_and(|motion| !self.near_prediction(&motion, &endpoints, seen)) {
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
    /// which `motion` projects `endpoints` (previous camera frame); true when the
    /// prediction leaves the image.
    fn near_prediction(
        &self,
        motion: &Isometry3<f64>,
        endpoints: &[Point3<f64>; 2],
        seen: &Segment,
    ) -> bool {
        let [Some(a), Some(b)] = endpoints.map(|x| self.rig.project_left(&(motion * x))) else {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::OdometryConfig;
    use crate::landmarks::sighted;
    use linetrack_geometry::StereoRig;
    use linetrack_vision::PointFeatures;
    use nalgebra::Isometry3;

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
            disparity_offset_px: 0.0,
        });
        let previous = [seen, elsewhere];
        let (mut out, mut moved) = (Vec::new(), Vec::new());
        // No motion measured yet: nothing to predict with.
        assert!(!tracker.predict_segments(&previous, &mut out, &mut moved));
        assert!(out.is_empty() && moved.is_empty());

        let motion = Isometry3::from_parts(
            nalgebra::Translation3::new(0.05, 0.0, -0.1),
            nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.02, 0.01),
        );
        tracker.last_motion = motion;
        tracker.motion_known = true;
        assert!(tracker.predict_segments(&previous, &mut out, &mut moved));
        assert_eq!(moved, [true, false]);
        let expected = [at(0.25), at(0.75)].map(|x| project(motion * x));
        assert!((out[0].start - expected[0]).norm() < 1e-9, "{:?}", out[0]);
        assert!((out[0].end - expected[1]).norm() < 1e-9, "{:?}", out[0]);
        // Without a landmark a segment stays where it was.
        assert_eq!(out[1], elsewhere);

        // Points first: the frame's own motion from its points predicts instead of the
        // last one, also when no motion is known (after a lost frame).
        let from_points = Isometry3::translation(-0.08, 0.01, -0.3);
        tracker.segment_motion = Some(from_points);
        for known in [true, false] {
            tracker.motion_known = known;
            assert!(tracker.predict_segments(&previous, &mut out, &mut moved));
            let expected = [at(0.25), at(0.75)].map(|x| project(from_points * x));
            assert!((out[0].start - expected[0]).norm() < 1e-9, "{:?}", out[0]);
            assert!((out[0].end - expected[1]).norm() < 1e-9, "{:?}", out[0]);
        }
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
