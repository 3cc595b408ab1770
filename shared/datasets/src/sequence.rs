//! A stereo sequence (frames, rig, rectification) and its read-ahead stream.

use crate::{DatasetError, Rectifier};
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TrySendError, bounded, unbounded};
use linetrack_geometry::StereoRig;
use linetrack_vision::GrayImage;
use nalgebra::Isometry3;
use std::path::{Path, PathBuf};
use std::thread::JoinHandle;
use std::time::Duration;

/// One frame as listed by the dataset (nothing loaded yet).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameEntry {
    /// Position in the sequence, from 0.
    pub index: usize,
    /// Capture time, nanoseconds.
    pub timestamp_ns: u64,
    /// Left image file.
    pub left: PathBuf,
    /// Right image file.
    pub right: PathBuf,
    /// Ground-truth pose of the rectified left camera in the dataset's world, if known.
    pub pose: Option<Isometry3<f64>>,
}

/// One loaded, rectified stereo frame.
#[derive(Debug, Clone)]
pub struct StereoFrame {
    /// Position in the sequence.
    pub index: usize,
    /// Capture time, nanoseconds.
    pub timestamp_ns: u64,
    /// Rectified left image.
    pub left: GrayImage,
    /// Rectified right image.
    pub right: GrayImage,
    /// Ground-truth pose of the rectified left camera, if known.
    pub pose: Option<Isometry3<f64>>,
}

/// A frame that could not be loaded: the stream reports it and goes on.
#[derive(Debug)]
pub struct FrameError {
    /// Position in the sequence.
    pub index: usize,
    /// Capture time, nanoseconds.
    pub timestamp_ns: u64,
    /// Why.
    pub error: DatasetError,
}

impl std::fmt::Display for FrameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "frame {} (t = {} ns) skipped: {}",
            self.index, self.timestamp_ns, self.error
        )
    }
}

/// A stereo sequence from any supported dataset.
#[derive(Debug)]
pub struct StereoSequence {
    /// The sequence's folder name.
    pub name: String,
    /// The frames, in time order.
    pub frames: Vec<FrameEntry>,
    /// The rectified rig.
    pub rig: StereoRig,
    /// Nominal frame rate, Hz.
    pub rate_hz: f64,
    rectifier: Option<Rectifier>,
}

impl StereoSequence {
    pub(crate) fn new(
        name: String,
        frames: Vec<FrameEntry>,
        rig: StereoRig,
        rectifier: Option<Rectifier>,
        rate_hz: f64,
    ) -> Self {
        Self {
            name,
            frames,
            rig,
            rate_hz,
            rectifier,
        }
    }

