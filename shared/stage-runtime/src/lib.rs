//! What every node process of the pipeline shares.
//!
//! A node binary's `main` is one call, [`stage_main`] (or [`node_main`] with a log filter of
//! its own): it parses the [`StageArgs`] the supervisor passes, loads the run's config,
//! starts telemetry, joins the run's shared-memory bus, arms SIGINT/SIGTERM, and runs the
//! node's loop. The loop is the runtime's, by the node's role: [`run_stage`] for a
//! processing stage (one input message in, one output message out, per frame),
//! [`run_source`] for a node that brings frames in (a sequence, a recording, a camera, or
//! frames delivered by another system's callbacks), [`run_sink`] for one that takes
//! messages out (the recorder, the link). Each uses a [`Reporter`] for heartbeats and
//! events, and hears the supervisor's stop through [`shutdown_ordered`].

use anyhow::Context;
use clap::Parser;
use linetrack_geometry::{Point, Segment, StereoRig};
use linetrack_ipc::{Bus, Inlet, IpcError, Outlet, Received, Record, Scope, Shutdown};

mod drop_rule;
#[cfg(feature = "images")]
mod images;
mod runner;
#[cfg(feature = "images")]
mod side;
mod sink;
mod source;
pub mod time;
pub use drop_rule::{WorkTime, WorkTimes, late_drop, stages_left};
#[cfg(feature = "images")]
pub use images::{stereo_frame, stereo_views};
use linetrack_msgs::{Command, Control, RigRecord, SegmentRecord, topics};
use linetrack_msgs::{
    Detector, FrameHeader, FrameMessage, FrameStatus, StageKind, StatusKind, StatusReport, Topic,
};
use linetrack_pipeline_config::{BudgetConfig, PipelineConfig};
use linetrack_vision_config::DetectorKind;
pub use runner::{Stage, run_stage};
#[cfg(feature = "images")]
pub use side::RightImageWorker;
pub use sink::{Sink, run_sink};
pub use source::{RigOutlet, Source, SourceOut, Step, run_source};
use std::collections::VecDeque;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;
pub use time::{Backoff, Clock, GivenUp};

/// The arguments the supervisor passes to every stage.
#[derive(Debug, Clone, Parser)]
#[command(about = "A linetrack pipeline stage; started by the supervisor (`linetrack run`).")]
pub struct StageArgs {
    /// The run's pipeline config (the supervisor writes the effective one into the run folder).
    #[arg(long)]
    pub config: PathBuf,
    /// The run's id: it names the shared-memory services.
    #[arg(long)]
    pub run_id: String,
    /// The run folder (span files go under it).
    #[arg(long)]
    pub run_dir: PathBuf,
    /// Line detector: overrides the config's (a hot swap starts the other one).
    #[arg(long)]
    pub detector: Option<DetectorKind>,
    /// Start as a standby detector: warm up, report ready, wait for the hand-over.
    #[arg(long)]
    pub standby: bool,
    /// Frame source: start at this frame (after a restart).
    #[arg(long, default_value_t = 0)]
    pub start_frame: usize,
    /// Pose estimator: continue from this pose, "frame,tx,ty,tz,qx,qy,qz,qw" (after a restart).
    #[arg(long)]
    pub resume_pose: Option<String>,
    /// The supervisor's pid: the stage ends when that process does.
    #[arg(long)]
    pub supervisor_pid: Option<u32>,
}

/// A stage's view of its run.
#[derive(Debug, Clone)]
pub struct StageContext {
    /// Which stage this is.
    pub stage: StageKind,
    /// The run's config.
    pub config: PipelineConfig,
    /// Arguments.
    pub args: StageArgs,
    /// This process.
    pub pid: u32,
    /// The time the stage's policies read.
    pub clock: Clock,
}

