//! What [`MotionTracker::prepare`] does with a frame's images before its segments arrive
//! (dark images stretched, ORB corners found, and the points' work that needs no segments
//! done ahead) and how [`MotionTracker::update_prepared`] finishes the frame with it.

use super::points::{PointSearch, PointWorkMs};
use super::{MatchedLines, MotionTracker, SeenImages, departure, keep_spare};
use crate::stats::since;
use crate::{Features, FrameResult, FrameStats, OdometryError};
use linetrack_stereo_vo::{estimate_motion, estimate_motion_near};
use linetrack_vision::{
    GrayImage, PointFeatures, PointStereo, RowSearchSettings, VisionError, stretch_contrast_into,
};
use std::time::Instant;

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

impl PreparedImages {
    /// The left and right images as tracking sees them: stretched, or the originals `left`
    /// and `right` where they were not.
    pub(crate) fn seen<'a>(
        &'a self,
        left: &'a GrayImage,
        right: &'a GrayImage,
    ) -> (&'a GrayImage, &'a GrayImage) {
        let [left_stretched, right_stretched] = &self.stretched;
        (
            left_stretched.as_ref().unwrap_or(left),
            right_stretched.as_ref().unwrap_or(right),
        )
    }
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
pub(super) struct PointsAhead {
    /// The preparation it was done for.
    serial: u64,
    /// Its milliseconds.
    ms: PointWorkMs,
}

impl MotionTracker {
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
        let ahead_ms = self
            .points_ahead
            .filter(|a| a.serial == prepared.serial)
            .map_or(0.0, |a| a.ms.total());
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
            if self.config.frontend.orb.stereo == PointStereo::RowSearch {
                // Only the left image's corners; the right image is searched along their
                // rows, here, between finding and refining the landmarks' matches.
                self.orb_left.extract(image_l, points_l)?;
                points_r.points.clear();
                points_r.levels.clear();
                if ahead {
                    let started = Instant::now();
                    self.tracking.find(search.as_ref(), points_l);
                    tracking_ms = since(started);
                    let lists = &mut self.spares.lists;
                    let started = Instant::now();
                    let frontend = &self.config.frontend;
                    self.row_search.find_partners(
                        [image_l, image_r],
                        points_l,
                        &RowSearchSettings::of(&frontend.orb, &frontend.appearance_gates),
                        points_r,
                        &mut lists.stereo_matches,
                    );
                    stereo_ms = since(started);
                    let started = Instant::now();
                    self.tracking.observe_found(
                        search.as_ref(),
                        points_l,
                        image_l,
                        &mut lists.observations,
                    );
                    tracking_ms += since(started);
                }
            } else {
                let tracking = &mut self.tracking;
                let (right_side, left_side) =
                    self.orb_right.extract_while(image_r, points_r, || {
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
                ms: PointWorkMs {
                    stereo_ms: stereo_ms + since(started),
                    frame_to_frame_ms: tracking_ms,
                },
            });
        }
        Ok(prepared)
    }

    /// [`LinePrediction::PointsFirst`](crate::LinePrediction): the prepared frame's motion
    /// estimated from its tracked points alone (the work [`Preparation::CornersAndPoints`]
    /// did for it), so that its segments are predicted with it rather than with the last
    /// motion. Returns whether there is such a motion: none without that work, with too few
    /// points, or when the estimate is not believed (then the last motion predicts, as
    /// before). Its milliseconds are the frame's `motion_ms`' share.
    pub fn predict_from_points(&mut self, prepared: &PreparedImages) -> bool {
        self.segment_motion = None;
        let done_ahead = self
            .points_ahead
            .is_some_and(|ahead| ahead.serial == prepared.serial);
        if !done_ahead || self.reference.is_none() {
            return false;
        }
        let points = &self.spares.lists.observations.points;
        let estimate = if self.motion_known {
            estimate_motion_near
        } else {
            estimate_motion
        }(
            &self.rig,
            points,
            &[],
            &self.last_motion,
            &self.config.motion,
        );
        let Ok(estimate) = estimate else {
            return false;
        };
        let departure = departure(&self.last_motion, &estimate.motion);
        if self.motion_known && self.departs_sharply(&self.last_motion, departure).is_some() {
            return false;
        }
        self.segment_motion = Some(estimate.motion);
        true
    }

    /// The milliseconds of the point work done ahead for preparation `serial`, if it was
    /// (and no frame was tracked since: tracking one uses it up).
    fn take_points_ahead(&mut self, serial: u64) -> Option<PointWorkMs> {
        self.points_ahead
            .take()
            .filter(|a| a.serial == serial)
            .map(|a| a.ms)
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
        stats.detect_ms += ms;
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
}

/// Both images of a stereo pair through [`stretch_contrast_into`] (`None`: keep the original),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::OdometryConfig;
    use linetrack_geometry::StereoRig;

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
    fn untimed(result: FrameResult) -> FrameResult {
        let stats = FrameStats {
            detect_ms: 0.0,
            describe_ms: 0.0,
            stereo_ms: 0.0,
            frame_to_frame_ms: 0.0,
            motion_ms: 0.0,
            ..result.stats
        };
        FrameResult { stats, ..result }
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
        // and their points weighted by the gain. Stereo partners by descriptor and, with
        // the right image not extracted, along its rows.
        let dark: Vec<_> = frames.iter().map(darkened).collect();
        let new = || MotionTracker::new(OdometryConfig::default(), rig).unwrap();
        let new_row_search = || MotionTracker::new(row_search_config(), rig).unwrap();
        for (frames, new) in [
            (&frames, &new as &dyn Fn() -> MotionTracker),
            (&dark, &new),
            (&frames, &new_row_search),
            (&dark, &new_row_search),
        ] {
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

    /// The default configuration with `[orb] stereo = "row-search"`.
    fn row_search_config() -> OdometryConfig {
        let mut config = OdometryConfig::default();
        config.frontend.orb.stereo = linetrack_vision::PointStereo::RowSearch;
        config
    }

    #[test]
    fn the_row_search_extracts_no_right_points_and_triangulates_as_many() {
        let (frames, rig) = euroc_frames(&[0, 4]);
        let mut row_search = MotionTracker::new(row_search_config(), rig).unwrap();
        let mut descriptors = MotionTracker::new(OdometryConfig::default(), rig).unwrap();
        for frame in &frames {
            let a = track_prepared(&mut row_search, frame, Preparation::CornersAndPoints);
            let b = track_prepared(&mut descriptors, frame, Preparation::CornersAndPoints);
            // The right "points" are the partners the search found, no more than the
            // left points; the descriptor matching extracted the right image's own.
            assert!(a.stats.points[1] <= a.stats.points[0], "{:?}", a.stats);
            assert!(a.stats.points[1] > a.stats.points[0] / 2, "{:?}", a.stats);
            assert!(
                a.stats.triangulated[0] * 10 >= b.stats.triangulated[0] * 8,
                "{:?} against {:?}",
                a.stats,
                b.stats
            );
            if frame.index > 0 {
                assert!(a.stats.observations[0] > 100, "{:?}", a.stats);
            }
        }
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
}
