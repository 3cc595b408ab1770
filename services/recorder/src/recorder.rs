//! The recorder as a sink of the stage runtime.

use anyhow::Context;
use linetrack_ipc::{Bus, Inlet, Shutdown};
use linetrack_mcap::Recording;
use linetrack_msgs::{
    FrameHeader, PoseRecord, RigRecord, SegmentRecord, SegmentsHeader, StageKind, StatusKind,
    StatusReport, TrackedLine, TracksHeader, now_ns, topics,
};
use linetrack_stage_runtime::{GapWatch, Sink, StageContext, run_sink};
use std::collections::BTreeMap;

/// The recorder's subscriptions.
struct Inlets {
    frames: Inlet<u8, FrameHeader>,
    segments: Inlet<SegmentRecord, SegmentsHeader>,
    tracks: Inlet<TrackedLine, TracksHeader>,
    poses: Inlet<PoseRecord, TracksHeader>,
    status: Inlet<StatusReport, ()>,
    rig: Inlet<RigRecord, ()>,
}

/// What the recorder saw and could not record.
#[derive(Debug, Default)]
struct Losses {
    frames: GapWatch,
    /// Frames whose images never reached the recorder (its queue overwritten).
    frames_missed: u64,
}

/// A recording being written.
struct Recorder {
    inlets: Inlets,
    recording: Recording,
    losses: Losses,
    every_nth_image: u64,
}

/// Runs the recorder until a shutdown command or signal; the file is closed either way.
pub fn run(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    run_sink(ctx, bus, shutdown, |bus| {
        let inlets = Inlets {
            frames: bus.inlet(topics::FRAMES)?,
            segments: bus.inlet(topics::SEGMENTS)?,
            tracks: bus.inlet(topics::TRACKS)?,
            poses: bus.inlet(topics::POSES)?,
            status: bus.inlet(topics::STATUS)?,
            rig: bus.inlet(topics::RIG)?,
        };
        let record = &ctx.config.record;
        let path = record.file(&ctx.args.run_dir);
        let recording = Recording::create(&path)?;
        tracing::info!("recording into {}", path.display());
        Ok(Recorder {
            inlets,
            recording,
            losses: Losses::default(),
            every_nth_image: record.every_nth_image,
        })
    })
}

impl Sink for Recorder {
    const KIND: StageKind = StageKind::Recorder;
    const WAKES_WITH: StageKind = StageKind::Recorder;

    /// Writes everything queued.
    fn drain(&mut self) -> anyhow::Result<()> {
        let (inlets, recording) = (&mut self.inlets, &mut self.recording);
        for message in inlets.rig.receive_all()? {
            if let Some(rig) = message.payload().first() {
                recording.rig(rig, now_ns())?;
            }
        }
        for message in inlets.frames.receive_all()? {
            let header = message.header();
            if let Some((first, count)) = self.losses.frames.observe(header.frame_id) {
                tracing::warn!(
                    "frames {first}..{} not recorded: the recorder fell behind",
                    first + count
                );
                self.losses.frames_missed += count;
            }
            if message.payload().is_empty() {
                // A marker (corrupt, or dropped at the camera): its outcome is recorded.
                continue;
            }
            let every = self.every_nth_image;
            if every > 0 && header.frame_id.is_multiple_of(every) {
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

    fn count(&self) -> u64 {
        self.recording.counts().images
    }

    /// Writes the recorder's counts into the file's metadata and closes it.
    fn finish(self) -> anyhow::Result<()> {
        let Self {
            mut recording,
            losses,
            every_nth_image: every,
            ..
        } = self;
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
        Ok(())
    }
}