impl StageContext {
    /// A context for an in-process stage (single-process mode and tests).
    pub fn in_process(stage: StageKind, config: PipelineConfig, run_dir: PathBuf) -> Self {
        let args = StageArgs {
            config: PathBuf::new(),
            run_id: "local".to_string(),
            run_dir,
            detector: None,
            standby: false,
            start_frame: 0,
            resume_pose: None,
            supervisor_pid: None,
        };
        Self {
            stage,
            config,
            args,
            pid: std::process::id(),
            clock: Clock::System,
        }
    }

    /// The heartbeat period.
    pub fn heartbeat(&self) -> Duration {
        Duration::from_millis(self.config.supervisor.heartbeat_ms)
    }

    /// This stage's budget, milliseconds.
    pub fn budget_ms(&self) -> f64 {
        self.config
            .budget
            .stage_ms(self.stage)
            .unwrap_or(f64::INFINITY)
    }
}

/// Sends a stage's heartbeats and events on the status topic.
pub struct Reporter {
    outlet: Outlet<StatusReport, ()>,
    stage: StageKind,
    pid: u32,
    detail: u32,
    every: Duration,
    clock: Clock,
    last_ns: Option<u64>,
}

impl Reporter {
    /// A reporter for `ctx`'s stage; `detail` travels in every report (the detector kind).
    pub fn new(bus: &Bus, ctx: &StageContext, detail: u32) -> Result<Self, IpcError> {
        Ok(Self {
            outlet: bus.outlet(topics::STATUS, 1)?,
            stage: ctx.stage,
            pid: ctx.pid,
            detail,
            every: ctx.heartbeat(),
            clock: ctx.clock.clone(),
            last_ns: None,
        })
    }

    /// Sends an event.
    pub fn report(&mut self, kind: StatusKind, frame_id: u64, value: u64) {
        self.report_detail(kind, frame_id, value, self.detail);
    }

    /// Sends an event with its own `detail` code in place of the stage's (the reason of a
    /// `CameraLost`).
    pub fn report_detail(&mut self, kind: StatusKind, frame_id: u64, value: u64, detail: u32) {
        let report = StatusReport {
            stage: self.stage.into(),
            pid: self.pid,
            kind: kind.into(),
            detail,
            frame_id,
            value,
        };
        if let Err(e) = self.outlet.publish(&(), &[&[report]]) {
            tracing::warn!("status report lost: {e}");
        }
        if kind == StatusKind::Heartbeat {
            self.last_ns = Some(self.clock.now_ns());
        }
    }

    /// Sends a heartbeat if one is due; `processed` = frames handled so far.
    pub fn beat(&mut self, processed: u64) {
        if self
            .last_ns
            .is_none_or(|t| self.clock.since(t) >= self.every)
        {
            self.report(StatusKind::Heartbeat, 0, processed);
        }
    }

    /// Reports an overflow of the stage's hold, if there was one (the supervisor records it
    /// as an event).
    pub fn overflow(&mut self, overflow: Overflow) {
        if let Some(first) = overflow.first_frame {
            tracing::warn!(
                "hold full ({} messages): {} frames from {first} released before their turn",
                overflow.capacity,
                overflow.frames
            );
            self.report(StatusKind::Overflow, first, overflow.frames);
        }
    }

    /// Reports frames that never arrived on the stage's input (see [`GapWatch`]).
    pub fn gap(&mut self, gap: Option<(u64, u64)>) {
        if let Some((first, count)) = gap {
            tracing::warn!(
                "frames {first}..{} never arrived: lost in the full queue",
                first + count
            );
            self.report(StatusKind::QueueGap, first, count);
        }
    }

    /// How long until the next heartbeat is due.
    pub fn until_due(&self) -> Duration {
        self.last_ns.map_or(Duration::ZERO, |t| {
            self.every.saturating_sub(self.clock.since(t))
        })
    }
}

