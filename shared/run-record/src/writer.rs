//! [`RecordWriter`]: appends a run's frames, events and poses as they happen.

use crate::RecordError;
use crate::files::{RowFile, SpaceReserve};
use crate::rows::{
    EVENT_HEADER, EventRecord, FRAME_HEADER, FrameRecord, FrameRow, csv_line, three_decimals,
};
use std::path::Path;

pub(crate) const POSES_HEADER: &str =
    "# timestamp tx ty tz qx qy qz qw (left camera in the first frame's world)";

/// Appends a run's records as they happen: `frames.csv` (a row per frame as its outcome
/// is known, so not necessarily in frame order), `events.csv` and `poses.tum`. Every row
/// goes to the kernel whole when it is added ([`files`]), so the records of a run whose
/// supervisor is killed are complete up to that moment.
///
/// The first row that cannot be written (a full disk, ...) is an error naming the file and
/// the OS error; the writer then stops (every file ends at its last whole row, later rows
/// are not attempted) and gives up its [`SpaceReserve`], so that `summary.json` and
/// `status.json` can still say how the run ended.
pub struct RecordWriter {
    frames: RowFile,
    events: RowFile,
    poses: RowFile,
    reserve: SpaceReserve,
    stopped: bool,
}

impl RecordWriter {
    /// Holds [`SpaceReserve::BYTES`] in `run_dir`, then creates the three files there
    /// (emptying earlier ones) with their headers.
    pub fn create(run_dir: &Path) -> Result<Self, RecordError> {
        let reserve = SpaceReserve::hold(run_dir, SpaceReserve::BYTES)?;
        let line = |text: &str| format!("{text}\n").into_bytes();
        Ok(Self {
            frames: RowFile::create(run_dir.join("frames.csv"), &line(FRAME_HEADER))?,
            events: RowFile::create(run_dir.join("events.csv"), &line(EVENT_HEADER))?,
            poses: RowFile::create(run_dir.join("poses.tum"), &line(POSES_HEADER))?,
            reserve,
            stopped: false,
        })
    }

    /// Whether a row could not be written (no more are).
    pub fn stopped(&self) -> bool {
        self.stopped
    }

    /// Stops the writer as a failed row would (another file of the run folder could not be
    /// written): no more rows, the reserve given up.
    pub fn stop(&mut self) {
        self.stopped = true;
        self.reserve.release();
    }

    /// Appends `row` to one of the files unless the writer has stopped; the first failure
    /// stops it and gives up the reserve.
    fn append(
        file: &mut RowFile,
        reserve: &mut SpaceReserve,
        stopped: &mut bool,
        row: Result<Vec<u8>, csv::Error>,
    ) -> Result<(), RecordError> {
        if *stopped {
            return Ok(());
        }
        let written = match row {
            Ok(row) => file.append(&row),
            // Serialising a record into memory cannot fail; were it to, it is no disk error.
            Err(e) => Err(RecordError::Parse {
                path: file.path().to_path_buf(),
                line: 0,
                message: format!("a row could not be formed: {e}"),
            }),
        };
        if written.is_err() {
            *stopped = true;
            reserve.release();
        }
        written
    }

    /// Appends a frame's row to `frames.csv`.
    pub fn frame(&mut self, frame: &FrameRecord) -> Result<(), RecordError> {
        let row = csv_line(&FrameRow::from(frame));
        Self::append(&mut self.frames, &mut self.reserve, &mut self.stopped, row)
    }

    /// Appends an event's row to `events.csv`.
    pub fn event(&mut self, event: &EventRecord) -> Result<(), RecordError> {
        let row = csv_line(&EventRecord {
            time_s: three_decimals(event.time_s),
            ..event.clone()
        });
        Self::append(&mut self.events, &mut self.reserve, &mut self.stopped, row)
    }

    /// Appends a pose (TUM: seconds, position, quaternion x y z w) to `poses.tum`.
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
        Self::append(
            &mut self.poses,
            &mut self.reserve,
            &mut self.stopped,
            Ok(line.into_bytes()),
        )
    }

    /// The end of the run: syncs the files to the disk and gives up the reserve (the
    /// summary is written next).
    pub fn close(&mut self) -> Result<(), RecordError> {
        self.reserve.release();
        for file in [&self.frames, &self.events, &self.poses] {
            file.sync()?;
        }
        Ok(())
    }
}
