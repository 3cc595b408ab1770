//! The frame source on a live stereo camera (`[camera]` in the config).
//!
//! The rig comes from the calibration file and is published first, as for a sequence.
//! A capture thread reads the camera as fast as it delivers (paced like a sequence when
//! the capture is not live: a file pipeline is read at `source.rate_hz`, or at its driver
//! timestamps' rate, unless `source.pacing = "fastest"`) and hands each rectified pair to
//! the publishing loop through a queue of [`HANDOVER_FRAMES`]. Every frame the camera
//! delivered gets a frame id and ends up in the run's records:
//!
//! - published with its pixels, stamped with the driver's capture time
//!   ([`linetrack_camera::timing`]);
//! - `capture-dropped` (a marker, no pixels): lost in a gap of a V4L2 driver's timestamps, or
//!   not taken because the hand-over queue was full (the publishing loop was behind);
//! - `capture-late` (a marker): it waited more than `camera.late_ms` longer than the
//!   least-delayed frame, and `budget.drop_late` is on (not judged when `source.rate_hz`
//!   paces the capture: the waiting is then the source's own).
//!
//! A camera that fails (cannot be opened, a read fails: device gone, stream ended; frames
//! of the wrong size) is reported as a `camera-lost` event naming the device and reopened
//! after a backoff (`camera.retry_ms`, doubling to `camera.retry_max_ms`); when it
//! delivers again, a `camera-back` event. Heartbeats go on meanwhile, so the supervisor
//! neither restarts the source nor stops the run. The run ends after `camera.duration_s`
//! or `source.max_frames` frame ids, or by Ctrl-C / shutdown.

use crate::Ports;
use anyhow::Context;
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TrySendError};
use linetrack_camera::{CameraError, FrameClock, Stamp, StereoCamera, StereoImages};
use linetrack_datasets::Rectifier;
use linetrack_ipc::Shutdown;
use linetrack_msgs::{CameraFailure, FrameHeader, FrameStatus, StageKind, StatusKind};
use linetrack_pipeline_config::{CameraConfig, Pacing, PipelineConfig};
use linetrack_stage_runtime::{
    Backoff, Clock, StageContext, rig_record, shutdown_ordered, stamp_end,
};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};
use tracing::info_span;

/// Pairs the capture thread may hand over before the publishing loop takes them; one more
/// is counted as `capture-dropped`.
pub const HANDOVER_FRAMES: usize = 2;

/// The longest the publishing loop waits for a frame before it looks at commands.
const POLL: Duration = Duration::from_millis(20);

/// What the capture thread hands over.
enum Captured {
    /// A pair.
    Frame {
        /// The rectified images.
        images: StereoImages,
        /// Its stamp.
        stamp: Stamp,
    },
    /// The camera failed; it is reopened after `retry_in`.
    Lost {
        /// The error, naming the device.
        error: String,
        /// Its kind.
        failure: CameraFailure,
        /// Attempt number since the camera last delivered.
        attempt: u64,
        /// The wait before the next attempt.
        retry_in: Duration,
    },
    /// The camera delivers again after `attempts` failed attempts.
    Back {
        /// The device.
        device: String,
        /// How many attempts failed before.
        attempts: u64,
    },
}

/// The capture thread's side.
struct CaptureThread {
    camera: CameraConfig,
    pacing: Pacing,
    rate_hz: f64,
    rectifier: Arc<Rectifier>,
    clock: Clock,
    frames: Sender<Captured>,
    /// Frames read but not taken (the queue was full), plus the gaps they announced.
    not_taken: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
}

impl CaptureThread {
    /// Sleeps `wait` in short steps, returning early when told to stop.
    fn sleep(&self, wait: Duration) {
        let until = Instant::now() + wait;
        while !self.stop.load(Ordering::SeqCst) {
            let now = Instant::now();
            if now >= until {
                return;
            }
            std::thread::sleep((until - now).min(POLL));
        }
    }

