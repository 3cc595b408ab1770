//! [`RecordWriter`]: appends a run's frames, events and poses as they happen, on a thread
//! of its own.

use crate::RecordError;
use crate::files::{RowFile, SpaceReserve};
use crate::rows::{
    EVENT_HEADER, EventRecord, FRAME_HEADER, FrameRecord, FrameRow, csv_line, three_decimals,
};
use std::path::Path;
use std::sync::mpsc::{Receiver, Sender};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;

pub(crate) const POSES_HEADER: &str =
    "# timestamp tx ty tz qx qy qz qw (left camera in the first frame's world)";

/// Which record file a row goes to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Record {
    Frames,
    Events,
    Poses,
}

/// Where the writer's thread puts rows: the run folder's files, or a test's sink.
pub(crate) trait Rows: Send {
    /// Appends `row` (whole lines) to `record`'s file; a failure names the file and the OS
    /// error and leaves the file at its last whole row.
    fn append(&mut self, record: Record, row: &[u8]) -> Result<(), RecordError>;
    /// Gives up the space held for the end of the run.
    fn release(&mut self);
    /// Syncs the files to the disk.
    fn sync(&mut self) -> Result<(), RecordError>;
}

/// The three record files of a run folder and the space held beside them.
struct Files {
    frames: RowFile,
    events: RowFile,
    poses: RowFile,
    reserve: SpaceReserve,
}

impl Rows for Files {
    fn append(&mut self, record: Record, row: &[u8]) -> Result<(), RecordError> {
        match record {
            Record::Frames => self.frames.append(row),
            Record::Events => self.events.append(row),
            Record::Poses => self.poses.append(row),
        }
    }

    fn release(&mut self) {
        self.reserve.release();
    }

    fn sync(&mut self) -> Result<(), RecordError> {
        for file in [&self.frames, &self.events, &self.poses] {
            file.sync()?;
        }
        Ok(())
    }
}

/// What the loop hands the writer's thread, in order.
enum Job {
    Row(Record, Vec<u8>),
    /// No more rows: give up the reserve (another file of the run folder failed).
    Stop,
    /// Answer once every job before this one is done.
    Flush(Sender<()>),
}

/// The writer's first failure, shared with its thread.
#[derive(Default)]
struct Failure {
    /// The failed write, until the loop takes it.
    error: Option<RecordError>,
    /// Its message, kept after it is taken.
    message: Option<String>,
}

fn lock(failure: &Mutex<Failure>) -> MutexGuard<'_, Failure> {
    // The thread holds the lock only to store a value; a panic there leaves it whole.
    failure.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The writer's thread: writes each row in the order handed over until the first failure
/// (then none), and at the end gives up the reserve and syncs the files.
fn write_rows(
    mut rows: Box<dyn Rows>,
    jobs: &Receiver<Job>,
    failure: &Mutex<Failure>,
) -> Result<(), RecordError> {
    let mut stopped = false;
    for job in jobs {
        match job {
            Job::Row(record, row) if !stopped => {
                if let Err(e) = rows.append(record, &row) {
                    stopped = true;
                    rows.release();
                    let mut failure = lock(failure);
                    failure.message = Some(crate::full_message(&e));
                    failure.error = Some(e);
                }
            }
            Job::Row(..) => {}
            Job::Stop => {
                stopped = true;
                rows.release();
            }
            Job::Flush(done) => {
                let _ = done.send(());
            }
        }
    }
    rows.release();
    rows.sync()
}

/// Appends a run's records as they happen: `frames.csv` (a row per frame as its outcome
/// is known, so not necessarily in frame order), `events.csv` and `poses.tum`.
///
/// The caller (the supervisor's loop) never waits for the disk: each row is formed in
/// memory and handed to a thread of the writer's own, which writes the rows in the order
/// they were added, each whole in one write to the kernel ([`crate::files`]). A writeback
/// stall or a slow disk holds that thread, not the loop (the rows wait in memory
/// meanwhile). [`RecordWriter::close`] writes the last row and joins the thread, so the
/// summary that follows is written after every row.
///
/// The first row that cannot be written (a full disk, a file size limit, ...) is an error
/// naming the file and the OS error; the writer then stops (every file ends at its last
/// whole row, later rows are not attempted) and gives up its [`SpaceReserve`], so that
/// `summary.json` and `status.json` can still say how the run ended. The loop learns of it
/// from the next row it adds, [`RecordWriter::take_error`] or [`RecordWriter::failure`].
pub struct RecordWriter {
    jobs: Option<Sender<Job>>,
    thread: Option<JoinHandle<Result<(), RecordError>>>,
    failure: Arc<Mutex<Failure>>,
    /// No more rows are handed over ([`RecordWriter::stop`], or a row not formed).
    stopped: bool,
}

