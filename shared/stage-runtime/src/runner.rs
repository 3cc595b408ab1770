//! The one loop every processing stage runs: the runtime receives, holds, joins by frame
//! id, applies the drop policy, counts overflows and gaps, answers commands, takes part in
//! hot swaps, and sends heartbeats; a stage only says what it does with one frame
//! ([`Stage::process`]). The same loop runs over shared memory between processes and over
//! channels between threads: it sees only a [`Bus`].
//!
//! Hot swap, for any stage: a second instance starts as a standby (`--standby`), holds the
//! newest inputs and reports ready; the supervisor asks the running one to hand over. The
//! running one picks the hand-over frame F (the first it has not published, and no earlier
//! than the oldest frame the standby holds), publishes everything below F, reports
//! `HandedOver(F)` and exits; the standby, told F, publishes from F on. Frames below F come
//! only from the old instance and frames from F on only from the new one.

use crate::{
    FramePolicy, GapWatch, Held, Images, Reporter, StageContext, WorkTimes, process_frame,
};
use linetrack_ipc::{Bus, Inlet, Outlet, Received, Record, Shutdown, Wake};
use linetrack_msgs::{
    Command, Control, FrameHeader, FrameMessage, StageKind, StatusKind, Topic, TopicOf, topics,
};
use std::time::Duration;
use tracing::info_span;

/// How many frames from the next one to process [`Stage::prepare`] may run ahead.
const PREPARED_AHEAD: u64 = 1;

/// One processing stage's per-frame work.
pub trait Stage {
    /// The records of the input it processes, one message per frame.
    type Input: Record;
    /// The user header of the input: the frame and the results upstream.
    type InputHeader: Record + FrameMessage;
    /// The records it publishes, one message per frame.
    type Output: Record;
    /// The user header it publishes: the input's, carried on, with this stage's results.
    type OutputHeader: Record + FrameMessage + From<Self::InputHeader>;
    /// Which stage it is.
    const KIND: StageKind;
    /// Where its input comes from (a topic of its input's types: another does not compile).
    const INPUT: TopicOf<Self::Input, Self::InputHeader>;
    /// Where its output goes (a topic of its output's types).
    const OUTPUT: TopicOf<Self::Output, Self::OutputHeader>;
    /// Records an output message holds before more are allocated.
    const OUTPUT_LEN: usize;

    /// Whether each input is joined with the frame's images (held, in place, since they
    /// arrived on [`Topic::Frames`]).
    fn joins_images(&self) -> bool;

    /// What travels in every status report of this stage (the detector kind).
    fn detail(&self) -> u32 {
        0
    }

    /// Processes one frame: `input` is the frame's message on [`Stage::INPUT`], `images`
    /// the frame's images when the stage joins them (`None` when they never arrived).
    /// Fills its own results in `header` (made from the input's) and its records in `out`
    /// (given empty, and kept from frame to frame: no list is allocated per frame); an
    /// error marks the frame failed by this stage.
    fn process(
        &mut self,
        header: &mut Self::OutputHeader,
        input: &Received<Self::Input, Self::InputHeader>,
        images: Option<&Images>,
        out: &mut Vec<Self::Output>,
    ) -> anyhow::Result<()>;

    /// Work on a frame's images that need not wait for its input (the pose estimator's
    /// corners): called once per frame whose images arrived before its input, when no
    /// input is waiting, so that it runs while the stages upstream work on the same frame
    /// (for the next frame to process only).
    /// [`Stage::process`] must still work for a frame that was not prepared. An error is
    /// logged and the frame goes on to `process`.
    fn prepare(&mut self, _header: &FrameHeader, _images: &Images) -> anyhow::Result<()> {
        Ok(())
    }

    /// Whether [`Stage::prepare`] does anything (the runtime calls it only then).
    fn prepares(&self) -> bool {
        false
    }

    /// Whether a frame's processing leaves what the next frame needs (the matcher matches
    /// each frame with the one before): a standby taking over at frame F then processes
    /// the held frame before F first, without publishing it.
    fn keeps_state(&self) -> bool {
        false
    }

    /// What is published for a frame that was dropped or failed, into `out` (given
    /// empty; nothing by default).
    fn placeholder(&self, _out: &mut Vec<Self::Output>) {}

    /// A command for this stage that the runtime does not handle itself (shutdown and the
    /// hot swap are the runtime's).
    fn command(&mut self, _command: Command, _control: &Control) {}

    /// Called once per turn of the loop, before the frames: a stage reads its own side
    /// inputs here (the pose estimator's rig).
    fn poll(&mut self) -> anyhow::Result<()> {
        Ok(())
    }
}