/// What a stage applies to every frame it takes: who it is, its budget, its clock, its
/// recent time a frame (for the drop rule, [`late_drop`]).
#[derive(Debug, Clone, Copy)]
pub struct FramePolicy<'a> {
    /// The stage.
    pub stage: StageKind,
    /// The run's budget.
    pub budget: &'a BudgetConfig,
    /// The stage's clock.
    pub clock: &'a Clock,
    /// The stage's recent time for a frame of this one's kind (prepared ahead or not,
    /// [`WorkTimes::expected`]).
    pub work: &'a WorkTime,
}

/// Takes one frame through a stage: stamps when it took it, applies the drop policy
/// (`newer_waiting`: a newer frame is queued behind it), runs `work` on `stage` for a frame
/// still to be processed — it fills the stage's own results in the header and its records
/// in `records` (emptied first; the caller keeps it from frame to frame); an error marks
/// the frame failed by this stage and is logged — and publishes the records, or those of
/// `placeholder` for a dropped or failed frame, under the stamped header. Returns how long
/// `work` took, milliseconds of the stage's clock (`None` for a frame not processed), for
/// the stage's [`WorkTime`].
#[allow(clippy::too_many_arguments)] // the frame, where it goes, and the stage's two answers
pub fn process_frame<S, O: Record, H: Record + FrameMessage>(
    policy: FramePolicy<'_>,
    mut header: H,
    newer_waiting: bool,
    out: &mut Outlet<O, H>,
    records: &mut Vec<O>,
    stage: &mut S,
    work: impl FnOnce(&mut S, &mut H, &mut Vec<O>) -> anyhow::Result<()>,
    placeholder: impl FnOnce(&S, &mut Vec<O>),
) -> anyhow::Result<Option<f64>> {
    let kind = policy.stage;
    let taken_ns = policy.clock.now_ns();
    let frame = header.frame_mut();
    stamp_start(frame, kind, taken_ns);
    if frame.is_ok()
        && let Some(status) = late_drop(
            frame,
            newer_waiting,
            policy.budget,
            kind,
            policy.work,
            taken_ns,
        )
    {
        frame.mark(status, kind);
    }
    records.clear();
    let worked = header.frame().is_ok();
    if worked {
        if let Err(e) = work(stage, &mut header, records) {
            tracing::warn!("frame {}: {e:#}", header.frame().frame_id);
            header.frame_mut().mark(FrameStatus::StageError, kind);
            records.clear();
            placeholder(stage, records);
        }
    } else {
        placeholder(stage, records);
    }
    let end_ns = policy.clock.now_ns();
    stamp_end(header.frame_mut(), kind, end_ns);
    out.publish(&header, &[records])?;
    Ok(worked.then(|| end_ns.saturating_sub(taken_ns) as f64 / 1e6))
}

/// Marks `header` as taken by `stage` at `now_ns`.
pub fn stamp_start(header: &mut FrameHeader, stage: StageKind, now_ns: u64) {
    if let Some(s) = header.stamp_mut(stage) {
        s.start_ns = now_ns;
    }
}

/// Marks `header` as published by `stage` at `now_ns`.
pub fn stamp_end(header: &mut FrameHeader, stage: StageKind, now_ns: u64) {
    if let Some(s) = header.stamp_mut(stage) {
        s.end_ns = now_ns;
    }
}

/// A frame's images as received: left image then right image, row-major, under the frame's
/// header.
pub type Images = Received<u8, FrameHeader>;

/// Messages of `topic` a stage holds at most (see [`Held`]).
pub const fn held_capacity(topic: Topic) -> usize {
    topic.queue_depth() - 1
}

/// Frames a stage holds at most: the images' hold.
pub const HELD_FRAMES: usize = held_capacity(Topic::Frames);

/// Frames released from a hold before their turn: the hold overflowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Overflow {
    /// The hold's capacity.
    pub capacity: usize,
    /// The first frame released.
    pub first_frame: Option<u64>,
    /// Frames released.
    pub frames: u64,
}

impl Overflow {
    fn add(&mut self, frame_id: u64) {
        self.first_frame.get_or_insert(frame_id);
        self.frames += 1;
    }
}

