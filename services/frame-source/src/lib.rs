//! The frame source: reads a stereo sequence (EuRoC or KITTI layout, rectified on load)
//! and publishes each frame's two images into one shared-memory message, paced at the
//! sequence's rate or as fast as it can. A frame that cannot be read is published as a
//! `corrupt` marker (no pixels) so that downstream stages and the records count it.
//! With `[camera]` set, it reads a live stereo camera instead ([`camera`]).

pub mod camera;
mod gain_jumps;
#[cfg(feature = "mcap")]
mod replay;

use anyhow::Context;
use linetrack_datasets::StereoSequence;
use linetrack_ipc::{Bus, Inlet, Outlet, Shutdown, Wake};
use linetrack_msgs::{Control, FrameHeader, FrameStatus, RigRecord, StageKind, StatusKind, Topic};
use linetrack_pipeline_config::Pacing;
use linetrack_stage_runtime::{Reporter, StageContext, rig_record, shutdown_ordered, stamp_end};
use std::time::{Duration, Instant};
use tracing::info_span;

/// The source's connections.
pub struct Ports {
    frames: Outlet<u8, FrameHeader>,
    rig: Outlet<RigRecord, ()>,
    control: Inlet<Control, ()>,
    wake: Wake,
    reporter: Reporter,
}

impl Ports {
    /// Opens the source's services on `bus`.
    fn open(bus: &Bus, ctx: &StageContext) -> anyhow::Result<Self> {
        Ok(Self {
            frames: bus.outlet(Topic::Frames, 2 * 752 * 480)?,
            rig: bus.outlet(Topic::Rig, 1)?,
            control: bus.inlet(Topic::Control)?,
            wake: bus.wake(StageKind::FrameSource)?,
            reporter: Reporter::new(bus, ctx, 0)?,
        })
    }
}

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

/// Runs the source: publishes the rig and the sequence, then holds the rig until the run
/// ends (shutdown by signal or command).
pub fn run(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    publish(ctx, Ports::open(bus, ctx)?, shutdown)
}

fn publish(ctx: &StageContext, mut ports: Ports, shutdown: &Shutdown) -> anyhow::Result<()> {
    if ctx.config.camera.enabled() {
        return camera::publish(ctx, ports, shutdown);
    }
    if let Some(file) = ctx.config.source.replay() {
        #[cfg(feature = "mcap")]
        return replay::publish(ctx, ports, shutdown, file);
        #[cfg(not(feature = "mcap"))]
        anyhow::bail!("{}: {NO_MCAP}", file.display());
    }
    let source = &ctx.config.source;
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
    let rate = if source.rate_hz > 0.0 {
        source.rate_hz
    } else {
        0.0
    };
    tracing::info!(
        "{}: frames {start}..{end} of {total}, {:?}",
        sequence.name,
        source.pacing
    );
    // The rig goes first: the pose estimator needs it before the first frame's tracks.
    ports.rig.publish(&(), &[&[rig_record(&sequence.rig)]])?;
    let origin_ns = sequence.frames.first().map_or(0, |f| f.timestamp_ns);
    let mut gain_jumps =
        gain_jumps::GainJumps::new(source.gain_jumps_s, source.gain_jumps_seed, origin_ns);
    let reader_nice = source.reader_nice;
    let stream = sequence.into_stream_with(start, 4, move || read_in_background(reader_nice));
    ports.reporter.report(StatusKind::Ready, start as u64, 0);

    let began = Instant::now();
    let mut published = 0u64;
    for (k, item) in stream.take(end.saturating_sub(start)).enumerate() {
        let (index, timestamp_ns) = match &item {
            Ok(frame) => (frame.index, frame.timestamp_ns),
            Err(e) => (e.index, e.timestamp_ns),
        };
        let due = began + due_offset(source.pacing, rate, first_ns, timestamp_ns, k);
        if !wait_until(ctx, &mut ports, shutdown, due, published)? {
            return Ok(());
        }
        let span = info_span!("publish_frame", frame_id = index as u64);
        let _entered = span.enter();
        let capture_ns = ctx.clock.now_ns();
        let mut header = FrameHeader::new(index as u64, timestamp_ns, capture_ns);
        if let Some(stamp) = header.stamp_mut(StageKind::FrameSource) {
            stamp.start_ns = capture_ns;
        }
        match item {
            Ok(frame) => {
                let (w, h) = (frame.left.width() as u32, frame.left.height() as u32);
                header.width = w;
                header.height = h;
                let (Some(left), Some(right)) = (frame.left.pixels(), frame.right.pixels()) else {
                    anyhow::bail!("frame {index}: images are not continuous in memory");
                };
                let [left, right] = match &mut gain_jumps {
                    Some(jumps) => jumps.apply(timestamp_ns, [left, right]),
                    None => [left, right],
                };
                stamp_end(&mut header, StageKind::FrameSource, ctx.clock.now_ns());
                ports.frames.publish(&header, &[left, right])?;
            }
            Err(e) => {
                tracing::warn!("{e}");
                header.mark(FrameStatus::Corrupt, StageKind::FrameSource);
                stamp_end(&mut header, StageKind::FrameSource, ctx.clock.now_ns());
                ports.frames.publish(&header, &[])?;
            }
        }
        published += 1;
        ports
            .reporter
            .report(StatusKind::Heartbeat, index as u64, published);
        // A stage that (re)started since gets the rig.
        ports.rig.update_connections()?;
    }
    stay_until_the_run_ends(ctx, &mut ports, shutdown, start as u64, published)
}

/// Waits for a frame's time `due`, waking for commands and beating; `false` when the run
/// is shutting down instead.
pub(crate) fn wait_until(
    ctx: &StageContext,
    ports: &mut Ports,
    shutdown: &Shutdown,
    due: Instant,
    published: u64,
) -> anyhow::Result<bool> {
    loop {
        if shutdown.requested()
            || shutdown_ordered(&mut ports.control, StageKind::FrameSource, ctx.pid)?
        {
            tracing::info!("shutdown after {published} frames");
            return Ok(false);
        }
        let now = Instant::now();
        if now >= due {
            return Ok(true);
        }
        ports
            .wake
            .wait((due - now).min(ports.reporter.until_due().max(Duration::from_millis(1))))?;
        ports.reporter.beat(published);
    }
}

/// Reports the source finished after `published` frames from `start`, then stays until the
/// run ends: it holds the rig, which a stage restarted after the last frame still needs.
pub(crate) fn stay_until_the_run_ends(
    ctx: &StageContext,
    ports: &mut Ports,
    shutdown: &Shutdown,
    start: u64,
    published: u64,
) -> anyhow::Result<()> {
    ports.reporter.report(
        StatusKind::SourceFinished,
        (start + published).saturating_sub(1),
        published,
    );
    tracing::info!("finished: {published} frames published");
    while !shutdown.requested()
        && !shutdown_ordered(&mut ports.control, StageKind::FrameSource, ctx.pid)?
    {
        ports.rig.update_connections()?;
        ports.reporter.beat(published);
        ports
            .wake
            .wait(ports.reporter.until_due().max(Duration::from_millis(1)))?;
    }
    Ok(())
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
}
