//! Tests of the source and sink roles: real threads over the local transport, a manual
//! clock for the stamps.

use crate::{Clock, Sink, Source, SourceOut, StageContext, Step, run_sink, run_source};
use crossbeam_channel::{Receiver, RecvTimeoutError};
use linetrack_ipc::{Bus, Inlet, Shutdown};
use linetrack_msgs::{
    Command, Control, FrameHeader, FrameStatus, StageKind, StampSlot, StatusKind, StatusReport,
    topics,
};
use linetrack_pipeline_config::PipelineConfig;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Long enough for a loaded machine; the tests wait for messages, never for time.
const PATIENCE: Duration = Duration::from_secs(30);

/// A frame as another system's callback delivers it: an id, a timestamp and two 2×1
/// images, or a frame that could not be read.
type Delivered = Result<(u64, u64, [u8; 4]), u64>;

/// A source driven by what a callback on another thread sends it.
struct Fed(Receiver<Delivered>);

impl Source for Fed {
    const KIND: StageKind = StageKind::FrameSource;
    const FRAME_BYTES: usize = 4;

    fn start(&mut self, _out: &mut SourceOut) -> anyhow::Result<()> {
        Ok(())
    }

    fn step(&mut self, out: &mut SourceOut, wait: Duration) -> anyhow::Result<Step> {
        match self.0.recv_timeout(wait) {
            Ok(Ok((id, timestamp_ns, pixels))) => {
                let now = out.now_ns();
                out.frame(id, timestamp_ns, now, (2, 1), &[&pixels[..2], &pixels[2..]])?;
                Ok(Step::Again)
            }
            Ok(Err(id)) => {
                let now = out.now_ns();
                out.marker(id, 0, now, FrameStatus::Corrupt)?;
                Ok(Step::Again)
            }
            Err(RecvTimeoutError::Timeout) => Ok(Step::Again),
            Err(RecvTimeoutError::Disconnected) => Ok(Step::Finished),
        }
    }
}

fn context(stage: StageKind, clock: &Clock, start_frame: usize) -> StageContext {
    let mut ctx = StageContext::in_process(stage, PipelineConfig::default(), PathBuf::new());
    ctx.clock = clock.clone();
    ctx.args.start_frame = start_frame;
    ctx
}

/// Status reports (heartbeats that count something, and events) until `until` holds.
fn reports_until(
    bus: &Bus,
    status: &mut Inlet<StatusReport, ()>,
    until: impl Fn(&[StatusReport]) -> bool,
) -> Vec<StatusReport> {
    let wake = bus
        .wake(StageKind::Supervisor)
        .unwrap_or_else(|e| panic!("{e}"));
    let mut got = Vec::new();
    let began = Instant::now();
    while !until(&got) {
        assert!(began.elapsed() < PATIENCE, "gave up waiting: {got:?}");
        for m in status.receive_all().unwrap_or_else(|e| panic!("{e}")) {
            let r = m.payload()[0];
            if !(r.kind.is(StatusKind::Heartbeat) && r.value == 0) {
                got.push(r);
            }
        }
        wake.wait(Duration::from_millis(10))
            .unwrap_or_else(|e| panic!("{e}"));
    }
    got
}

fn stop(bus: &Bus, stage: StageKind) {
    let mut control = bus
        .outlet::<Control, ()>(topics::CONTROL, 1)
        .unwrap_or_else(|e| panic!("{e}"));
    let command = Control::new(Command::Shutdown, stage, 0, 0, 0);
    control
        .publish(&(), &[&[command]])
        .unwrap_or_else(|e| panic!("{e}"));
}

/// A local bus for a source under test, its hub (for the source's thread), and inlets on
/// the frames and the status reports it publishes.
fn source_bus() -> (
    Bus,
    linetrack_ipc::LocalHub,
    Inlet<u8, FrameHeader>,
    Inlet<StatusReport, ()>,
) {
    let bus = Bus::local();
    let hub = bus.local_hub().unwrap_or_else(|| panic!("a local bus"));
    let frames = bus
        .inlet::<u8, FrameHeader>(topics::FRAMES)
        .unwrap_or_else(|e| panic!("{e}"));
    let status = bus
        .inlet::<StatusReport, ()>(topics::STATUS)
        .unwrap_or_else(|e| panic!("{e}"));
    (bus, hub, frames, status)
}

fn summary(r: &StatusReport) -> (Option<StatusKind>, u64, u64) {
    (r.kind.get().ok(), r.frame_id, r.value)
}

