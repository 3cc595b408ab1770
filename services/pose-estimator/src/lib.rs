//! The pose estimator: the odometry's back end on the matcher's output. It triangulates
//! the stereo-matched segments (and ORB points of the frame's images, read in place, when
//! the config uses points), finds the previous frame's 3-D features through the
//! frame-to-frame matches, and publishes the frame's pose. The points' part (corners,
//! their stereo matches, their search for the last frame's landmarks) needs only the
//! images: it is done when they arrive, while the segments are still being detected and
//! matched. When the tracks were matched against another frame than the one it last
//! tracked (a drop upstream, a restart), it starts again from the current pose instead of
//! using them. The stereo rig comes from the stream (the frame source publishes it on
//! [`Topic::Rig`]): the stage never opens the data set, so any source (a live camera) can
//! feed it. Each pose carries its covariance (the motion estimates' chained with
//! [`PoseCovariance`]) and the frame's step's.

use anyhow::Context;
use linetrack_geometry::{Segment, StereoRig};
use linetrack_ipc::{Bus, Inlet, Received, Shutdown};
use linetrack_msgs::{
    FrameHeader, MatcherMode, NO_FRAME, PoseRecord, RigRecord, StageKind, Topic, TopicOf,
    TrackedLine, TracksHeader, topics,
};
use linetrack_odometry::{
    Features, FrameStats, LinePrediction, LostKind, MatchedLines, MotionTracker, OdometryConfig,
    PoseCovariance, Preparation, PreparedImages, SegmentTracking, rescue_matcher,
};
use linetrack_pipeline_config::MatcherPolicy;
use linetrack_stage_runtime::{
    Images, Stage, StageContext, held_capacity, rig_from_record, run_stage, stereo_views,
    to_segment,
};
use linetrack_vision::{
    FeatureMatch, LineFeatures, MatcherKind, SegmentMatcher, create_segment_matcher,
};
use nalgebra::{Isometry3, Matrix6, Quaternion, Translation3, UnitQuaternion};
use std::collections::VecDeque;

/// A pose as a record.
pub fn pose_record(pose: &Isometry3<f64>) -> PoseRecord {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    PoseRecord {
        translation: [t.x, t.y, t.z],
        rotation_xyzw: [q.i, q.j, q.k, q.w],
        ..PoseRecord::default()
    }
}

/// A symmetric 6×6 covariance as the pose record carries it.
fn packed(covariance: &Matrix6<f64>) -> [f64; 21] {
    PoseRecord::pack_covariance(&(*covariance).into())
}

/// Where a restarted pose estimator picks up: the last pose the run recorded and the
/// motion per frame before it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resume {
    /// The frame of the last pose.
    pub frame: u64,
    /// Its pose (camera to world).
    pub pose: Isometry3<f64>,
    /// The motion per frame (`p_curr = motion · p_prev`) from the two last poses when they
    /// are consecutive frames; the identity otherwise.
    pub motion: Isometry3<f64>,
}

/// Parses the supervisor's `--resume-pose`: `frame,tx,ty,tz,qx,qy,qz,qw` for the last pose,
/// optionally followed by `;` and the pose before it in the same form.
pub fn parse_resume_pose(text: &str) -> anyhow::Result<Resume> {
    let mut parts = text.split(';');
    let (frame, pose) = parse_pose(parts.next().unwrap_or_default())?;
    let motion = match parts.next() {
        Some(previous) => {
            let (previous_frame, previous_pose) = parse_pose(previous)?;
            if previous_frame + 1 == frame {
                pose.inverse() * previous_pose
            } else {
                Isometry3::identity()
            }
        }
        None => Isometry3::identity(),
    };
    anyhow::ensure!(
        parts.next().is_none(),
        "--resume-pose {text:?}: at most two poses"
    );
    Ok(Resume {
        frame,
        pose,
        motion,
    })
}

