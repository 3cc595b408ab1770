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
    Control, FrameHeader, FrameStatus, PoseRecord, StageKind, StatusKind, Topic, TracksHeader,
};
use linetrack_pipeline_config::{Pacing, PipelineConfig};
use std::time::{Duration, Instant};
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

/// Runs `source` until the run ends (a signal or the supervisor's stop): its frames, then,
/// once it has no more, stays (see the module's doc).
pub fn run_source<S: Source>(
    ctx: &StageContext,
    bus: &Bus,
    mut source: S,
    shutdown: &Shutdown,
) -> anyhow::Result<()> {
    let mut out = SourceOut {
        frames: bus.outlet(Topic::Frames, S::FRAME_BYTES)?,
        reporter: Reporter::new(bus, ctx, 0)?,
        kind: S::KIND,
        clock: ctx.clock.clone(),
        start: ctx.args.start_frame as u64,
        published: 0,
        last_id: 0,
    };
    let mut control: Inlet<Control, ()> = bus.inlet(Topic::Control)?;
    let wake = bus.wake(S::KIND)?;
    let stop = |control: &mut Inlet<Control, ()>| -> anyhow::Result<bool> {
        Ok(shutdown.requested() || shutdown_ordered(control, S::KIND, ctx.pid)?)
    };
    let mut pressure = BackPressure::applies(&ctx.config)
        .then(|| BackPressure::open(bus, &ctx.config))
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
struct BackPressure {
    poses: Inlet<PoseRecord, TracksHeader>,
    /// The id after the newest frame out of the pose estimator.
    done: Option<u64>,
    /// When `done` last moved (or the wait began).
    moved: Instant,
    /// A pipeline that moves on no frame for this long (a stage stopped, a frame lost with
    /// a stage that died) no longer holds the source back.
    patience: Duration,
    gave_up: bool,
}

impl BackPressure {
    /// Whether a source under `config` waits for the pipeline: files read as fast as they
    /// can be, every frame processed. A live camera does not wait (its driver would drop).
    fn applies(config: &PipelineConfig) -> bool {
        config.source.pacing == Pacing::Fastest
            && !config.budget.drop_late
            && !config.camera.enabled()
    }

    fn open(bus: &Bus, config: &PipelineConfig) -> anyhow::Result<Self> {
        Ok(Self {
            poses: bus.inlet(Topic::Poses)?,
            done: None,
            moved: Instant::now(),
            patience: Duration::from_millis(config.supervisor.hang_timeout_ms),
            gave_up: false,
        })
    }

    /// Whether the frame `next` must wait: [`IN_FLIGHT`] frames are out and not through.
    /// `published` frames of this instance are out.
    fn must_wait(&mut self, next: u64, published: u64) -> anyhow::Result<bool> {
        for pose in self.poses.receive_all()? {
            let after = pose.header().frame.frame_id + 1;
            if self.done.is_none_or(|done| after > done) {
                self.done = Some(after);
                self.moved = Instant::now();
                self.gave_up = false;
            }
        }
        // Before any frame is through, the first ones published count as in flight.
        let through = self.done.unwrap_or(next - published.min(next));
        if next.saturating_sub(through) < IN_FLIGHT || self.gave_up {
            // Not waiting: a wait starts its patience from here.
            self.moved = Instant::now();
            return Ok(false);
        }
        if self.moved.elapsed() >= self.patience {
            tracing::warn!(
                "no frame through the pipeline for {:?}: publishing without waiting until one is",
                self.patience
            );
            self.gave_up = true;
            return Ok(false);
        }
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::FrameHeader;

    fn pressure(bus: &Bus, patience: Duration) -> BackPressure {
        BackPressure {
            poses: bus.inlet(Topic::Poses).unwrap_or_else(|e| panic!("{e}")),
            done: None,
            moved: Instant::now(),
            patience,
            gave_up: false,
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

    #[test]
    fn the_source_waits_with_in_flight_frames_out_and_goes_on_as_poses_come() {
        let bus = Bus::local();
        let mut poses = bus
            .outlet::<PoseRecord, TracksHeader>(Topic::Poses, 1)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut p = pressure(&bus, Duration::from_secs(3600));
        let wait = |p: &mut BackPressure, next, published| {
            p.must_wait(next, published)
                .unwrap_or_else(|e| panic!("{e}"))
        };
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

    #[test]
    fn a_pipeline_that_lets_nothing_through_stops_holding_the_source_back() {
        let bus = Bus::local();
        let mut poses = bus
            .outlet::<PoseRecord, TracksHeader>(Topic::Poses, 1)
            .unwrap_or_else(|e| panic!("{e}"));
        // No patience: the first wait gives up at once (no clock read is asserted).
        let mut p = pressure(&bus, Duration::ZERO);
        assert!(!p.must_wait(IN_FLIGHT, IN_FLIGHT).unwrap_or_default());
        assert!(
            !p.must_wait(IN_FLIGHT + 5, IN_FLIGHT + 5)
                .unwrap_or_default()
        );
        // A frame through: the source waits again (and gives up again with no patience).
        pose_out(&mut poses, 0);
        p.patience = Duration::from_secs(3600);
        assert!(
            p.must_wait(IN_FLIGHT + 5, IN_FLIGHT + 5)
                .unwrap_or_default()
        );
    }
}