    /// Opens, reads, reopens, until told to stop or the publishing loop is gone.
    fn run(self) {
        let retry = Backoff::new(
            Duration::from_millis(self.camera.retry_ms),
            Duration::from_millis(self.camera.retry_max_ms),
        );
        let mut backoff = retry;
        let mut failures = 0u64;
        while !self.stop.load(Ordering::SeqCst) {
            let fail = |backoff: &mut Backoff, error: CameraError| -> (Captured, Duration) {
                let (retry_in, attempt) = backoff.next_wait();
                let failure = match error {
                    CameraError::Open { .. } | CameraError::Spec { .. } => CameraFailure::Open,
                    CameraError::Read { .. } => CameraFailure::Read,
                    CameraError::Size { .. } => CameraFailure::Size,
                    _ => CameraFailure::Other,
                };
                (
                    Captured::Lost {
                        error: error.to_string(),
                        failure,
                        attempt,
                        retry_in,
                    },
                    retry_in,
                )
            };
            let mut camera = match StereoCamera::open(
                &self.camera.capture,
                self.camera.right(),
                Arc::clone(&self.rectifier),
            ) {
                Ok(camera) => camera,
                Err(e) => {
                    let (message, wait) = fail(&mut backoff, e);
                    failures += 1;
                    if self.frames.send(message).is_err() {
                        return;
                    }
                    self.sleep(wait);
                    continue;
                }
            };
            let period_ns = (if self.camera.fps > 0.0 {
                Some(self.camera.fps)
            } else {
                camera.driver_fps()
            })
            .map(|fps| (1e9 / fps).round() as u64)
            // Gaps count as lost frames only where each frame carries its own time.
            .filter(|_| camera.stamps_each_frame());
            let mut frame_clock = FrameClock::new(period_ns);
            let mut first: Option<(Instant, u64)> = None;
            let mut k = 0u64;
            loop {
                if self.stop.load(Ordering::SeqCst) {
                    return;
                }
                let images = match camera.read() {
                    Ok(images) => images,
                    Err(e) => {
                        drop(camera);
                        let (message, wait) = fail(&mut backoff, e);
                        failures += 1;
                        if self.frames.send(message).is_err() {
                            return;
                        }
                        self.sleep(wait);
                        break;
                    }
                };
                if failures > 0 {
                    let back = Captured::Back {
                        device: camera.describe(),
                        attempts: failures,
                    };
                    if self.frames.send(back).is_err() {
                        return;
                    }
                    failures = 0;
                }
                backoff.reset();
                let mut stamp = frame_clock.stamp(images.driver_ms, self.clock.now_ns());
                // Pacing for captures that are not live (files): like a sequence.
                let (began, first_ns) = *first.get_or_insert((Instant::now(), stamp.timestamp_ns));
                let due = began
                    + crate::due_offset(
                        self.pacing,
                        self.rate_hz,
                        first_ns,
                        stamp.timestamp_ns,
                        k as usize,
                    );
                k += 1;
                let wait = due.saturating_duration_since(Instant::now());
                if !wait.is_zero() {
                    // A capture read ahead of its time (not live): it is captured, for
                    // the latency, when the source lets it through.
                    self.sleep(wait);
                    stamp.capture_ns = self.clock.now_ns();
                }
                match self.frames.try_send(Captured::Frame { images, stamp }) {
                    Ok(()) => {}
                    Err(TrySendError::Full(_)) => {
                        self.not_taken
                            .fetch_add(1 + stamp.dropped_before, Ordering::SeqCst);
                    }
                    Err(TrySendError::Disconnected(_)) => return,
                }
            }
        }
    }
}

/// Reads the calibration and computes the rectification once: the rig and its maps.
pub fn rectifier(camera: &CameraConfig) -> anyhow::Result<Rectifier> {
    let calibration = linetrack_camera::read_calibration(&camera.calibration)?;
    let (rectifier, _) = linetrack_camera::rectify_calibration(&calibration)
        .with_context(|| format!("calibration {}", camera.calibration.display()))?;
    Ok(rectifier)
}