/// One `frame,tx,ty,tz,qx,qy,qz,qw`.
fn parse_pose(text: &str) -> anyhow::Result<(u64, Isometry3<f64>)> {
    let fields: Vec<&str> = text.split(',').map(str::trim).collect();
    anyhow::ensure!(
        fields.len() == 8,
        "--resume-pose {text:?}: expected frame,tx,ty,tz,qx,qy,qz,qw"
    );
    let frame: u64 = fields[0]
        .parse()
        .with_context(|| format!("--resume-pose: frame {:?}", fields[0]))?;
    let mut v = [0.0f64; 7];
    for (slot, f) in v.iter_mut().zip(&fields[1..]) {
        *slot = f
            .parse()
            .with_context(|| format!("--resume-pose: {f:?} is not a number"))?;
        anyhow::ensure!(slot.is_finite(), "--resume-pose: {f:?} is not finite");
    }
    let q = Quaternion::new(v[6], v[3], v[4], v[5]);
    anyhow::ensure!(q.norm() > 1e-9, "--resume-pose: zero quaternion");
    Ok((
        frame,
        Isometry3::from_parts(
            Translation3::new(v[0], v[1], v[2]),
            UnitQuaternion::from_quaternion(q),
        ),
    ))
}

/// Tracking state: the back end (once the rig is known) and the frame it last tracked.
pub struct PoseTracker {
    config: OdometryConfig,
    tracker: Option<MotionTracker>,
    rig: Option<StereoRig>,
    last_frame: u64,
    /// After a restart: where to pick up, until the tracker exists.
    resume: Option<Resume>,
    /// After a restart: the frame of the last recorded pose, until the first frame is tracked.
    resumed_after: Option<u64>,
    /// Frames whose images were prepared before their segments arrived, oldest first.
    prepared: VecDeque<(u64, PreparedImages)>,
    buffers: FrameBuffers,
    /// The pose's covariance, chained over the frames (a resumed pose starts exact).
    covariance: PoseCovariance,
    /// Frames the matcher matched with ℓ1 are matched to the last frame again here, where
    /// the motion predicts the last frame's segments (the matcher stage does not know the
    /// motion): the odometry's own front end does the same for every frame.
    relink: Relink,
}

/// What matching ℓ1 frames again at their predicted positions keeps between frames.
struct Relink {
    l1: Box<dyn SegmentMatcher>,
    /// The ℓ1 matcher of `[lost] rescue_*` for frames that would be lost (lines only;
    /// `None`: off), as the odometry's own front end rescues them.
    rescue: Option<Box<dyn SegmentMatcher>>,
    /// LBD frames that would be lost are matched again with ℓ1 (`[matcher.fallback]
    /// rescue_lost_frames` with the `auto` policy).
    rescue_lbd: bool,
    segments: SegmentTracking,
    /// The last tracked frame's left segments (as the tracker was given them) with the ℓ1
    /// matcher's description of its left image, and that frame's id.
    previous: Option<(u64, LineFeatures)>,
    /// The current frame's, refilled in place.
    current: LineFeatures,
}

impl Relink {
    /// Replaces `tracked` (the matcher's matches of `previous_frame_id`'s left segments
    /// with this frame's, made around their old positions) by ℓ1 matches at the positions
    /// the tracker predicts for them, or where the frame's own segment motion puts them
    /// (`rematch_passes`), when this frame was matched with ℓ1, `previous_frame_id` is the
    /// frame described last, and the config matches predicted positions; an LBD frame's
    /// when they would lose it and ℓ1 at the predicted positions does not (`rescue_lbd`),
    /// returning true then. Then keeps this frame's left segments, described from `left`,
    /// for the next frame.
    fn relink(
        &mut self,
        tracker: &mut MotionTracker,
        (frame_id, matching, continues): (u64, &linetrack_msgs::Matching, bool),
        left_segments: &[Segment],
        left: Option<&linetrack_vision::GrayImage>,
        tracked: &mut Vec<FeatureMatch>,
    ) -> anyhow::Result<bool> {
        let current = &mut self.current;
        current.clear();
        current.segments.extend_from_slice(left_segments);
        let Some(left) = left else {
            self.previous = None;
            return Ok(false);
        };
        self.l1.describe(left, current)?;
        let l1_frame = matching.mode.is(MatcherMode::L1);
        let mut fell_back = false;
        if let Some((id, previous)) = &mut self.previous
            && !l1_frame
            && self.rescue_lbd
            && continues
            && *id == matching.previous_frame_id
        {
            let rescue = self
                .rescue
                .as_mut()
                .map(|m| -> &mut dyn SegmentMatcher { m.as_mut() });
            fell_back = self.segments.fall_back_to_l1(
                self.l1.as_mut(),
                rescue,
                tracker,
                previous,
                current,
                tracked,
            );
        } else if let Some((id, previous)) = &mut self.previous
            && l1_frame
            && continues
            && *id == matching.previous_frame_id
        {
            if !self
                .segments
                .match_predicted(self.l1.as_mut(), tracker, previous, current, tracked)
            {
                self.segments
                    .rematch(self.l1.as_mut(), tracker, previous, current, tracked);
            } else if let Some(rescue) = self.rescue.as_mut()
                && self
                    .segments
                    .rescue(Some(rescue.as_mut()), tracker, previous, current, tracked)
            {
                tracing::debug!(frame_id, "a frame that would be lost was matched again");
            }
        }
        let done = self.previous.take().map(|(_, p)| p).unwrap_or_default();
        let kept = std::mem::replace(&mut self.current, done);
        self.previous = Some((frame_id, kept));
        Ok(fell_back)
    }
}

