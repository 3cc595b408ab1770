//! The supervisor: runs the pipeline and records the run.
//!
//! In multi-process mode ([`Mode::Processes`]) it starts one process per stage
//! (`linetrack-line-detector`, `linetrack-matcher`, `linetrack-pose-estimator`, then, once
//! those report ready, `linetrack-frame-source`; found beside this program or in
//! `LINETRACK_BIN_DIR`, started through `LINETRACK_STAGE_RUNNER` when it is set, see
//! [`stage_runner`]), watches their heartbeats and exits,
//! restarts a stage that crashed or hung (with exponential backoff, up to a limit), hot-swaps
//! the detector on command, steers the matcher between LBD and ℓ1, and shuts everything
//! down on SIGINT/SIGTERM or when every frame has an outcome. In single-process mode
//! ([`Mode::Threads`]) the same stage code runs on threads over crossbeam channels, under
//! the same supervision (restarts, swaps, fallback, status, records): the baseline that
//! shows what the IPC costs. A thread stage has an id in place of a pid (from
//! [`THREAD_IDS`]); a hung thread cannot be killed, only asked to stop and left behind.
//!
//! With `[camera.ros2_images]` the frame source is `linetrack-ros2-source` (frames from
//! ROS 2 image topics, cargo feature `linetrack-ros2-bridge/ros2`), in processes only.
//!
//! With `[record] mcap = true` it first starts `linetrack-recorder` (found like the stages),
//! starts the frame source once the recorder is subscribed, records its death as an event
//! without stopping the run, and stops it last so that it closes its file.
//!
//! Records go to the run folder as the run goes ([`monitor::Monitor`]); however the run
//! ends (completed, interrupted, a stage that would not start or died past the restart
//! limit) `summary.json` says how, and `status.json` stops saying "running". When the
//! sequence has ground truth, `summary.json` also scores the run's `poses.tum` against it
//! (`metrics`: the names and definitions of `linetrack-vo`'s `metrics.json`).

mod camera_check;
pub mod clock;
pub mod core;
pub mod detector_policy;
pub mod fallback;
mod launch;
pub mod monitor;
pub mod optional;
pub mod pipeline;
pub mod run_dir;
mod shell;
pub mod stage_runner;
pub mod stamps;
mod status;
mod status_writer;
pub mod stderr_tail;

pub use launch::THREAD_IDS;
pub use pipeline::Pipeline;
pub use status::{LiveStatus, StageEntry};

use anyhow::Context;
use linetrack_ipc::{Scope, Shutdown};
use linetrack_msgs::now_ns;
use linetrack_pipeline_config::PipelineConfig;
use linetrack_run_record::{Report, RunEnd};
use linetrack_stage_runtime::detector_on_wire;
use linetrack_vision::DetectorKind;
use monitor::Monitor;
use shell::Supervisor;
use status::{final_status, prepare_run_dir};
use std::path::{Path, PathBuf};

/// How the stages run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// One process per stage, shared memory between them.
    Processes,
    /// One thread per stage in this process, channels between them.
    Threads,
}

/// How to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Processes or threads.
    pub mode: Mode,
    /// Where the stage binaries are (default: next to this program).
    pub bin_dir: Option<PathBuf>,
    /// Print the live status line.
    pub live_status: bool,
}

/// What a finished run left.
#[derive(Debug)]
pub struct RunOutcome {
    /// The run folder.
    pub run_dir: PathBuf,
    /// The run id.
    pub run_id: String,
    /// Its report.
    pub report: Report,
    /// Whether it was stopped by a signal before the sequence ended.
    pub interrupted: bool,
}

/// A new run id: 8 hex digits from the clock and the process id.
pub fn new_run_id() -> String {
    format!(
        "{:08x}",
        (now_ns() ^ (u64::from(std::process::id()) << 20)) as u32
    )
}

/// Runs the pipeline on `config` until the sequence is done or `shutdown` is set.
pub fn run(
    config: &PipelineConfig,
    options: &RunOptions,
    shutdown: &Shutdown,
) -> anyhow::Result<RunOutcome> {
    run_pipeline(config, options, &Pipeline::default(), shutdown)
}

