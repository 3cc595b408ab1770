//! The line detector: LSD, FLD or edgelines on both images of each frame, read in place from
//! shared memory, publishing the segments.
//!
//! Hot swap (the stage runtime's, see `linetrack_stage_runtime::run_stage`): a second
//! detector of the other kind starts with `--standby`, warms up and holds the newest frames
//! until the running one hands over; no frame is lost or published twice.

use linetrack_ipc::{Bus, Shutdown};
use linetrack_msgs::StageKind;
use linetrack_msgs::{
    Detector as WireDetector, FrameHeader, SegmentRecord, SegmentsHeader, TopicOf, topics,
};
use linetrack_stage_runtime::{
    Images, RightImageWorker, Stage, StageContext, detector_on_wire, run_stage, stereo_views,
    to_record,
};
use linetrack_vision::{ContrastStretch, GrayImage, LineDetector, create_detector};

/// One side's detector, its stretched image and its output buffer (all kept from frame to
/// frame).
struct Side {
    detector: Box<dyn LineDetector>,
    stretch: ContrastStretch,
    segments: Vec<linetrack_geometry::Segment>,
}

impl Side {
    /// Detects in `image`, stretched first when it is dark (as the odometry does:
    /// `odometry.max_contrast_gain`).
    fn detect(&mut self, image: &GrayImage, max_gain: f64) -> anyhow::Result<()> {
        let seen = self.stretch.apply(image, max_gain)?;
        self.detector.detect(seen, &mut self.segments)?;
        Ok(())
    }
}

/// The detector stage: a detector per image side, so that both sides can run at once.
pub struct Detector {
    left: Side,
    /// The right side: on a thread of its own under `detect_sides_in_parallel`, else
    /// after the left one.
    right: RightImageWorker<Side, anyhow::Error>,
    kind: WireDetector,
    pid: u32,
    max_contrast_gain: f64,
}

impl Detector {
    /// The detector `ctx` asks for (`--detector`, else the config's), warmed up: the first
    /// detection allocates.
    pub fn new(ctx: &StageContext) -> anyhow::Result<Self> {
        let kind = ctx.args.detector.unwrap_or(ctx.config.detector);
        let side = || -> anyhow::Result<Side> {
            Ok(Side {
                detector: create_detector(kind, &ctx.config.odometry.frontend)?,
                stretch: ContrastStretch::new(),
                segments: Vec::new(),
            })
        };
        let max_gain = ctx.config.odometry.max_contrast_gain;
        let right = RightImageWorker::new(
            "detect-right",
            ctx.config.detect_sides_in_parallel,
            side()?,
            move |side: &mut Side, image: &GrayImage| side.detect(image, max_gain),
        )?;
        let mut detector = Self {
            left: side()?,
            right,
            kind: detector_on_wire(kind),
            pid: ctx.pid,
            max_contrast_gain: ctx.config.odometry.max_contrast_gain,
        };
        let (w, h) = (752, 480);
        let card: Vec<u8> = (0..w * h)
            .map(|i| {
                if (i % w) / 40 % 2 == (i / w) / 40 % 2 {
                    40
                } else {
                    200
                }
            })
            .collect();
        let warm = GrayImage::from_pixels(w, h, &card, "warm-up card")?;
        detector.left.detect(&warm, 0.0)?;
        detector.right.state()?.detect(&warm, 0.0)?;
        tracing::info!("{} detector ready", kind.name());
        Ok(detector)
    }
}

impl Stage for Detector {
    type Input = u8;
    type InputHeader = FrameHeader;
    type Output = SegmentRecord;
    type OutputHeader = SegmentsHeader;
    const KIND: StageKind = StageKind::LineDetector;
    const INPUT: TopicOf<Self::Input, Self::InputHeader> = topics::FRAMES;
    const OUTPUT: TopicOf<Self::Output, Self::OutputHeader> = topics::SEGMENTS;
    const OUTPUT_LEN: usize = 256;

    fn joins_images(&self) -> bool {
        // The input is the images.
        false
    }

    fn detail(&self) -> u32 {
        self.kind.into()
    }

    fn process(
        &mut self,
        header: &mut SegmentsHeader,
        frame: &Images,
        _images: Option<&Images>,
        out: &mut Vec<SegmentRecord>,
    ) -> anyhow::Result<()> {
        let detection = &mut header.detection;
        detection.detector = self.kind.into();
        detection.detector_pid = self.pid;
        let (left, right) = stereo_views(frame)?;
        let gain = self.max_contrast_gain;
        let left_side = &mut self.left;
        let (right_side, right_done, left_done) = self
            .right
            .run_while(&right, || left_side.detect(&left, gain))?;
        left_done.and(right_done)?;
        let right_segments = &right_side.segments;
        detection.left_count = self.left.segments.len() as u32;
        detection.right_count = right_segments.len() as u32;
        out.extend(
            self.left
                .segments
                .iter()
                .chain(right_segments)
                .map(to_record),
        );
        Ok(())
    }
}

/// Runs the detector stage until shutdown (or, after a hand-over, until its part is
/// published).
pub fn run(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    run_stage(ctx, bus, Detector::new(ctx)?, shutdown)
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_pipeline_config::PipelineConfig;
    use linetrack_stage_runtime::stereo_frame;
    use std::path::PathBuf;

    /// The segments of two EuRoC stereo frames, detected with the sides at once or in turn.
    fn detect(in_parallel: bool) -> Vec<(SegmentsHeader, Vec<SegmentRecord>)> {
        let config = PipelineConfig {
            detect_sides_in_parallel: in_parallel,
            ..PipelineConfig::default()
        };
        let ctx = StageContext::in_process(StageKind::LineDetector, config, PathBuf::new());
        let mut detector = Detector::new(&ctx).unwrap_or_else(|e| panic!("{e}"));
        (0..2)
            .map(|index| {
                let (left, right) =
                    linetrack_test_data::euroc_stereo_pair(index).unwrap_or_else(|e| panic!("{e}"));
                let read =
                    |p: &std::path::Path| GrayImage::load(p).unwrap_or_else(|e| panic!("{e}"));
                let frame = stereo_frame(index as u64, &read(&left), &read(&right))
                    .unwrap_or_else(|e| panic!("{e}"));
                let mut segments = SegmentsHeader::from(*frame.header());
                let mut records = Vec::new();
                detector
                    .process(&mut segments, &frame, None, &mut records)
                    .unwrap_or_else(|e| panic!("{e}"));
                (segments, records)
            })
            .collect()
    }

    #[test]
    fn both_sides_at_once_find_what_one_after_the_other_finds() {
        let (serial, parallel) = (detect(false), detect(true));
        assert_eq!(serial.len(), 2);
        for ((serial_header, serial), (parallel_header, parallel)) in serial.iter().zip(&parallel) {
            let (serial_found, parallel_found) =
                (serial_header.detection, parallel_header.detection);
            assert!(serial_found.left_count > 20 && serial_found.right_count > 20);
            assert_eq!(parallel_found, serial_found);
            assert_eq!(parallel, serial);
        }
    }
}
