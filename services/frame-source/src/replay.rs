//! The source reading an MCAP recording (`source.replay`, `linetrack replay FILE`): the
//! recorded rig first, then each recorded stereo frame with its sequence timestamp, paced
//! as a sequence is. Frames are numbered from 0 in the order recorded (a recording of
//! every frame keeps the recorded run's ids); frames recorded without both images (a
//! decimated recording, markers) are not replayed. A thread reads the file and hands the
//! frames over through a short queue: the source is driven by what arrives on it, as a
//! source fed by another system's callbacks is.

use crate::{Capture, Rig, due_offset, not_yet};
use anyhow::Context;
use crossbeam_channel::{Receiver, RecvTimeoutError};
use linetrack_mcap::{Replay, ReplayFrame};
use linetrack_msgs::{FrameStatus, RigRecord, StageKind};
use linetrack_pipeline_config::{BudgetConfig, SourceConfig};
use linetrack_stage_runtime::{Source, SourceOut, StageContext, Step};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Frames the reading thread may hand over ahead of their time.
const READ_AHEAD: usize = 2;

/// What the reading thread hands over: frame `k` of the recording, or why reading stopped.
type Read = anyhow::Result<(usize, ReplayFrame)>;

/// A recording's frames, read on a thread of their own.
pub(crate) struct ReplaySource {
    rig: Rig,
    recorded_rig: RigRecord,
    replay: Option<Replay>,
    file: PathBuf,
    source: SourceConfig,
    budget: BudgetConfig,
    range: (usize, usize),
    frames: Option<Receiver<Read>>,
    /// When the source had its first frame, on its monotonic clock (the schedule starts
    /// there), and that frame's timestamp.
    began: Option<Duration>,
    first_ns: Option<u64>,
    pending: Option<(usize, ReplayFrame)>,
}

impl ReplaySource {
    /// Opens the recording `file` (checked: the rig and the frames are readable).
    pub(crate) fn open(ctx: &StageContext, rig: Rig, file: &Path) -> anyhow::Result<Self> {
        let source = ctx.config.source.clone();
        let replay =
            Replay::open(file).with_context(|| format!("source.replay {}", file.display()))?;
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
        Ok(Self {
            rig,
            recorded_rig: replay.rig,
            replay: Some(replay),
            file: file.to_path_buf(),
            source,
            budget: ctx.config.budget.clone(),
            range: (start, end),
            frames: None,
            began: None,
            first_ns: None,
            pending: None,
        })
    }
}

/// Reads frames `start..end` of `replay` into `tx` until done or nobody takes them.
fn read(
    replay: &Replay,
    file: &Path,
    (start, end): (usize, usize),
    tx: &crossbeam_channel::Sender<Read>,
) {
    let mut k = 0usize;
    let read = replay.for_each_frame(|frame| {
        let index = k;
        k += 1;
        if index < start {
            return true;
        }
        index < end && tx.send(Ok((index, frame))).is_ok()
    });
    if let Err(e) = read {
        let _ = tx.send(Err(
            anyhow::Error::new(e).context(format!("source.replay {}", file.display()))
        ));
    }
}

impl Source for ReplaySource {
    const KIND: StageKind = StageKind::FrameSource;
    const FRAME_BYTES: usize = crate::FRAME_BYTES;

    fn start(&mut self, _out: &mut SourceOut) -> anyhow::Result<()> {
        self.rig.publish(self.recorded_rig)?;
        let (tx, rx) = crossbeam_channel::bounded(READ_AHEAD);
        let (replay, file, range) = (self.replay.take(), self.file.clone(), self.range);
        std::thread::Builder::new()
            .name("replay-reader".to_string())
            .spawn(move || {
                if let Some(replay) = replay {
                    read(&replay, &file, range, &tx);
                }
            })
            .context("starting the recording's reader thread")?;
        self.frames = Some(rx);
        Ok(())
    }

    fn step(&mut self, out: &mut SourceOut, wait: Duration) -> anyhow::Result<Step> {
        if self.pending.is_none() {
            let Some(frames) = &self.frames else {
                return Ok(Step::Finished);
            };
            match frames.recv_timeout(wait) {
                Ok(read) => self.pending = Some(read?),
                Err(RecvTimeoutError::Timeout) => return Ok(Step::Again),
                Err(RecvTimeoutError::Disconnected) => return Ok(Step::Finished),
            }
        }
        let Some((k, frame)) = &self.pending else {
            return Ok(Step::Finished);
        };
        let first = *self.first_ns.get_or_insert(frame.timestamp_ns);
        let began = *self.began.get_or_insert_with(|| out.clock().monotonic());
        let due = due_offset(
            self.source.pacing,
            self.source.rate_hz,
            first,
            frame.timestamp_ns,
            k - self.range.0,
        );
        if let Some(wait) = not_yet(out, began, due) {
            return Ok(Step::Idle(wait));
        }
        let capture = Capture::at(out.clock(), self.source.pacing, began, due);
        if capture.too_late(&self.budget) {
            out.marker(
                *k as u64,
                frame.timestamp_ns,
                capture.capture_ns,
                FrameStatus::CaptureLate,
            )?;
        } else {
            out.frame(
                *k as u64,
                frame.timestamp_ns,
                capture.capture_ns,
                (frame.width, frame.height),
                &[&frame.pixels],
            )?;
        }
        self.pending = None;
        Ok(Step::Again)
    }

    fn poll(&mut self) -> anyhow::Result<()> {
        self.rig.poll()
    }
}
