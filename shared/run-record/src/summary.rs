//! `summary.json`: how a run ended, its report and its trajectory's metrics.

use crate::RecordError;
use crate::files;
use crate::report::Report;
use linetrack_trajectory::metrics;
use linetrack_trajectory::tum::{self, StampedPose};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// How a run ended (`summary.json`, and `status.json` while it runs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RunEnd {
    /// Not over yet.
    Running,
    /// Every frame has an outcome (or the drain timed out).
    Completed,
    /// Stopped by a signal before the sequence ended.
    Interrupted,
    /// Abandoned: a stage would not start, died past the restart limit, ... (see `reason`).
    Failed,
    /// A record could not be written (a full disk, ...): the records end at their last
    /// whole row; `reason` names the file and the OS error (`output.on_record_error` says
    /// whether the pipeline stopped there or ran on).
    RecordsFailed,
}

/// `summary.json`: how the run ended and its report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// How it ended.
    pub end: RunEnd,
    /// Why it failed (or other words on its end).
    pub reason: Option<String>,
    /// What the records add up to.
    #[serde(flatten)]
    pub report: Report,
    /// The trajectory (`poses.tum`) against the sequence's ground truth, when it has some:
    /// the names and definitions of `linetrack-vo`'s `metrics.json`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metrics: Option<metrics::Summary>,
}

/// The metrics of the run's trajectory (`poses`, a `poses.tum` as [`RecordWriter`] writes it)
/// against `truth` (the sequence's ground truth, stamped with the same sequence times), each
/// pose compared with the true pose of its frame ([`metrics::Summary::of_stamped`]).
/// `None` without ground truth or when no pose has one.
pub fn trajectory_metrics(
    poses: &Path,
    truth: &[StampedPose],
) -> Result<Option<metrics::Summary>, RecordError> {
    if truth.is_empty() {
        return Ok(None);
    }
    Ok(metrics::Summary::of_stamped(&tum::read(poses)?, truth))
}

impl Summary {
    /// Writes `path` whole or not at all ([`files::write_whole`], synced to the disk).
    pub fn write(&self, path: &Path) -> Result<(), RecordError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| RecordError::Io {
            path: path.to_path_buf(),
            source: e.into(),
        })?;
        files::write_whole(path, text.as_bytes(), true)
    }

    /// Reads `summary.json`.
    pub fn read(path: &Path) -> Result<Self, RecordError> {
        let text = std::fs::read_to_string(path).map_err(|source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|e| RecordError::Parse {
            path: path.to_path_buf(),
            line: e.line(),
            message: e.to_string(),
        })
    }
}