    /// Opens `dir` as EuRoC when it holds `mav0/`, as KITTI odometry when it holds
    /// `calib.txt`, as a KITTI raw drive when it holds `image_00/` and its parent
    /// `calib_cam_to_cam.txt`.
    pub fn open(dir: &Path) -> Result<Self, DatasetError> {
        if dir.join("mav0").is_dir() {
            Self::open_euroc(dir)
        } else if dir.join("calib.txt").is_file() {
            Self::open_kitti(dir, None)
        } else if crate::kitti_raw::is_kitti_raw(dir) {
            Self::open_kitti_raw(dir)
        } else {
            Err(DatasetError::Io {
                path: dir.to_path_buf(),
                reason: std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    "not a dataset folder: expected mav0/ (EuRoC), calib.txt (KITTI odometry sequence) \
                     or image_00/ with ../calib_cam_to_cam.txt (KITTI raw drive)",
                ),
            })
        }
    }

    /// Whether images are remapped on load.
    pub fn is_rectified_on_load(&self) -> bool {
        self.rectifier.is_some()
    }

    /// Loads, checks and rectifies frame `index`.
    pub fn load_frame(&self, index: usize) -> Result<StereoFrame, FrameError> {
        let Some(entry) = self.frames.get(index) else {
            return Err(FrameError {
                index,
                timestamp_ns: 0,
                error: DatasetError::Calibration(format!(
                    "frame {index} out of range (sequence has {})",
                    self.frames.len()
                )),
            });
        };
        self.load_entry(entry).map_err(|error| FrameError {
            index,
            timestamp_ns: entry.timestamp_ns,
            error,
        })
    }

    fn load_entry(&self, entry: &FrameEntry) -> Result<StereoFrame, DatasetError> {
        let left = GrayImage::load(&entry.left)?;
        let right = GrayImage::load(&entry.right)?;
        left.ensure_same_size(&right)?;
        let (w, h) = (self.rig.width_px as i32, self.rig.height_px as i32);
        if (left.width(), left.height()) != (w, h) {
            return Err(DatasetError::Calibration(format!(
                "{} is {}×{} but the sequence's images are {w}×{h}",
                entry.left.display(),
                left.width(),
                left.height()
            )));
        }
        let (left, right) = match &self.rectifier {
            Some(r) => (r.rectify(&left, false)?, r.rectify(&right, true)?),
            None => (left, right),
        };
        Ok(StereoFrame {
            index: entry.index,
            timestamp_ns: entry.timestamp_ns,
            left,
            right,
            pose: entry.pose,
        })
    }

    /// Streams the frames from `start`, loading up to `read_ahead` ahead on a thread.
    pub fn into_stream(self, start: usize, read_ahead: usize) -> StereoStream {
        self.into_stream_with(start, read_ahead, || {})
    }

    /// [`StereoSequence::into_stream`], with `on_start` called first on the reading thread
    /// (to set its scheduling: a real-time pipeline decodes ahead at a lower priority).
    pub fn into_stream_with(
        self,
        start: usize,
        read_ahead: usize,
        on_start: impl FnOnce() + Send + 'static,
    ) -> StereoStream {
        self.stream(start, read_ahead, on_start, false)
    }

    /// [`StereoSequence::into_stream_with`], but once the frames read ahead have filled the
    /// queue, the reading thread reads each next frame only when let
    /// ([`StereoStream::let_read`]): a real-time source lets it read between frames, so
    /// that the decoding does not share the processor with a frame in flight. Its owner
    /// lets one read for each frame it takes: a stream never let stops once its queue has
    /// been full and taken.
    pub fn into_paced_stream(
        self,
        start: usize,
        read_ahead: usize,
        on_start: impl FnOnce() + Send + 'static,
    ) -> StereoStream {
        self.stream(start, read_ahead, on_start, true)
    }

    /// The stream of [`StereoSequence::into_stream_with`], paced by
    /// [`StereoStream::let_read`] when `paced`.
    fn stream(
        self,
        start: usize,
        read_ahead: usize,
        on_start: impl FnOnce() + Send + 'static,
        paced: bool,
    ) -> StereoStream {
        let (sender, receiver) = bounded(read_ahead.max(1));
        // Said once, when the reading first finds the queue full (or ends, by being dropped).
        let (primed_sender, primed) = bounded(1);
        let (reads, let_reads) = unbounded::<()>();
        let let_reads = paced.then_some(let_reads);
        let rig = self.rig;
        let total = self.frames.len();
        let worker = std::thread::Builder::new()
            .name("frame-reader".to_string())
            .spawn(move || {
                on_start();
                let mut primed = Some(primed_sender);
                for index in start..self.frames.len() {
                    // Paced, once primed: each frame waits to be let (the stream's end, when
                    // dropped, ends the reading).
                    if primed.is_none()
                        && let Some(let_reads) = &let_reads
                        && let_reads.recv().is_err()
                    {
                        break;
                    }
                    let item = match sender.try_send(self.load_frame(index)) {
                        Ok(()) => continue,
                        Err(TrySendError::Full(item)) => item,
                        // A closed receiver ends the reading.
                        Err(TrySendError::Disconnected(_)) => break,
                    };
                    if let Some(primed) = primed.take() {
                        let _ = primed.send(());
                    }
                    if sender.send(item).is_err() {
                        break;
                    }
                }
            })
            .ok();
        StereoStream {
            receiver,
            primed: Some(primed),
            reads: paced.then_some(reads),
            worker,
            rig,
            total,
            skipped: 0,
        }
    }
}

/// Makes OpenCV do its work on the thread that asks for it instead of on its thread pool,
/// for the whole process. A process that only reads frames calls it first: the pool's
/// threads run at the priority of the thread that started them, so without this the
/// rectification of the frames read ahead ([`StereoSequence::into_stream_with`]) spills onto
/// threads at the process's priority instead of the reading thread's lower one.
pub fn opencv_on_calling_threads() -> Result<(), DatasetError> {
    opencv::core::set_num_threads(1).map_err(|reason| DatasetError::OpenCv {
        context: "set_num_threads(1)",
        reason,
    })
}

