//! The frame source: reads a stereo sequence (EuRoC or KITTI layout, rectified on load)
//! and publishes each frame's two images into one shared-memory message, paced at the
//! sequence's rate or as fast as it can. A frame that cannot be read is published as a
//! `corrupt` marker (no pixels) so that downstream stages and the records count it.
//! Paced in real time, a frame is stamped with the time it was due, however late the
//! source has it (`Capture`): a source that falls behind shows its delay in the
//! end-to-end latency, and a frame already over the end-to-end budget leaves as a
//! `capture-late` marker. A sequence's frames are decoded ahead on a thread of their own;
//! the schedule starts once that thread has filled its queue, and in real time it reads
//! each next frame half a period after a frame is due, between the frames' processing
//! rather than beside it.
//! With `[camera]` set, it reads a live stereo camera instead ([`camera`]); with
//! `source.replay`, an MCAP recording. Each of the three is a
//! [`linetrack_stage_runtime::Source`]: the stage runtime publishes, stamps, beats, stops
//! and, after the last frame, keeps the source (and its rig) until the run ends.

pub mod camera;
mod gain_jumps;
#[cfg(feature = "mcap")]
mod replay;

use anyhow::Context;
use linetrack_datasets::{Next, StereoSequence, StereoStream};
use linetrack_ipc::{Bus, Shutdown};
use linetrack_msgs::{FrameStatus, RigRecord, StageKind};
use linetrack_pipeline_config::{BudgetConfig, Pacing, SourceConfig};
use linetrack_stage_runtime::{
    RigOutlet as Rig, Source, SourceOut, StageContext, Step, rig_record, run_source,
};
use std::time::Duration;

/// Bytes a frame message holds before more are allocated: a 752×480 stereo pair.
const FRAME_BYTES: usize = 2 * 752 * 480;

/// What a build without the `mcap` feature says when asked to replay.
pub const NO_MCAP: &str =
    "this build cannot replay MCAP recordings: build with --features linetrack-frame-source/mcap";

/// Opens the recording `file` as the source will and checks it (before any stage starts):
/// its number of stereo frames, or an error naming the file and what is wrong with it.
pub fn check_replay(file: &std::path::Path) -> anyhow::Result<usize> {
    #[cfg(feature = "mcap")]
    return Ok(linetrack_mcap::Replay::open(file)?.frames);
    #[cfg(not(feature = "mcap"))]
    anyhow::bail!("{}: {NO_MCAP}", file.display())
}

/// When frame `k` (0-based from the first one published) is due, from the start.
pub(crate) fn due_offset(
    pacing: Pacing,
    rate_hz: f64,
    first_ns: u64,
    timestamp_ns: u64,
    k: usize,
) -> Duration {
    match pacing {
        Pacing::Fastest => Duration::ZERO,
        Pacing::Realtime if rate_hz > 0.0 => Duration::from_secs_f64(k as f64 / rate_hz),
        Pacing::Realtime => Duration::from_nanos(timestamp_ns.saturating_sub(first_ns)),
    }
}

/// How long until `due` (from the start `began`) on `out`'s clock: `None` when it is due.
pub(crate) fn not_yet(out: &SourceOut, began: Duration, due: Duration) -> Option<Duration> {
    let wait = (began + due).saturating_sub(out.clock().monotonic());
    (!wait.is_zero()).then_some(wait)
}

/// A frame's capture stamp under `pacing`, read on `clock` as it is published.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Capture {
    /// UNIX-epoch nanoseconds: when the frame was due (realtime pacing; the sequence's
    /// clock mapped to the run's start), or now (`fastest`: nothing is due).
    pub(crate) capture_ns: u64,
    /// How far behind its time the source publishes it.
    pub(crate) behind: Duration,
}

