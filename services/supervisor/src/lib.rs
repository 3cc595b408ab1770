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
pub mod detector_policy;
pub mod fallback;
pub mod monitor;
pub mod optional;
pub mod run_dir;
pub mod stage_runner;
pub mod stderr_tail;

use anyhow::{Context, bail};
use clock::{Backoff, Clock, Every, SystemClock, Timeout, Watchdog};
use linetrack_ipc::{Bus, Inlet, LocalHub, Outlet, Scope, Shutdown, Wake};
use linetrack_msgs::{
    Command, Control, MatcherMode, PoseRecord, StageKind, StatusKind, StatusReport, Topic,
    TracksHeader, now_ns,
};
use linetrack_pipeline_config::{OnRecordError, PipelineConfig};
use linetrack_run_record::{RecordError, Report, RunEnd};
use linetrack_stage_runtime::{StageContext, detector_kind, detector_on_wire};
use linetrack_vision::DetectorKind;
use monitor::Monitor;
use optional::{OptionalProcess, StopBy};
use serde::Serialize;
use stage_runner::StageRunner;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::Duration;

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

/// The supervisor's connections.
struct Ports {
    poses: Inlet<PoseRecord, TracksHeader>,
    status: Inlet<StatusReport, ()>,
    control_in: Inlet<Control, ()>,
    control: Outlet<Control, ()>,
    wake: Wake,
    /// Single-process mode with an output process: the poses, passed on to shared memory
    /// (where the output reads them).
    forward_poses: Option<Outlet<PoseRecord, TracksHeader>>,
    /// Single-process mode with an output process: its reports (on shared memory).
    output_status: Option<Inlet<StatusReport, ()>>,
}

impl Ports {
    /// The supervisor's ports: to and from the stages on `stages`, requests (`linetrack ctl`)
    /// on `requests` (shared memory in both modes).
    fn open(stages: &Bus, requests: &Bus) -> anyhow::Result<Self> {
        Ok(Self {
            poses: stages.inlet(Topic::Poses)?,
            status: stages.inlet(Topic::Status)?,
            control_in: requests.inlet(Topic::Control)?,
            control: stages.outlet(Topic::Control, 1)?,
            wake: stages.wake(StageKind::Supervisor)?,
            forward_poses: None,
            output_status: None,
        })
    }

    fn send(
        &mut self,
        stage: StageKind,
        pid: u32,
        command: Command,
        value: u32,
        frame_id: u64,
    ) -> anyhow::Result<()> {
        let c = Control::new(command, stage, pid, value, frame_id);
        self.control.publish(&(), &[&[c]])?;
        Ok(())
    }
}

