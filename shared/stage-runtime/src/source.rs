//! The source role: a node that brings frames into the pipeline (a sequence read from
//! disk, a recording replayed, a live camera, or frames another system delivers). The
//! runtime owns what every source shares: the frames' outlet, the stamps, the ready report,
//! a heartbeat that counts the frames published, the supervisor's stop, and, once the
//! source has no more frames, the `SourceFinished` report and staying until the run ends
//! (a stage restarted after the last frame still needs what the source holds: the rig).
//!
//! A source only says what one turn publishes ([`Source::step`]). A turn may wait up to the
//! time it is given for input of its own (a capture thread's queue, a subscription's
//! callback through a channel), or say how long nothing is due ([`Step::Idle`]) so that
//! the runtime sleeps on its wake-up meanwhile, where a command still reaches it.
//!
//! With `source.pacing = "fastest"` and `budget.drop_late = false` (every frame processed
//! however late), a source reading files waits for the pipeline ([`BackPressure`]): it
//! keeps at most [`IN_FLIGHT`] frames published and not yet out of the pose estimator, so
//! no stage's queue is ever full and no frame is overwritten there (`skipped`). It sleeps
//! on its wake-up meanwhile, which every pose published rings.

use crate::{Reporter, StageContext, shutdown_ordered, stamp_end};
use linetrack_ipc::{Bus, Inlet, Outlet, Shutdown};
use linetrack_msgs::{
    Control, FrameHeader, FrameStatus, PoseRecord, RigRecord, StageKind, StatusKind, StatusReport,
    TracksHeader, topics,
};
use linetrack_pipeline_config::{Pacing, PipelineConfig};
use std::time::Duration;
use tracing::info_span;

/// What a turn of a source did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Call again (it published, or its wait for input ended).
    Again,
    /// Nothing is due for this long: the runtime sleeps on its wake-up meanwhile (at most
    /// until the next heartbeat).
    Idle(Duration),
    /// No more frames: the runtime reports the source finished and stays until the run ends.
    Finished,
}

/// One source's work.
pub trait Source {
    /// Which node it is.
    const KIND: StageKind;
    /// Bytes a frame message holds before more are allocated.
    const FRAME_BYTES: usize;

    /// Publishes what must reach the stages before the first frame (the rig); the runtime
    /// reports the source ready after it.
    fn start(&mut self, out: &mut SourceOut) -> anyhow::Result<()>;

    /// One turn: publishes into `out` what is due, waiting at most `wait` for input it does
    /// not have yet.
    fn step(&mut self, out: &mut SourceOut, wait: Duration) -> anyhow::Result<Step>;

    /// Called on every turn and while the source stays after its last frame (the rig's
    /// outlet connects the stages that started since).
    fn poll(&mut self) -> anyhow::Result<()> {
        Ok(())
    }
}

/// Where a source publishes: the frames' outlet, stamped and counted, and its reporter.
pub struct SourceOut {
    frames: Outlet<u8, FrameHeader>,
    reporter: Reporter,
    kind: StageKind,
    clock: crate::Clock,
    start: u64,
    published: u64,
    last_id: u64,
}

impl SourceOut {
    /// The first frame id of this instance (after a restart, where the last one stopped).
    pub fn start(&self) -> u64 {
        self.start
    }

    /// Frame ids published so far by this instance (markers too).
    pub fn published(&self) -> u64 {
        self.published
    }

    /// The id that follows the ones published so far.
    pub fn next_id(&self) -> u64 {
        self.start + self.published
    }

    /// The source's clock, UNIX-epoch nanoseconds.
    pub fn now_ns(&self) -> u64 {
        self.clock.now_ns()
    }

    /// The source's clock.
    pub fn clock(&self) -> &crate::Clock {
        &self.clock
    }

    /// The status reporter (a camera's lost and back events).
    pub fn reporter(&mut self) -> &mut Reporter {
        &mut self.reporter
    }

    /// Publishes frame `frame_id` taken at `capture_ns`: its images, `width`×`height` each,
    /// in `images` (left then right).
    pub fn frame(
        &mut self,
        frame_id: u64,
        timestamp_ns: u64,
        capture_ns: u64,
        size: (u32, u32),
        images: &[&[u8]],
    ) -> anyhow::Result<()> {
        let span = info_span!("publish_frame", frame_id);
        let _entered = span.enter();
        let mut header = self.header(frame_id, timestamp_ns, capture_ns);
        (header.width, header.height) = size;
        self.publish(header, images)
    }