impl Capture {
    /// The stamp of a frame due at `due` from the start `began` (monotonic, on `clock`). A
    /// source that falls behind its schedule (its reading starved of CPU) stamps the frame
    /// with the time it was due, not the time it has it: as a camera's frame carries the
    /// time it was taken, so the end-to-end latency and the budget policies downstream see
    /// the source's delay.
    pub(crate) fn at(
        clock: &linetrack_stage_runtime::Clock,
        pacing: Pacing,
        began: Duration,
        due: Duration,
    ) -> Self {
        let now_ns = clock.now_ns();
        if pacing == Pacing::Fastest {
            return Self {
                capture_ns: now_ns,
                behind: Duration::ZERO,
            };
        }
        let behind = clock.monotonic().saturating_sub(began + due);
        let behind_ns = u64::try_from(behind.as_nanos()).unwrap_or(u64::MAX);
        Self {
            capture_ns: now_ns.saturating_sub(behind_ns),
            behind,
        }
    }

    /// Whether the frame is already over `budget`'s end-to-end budget as it would leave the
    /// source (with `budget.drop_late`): it is published as a `capture-late` marker, no
    /// pixels, as a camera's frame that waited too long is.
    pub(crate) fn too_late(&self, budget: &BudgetConfig) -> bool {
        budget.drop_late && self.behind.as_secs_f64() * 1e3 > budget.end_to_end_ms
    }
}

/// [`run`] as a process of its own (`linetrack-frame-source`): OpenCV is first set to one
/// thread, so that its work (rectifying the frames read ahead, or a camera's on the capture
/// thread) runs on the thread that asks for it, at that thread's priority
/// (`source.reader_nice` for the frames read ahead). In one process with the other stages
/// (`--single-process`) the setting would reach them too, so [`run`] leaves it alone.
pub fn run_process(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    if let Err(e) = linetrack_datasets::opencv_on_calling_threads() {
        tracing::warn!("{e}");
    }
    run(ctx, bus, shutdown)
}

/// Runs the source: publishes the rig and the frames of the camera, the recording or the
/// sequence the config names, then holds the rig until the run ends (shutdown by signal or
/// command).
pub fn run(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    let rig = Rig::open(bus)?;
    if ctx.config.camera.enabled() {
        return run_source(ctx, bus, camera::CameraSource::new(ctx, rig)?, shutdown);
    }
    if let Some(file) = ctx.config.source.replay() {
        #[cfg(feature = "mcap")]
        return run_source(
            ctx,
            bus,
            replay::ReplaySource::open(ctx, rig, file)?,
            shutdown,
        );
        #[cfg(not(feature = "mcap"))]
        anyhow::bail!("{}: {NO_MCAP}", file.display());
    }
    run_source(ctx, bus, SequenceSource::open(ctx, rig)?, shutdown)
}

/// A sequence's frames, read ahead on a thread of their own.
struct SequenceSource {
    rig: Rig,
    rig_record: RigRecord,
    stream: StereoStream,
    /// Frames to publish, from the frame to start at.
    count: usize,
    source: SourceConfig,
    budget: BudgetConfig,
    first_ns: u64,
    gain_jumps: Option<gain_jumps::GainJumps>,
    /// When the source had its first frame, on its monotonic clock: the schedule starts
    /// there (the time the first frame takes to read is no lateness).
    began: Option<Duration>,
    /// Frames taken from the stream.
    taken: usize,
    /// The frame taken and waiting for its time.
    pending: Option<<StereoStream as Iterator>::Item>,
    /// The time between frames: the paced reader reads the next frame half of it after a
    /// frame is due, while the stages are done with that frame.
    period: Duration,
    /// When the reader may read its next frame (monotonic; `None`: nothing to let).
    read_at: Option<Duration>,
}

impl SequenceSource {
    /// Opens `ctx`'s sequence from the frame to start at.
    fn open(ctx: &StageContext, rig: Rig) -> anyhow::Result<Self> {
        let reader_nice = ctx.config.source.reader_nice;
        Self::open_with(ctx, rig, move || read_in_background(reader_nice))
    }

