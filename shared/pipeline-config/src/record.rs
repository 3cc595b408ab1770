//! `[record]`: the run's MCAP recording.

use crate::limits::{MAX_FRAMES, MAX_WAIT_MS, in_range};
use crate::source::is_empty_path;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The run's MCAP recording (`[record]`), written by the `linetrack-recorder` process the
/// supervisor starts next to the stages.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecordConfig {
    /// Record the run into an MCAP file.
    pub mcap: bool,
    /// The file; empty: `recording.mcap` in the run folder.
    #[serde(skip_serializing_if = "is_empty_path")]
    pub path: PathBuf,
    /// Record the images of every n-th frame (frame id divisible by n); 0 = no images.
    /// Only a recording of every frame's images (1) replays the run.
    pub every_nth_image: u64,
    /// How long the supervisor waits for the recorder to open its file before starting
    /// the frame source (it starts it anyway then, without a recording).
    pub startup_timeout_ms: u64,
    /// How long the recorder may take to write what it still holds and close the file
    /// when the run ends, before it is killed.
    pub close_timeout_ms: u64,
}

impl Default for RecordConfig {
    fn default() -> Self {
        Self {
            mcap: false,
            path: PathBuf::new(),
            every_nth_image: 1,
            startup_timeout_ms: 10_000,
            close_timeout_ms: 10_000,
        }
    }
}

impl RecordConfig {
    /// The file a run into `run_dir` records into.
    pub fn file(&self, run_dir: &Path) -> PathBuf {
        if self.path.as_os_str().is_empty() {
            run_dir.join("recording.mcap")
        } else {
            self.path.clone()
        }
    }
}

impl RecordConfig {
    /// The first out-of-range key of `[record]`.
    pub fn validate(&self) -> Result<(), String> {
        in_range(
            "record.every_nth_image",
            self.every_nth_image,
            0..=MAX_FRAMES as u64,
        )?;
        in_range(
            "record.startup_timeout_ms",
            self.startup_timeout_ms,
            1..=MAX_WAIT_MS,
        )?;
        in_range(
            "record.close_timeout_ms",
            self.close_timeout_ms,
            1..=MAX_WAIT_MS,
        )
    }
}