/// A frame's segments and matches as the back end takes them.
#[derive(Default)]
struct FrameBuffers {
    left: Vec<Segment>,
    right: Vec<Segment>,
    stereo: Vec<FeatureMatch>,
    tracked: Vec<FeatureMatch>,
}

impl PoseTracker {
    /// A tracker for the run's odometry settings (and `--resume-pose` after a restart); it
    /// tracks once it has a rig ([`PoseTracker::set_rig`]).
    pub fn new(ctx: &StageContext) -> anyhow::Result<Self> {
        let resume = ctx
            .args
            .resume_pose
            .as_deref()
            .map(parse_resume_pose)
            .transpose()?;
        Ok(Self {
            config: ctx.config.odometry_config(),
            tracker: None,
            rig: None,
            last_frame: NO_FRAME,
            resumed_after: resume.map(|r| r.frame),
            resume,
            prepared: VecDeque::new(),
            buffers: FrameBuffers::default(),
            covariance: PoseCovariance::default(),
            relink: Relink {
                l1: create_segment_matcher(
                    MatcherKind::L1,
                    &ctx.config.odometry.tracking_frontend(),
                )?,
                rescue: rescue_matcher(&ctx.config.odometry, MatcherKind::L1)?,
                rescue_lbd: ctx.config.matcher.mode == MatcherPolicy::Auto
                    && ctx.config.matcher.fallback.rescue_lost_frames,
                segments: SegmentTracking::default(),
                previous: None,
                current: LineFeatures::default(),
            },
        })
    }

    /// Uses `rig` from now on. A new rig starts the back end again from the current pose
    /// (the features of the old rig do not carry over).
    pub fn set_rig(&mut self, rig: StereoRig) -> anyhow::Result<()> {
        if self.rig == Some(rig) {
            return Ok(());
        }
        let mut tracker = MotionTracker::new(self.config.clone(), rig)?;
        match (&self.tracker, self.resume.take()) {
            (Some(old), _) => tracker.resume_from(old.pose(), old.last_motion()),
            (None, Some(resume)) => {
                tracing::info!("resuming after frame {}", resume.frame);
                tracker.resume_from(resume.pose, resume.motion);
            }
            (None, None) => {}
        }
        tracing::info!(
            "rig: f {:.1} px, c ({:.1}, {:.1}) px, baseline {:.4} m, {}×{}",
            rig.focal_px,
            rig.cx_px,
            rig.cy_px,
            rig.baseline_m,
            rig.width_px,
            rig.height_px
        );
        self.tracker = Some(tracker);
        self.rig = Some(rig);
        self.prepared.clear();
        self.last_frame = NO_FRAME;
        Ok(())
    }

    /// The current pose (the identity before the rig is known, or the resumed pose).
    pub fn pose(&self) -> Isometry3<f64> {
        match (&self.tracker, &self.resume) {
            (Some(t), _) => t.pose(),
            (None, Some(r)) => r.pose,
            (None, None) => Isometry3::identity(),
        }
    }

    /// The current pose as a record, with its covariance (what a dropped frame repeats).
    pub fn pose_record(&self) -> PoseRecord {
        PoseRecord {
            covariance: packed(&self.covariance.covariance()),
            ..pose_record(&self.pose())
        }
    }