/// Where a stage instance is in a hot swap.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    /// Waiting to take over; holds inputs.
    Standby,
    /// Processing and publishing.
    Active,
    /// Publishing frames below `at`, then handing over.
    HandingOver { at: u64 },
}

/// A stage's connections, opened by the runtime.
struct Ports<S: Stage> {
    input: Inlet<S::Input, S::InputHeader>,
    output: Outlet<S::Output, S::OutputHeader>,
    frames: Option<Inlet<u8, FrameHeader>>,
    control: Inlet<Control, ()>,
    wake: Wake,
    reporter: Reporter,
}

/// The loop's state besides the ports.
struct Runner<'a, S: Stage> {
    ctx: &'a StageContext,
    stage: S,
    role: Role,
    /// Inputs held by a standby.
    waiting: Held<S::Input, S::InputHeader>,
    /// Images held until the input of the same frame arrives.
    images: Held<u8, FrameHeader>,
    gaps: GapWatch,
    next_unpublished: u64,
    /// Frames below this were prepared (or processed) already.
    next_unprepared: u64,
    processed: u64,
    /// The stage's recent time a frame, prepared frames apart, for the drop rule.
    work: WorkTimes,
    /// The records of the frame being published, kept from frame to frame.
    records: Vec<S::Output>,
}

/// How a turn of the loop ended.
enum Turn {
    Continue,
    Finished,
}

/// Runs `stage` until shutdown (a signal, a shutdown command, or, after a hand-over, once
/// its part is published).
pub fn run_stage<S: Stage>(
    ctx: &StageContext,
    bus: &Bus,
    stage: S,
    shutdown: &Shutdown,
) -> anyhow::Result<()> {
    let mut ports = Ports::<S> {
        input: bus.inlet(S::INPUT)?,
        output: bus.outlet(S::OUTPUT, S::OUTPUT_LEN)?,
        frames: if stage.joins_images() {
            Some(bus.inlet(topics::FRAMES)?)
        } else {
            None
        },
        control: bus.inlet(topics::CONTROL)?,
        wake: bus.wake(S::KIND)?,
        reporter: Reporter::new(bus, ctx, stage.detail())?,
    };
    let role = if ctx.args.standby {
        Role::Standby
    } else {
        Role::Active
    };
    let mut runner = Runner::new(ctx, stage, role);
    let mut ready_sent = false;
    if role == Role::Active {
        ports.reporter.report(StatusKind::Ready, 0, 0);
        ready_sent = true;
    }
    tracing::info!("{} {role:?}", S::KIND);
    while !shutdown.requested() {
        if let Turn::Finished = runner.commands(&mut ports)? {
            return Ok(());
        }
        runner.stage.poll()?;
        if let Some(frames) = &mut ports.frames {
            let overflow = runner.images.receive(frames)?;
            ports.reporter.overflow(overflow);
        }
        let mut more = false;
        match runner.role {
            Role::Standby => {
                let overflow = runner.waiting.receive(&mut ports.input)?;
                ports.reporter.overflow(overflow);
                if !ready_sent && let Some(first) = runner.waiting.first_id() {
                    ports.reporter.report(StatusKind::Ready, first, 0);
                    ready_sent = true;
                }
            }
            Role::Active | Role::HandingOver { .. } => {
                more = runner.process_waiting(&mut ports)?;
                if !more && runner.stage.prepares() {
                    runner.prepare_held();
                }
            }
        }
        if let Role::HandingOver { at } = runner.role
            && runner.next_unpublished >= at
        {
            ports
                .reporter
                .report(StatusKind::HandedOver, at, runner.processed);
            tracing::info!(
                "handed over at frame {at} after {} frames",
                runner.processed
            );
            return Ok(());
        }
        ports.reporter.beat(runner.processed);
        if more {
            // A full batch: more may be queued, whose wake-up was already spent.
            continue;
        }
        ports
            .wake
            .wait(ports.reporter.until_due().max(Duration::from_millis(1)))?;
    }
    Ok(())
}

impl<'a, S: Stage> Runner<'a, S> {
    /// A runner in `role` that has seen no frame yet.
    fn new(ctx: &'a StageContext, stage: S, role: Role) -> Self {
        Runner {
            ctx,
            stage,
            role,
            waiting: Held::new(S::INPUT.topic()),
            images: Held::new(Topic::Frames),
            gaps: GapWatch::default(),
            next_unpublished: 0,
            next_unprepared: 0,
            processed: 0,
            work: WorkTimes::default(),
            records: Vec::with_capacity(S::OUTPUT_LEN),
        }
    }

