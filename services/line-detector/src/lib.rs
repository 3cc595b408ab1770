//! The line detector: LSD, FLD or edgelines on both images of each frame, read in place from
//! shared memory, publishing the segments.
//!
//! Hot swap: a second detector starts with `--standby`, warms up and holds the newest
//! frames; the supervisor then asks the running one to hand over. The running detector
//! picks the hand-over frame F (the first it has not published, and no earlier than the
//! oldest frame the standby holds), publishes everything below F, reports `HandedOver(F)`
//! and exits; the standby, told F, publishes from F on. Frames below F come only from the
//! old detector and frames from F on only from the new one: none lost, none twice.

use linetrack_ipc::{Bus, Inlet, Outlet, Received, Shutdown, Wake};
use linetrack_msgs::{Command, Control, FrameHeader, SegmentRecord, StageKind, StatusKind, Topic};
use linetrack_stage_runtime::{
    GapWatch, HeldFrames, Reporter, StageContext, detector_code, process_frame, stereo_views,
    to_records,
};
use linetrack_vision::{GrayImage, LineDetector, create_detector, stretch_contrast};
use std::time::Duration;
use tracing::info_span;

/// The detector's connections.
pub struct Ports {
    frames: Inlet<u8>,
    segments: Outlet<SegmentRecord>,
    control: Inlet<Control>,
    wake: Wake,
    reporter: Reporter,
}

impl Ports {
    /// Opens the detector's services on `bus`.
    pub fn open(bus: &Bus, ctx: &StageContext) -> anyhow::Result<Self> {
        let kind = ctx.args.detector.unwrap_or(ctx.config.detector);
        Ok(Self {
            frames: bus.inlet(Topic::Frames)?,
            segments: bus.outlet(Topic::Segments, 256)?,
            control: bus.inlet(Topic::Control)?,
            wake: bus.wake(StageKind::LineDetector)?,
            reporter: Reporter::new(bus, ctx, detector_code(kind))?,
        })
    }
}

/// Where the detector is in a hot swap.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    /// Waiting to take over; holds frames.
    Standby,
    /// Detecting and publishing.
    Active,
    /// Publishing frames below `at`, then handing over.
    HandingOver { at: u64 },
}

struct Detector {
    detector: Box<dyn LineDetector>,
    kind_code: u32,
    pid: u32,
    left: Vec<linetrack_geometry::Segment>,
    right: Vec<linetrack_geometry::Segment>,
}

impl Detector {
    /// Detects and publishes one frame (or forwards its drop marker).
    fn process(
        &mut self,
        ctx: &StageContext,
        frame: &Received<u8>,
        newer_waiting: bool,
        out: &mut Outlet<SegmentRecord>,
    ) -> anyhow::Result<()> {
        let mut header: FrameHeader = *frame.header();
        let span = info_span!("detect", frame_id = header.frame_id);
        let _entered = span.enter();
        header.detector = self.kind_code;
        header.detector_pid = self.pid;
        // Dark images are stretched first, as the odometry does (`odometry.max_contrast_gain`).
        let gain = ctx.config.odometry.max_contrast_gain;
        let work = |h: &mut FrameHeader| {
            let (left, right) = stereo_views(frame)?;
            let (left_stretched, right_stretched) = (
                stretch_contrast(&left, gain)?,
                stretch_contrast(&right, gain)?,
            );
            let left = left_stretched.as_ref().unwrap_or(&left);
            let right = right_stretched.as_ref().unwrap_or(&right);
            self.detector.detect(left, &mut self.left)?;
            self.detector.detect(right, &mut self.right)?;
            h.left_count = self.left.len() as u32;
            h.right_count = self.right.len() as u32;
            let mut records = to_records(&self.left);
            records.extend(to_records(&self.right));
            Ok(records)
        };
        process_frame(
            StageKind::LineDetector,
            header,
            newer_waiting,
            &ctx.config.budget,
            out,
            work,
            Vec::new,
        )
    }
}

