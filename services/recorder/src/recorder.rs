//! The recorder's loop.

use anyhow::Context;
use linetrack_ipc::{Bus, Inlet, Shutdown};
use linetrack_mcap::Recording;
use linetrack_msgs::{
    Control, FrameHeader, PoseRecord, RigRecord, SegmentRecord, SegmentsHeader, StageKind,
    StatusKind, StatusReport, Topic, TrackedLine, TracksHeader, now_ns,
};
use linetrack_stage_runtime::{GapWatch, Reporter, StageContext, shutdown_ordered};
use std::collections::BTreeMap;
use std::time::Duration;

/// The recorder's subscriptions.
struct Inlets {
    frames: Inlet<u8, FrameHeader>,
    segments: Inlet<SegmentRecord, SegmentsHeader>,
    tracks: Inlet<TrackedLine, TracksHeader>,
    poses: Inlet<PoseRecord, TracksHeader>,
    status: Inlet<StatusReport, ()>,
    rig: Inlet<RigRecord, ()>,
    control: Inlet<Control, ()>,
}

/// What the recorder saw and could not record.
#[derive(Debug, Default)]
struct Losses {
    frames: GapWatch,
    /// Frames whose images never reached the recorder (its queue overwritten).
    frames_missed: u64,
}

/// Runs the recorder until a shutdown command or signal; the file is closed either way.
pub fn run(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    // Listening before subscribing: no message comes without its wake-up.
    let wake = bus.wake(StageKind::Recorder)?;
    let heartbeat = Duration::from_millis(ctx.config.supervisor.heartbeat_ms);
    let mut inlets = Inlets {
        frames: bus.inlet(Topic::Frames)?,
        segments: bus.inlet(Topic::Segments)?,
        tracks: bus.inlet(Topic::Tracks)?,
        poses: bus.inlet(Topic::Poses)?,
        status: bus.inlet(Topic::Status)?,
        rig: bus.inlet(Topic::Rig)?,
        control: bus.inlet(Topic::Control)?,
    };
    let record = &ctx.config.record;
    let path = record.file(&ctx.args.run_dir);
    let mut recording = Recording::create(&path)?;
    let mut reporter = Reporter::new(bus, ctx, 0)?;
    // Subscribed and writing: the supervisor may start the frame source.
    reporter.report(StatusKind::Ready, 0, 0);
    tracing::info!("recording into {}", path.display());
    let mut losses = Losses::default();
    let every = record.every_nth_image;
    let mut result = Ok(());
    loop {
        let stop = shutdown.requested()
            || shutdown_ordered(&mut inlets.control, StageKind::Recorder, ctx.pid)?;
        // On a stop, one more pass writes what the queues still hold.
        if let Err(e) = drain(&mut inlets, &mut recording, &mut losses, every) {
            result = Err(e);
            break;
        }
        reporter.beat(recording.counts().images);
        if stop {
            break;
        }
        // Until a publisher of a recorded topic (or a signal) wakes it; at the latest when
        // its heartbeat is due.
        if let Err(e) = wake.wait(heartbeat) {
            result = Err(e.into());
            break;
        }
    }
    let counts = recording.counts();
    let mut values = BTreeMap::new();
    values.insert("images".to_string(), counts.images.to_string());
    values.insert(
        "images_decimated".to_string(),
        counts.images_decimated.to_string(),
    );
    values.insert(
        "frames_missed".to_string(),
        losses.frames_missed.to_string(),
    );
    values.insert("poses".to_string(), counts.poses.to_string());
    values.insert("latencies".to_string(), counts.latencies.to_string());
    values.insert("every_nth_image".to_string(), every.to_string());
    recording.metadata("linetrack.recorder", values)?;
    let file = recording.path().to_path_buf();
    let counts = recording
        .finish()
        .with_context(|| format!("closing {}", file.display()))?;
    tracing::info!(
        "closed {}: {} stereo images, {} decimated, {} frames missed (the recorder fell behind), {} poses",
        file.display(),
        counts.images,
        counts.images_decimated,
        losses.frames_missed,
        counts.poses
    );
    if losses.frames_missed > 0 {
        tracing::warn!(
            "{} frames were not recorded: the recorder fell behind and its queue was overwritten",
            losses.frames_missed
        );
    }
    result
}

/// Writes everything queued.
fn drain(
    inlets: &mut Inlets,
    recording: &mut Recording,
    losses: &mut Losses,
    every_nth_image: u64,
) -> anyhow::Result<()> {
    for message in inlets.rig.receive_all()? {
        if let Some(rig) = message.payload().first() {
            recording.rig(rig, now_ns())?;
        }
    }
    for message in inlets.frames.receive_all()? {
        let header = message.header();
        if let Some((first, count)) = losses.frames.observe(header.frame_id) {
            tracing::warn!(
                "frames {first}..{} not recorded: the recorder fell behind",
                first + count
            );
            losses.frames_missed += count;
        }
        if message.payload().is_empty() {
            // A marker (corrupt, or dropped at the camera): its outcome is recorded.
            continue;
        }
        if every_nth_image > 0 && header.frame_id.is_multiple_of(every_nth_image) {
            recording.images(header, message.payload())?;
        } else {
            recording.skip_images();
        }
    }
    for message in inlets.segments.receive_all()? {
        recording.segments(message.header(), message.payload())?;
    }
    for message in inlets.tracks.receive_all()? {
        recording.matches(&message.header().frame, message.payload())?;
    }
    for message in inlets.poses.receive_all()? {
        recording.outcome(&message.header().frame, message.payload().first())?;
    }
    for message in inlets.status.receive_all()? {
        if let Some(report) = message.payload().first()
            && !report.kind.is(StatusKind::Heartbeat)
        {
            recording.event(report, now_ns())?;
        }
    }
    Ok(())
}