    /// Stretches frame `header`'s images and finds their corners ahead of its segments
    /// (nothing before a rig arrived), and their stereo partners and frame-to-frame
    /// observations when no earlier frame still waits for its segments; kept for
    /// [`PoseTracker::track`] of the same frame.
    pub fn prepare(&mut self, header: &FrameHeader, frame: &Images) -> anyhow::Result<()> {
        let Some(tracker) = &mut self.tracker else {
            return Ok(());
        };
        let (left, right) = stereo_views(frame)?;
        // With no frame before it waiting for its segments, the last one tracked is the
        // one this frame's points are searched against: that search is done now too.
        let preparation = if self.prepared.is_empty() {
            Preparation::CornersAndPoints
        } else {
            Preparation::Corners
        };
        let prepared = tracker.prepare(&left, &right, preparation)?;
        if self.prepared.len() >= held_capacity(Topic::Frames) {
            self.prepared.pop_front();
        }
        self.prepared.push_back((header.frame_id, prepared));
        Ok(())
    }

    /// What was prepared for frame `frame_id`, if it was (older entries are let go).
    fn take_prepared(&mut self, frame_id: u64) -> Option<PreparedImages> {
        while self.prepared.front().is_some_and(|(id, _)| *id < frame_id) {
            self.prepared.pop_front();
        }
        self.prepared
            .front()
            .is_some_and(|(id, _)| *id == frame_id)
            .then(|| self.prepared.pop_front().map(|(_, p)| p))
            .flatten()
    }

    /// Tracks one frame (with what was prepared from its images, if anything).
    pub fn track(
        &mut self,
        header: &TracksHeader,
        lines: &[TrackedLine],
        frame: Option<&Images>,
    ) -> anyhow::Result<PoseRecord> {
        let previous_frame_id = header.matching.previous_frame_id;
        let tracks_matching = header.matching;
        let header = &header.frame;
        let prepared = self.take_prepared(header.frame_id);
        // The frame's segments and matches, in buffers kept from frame to frame.
        let buffers = &mut self.buffers;
        buffers.left.clear();
        buffers
            .left
            .extend(lines.iter().map(|t| to_segment(&t.left)));
        buffers.right.clear();
        buffers.right.extend(
            lines
                .iter()
                .filter(|t| t.has_stereo == 1)
                .map(|t| to_segment(&t.right)),
        );
        buffers.stereo.clear();
        buffers.tracked.clear();
        let mut r = 0;
        for (i, t) in lines.iter().enumerate() {
            if t.has_stereo == 1 {
                buffers.stereo.push(FeatureMatch {
                    query: i,
                    train: r,
                    distance: 0.0,
                });
                r += 1;
            }
            if let Ok(previous) = usize::try_from(t.previous) {
                buffers.tracked.push(FeatureMatch {
                    query: previous,
                    train: i,
                    distance: 0.0,
                });
            }
        }
        let continues = previous_frame_id != NO_FRAME && previous_frame_id == self.last_frame;
        let views = match frame.map(stereo_views) {
            Some(Ok(v)) => Some(v),
            Some(Err(e)) => {
                tracing::warn!("frame {}: {e}; tracking on lines only", header.frame_id);
                None
            }
            None => None,
        };
        let images = views.as_ref().map(|(l, r)| (&**l, &**r));
        // The first frame after a restart: the motion across the gap is predicted (the
        // last motion per frame), and the pose says so.
        let tracker = self
            .tracker
            .as_mut()
            .context("no stereo rig has arrived from the frame source yet")?;
        let resumed = self.resumed_after.take();
        let before = tracker.pose();
        if let Some(frame) = resumed {
            tracker.predict_frames(header.frame_id.saturating_sub(frame));
        }
        if continues
            && self.config.line_prediction == LinePrediction::PointsFirst
            && let Some(prepared) = &prepared
        {
            tracker.predict_from_points(prepared);
        }
        let matching = (header.frame_id, &tracks_matching, continues);
        let fell_back = self.relink.relink(
            tracker,
            matching,
            &self.buffers.left,
            images.map(|(left, _)| left),
            &mut self.buffers.tracked,
        )?;
        let matched = MatchedLines {
            left: &self.buffers.left,
            right: &self.buffers.right,
            stereo: &self.buffers.stereo,
            tracked: continues.then_some(self.buffers.tracked.as_slice()),
        };
        let result = match (images, prepared) {
            (Some(images), Some(prepared)) => {
                tracker.update_prepared(Some((images, prepared)), matched, FrameStats::default())?
            }
            (images, _) => tracker.update(images, matched, FrameStats::default())?,
        };
        self.last_frame = header.frame_id;
        // A measured step adds its covariance; a predicted one (lost, or across a restart's
        // gap) the last measured one's; a fresh start (the pose unchanged) nothing.
        let step = result.step_covariance.as_ref();
        if step.is_some() || result.lost || resumed.is_some() {
            self.covariance.advance(&before, &result.pose, step);
        }
        let mut record = pose_record(&result.pose);
        record.covariance = packed(&self.covariance.covariance());
        record.step_covariance = step.map(packed).unwrap_or_default();
        record.lost = u32::from(result.lost || resumed.is_some());
        record.inliers = result.stats.inliers.map(|n| n as u32);
        record.observations = result.stats.observations.map(|n| n as u32);
        record.rms_px = result.stats.rms_px;
        record.conditioning = result.stats.conditioning;
        record.rescued = u32::from(fell_back && !result.lost);
        record.disparity_offset_px = result.stats.disparity_offset_px;
        record.lost_reason = lost_reason(result.lost_kind, resumed.is_some());
        if let Some(reason) = &result.reason {
            tracing::debug!("frame {} lost: {reason}", header.frame_id);
        }
        Ok(record)
    }
}

