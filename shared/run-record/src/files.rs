//! How a run's files are written so that a crash or a full disk leaves them valid.
//!
//! - A record file (`RowFile`: `frames.csv`, `events.csv`, `poses.tum`) takes a whole row
//!   in one write to the kernel. A row the file system refuses in part (no space, a quota)
//!   is cut back off at once, so the file always ends at its last whole row,
//!   and the error names the file and the OS error.
//! - A small file (`summary.json`, `status.json`) is written whole or not at all
//!   ([`write_whole`]: a temporary file renamed over it, removed when the write fails).
//! - Every file is created owner-only and without following a link at its place
//!   ([`create_file`]): a link planted where a record goes is an error, not a way to write
//!   somewhere else.
//! - [`SpaceReserve`] holds some space on the run folder's file system from the start; it is
//!   given up when a record cannot be written, so that the run can still say how it ended.
//!
//! Durability: rows reach the kernel one at a time, in the order added, as the record
//! writer's thread writes them ([`crate::RecordWriter`]; a killed run keeps every row it
//! wrote); the record files are synced to the disk when the run ends, and
//! `summary.json` before it is renamed into place. A power cut may lose the rows the kernel
//! had not written back yet; a row it cuts is left out by the readers
//! ([`crate::read_frames_to_cut`]).

use crate::RecordError;
use std::fs::{File, OpenOptions};
use std::io::Write as _;
use std::os::unix::fs::{FileExt as _, OpenOptionsExt as _};
use std::path::{Path, PathBuf};

/// The permission bits of every file a run writes: its owner's only.
pub const FILE_MODE: u32 = 0o600;

/// The error of `path`.
fn io(path: &Path) -> impl Fn(std::io::Error) -> RecordError + '_ {
    move |source| RecordError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Creates (or empties) `path` for writing, owner-only, without following a link at its
/// place (`O_NOFOLLOW`: a link there fails with "too many levels of symbolic links").
pub fn create_file(path: &Path) -> std::io::Result<File> {
    OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(FILE_MODE)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(path)
}

/// Writes `bytes` to `path` whole or not at all: into `<path>.tmp` (created as by
/// [`create_file`]), synced to the disk first when `durable`, then renamed over `path`. A
/// failed write removes the temporary file and names `path` with the OS error.
pub fn write_whole(path: &Path, bytes: &[u8], durable: bool) -> Result<(), RecordError> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let written = create_file(&tmp).and_then(|mut file| {
        file.write_all(bytes)?;
        if durable {
            file.sync_data()?;
        }
        std::fs::rename(&tmp, path)
    });
    written.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        io(path)(e)
    })
}

/// A record file written a whole row at a time.
pub(crate) struct RowFile {
    path: PathBuf,
    file: File,
    /// Bytes of whole rows in the file.
    len: u64,
}

impl RowFile {
    /// Creates (or empties) `path` ([`create_file`]) and writes `header` (a whole line).
    pub(crate) fn create(path: PathBuf, header: &[u8]) -> Result<Self, RecordError> {
        let file = create_file(&path).map_err(io(&path))?;
        let mut rows = Self { path, file, len: 0 };
        rows.append(header)?;
        Ok(rows)
    }

    /// Appends `row` (one or more whole lines). Once this returns `Ok`, the row survives
    /// the process being killed; when it fails, whatever part of the row was written is
    /// cut off again and the file still ends at its last whole row.
    pub(crate) fn append(&mut self, row: &[u8]) -> Result<(), RecordError> {
        match self.file.write_all_at(row, self.len) {
            Ok(()) => {
                self.len += row.len() as u64;
                Ok(())
            }
            Err(e) => {
                // Giving blocks back needs no space: this works on a full disk.
                if let Err(cut) = self.file.set_len(self.len) {
                    tracing::error!(
                        "{}: a torn row could not be cut off ({cut}): readers leave it out",
                        self.path.display()
                    );
                }
                Err(io(&self.path)(e))
            }
        }
    }

    /// Syncs the file to the disk.
    pub(crate) fn sync(&self) -> Result<(), RecordError> {
        self.file.sync_data().map_err(io(&self.path))
    }
}

/// Space held on the run folder's file system from the start of a run (a file of zeros,
/// [`SpaceReserve::FILE`]), given up when a record cannot be written so that the end of
/// the run (`summary.json`, `status.json`, the trace) still finds room.
#[derive(Debug)]
pub struct SpaceReserve {
    path: PathBuf,
    held: bool,
}