/// A new run id: 8 hex digits from the clock and the process id.
pub fn new_run_id() -> String {
    format!(
        "{:08x}",
        (now_ns() ^ (u64::from(std::process::id()) << 20)) as u32
    )
}

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
    fn write(&self, run_dir: &Path) -> Result<(), RecordError> {
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
fn prepare_run_dir(
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
    let config_path = run_dir.join("pipeline.toml");
    linetrack_run_record::files::write_whole(
        &config_path,
        toml::to_string(config)?.as_bytes(),
        false,
    )?;
    Ok((config_path, earlier))
}

/// Runs the pipeline on `config` until the sequence is done or `shutdown` is set.
pub fn run(
    config: &PipelineConfig,
    options: &RunOptions,
    shutdown: &Shutdown,
) -> anyhow::Result<RunOutcome> {
    config
        .validate()
        .map_err(|e| anyhow::anyhow!("pipeline config: {e}"))?;
    // Refuse a sequence no stage could open, or a camera whose calibration or frame size
    // is wrong, before starting any stage.
    let ground_truth = if config.camera.enabled() {
        camera_check::preflight(&config.camera)?;
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
            &run_id,
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

/// The last `status.json` of a run: no stage left, how it ended. The detector is the one
/// the live status last named (a swap may have changed it).
fn final_status(
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

/// Ids of thread stages start here (above any Linux pid), so that commands and status
/// reports name each instance as they name processes.
pub const THREAD_IDS: u32 = 1 << 30;

/// How a stage instance runs: a child process, or a thread of this process.
enum Launch {
    Process(Child),
    Thread {
        handle: Option<std::thread::JoinHandle<anyhow::Result<()>>>,
        stop: Shutdown,
    },
}

impl Launch {
    /// How it ended, if it has: a description and whether it succeeded.
    fn try_wait(&mut self) -> Result<Option<(String, bool)>, std::io::Error> {
        match self {
            Launch::Process(child) => Ok(child
                .try_wait()?
                .map(|status| (status.to_string(), status.success()))),
            Launch::Thread { handle, .. } => {
                if !handle.as_ref().is_some_and(|h| h.is_finished()) {
                    return Ok(handle.is_none().then(|| ("left behind".to_string(), false)));
                }
                Ok(handle.take().map(|h| match h.join() {
                    Ok(Ok(())) => ("exit status: 0".to_string(), true),
                    Ok(Err(e)) => (format!("failed: {e:#}"), false),
                    Err(_) => ("panicked".to_string(), false),
                }))
            }
        }
    }

    /// Ends it: a process is killed; a thread is asked to stop (it cannot be killed).
    fn kill(&mut self) {
        match self {
            Launch::Process(child) => {
                let _ = child.kill();
            }
            Launch::Thread { stop, .. } => stop.request(),
        }
    }

    /// Reaps a process; a thread that has not ended is left behind.
    fn reap(&mut self) {
        match self {
            Launch::Process(child) => {
                let _ = child.wait();
            }
            Launch::Thread { handle, .. } => {
                if handle.as_ref().is_some_and(|h| h.is_finished())
                    && let Some(h) = handle.take()
                {
                    let _ = h.join();
                }
                *handle = None;
            }
        }
    }
}

/// A stage's code, as a thread runs it.
type StageRun = fn(&StageContext, &Bus, &Shutdown) -> anyhow::Result<()>;

/// The code of `stage` (the same function its process's `main` runs).
fn stage_code(stage: StageKind) -> Option<StageRun> {
    match stage {
        StageKind::FrameSource => Some(linetrack_frame_source::run),
        StageKind::LineDetector => Some(linetrack_line_detector::run),
        StageKind::Matcher => Some(linetrack_matcher::run),
        StageKind::PoseEstimator => Some(linetrack_pose_estimator::run),
        StageKind::Supervisor | StageKind::Recorder | StageKind::Ros2Bridge => None,
    }
}

/// A running stage instance.
struct StageProcess {
    stage: StageKind,
    child: Launch,
    pid: u32,
    started: Duration,
    last_seen: Duration,
    ready: bool,
    standby: bool,
    detector: Option<DetectorKind>,
    /// Expected to exit (handed over, finished, killed for hanging).
    retiring: bool,
    /// A process's last lines on stderr (none for a thread).
    stderr: Option<stderr_tail::StderrTail>,
}

struct Supervisor<'m> {
    /// Threads mode: the stages' channels (the supervisor's `bus` is on them too).
    hub: Option<LocalHub>,
    next_thread_id: u32,
    config: PipelineConfig,
    options: RunOptions,
    run_id: String,
    scope: Scope,
    run_dir: PathBuf,
    config_path: PathBuf,
    bin_dir: PathBuf,
    /// What the stage binaries are started through (`LINETRACK_STAGE_RUNNER`).
    stage_runner: StageRunner,
    bus: Bus,
    ports: Ports,
    monitor: &'m mut Monitor,
    processes: Vec<StageProcess>,
    /// Each stage's restarts.
    restarts: [Backoff; 4],
    /// How long a stage may be silent.
    watchdog: Watchdog,
    /// The optional processes the config turns on: the MCAP recorder, the ROS 2 output,
    /// the ground-station link (in that order; stopped in the reverse one).
    optional: Vec<OptionalProcess>,
    detector: DetectorKind,
    swap_to: Option<DetectorKind>,
    /// What every timer reads.
    clock: Box<dyn Clock>,
    /// The automatic LSD → faster detector swap (`[detector_fallback] enabled`).
    detector_policy: Option<detector_policy::DetectorPolicy>,
}

fn stage_slot(stage: StageKind) -> usize {
    stage.stamp_index().unwrap_or(0)
}

impl<'m> Supervisor<'m> {
    fn new(
        config: &PipelineConfig,
        options: &RunOptions,
        run_id: &str,
        scope: &Scope,
        run_dir: &Path,
        config_path: PathBuf,
        monitor: &'m mut Monitor,
    ) -> anyhow::Result<Self> {
        let bin_dir = match &options.bin_dir {
            Some(dir) => dir.clone(),
            None => match std::env::var_os("LINETRACK_BIN_DIR") {
                Some(dir) => PathBuf::from(dir),
                None => std::env::current_exe()?
                    .parent()
                    .map(Path::to_path_buf)
                    .context("locating the stage binaries")?,
            },
        };
        for stage in StageKind::PROCESSING {
            let bin = bin_dir.join(format!("linetrack-{}", stage.name()));
            if options.mode == Mode::Processes && !bin.is_file() {
                bail!(
                    "{} not found: build the stage binaries (cargo build --release --workspace) or set LINETRACK_BIN_DIR",
                    bin.display()
                );
            }
        }
        let optional = optional_processes(config, options.mode, &bin_dir, run_dir, monitor)?;
        let stage_runner = StageRunner::from_env()?;
        if !stage_runner.is_direct() {
            tracing::info!("stages start through {stage_runner}");
        }
        let scope = scope.clone();
        // Nodes of killed runs are cleaned when a node starts (or by the explicit call).
        let dead_before = scope.dead_nodes()?;
        let bus = Bus::shared_memory(&scope, &format!("supervisor-{}", std::process::id()))?;
        bus.remove_stale_resources();
        let stale = dead_before.saturating_sub(scope.dead_nodes()?);
        let hub = (options.mode == Mode::Threads).then(LocalHub::default);
        let mut ports = match &hub {
            Some(hub) => Ports::open(&hub.bus(), &bus)?,
            None => Ports::open(&bus, &bus)?,
        };
        if hub.is_some() && config.ros2.enabled {
            ports.forward_poses = Some(bus.outlet(Topic::Poses, 1)?);
            ports.output_status = Some(bus.inlet(Topic::Status)?);
        }
        if stale > 0 {
            monitor.event(
                "stale-cleanup",
                "supervisor",
                None,
                format!("removed the shared memory of {stale} dead processes of earlier runs"),
            );
        }
        Ok(Self {
            hub,
            next_thread_id: THREAD_IDS,
            config: config.clone(),
            options: options.clone(),
            run_id: run_id.to_string(),
            scope,
            run_dir: run_dir.to_path_buf(),
            config_path,
            bin_dir: bin_dir.clone(),
            stage_runner,
            bus,
            ports,
            monitor,
            processes: Vec::new(),
            restarts: [Backoff::new(&config.supervisor); 4],
            watchdog: Watchdog::new(&config.supervisor),
            optional,
            detector: config.detector,
            swap_to: None,
            clock: Box::new(SystemClock::default()),
            detector_policy: detector_policy::DetectorPolicy::new(
                &config.detector_fallback,
                config.budget.line_detector_ms,
                config.budget.end_to_end_ms,
            ),
        })
    }

    fn spawn(
        &mut self,
        stage: StageKind,
        detector: Option<DetectorKind>,
        standby: bool,
    ) -> anyhow::Result<()> {
        let restarted = self.restarts[stage_slot(stage)].count() > 0;
        let resume_pose = (restarted && stage == StageKind::PoseEstimator)
            .then(|| self.monitor.resume_pose())
            .flatten();
        let start_frame = if restarted && stage == StageKind::FrameSource {
            self.monitor.next_source_frame()
        } else {
            0
        };
        let (child, pid, stderr) = match &self.hub {
            None => self.spawn_process(stage, detector, standby, resume_pose, start_frame)?,
            Some(hub) => {
                let pid = self.next_thread_id;
                self.next_thread_id += 1;
                let mut ctx =
                    StageContext::in_process(stage, self.config.clone(), self.run_dir.clone());
                ctx.pid = pid;
                ctx.args.detector = detector;
                ctx.args.standby = standby;
                ctx.args.resume_pose = resume_pose;
                ctx.args.start_frame = usize::try_from(start_frame).unwrap_or(usize::MAX);
                let code = stage_code(stage).context("the supervisor is no stage")?;
                let stop = Shutdown::default();
                let (hub, flag) = (hub.clone(), stop.clone());
                let settings = self.config.stages.of(stage).cloned().unwrap_or_default();
                let handle = std::thread::Builder::new()
                    .name(stage.name().to_string())
                    .spawn(move || {
                        // The stage's CPUs and policy, on its own thread (and the threads
                        // it starts).
                        for refusal in linetrack_sched::apply(stage.name(), &settings)? {
                            tracing::warn!("{refusal}");
                        }
                        code(&ctx, &hub.bus(), &flag)
                    })
                    .with_context(|| format!("starting the {stage} thread"))?;
                (
                    Launch::Thread {
                        handle: Some(handle),
                        stop,
                    },
                    pid,
                    None,
                )
            }
        };
        tracing::info!(
            "started {stage} (pid {pid}{})",
            if standby { ", standby" } else { "" }
        );
        let now = self.clock.now();
        self.processes.push(StageProcess {
            stage,
            child,
            pid,
            started: now,
            last_seen: now,
            ready: false,
            standby,
            detector,
            retiring: false,
            stderr,
        });
        self.write_status();
        Ok(())
    }

    /// The command that starts `bin` as a child of this run (a stage or an output): through
    /// the stage runner, with the run's config, id, this process's pid and the run's
    /// shared-memory scope.
    fn child_command(&self, bin: &Path) -> std::process::Command {
        let mut command = self.stage_runner.command(bin);
        command
            .arg("--config")
            .arg(&self.config_path)
            .arg("--run-id")
            .arg(&self.run_id)
            .arg("--supervisor-pid")
            .arg(std::process::id().to_string())
            .env(Scope::PREFIX_VAR, &self.scope.prefix)
            .env(Scope::ROOT_VAR, &self.scope.root)
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        command
    }

    /// Starts `stage`'s binary as a child process, its stderr followed
    /// ([`stderr_tail`]).
    fn spawn_process(
        &self,
        stage: StageKind,
        detector: Option<DetectorKind>,
        standby: bool,
        resume_pose: Option<String>,
        start_frame: u64,
    ) -> anyhow::Result<(Launch, u32, Option<stderr_tail::StderrTail>)> {
        let bin = self.bin_dir.join(format!("linetrack-{}", stage.name()));
        let mut command = self.child_command(&bin);
        command.arg("--run-dir").arg(&self.run_dir);
        if let Some(kind) = detector {
            command.arg("--detector").arg(kind.name());
        }
        if standby {
            command.arg("--standby");
        }
        if let Some(pose) = resume_pose {
            command.arg("--resume-pose").arg(pose);
        }
        if start_frame > 0 {
            command.arg("--start-frame").arg(start_frame.to_string());
        }
        command.stderr(Stdio::piped());
        let mut child = command.spawn().with_context(|| {
            if self.stage_runner.is_direct() {
                format!("starting {}", bin.display())
            } else {
                format!("starting {} through {}", bin.display(), self.stage_runner)
            }
        })?;
        let pid = child.id();
        let stderr = match child.stderr.take() {
            Some(pipe) => Some(
                stderr_tail::StderrTail::follow(stage.name(), pipe)
                    .with_context(|| format!("following the stderr of {stage} (pid {pid})"))?,
            ),
            None => None,
        };
        Ok((Launch::Process(child), pid, stderr))
    }

    /// Starts the optional processes that are due (at the start, or a restart), notes
    /// their exits. Called on every turn of the loop.
    fn supervise_optional(&mut self) {
        let now = self.clock.now();
        for i in 0..self.optional.len() {
            let command = self.optional[i].wants_start(now).then(|| {
                let process = &self.optional[i];
                let mut command = self.child_command(&process.binary());
                command.args(process.args());
                command
            });
            self.optional[i].supervise(command, now, self.monitor);
        }
    }

    fn write_status(&mut self) {
        let written = LiveStatus {
            run_id: self.run_id.clone(),
            ipc_prefix: self.scope.prefix.clone(),
            ipc_root: Some(self.scope.root.clone()),
            supervisor_pid: std::process::id(),
            stages: self
                .processes
                .iter()
                .map(|p| StageEntry {
                    stage: p.stage.name().to_string(),
                    pid: p.pid,
                    ready: p.ready,
                    standby: p.standby,
                })
                .collect(),
            detector: self.detector.name().to_string(),
            frames: self.monitor.accounted(),
            state: RunEnd::Running,
            reason: None,
        }
        .write(&self.run_dir);
        if let Err(e) = written {
            self.monitor.file_failed(e);
        }
    }

    fn all_ready(&self, stages: &[StageKind]) -> bool {
        stages.iter().all(|s| {
            self.processes
                .iter()
                .any(|p| p.stage == *s && p.ready && !p.standby)
        })
    }

    /// Supervises until the run ends, then stops every stage; returns whether it was
    /// interrupted. The caller closes the records.
    fn run(mut self, shutdown: &Shutdown) -> anyhow::Result<bool> {
        let result = self.supervise(shutdown);
        self.stop_all();
        if self.config.output.trace {
            match linetrack_telemetry::merge_traces(&self.run_dir) {
                Ok(n) => tracing::info!(
                    "trace: {n} spans in {}",
                    self.run_dir.join("trace.json").display()
                ),
                Err(e) => tracing::warn!(
                    "trace not merged: {} (the span files stay in {})",
                    linetrack_run_record::full_message(&e),
                    self.run_dir.join("spans").display()
                ),
            }
        }
        result
    }

    /// The main loop; returns whether it was interrupted.
    fn supervise(&mut self, shutdown: &Shutdown) -> anyhow::Result<bool> {
        self.supervise_optional();
        for stage in [
            StageKind::LineDetector,
            StageKind::Matcher,
            StageKind::PoseEstimator,
        ] {
            let detector = (stage == StageKind::LineDetector).then_some(self.detector);
            self.spawn(stage, detector, false)?;
        }
        let startup = Duration::from_millis(self.config.supervisor.startup_timeout_ms);
        let mut waiting = Timeout::new(startup);
        waiting.expired(self.clock.now());
        let mut source_started = false;
        let mut drain = Timeout::new(Duration::from_millis(
            self.config.supervisor.drain_timeout_ms,
        ));
        let status_every = Duration::from_millis(self.config.supervisor.status_every_ms);
        let mut status_line = Every::new(status_every);
        let mut status_file = Every::new(STATUS_FILE_EVERY);
        loop {
            if shutdown.requested() {
                tracing::info!("shutdown requested");
                return Ok(true);
            }
            self.ports.wake.wait(Duration::from_millis(50))?;
            self.handle_status()?;
            self.handle_poses()?;
            self.handle_requests()?;
            self.check_processes(shutdown)?;
            self.supervise_optional();
            if !source_started {
                let now = self.clock.now();
                let mut optional_settled = true;
                for process in &mut self.optional {
                    optional_settled &= process.settled(now, self.monitor);
                }
                if optional_settled
                    && self.all_ready(&[
                        StageKind::LineDetector,
                        StageKind::Matcher,
                        StageKind::PoseEstimator,
                    ])
                {
                    self.spawn(StageKind::FrameSource, None, false)?;
                    source_started = true;
                } else if waiting.expired(now) {
                    bail!(
                        "stages not ready after {:?}: {}",
                        startup,
                        self.processes
                            .iter()
                            .filter(|p| !p.ready)
                            .map(|p| p.stage.name())
                            .collect::<Vec<_>>()
                            .join(", ")
                    );
                }
            }
            if let Some(records) = self.monitor.records_failed()
                && self.config.output.on_record_error == OnRecordError::Stop
            {
                bail!(
                    "run records: {records}: the pipeline stops (output.on_record_error = \"stop\")"
                );
            }
            if self.monitor.complete() {
                match self.monitor.records_failed() {
                    None => tracing::info!("every frame accounted for"),
                    Some(records) => tracing::warn!(
                        "every frame has an outcome, but the records end early: {records}"
                    ),
                }
                return Ok(false);
            }
            let now = self.clock.now();
            if self.monitor.source_done() && drain.expired(now) {
                tracing::warn!("drain timeout: frames still missing are recorded as missing");
                return Ok(false);
            }
            if status_file.due(now) {
                self.write_status();
            }
            if self.options.live_status && status_every > Duration::ZERO && status_line.due(now) {
                println!("{}", self.monitor.status_line());
            }
        }
    }

    fn process_mut(&mut self, pid: u32) -> Option<&mut StageProcess> {
        self.processes.iter_mut().find(|p| p.pid == pid)
    }

    fn handle_status(&mut self) -> anyhow::Result<()> {
        let mut messages = self.ports.status.receive_all()?;
        if let Some(outputs) = &mut self.ports.output_status {
            messages.extend(outputs.receive_all()?);
        }
        for message in messages {
            let Some(&report) = message.payload().first() else {
                continue;
            };
            if let Some(process) = self
                .optional
                .iter_mut()
                .find(|o| o.pid() == Some(report.pid))
            {
                if report.kind.is(StatusKind::Ready) {
                    process.set_ready();
                }
                continue;
            }
            let now = self.clock.now();
            let Some(process) = self.process_mut(report.pid) else {
                continue;
            };
            process.last_seen = now;
            let (stage, standby) = (process.stage, process.standby);
            match report.kind.get().ok() {
                Some(StatusKind::Ready) => {
                    process.ready = true;
                    if standby {
                        if let Some(old) = self.processes.iter().find(|p| {
                            p.stage == StageKind::LineDetector && !p.standby && !p.retiring
                        }) {
                            let old_pid = old.pid;
                            tracing::info!(
                                "standby detector {} ready holding frames from {}; asking {old_pid} to hand over",
                                report.pid,
                                report.frame_id
                            );
                            self.ports.send(
                                StageKind::LineDetector,
                                old_pid,
                                Command::HandOver,
                                0,
                                report.frame_id,
                            )?;
                        } else {
                            // No running detector to hand over from: take over at once.
                            self.ports.send(
                                StageKind::LineDetector,
                                report.pid,
                                Command::TakeOver,
                                0,
                                report.frame_id,
                            )?;
                            self.promote_standby(report.pid, report.frame_id);
                        }
                    } else if stage == StageKind::Matcher
                        && let Some(mode) = self.monitor.matcher_mode()
                        && mode != MatcherMode::Lbd
                    {
                        self.ports.send(
                            StageKind::Matcher,
                            report.pid,
                            Command::SetMatcherMode,
                            mode.into(),
                            0,
                        )?;
                    }
                    self.write_status();
                }
                Some(StatusKind::HandedOver) => {
                    process.retiring = true;
                    let old_kind = process.detector;
                    if let Some(new_pid) = self.processes.iter().find(|p| p.standby).map(|p| p.pid)
                    {
                        self.ports.send(
                            StageKind::LineDetector,
                            new_pid,
                            Command::TakeOver,
                            0,
                            report.frame_id,
                        )?;
                        self.promote_standby(new_pid, report.frame_id);
                        let from = old_kind.map(|k| k.name()).unwrap_or("?");
                        self.monitor.event(
                            "swap",
                            "line-detector",
                            Some(report.frame_id),
                            format!(
                                "{from} (pid {}) -> {} (pid {new_pid})",
                                report.pid,
                                self.detector.name()
                            ),
                        );
                    }
                }
                Some(StatusKind::SourceFinished) => {
                    process.retiring = true;
                    self.monitor.on_report(&report, stage, &self.config.camera);
                }
                _ => self.monitor.on_report(&report, stage, &self.config.camera),
            }
        }
        Ok(())
    }

    fn promote_standby(&mut self, pid: u32, frame_id: u64) {
        if let Some(p) = self.process_mut(pid) {
            p.standby = false;
            let kind = p.detector;
            if let Some(kind) = kind {
                self.detector = kind;
            }
        }
        self.swap_to = None;
        tracing::info!("detector {pid} takes over at frame {frame_id}");
        self.write_status();
    }

    fn handle_poses(&mut self) -> anyhow::Result<()> {
        for message in self.ports.poses.receive_all()? {
            let Some(&pose) = message.payload().first() else {
                continue;
            };
            if let Some(forward) = &mut self.ports.forward_poses
                && let Err(e) = forward.publish(message.header(), &[&[pose]])
            {
                tracing::warn!(
                    "pose of frame {} not passed to the outputs: {e}",
                    message.header().frame.frame_id
                );
            }
            if let Some(switch) = self.monitor.on_pose(message.header(), &pose) {
                self.ports.send(
                    StageKind::Matcher,
                    0,
                    Command::SetMatcherMode,
                    switch.to.into(),
                    0,
                )?;
            }
            // The detector policy waits while a swap is under way (its own or one asked for).
            if self.swap_to.is_none()
                && let Some(switch) = self
                    .detector_policy
                    .as_mut()
                    .and_then(|p| p.observe(message.header(), self.detector))
                && switch.to != self.detector
            {
                self.monitor.event(
                    switch.event,
                    "line-detector",
                    Some(message.header().frame.frame_id),
                    format!(
                        "{} -> {}: {}",
                        self.detector.name(),
                        switch.to.name(),
                        switch.reason
                    ),
                );
                self.start_swap(switch.to)?;
            }
        }
        Ok(())
    }

    fn handle_requests(&mut self) -> anyhow::Result<()> {
        for message in self.ports.control_in.receive_all()? {
            let Some(&c) = message.payload().first() else {
                continue;
            };
            if !c.is_for(StageKind::Supervisor, std::process::id())
                || !c.command.is(Command::SwapDetector)
            {
                continue;
            }
            let kind = match linetrack_msgs::decode(c.value) {
                Ok(detector) => detector_kind(detector),
                Err(unknown) => {
                    tracing::warn!("swap request refused: {unknown}");
                    continue;
                }
            };
            if self.swap_to.is_some() {
                tracing::warn!("swap to {} refused: a swap is in progress", kind.name());
            } else if kind == self.detector {
                tracing::info!("swap to {} ignored: already running", kind.name());
            } else {
                self.monitor.event(
                    "swap-requested",
                    "line-detector",
                    None,
                    format!("{} -> {}", self.detector.name(), kind.name()),
                );
                self.start_swap(kind)?;
            }
        }
        Ok(())
    }

    /// Starts a standby detector of `kind`; the running one hands over to it.
    fn start_swap(&mut self, kind: DetectorKind) -> anyhow::Result<()> {
        self.swap_to = Some(kind);
        self.spawn(StageKind::LineDetector, Some(kind), true)
    }

    fn check_processes(&mut self, shutdown: &Shutdown) -> anyhow::Result<()> {
        let now = self.clock.now();
        let mut exited = Vec::new();
        for (i, p) in self.processes.iter_mut().enumerate() {
            match p.child.try_wait() {
                Ok(Some((status, success))) => exited.push((i, status, success)),
                Ok(None) => {
                    if !p.retiring
                        && let Some(silent) = self.watchdog.overdue(p.last_seen, now, p.ready)
                    {
                        tracing::warn!(
                            "{} (pid {}) silent for {silent:?}: killing it",
                            p.stage,
                            p.pid
                        );
                        p.child.kill();
                    }
                }
                Err(e) => tracing::warn!("cannot poll {} (pid {}): {e}", p.stage, p.pid),
            }
        }
        if !exited.is_empty() {
            // What a stage said before it ended (a hand-over, the source's last frame) and
            // the poses it published are queued by now: read them before its exit is judged.
            self.handle_status()?;
            self.handle_poses()?;
        }
        for (i, status, success) in exited.into_iter().rev() {
            let mut p = self.processes.remove(i);
            p.child.reap();
            let expected = p.retiring
                || (p.stage == StageKind::FrameSource && success && self.monitor.source_done());
            if expected || shutdown.requested() {
                tracing::info!("{} (pid {}) exited: {status}", p.stage, p.pid);
                continue;
            }
            let last_words = p
                .stderr
                .as_ref()
                .map(|tail| stderr_tail::last_words(&tail.lines(STDERR_END_WAIT)))
                .unwrap_or_default();
            let restarting = self.restarts[stage_slot(p.stage)].count() > 0;
            if !p.ready && !p.standby && !restarting {
                // A stage that cannot start at all will not start on a retry either; one
                // that ran before and dies while restarting is a crash like any other.
                bail!(
                    "{} (pid {}) exited before it was ready ({status}){last_words}",
                    p.stage,
                    p.pid
                );
            }
            let silent = self.watchdog.overdue(p.last_seen, now, p.ready).is_some();
            let kind = if silent { "hang" } else { "crash" };
            self.monitor.event(
                kind,
                p.stage.name(),
                None,
                format!(
                    "pid {} {status} after {:.1} s{}{last_words}",
                    p.pid,
                    now.saturating_sub(p.started).as_secs_f64(),
                    if p.ready { "" } else { ", before it was ready" }
                ),
            );
            if p.standby {
                self.monitor.event(
                    "swap-abandoned",
                    "line-detector",
                    None,
                    "the standby detector died before taking over".to_string(),
                );
                self.swap_to = None;
                continue;
            }
            if p.stage == StageKind::PoseEstimator {
                self.monitor
                    .pose_estimator_died(format!("pid {} {kind}: {status}", p.pid));
            }
            if let Err(given_up) = self.restarts[stage_slot(p.stage)].schedule(now) {
                bail!(
                    "{} died {} times (restart limit {}): giving up; the last time {status}{last_words}",
                    p.stage,
                    given_up.deaths,
                    given_up.limit
                );
            }
            self.write_status();
        }
        for stage in StageKind::PROCESSING {
            let slot = &mut self.restarts[stage_slot(stage)];
            if let Some(count) = slot.take_due(now) {
                let limit = slot.limit();
                let detector = (stage == StageKind::LineDetector).then_some(self.detector);
                self.monitor.event(
                    "restart",
                    stage.name(),
                    None,
                    format!("restart {count} of {limit}"),
                );
                self.spawn(stage, detector, false)?;
            }
        }
        Ok(())
    }

    /// Asks every stage to exit, waits for the grace period, then kills what is left.
    fn stop_all(&mut self) {
        for stage in StageKind::PROCESSING {
            if let Err(e) = self.ports.send(stage, 0, Command::Shutdown, 0, 0) {
                tracing::warn!("shutdown command to {stage} not sent: {e}");
            }
        }
        let grace = self.clock.now().saturating_add(Duration::from_millis(
            self.config.supervisor.shutdown_grace_ms,
        ));
        while !self.processes.is_empty() {
            self.processes
                .retain_mut(|p| !matches!(p.child.try_wait(), Ok(Some(_))));
            if self.clock.now() >= grace {
                for p in &mut self.processes {
                    tracing::warn!(
                        "{} (pid {}) did not exit in time: killing it",
                        p.stage,
                        p.pid
                    );
                    p.child.kill();
                    p.child.reap();
                }
                self.processes.clear();
                break;
            }
            let _ = self.ports.wake.wait(Duration::from_millis(20));
        }
        // The optional processes last: they forward and record what the stages published
        // to the end; the recorder, started first, stops last.
        for process in self.optional.iter_mut().rev() {
            if let (StopBy::Command(stage), Some(pid)) = (process.rule().stop, process.pid())
                && let Err(e) = self.ports.send(stage, pid, Command::Shutdown, 0, 0)
            {
                tracing::warn!("shutdown command to {} not sent: {e}", process.rule().name);
            }
            process.stop(self.clock.as_ref(), self.monitor);
        }
        let cleaned = self.bus.remove_stale_resources();
        if cleaned > 0 {
            tracing::info!("removed the shared memory of {cleaned} killed stage processes");
        }
        self.write_status();
    }
}

/// How long a dead stage's last lines on stderr are awaited (its pipe ends as it exits;
/// this only bounds a stage runner that keeps the pipe open).
const STDERR_END_WAIT: Duration = Duration::from_millis(500);

/// How often `status.json` is rewritten while the run goes.
const STATUS_FILE_EVERY: Duration = Duration::from_millis(200);

/// The optional processes `config` turns on, in the order they start (the recorder, the
/// ROS 2 output, the link); a binary the config needs and that is not there is refused.
fn optional_processes(
    config: &PipelineConfig,
    mode: Mode,
    bin_dir: &Path,
    run_dir: &Path,
    monitor: &mut Monitor,
) -> anyhow::Result<Vec<OptionalProcess>> {
    let supervisor = &config.supervisor;
    let grace = Duration::from_millis(supervisor.shutdown_grace_ms);
    let in_run_dir = vec!["--run-dir".into(), run_dir.as_os_str().to_owned()];
    let mut processes = Vec::new();
    if config.record.mcap && mode == Mode::Threads {
        tracing::warn!(
            "[record] mcap = true is ignored with --single-process: the recorder subscribes over shared memory"
        );
        monitor.event(
            "recorder-off",
            "recorder",
            None,
            "no recording in single-process mode".to_string(),
        );
    } else if config.record.mcap {
        optional::require_binary(&optional::RECORDER, bin_dir, "[record] mcap = true")?;
        tracing::info!("recording into {}", config.record.file(run_dir).display());
        let settings = optional::Settings {
            bin_dir: bin_dir.to_path_buf(),
            args: in_run_dir.clone(),
            ready_timeout: Duration::from_millis(config.record.startup_timeout_ms),
            grace: Duration::from_millis(config.record.close_timeout_ms),
        };
        processes.push(OptionalProcess::new(
            optional::RECORDER,
            settings,
            supervisor,
        ));
    }
    if config.ros2.enabled {
        optional::require_binary(&optional::ROS2, bin_dir, "ros2.enabled = true")?;
        let settings = optional::Settings {
            bin_dir: bin_dir.to_path_buf(),
            args: Vec::new(),
            ready_timeout: Duration::from_millis(supervisor.startup_timeout_ms),
            grace,
        };
        processes.push(OptionalProcess::new(optional::ROS2, settings, supervisor));
    }
    if config.link.enabled && mode == Mode::Processes {
        let settings = optional::Settings {
            bin_dir: bin_dir.to_path_buf(),
            args: in_run_dir,
            ready_timeout: Duration::ZERO,
            grace,
        };
        processes.push(OptionalProcess::new(optional::LINK, settings, supervisor));
    }
    Ok(processes)
}

/// The detector's code in a [`Command::SwapDetector`]'s value (for `linetrack ctl`).
pub fn detector_wire_code(kind: DetectorKind) -> u32 {
    detector_on_wire(kind).into()
}