impl RecordWriter {
    /// Holds [`SpaceReserve::BYTES`] in `run_dir`, then creates the three files there
    /// (emptying earlier ones) with their headers, and starts the writer's thread.
    pub fn create(run_dir: &Path) -> Result<Self, RecordError> {
        let reserve = SpaceReserve::hold(run_dir, SpaceReserve::BYTES)?;
        let line = |text: &str| format!("{text}\n").into_bytes();
        let files = Files {
            frames: RowFile::create(run_dir.join("frames.csv"), &line(FRAME_HEADER))?,
            events: RowFile::create(run_dir.join("events.csv"), &line(EVENT_HEADER))?,
            poses: RowFile::create(run_dir.join("poses.tum"), &line(POSES_HEADER))?,
            reserve,
        };
        Self::with(Box::new(files)).map_err(|source| RecordError::Io {
            path: run_dir.to_path_buf(),
            source,
        })
    }

    /// A writer handing its rows to `rows` on a thread of its own.
    pub(crate) fn with(rows: Box<dyn Rows>) -> std::io::Result<Self> {
        let (jobs, theirs) = std::sync::mpsc::channel();
        let failure = Arc::new(Mutex::new(Failure::default()));
        let shared = Arc::clone(&failure);
        let thread = std::thread::Builder::new()
            .name("record-writer".to_string())
            .spawn(move || write_rows(rows, &theirs, &shared))?;
        Ok(Self {
            jobs: Some(jobs),
            thread: Some(thread),
            failure,
            stopped: false,
        })
    }

    /// Whether no more rows are written: one could not be, or [`RecordWriter::stop`].
    pub fn stopped(&self) -> bool {
        self.stopped || lock(&self.failure).message.is_some()
    }

    /// Stops the writer as a failed row would (another file of the run folder could not be
    /// written): no more rows after those already added, the reserve given up.
    pub fn stop(&mut self) {
        if !std::mem::replace(&mut self.stopped, true) {
            self.send(Job::Stop);
        }
    }

    /// The failed write not yet taken, if one failed (once).
    pub fn take_error(&mut self) -> Option<RecordError> {
        lock(&self.failure).error.take()
    }

    /// The message of the first failed write (the file and the OS error), taken or not.
    pub fn failure(&self) -> Option<String> {
        lock(&self.failure).message.clone()
    }

    /// Waits until every row added so far is written or refused (tests, and anyone who
    /// must read the files back while the writer is open).
    pub fn flush(&self) {
        let (done, wait) = std::sync::mpsc::channel();
        if self.send(Job::Flush(done)) {
            let _ = wait.recv();
        }
    }

    /// Hands `job` over; false when the thread is gone (closed, or it panicked).
    fn send(&self, job: Job) -> bool {
        self.jobs
            .as_ref()
            .is_some_and(|jobs| jobs.send(job).is_ok())
    }

    /// Hands a row over unless the writer has stopped; returns a failure of an earlier
    /// row not yet taken.
    fn add(&mut self, record: Record, row: Result<Vec<u8>, csv::Error>) -> Result<(), RecordError> {
        if self.stopped() {
            return self.take_error().map_or(Ok(()), Err);
        }
        match row {
            Ok(row) => {
                self.send(Job::Row(record, row));
                self.take_error().map_or(Ok(()), Err)
            }
            // Serialising a record into memory cannot fail; were it to, it is no disk error.
            Err(e) => {
                self.stop();
                Err(RecordError::Parse {
                    path: Path::new(record.file()).to_path_buf(),
                    line: 0,
                    message: format!("a row could not be formed: {e}"),
                })
            }
        }
    }