    /// Publishes frame `frame_id` without pixels, marked `status` (read corrupt, dropped or
    /// late at the capture), taken at `capture_ns`.
    pub fn marker(
        &mut self,
        frame_id: u64,
        timestamp_ns: u64,
        capture_ns: u64,
        status: FrameStatus,
    ) -> anyhow::Result<()> {
        let mut header = self.header(frame_id, timestamp_ns, capture_ns);
        header.mark(status, self.kind);
        self.publish(header, &[])
    }

    fn header(&self, frame_id: u64, timestamp_ns: u64, capture_ns: u64) -> FrameHeader {
        let mut header = FrameHeader::new(frame_id, timestamp_ns, capture_ns);
        if let Some(stamp) = header.stamp_mut(self.kind) {
            stamp.start_ns = capture_ns;
        }
        header
    }

    fn publish(&mut self, mut header: FrameHeader, images: &[&[u8]]) -> anyhow::Result<()> {
        stamp_end(&mut header, self.kind, self.clock.now_ns());
        self.frames.publish(&header, images)?;
        self.published += 1;
        self.last_id = header.frame_id;
        Ok(())
    }
}

/// A source's rig outlet: published before the first frame, held until the run ends.
pub struct RigOutlet(Outlet<RigRecord, ()>);

impl RigOutlet {
    /// The rig's outlet on `bus`.
    pub fn open(bus: &Bus) -> anyhow::Result<Self> {
        Ok(Self(bus.outlet(topics::RIG, 1)?))
    }

    /// Publishes `rig` (the pose estimator needs it before the first frame's tracks).
    pub fn publish(&mut self, rig: RigRecord) -> anyhow::Result<()> {
        self.0.publish(&(), &[&[rig]])?;
        Ok(())
    }

    /// A stage that (re)started since gets the rig.
    pub fn poll(&mut self) -> anyhow::Result<()> {
        Ok(self.0.update_connections()?)
    }
}

/// Runs `source` until the run ends (a signal or the supervisor's stop): its frames, then,
/// once it has no more, stays (see the module's doc).
pub fn run_source<S: Source>(
    ctx: &StageContext,
    bus: &Bus,
    mut source: S,
    shutdown: &Shutdown,
) -> anyhow::Result<()> {
    let mut out = SourceOut {
        frames: bus.outlet(topics::FRAMES, S::FRAME_BYTES)?,
        reporter: Reporter::new(bus, ctx, 0)?,
        kind: S::KIND,
        clock: ctx.clock.clone(),
        start: ctx.args.start_frame as u64,
        published: 0,
        last_id: 0,
    };
    let mut control: Inlet<Control, ()> = bus.inlet(topics::CONTROL)?;
    let wake = bus.wake(S::KIND)?;
    let stop = |control: &mut Inlet<Control, ()>| -> anyhow::Result<bool> {
        Ok(shutdown.requested() || shutdown_ordered(control, S::KIND, ctx.pid)?)
    };
    let mut pressure = BackPressure::applies(&ctx.config)
        .then(|| BackPressure::open(bus, ctx))
        .transpose()?;
    source.start(&mut out)?;
    out.reporter.report(StatusKind::Ready, out.start, 0);
    let mut reported = 0;
    loop {
        if stop(&mut control)? {
            tracing::info!("shutdown after {} frames", out.published);
            return Ok(());
        }
        let wait = out.reporter.until_due().max(Duration::from_millis(1));
        if let Some(pressure) = &mut pressure
            && pressure.must_wait(out.next_id(), out.published)?
        {
            out.reporter.beat(out.published);
            wake.wait(wait)?;
            continue;
        }
        let step = source.step(&mut out, wait)?;
        if out.published > reported {
            // The supervisor counts the frames published from these.
            out.reporter
                .report(StatusKind::Heartbeat, out.last_id, out.published);
            reported = out.published;
        }
        out.reporter.beat(out.published);
        source.poll()?;
        match step {
            Step::Again => {}
            Step::Idle(idle) => wake.wait(idle.min(wait))?,
            Step::Finished => break,
        }
    }
    out.reporter.report(
        StatusKind::SourceFinished,
        out.next_id().saturating_sub(1),
        out.published,
    );
    tracing::info!("finished: {} frames published", out.published);
    while !stop(&mut control)? {
        source.poll()?;
        out.reporter.beat(out.published);
        wake.wait(out.reporter.until_due().max(Duration::from_millis(1)))?;
    }
    Ok(())
}

/// Frames a source waiting for the pipeline keeps published and not yet out of the pose
/// estimator: well under the frames' queue depth (12), so no stage's queue fills.
pub const IN_FLIGHT: u64 = 4;

