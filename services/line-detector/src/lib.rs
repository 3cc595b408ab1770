//! The line detector: LSD or FLD on both images of each frame, read in place from shared
//! memory, publishing the segments.
//!
//! Hot swap (the stage runtime's, see `linetrack_stage_runtime::run_stage`): a second
//! detector of the other kind starts with `--standby`, warms up and holds the newest frames
//! until the running one hands over; no frame is lost or published twice.

use linetrack_ipc::{Bus, Received, Shutdown};
use linetrack_msgs::{FrameHeader, SegmentRecord, StageKind, Topic};
use linetrack_stage_runtime::{
    Stage, StageContext, detector_code, run_stage, stereo_views, to_records,
};
use linetrack_vision::{GrayImage, LineDetector, create_detector, stretch_contrast};

/// The detector stage: one detector, with its output buffers.
pub struct Detector {
    detector: Box<dyn LineDetector>,
    kind_code: u32,
    pid: u32,
    max_contrast_gain: f64,
    left: Vec<linetrack_geometry::Segment>,
    right: Vec<linetrack_geometry::Segment>,
}

impl Detector {
    /// The detector `ctx` asks for (`--detector`, else the config's), warmed up: the first
    /// detection allocates.
    pub fn new(ctx: &StageContext) -> anyhow::Result<Self> {
        let kind = ctx.args.detector.unwrap_or(ctx.config.detector);
        let mut detector = Self {
            detector: create_detector(kind, &ctx.config.odometry.frontend)?,
            kind_code: detector_code(kind),
            pid: ctx.pid,
            max_contrast_gain: ctx.config.odometry.max_contrast_gain,
            left: Vec::new(),
            right: Vec::new(),
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
        detector.detector.detect(&warm, &mut detector.left)?;
        tracing::info!("{} detector ready", kind.name());
        Ok(detector)
    }
}

impl Stage for Detector {
    type Input = u8;
    type Output = SegmentRecord;
    const KIND: StageKind = StageKind::LineDetector;
    const INPUT: Topic = Topic::Frames;
    const OUTPUT: Topic = Topic::Segments;
    const OUTPUT_LEN: usize = 256;

    fn joins_images(&self) -> bool {
        // The input is the images.
        false
    }

    fn detail(&self) -> u32 {
        self.kind_code
    }

    fn process(
        &mut self,
        header: &mut FrameHeader,
        frame: &Received<u8>,
        _images: Option<&Received<u8>>,
    ) -> anyhow::Result<Vec<SegmentRecord>> {
        header.detector = self.kind_code;
        header.detector_pid = self.pid;
        let (left, right) = stereo_views(frame)?;
        // Dark images are stretched first, as the odometry does (`odometry.max_contrast_gain`).
        let (left_stretched, right_stretched) = (
            stretch_contrast(&left, self.max_contrast_gain)?,
            stretch_contrast(&right, self.max_contrast_gain)?,
        );
        let left = left_stretched.as_ref().unwrap_or(&left);
        let right = right_stretched.as_ref().unwrap_or(&right);
        self.detector.detect(left, &mut self.left)?;
        self.detector.detect(right, &mut self.right)?;
        header.left_count = self.left.len() as u32;
        header.right_count = self.right.len() as u32;
        let mut records = to_records(&self.left);
        records.extend(to_records(&self.right));
        Ok(records)
    }
}

/// Runs the detector stage until shutdown (or, after a hand-over, until its part is
/// published).
pub fn run(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    run_stage(ctx, bus, Detector::new(ctx)?, shutdown)
}