/// Frames of a sequence, loaded ahead on a thread. Yields `Err` for a frame that could not
/// be loaded (counted in [`StereoStream::skipped`]) and goes on with the next.
pub struct StereoStream {
    receiver: Receiver<Result<StereoFrame, FrameError>>,
    /// Until [`StereoStream::wait_primed`] has seen it: the reading thread's word that its
    /// queue is full or the reading is over.
    primed: Option<Receiver<()>>,
    /// A paced stream's leave to read a frame more ([`StereoStream::let_read`]).
    reads: Option<Sender<()>>,
    worker: Option<JoinHandle<()>>,
    rig: StereoRig,
    total: usize,
    skipped: usize,
}

impl StereoStream {
    /// The rectified rig of the frames.
    pub fn rig(&self) -> StereoRig {
        self.rig
    }

    /// Frames in the sequence.
    pub fn len(&self) -> usize {
        self.total
    }

    /// Whether the sequence has no frames.
    pub fn is_empty(&self) -> bool {
        self.total == 0
    }

    /// Frames skipped so far.
    pub fn skipped(&self) -> usize {
        self.skipped
    }

    /// Whether the frames read ahead fill the queue (or the reading is over), waiting for
    /// that at most `wait`. A real-time source starts its schedule only then: the first
    /// frames' processing would otherwise share the processor with the reading thread's
    /// burst of decoding (on 2 cores it made the first frame the slowest of a run).
    pub fn wait_primed(&mut self, wait: Duration) -> bool {
        let Some(primed) = &self.primed else {
            return true;
        };
        match primed.recv_timeout(wait) {
            Ok(()) | Err(RecvTimeoutError::Disconnected) => {
                self.primed = None;
                true
            }
            Err(RecvTimeoutError::Timeout) => false,
        }
    }

    /// Lets the reading thread of a paced stream ([`StereoSequence::into_paced_stream`])
    /// read one frame more once its queue has been full; nothing for another stream.
    pub fn let_read(&self) {
        if let Some(reads) = &self.reads {
            // A reading thread that has ended needs no leave.
            let _ = reads.send(());
        }
    }

    /// The next frame if the reading thread has it within `wait`: a caller that must stay
    /// responsive (a pipeline stage that reports it is alive while its reader is behind)
    /// waits in slices instead of for as long as the reading takes.
    pub fn next_within(&mut self, wait: Duration) -> Next {
        match self.receiver.recv_timeout(wait) {
            Ok(item) => self.counted(Some(item)).map_or(Next::End, Next::Frame),
            Err(RecvTimeoutError::Timeout) => Next::NotYet,
            Err(RecvTimeoutError::Disconnected) => {
                self.counted(None);
                Next::End
            }
        }
    }

    /// Counts a skipped frame; joins the reading thread at the end.
    fn counted(
        &mut self,
        item: Option<Result<StereoFrame, FrameError>>,
    ) -> Option<Result<StereoFrame, FrameError>> {
        if matches!(item, Some(Err(_))) {
            self.skipped += 1;
        }
        if item.is_none()
            && let Some(worker) = self.worker.take()
        {
            let _ = worker.join();
        }
        item
    }
}

impl Drop for StereoStream {
    /// A stream dropped before its end closes its channel, so that the reading thread stops
    /// at its next frame, and waits for it: a thread left reading (through OpenCV) while the
    /// process exits can crash it in OpenCV's teardown.
    fn drop(&mut self) {
        if let Some(worker) = self.worker.take() {
            drop(std::mem::replace(
                &mut self.receiver,
                crossbeam_channel::never(),
            ));
            // (A paced reading thread may be waiting for leave instead.)
            self.reads = None;
            let _ = worker.join();
        }
    }
}

/// What [`StereoStream::next_within`] found.
#[derive(Debug)]
pub enum Next {
    /// The next frame, or the error that kept it from loading.
    Frame(Result<StereoFrame, FrameError>),
    /// The reading thread did not have it in time.
    NotYet,
    /// No more frames.
    End,
}

impl Iterator for StereoStream {
    type Item = Result<StereoFrame, FrameError>;

    fn next(&mut self) -> Option<Self::Item> {
        let item = self.receiver.recv().ok();
        self.counted(item)
    }
}