/// Publishes one frame id without pixels, marked `status`.
fn publish_marker(
    ports: &mut Ports,
    ctx: &StageContext,
    frame_id: u64,
    timestamp_ns: u64,
    status: FrameStatus,
) -> anyhow::Result<()> {
    let now = ctx.clock.now_ns();
    let mut header = FrameHeader::new(frame_id, timestamp_ns, now);
    if let Some(stamp) = header.stamp_mut(StageKind::FrameSource) {
        stamp.start_ns = now;
    }
    header.mark(status, StageKind::FrameSource);
    stamp_end(&mut header, StageKind::FrameSource, ctx.clock.now_ns());
    ports.frames.publish(&header, &[])?;
    Ok(())
}

/// Runs the source on the camera of `ctx.config.camera`.
pub fn publish(ctx: &StageContext, mut ports: Ports, shutdown: &Shutdown) -> anyhow::Result<()> {
    let config: &PipelineConfig = &ctx.config;
    let camera = &config.camera;
    let rectifier = Arc::new(rectifier(camera)?);
    let rig = rectifier.rig();
    tracing::info!(
        "camera {:?}{}: rig {rig:?}",
        camera.capture,
        camera
            .right()
            .map_or_else(|| " (side by side)".to_string(), |r| format!(" and {r:?}"))
    );
    ports.rig.publish(&(), &[&[rig_record(&rig)]])?;
    let (tx, rx) = crossbeam_channel::bounded(HANDOVER_FRAMES);
    let not_taken = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let thread = CaptureThread {
        camera: camera.clone(),
        pacing: config.source.pacing,
        rate_hz: config.source.rate_hz,
        rectifier,
        clock: ctx.clock.clone(),
        frames: tx,
        not_taken: Arc::clone(&not_taken),
        stop: Arc::clone(&stop),
    };
    std::thread::Builder::new()
        .name("camera".to_string())
        .spawn(move || thread.run())
        .context("starting the capture thread")?;
    let start = ctx.args.start_frame as u64;
    ports.reporter.report(StatusKind::Ready, start, 0);
    let result = publish_frames(ctx, &mut ports, shutdown, &rx, &not_taken, start);
    // The capture thread ends at its next frame or wait (a read blocked in a hung driver
    // ends with the process).
    stop.store(true, Ordering::SeqCst);
    drop(rx);
    let published = match result? {
        Some(published) => published,
        None => return Ok(()),
    };
    crate::stay_until_the_run_ends(ctx, &mut ports, shutdown, start, published)
}

/// Publishes `count` `capture-dropped` markers from frame `first` on; returns `count`.
fn publish_dropped(
    ports: &mut Ports,
    ctx: &StageContext,
    first: u64,
    timestamp_ns: u64,
    count: u64,
) -> anyhow::Result<u64> {
    for k in 0..count {
        publish_marker(
            ports,
            ctx,
            first + k,
            timestamp_ns,
            FrameStatus::CaptureDropped,
        )?;
    }
    Ok(count)
}

