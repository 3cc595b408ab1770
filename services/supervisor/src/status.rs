//! The run folder's `status.json` (what `linetrack ctl` and the tests read while a run goes
//! and after it), and what an earlier run left in the folder.

use anyhow::Context;
use linetrack_ipc::Scope;
use linetrack_pipeline_config::PipelineConfig;
use linetrack_run_record::{RecordError, RunEnd};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// What `status.json` in the run folder says (read by `linetrack ctl` and the tests).
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct LiveStatus {
    /// The run id.
    pub run_id: String,
    /// The shared-memory prefix.
    pub ipc_prefix: String,
    /// The folder of iceoryx2's bookkeeping (absent in runs recorded before it was kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ipc_root: Option<PathBuf>,
    /// The supervisor's pid.
    pub supervisor_pid: u32,
    /// The running stages.
    pub stages: Vec<StageEntry>,
    /// The active detector.
    pub detector: String,
    /// Frames with an outcome so far.
    pub frames: usize,
    /// `running`, or how the run ended.
    pub state: RunEnd,
    /// Why it failed, when it did.
    pub reason: Option<String>,
}

impl LiveStatus {
    /// Whether the run is over.
    pub fn finished(&self) -> bool {
        self.state != RunEnd::Running
    }

    /// Writes `status.json` in `run_dir` whole or not at all (readers never see half of it;
    /// a failed write leaves no temporary file).
    pub(crate) fn write(&self, run_dir: &Path) -> Result<(), RecordError> {
        let path = run_dir.join("status.json");
        let text = serde_json::to_string_pretty(self).map_err(|e| RecordError::Io {
            path: path.clone(),
            source: e.into(),
        })?;
        linetrack_run_record::files::write_whole(&path, text.as_bytes(), false)
    }
}

/// One running stage process.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct StageEntry {
    /// Stage name.
    pub stage: String,
    /// Process id.
    pub pid: u32,
    /// Whether it reported ready.
    pub ready: bool,
    /// A detector waiting to take over.
    pub standby: bool,
}

/// What an earlier run left in the run folder, when it left records: how it ended, or that
/// its supervisor is gone while it still said running (killed).
fn earlier_run(run_dir: &Path) -> Option<String> {
    let status: LiveStatus =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("status.json")).ok()?).ok()?;
    let ended = match status.state {
        RunEnd::Running => format!(
            "still said running, its supervisor (pid {}) gone: it was killed",
            status.supervisor_pid
        ),
        other => format!(
            "ended {}",
            serde_json::to_value(other)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default()
        ),
    };
    Some(format!(
        "the run folder held the records of run {} ({} frames; it {ended}): they are replaced",
        status.run_id, status.frames
    ))
}

/// Clears an earlier run's files from the (locked) run folder and writes the effective
/// config into it; returns the config's path and what the earlier run was, if one left
/// records (said in a warning and an event, not replaced silently).
pub(crate) fn prepare_run_dir(
    config: &PipelineConfig,
    run_dir: &Path,
) -> anyhow::Result<(PathBuf, Option<String>)> {
    let earlier = earlier_run(run_dir);
    for stale in [
        "spans",
        "trace.json",
        "frames.csv",
        "events.csv",
        "summary.json",
        "poses.tum",
        "status.json",
    ] {
        let path = run_dir.join(stale);
        // A link is removed, never followed.
        match std::fs::symlink_metadata(&path) {
            Ok(meta) if meta.is_dir() => std::fs::remove_dir_all(&path),
            Ok(_) => std::fs::remove_file(&path),
            Err(_) => Ok(()),
        }
        .with_context(|| format!("clearing {}", path.display()))?;
    }
    if config.output.trace {
        // Made once here, before any stage starts: a stage then only creates its own file
        // in it (`linetrack_telemetry::span_file`), never a folder in the run folder,
        // whose lock a stage's mkdir waited for while the disk was slow.
        linetrack_private_dir::private_dir(
            &run_dir.join("spans"),
            linetrack_private_dir::Create::Missing,
        )
        .context("the run folder's spans folder")?;
    }
    let config_path = run_dir.join("pipeline.toml");
    linetrack_run_record::files::write_whole(
        &config_path,
        toml::to_string(config)?.as_bytes(),
        false,
    )?;
    Ok((config_path, earlier))
}

/// The last `status.json` of a run: no stage left, how it ended. The detector is the one
/// the live status last named (a swap may have changed it).
pub(crate) fn final_status(
    config: &PipelineConfig,
    run_id: &str,
    scope: &Scope,
    run_dir: &Path,
    frames: usize,
    state: RunEnd,
    reason: Option<String>,
) {
    let detector = std::fs::read_to_string(run_dir.join("status.json"))
        .ok()
        .and_then(|text| serde_json::from_str::<LiveStatus>(&text).ok())
        .map_or_else(|| config.detector.name().to_string(), |s| s.detector);
    LiveStatus {
        run_id: run_id.to_string(),
        ipc_prefix: scope.prefix.clone(),
        ipc_root: Some(scope.root.clone()),
        supervisor_pid: std::process::id(),
        stages: Vec::new(),
        detector,
        frames,
        state,
        reason,
    }
    .write(run_dir)
    .unwrap_or_else(|e| {
        tracing::error!(
            "the run's end is not in status.json: {}",
            linetrack_run_record::full_message(&e)
        );
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_test_data::Scratch;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn the_run_folder_gets_an_empty_owner_only_spans_folder_when_spans_are_recorded() {
        let dir = Scratch::new("supervisor", "prepare-run-dir");
        let spans = dir.join("spans");
        std::fs::create_dir_all(&spans).unwrap_or_else(|e| panic!("{e}"));
        std::fs::write(spans.join("matcher-1.jsonl"), "{}\n").unwrap_or_else(|e| panic!("{e}"));
        let mut config = PipelineConfig::default();
        config.output.trace = true;
        prepare_run_dir(&config, &dir).unwrap_or_else(|e| panic!("{e:#}"));
        let meta = std::fs::symlink_metadata(&spans).unwrap_or_else(|e| panic!("{e}"));
        assert!(meta.is_dir());
        assert_eq!(meta.permissions().mode() & 0o777, 0o700);
        assert_eq!(std::fs::read_dir(&spans).map(|d| d.count()).ok(), Some(0));
        config.output.trace = false;
        prepare_run_dir(&config, &dir).unwrap_or_else(|e| panic!("{e:#}"));
        assert!(!spans.exists(), "no spans folder without spans");
    }
}
