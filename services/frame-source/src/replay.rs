//! The source reading an MCAP recording (`source.replay`, `linetrack replay FILE`): the
//! recorded rig first, then each recorded stereo frame with its sequence timestamp, paced
//! as a sequence is. Frames are numbered from 0 in the order recorded (a recording of
//! every frame keeps the recorded run's ids); frames recorded without both images (a
//! decimated recording, markers) are not replayed.

use crate::{Ports, due_offset, stay_until_the_run_ends, wait_until};
use anyhow::Context;
use linetrack_ipc::Shutdown;
use linetrack_mcap::Replay;
use linetrack_msgs::{FrameHeader, StageKind, StatusKind};
use linetrack_stage_runtime::{StageContext, stamp_end};
use std::path::Path;
use std::time::Instant;
use tracing::info_span;

/// Publishes the recording `file`'s rig and frames, then stays until the run ends.
pub(crate) fn publish(
    ctx: &StageContext,
    mut ports: Ports,
    shutdown: &Shutdown,
    file: &Path,
) -> anyhow::Result<()> {
    let source = &ctx.config.source;
    let replay = Replay::open(file).with_context(|| format!("source.replay {}", file.display()))?;
    let start = ctx.args.start_frame;
    let end = if source.max_frames > 0 {
        replay.frames.min(source.max_frames)
    } else {
        replay.frames
    };
    tracing::info!(
        "replaying {}: frames {start}..{end} of {}, {:?}",
        file.display(),
        replay.frames,
        source.pacing
    );
    ports.rig.publish(&(), &[&[replay.rig]])?;
    ports.reporter.report(StatusKind::Ready, start as u64, 0);
    let began = Instant::now();
    let mut first_ns = None;
    let mut published = 0u64;
    let mut index = 0usize;
    let mut failure = None;
    let mut stopped = false;
    replay.for_each_frame(|frame| {
        let k = index;
        index += 1;
        if k < start {
            return true;
        }
        if k >= end {
            return false;
        }
        let first = *first_ns.get_or_insert(frame.timestamp_ns);
        let due = began
            + due_offset(
                source.pacing,
                source.rate_hz,
                first,
                frame.timestamp_ns,
                k - start,
            );
        let mut step = || -> anyhow::Result<bool> {
            if !wait_until(ctx, &mut ports, shutdown, due, published)? {
                return Ok(false);
            }
            let span = info_span!("publish_frame", frame_id = k as u64);
            let _entered = span.enter();
            let capture_ns = ctx.clock.now_ns();
            let mut header = FrameHeader::new(k as u64, frame.timestamp_ns, capture_ns);
            if let Some(stamp) = header.stamp_mut(StageKind::FrameSource) {
                stamp.start_ns = capture_ns;
            }
            header.width = frame.width;
            header.height = frame.height;
            stamp_end(&mut header, StageKind::FrameSource, ctx.clock.now_ns());
            ports.frames.publish(&header, &[&frame.pixels])?;
            published += 1;
            ports
                .reporter
                .report(StatusKind::Heartbeat, k as u64, published);
            ports.rig.update_connections()?;
            Ok(true)
        };
        match step() {
            Ok(go_on) => {
                stopped = !go_on;
                go_on
            }
            Err(e) => {
                failure = Some(e);
                false
            }
        }
    })?;
    if let Some(e) = failure {
        return Err(e);
    }
    if stopped {
        return Ok(());
    }
    stay_until_the_run_ends(ctx, &mut ports, shutdown, start as u64, published)
}