    /// [`Self::open`] with `on_start` run on the reading thread before its first frame.
    fn open_with(
        ctx: &StageContext,
        rig: Rig,
        on_start: impl FnOnce() + Send + 'static,
    ) -> anyhow::Result<Self> {
        let source = ctx.config.source.clone();
        let sequence = StereoSequence::open(&source.sequence)
            .with_context(|| format!("opening sequence {}", source.sequence.display()))?;
        let total = sequence.frames.len();
        let start = ctx.args.start_frame.min(total);
        let end = if source.max_frames > 0 {
            total.min(source.max_frames)
        } else {
            total
        };
        let first_ns = sequence.frames.get(start).map_or(0, |f| f.timestamp_ns);
        tracing::info!(
            "{}: frames {start}..{end} of {total}, {:?}",
            sequence.name,
            source.pacing
        );
        let rig_record = rig_record(&sequence.rig);
        let origin_ns = sequence.frames.first().map_or(0, |f| f.timestamp_ns);
        let gain_jumps =
            gain_jumps::GainJumps::new(source.gain_jumps_s, source.gain_jumps_seed, origin_ns);
        let rate_hz = if source.rate_hz > 0.0 {
            source.rate_hz
        } else {
            sequence.rate_hz
        };
        let period = Duration::try_from_secs_f64(1.0 / rate_hz).unwrap_or(Duration::ZERO);
        let stream = sequence.into_paced_stream(start, 4, on_start);
        Ok(Self {
            rig,
            rig_record,
            stream,
            count: end.saturating_sub(start),
            source,
            budget: ctx.config.budget.clone(),
            first_ns,
            gain_jumps,
            began: None,
            taken: 0,
            pending: None,
            period,
            read_at: None,
        })
    }
}

impl Source for SequenceSource {
    const KIND: StageKind = StageKind::FrameSource;
    const FRAME_BYTES: usize = FRAME_BYTES;

    fn start(&mut self, _out: &mut SourceOut) -> anyhow::Result<()> {
        self.rig.publish(self.rig_record)?;
        Ok(())
    }

    fn step(&mut self, out: &mut SourceOut, wait: Duration) -> anyhow::Result<Step> {
        // The reader's next frame, once its time has come; no wait goes past that time.
        let now = out.clock().monotonic();
        if self.read_at.is_some_and(|at| now >= at) {
            self.let_read();
        }
        let wait = self
            .read_at
            .map_or(wait, |at| wait.min(at.saturating_sub(now)));
        if self.pending.is_none() {
            if self.taken >= self.count {
                return Ok(Step::Finished);
            }
            // The reading thread runs at a lower priority: on a loaded machine it may be
            // behind for longer than the supervisor's hang timeout. Waiting for it here for
            // at most `wait` lets the runtime report the source alive meanwhile.
            match self.stream.next_within(wait) {
                Next::Frame(item) => self.pending = Some(item),
                Next::NotYet => return Ok(Step::Again),
                Next::End => return Ok(Step::Finished),
            }
            self.taken += 1;
        }
        let Some(item) = &self.pending else {
            return Ok(Step::Finished);
        };
        let (index, timestamp_ns) = match item {
            Ok(frame) => (frame.index, frame.timestamp_ns),
            Err(e) => (e.index, e.timestamp_ns),
        };
        // The schedule starts once the frames read ahead are in: the first frames would
        // otherwise be processed beside the reading's burst of decoding.
        if self.began.is_none() && !self.stream.wait_primed(wait) {
            return Ok(Step::Again);
        }
        let began = *self.began.get_or_insert_with(|| out.clock().monotonic());
        let rate = self.source.rate_hz.max(0.0);
        let due = due_offset(
            self.source.pacing,
            rate,
            self.first_ns,
            timestamp_ns,
            self.taken - 1,
        );
        if let Some(until_due) = not_yet(out, began, due) {
            return Ok(Step::Idle(until_due.min(wait)));
        }
        let capture = Capture::at(out.clock(), self.source.pacing, began, due);
        let capture_ns = capture.capture_ns;
        // The reader reads its next frame once this one is through the stages (paced in
        // real time: half a period after it is due), or at once (`fastest`). A leave still
        // to give for the frame before is given now.
        self.let_read();
        match self.source.pacing {
            Pacing::Realtime => self.read_at = Some(began + due + self.period / 2),
            Pacing::Fastest => self.stream.let_read(),
        }
        let (id, item) = (index as u64, self.pending.take());
        match item {
            Some(Ok(_)) if capture.too_late(&self.budget) => {
                out.marker(id, timestamp_ns, capture_ns, FrameStatus::CaptureLate)?;
            }
            Some(Ok(frame)) => {
                let size = (frame.left.width() as u32, frame.left.height() as u32);
                let (Some(left), Some(right)) = (frame.left.pixels(), frame.right.pixels()) else {
                    anyhow::bail!("frame {index}: images are not continuous in memory");
                };
                let [left, right] = match &mut self.gain_jumps {
                    Some(jumps) => jumps.apply(timestamp_ns, [left, right]),
                    None => [left, right],
                };
                out.frame(id, timestamp_ns, capture_ns, size, &[left, right])?;
            }
            Some(Err(e)) => {
                tracing::warn!("{e}");
                out.marker(id, timestamp_ns, capture_ns, FrameStatus::Corrupt)?;
            }
            None => {}
        }
        Ok(Step::Again)
    }