    /// Answers the commands for this process.
    fn commands(&mut self, ports: &mut Ports<S>) -> anyhow::Result<Turn> {
        for message in ports.control.receive_all()? {
            let Some(&c) = message.payload().first() else {
                continue;
            };
            if !c.is_for(S::KIND, self.ctx.pid) {
                continue;
            }
            match c.command.get() {
                Ok(Command::Shutdown) => return Ok(Turn::Finished),
                Ok(Command::HandOver) if self.role == Role::Active => {
                    let at = self.next_unpublished.max(c.frame_id);
                    tracing::info!("handing over at frame {at}");
                    self.role = Role::HandingOver { at };
                }
                Ok(Command::TakeOver) if self.role == Role::Standby => {
                    self.take_over(c.frame_id, ports)?
                }
                Ok(command) => self.stage.command(command, &c),
                Err(unknown) => tracing::warn!("{unknown}: ignored"),
            }
        }
        Ok(Turn::Continue)
    }

    /// A standby takes over at frame `from`: the held inputs below it were published by the
    /// old instance; the rest are processed now.
    fn take_over(&mut self, from: u64, ports: &mut Ports<S>) -> anyhow::Result<()> {
        tracing::info!("taking over at frame {from}");
        // What arrived since the last turn is held too.
        let overflow = self.waiting.receive(&mut ports.input)?;
        ports.reporter.overflow(overflow);
        if let Some(first) = self.waiting.first_id()
            && first > from
        {
            tracing::warn!("frames {from}..{first} were released before the take-over");
        }
        let (before, inputs): (Vec<_>, Vec<_>) = std::iter::from_fn(|| self.waiting.take_next())
            .partition(|m| m.header().frame().frame_id < from);
        if self.stage.keeps_state()
            && let Some(last) = before.last()
        {
            self.warm_up(last, ports);
        }
        self.role = Role::Active;
        // Held inputs were queued by the swap, not by slowness: none is dropped as behind
        // (the age limit still applies).
        for input in &inputs {
            self.one_frame(input, false, ports)?;
        }
        Ok(())
    }

    /// Processes `input` (a frame the old instance published) for the state it leaves; the
    /// result is not published.
    fn warm_up(&mut self, input: &Received<S::Input, S::InputHeader>, ports: &Ports<S>) {
        let mut header = S::OutputHeader::from(*input.header());
        let frame_id = header.frame().frame_id;
        if !header.frame().is_ok() {
            // Dropped or failed upstream: the old instance did not process it either.
            return;
        }
        let images = if ports.frames.is_some() {
            self.images.take(frame_id)
        } else {
            None
        };
        self.records.clear();
        match self
            .stage
            .process(&mut header, input, images.as_ref(), &mut self.records)
        {
            Ok(()) => tracing::info!("warmed up on frame {frame_id}"),
            Err(e) => tracing::warn!("warming up on frame {frame_id}: {e:#}"),
        }
        self.records.clear();
    }

    /// Processes the waiting inputs (at most the subscriber's borrow limit at once),
    /// stopping at the hand-over frame; returns whether the batch was full (more may wait).
    fn process_waiting(&mut self, ports: &mut Ports<S>) -> anyhow::Result<bool> {
        let batch = ports.input.receive_all()?;
        let full = batch.len() >= ports.input.limit();
        let count = batch.len();
        for (k, input) in batch.iter().enumerate() {
            let id = input.header().frame().frame_id;
            ports.reporter.gap(self.gaps.observe(id));
            if let Role::HandingOver { at } = self.role
                && id >= at
            {
                // Every frame below F has been seen: the rest is the new instance's.
                self.next_unpublished = self.next_unpublished.max(at);
                break;
            }
            self.one_frame(input, k + 1 < count, ports)?;
            // A long batch on a loaded machine must not look like a hang.
            ports.reporter.beat(self.processed);
        }
        Ok(full)
    }

    /// Prepares the held images of the next frame to process, if not done yet. Frames
    /// further ahead are left alone: when the stages upstream lag they drop frames, and
    /// preparing those would take the processor from them (and a frame whose input arrives
    /// while a later one is being prepared would wait for it).
    fn prepare_held(&mut self) {
        let from = self.next_unprepared.max(self.next_unpublished);
        let until = self.next_unpublished.saturating_add(PREPARED_AHEAD);
        for images in self.images.iter() {
            let header = images.header();
            if header.frame_id < from || header.frame_id >= until {
                continue;
            }
            let span = info_span!(
                linetrack_telemetry::PREPARE_SPAN,
                frame_id = header.frame_id,
                stage = S::KIND.name()
            );
            let _entered = span.enter();
            if let Err(e) = self.stage.prepare(header, images) {
                tracing::warn!("frame {}: preparing: {e:#}", header.frame_id);
            }
            self.next_unprepared = header.frame_id + 1;
        }
    }