/// The pose estimator stage: the tracker and the rig's topic.
pub struct PoseStage {
    tracker: PoseTracker,
    rig: Inlet<RigRecord, ()>,
    points: bool,
    /// Whether ℓ1 frames are matched again at their predicted positions (which reads the
    /// left image, for the ℓ1 matcher's photometric check).
    relinks: bool,
}

impl PoseStage {
    /// The stage of `ctx`, subscribed to the rig on `bus`.
    pub fn new(ctx: &StageContext, bus: &Bus) -> anyhow::Result<Self> {
        Ok(Self {
            tracker: PoseTracker::new(ctx)?,
            rig: bus.inlet(topics::RIG)?,
            points: ctx.config.odometry.features == Features::PointsAndLines,
            relinks: ctx.config.odometry.predicted_matching,
        })
    }
}

impl Stage for PoseStage {
    type Input = TrackedLine;
    type InputHeader = TracksHeader;
    type Output = PoseRecord;
    type OutputHeader = TracksHeader;
    const KIND: StageKind = StageKind::PoseEstimator;
    const INPUT: TopicOf<Self::Input, Self::InputHeader> = topics::TRACKS;
    const OUTPUT: TopicOf<Self::Output, Self::OutputHeader> = topics::POSES;
    const OUTPUT_LEN: usize = 1;

    fn joins_images(&self) -> bool {
        // ORB points are found in the images, and ℓ1 frames matched again read the left.
        self.points || self.relinks
    }

    fn poll(&mut self) -> anyhow::Result<()> {
        for message in self.rig.receive_all()? {
            let Some(record) = message.payload().first() else {
                continue;
            };
            // A bad rig is refused and the last good one kept: the run goes on.
            match rig_from_record(record) {
                Ok(rig) => self.tracker.set_rig(rig)?,
                Err(e) => tracing::error!("{e}"),
            }
        }
        Ok(())
    }

    fn prepares(&self) -> bool {
        // Corners are found ahead; segments-only odometry has nothing to prepare.
        self.points
    }

    fn prepare(&mut self, header: &FrameHeader, images: &Images) -> anyhow::Result<()> {
        self.tracker.prepare(header, images)
    }

    fn process(
        &mut self,
        header: &mut TracksHeader,
        tracks: &Received<TrackedLine, TracksHeader>,
        images: Option<&Images>,
        out: &mut Vec<PoseRecord>,
    ) -> anyhow::Result<()> {
        out.push(self.tracker.track(header, tracks.payload(), images)?);
        Ok(())
    }