#[test]
fn a_source_fed_by_a_callback_publishes_stamps_counts_finishes_and_stays_until_stopped() {
    let (bus, hub, mut frames, mut status) = source_bus();
    let clock = Clock::manual(5_000_000_000);
    let ctx = context(StageKind::FrameSource, &clock, 7);
    let (deliver, delivered) = crossbeam_channel::bounded::<Delivered>(1);
    let shutdown = Shutdown::default();
    let source = std::thread::spawn({
        let shutdown = shutdown.clone();
        move || run_source(&ctx, &hub.bus(), Fed(delivered), &shutdown)
    });
    // The callback: another system's thread delivering frames as they come.
    let callback = std::thread::spawn(move || {
        for d in [Ok((7, 70, [1, 2, 3, 4])), Err(8), Ok((9, 90, [5, 6, 7, 8]))] {
            deliver.send(d).unwrap_or_else(|e| panic!("{e}"));
        }
    });
    let finished = |got: &[StatusReport]| got.iter().any(|r| r.kind.is(StatusKind::SourceFinished));
    let reports = reports_until(&bus, &mut status, finished);
    callback.join().unwrap_or_else(|_| panic!("callback"));
    let got: Vec<_> = reports.iter().map(summary).collect();
    assert_eq!(
        got,
        [
            (Some(StatusKind::Ready), 7, 0),
            (Some(StatusKind::Heartbeat), 7, 1),
            (Some(StatusKind::Heartbeat), 8, 2),
            (Some(StatusKind::Heartbeat), 9, 3),
            (Some(StatusKind::SourceFinished), 9, 3),
        ]
    );
    let published: Vec<_> = frames
        .receive_all()
        .unwrap_or_else(|e| panic!("{e}"))
        .iter()
        .map(|m| {
            let h = m.header();
            let stamp = h.stamps[StampSlot::FrameSource];
            assert_eq!(
                (stamp.start_ns, stamp.end_ns),
                (clock.now_ns(), clock.now_ns())
            );
            (
                h.frame_id,
                h.sequence_ns,
                h.status.get().ok(),
                (h.width, h.height),
                m.payload().to_vec(),
            )
        })
        .collect();
    assert_eq!(
        published,
        [
            (7, 70, Some(FrameStatus::Ok), (2, 1), vec![1, 2, 3, 4]),
            (8, 0, Some(FrameStatus::Corrupt), (0, 0), vec![]),
            (9, 90, Some(FrameStatus::Ok), (2, 1), vec![5, 6, 7, 8]),
        ]
    );
    // Finished, it stays (it holds what restarted stages need) until it is told to stop.
    assert!(!source.is_finished());
    stop(&bus, StageKind::FrameSource);
    source
        .join()
        .unwrap_or_else(|_| panic!("source thread"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(!shutdown.requested());
}

/// A sink that counts the frames it takes; fails a pass on frame `fail_at`, and says
/// whether it was closed.
struct Counter {
    frames: Inlet<u8, FrameHeader>,
    taken: Vec<u64>,
    fail_at: Option<u64>,
    closed: crossbeam_channel::Sender<Vec<u64>>,
}

impl Sink for Counter {
    const KIND: StageKind = StageKind::Recorder;
    const WAKES_WITH: StageKind = StageKind::Recorder;

    fn drain(&mut self) -> anyhow::Result<()> {
        for m in self.frames.receive_all()? {
            let id = m.header().frame_id;
            anyhow::ensure!(Some(id) != self.fail_at, "frame {id} cannot be taken");
            self.taken.push(id);
        }
        Ok(())
    }

    fn count(&self) -> u64 {
        self.taken.len() as u64
    }

    fn finish(self) -> anyhow::Result<()> {
        self.closed.send(self.taken)?;
        Ok(())
    }
}

#[test]
fn a_sink_takes_what_comes_counts_it_and_is_closed_on_a_stop_or_a_failure() {
    for fail_at in [None, Some(2)] {
        let bus = Bus::local();
        let hub = bus.local_hub().unwrap_or_else(|| panic!("a local bus"));
        let mut status = bus
            .inlet::<StatusReport, ()>(topics::STATUS)
            .unwrap_or_else(|e| panic!("{e}"));
        let clock = Clock::manual(1_000_000_000);
        let ctx = context(StageKind::Recorder, &clock, 0);
        let (closed, was_closed) = crossbeam_channel::bounded(1);
        let sink = std::thread::spawn(move || {
            run_sink(&ctx, &hub.bus(), &Shutdown::default(), |bus| {
                Ok(Counter {
                    frames: bus.inlet(topics::FRAMES)?,
                    taken: Vec::new(),
                    fail_at,
                    closed,
                })
            })
        });
        let ready = |got: &[StatusReport]| got.iter().any(|r| r.kind.is(StatusKind::Ready));
        reports_until(&bus, &mut status, ready);
        let mut out = bus
            .outlet::<u8, FrameHeader>(topics::FRAMES, 1)
            .unwrap_or_else(|e| panic!("{e}"));
        for id in 0..4 {
            out.publish(&FrameHeader::new(id, 0, 0), &[&[0]])
                .unwrap_or_else(|e| panic!("{e}"));
        }
        let taken = match fail_at {
            None => {
                // What was queued at the stop is taken in the last pass.
                stop(&bus, StageKind::Recorder);
                sink.join()
                    .unwrap_or_else(|_| panic!("sink thread"))
                    .unwrap_or_else(|e| panic!("{e}"));
                vec![0, 1, 2, 3]
            }
            Some(at) => {
                let err = sink
                    .join()
                    .unwrap_or_else(|_| panic!("sink thread"))
                    .err()
                    .map(|e| e.to_string());
                assert_eq!(err, Some(format!("frame {at} cannot be taken")));
                vec![0, 1]
            }
        };
        assert_eq!(
            was_closed.recv_timeout(PATIENCE).ok(),
            Some(taken),
            "closed after {fail_at:?}"
        );
    }
}

/// With `pacing = "fastest"` and `drop_late = false` a source waits for the pipeline. A
/// pipeline slower than the supervisor's hang timeout (a loaded machine) holds it that long;
/// it beats all the while, so the supervisor does not take it for hung, and it goes on when
/// a pose comes out.
#[test]
fn a_source_waiting_for_a_slow_pipeline_beats_past_the_hang_timeout() {
    let (bus, hub, mut frames, mut status) = source_bus();
    let clock = Clock::manual(1_000_000_000);
    let mut ctx = context(StageKind::FrameSource, &clock, 0);
    ctx.config.source.pacing = linetrack_pipeline_config::Pacing::Fastest;
    ctx.config.budget.drop_late = false;
    ctx.config.supervisor.heartbeat_ms = 10;
    ctx.config.supervisor.hang_timeout_ms = 100;
    let (every, hang) = (ctx.heartbeat(), Duration::from_millis(100));
    let (deliver, delivered) = crossbeam_channel::unbounded::<Delivered>();
    for id in 0..=crate::source::IN_FLIGHT {
        deliver
            .send(Ok((id, id, [0; 4])))
            .unwrap_or_else(|e| panic!("{e}"));
    }
    let shutdown = Shutdown::default();
    let source = std::thread::spawn({
        let shutdown = shutdown.clone();
        move || run_source(&ctx, &hub.bus(), Fed(delivered), &shutdown)
    });
    let in_flight = crate::source::IN_FLIGHT;
    let counted = move |got: &[StatusReport]| got.iter().any(|r| r.value == in_flight);
    reports_until(&bus, &mut status, counted);
    // Held: the clock moves past the hang timeout, a heartbeat period at a time; each
    // period has its heartbeat, still counting the frames out before the wait.
    let mut held = Duration::ZERO;
    while held <= hang {
        clock.advance(every);
        held += every;
        let beat = reports_until(&bus, &mut status, |got| {
            got.iter().any(|r| r.kind.is(StatusKind::Heartbeat))
        });
        assert!(beat.iter().all(|r| r.value == in_flight), "{beat:?}");
    }
    let out: Vec<u64> = frames
        .receive_all()
        .unwrap_or_else(|e| panic!("{e}"))
        .iter()
        .map(|m| m.header().frame_id)
        .collect();
    assert_eq!(out, (0..in_flight).collect::<Vec<_>>());
    // A pose for frame 0: the next frame goes out.
    let mut poses = bus
        .outlet::<linetrack_msgs::PoseRecord, linetrack_msgs::TracksHeader>(topics::POSES, 1)
        .unwrap_or_else(|e| panic!("{e}"));
    let header = linetrack_msgs::TracksHeader {
        frame: FrameHeader::new(0, 0, 0),
        ..Default::default()
    };
    poses
        .publish(&header, &[&[linetrack_msgs::PoseRecord::default()]])
        .unwrap_or_else(|e| panic!("{e}"));
    reports_until(&bus, &mut status, move |got| {
        got.iter().any(|r| r.value == in_flight + 1)
    });
    let next: Vec<u64> = frames
        .receive_all()
        .unwrap_or_else(|e| panic!("{e}"))
        .iter()
        .map(|m| m.header().frame_id)
        .collect();
    assert_eq!(next, [in_flight]);
    shutdown.request();
    source
        .join()
        .unwrap_or_else(|_| panic!("source thread"))
        .unwrap_or_else(|e| panic!("{e}"));
}
