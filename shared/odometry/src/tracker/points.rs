//! The ORB points' part of tracking a frame: each left point's stereo partner, the
//! reference frame's point landmarks searched for around where the last motion moves them
//! ([`PointSearch`], [`PointTracking`]) and refined to a fraction of a pixel, and the
//! points triangulated where they were tracked; with the weights of their pyramid level
//! and of the image's stretch.

use super::{FrameLists, MotionTracker, Observations, Reference, SeenImages, Triangulations};
use crate::stats::since;
use crate::{Features, FrameStats, OdometryConfig};
use linetrack_geometry::{MatchCase, Point, StereoRig};
use linetrack_stereo_vo::{
    PointObservation, TriangulationLimits, disparity_weight, triangulate_point,
};
use linetrack_vision::{
    AppearanceGates, FeatureMatch, GrayImage, PointFeatures, PointMatcher, PointStereo,
    RowSearchSettings, copy_image_into, refine_stereo_column, refine_track,
};
use nalgebra::Isometry3;
use std::time::Instant;

/// The milliseconds of a frame's point work.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PointWorkMs {
    /// Stereo matching.
    pub(super) stereo_ms: f64,
    /// Frame-to-frame matching (and refinement).
    pub(super) frame_to_frame_ms: f64,
}

impl PointWorkMs {
    /// Both.
    pub(super) fn total(self) -> f64 {
        self.stereo_ms + self.frame_to_frame_ms
    }
}

impl MotionTracker {
    /// This frame's left and right points, with the images they were found in, when the
    /// config uses points and `images` are given. Their work is done here unless it was
    /// done ahead: stereo partners found and, when the frame `continues` from the
    /// reference, the reference's landmarks observed; its milliseconds are added to
    /// `stats`. Otherwise there are no points, and the last frame's stereo partners,
    /// refined points and point observations are cleared.
    pub(super) fn frame_points<'a>(
        &mut self,
        lists: &mut FrameLists,
        images: Option<SeenImages<'a>>,
        continues: bool,
        stats: &mut FrameStats,
    ) -> (Option<(&'a GrayImage, &'a GrayImage)>, [PointFeatures; 2]) {
        match images {
            Some(mut seen) if self.config.features == Features::PointsAndLines => {
                // Stereo partners, and observations of the reference's landmarks when this
                // frame continues from it, unless done ahead (points are triangulated once
                // they are where they were tracked).
                let ms = match seen.points_ahead {
                    Some(ms) => ms,
                    None => {
                        let [points_l, points_r] = &mut seen.points;
                        self.track_points(
                            lists,
                            (&*points_l, points_r),
                            seen.images,
                            seen.left_gain,
                            continues,
                        )
                    }
                };
                stats.stereo_ms += ms.stereo_ms;
                stats.frame_to_frame_ms += ms.frame_to_frame_ms;
                (Some(seen.images), seen.points)
            }
            _ => {
                self.stereo_partners.clear();
                self.tracking.refined.clear();
                lists.observations.clear();
                (None, Default::default())
            }
        }
    }

    /// A frame's point work that needs no segments, into `lists` and the tracker's
    /// per-frame state: the stereo partners of `points_l` ([`MotionTracker::match_stereo`]
    /// in `images`) and, when there is a reference frame and `observe` says so, their
    /// observations of its landmarks. Returns its milliseconds.
    fn track_points(
        &mut self,
        lists: &mut FrameLists,
        (points_l, points_r): (&PointFeatures, &mut PointFeatures),
        images: (&GrayImage, &GrayImage),
        left_gain: f64,
        observe: bool,
    ) -> PointWorkMs {
        let left_image = images.0;
        let stereo_ms = self.match_stereo(lists, images, (points_l, points_r));
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
        PointWorkMs {
            stereo_ms,
            frame_to_frame_ms: since(started),
        }
    }

    /// The stereo partners of `points_l`: among `points_r` by descriptor, or with
    /// `[orb] stereo = "row-search"` along the rows of `images`' right one (`points_r`
    /// then replaced by the partners found); returns its milliseconds.
    pub(super) fn match_stereo(
        &mut self,
        lists: &mut FrameLists,
        (left_image, right_image): (&GrayImage, &GrayImage),
        (points_l, points_r): (&PointFeatures, &mut PointFeatures),
    ) -> f64 {
        let started = Instant::now();
        let orb = &self.config.frontend.orb;
        let gates = &self.config.frontend.appearance_gates;
        match orb.stereo {
            PointStereo::Descriptors => self.point_matcher.match_points(
                MatchCase::Stereo,
                points_l,
                points_r,
                gates,
                orb.min_distance_ratio,
                &mut lists.stereo_matches,
            ),
            PointStereo::RowSearch => self.row_search.find_partners(
                [left_image, right_image],
                points_l,
                &RowSearchSettings::of(orb, gates),
                points_r,
                &mut lists.stereo_matches,
            ),
        }
        self.set_stereo_partners(&lists.stereo_matches, [points_l, points_r]);
        since(started)
    }

    /// Each of `points_l`'s stereo partner among `points_r`, from their `matches`, with
    /// the weight of the two keypoints' levels.
    pub(super) fn set_stereo_partners(
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

    /// Triangulates each of `points` (this frame's left points, where they were tracked)
    /// with its stereo partner into `fresh`, the partner's column refined to a fraction of
    /// a pixel around it when `subpixel_stereo` is on; weighted by disparity and by the two
    /// keypoints' pyramid levels.
    pub(super) fn triangulate_points(
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
        stats.stereo_ms += since(started);
    }

    /// Moves this frame's left points that were tracked to a fraction of a pixel onto their
    /// tracked positions, where they are then triangulated. A landmark so fuses sightings
    /// of one physical point, the one first seen, instead of whichever pixel each frame's
    /// detector rounded the corner to (up to a pixel of its pyramid level apart), and the
    /// next frame's tracking starts from there too. The stereo weight stays that of the
    /// keypoints' levels (counting the tracked left point as exact did no better on the
    /// generated sequences).
    pub(super) fn anchor_refined_points(&self, points: &mut PointFeatures) {
        for &(j, pixel) in &self.tracking.refined {
            if let Some(point) = points.points.get_mut(j) {
                *point = pixel;
            }
        }
    }

    /// Keeps `image` (this frame's left image, as its points were found in) for the next
    /// frame's sub-pixel tracking, in the buffer of the last one.
    pub(super) fn keep_reference_image(&mut self, image: Option<&GrayImage>) {
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
pub(super) fn search_radius_px(config: &OdometryConfig, motion_known: bool) -> f64 {
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
pub(super) struct PointSearch<'a> {
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
    pub(super) fn of(
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
pub(super) struct PointTracking {
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
    pub(super) fn find(&mut self, search: Option<&PointSearch<'_>>, current: &PointFeatures) {
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
    pub(super) fn observe_found(
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
                    // Set once this frame's stereo matches are triangulated.
                    right_x: None,
                    weight: landmark.observation_weight() * level_weight * search.noise_weight,
                });
                observations.point_pairs.push((m.query, m.train));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
