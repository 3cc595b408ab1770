//! The matcher: stereo and frame-to-frame segment matching.
//!
//! It takes each frame's segments from the detector and the frame's images, held in shared
//! memory since they arrived. In LBD mode it describes both images' segments and matches
//! them by descriptor; in ℓ1 mode it matches by geometry and the intensity profiles
//! across the segments (the ℓ1 matcher's photometric check), and every
//! `probe_every`-th frame also tries LBD and reports how many stereo matches it found, so
//! the supervisor can tell when LBD works again. Frame-to-frame matching uses LBD when both
//! frames were described, else ℓ1. The supervisor sets the mode; the matcher reports.

use linetrack_geometry::MatchCase;
use linetrack_ipc::{Bus, Received, Shutdown};
use linetrack_msgs::{
    Command, Control, MatcherMode, Matching, SegmentRecord, SegmentsHeader, StageKind, TopicOf,
    TrackedLine, TracksHeader, decode, topics,
};
use linetrack_pipeline_config::MatcherPolicy;
use linetrack_stage_runtime::{
    Images, RightImageWorker, Stage, StageContext, run_stage, stereo_views, to_segment,
};
use linetrack_vision::{
    FeatureMatch, GrayImage, LineFeatures, MatcherKind, SegmentMatcher, VisionError,
    create_segment_matcher,
};
use tracing::info_span;

/// The previous frame's left features.
struct Previous {
    frame_id: u64,
    features: LineFeatures,
    described: bool,
}

/// The right image's LBD describer and its features, for the worker that describes it.
struct Describe {
    lbd: Box<dyn SegmentMatcher>,
    features: LineFeatures,
    /// The frame's left segments: only right segments that could match one are described
    /// (the right features serve stereo matching alone).
    left: Vec<linetrack_geometry::Segment>,
}

/// Matching state across frames.
pub struct FrameMatcher {
    lbd: Box<dyn SegmentMatcher>,
    /// LBD on the right image: on a thread of its own under `detect_sides_in_parallel`,
    /// else after the left image.
    describe_right: RightImageWorker<Describe, VisionError>,
    l1: Box<dyn SegmentMatcher>,
    mode: MatcherMode,
    /// Whether ℓ1 frames probe LBD (the `auto` policy only: under `l1` nothing would come
    /// of a probe but its cost).
    probes: bool,
    probe_every: u32,
    frames_in_l1: u32,
    previous: Option<Previous>,
    /// Features of frames done with (the left image's of the frame before the previous,
    /// the right image's of the previous), refilled in place: none allocated per frame.
    spare: [LineFeatures; 2],
    stereo: Vec<FeatureMatch>,
    tracked: Vec<FeatureMatch>,
}

impl FrameMatcher {
    /// A matcher with the run's front-end settings, starting in the policy's mode.
    pub fn new(ctx: &StageContext) -> anyhow::Result<Self> {
        let frontend = &ctx.config.odometry.frontend;
        let mode = match ctx.config.matcher.mode {
            MatcherPolicy::Auto | MatcherPolicy::Lbd => MatcherMode::Lbd,
            MatcherPolicy::L1 => MatcherMode::L1,
        };
        let right = Describe {
            lbd: create_segment_matcher(MatcherKind::Lbd, frontend)?,
            features: LineFeatures::default(),
            left: Vec::new(),
        };
        let describe_right = RightImageWorker::new(
            "describe-right",
            ctx.config.detect_sides_in_parallel,
            right,
            |d: &mut Describe, image: &GrayImage| {
                d.lbd.describe_stereo_right(image, &d.left, &mut d.features)
            },
        )?;
        Ok(Self {
            lbd: create_segment_matcher(MatcherKind::Lbd, frontend)?,
            describe_right,
            l1: create_segment_matcher(MatcherKind::L1, frontend)?,
            mode,
            probes: ctx.config.matcher.mode == MatcherPolicy::Auto,
            probe_every: ctx.config.matcher.fallback.probe_every,
            frames_in_l1: 0,
            previous: None,
            spare: Default::default(),
            stereo: Vec::new(),
            tracked: Vec::new(),
        })
    }

    /// Whether a frame matched in `mode` also tries LBD: every `probe_every`-th ℓ1 frame
    /// under the `auto` policy.
    fn probes_now(&self, mode: MatcherMode) -> bool {
        self.probes
            && mode == MatcherMode::L1
            && self.mode == MatcherMode::L1
            && self.frames_in_l1.is_multiple_of(self.probe_every)
    }

    /// The mode for the next frames.
    pub fn set_mode(&mut self, mode: MatcherMode) {
        if mode != self.mode {
            tracing::info!("matcher mode {} -> {}", self.mode.name(), mode.name());
            self.mode = mode;
            self.frames_in_l1 = 0;
        }
    }

    /// The current mode.
    pub fn mode(&self) -> MatcherMode {
        self.mode
    }