    /// Takes one frame through the stage and publishes the result.
    fn one_frame(
        &mut self,
        input: &Received<S::Input, S::InputHeader>,
        newer_waiting: bool,
        ports: &mut Ports<S>,
    ) -> anyhow::Result<()> {
        let header = S::OutputHeader::from(*input.header());
        let frame_id = header.frame().frame_id;
        let span = info_span!("frame", frame_id, stage = S::KIND.name());
        let _entered = span.enter();
        let images = if ports.frames.is_some() {
            self.images.take(frame_id)
        } else {
            None
        };
        // Its images were prepared while the stage waited (or their preparation was tried).
        let prepared = self.stage.prepares() && frame_id < self.next_unprepared;
        let stage = &mut self.stage;
        let policy = FramePolicy {
            stage: S::KIND,
            budget: &self.ctx.config.budget,
            clock: &self.ctx.clock,
            work: self.work.expected(prepared),
        };
        let took = process_frame(
            policy,
            header,
            newer_waiting,
            &mut ports.output,
            &mut self.records,
            stage,
            |stage, h, out| stage.process(h, input, images.as_ref(), out),
            |stage, out| stage.placeholder(out),
        )?;
        if let Some(ms) = took {
            self.work.observe(prepared, ms);
        }
        self.next_unpublished = frame_id + 1;
        self.processed += 1;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::{FrameStatus, SegmentRecord, SegmentsHeader, StatusReport, TracksHeader};
    use linetrack_pipeline_config::PipelineConfig;
    use std::path::PathBuf;
    use std::time::Instant;

    /// A stage that answers each frame with one record: which instance took it, the frame,
    /// and fails a blank frame.
    struct Tag {
        instance: f32,
        /// Keeps the last frame it processed (as the matcher keeps the previous frame).
        remembers: bool,
        last: Option<u64>,
        /// With a manual clock: each frame's work takes this much of it.
        work: Option<(crate::Clock, Duration)>,
    }

    impl Stage for Tag {
        type Input = u8;
        type InputHeader = FrameHeader;
        type Output = SegmentRecord;
        type OutputHeader = SegmentsHeader;
        const KIND: StageKind = StageKind::LineDetector;
        const INPUT: TopicOf<Self::Input, Self::InputHeader> = topics::FRAMES;
        const OUTPUT: TopicOf<Self::Output, Self::OutputHeader> = topics::SEGMENTS;
        const OUTPUT_LEN: usize = 1;

        fn joins_images(&self) -> bool {
            false
        }

        fn process(
            &mut self,
            header: &mut SegmentsHeader,
            input: &Images,
            _images: Option<&Images>,
            out: &mut Vec<SegmentRecord>,
        ) -> anyhow::Result<()> {
            anyhow::ensure!(input.payload().first() != Some(&0), "a blank frame");
            if let Some((clock, took)) = &self.work {
                clock.advance(*took);
            }
            let last = self.last.replace(header.frame.frame_id);
            out.push(SegmentRecord {
                endpoints: [
                    self.instance,
                    header.frame.frame_id as f32,
                    last.map_or(-1.0, |l| l as f32),
                    0.0,
                ],
            });
            Ok(())
        }

        fn keeps_state(&self) -> bool {
            self.remembers
        }
    }

    fn context(pid: u32, standby: bool) -> StageContext {
        let mut config = PipelineConfig::default();
        config.budget.drop_late = false;
        let mut ctx = StageContext::in_process(StageKind::LineDetector, config, PathBuf::new());
        ctx.pid = pid;
        ctx.args.standby = standby;
        ctx.clock = crate::Clock::manual(1);
        ctx
    }

    /// Receives until `n` messages arrived (panics after a generous minute: a hung runtime).
    fn collect<P: Record, H: Record>(inlet: &mut Inlet<P, H>, n: usize) -> Vec<Received<P, H>> {
        let deadline = Instant::now() + Duration::from_secs(60);
        let mut got = Vec::new();
        while got.len() < n {
            got.extend(inlet.receive_all().unwrap_or_else(|e| panic!("{e}")));
            assert!(Instant::now() < deadline, "{} of {n} messages", got.len());
            std::thread::sleep(Duration::from_millis(2));
        }
        got
    }

    #[test]
    fn a_hand_over_between_two_instances_publishes_every_frame_once() {
        hand_over(false);
    }

    #[test]
    fn a_standby_that_keeps_state_takes_over_with_the_frame_before_processed() {
        hand_over(true);
    }

    /// Two instances of a stage (that `remembers` its last frame or not) hand over.
    fn hand_over(remembers: bool) {
        let hub = linetrack_ipc::LocalHub::default();
        let bus = hub.bus();
        let mut frames = bus
            .outlet::<u8, FrameHeader>(topics::FRAMES, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut control = bus
            .outlet::<Control, ()>(topics::CONTROL, 1)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut out = bus
            .inlet::<SegmentRecord, SegmentsHeader>(topics::SEGMENTS)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut status = bus
            .inlet::<StatusReport, ()>(topics::STATUS)
            .unwrap_or_else(|e| panic!("{e}"));
        let start = |pid: u32, standby: bool, instance: f32| {
            let hub = hub.clone();
            std::thread::spawn(move || {
                let stage = Tag {
                    instance,
                    remembers,
                    last: None,
                    work: None,
                };
                run_stage(
                    &context(pid, standby),
                    &hub.bus(),
                    stage,
                    &Shutdown::default(),
                )
            })
        };
        let mut publish = |ids: std::ops::Range<u64>| {
            for id in ids {
                // Frame 3 is blank: the stage fails it, and it is still published.
                let pixel = u8::from(id != 3);
                frames
                    .publish(&FrameHeader::new(id, 0, 1), &[&[pixel]])
                    .unwrap_or_else(|e| panic!("{e}"));
            }
        };
        // The frame id of `pid`'s ready report, if it sent one.
        let ready = |status: &mut Inlet<StatusReport, ()>, pid: u32| {
            status
                .receive_all()
                .unwrap_or_else(|e| panic!("{e}"))
                .iter()
                .map(|r| r.payload()[0])
                .find(|r| r.pid == pid && r.kind.is(StatusKind::Ready))
                .map(|r| r.frame_id)
        };
        let mut send = |pid: u32, command: Command, frame_id: u64| {
            let c = Control::new(command, StageKind::LineDetector, pid, 0, frame_id);
            control
                .publish(&(), &[&[c]])
                .unwrap_or_else(|e| panic!("{e}"));
        };
        let old = start(100, false, 1.0);
        let deadline = Instant::now() + Duration::from_secs(60);
        while ready(&mut status, 100).is_none() {
            assert!(Instant::now() < deadline, "never ready");
            std::thread::sleep(Duration::from_millis(2));
        }
        publish(0..5);
        let mut results = collect(&mut out, 5);
        // The standby reports ready once it holds a frame: frames go on until it does.
        let new = start(200, true, 2.0);
        let mut next = 5;
        let first_held = loop {
            publish(next..next + 1);
            next += 1;
            results.extend(collect(&mut out, 1));
            if let Some(first) = ready(&mut status, 200) {
                break first;
            }
            assert!(Instant::now() < deadline, "the standby never got ready");
        };
        assert!(first_held < next);
        // The old instance has published every frame below `next`: it hands over there.
        send(100, Command::HandOver, first_held);
        let handed = old.join().map_err(|_| "panicked");
        assert!(matches!(handed, Ok(Ok(()))), "{handed:?}");
        send(200, Command::TakeOver, next);
        publish(next..next + 4);
        results.extend(collect(&mut out, 4));
        send(0, Command::Shutdown, 0);
        let ended = new.join().map_err(|_| "panicked");
        assert!(matches!(ended, Ok(Ok(()))), "{ended:?}");

        let seen: Vec<(u64, f32, usize)> = results
            .iter()
            .map(|m| {
                let instance = m.payload().first().map_or(0.0, |r| r.endpoints[0]);
                (m.header().frame.frame_id, instance, m.payload().len())
            })
            .collect();
        let expected: Vec<(u64, f32, usize)> = (0..next + 4)
            .map(|id| match id {
                3 => (3, 0.0, 0),
                _ if id < next => (id, 1.0, 1),
                _ => (id, 2.0, 1),
            })
            .collect();
        assert_eq!(seen, expected, "(frame, instance, records)");
        // The new instance's first frame: the one before it was processed (not published)
        // by the new instance when it keeps state, else it starts afresh.
        let before_first = results[next as usize].payload()[0].endpoints[2];
        let expected_before = if remembers { (next - 1) as f32 } else { -1.0 };
        assert_eq!(before_first, expected_before);
        assert_eq!(
            results[3].header().frame.status.get(),
            Ok(linetrack_msgs::FrameStatus::StageError)
        );
        assert!(
            out.receive_all()
                .unwrap_or_else(|e| panic!("{e}"))
                .is_empty()
        );
    }

    /// A stage joining images that prepares them ahead: it notes which frames it prepared
    /// and answers each frame with whether it had been prepared. With a manual `clock`, a
    /// frame's work takes 2 ms of it when the frame was prepared, 40 ms when not (the pose
    /// estimator's two kinds of frame).
    struct Ahead {
        prepared: std::sync::Arc<std::sync::Mutex<Vec<u64>>>,
        clock: Option<crate::Clock>,
    }

    impl Stage for Ahead {
        type Input = SegmentRecord;
        type InputHeader = SegmentsHeader;
        type Output = linetrack_msgs::TrackedLine;
        type OutputHeader = TracksHeader;
        const KIND: StageKind = StageKind::Matcher;
        const INPUT: TopicOf<Self::Input, Self::InputHeader> = topics::SEGMENTS;
        const OUTPUT: TopicOf<Self::Output, Self::OutputHeader> = topics::TRACKS;
        const OUTPUT_LEN: usize = 1;

        fn joins_images(&self) -> bool {
            true
        }

        fn prepares(&self) -> bool {
            true
        }

        fn prepare(&mut self, header: &FrameHeader, images: &Images) -> anyhow::Result<()> {
            anyhow::ensure!(images.payload().first() != Some(&0), "a blank image");
            self.prepared
                .lock()
                .map_err(|_| anyhow::anyhow!("poisoned"))?
                .push(header.frame_id);
            Ok(())
        }

        fn process(
            &mut self,
            header: &mut TracksHeader,
            _input: &Received<SegmentRecord, SegmentsHeader>,
            images: Option<&Images>,
            out: &mut Vec<linetrack_msgs::TrackedLine>,
        ) -> anyhow::Result<()> {
            let prepared = self
                .prepared
                .lock()
                .map_err(|_| anyhow::anyhow!("poisoned"))?
                .contains(&header.frame.frame_id);
            if let Some(clock) = &self.clock {
                clock.advance(Duration::from_millis(if prepared { 2 } else { 40 }));
            }
            out.push(linetrack_msgs::TrackedLine {
                has_stereo: u32::from(prepared),
                previous: i32::from(images.is_some()),
                ..Default::default()
            });
            Ok(())
        }
    }

    #[test]
    fn images_that_arrive_before_their_input_are_prepared_once_while_the_stage_waits() {
        let hub = linetrack_ipc::LocalHub::default();
        let bus = hub.bus();
        let mut frames = bus
            .outlet::<u8, FrameHeader>(topics::FRAMES, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut segments = bus
            .outlet::<SegmentRecord, SegmentsHeader>(topics::SEGMENTS, 1)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut control = bus
            .outlet::<Control, ()>(topics::CONTROL, 1)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut out = bus
            .inlet::<linetrack_msgs::TrackedLine, TracksHeader>(topics::TRACKS)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut status = bus
            .inlet::<StatusReport, ()>(topics::STATUS)
            .unwrap_or_else(|e| panic!("{e}"));
        let prepared = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let stage = Ahead {
            prepared: prepared.clone(),
            clock: None,
        };
        let runner = {
            let hub = hub.clone();
            std::thread::spawn(move || {
                let mut ctx = context(7, false);
                ctx.stage = StageKind::Matcher;
                run_stage(&ctx, &hub.bus(), stage, &Shutdown::default())
            })
        };
        let prepared_ids = || prepared.lock().map(|p| p.clone()).unwrap_or_default();
        let deadline = Instant::now() + Duration::from_secs(60);
        let mut ready = false;
        while !ready {
            assert!(Instant::now() < deadline, "never ready");
            ready = status
                .receive_all()
                .unwrap_or_else(|e| panic!("{e}"))
                .iter()
                .any(|r| r.payload()[0].kind.is(StatusKind::Ready));
            std::thread::sleep(Duration::from_millis(2));
        }
        // Frames 0–3's images, frame 1's blank (its preparation fails): the stage prepares
        // the next frame to process while no segments are waiting, not the ones after.
        for id in 0..4u64 {
            let pixel = u8::from(id != 1);
            frames
                .publish(&FrameHeader::new(id, 0, 1), &[&[pixel]])
                .unwrap_or_else(|e| panic!("{e}"));
        }
        while prepared_ids().is_empty() {
            assert!(Instant::now() < deadline, "prepared {:?}", prepared_ids());
            std::thread::sleep(Duration::from_millis(2));
        }
        // Frame 0's segments, then frame 1's (frame 1 was tried once 0 was done): frame 2
        // is prepared next.
        let mut results = Vec::new();
        for id in 0..2u64 {
            segments
                .publish(
                    &SegmentsHeader::from(FrameHeader::new(id, 0, 1)),
                    &[&[SegmentRecord::default()]],
                )
                .unwrap_or_else(|e| panic!("{e}"));
            results.extend(collect(&mut out, 1));
        }
        while prepared_ids().len() < 2 {
            assert!(Instant::now() < deadline, "prepared {:?}", prepared_ids());
            std::thread::sleep(Duration::from_millis(2));
        }
        for id in 2..4u64 {
            segments
                .publish(
                    &SegmentsHeader::from(FrameHeader::new(id, 0, 1)),
                    &[&[SegmentRecord::default()]],
                )
                .unwrap_or_else(|e| panic!("{e}"));
        }
        results.extend(collect(&mut out, 2));
        control
            .publish(
                &(),
                &[&[Control::new(Command::Shutdown, StageKind::Matcher, 7, 0, 0)]],
            )
            .unwrap_or_else(|e| panic!("{e}"));
        let ended = runner.join().map_err(|_| "panicked");
        assert!(matches!(ended, Ok(Ok(()))), "{ended:?}");
        // Frames prepared once each, one ahead (the failed one not at all; frame 3 maybe,
        // if its turn came before its segments), then processed with their images.
        let ids = prepared_ids();
        assert!(
            ids == vec![0, 2] || ids == vec![0, 2, 3],
            "prepared {ids:?}"
        );
        let seen: Vec<(u64, u32, i32)> = results
            .iter()
            .map(|m| {
                let r = m.payload()[0];
                (m.header().frame.frame_id, r.has_stereo, r.previous)
            })
            .collect();
        let three = u32::from(ids.contains(&3));
        assert_eq!(seen, vec![(0, 1, 1), (1, 0, 1), (2, 1, 1), (3, three, 1)]);
    }

    /// The ports and runner of an active `stage` on `bus`, for a test that drives the loop's
    /// steps by hand (no thread, no timing luck).
    fn by_hand<'a, S: Stage>(
        ctx: &'a StageContext,
        bus: &Bus,
        stage: S,
    ) -> (Ports<S>, Runner<'a, S>) {
        let ports = Ports::<S> {
            input: bus.inlet(S::INPUT).unwrap_or_else(|e| panic!("{e}")),
            output: bus
                .outlet(S::OUTPUT, S::OUTPUT_LEN)
                .unwrap_or_else(|e| panic!("{e}")),
            frames: stage
                .joins_images()
                .then(|| bus.inlet(topics::FRAMES).unwrap_or_else(|e| panic!("{e}"))),
            control: bus.inlet(topics::CONTROL).unwrap_or_else(|e| panic!("{e}")),
            wake: bus.wake(S::KIND).unwrap_or_else(|e| panic!("{e}")),
            reporter: Reporter::new(bus, ctx, 0).unwrap_or_else(|e| panic!("{e}")),
        };
        (ports, Runner::new(ctx, stage, Role::Active))
    }

    /// The frames a test's stage published, with their status.
    fn statuses<O: Record, H: Record + FrameMessage>(
        out: &mut linetrack_ipc::Inlet<O, H>,
    ) -> Vec<(u64, linetrack_msgs::FrameStatus)> {
        out.receive_all()
            .unwrap_or_else(|e| panic!("{e}"))
            .iter()
            .map(|m| {
                let frame = m.header().frame();
                (
                    frame.frame_id,
                    frame
                        .status
                        .get()
                        .unwrap_or(linetrack_msgs::FrameStatus::Ok),
                )
            })
            .collect()
    }

    /// The runner times the frames its stage works on and the drop rule reads that time.
    /// A line detector at 10 ms a frame (3 stages left: 30 ms still needed) gets frame 0,
    /// then frames 1 (80 ms old), 2 (5 ms) and 3 (new) queued together, driven by hand (no
    /// thread, no timing luck). `deadline` drops only frame 1 (80 + 30 > 100 ms) behind;
    /// `newest` drops 1 and 2.
    #[test]
    fn an_older_frame_queued_with_newer_ones_is_kept_while_it_can_make_the_budget() {
        use linetrack_msgs::FrameStatus::{DroppedBehind, Ok as Done};
        use linetrack_pipeline_config::BehindRule;
        for (rule, expected) in [
            (BehindRule::Deadline, [Done, DroppedBehind, Done, Done]),
            (
                BehindRule::Newest,
                [Done, DroppedBehind, DroppedBehind, Done],
            ),
        ] {
            let bus = Bus::local();
            let mut ctx = context(1, false);
            ctx.config.budget.drop_late = true;
            ctx.config.budget.behind = rule;
            let clock = ctx.clock.clone();
            clock.advance(Duration::from_secs(10));
            let mut frames = bus
                .outlet::<u8, FrameHeader>(topics::FRAMES, 1)
                .unwrap_or_else(|e| panic!("{e}"));
            let mut out = bus
                .inlet::<SegmentRecord, SegmentsHeader>(topics::SEGMENTS)
                .unwrap_or_else(|e| panic!("{e}"));
            let (mut ports, mut runner) = by_hand(
                &ctx,
                &bus,
                Tag {
                    instance: 0.0,
                    remembers: false,
                    last: None,
                    work: Some((clock.clone(), Duration::from_millis(10))),
                },
            );
            let mut publish = |id: u64, age_ms: u64| {
                let captured = clock.now_ns() - age_ms * 1_000_000;
                frames
                    .publish(&FrameHeader::new(id, 0, captured), &[&[1]])
                    .unwrap_or_else(|e| panic!("{e}"));
            };
            publish(0, 0);
            runner
                .process_waiting(&mut ports)
                .unwrap_or_else(|e| panic!("{e}"));
            publish(1, 80);
            publish(2, 5);
            publish(3, 0);
            runner
                .process_waiting(&mut ports)
                .unwrap_or_else(|e| panic!("{e}"));
            let want: Vec<(u64, FrameStatus)> = (0..4).zip(expected).collect();
            assert_eq!(statuses(&mut out), want, "{rule:?}");
            assert_eq!(
                runner.work.expected(false).mean_ms(),
                Some(10.0),
                "{rule:?}"
            );
        }
    }

    /// A stage that prepares ahead is timed per kind of frame. Frames 0 and 2 unprepared
    /// (40 ms each) and 1 prepared (2 ms), one at a time; then frame 3, 60 ms old and
    /// prepared while the stage waited, queued with frame 4. Prepared frames take 2 ms,
    /// 2 stages left: 60 + 4 ms fits the 100 ms budget, so frame 3 is kept. One mean of both
    /// kinds (35.8 ms after 40, 2, 40) would have dropped it behind (60 + 71.7 ms).
    #[test]
    fn a_prepared_frame_is_judged_by_the_time_prepared_frames_take() {
        use linetrack_msgs::FrameStatus::Ok as Done;
        let bus = Bus::local();
        let mut ctx = context(1, false);
        ctx.stage = StageKind::Matcher;
        ctx.config.budget.drop_late = true;
        ctx.config.budget.behind = linetrack_pipeline_config::BehindRule::Deadline;
        ctx.config.budget.end_to_end_ms = 100.0;
        let clock = ctx.clock.clone();
        clock.advance(Duration::from_secs(10));
        let mut images = bus
            .outlet::<u8, FrameHeader>(topics::FRAMES, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut segments = bus
            .outlet::<SegmentRecord, SegmentsHeader>(topics::SEGMENTS, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut out = bus
            .inlet::<linetrack_msgs::TrackedLine, TracksHeader>(topics::TRACKS)
            .unwrap_or_else(|e| panic!("{e}"));
        let prepared = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let stage = Ahead {
            prepared: prepared.clone(),
            clock: Some(clock.clone()),
        };
        let (mut ports, mut runner) = by_hand(&ctx, &bus, stage);
        let frame =
            |id: u64, age_ms: u64| FrameHeader::new(id, 0, clock.now_ns() - age_ms * 1_000_000);
        // A frame's images arrive (and are prepared if `prepare`) before its segments.
        let mut arrive = |runner: &mut Runner<'_, Ahead>,
                          ports: &mut Ports<Ahead>,
                          header: FrameHeader,
                          prepare: bool| {
            images
                .publish(&header, &[&[1]])
                .unwrap_or_else(|e| panic!("{e}"));
            if let Some(frames) = &mut ports.frames {
                runner
                    .images
                    .receive(frames)
                    .unwrap_or_else(|e| panic!("{e}"));
            }
            if prepare {
                runner.prepare_held();
            }
        };
        let mut segments_of = |header: FrameHeader| {
            segments
                .publish(
                    &SegmentsHeader::from(header),
                    &[&[SegmentRecord::default()]],
                )
                .unwrap_or_else(|e| panic!("{e}"));
        };
        for id in 0..3 {
            let header = frame(id, 0);
            arrive(&mut runner, &mut ports, header, id == 1);
            segments_of(header);
            runner
                .process_waiting(&mut ports)
                .unwrap_or_else(|e| panic!("{e}"));
        }
        let (third, fourth) = (frame(3, 60), frame(4, 0));
        arrive(&mut runner, &mut ports, third, true);
        arrive(&mut runner, &mut ports, fourth, false);
        segments_of(third);
        segments_of(fourth);
        runner
            .process_waiting(&mut ports)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(prepared.lock().map(|p| p.clone()).ok(), Some(vec![1, 3]));
        assert_eq!(
            statuses(&mut out),
            (0..5).map(|id| (id, Done)).collect::<Vec<_>>()
        );
        assert_eq!(runner.work.expected(true).mean_ms(), Some(2.0));
        assert_eq!(runner.work.expected(false).mean_ms(), Some(40.0));
    }
}