/// Runs the detector until shutdown (or, after a hand-over, until its part is published).
pub fn run(ctx: &StageContext, mut ports: Ports, shutdown: &Shutdown) -> anyhow::Result<()> {
    let kind = ctx.args.detector.unwrap_or(ctx.config.detector);
    let mut detector = Detector {
        detector: create_detector(kind, &ctx.config.odometry.frontend)?,
        kind_code: detector_code(kind),
        pid: ctx.pid,
        left: Vec::new(),
        right: Vec::new(),
    };
    // Warm up on a synthetic image: the first detection allocates.
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

    let mut role = if ctx.args.standby {
        Role::Standby
    } else {
        Role::Active
    };
    let mut held = HeldFrames::default();
    let mut gaps = GapWatch::default();
    let mut next_unpublished = 0u64;
    let mut processed = 0u64;
    let mut ready_sent = false;
    if role == Role::Active {
        ports.reporter.report(StatusKind::Ready, 0, 0);
        ready_sent = true;
    }
    tracing::info!("{} detector {:?}", kind.name(), role);
    while !shutdown.requested() {
        // Commands first: they decide what to do with the frames.
        for message in ports.control.receive_all()? {
            let Some(&c) = message.payload().first() else {
                continue;
            };
            if !c.is_for(StageKind::LineDetector, ctx.pid) {
                continue;
            }
            match Command::from_code(c.command) {
                Some(Command::Shutdown) => return Ok(()),
                Some(Command::HandOver) if role == Role::Active => {
                    let at = next_unpublished.max(c.frame_id);
                    tracing::info!("handing over at frame {at}");
                    role = Role::HandingOver { at };
                }
                Some(Command::TakeOver) if role == Role::Standby => {
                    tracing::info!("taking over at frame {}", c.frame_id);
                    // Held frames below F were published by the old detector.
                    if let Some(first) = held.first_id()
                        && first > c.frame_id
                    {
                        tracing::warn!(
                            "frames {}..{first} were released before the take-over",
                            c.frame_id
                        );
                    }
                    let frames: Vec<Received<u8>> = std::iter::from_fn(|| held.take_next())
                        .filter(|f| f.header().frame_id >= c.frame_id)
                        .collect();
                    role = Role::Active;
                    // Held frames were queued by the swap, not by slowness: none is dropped as
                    // behind (the age limit still applies).
                    for frame in &frames {
                        detector.process(ctx, frame, false, &mut ports.segments)?;
                        processed += 1;
                    }
                }
                _ => {}
            }
        }
        match role {
            Role::Standby => {
                let overflow = held.receive(&mut ports.frames)?;
                ports.reporter.overflow(overflow);
                if !ready_sent && let Some(first) = held.first_id() {
                    ports.reporter.report(StatusKind::Ready, first, 0);
                    ready_sent = true;
                }
            }
            Role::Active | Role::HandingOver { .. } => {
                // Nothing is held here: the whole queue fits the borrow limit.
                let frames = ports.frames.receive_all()?;
                let count = frames.len();
                for (k, frame) in frames.iter().enumerate() {
                    let id = frame.header().frame_id;
                    ports.reporter.gap(gaps.observe(id));
                    if let Role::HandingOver { at } = role
                        && id >= at
                    {
                        // Every frame below F has been seen: the rest is the new detector's.
                        next_unpublished = next_unpublished.max(at);
                        break;
                    }
                    let span = info_span!("frame", frame_id = id);
                    let _entered = span.enter();
                    detector.process(ctx, frame, k + 1 < count, &mut ports.segments)?;
                    next_unpublished = id + 1;
                    processed += 1;
                }
            }
        }
        if let Role::HandingOver { at } = role
            && next_unpublished >= at
        {
            ports.reporter.report(StatusKind::HandedOver, at, processed);
            tracing::info!("handed over at frame {at} after {processed} frames");
            return Ok(());
        }
        ports.reporter.beat(processed);
        ports
            .wake
            .wait(ports.reporter.until_due().max(Duration::from_millis(1)))?;
    }
    Ok(())
}