/// The source's wait for the pipeline (see the module's doc): the poses (and markers) the
/// pose estimator publishes say which frames are out.
///
/// A source waiting because the pipeline is behind is not hung: the runtime beats while it
/// waits, so the supervisor's hang detection never takes a slow pipeline for a stopped
/// source. Frames in flight can be lost, though (a stage killed or crashed with them), and
/// would then hold the source back for good. Two things let it go on, neither racing the
/// supervisor's hang detection: a stage reporting itself ready (a restart: what the dead
/// instance held is gone), and, as a last resort, no frame through for twice
/// `supervisor.hang_timeout_ms` (longer than the supervisor takes to find a hung stage, so
/// it finds and restarts it first). Either way the frames in flight are written off and the
/// source publishes [`IN_FLIGHT`] more, then waits again: it never floods the queues.
struct BackPressure {
    poses: Inlet<PoseRecord, TracksHeader>,
    status: Inlet<StatusReport, ()>,
    /// The source's own stage, whose reports are not another stage's restart.
    stage: StageKind,
    clock: crate::Clock,
    /// The id after the newest frame out of the pose estimator, or written off.
    done: Option<u64>,
    /// When `done` last moved (or the wait began), on `clock`.
    moved: Duration,
    /// No frame through for this long: the frames in flight are written off.
    patience: Duration,
}

impl BackPressure {
    /// Whether a source under `config` waits for the pipeline: files read as fast as they
    /// can be, every frame processed. A live camera does not wait (its driver would drop).
    fn applies(config: &PipelineConfig) -> bool {
        config.source.pacing == Pacing::Fastest
            && !config.budget.drop_late
            && !config.camera.enabled()
    }

    fn open(bus: &Bus, ctx: &StageContext) -> anyhow::Result<Self> {
        Ok(Self {
            poses: bus.inlet(topics::POSES)?,
            status: bus.inlet(topics::STATUS)?,
            stage: ctx.stage,
            clock: ctx.clock.clone(),
            done: None,
            moved: ctx.clock.monotonic(),
            patience: Self::patience(&ctx.config),
        })
    }

    /// How long a wait lasts without a frame through before the frames in flight are
    /// written off: twice the hang timeout, so that a stage that stopped is killed and
    /// restarted by the supervisor before the source gives up on it.
    fn patience(config: &PipelineConfig) -> Duration {
        Duration::from_millis(config.supervisor.hang_timeout_ms.saturating_mul(2))
    }

    /// Whether the frame `next` must wait: [`IN_FLIGHT`] frames are out and not through.
    /// `published` frames of this instance are out.
    fn must_wait(&mut self, next: u64, published: u64) -> anyhow::Result<bool> {
        let now = self.clock.monotonic();
        for pose in self.poses.receive_all()? {
            let after = pose.header().frame.frame_id + 1;
            if self.done.is_none_or(|done| after > done) {
                self.done = Some(after);
                self.moved = now;
            }
        }
        let restarted = self.status.receive_all()?.iter().any(|m| {
            let report = m.payload()[0];
            report.kind.is(StatusKind::Ready) && !report.stage.is(self.stage)
        });
        if restarted {
            tracing::info!("a stage (re)started: frames up to {next} no longer held back on");
            self.write_off(next, now);
        }
        // Before any frame is through, the first ones published count as in flight.
        let through = self.done.unwrap_or(next - published.min(next));
        if next.saturating_sub(through) < IN_FLIGHT {
            // Not waiting: a wait starts its patience from here.
            self.moved = now;
            return Ok(false);
        }
        if now.saturating_sub(self.moved) >= self.patience {
            tracing::warn!(
                "no frame through the pipeline for {:?}: frames {through}..{next} written off, \
                 {IN_FLIGHT} more published",
                self.patience
            );
            self.write_off(next, now);
            return Ok(false);
        }
        Ok(true)
    }

