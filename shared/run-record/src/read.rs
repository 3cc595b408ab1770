//! Reading `frames.csv` and `events.csv` back, up to a last row a crash or a full disk cut.

use crate::RecordError;
use crate::rows::{
    EVENT_HEADER, EventRecord, FRAME_HEADER, FRAME_HEADER_WITHOUT_OFFSET,
    FRAME_HEADER_WITHOUT_REASON, FrameRecord, FrameRow,
};
use std::path::{Path, PathBuf};

/// The last row of a record file, cut (by a crash, a full disk, a power cut) and left out.
#[derive(Debug, Clone, PartialEq)]
pub struct CutRow {
    /// The file.
    pub path: PathBuf,
    /// The row's 1-based line.
    pub line: usize,
    /// What is wrong with it.
    pub message: String,
}

impl std::fmt::Display for CutRow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}:{}: the last row is cut ({}); read up to the row before it",
            self.path.display(),
            self.line,
            self.message
        )
    }
}

/// The whole rows of a record file, and its cut last row if it has one.
pub type ReadToCut<T> = (Vec<T>, Option<CutRow>);

/// How the readers take a file's last row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum LastRow {
    /// Like every other: a bad one is an error.
    Strict,
    /// A last row without its end of line, or one that does not parse, is a cut row: left
    /// out and reported ([`CutRow`]); a bad row before it is still an error.
    MayBeCut,
}

/// The rows of the CSV record file `path` whose header must be `header`, in file order
/// with their lines; errors name the file, the line and the column.
pub(crate) fn read_rows<T: serde::de::DeserializeOwned>(
    path: &Path,
    headers: &[&str],
    last: LastRow,
) -> Result<ReadToCut<(usize, T)>, RecordError> {
    let bytes = std::fs::read(path).map_err(|source| RecordError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let parse = |line: u64, message: String| RecordError::Parse {
        path: path.to_path_buf(),
        line: usize::try_from(line).unwrap_or(usize::MAX),
        message,
    };
    let line_of = |at: usize| bytes[..at].iter().filter(|&&b| b == b'\n').count() + 1;
    // A whole row ends with its end of line: bytes after the last one are a cut row.
    let mut cut = None;
    let mut body = &bytes[..];
    if !bytes.is_empty() && !bytes.ends_with(b"\n") {
        let whole = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        let message = format!("{} bytes without an end of line", bytes.len() - whole);
        if last == LastRow::Strict {
            return Err(parse(line_of(whole) as u64, message));
        }
        body = &bytes[..whole];
        cut = Some(CutRow {
            path: path.to_path_buf(),
            line: line_of(whole),
            message,
        });
    }
    let mut reader = csv::ReaderBuilder::new().from_reader(body);
    let columns = match reader.headers() {
        Ok(found) if headers.iter().any(|h| found.iter().eq(h.split(','))) => found.clone(),
        _ => return Err(parse(1, format!("expected the header {:?}", headers[0]))),
    };
    let mut rows = Vec::new();
    let mut record = csv::StringRecord::new();
    loop {
        let (line, row) = match reader.read_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {
                let line = record.position().map_or(0, csv::Position::line);
                let row = record.deserialize::<T>(Some(&columns)).map_err(|e| {
                    let message = match e.kind() {
                        csv::ErrorKind::Deserialize { err, .. } => {
                            let column = err
                                .field()
                                .and_then(|k| columns.get(usize::try_from(k).ok()?))
                                .unwrap_or("?");
                            format!("{column}: {}", err.kind())
                        }
                        _ => e.to_string(),
                    };
                    (line, message)
                });
                (line, row)
            }
            Err(e) => {
                let line = e.position().map_or(0, csv::Position::line);
                (line, Err((line, e.to_string())))
            }
        };
        match row {
            Ok(row) => rows.push((usize::try_from(line).unwrap_or(usize::MAX), row)),
            Err((line, message)) => {
                // Only the last row may be cut: nothing whole may follow it.
                let more = !matches!(reader.read_record(&mut record), Ok(false));
                if last == LastRow::Strict || more || cut.is_some() {
                    return Err(parse(line, message));
                }
                cut = Some(CutRow {
                    path: path.to_path_buf(),
                    line: usize::try_from(line).unwrap_or(usize::MAX),
                    message,
                });
                break;
            }
        }
    }
    Ok((rows, cut))
}