/// Watches the frame ids of a stage's main input for gaps: frames the queue overwrote
/// while the stage was stopped or slow (every frame, dropped ones too, travels down the
/// pipeline, so ids arrive one after another).
#[derive(Debug, Clone, Copy, Default)]
pub struct GapWatch {
    next: Option<u64>,
}

impl GapWatch {
    /// Takes the next frame id; returns `(first, count)` of the frames skipped before it.
    /// An id below the expected one (an earlier frame arriving late) is no gap.
    pub fn observe(&mut self, frame_id: u64) -> Option<(u64, u64)> {
        let gap = self
            .next
            .filter(|&n| frame_id > n)
            .map(|n| (n, frame_id - n));
        self.next = Some(self.next.map_or(frame_id + 1, |n| n.max(frame_id + 1)));
        gap
    }
}

/// Messages held (in shared memory, not copied): images until the stage's input for the
/// same frame arrives, or a standby's inputs until it takes over. At most one less than the
/// topic's subscriber borrow limit ([`Topic::queue_depth`], which also sizes its buffer),
/// so that the held messages and the one being received never exceed what iceoryx2 lets a
/// subscriber borrow, however long the stage was stopped.
pub struct Held<P: Record, H: Record + FrameMessage> {
    held: VecDeque<Received<P, H>>,
    capacity: usize,
}

impl<P: Record, H: Record + FrameMessage> Held<P, H> {
    /// An empty hold for messages of `topic`.
    pub fn new(topic: Topic) -> Self {
        let capacity = held_capacity(topic);
        Self {
            held: VecDeque::with_capacity(capacity),
            capacity,
        }
    }

    /// Holds `message`, releasing the oldest when full; returns the id of the frame released.
    pub fn push(&mut self, message: Received<P, H>) -> Option<u64> {
        let released = (self.held.len() >= self.capacity)
            .then(|| self.held.pop_front())
            .flatten()
            .map(|f| f.header().frame().frame_id);
        self.held.push_back(message);
        released
    }

    /// Receives every waiting message into the hold, one at a time (the oldest released
    /// first when full, so never more than the subscriber's borrow limit is borrowed);
    /// returns what was released to make room.
    pub fn receive(&mut self, inlet: &mut Inlet<P, H>) -> Result<Overflow, IpcError> {
        let mut overflow = Overflow {
            capacity: self.capacity,
            ..Overflow::default()
        };
        while let Some(message) = inlet.receive()? {
            if let Some(id) = self.push(message) {
                overflow.add(id);
            }
        }
        Ok(overflow)
    }

    /// Takes frame `frame_id`'s message, releasing every older one (their turn has passed).
    pub fn take(&mut self, frame_id: u64) -> Option<Received<P, H>> {
        while self.first_id().is_some_and(|id| id < frame_id) {
            self.held.pop_front();
        }
        if self.first_id() == Some(frame_id) {
            self.held.pop_front()
        } else {
            None
        }
    }

    /// The held messages, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &Received<P, H>> {
        self.held.iter()
    }

    /// Takes the oldest held message.
    pub fn take_next(&mut self) -> Option<Received<P, H>> {
        self.held.pop_front()
    }

    /// Messages held.
    pub fn len(&self) -> usize {
        self.held.len()
    }

    /// Whether none is held.
    pub fn is_empty(&self) -> bool {
        self.held.is_empty()
    }

    /// The oldest held message's frame id.
    pub fn first_id(&self) -> Option<u64> {
        self.held.front().map(|f| f.header().frame().frame_id)
    }
}

/// Segments as records.
pub fn to_records(segments: &[Segment]) -> Vec<SegmentRecord> {
    segments.iter().map(to_record).collect()
}

/// A segment as a record.
pub fn to_record(s: &Segment) -> SegmentRecord {
    SegmentRecord {
        endpoints: [
            s.start.x as f32,
            s.start.y as f32,
            s.end.x as f32,
            s.end.y as f32,
        ],
    }
}