/// The publishing loop: `Some(frame ids published)` when the duration or frame limit is
/// reached, `None` when shut down first.
fn publish_frames(
    ctx: &StageContext,
    ports: &mut Ports,
    shutdown: &Shutdown,
    rx: &Receiver<Captured>,
    not_taken: &AtomicU64,
    start: u64,
) -> anyhow::Result<Option<u64>> {
    let camera = &ctx.config.camera;
    let max_frames = ctx.config.source.max_frames as u64;
    let duration = (camera.duration_s > 0.0).then(|| Duration::from_secs_f64(camera.duration_s));
    let late_ns = (camera.late_ms * 1e6) as u64;
    // With `source.rate_hz` the source sets the pace (a file read slower than its
    // timestamps): waiting is then its own doing, not lateness.
    let source = &ctx.config.source;
    let paced_by_rate = source.pacing == Pacing::Realtime && source.rate_hz > 0.0;
    let drop_late = ctx.config.budget.drop_late && !paced_by_rate;
    let began = Instant::now();
    let mut published = 0u64;
    let mut reported = 0u64;
    let mut last_timestamp_ns = 0u64;
    let limit_reached = |published: u64| max_frames > 0 && published >= max_frames;
    // How many more frames the limit allows.
    let room = |published: u64| match max_frames {
        0 => u64::MAX,
        m => m.saturating_sub(published),
    };
    loop {
        if shutdown.requested()
            || shutdown_ordered(&mut ports.control, StageKind::FrameSource, ctx.pid)?
        {
            tracing::info!("shutdown after {published} frames");
            return Ok(None);
        }
        if limit_reached(published) || duration.is_some_and(|d| began.elapsed() >= d) {
            return Ok(Some(published));
        }
        // Frames the queue could not take, in the order they were lost.
        let lost = not_taken.swap(0, Ordering::SeqCst);
        published += publish_dropped(
            ports,
            ctx,
            start + published,
            last_timestamp_ns,
            lost.min(room(published)),
        )?;
        let wait = POLL.min(ports.reporter.until_due().max(Duration::from_millis(1)));
        match rx.recv_timeout(wait) {
            Ok(Captured::Frame { images, stamp }) => {
                published += publish_dropped(
                    ports,
                    ctx,
                    start + published,
                    last_timestamp_ns,
                    stamp.dropped_before.min(room(published)),
                )?;
                if limit_reached(published) {
                    continue;
                }
                let frame_id = start + published;
                last_timestamp_ns = stamp.timestamp_ns;
                if drop_late && stamp.lag_ns > late_ns {
                    tracing::warn!(
                        "frame {frame_id}: waited {:.1} ms more than the least-delayed frame: dropped as late",
                        stamp.lag_ns as f64 * 1e-6
                    );
                    publish_marker(
                        ports,
                        ctx,
                        frame_id,
                        stamp.timestamp_ns,
                        FrameStatus::CaptureLate,
                    )?;
                } else {
                    publish_images(ports, ctx, frame_id, &images, &stamp)?;
                }
                published += 1;
                ports.rig.update_connections()?;
            }
            Ok(Captured::Lost {
                error,
                failure,
                attempt,
                retry_in,
            }) => {
                tracing::warn!(
                    "camera lost (attempt {attempt}): {error}; retrying in {:.1} s",
                    retry_in.as_secs_f64()
                );
                ports.reporter.report_detail(
                    StatusKind::CameraLost,
                    start + published,
                    attempt,
                    failure.into(),
                );
            }
            Ok(Captured::Back { device, attempts }) => {
                tracing::info!(
                    "camera back: {device} delivers again after {attempts} failed attempts"
                );
                ports
                    .reporter
                    .report(StatusKind::CameraBack, start + published, attempts);
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => {
                anyhow::bail!("the capture thread ended unexpectedly")
            }
        }
        // Commands are read above on every turn; the source's wake-ups are not waited on
        // here (the hand-over queue is), and iceoryx2 keeps them as flags, not a queue.
        if published > reported {
            // The supervisor counts frames published from these.
            ports
                .reporter
                .report(StatusKind::Heartbeat, start + published - 1, published);
            reported = published;
        }
        ports.reporter.beat(published);
    }
}

/// Publishes a pair, stamped with its capture time.
fn publish_images(
    ports: &mut Ports,
    ctx: &StageContext,
    frame_id: u64,
    images: &StereoImages,
    stamp: &Stamp,
) -> anyhow::Result<()> {
    let span = info_span!("publish_frame", frame_id);
    let _entered = span.enter();
    let mut header = FrameHeader::new(frame_id, stamp.timestamp_ns, stamp.capture_ns);
    if let Some(s) = header.stamp_mut(StageKind::FrameSource) {
        s.start_ns = stamp.capture_ns;
    }
    header.width = images.left.width() as u32;
    header.height = images.left.height() as u32;
    let (Some(left), Some(right)) = (images.left.pixels(), images.right.pixels()) else {
        anyhow::bail!("frame {frame_id}: rectified images are not continuous in memory");
    };
    stamp_end(&mut header, StageKind::FrameSource, ctx.clock.now_ns());
    ports.frames.publish(&header, &[left, right])?;
    Ok(())
}