    /// Matches one frame's segments (with `images` for LBD and the ℓ1 matcher's photometric
    /// check; without, by geometry alone); fills `header`'s [`Matching`] and puts
    /// one record per left segment in `out` (emptied first).
    pub fn match_frame(
        &mut self,
        header: &mut TracksHeader,
        segments: &[SegmentRecord],
        images: Option<&Images>,
        out: &mut Vec<TrackedLine>,
    ) -> anyhow::Result<()> {
        let frame_id = header.frame.frame_id;
        let n_left = (header.detection.left_count as usize).min(segments.len());
        let (left_records, right_records) = segments.split_at(n_left);
        let [mut left, mut right] = std::mem::take(&mut self.spare);
        for (features, records) in [(&mut left, left_records), (&mut right, right_records)] {
            features.clear();
            features
                .segments
                .extend(records.iter().map(|r| to_segment(&r.endpoints)));
        }
        let views = match images.map(stereo_views) {
            Some(Ok(views)) => Some(views),
            Some(Err(e)) => {
                tracing::warn!("frame {frame_id}: {e}; matching by geometry");
                None
            }
            None => None,
        };
        let mut mode = self.mode;
        if mode == MatcherMode::Lbd && views.is_none() {
            mode = MatcherMode::L1;
        }
        let probe = views.is_some() && self.probes_now(mode);
        let mut matching = Matching::default();
        let mut described = false;
        if let Some((l, r)) = &views {
            let span = info_span!("describe");
            let _entered = span.enter();
            if mode == MatcherMode::Lbd || probe {
                let describe = self.describe_right.state()?;
                std::mem::swap(&mut describe.features, &mut right);
                describe.left.clone_from(&left.segments);
                let lbd = &mut self.lbd;
                let (described_right, right_done, left_done) = self
                    .describe_right
                    .run_while(r, || lbd.describe(l, &mut left))?;
                std::mem::swap(&mut described_right.features, &mut right);
                left_done.and(right_done)?;
                described = true;
            }
            if mode == MatcherMode::L1 {
                // The ℓ1 matcher's photometric check reads the images too (tens of µs).
                self.l1.describe(l, &mut left)?;
                self.l1.describe(r, &mut right)?;
            }
        }
        {
            let span = info_span!("stereo_match");
            let _entered = span.enter();
            if mode == MatcherMode::Lbd {
                self.lbd
                    .match_lines(MatchCase::Stereo, &left, &right, &mut self.stereo);
            } else {
                if probe {
                    self.lbd
                        .match_lines(MatchCase::Stereo, &left, &right, &mut self.stereo);
                    matching.lbd_probe_matches = self.stereo.len() as i32;
                }
                self.l1
                    .match_lines(MatchCase::Stereo, &left, &right, &mut self.stereo);
            }
        }
        self.tracked.clear();
        if let Some(previous) = &self.previous {
            let span = info_span!("track_match");
            let _entered = span.enter();
            let use_lbd = mode == MatcherMode::Lbd && previous.described && described;
            let matcher = if use_lbd { &mut self.lbd } else { &mut self.l1 };
            matcher.match_lines(
                MatchCase::FrameToFrame,
                &previous.features,
                &left,
                &mut self.tracked,
            );
            matching.previous_frame_id = previous.frame_id;
        }
        if self.mode == MatcherMode::L1 {
            self.frames_in_l1 += 1;
        }
        matching.mode = mode.into();
        matching.stereo_matches = self.stereo.len() as u32;
        matching.tracked_matches = self.tracked.len() as u32;
        header.matching = matching;

        out.clear();
        out.extend(left_records.iter().map(|r| TrackedLine {
            left: r.endpoints,
            previous: -1,
            ..TrackedLine::default()
        }));
        for m in &self.stereo {
            if let (Some(t), Some(r)) = (out.get_mut(m.query), right_records.get(m.train)) {
                t.right = r.endpoints;
                t.has_stereo = 1;
            }
        }
        for m in &self.tracked {
            if let Some(t) = out.get_mut(m.train) {
                t.previous = i32::try_from(m.query).unwrap_or(-1);
            }
        }
        let done = self.previous.replace(Previous {
            frame_id,
            features: left,
            described,
        });
        self.spare = [done.map(|p| p.features).unwrap_or_default(), right];
        Ok(())
    }
}

impl Stage for FrameMatcher {
    type Input = SegmentRecord;
    type InputHeader = SegmentsHeader;
    type Output = TrackedLine;
    type OutputHeader = TracksHeader;
    const KIND: StageKind = StageKind::Matcher;
    const INPUT: TopicOf<Self::Input, Self::InputHeader> = topics::SEGMENTS;
    const OUTPUT: TopicOf<Self::Output, Self::OutputHeader> = topics::TRACKS;
    const OUTPUT_LEN: usize = 128;

    fn joins_images(&self) -> bool {
        true
    }