/// [`run`] of the nodes `pipeline` declares (the shipped ones and those a test or an
/// experiment added, [`Pipeline::with_node`]).
pub fn run_pipeline(
    config: &PipelineConfig,
    options: &RunOptions,
    pipeline: &Pipeline,
    shutdown: &Shutdown,
) -> anyhow::Result<RunOutcome> {
    // Records over the file size limit fail as on a full disk instead of killing the run.
    linetrack_ipc::survive_the_file_size_limit().context("catching SIGXFSZ")?;
    config
        .validate()
        .map_err(|e| anyhow::anyhow!("pipeline config: {e}"))?;
    // Refuse a sequence no stage could open, or a camera whose calibration or frame size
    // is wrong, before starting any stage.
    let ground_truth = if config.camera.enabled() {
        camera_check::preflight(&config.camera)?;
        Vec::new()
    } else if config.camera.ros2_images.enabled() {
        // The frames, and their rig, come when the topics deliver them.
        Vec::new()
    } else if let Some(file) = config.source.replay() {
        let frames = linetrack_frame_source::check_replay(file)
            .with_context(|| format!("source.replay {}", file.display()))?;
        tracing::info!("replaying {frames} stereo frames of {}", file.display());
        Vec::new()
    } else {
        sequence_ground_truth(&config.source.sequence)?
    };
    // Each stage's CPUs and policy, tried on a passing thread: a CPU this process may not
    // use ends the run before any stage starts; a refused privilege is a warning.
    let mut refused = Vec::new();
    for (stage, settings) in config.stages.all() {
        refused.extend(linetrack_sched::probe(stage.name(), settings)?);
    }
    let run_dir = run_dir::resolve(&config.output, std::time::SystemTime::now())?;
    // Held until the run is over; released by the kernel if this process dies.
    let _lock = run_dir::lock(&run_dir)?;
    let config = &PipelineConfig {
        output: linetrack_pipeline_config::OutputConfig {
            run_dir: Some(run_dir.clone()),
            ..config.output.clone()
        },
        ..config.clone()
    };
    let (config_path, earlier) = prepare_run_dir(config, &run_dir)?;
    let run_id = new_run_id();
    let scope = Scope::new(&run_id).with_configured_root(config.ipc.root.as_deref());
    let mut monitor = Monitor::new(config, 0, &run_dir)?.with_ground_truth(ground_truth);
    if let Some(earlier) = earlier {
        tracing::warn!("{}: {earlier}", run_dir.display());
        monitor.event("earlier-run-replaced", "supervisor", None, earlier);
    }
    for refusal in refused {
        tracing::warn!("{refusal}");
        monitor.event(
            "sched-refused",
            &refusal.stage.clone(),
            None,
            refusal.to_string(),
        );
    }
    let result = match options.mode {
        Mode::Processes | Mode::Threads => Supervisor::new(
            config,
            options,
            pipeline,
            &scope,
            &run_dir,
            config_path,
            &mut monitor,
        )
        .and_then(|supervisor| supervisor.run(shutdown)),
    };
    // A run that tracked nothing did not do its job, however cleanly it ran.
    let result = match result {
        Ok(false) if monitor.tracked() == 0 => Err(anyhow::anyhow!(
            "nothing was tracked: none of the {} frames with an outcome got a tracked pose (what became of them: linetrack report {})",
            monitor.accounted(),
            run_dir.display()
        )),
        other => other,
    };
    // Whatever happened, the run's records are closed and say how it ended; records that
    // failed say so first (the pipeline may have run on: `output.on_record_error`).
    let result_reason = monitor.records_failed().map(|records| match &result {
        Err(e) if !format!("{e:#}").contains(&records) => format!("{e:#}; run records: {records}"),
        Err(e) => format!("{e:#}"),
        Ok(_) => format!("run records: {records}"),
    });
    let (end, reason) = match &result {
        _ if monitor.records_failed().is_some() => (RunEnd::RecordsFailed, result_reason),
        Ok(false) => (RunEnd::Completed, None),
        Ok(true) => (RunEnd::Interrupted, None),
        Err(e) => (RunEnd::Failed, Some(format!("{e:#}"))),
    };
    let frames = monitor.accounted();
    let report = monitor.finish(end, reason.clone());
    final_status(config, &run_id, &scope, &run_dir, frames, end, reason);
    let in_folder = |e: anyhow::Error| e.context(RunFolder(run_dir.clone()));
    let interrupted = result.map_err(in_folder)?;
    let report = report
        .with_context(|| format!("records of {}", run_dir.display()))
        .map_err(in_folder)?;
    Ok(RunOutcome {
        run_dir,
        run_id,
        report,
        interrupted,
    })
}

/// The folder of a run that failed once it had one: the context of [`run`]'s error (find it
/// with `error.downcast_ref::<RunFolder>()`), so that the caller can still report it.
#[derive(Debug, Clone)]
pub struct RunFolder(pub PathBuf);

impl std::fmt::Display for RunFolder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "run {}", self.0.display())
    }
}

/// Opens the sequence (refusing one no stage could open) and returns its ground truth.
fn sequence_ground_truth(
    path: &Path,
) -> anyhow::Result<Vec<linetrack_trajectory::tum::StampedPose>> {
    let sequence = linetrack_datasets::StereoSequence::open(path)
        .with_context(|| format!("source.sequence {}", path.display()))?;
    anyhow::ensure!(
        !sequence.frames.is_empty(),
        "source.sequence {}: no frames",
        path.display()
    );
    Ok(sequence
        .frames
        .iter()
        .filter_map(|f| {
            Some(linetrack_trajectory::tum::StampedPose {
                timestamp_s: f.timestamp_ns as f64 * 1e-9,
                pose: f.pose?,
            })
        })
        .collect())
}

/// The detector's code in a `SwapDetector` command's value (for `linetrack ctl`).
pub fn detector_wire_code(kind: DetectorKind) -> u32 {
    detector_on_wire(kind).into()
}