    /// Adds a frame's row to `frames.csv`.
    pub fn frame(&mut self, frame: &FrameRecord) -> Result<(), RecordError> {
        let row = csv_line(&FrameRow::from(frame));
        self.add(Record::Frames, row)
    }

    /// Adds an event's row to `events.csv`.
    pub fn event(&mut self, event: &EventRecord) -> Result<(), RecordError> {
        let row = csv_line(&EventRecord {
            time_s: three_decimals(event.time_s),
            ..event.clone()
        });
        self.add(Record::Events, row)
    }

    /// Adds a pose (TUM: seconds, position, quaternion x y z w) to `poses.tum`.
    pub fn pose(
        &mut self,
        sequence_ns: u64,
        translation: [f64; 3],
        rotation_xyzw: [f64; 4],
    ) -> Result<(), RecordError> {
        let [tx, ty, tz] = translation;
        let [qx, qy, qz, qw] = rotation_xyzw;
        let line = format!(
            "{:.9} {tx:.6} {ty:.6} {tz:.6} {qx:.6} {qy:.6} {qz:.6} {qw:.6}\n",
            sequence_ns as f64 * 1e-9
        );
        self.add(Record::Poses, Ok(line.into_bytes()))
    }

    /// The end of the run: writes the rows still queued, gives up the reserve, syncs the
    /// files to the disk and joins the thread (the summary is written next). Returns a
    /// failed row not yet taken, else a failed sync. Later calls return `Ok`.
    pub fn close(&mut self) -> Result<(), RecordError> {
        self.jobs = None;
        let Some(thread) = self.thread.take() else {
            return Ok(());
        };
        let synced = thread.join().unwrap_or_else(|_| {
            tracing::error!("the run records' writer panicked: the records may end early");
            Ok(())
        });
        match self.take_error() {
            Some(e) => Err(e),
            None => synced,
        }
    }
}

impl Record {
    /// The file's name in the run folder.
    fn file(self) -> &'static str {
        match self {
            Record::Frames => "frames.csv",
            Record::Events => "events.csv",
            Record::Poses => "poses.tum",
        }
    }
}