    /// Counts the frames before `next` as through (lost with a stage, or stuck).
    fn write_off(&mut self, next: u64, now: Duration) {
        self.done = Some(self.done.map_or(next, |done| done.max(next)));
        self.moved = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Clock;
    use linetrack_msgs::FrameHeader;

    fn pressure(bus: &Bus, clock: &Clock, patience: Duration) -> BackPressure {
        BackPressure {
            poses: bus.inlet(topics::POSES).unwrap_or_else(|e| panic!("{e}")),
            status: bus.inlet(topics::STATUS).unwrap_or_else(|e| panic!("{e}")),
            stage: StageKind::FrameSource,
            clock: clock.clone(),
            done: None,
            moved: clock.monotonic(),
            patience,
        }
    }

    fn pose_out(outlet: &mut Outlet<PoseRecord, TracksHeader>, frame_id: u64) {
        let header = TracksHeader {
            frame: FrameHeader::new(frame_id, 0, 0),
            ..Default::default()
        };
        outlet
            .publish(&header, &[&[PoseRecord::default()]])
            .unwrap_or_else(|e| panic!("{e}"));
    }

    fn ready(outlet: &mut Outlet<StatusReport, ()>, stage: StageKind) {
        let report = StatusReport {
            stage: stage.into(),
            pid: 7,
            kind: StatusKind::Ready.into(),
            detail: 0,
            frame_id: 0,
            value: 0,
        };
        outlet
            .publish(&(), &[&[report]])
            .unwrap_or_else(|e| panic!("{e}"));
    }

    fn wait(p: &mut BackPressure, next: u64, published: u64) -> bool {
        p.must_wait(next, published)
            .unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn the_source_waits_with_in_flight_frames_out_and_goes_on_as_poses_come() {
        let bus = Bus::local();
        let mut poses = bus
            .outlet::<PoseRecord, TracksHeader>(topics::POSES, 1)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut p = pressure(&bus, &Clock::manual(0), Duration::from_secs(3600));
        // A source restarted at frame 10: its first IN_FLIGHT frames go out unasked.
        for k in 0..IN_FLIGHT {
            assert!(!wait(&mut p, 10 + k, k), "frame {}", 10 + k);
        }
        assert!(wait(&mut p, 10 + IN_FLIGHT, IN_FLIGHT));
        pose_out(&mut poses, 10);
        assert!(!wait(&mut p, 10 + IN_FLIGHT, IN_FLIGHT));
        assert!(wait(&mut p, 11 + IN_FLIGHT, IN_FLIGHT + 1));
        // Frames lost on the way (a marker-less gap): the newest frame through counts.
        pose_out(&mut poses, 13);
        assert!(!wait(&mut p, 11 + IN_FLIGHT, IN_FLIGHT + 1));
        assert!(!wait(&mut p, 13 + IN_FLIGHT, IN_FLIGHT + 3));
        assert!(wait(&mut p, 14 + IN_FLIGHT, IN_FLIGHT + 4));
    }

    /// The supervisor finds a hung stage after `hang_timeout_ms`: the source writes off
    /// the frames in flight only after twice that, and then lets out one more window, not a
    /// flood.
    #[test]
    fn frames_in_flight_are_written_off_after_twice_the_hang_timeout_a_window_at_a_time() {
        let bus = Bus::local();
        let clock = Clock::manual(0);
        let mut config = PipelineConfig::default();
        config.supervisor.hang_timeout_ms = 2000;
        let patience = BackPressure::patience(&config);
        assert_eq!(patience, Duration::from_secs(4));
        let mut p = pressure(&bus, &clock, patience);
        for k in 0..IN_FLIGHT {
            assert!(!wait(&mut p, k, k));
        }
        // A stage slower than the hang timeout holds the source; the source waits on.
        assert!(wait(&mut p, IN_FLIGHT, IN_FLIGHT));
        clock.advance(Duration::from_millis(config.supervisor.hang_timeout_ms + 1));
        assert!(wait(&mut p, IN_FLIGHT, IN_FLIGHT));
        clock.advance(patience - Duration::from_millis(config.supervisor.hang_timeout_ms + 2));
        assert!(
            wait(&mut p, IN_FLIGHT, IN_FLIGHT),
            "just under the patience"
        );
        clock.advance(Duration::from_millis(1));
        // Nothing through for the whole patience: the four in flight are written off.
        for k in IN_FLIGHT..2 * IN_FLIGHT {
            assert!(!wait(&mut p, k, k), "frame {k}");
        }
        assert!(
            wait(&mut p, 2 * IN_FLIGHT, 2 * IN_FLIGHT),
            "one window, no more"
        );
        clock.advance(patience - Duration::from_millis(1));
        assert!(wait(&mut p, 2 * IN_FLIGHT, 2 * IN_FLIGHT));
    }

    /// A stage that reports ready while the source waits was restarted: what its dead
    /// instance held is lost, so the source goes on at once. Its own ready does not count.
    #[test]
    fn a_restarted_stage_releases_the_wait_at_once() {
        let bus = Bus::local();
        let mut status = bus
            .outlet::<StatusReport, ()>(topics::STATUS, 1)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut p = pressure(&bus, &Clock::manual(0), Duration::from_secs(3600));
        for k in 0..IN_FLIGHT {
            assert!(!wait(&mut p, k, k));
        }
        assert!(wait(&mut p, IN_FLIGHT, IN_FLIGHT));
        ready(&mut status, StageKind::FrameSource);
        assert!(wait(&mut p, IN_FLIGHT, IN_FLIGHT), "its own ready");
        ready(&mut status, StageKind::PoseEstimator);
        for k in IN_FLIGHT..2 * IN_FLIGHT {
            assert!(!wait(&mut p, k, k), "frame {k}");
        }
        assert!(wait(&mut p, 2 * IN_FLIGHT, 2 * IN_FLIGHT));
    }
}