    fn poll(&mut self) -> anyhow::Result<()> {
        self.rig.poll()
    }
}

impl SequenceSource {
    /// Lets the reader read its next frame, if that is still to be let.
    fn let_read(&mut self) {
        if self.read_at.take().is_some() {
            self.stream.let_read();
        }
    }
}

/// Puts the calling thread (the one reading frames ahead) under the `other` policy at nice
/// `nice`: it then decodes in the time the stages leave. What the system refuses is a
/// warning; the frames are read all the same.
fn read_in_background(nice: i32) {
    let settings = linetrack_sched::SchedSettings {
        policy: Some(linetrack_sched::Policy::Other),
        nice: Some(nice),
        ..Default::default()
    };
    match linetrack_sched::apply("frame-source (reading ahead)", &settings) {
        Ok(refused) => refused.iter().for_each(|r| tracing::warn!("{r}")),
        Err(e) => tracing::warn!("{e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::{StatusKind, StatusReport, topics};
    use linetrack_stage_runtime::Clock;

    #[test]
    fn pacing_follows_timestamps_or_the_rate() {
        assert_eq!(
            due_offset(Pacing::Realtime, 0.0, 1_000, 51_000_000, 3),
            Duration::from_nanos(50_999_000)
        );
        assert_eq!(
            due_offset(Pacing::Realtime, 20.0, 0, 999, 4),
            Duration::from_millis(200)
        );
        assert_eq!(due_offset(Pacing::Fastest, 20.0, 0, 999, 4), Duration::ZERO);
    }

    #[test]
    fn a_late_frame_is_stamped_when_it_was_due_and_dropped_over_the_budget() {
        let clock = Clock::manual(5_000_000_000);
        let began = clock.monotonic();
        let due = Duration::from_millis(50);
        clock.advance(due);
        let on_time = Capture::at(&clock, Pacing::Realtime, began, due);
        assert_eq!(
            on_time,
            Capture {
                capture_ns: 5_050_000_000,
                behind: Duration::ZERO
            }
        );
        // The reader starved for 150 ms: the frame keeps the time it was due.
        clock.advance(Duration::from_millis(150));
        let late = Capture::at(&clock, Pacing::Realtime, began, due);
        assert_eq!(late.capture_ns, 5_050_000_000);
        assert_eq!(late.behind, Duration::from_millis(150));
        let mut budget = BudgetConfig {
            end_to_end_ms: 150.0,
            ..Default::default()
        };
        assert!(!late.too_late(&budget), "at the budget, not over it");
        budget.end_to_end_ms = 149.0;
        assert!(late.too_late(&budget));
        budget.drop_late = false;
        assert!(
            !late.too_late(&budget),
            "drop_late = false keeps every frame"
        );
        // `fastest`: nothing is due, a frame is stamped as it goes.
        let fastest = Capture::at(&clock, Pacing::Fastest, began, Duration::ZERO);
        assert_eq!(
            (fastest.capture_ns, fastest.behind),
            (5_200_000_000, Duration::ZERO)
        );
    }

    /// A sequence source running on a thread on a manual clock (heartbeats every 10 ms)
    /// over the EuRoC excerpt, on a local bus, and the inlets a test watches it through.
    struct Running {
        clock: Clock,
        every: Duration,
        bus: Bus,
        status: linetrack_ipc::Inlet<StatusReport, ()>,
        frames: linetrack_ipc::Inlet<u8, linetrack_msgs::FrameHeader>,
        shutdown: Shutdown,
        runner: std::thread::JoinHandle<anyhow::Result<()>>,
    }

    impl Running {
        /// Starts the source of the config `set` leaves; `on_start` runs on its reading
        /// thread before the first frame.
        fn start(
            set: impl FnOnce(&mut linetrack_pipeline_config::PipelineConfig),
            on_start: impl FnOnce() + Send + 'static,
        ) -> Self {
            let mut config = linetrack_pipeline_config::PipelineConfig::default();
            config.source.sequence =
                linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
            config.supervisor.heartbeat_ms = 10;
            set(&mut config);
            let clock = Clock::manual(1_000_000_000);
            let mut ctx =
                StageContext::in_process(StageKind::FrameSource, config, std::path::PathBuf::new());
            ctx.clock = clock.clone();
            let every = ctx.heartbeat();
            let bus = Bus::local();
            let hub = bus.local_hub().unwrap_or_else(|| panic!("a local bus"));
            let status = bus
                .inlet::<StatusReport, ()>(topics::STATUS)
                .unwrap_or_else(|e| panic!("{e}"));
            let frames = bus
                .inlet::<u8, linetrack_msgs::FrameHeader>(topics::FRAMES)
                .unwrap_or_else(|e| panic!("{e}"));
            let shutdown = Shutdown::default();
            let runner = std::thread::spawn({
                let shutdown = shutdown.clone();
                move || {
                    let bus = hub.bus();
                    let source = SequenceSource::open_with(&ctx, Rig::open(&bus)?, on_start)?;
                    run_source(&ctx, &bus, source, &shutdown)
                }
            });
            Self {
                clock,
                every,
                bus,
                status,
                frames,
                shutdown,
                runner,
            }
        }

        /// A realtime source at 20 Hz over `frames` frames (`budget.drop_late` as given),
        /// and the supervisor's wake-up to wait on between looks.
        fn realtime_20_hz(frames: usize, drop_late: bool) -> (Self, linetrack_ipc::Wake) {
            let source = Self::start(
                |config| {
                    config.source.pacing = Pacing::Realtime;
                    config.source.rate_hz = 20.0;
                    config.source.max_frames = frames;
                    config.budget.drop_late = drop_late;
                },
                || {},
            );
            let wake = source
                .bus
                .wake(StageKind::Supervisor)
                .unwrap_or_else(|e| panic!("{e}"));
            (source, wake)
        }

        /// Status reports until `count` of them hold `wanted` ([`reports`]).
        fn reports(
            &mut self,
            wanted: impl Fn(&StatusReport) -> bool,
            count: usize,
        ) -> Vec<StatusReport> {
            reports(
                &self.bus,
                &mut self.status,
                &self.clock,
                self.every,
                wanted,
                count,
            )
        }

        /// The frames published since the last look.
        fn frames(&mut self) -> Vec<linetrack_msgs::FrameHeader> {
            let got = self.frames.receive_all().unwrap_or_else(|e| panic!("{e}"));
            got.iter().map(|m| *m.header()).collect()
        }

        /// Stops the source and checks it ended without an error.
        fn stop(self) {
            self.shutdown.request();
            self.runner
                .join()
                .unwrap_or_else(|_| panic!("source thread"))
                .unwrap_or_else(|e| panic!("{e}"));
        }
    }

    /// Status reports of `status` until `count` of them hold `wanted`; the clock moves one
    /// heartbeat period per look, so that the source's heartbeats fall due.
    fn reports(
        bus: &Bus,
        status: &mut linetrack_ipc::Inlet<StatusReport, ()>,
        clock: &Clock,
        every: Duration,
        wanted: impl Fn(&StatusReport) -> bool,
        count: usize,
    ) -> Vec<StatusReport> {
        // Long enough for a loaded machine: the test waits for messages, never for time.
        const PATIENCE: Duration = Duration::from_secs(60);
        let wake = bus
            .wake(StageKind::Supervisor)
            .unwrap_or_else(|e| panic!("{e}"));
        let began = std::time::Instant::now();
        let mut got = Vec::new();
        while got.iter().filter(|r| wanted(r)).count() < count {
            assert!(began.elapsed() < PATIENCE, "gave up waiting: {got:?}");
            for m in status.receive_all().unwrap_or_else(|e| panic!("{e}")) {
                got.push(m.payload()[0]);
            }
            clock.advance(every);
            wake.wait(Duration::from_millis(5))
                .unwrap_or_else(|e| panic!("{e}"));
        }
        got
    }

    /// Under load the reading thread (at a lower priority) can fall behind for longer than
    /// the supervisor's hang timeout. The source waits for it in slices and beats meanwhile:
    /// it is behind, not hung. (Waiting on the reader for as long as it took silenced the
    /// source, and a loaded CI machine's supervisor killed it as hung.)
    #[test]
    fn a_source_whose_reader_is_behind_still_beats_and_publishes_once_it_has_the_frame() {
        // The reading thread is held before its first frame until the test lets it go.
        let (release, held) = crossbeam_channel::bounded::<()>(0);
        let mut source = Running::start(
            |config| {
                config.source.pacing = Pacing::Fastest;
                config.source.max_frames = 1;
            },
            move || {
                let _ = held.recv();
            },
        );
        let beat = |r: &StatusReport| r.kind.is(StatusKind::Heartbeat) && r.value == 0;
        let early = source.reports(beat, 3);
        assert!(early.iter().all(|r| r.value == 0), "{early:?}");
        assert!(source.frames().is_empty());
        release.send(()).unwrap_or_else(|e| panic!("{e}"));
        let finished = |r: &StatusReport| r.kind.is(StatusKind::SourceFinished);
        let late = source.reports(finished, 1);
        assert_eq!(late.last().map(|r| (r.frame_id, r.value)), Some((0, 1)));
        let ids: Vec<u64> = source.frames().iter().map(|h| h.frame_id).collect();
        assert_eq!(ids, [0]);
        source.stop();
    }

    /// A realtime source over more frames than it reads ahead publishes all of them, each
    /// on its time: after each frame it lets its paced reader read the next one (without
    /// that leave the reader stops once its queue is full, and so would the frames).
    #[test]
    fn a_realtime_source_paces_its_reader_and_publishes_every_frame_on_its_time() {
        const FRAMES: usize = 12;
        const PATIENCE: Duration = Duration::from_secs(60);
        // However far the test's clock runs ahead of the source, no frame is dropped.
        let (mut source, wake) = Running::realtime_20_hz(FRAMES, false);
        let mut headers = Vec::new();
        let began = std::time::Instant::now();
        while headers.len() < FRAMES {
            assert!(began.elapsed() < PATIENCE, "{} frames", headers.len());
            headers.extend(source.frames());
            // A quarter of a period a look: every frame's and every leave's time comes.
            source.clock.advance(Duration::from_micros(12_500));
            wake.wait(Duration::from_millis(2))
                .unwrap_or_else(|e| panic!("{e}"));
        }
        source.stop();
        let ids: Vec<u64> = headers.iter().map(|h| h.frame_id).collect();
        assert_eq!(ids, (0..FRAMES as u64).collect::<Vec<_>>());
        assert!(
            headers
                .windows(2)
                .all(|w| w[1].capture_ns - w[0].capture_ns == 50_000_000)
        );
        assert!(
            headers
                .iter()
                .all(|h| h.status.get() == Ok(FrameStatus::Ok) && h.width > 0)
        );
    }

    /// Runs a 20 Hz realtime source over 3 frames; once it has published the first, its
    /// clock jumps 10 s (the source starved of CPU); returns the frames' headers.
    fn starved_realtime_frames(drop_late: bool) -> Vec<linetrack_msgs::FrameHeader> {
        const PATIENCE: Duration = Duration::from_secs(60);
        let (mut source, wake) = Running::realtime_20_hz(3, drop_late);
        // The first frame, on a clock that stands still: the next is not due yet.
        let mut headers = Vec::new();
        let waiting = std::time::Instant::now();
        while headers.is_empty() {
            assert!(waiting.elapsed() < PATIENCE, "no first frame");
            headers.extend(source.frames());
            wake.wait(Duration::from_millis(5))
                .unwrap_or_else(|e| panic!("{e}"));
        }
        source.clock.advance(Duration::from_secs(10));
        let finished = |r: &StatusReport| r.kind.is(StatusKind::SourceFinished);
        source.reports(finished, 1);
        headers.extend(source.frames());
        source.stop();
        headers
    }

    /// The source's delay is in the frames' stamps: each frame carries the time it was due
    /// (50 ms apart at 20 Hz, from the first frame), and the source's own stamp spans the
    /// 10 s it was behind. With `drop_late`, frames already over the end-to-end budget
    /// leave as `capture-late`, without pixels.
    #[test]
    fn a_starved_realtime_source_shows_its_delay_in_the_stamps_and_drops_what_is_over_budget() {
        for drop_late in [false, true] {
            let headers = starved_realtime_frames(drop_late);
            assert_eq!(
                headers.iter().map(|h| h.frame_id).collect::<Vec<_>>(),
                [0, 1, 2]
            );
            let gaps: Vec<u64> = headers
                .windows(2)
                .map(|w| w[1].capture_ns - w[0].capture_ns)
                .collect();
            assert_eq!(gaps, [50_000_000, 50_000_000], "drop_late {drop_late}");
            let behind = |h: &linetrack_msgs::FrameHeader| {
                let own = h
                    .stamp(StageKind::FrameSource)
                    .unwrap_or_else(|| panic!("no source stamp"));
                assert_eq!(own.start_ns, h.capture_ns);
                own.end_ns - own.start_ns
            };
            // The first frame starts the schedule: on time, whatever reading it took.
            assert_eq!(behind(&headers[0]), 0);
            assert_eq!(headers[0].status.get(), Ok(FrameStatus::Ok));
            assert!(headers[0].width > 0);
            for h in &headers[1..] {
                assert!(
                    behind(h) >= 9_900_000_000,
                    "frame {}: behind {} ns",
                    h.frame_id,
                    behind(h)
                );
                let want = if drop_late {
                    FrameStatus::CaptureLate
                } else {
                    FrameStatus::Ok
                };
                assert_eq!(h.status.get(), Ok(want), "frame {}", h.frame_id);
                assert_eq!(h.width > 0, !drop_late, "pixels only when kept");
            }
        }
    }
}