/// A record as a segment.
pub fn to_segment(endpoints: &[f32; 4]) -> Segment {
    let [x1, y1, x2, y2] = endpoints.map(f64::from);
    Segment::new(Point::new(x1, y1), Point::new(x2, y2))
}

/// A rig as a record.
pub fn rig_record(rig: &StereoRig) -> RigRecord {
    RigRecord {
        focal_px: rig.focal_px,
        cx_px: rig.cx_px,
        cy_px: rig.cy_px,
        baseline_m: rig.baseline_m,
        width_px: rig.width_px,
        height_px: rig.height_px,
    }
}

/// A record as a rig, refused (saying which value) unless it describes a camera: finite,
/// positive focal length and baseline, a non-empty image with the principal point inside.
pub fn rig_from_record(r: &RigRecord) -> anyhow::Result<StereoRig> {
    let finite = [r.focal_px, r.cx_px, r.cy_px, r.baseline_m]
        .iter()
        .all(|v| v.is_finite());
    anyhow::ensure!(finite, "the stereo rig has a non-finite value: {r:?}");
    anyhow::ensure!(
        r.focal_px > 0.0 && r.baseline_m > 0.0,
        "the stereo rig's focal length ({} px) and baseline ({} m) must be positive",
        r.focal_px,
        r.baseline_m
    );
    anyhow::ensure!(
        r.width_px > 0 && r.height_px > 0,
        "the stereo rig's image is {}×{} pixels",
        r.width_px,
        r.height_px
    );
    anyhow::ensure!(
        (0.0..=f64::from(r.width_px)).contains(&r.cx_px)
            && (0.0..=f64::from(r.height_px)).contains(&r.cy_px),
        "the stereo rig's principal point ({}, {}) lies outside its {}×{} image",
        r.cx_px,
        r.cy_px,
        r.width_px,
        r.height_px
    );
    Ok(StereoRig {
        focal_px: r.focal_px,
        cx_px: r.cx_px,
        cy_px: r.cy_px,
        baseline_m: r.baseline_m,
        width_px: r.width_px,
        height_px: r.height_px,
    })
}

/// A detector kind as the wire names it (in status reports and detections).
pub fn detector_on_wire(kind: DetectorKind) -> Detector {
    match kind {
        DetectorKind::Lsd => Detector::Lsd,
        DetectorKind::Fld => Detector::Fld,
        DetectorKind::EdgeLines => Detector::EdgeLines,
    }
}

/// The detector kind the wire names.
pub fn detector_kind(detector: Detector) -> DetectorKind {
    match detector {
        Detector::Lsd => DetectorKind::Lsd,
        Detector::Fld => DetectorKind::Fld,
        Detector::EdgeLines => DetectorKind::EdgeLines,
    }
}

/// The whole `main` of a stage binary: `run` gets the context, the process's bus and the
/// shutdown flag. Errors are logged with their causes and give exit code 1.
pub fn stage_main(
    stage: StageKind,
    run: fn(&StageContext, &Bus, &Shutdown) -> anyhow::Result<()>,
) -> ExitCode {
    node_main(stage, "warn", run)
}