    /// A dropped or failed frame repeats the last pose.
    fn placeholder(&self, out: &mut Vec<PoseRecord>) {
        out.push(self.tracker.pose_record());
    }
}

/// Runs the pose estimator stage until shutdown.
pub fn run(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    run_stage(ctx, bus, PoseStage::new(ctx, bus)?, shutdown)
}

/// The [`PoseRecord::lost_reason`] code of a frame lost as `kind` (`None`: tracked), or
/// predicted across a restart's gap (`resumed`).
fn lost_reason(kind: Option<LostKind>, resumed: bool) -> u32 {
    match kind {
        Some(kind) => PoseRecord::lost_reason_code(kind.name()),
        None if resumed => PoseRecord::lost_reason_code(RESTART_GAP),
        None => 0,
    }
}

/// [`PoseRecord::lost_reason`]'s name for a pose predicted across a restart's gap.
const RESTART_GAP: &str = "restart-gap";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_way_of_losing_a_frame_has_a_code_that_names_it() {
        let mut codes = Vec::new();
        let cases = LostKind::ALL.map(|k| (Some(k), false, k.name()));
        for (kind, resumed, name) in cases.into_iter().chain([(None, true, RESTART_GAP)]) {
            let record = PoseRecord {
                lost_reason: lost_reason(kind, resumed),
                ..PoseRecord::default()
            };
            assert_ne!(record.lost_reason, 0, "{name}");
            assert_eq!(record.lost_reason_name(), name);
            codes.push(record.lost_reason);
        }
        codes.sort_unstable();
        codes.dedup();
        assert_eq!(
            codes.len(),
            LostKind::ALL.len() + 1,
            "codes differ: {codes:?}"
        );
        assert_eq!(lost_reason(None, false), 0);
    }

    #[test]
    fn resume_pose_round_trips_and_rejects_garbage() {
        let pose = Isometry3::from_parts(
            Translation3::new(1.0, -2.0, 0.5),
            UnitQuaternion::from_euler_angles(0.1, 0.2, -0.3),
        );
        let r = pose_record(&pose);
        let text = format!(
            "12,{},{},{},{},{},{},{}",
            r.translation[0],
            r.translation[1],
            r.translation[2],
            r.rotation_xyzw[0],
            r.rotation_xyzw[1],
            r.rotation_xyzw[2],
            r.rotation_xyzw[3]
        );
        let back = parse_resume_pose(&text).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back.frame, 12);
        assert!((back.pose.translation.vector - pose.translation.vector).norm() < 1e-12);
        assert!(back.pose.rotation.angle_to(&pose.rotation) < 1e-9);
        assert_eq!(back.motion, Isometry3::identity());
        // With the pose before it (frame 11, 5 cm behind along z): the motion per frame.
        let before = pose * Translation3::new(0.0, 0.0, -0.05);
        let b = pose_record(&before);
        let two = format!(
            "{text};11,{},{},{},{},{},{},{}",
            b.translation[0],
            b.translation[1],
            b.translation[2],
            b.rotation_xyzw[0],
            b.rotation_xyzw[1],
            b.rotation_xyzw[2],
            b.rotation_xyzw[3]
        );
        let back = parse_resume_pose(&two).unwrap_or_else(|e| panic!("{e}"));
        // p_curr = motion · p_prev: a camera moving 5 cm forward sees points 5 cm nearer.
        assert!(
            (back.motion.translation.vector - nalgebra::Vector3::new(0.0, 0.0, -0.05)).norm()
                < 1e-9,
            "{}",
            back.motion
        );
        // Not consecutive: no motion is inferred.
        let gap = two.replace(";11,", ";9,");
        assert_eq!(
            parse_resume_pose(&gap).unwrap().motion,
            Isometry3::identity()
        );
        for bad in [
            "",
            "1,2,3",
            "x,0,0,0,0,0,0,1",
            "1,0,0,nan,0,0,0,1",
            "1,0,0,0,0,0,0,0",
            "1,0,0,0,0,0,0,1;2,0,0,0,0,0,0,1;3,0,0,0,0,0,0,1",
        ] {
            assert!(parse_resume_pose(bad).is_err(), "{bad:?} accepted");
        }
    }
}
