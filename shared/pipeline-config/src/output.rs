//! `[output]`: where a run's records go and what a record that cannot be written does.

use crate::limits::not_empty_path;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Where the run's records go.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// Each run gets a new folder here named by its UTC start time
    /// (`2026-11-23T12-00-00`), and `latest` here is a symlink to the newest. Unset: the
    /// user's state folder, [`OutputConfig::runs_dir`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub runs_dir: Option<PathBuf>,
    /// A fixed run folder instead (`linetrack run --run-dir`): frames.csv, events.csv,
    /// poses (TUM), summary.json, trace files. Locked while a run writes into it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub run_dir: Option<PathBuf>,
    /// Write per-process span files and the merged Chrome/Perfetto trace.
    pub trace: bool,
    /// What a record that cannot be written (a full disk, a quota, an I/O error) does to the
    /// run: either way the records end at their last whole row, the error names the file
    /// and the OS error, and the run ends `records-failed` (non-zero exit).
    pub on_record_error: OnRecordError,
}

impl OutputConfig {
    /// The folder of dated run folders: `runs_dir` when set, else
    /// `$XDG_STATE_HOME/linetrack/runs` (an absolute `XDG_STATE_HOME`), else
    /// `$HOME/.local/state/linetrack/runs`: the user's own, never a relative path that may
    /// sit in a shared folder.
    pub fn runs_dir(&self) -> Result<PathBuf, String> {
        if let Some(dir) = &self.runs_dir {
            return Ok(dir.clone());
        }
        default_runs_dir()
    }
}

/// `$XDG_STATE_HOME/linetrack/runs`, else `$HOME/.local/state/linetrack/runs` (the XDG base
/// directory rules: a relative `XDG_STATE_HOME` is ignored).
pub fn default_runs_dir() -> Result<PathBuf, String> {
    let absolute = |var: &str| {
        std::env::var_os(var)
            .map(PathBuf::from)
            .filter(|p| p.is_absolute())
    };
    absolute("XDG_STATE_HOME")
        .or_else(|| absolute("HOME").map(|home| home.join(".local/state")))
        .map(|state| state.join("linetrack/runs"))
        .ok_or_else(|| {
            "output.runs_dir is unset and neither XDG_STATE_HOME nor HOME is an absolute path: set output.runs_dir or --run-dir".to_string()
        })
}

/// What a record that cannot be written does to the run (`output.on_record_error`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OnRecordError {
    /// The pipeline stops at once (cleanly, like Ctrl-C): a run is for its records.
    #[default]
    Stop,
    /// The pipeline runs on without records (its poses still go to the ROS 2 output and
    /// the link): a robot that needs its odometry more than its log.
    Continue,
}

impl OnRecordError {
    /// The value as the config spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Stop => "stop",
            Self::Continue => "continue",
        }
    }
}

impl Default for OutputConfig {
    fn default() -> Self {
        Self {
            runs_dir: None,
            run_dir: None,
            trace: true,
            on_record_error: OnRecordError::Stop,
        }
    }
}

impl OutputConfig {
    /// An empty `run_dir` or `runs_dir` (it would be the current folder).
    pub fn validate(&self) -> Result<(), String> {
        not_empty_path("output.run_dir", self.run_dir.as_deref())?;
        not_empty_path("output.runs_dir", self.runs_dir.as_deref())
    }
}
