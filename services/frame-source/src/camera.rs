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

use crate::Rig;
use anyhow::Context;
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TrySendError};
use linetrack_camera::{CameraError, FrameClock, Stamp, StereoCamera, StereoImages};
use linetrack_datasets::Rectifier;
use linetrack_msgs::{CameraFailure, FrameStatus, StageKind, StatusKind};
use linetrack_pipeline_config::{CameraConfig, Pacing, PipelineConfig};
use linetrack_stage_runtime::{Backoff, Clock, Source, SourceOut, StageContext, Step, rig_record};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

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

/// The camera as a source: the capture thread's pairs, stamped with their capture times,
/// and the frame ids it lost as markers.
pub(crate) struct CameraSource {
    rig: Rig,
    rectifier: Arc<Rectifier>,
    camera: CameraConfig,
    pacing: Pacing,
    rate_hz: f64,
    max_frames: u64,
    duration: Option<Duration>,
    late_ns: u64,
    drop_late: bool,
    frames: Option<Receiver<Captured>>,
    not_taken: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
    /// When the source started, on its monotonic clock.
    began: Duration,
    last_timestamp_ns: u64,
}

impl CameraSource {
    /// The camera of `ctx.config.camera`, its calibration read and its rectification
    /// computed; the capture starts with the source.
    pub(crate) fn new(ctx: &StageContext, rig: Rig) -> anyhow::Result<Self> {
        let config: &PipelineConfig = &ctx.config;
        let camera = &config.camera;
        let rectifier = Arc::new(rectifier(camera)?);
        // With `source.rate_hz` the source sets the pace (a file read slower than its
        // timestamps): waiting is then its own doing, not lateness.
        let source = &config.source;
        let paced_by_rate = source.pacing == Pacing::Realtime && source.rate_hz > 0.0;
        Ok(Self {
            rig,
            rectifier,
            camera: camera.clone(),
            pacing: source.pacing,
            rate_hz: source.rate_hz,
            max_frames: source.max_frames as u64,
            duration: (camera.duration_s > 0.0).then(|| Duration::from_secs_f64(camera.duration_s)),
            late_ns: (camera.late_ms * 1e6) as u64,
            drop_late: config.budget.drop_late && !paced_by_rate,
            frames: None,
            not_taken: Arc::new(AtomicU64::new(0)),
            stop: Arc::new(AtomicBool::new(false)),
            began: Duration::ZERO,
            last_timestamp_ns: 0,
        })
    }

    /// How many more frame ids the limit allows after `published`.
    fn room(&self, published: u64) -> u64 {
        match self.max_frames {
            0 => u64::MAX,
            m => m.saturating_sub(published),
        }
    }

    /// Publishes up to `count` `capture-dropped` markers (as many as the limit allows).
    fn publish_dropped(&self, out: &mut SourceOut, count: u64) -> anyhow::Result<()> {
        for _ in 0..count.min(self.room(out.published())) {
            let now = out.now_ns();
            out.marker(
                out.next_id(),
                self.last_timestamp_ns,
                now,
                FrameStatus::CaptureDropped,
            )?;
        }
        Ok(())
    }

    /// Takes what the capture thread handed over.
    fn take(&mut self, out: &mut SourceOut, captured: Captured) -> anyhow::Result<()> {
        match captured {
            Captured::Frame { images, stamp } => {
                self.publish_dropped(out, stamp.dropped_before)?;
                if self.room(out.published()) == 0 {
                    return Ok(());
                }
                let frame_id = out.next_id();
                self.last_timestamp_ns = stamp.timestamp_ns;
                if self.drop_late && stamp.lag_ns > self.late_ns {
                    tracing::warn!(
                        "frame {frame_id}: waited {:.1} ms more than the least-delayed frame: dropped as late",
                        stamp.lag_ns as f64 * 1e-6
                    );
                    let now = out.now_ns();
                    out.marker(frame_id, stamp.timestamp_ns, now, FrameStatus::CaptureLate)?;
                } else {
                    let size = (images.left.width() as u32, images.left.height() as u32);
                    let (Some(left), Some(right)) = (images.left.pixels(), images.right.pixels())
                    else {
                        anyhow::bail!(
                            "frame {frame_id}: rectified images are not continuous in memory"
                        );
                    };
                    out.frame(
                        frame_id,
                        stamp.timestamp_ns,
                        stamp.capture_ns,
                        size,
                        &[left, right],
                    )?;
                }
            }
            Captured::Lost {
                error,
                failure,
                attempt,
                retry_in,
            } => {
                tracing::warn!(
                    "camera lost (attempt {attempt}): {error}; retrying in {:.1} s",
                    retry_in.as_secs_f64()
                );
                let at = out.next_id();
                out.reporter()
                    .report_detail(StatusKind::CameraLost, at, attempt, failure.into());
            }
            Captured::Back { device, attempts } => {
                tracing::info!(
                    "camera back: {device} delivers again after {attempts} failed attempts"
                );
                let at = out.next_id();
                out.reporter().report(StatusKind::CameraBack, at, attempts);
            }
        }
        Ok(())
    }
}

impl Source for CameraSource {
    const KIND: StageKind = StageKind::FrameSource;
    const FRAME_BYTES: usize = crate::FRAME_BYTES;

    fn start(&mut self, out: &mut SourceOut) -> anyhow::Result<()> {
        let rig = self.rectifier.rig();
        tracing::info!(
            "camera {:?}{}: rig {rig:?}",
            self.camera.capture,
            self.camera
                .right()
                .map_or_else(|| " (side by side)".to_string(), |r| format!(" and {r:?}"))
        );
        self.rig.publish(rig_record(&rig))?;
        let (tx, rx) = crossbeam_channel::bounded(HANDOVER_FRAMES);
        let thread = CaptureThread {
            camera: self.camera.clone(),
            pacing: self.pacing,
            rate_hz: self.rate_hz,
            rectifier: Arc::clone(&self.rectifier),
            clock: out.clock().clone(),
            frames: tx,
            not_taken: Arc::clone(&self.not_taken),
            stop: Arc::clone(&self.stop),
        };
        std::thread::Builder::new()
            .name("camera".to_string())
            .spawn(move || thread.run())
            .context("starting the capture thread")?;
        self.frames = Some(rx);
        self.began = out.clock().monotonic();
        Ok(())
    }

    fn step(&mut self, out: &mut SourceOut, wait: Duration) -> anyhow::Result<Step> {
        let elapsed = out.clock().monotonic().saturating_sub(self.began);
        if self.room(out.published()) == 0 || self.duration.is_some_and(|d| elapsed >= d) {
            // The capture thread ends at its next frame or wait (a read blocked in a hung
            // driver ends with the process).
            self.stop.store(true, Ordering::SeqCst);
            self.frames = None;
            return Ok(Step::Finished);
        }
        // Frames the queue could not take, in the order they were lost.
        let lost = self.not_taken.swap(0, Ordering::SeqCst);
        self.publish_dropped(out, lost)?;
        let Some(frames) = &self.frames else {
            return Ok(Step::Finished);
        };
        // The source's wake-ups are not waited on here (the hand-over queue is), and
        // iceoryx2 keeps them as flags, not a queue: commands are read on every turn.
        match frames.recv_timeout(POLL.min(wait)) {
            Ok(captured) => self.take(out, captured)?,
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => {
                anyhow::bail!("the capture thread ended unexpectedly")
            }
        }
        Ok(Step::Again)
    }

    fn poll(&mut self) -> anyhow::Result<()> {
        self.rig.poll()
    }
}

impl Drop for CameraSource {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
    }
}