/// [`stage_main`] for any node, logging by `log_filter` (a `tracing` filter such as
/// `"info,zenoh=warn"`) unless `RUST_LOG` says otherwise.
pub fn node_main(
    stage: StageKind,
    log_filter: &str,
    run: fn(&StageContext, &Bus, &Shutdown) -> anyhow::Result<()>,
) -> ExitCode {
    let args = StageArgs::parse();
    match start(stage, log_filter, args, run) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{stage}: {e:#}");
            eprintln!("linetrack-{stage}: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn start(
    stage: StageKind,
    log_filter: &str,
    args: StageArgs,
    run: fn(&StageContext, &Bus, &Shutdown) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    linetrack_ipc::survive_the_file_size_limit().context("catching SIGXFSZ")?;
    let config = PipelineConfig::from_file(&args.config)?;
    // The stage's CPUs and policy first, so that every thread started from here on
    // (telemetry, iceoryx2, OpenCV) inherits them; refusals are logged once logging is up.
    let refused = linetrack_sched::apply(
        stage.name(),
        config.stages.of(stage).unwrap_or(&Default::default()),
    )?;
    let pid = std::process::id();
    let spans = config
        .output
        .trace
        .then(|| linetrack_telemetry::span_file(&args.run_dir, stage.name(), pid));
    let _spans = linetrack_telemetry::init(stage.name(), log_filter, spans.as_deref())?;
    for refusal in refused {
        tracing::warn!("{refusal}");
    }
    let shutdown = Shutdown::on_signals()?;
    end_with_parent(&shutdown, args.supervisor_pid)?;
    let bus = Bus::shared_memory(
        &Scope::new(&args.run_id).with_configured_root(config.ipc.root.as_deref()),
        &format!("{}-{pid}", stage.name()),
    )?;
    let ctx = StageContext {
        stage,
        config,
        args,
        pid,
        clock: Clock::System,
    };
    run(&ctx, &bus, &shutdown)
}

/// Whether a [`Command::Shutdown`] for `stage` (instance `pid`, or every instance) came in
/// on `control`: how the runtime's loops hear the supervisor's stop.
pub fn shutdown_ordered(
    control: &mut Inlet<Control, ()>,
    stage: StageKind,
    pid: u32,
) -> Result<bool, IpcError> {
    Ok(control.receive_all()?.iter().any(|c| {
        let c = c.payload().first().copied().unwrap_or_default();
        c.command.is(Command::Shutdown) && c.is_for(stage, pid)
    }))
}

/// Asks for shutdown when the process that started this one (the supervisor) dies: a stage
/// never outlives its supervisor. The kernel sends SIGTERM (which sets `shutdown`) when
/// the parent ends; a parent that ended before that was armed is seen by its pid.
pub fn end_with_parent(shutdown: &Shutdown, supervisor: Option<u32>) -> anyhow::Result<()> {
    rustix::process::set_parent_process_death_signal(Some(rustix::process::Signal::TERM))
        .context("arming the parent-death signal")?;
    let parent = std::os::unix::process::parent_id();
    if supervisor.is_some_and(|pid| pid != parent) {
        tracing::warn!("the supervisor is gone before this stage started: shutting down");
        shutdown.request();
    }
    Ok(())
}

#[cfg(test)]
mod role_tests;

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::SegmentsHeader;
    use linetrack_msgs::StampSlot;

    #[test]
    fn every_detector_has_its_own_wire_name_and_back() {
        let wire: Vec<Detector> = DetectorKind::ALL
            .into_iter()
            .map(detector_on_wire)
            .collect();
        assert_eq!(wire, Detector::ALL, "one wire name per kind, in order");
        for kind in DetectorKind::ALL {
            assert_eq!(detector_kind(detector_on_wire(kind)), kind);
        }
    }

    #[test]
    fn a_full_hold_and_a_full_queue_never_exceed_the_borrow_limit() {
        // Real shared memory: iceoryx2 enforces the subscriber's borrow limit.
        let scope = Scope::with_prefix(
            &format!("ltsrt{}_", std::process::id()),
            &format!("hold{}", std::process::id()),
        );
        let bus = Bus::shared_memory(&scope, &format!("hold-{}", std::process::id()))
            .unwrap_or_else(|e| panic!("{e}"));
        let mut inlet = bus
            .inlet::<u8, FrameHeader>(topics::FRAMES)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut outlet = bus
            .outlet::<u8, FrameHeader>(topics::FRAMES, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut publish = |from: u64, to: u64| {
            for id in from..to {
                outlet
                    .publish(&FrameHeader::new(id, 0, 0), &[&[1, 2, 3, 4]])
                    .unwrap_or_else(|e| panic!("{e}"));
            }
        };
        let depth = Topic::Frames.queue_depth() as u64;
        let mut held = Held::<u8, FrameHeader>::new(Topic::Frames);
        // A stage that was stopped: its queue full (the oldest overwritten), then a hold
        // full, then the queue full again.
        publish(0, 2 * depth);
        let first = held.receive(&mut inlet).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(held.len(), HELD_FRAMES);
        assert_eq!(first.frames, depth - HELD_FRAMES as u64);
        publish(2 * depth, 4 * depth);
        let second = held
            .receive(&mut inlet)
            .unwrap_or_else(|e| panic!("exceeded the borrow limit: {e}"));
        assert_eq!(held.len(), HELD_FRAMES);
        assert_eq!(second.frames, depth);
        // Queue had depth..2·depth; the hold kept the newest of them, so the next released
        // is the frame after the first one released.
        assert_eq!(first.first_frame, Some(depth));
        assert_eq!(second.first_frame, Some(depth + 1));
        // The newest frames are the ones held.
        assert_eq!(held.first_id(), Some(4 * depth - HELD_FRAMES as u64));
    }

    #[test]
    fn a_rig_travels_as_a_record_and_a_broken_one_is_refused_by_value() {
        let rig = StereoRig::default();
        assert_eq!(
            rig_from_record(&rig_record(&rig)).unwrap_or_else(|e| panic!("{e}")),
            rig
        );
        let broken = [
            (
                RigRecord {
                    focal_px: f64::NAN,
                    ..rig_record(&rig)
                },
                "non-finite",
            ),
            (
                RigRecord {
                    baseline_m: 0.0,
                    ..rig_record(&rig)
                },
                "baseline",
            ),
            (
                RigRecord {
                    width_px: 0,
                    ..rig_record(&rig)
                },
                "0×480",
            ),
            (
                RigRecord {
                    cx_px: 900.0,
                    ..rig_record(&rig)
                },
                "principal point",
            ),
        ];
        for (record, says) in broken {
            let err = rig_from_record(&record)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(err.contains(says), "{record:?}: {err:?}");
        }
    }

    #[test]
    fn gaps_in_the_frame_ids_are_found_and_late_frames_are_not_gaps() {
        let mut watch = GapWatch::default();
        assert_eq!(watch.observe(5), None, "the first frame sets the start");
        assert_eq!(watch.observe(6), None);
        assert_eq!(watch.observe(10), Some((7, 3)));
        assert_eq!(watch.observe(8), None, "a late frame");
        assert_eq!(watch.observe(11), None);
    }

    #[test]
    fn a_frame_is_processed_dropped_or_failed_and_always_published() {
        let bus = Bus::local();
        let mut inlet = bus
            .inlet::<SegmentRecord, SegmentsHeader>(topics::SEGMENTS)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut out = bus
            .outlet::<SegmentRecord, SegmentsHeader>(topics::SEGMENTS, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        let budget = BudgetConfig {
            end_to_end_ms: 100.0,
            ..BudgetConfig::default()
        };
        let clock = Clock::manual(10_000_000_000);
        // Untimed yet: the frame with a newer one behind is dropped whatever the rule.
        let work = WorkTime::default();
        let policy = FramePolicy {
            stage: StageKind::LineDetector,
            budget: &budget,
            clock: &clock,
            work: &work,
        };
        let record = SegmentRecord {
            endpoints: [1.0, 2.0, 3.0, 4.0],
        };
        let fresh = SegmentsHeader::from(FrameHeader::new(1, 0, clock.now_ns() - 10_000_000));
        let stale = SegmentsHeader::from(FrameHeader::new(2, 0, clock.now_ns() - 500_000_000));
        // The work takes 7 ms of the stage's clock.
        let ok = |_: &mut (), h: &mut SegmentsHeader, out: &mut Vec<SegmentRecord>| {
            h.detection.left_count = 1;
            clock.advance(Duration::from_millis(7));
            out.push(record);
            Ok(())
        };
        // One buffer for all: what a frame left in it does not reach the next.
        let mut records = vec![record; 3];
        let nothing = |_: &(), _: &mut Vec<SegmentRecord>| {};
        let records = &mut records;
        let took = process_frame(
            policy,
            fresh,
            false,
            &mut out,
            records,
            &mut (),
            ok,
            nothing,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(took, Some(7.0), "the work's time, for the stage's estimate");
        for (header, newer_waiting, which) in [(stale, false, "late"), (fresh, true, "behind")] {
            let not_processed = |_: &mut (), _: &mut SegmentsHeader, _: &mut Vec<_>| {
                panic!("a frame {which} is not processed")
            };
            let took = process_frame(
                policy,
                header,
                newer_waiting,
                &mut out,
                records,
                &mut (),
                not_processed,
                nothing,
            )
            .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(took, None, "a frame {which} takes no time");
        }
        process_frame(
            policy,
            fresh,
            false,
            &mut out,
            records,
            &mut (),
            |_, _, out| {
                out.push(record);
                anyhow::bail!("detector failed")
            },
            |_, out| out.push(SegmentRecord::default()),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let got = inlet.receive_all().unwrap_or_else(|e| panic!("{e}"));
        let summary: Vec<(Result<FrameStatus, _>, usize)> = got
            .iter()
            .map(|m| (m.header().frame.status.get(), m.payload().len()))
            .collect();
        assert_eq!(
            summary,
            [
                (Ok(FrameStatus::Ok), 1),
                (Ok(FrameStatus::DroppedLate), 0),
                (Ok(FrameStatus::DroppedBehind), 0),
                (Ok(FrameStatus::StageError), 1)
            ]
        );
        let first = got[0].header();
        assert_eq!(
            (first.detection.left_count, got[0].payload()[0]),
            (1, record)
        );
        let stamp = first.frame.stamps[StampSlot::LineDetector];
        assert_eq!(stamp.end_ns - stamp.start_ns, 7_000_000, "{stamp:?}");
        // A failed frame publishes the placeholder alone, not what the work left.
        assert_eq!(got[3].payload(), [SegmentRecord::default()]);
        assert!(
            got[1..]
                .iter()
                .all(|m| m.header().frame.status_by.is(StageKind::LineDetector))
        );
    }

    #[test]
    fn heartbeats_are_paced_by_the_stage_clock() {
        let bus = Bus::local();
        let mut ctx = StageContext::in_process(
            StageKind::Matcher,
            PipelineConfig::default(),
            PathBuf::new(),
        );
        ctx.clock = Clock::manual(1_000_000_000);
        let every = ctx.heartbeat();
        let mut inlet = bus
            .inlet::<StatusReport, ()>(topics::STATUS)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut reporter = Reporter::new(&bus, &ctx, 0).unwrap_or_else(|e| panic!("{e}"));
        let beats = |inlet: &mut Inlet<StatusReport, ()>| -> Vec<u64> {
            inlet
                .receive_all()
                .unwrap_or_else(|e| panic!("{e}"))
                .iter()
                .map(|m| m.payload()[0].value)
                .collect()
        };
        reporter.beat(1);
        assert_eq!(reporter.until_due(), every);
        ctx.clock.advance(every / 2);
        reporter.beat(2); // half a period later: not due
        assert_eq!(reporter.until_due(), every / 2);
        ctx.clock.advance(every / 2);
        assert_eq!(reporter.until_due(), Duration::ZERO);
        reporter.beat(3);
        assert_eq!(beats(&mut inlet), [1, 3]);
        let got_stage = {
            reporter.report(StatusKind::Ready, 0, 0);
            inlet.receive_all().unwrap_or_else(|e| panic!("{e}"))[0].payload()[0].stage
        };
        assert_eq!(got_stage.get(), Ok(StageKind::Matcher));
    }
}