impl SpaceReserve {
    /// The reserve's file in the run folder.
    pub const FILE: &'static str = ".space-reserve";
    /// Bytes held: room for `summary.json`, the last `status.json` and the last events
    /// several times over.
    pub const BYTES: usize = 256 * 1024;

    /// Holds `bytes` in `dir`; fails naming the file and the OS error when there is not
    /// that much space.
    pub fn hold(dir: &Path, bytes: usize) -> Result<Self, RecordError> {
        let path = dir.join(Self::FILE);
        let zeros = vec![0u8; bytes];
        let held = create_file(&path).and_then(|mut file| file.write_all(&zeros));
        if let Err(e) = held {
            let _ = std::fs::remove_file(&path);
            return Err(io(&path)(e));
        }
        Ok(Self { path, held: true })
    }

    /// Gives the space back (the file is removed); once is enough.
    pub fn release(&mut self) {
        if std::mem::take(&mut self.held)
            && let Err(e) = std::fs::remove_file(&self.path)
        {
            tracing::warn!("{}: {e}", self.path.display());
        }
    }
}

impl Drop for SpaceReserve {
    fn drop(&mut self) {
        self.release();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_test_data::Scratch;
    use std::os::unix::fs::PermissionsExt as _;

    #[test]
    fn a_link_planted_where_a_record_goes_is_refused_and_its_target_kept() {
        let scratch = Scratch::new("run-record", "planted");
        let dir = scratch.path();
        let target = dir.join("elsewhere");
        std::fs::write(&target, "theirs").unwrap_or_else(|e| panic!("{e}"));
        let planted = dir.join("frames.csv");
        std::os::unix::fs::symlink(&target, &planted).unwrap_or_else(|e| panic!("{e}"));
        let err = RowFile::create(planted.clone(), b"h\n")
            .err()
            .map(|e| crate::full_message(&e))
            .unwrap_or_default();
        assert!(
            err.contains("frames.csv") && err.contains("symbolic links"),
            "{err}"
        );
        // A dangling link creates nothing at its target either.
        let dangling = dir.join("summary.json");
        let nowhere = dir.join("nowhere");
        std::os::unix::fs::symlink(&nowhere, &dangling).unwrap_or_else(|e| panic!("{e}"));
        assert!(create_file(&dangling).is_err());
        assert!(!nowhere.exists());
        assert_eq!(
            std::fs::read_to_string(&target).ok().as_deref(),
            Some("theirs")
        );
        // What is created is the owner's only.
        write_whole(&dir.join("status.json"), b"{}", false).unwrap_or_else(|e| panic!("{e}"));
        let mode = std::fs::metadata(dir.join("status.json"))
            .map(|m| m.permissions().mode() & 0o777)
            .unwrap_or(0);
        assert_eq!(mode, FILE_MODE);
    }

    #[test]
    fn a_failed_whole_write_leaves_neither_a_torn_file_nor_its_temporary() {
        let scratch = Scratch::new("run-record", "whole");
        let dir = scratch.path();
        let path = dir.join("summary.json");
        write_whole(&path, b"{\"a\":1}", true).unwrap_or_else(|e| panic!("{e}"));
        // The temporary's place taken by a folder: the write fails, the old file stays.
        std::fs::create_dir(dir.join("summary.json.tmp")).unwrap_or_else(|e| panic!("{e}"));
        let err = write_whole(&path, b"{\"a\":2}", true)
            .err()
            .map(|e| crate::full_message(&e))
            .unwrap_or_default();
        assert!(err.contains("summary.json"), "{err}");
        assert_eq!(
            std::fs::read_to_string(&path).ok().as_deref(),
            Some("{\"a\":1}")
        );
    }

    #[test]
    fn the_reserve_is_held_and_given_back_once() {
        let scratch = Scratch::new("run-record", "reserve");
        let dir = scratch.path();
        let mut reserve = SpaceReserve::hold(dir, 4096).unwrap_or_else(|e| panic!("{e}"));
        let file = dir.join(SpaceReserve::FILE);
        assert_eq!(std::fs::metadata(&file).map(|m| m.len()).ok(), Some(4096));
        reserve.release();
        assert!(!file.exists());
        reserve.release();
        drop(reserve);
    }
}