/// The rows of `frames.csv` as records, in frame order.
pub(crate) fn frames_of(path: &Path, last: LastRow) -> Result<ReadToCut<FrameRecord>, RecordError> {
    let (rows, mut cut) = read_rows::<FrameRow>(
        path,
        &[
            FRAME_HEADER,
            FRAME_HEADER_WITHOUT_OFFSET,
            FRAME_HEADER_WITHOUT_REASON,
        ],
        last,
    )?;
    let count = rows.len();
    let mut frames = Vec::with_capacity(count);
    for (k, (line, row)) in rows.into_iter().enumerate() {
        match row.into_record() {
            Ok(frame) => frames.push(frame),
            Err(message) if last == LastRow::MayBeCut && cut.is_none() && k + 1 == count => {
                cut = Some(CutRow {
                    path: path.to_path_buf(),
                    line,
                    message,
                });
            }
            Err(message) => {
                return Err(RecordError::Parse {
                    path: path.to_path_buf(),
                    line,
                    message,
                });
            }
        }
    }
    // Rows are appended as frames complete: a frame lost to a stage crash comes last.
    frames.sort_by_key(|f| f.frame_id);
    Ok((frames, cut))
}

/// Reads `frames.csv`, in frame order; any bad row is an error.
pub fn read_frames(path: &Path) -> Result<Vec<FrameRecord>, RecordError> {
    Ok(frames_of(path, LastRow::Strict)?.0)
}

/// Reads `frames.csv` of a run that may have been cut short (a crash, a full disk), in
/// frame order: a cut last row is left out and returned, a bad row before it is an error.
pub fn read_frames_to_cut(path: &Path) -> Result<ReadToCut<FrameRecord>, RecordError> {
    frames_of(path, LastRow::MayBeCut)
}

/// Reads `events.csv`; any bad row is an error.
pub fn read_events(path: &Path) -> Result<Vec<EventRecord>, RecordError> {
    Ok(read_events_to_cut_as(path, LastRow::Strict)?.0)
}

/// Reads `events.csv` of a run that may have been cut short (as [`read_frames_to_cut`]).
pub fn read_events_to_cut(path: &Path) -> Result<ReadToCut<EventRecord>, RecordError> {
    read_events_to_cut_as(path, LastRow::MayBeCut)
}

pub(crate) fn read_events_to_cut_as(
    path: &Path,
    last: LastRow,
) -> Result<ReadToCut<EventRecord>, RecordError> {
    let (rows, cut) = read_rows::<EventRecord>(path, &[EVENT_HEADER], last)?;
    Ok((rows.into_iter().map(|(_, event)| event).collect(), cut))
}

/// The frame ids from 0 below `expected` that `frames` (in frame order) has no row for,
/// as ranges: what a cut run did not record.
pub fn unrecorded(frames: &[FrameRecord], expected: u64) -> Vec<std::ops::Range<u64>> {
    let mut gaps = Vec::new();
    let mut next = 0u64;
    for id in frames
        .iter()
        .map(|f| f.frame_id)
        .filter(|&id| id < expected)
    {
        if id > next {
            gaps.push(next..id);
        }
        next = next.max(id + 1);
    }
    if next < expected {
        gaps.push(next..expected);
    }
    gaps
}

/// `e` and the errors under it, joined by ": " (the OS error of a [`RecordError::Io`]).
pub fn full_message(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(inner) = source {
        text.push_str(": ");
        text.push_str(&inner.to_string());
        source = inner.source();
    }
    text
}