    fn keeps_state(&self) -> bool {
        true
    }

    fn process(
        &mut self,
        header: &mut TracksHeader,
        segments: &Received<SegmentRecord, SegmentsHeader>,
        images: Option<&Images>,
        out: &mut Vec<TrackedLine>,
    ) -> anyhow::Result<()> {
        self.match_frame(header, segments.payload(), images, out)
    }

    fn command(&mut self, command: Command, control: &Control) {
        if command == Command::SetMatcherMode {
            match decode::<MatcherMode>(control.value) {
                Ok(mode) => self.set_mode(mode),
                Err(unknown) => tracing::warn!("{unknown}: mode unchanged"),
            }
        }
    }
}

/// Runs the matcher stage until shutdown.
pub fn run(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    run_stage(ctx, bus, FrameMatcher::new(ctx)?, shutdown)
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_pipeline_config::PipelineConfig;
    use linetrack_stage_runtime::{stereo_frame, to_records};
    use linetrack_vision::DetectorKind;

    fn matcher(policy: MatcherPolicy) -> FrameMatcher {
        matcher_with(policy, false)
    }

    fn matcher_with(policy: MatcherPolicy, sides_in_parallel: bool) -> FrameMatcher {
        let mut config = PipelineConfig::default();
        config.matcher.mode = policy;
        config.detect_sides_in_parallel = sides_in_parallel;
        let ctx = StageContext::in_process(StageKind::Matcher, config, std::path::PathBuf::new());
        FrameMatcher::new(&ctx).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn only_the_auto_policy_probes_lbd_from_l1() {
        // Under `auto`, fallen back to ℓ1: the first ℓ1 frame and every probe_every-th.
        let mut auto = matcher(MatcherPolicy::Auto);
        auto.set_mode(MatcherMode::L1);
        assert!(auto.probes_now(MatcherMode::L1));
        auto.frames_in_l1 = 1;
        assert!(!auto.probes_now(MatcherMode::L1));
        auto.frames_in_l1 = auto.probe_every;
        assert!(auto.probes_now(MatcherMode::L1));
        // ℓ1 only: never (each probe cost an LBD description, ~15 ms, every 5th frame).
        let mut l1 = matcher(MatcherPolicy::L1);
        for frames in 0..10 {
            l1.frames_in_l1 = frames;
            assert!(!l1.probes_now(MatcherMode::L1), "frame {frames}");
        }
    }

    /// Three EuRoC frames' LSD segments matched by LBD, the images described one side
    /// after the other or at the same time.
    fn lbd_tracks(sides_in_parallel: bool) -> Vec<(Matching, Vec<TrackedLine>)> {
        let config = PipelineConfig::default();
        let mut detector =
            linetrack_vision::create_detector(DetectorKind::Lsd, &config.odometry.frontend)
                .unwrap_or_else(|e| panic!("{e}"));
        let mut matcher = matcher_with(MatcherPolicy::Lbd, sides_in_parallel);
        (0..3)
            .map(|index| {
                let (left, right) =
                    linetrack_test_data::euroc_stereo_pair(index).unwrap_or_else(|e| panic!("{e}"));
                let read =
                    |p: &std::path::Path| GrayImage::load(p).unwrap_or_else(|e| panic!("{e}"));
                let (left, right) = (read(&left), read(&right));
                let mut segments = Vec::new();
                detector
                    .detect(&left, &mut segments)
                    .unwrap_or_else(|e| panic!("{e}"));
                let mut records = to_records(&segments);
                let left_count = records.len() as u32;
                detector
                    .detect(&right, &mut segments)
                    .unwrap_or_else(|e| panic!("{e}"));
                records.extend(to_records(&segments));
                let frame =
                    stereo_frame(index as u64, &left, &right).unwrap_or_else(|e| panic!("{e}"));
                let mut header = TracksHeader::from(*frame.header());
                header.detection.left_count = left_count;
                let mut tracks = Vec::new();
                matcher
                    .match_frame(&mut header, &records, Some(&frame), &mut tracks)
                    .unwrap_or_else(|e| panic!("{e}"));
                (header.matching, tracks)
            })
            .collect()
    }

    #[test]
    fn lbd_describing_both_sides_at_once_matches_as_one_after_the_other() {
        let (serial, parallel) = (lbd_tracks(false), lbd_tracks(true));
        for (frame, (one_by_one, at_once)) in serial.iter().zip(&parallel).enumerate() {
            assert_eq!(one_by_one.0.mode, MatcherMode::Lbd.into());
            assert!(
                one_by_one.0.stereo_matches > 20,
                "frame {frame}: {:?}",
                one_by_one.0
            );
            if frame > 0 {
                assert!(
                    one_by_one.0.tracked_matches > 20,
                    "frame {frame}: {:?}",
                    one_by_one.0
                );
            }
            assert_eq!(at_once, one_by_one, "frame {frame}");
        }
    }
}