impl Drop for RecordWriter {
    fn drop(&mut self) {
        if let Err(e) = self.close() {
            tracing::error!("run records: {}", crate::full_message(&e));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;

    /// A sink that tells the test each row it starts on and may hold it there.
    struct Held {
        started: mpsc::Sender<String>,
        /// One message lets one row through.
        release: Option<mpsc::Receiver<()>>,
        /// Rows written, in order, and the row that fails (as a full disk would).
        written: Arc<Mutex<Vec<String>>>,
        fail_at: Option<String>,
        released: Arc<Mutex<usize>>,
    }

    impl Rows for Held {
        fn append(&mut self, record: Record, row: &[u8]) -> Result<(), RecordError> {
            let text = format!("{}:{}", record.file(), String::from_utf8_lossy(row).trim());
            let _ = self.started.send(text.clone());
            if let Some(release) = &self.release {
                let _ = release.recv();
            }
            if self.fail_at.as_deref() == Some(text.as_str()) {
                return Err(RecordError::Io {
                    path: record.file().into(),
                    source: std::io::Error::from_raw_os_error(libc::ENOSPC),
                });
            }
            self.written.lock().unwrap().push(text);
            Ok(())
        }

        fn release(&mut self) {
            *self.released.lock().unwrap() += 1;
        }

        fn sync(&mut self) -> Result<(), RecordError> {
            Ok(())
        }
    }

    struct Sink {
        started: mpsc::Receiver<String>,
        release: Option<mpsc::Sender<()>>,
        written: Arc<Mutex<Vec<String>>>,
        released: Arc<Mutex<usize>>,
    }

    fn writer(held: bool, fail_at: Option<&str>) -> (RecordWriter, Sink) {
        let (started_tx, started) = mpsc::channel();
        let (release_tx, release) = mpsc::channel();
        let written = Arc::new(Mutex::new(Vec::new()));
        let released = Arc::new(Mutex::new(0));
        let rows = Held {
            started: started_tx,
            release: held.then_some(release),
            written: Arc::clone(&written),
            fail_at: fail_at.map(str::to_string),
            released: Arc::clone(&released),
        };
        let writer = RecordWriter::with(Box::new(rows)).unwrap();
        let sink = Sink {
            started,
            release: held.then_some(release_tx),
            written,
            released,
        };
        (writer, sink)
    }

    fn pose(writer: &mut RecordWriter, k: u64) -> Result<(), RecordError> {
        writer.pose(k * 1_000_000_000, [0.0; 3], [0.0, 0.0, 0.0, 1.0])
    }

    fn pose_row(k: u64) -> String {
        format!(
            "poses.tum:{k}.000000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 1.000000"
        )
    }

    /// The disk holds the first row: the loop adds a thousand more without waiting, and
    /// they are written in the order added once the disk lets go.
    #[test]
    fn adding_rows_does_not_wait_for_a_blocked_write_and_keeps_their_order() {
        let (mut writer, sink) = writer(true, None);
        pose(&mut writer, 0).unwrap();
        assert_eq!(sink.started.recv().unwrap(), pose_row(0));
        // Row 0 cannot end until released: these return regardless.
        for k in 1..1000 {
            pose(&mut writer, k).unwrap();
        }
        assert!(sink.written.lock().unwrap().is_empty(), "still held");
        let release = sink.release.unwrap();
        for _ in 0..1000 {
            release.send(()).unwrap();
        }
        writer.close().unwrap();
        let written = sink.written.lock().unwrap().clone();
        assert_eq!(written, (0..1000).map(pose_row).collect::<Vec<_>>());
        assert_eq!(
            *sink.released.lock().unwrap(),
            1,
            "the reserve given up at the end"
        );
    }

    /// A row the disk refuses stops the writer: the rows after it are not attempted, the
    /// reserve is given up, and the loop learns the file and the OS error.
    #[test]
    fn a_refused_row_stops_the_writer_and_comes_back_naming_the_file_and_the_error() {
        let (mut writer, sink) = writer(false, Some(&pose_row(2)));
        for k in 0..3 {
            pose(&mut writer, k).unwrap();
        }
        writer.flush();
        let message = writer.failure().unwrap_or_default();
        assert!(
            message.contains("poses.tum") && message.contains("No space left on device"),
            "{message}"
        );
        assert!(writer.stopped());
        // The next row added returns the error (once); later ones are not written.
        assert!(pose(&mut writer, 3).is_err());
        pose(&mut writer, 4).unwrap();
        assert!(writer.close().is_ok(), "the error was taken");
        assert_eq!(writer.failure(), Some(message), "the message is kept");
        assert_eq!(*sink.written.lock().unwrap(), [pose_row(0), pose_row(1)]);
        let attempted: Vec<String> = sink.started.try_iter().collect();
        assert_eq!(attempted, (0..3).map(pose_row).collect::<Vec<_>>());
        assert!(*sink.released.lock().unwrap() >= 1);
    }

    /// A failure nobody took before the end comes back from `close`, after every row
    /// before it was written.
    #[test]
    fn close_writes_what_is_queued_and_returns_a_failure_not_taken() {
        let (mut writer, sink) = writer(true, Some(&pose_row(5)));
        for k in 0..8 {
            pose(&mut writer, k).unwrap();
        }
        let release = sink.release.unwrap();
        for _ in 0..8 {
            release.send(()).unwrap();
        }
        let closed = writer.close().err().map(|e| crate::full_message(&e));
        assert!(
            closed
                .as_deref()
                .is_some_and(|m| m.contains("No space left on device")),
            "{closed:?}"
        );
        assert_eq!(
            *sink.written.lock().unwrap(),
            (0..5).map(pose_row).collect::<Vec<_>>()
        );
        assert!(writer.close().is_ok(), "a second close is a no-op");
    }

    /// `stop` (another file of the run folder failed): rows added before it are written,
    /// none after, and the reserve is given up.
    #[test]
    fn stop_keeps_the_rows_before_it_and_writes_none_after() {
        let (mut writer, sink) = writer(false, None);
        pose(&mut writer, 0).unwrap();
        writer.stop();
        pose(&mut writer, 1).unwrap();
        writer.flush();
        assert_eq!(*sink.released.lock().unwrap(), 1);
        writer.close().unwrap();
        assert_eq!(*sink.written.lock().unwrap(), [pose_row(0)]);
    }
}
