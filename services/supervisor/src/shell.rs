//! The supervisor's I/O around its [`Core`]: it starts stage instances (processes, or
//! threads in single-process mode), polls them and the topics, turns what it sees into
//! [`Event`]s, and carries out the core's [`Action`]s (spawning, killing, sending commands,
//! recording, writing `status.json`). Every decision is the core's.

use crate::core::{Action, Core, End, Event, Log, Progress};
use crate::launch::{Launch, THREAD_IDS};
use crate::monitor::Monitor;
use crate::optional::{self, OptionalProcess, StopBy};
use crate::pipeline::{Pipeline, ROS2_SOURCE};
use crate::stage_runner::StageRunner;
use crate::status::{LiveStatus, StageEntry};
use crate::status_writer::StatusWriter;
use crate::{Mode, RunOptions, clock, stderr_tail};
use anyhow::{Context, bail};
use clock::Clock;
use linetrack_ipc::{Bus, Inlet, LocalHub, Outlet, Scope, Shutdown, Wake};
use linetrack_msgs::{
    Command, Control, PoseRecord, StageKind, StatusKind, StatusReport, TracksHeader, topics,
};
use linetrack_pipeline_config::PipelineConfig;
use linetrack_run_record::RunEnd;
use linetrack_stage_runtime::{StageContext, detector_kind};
use linetrack_vision::DetectorKind;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

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
            poses: stages.inlet(topics::POSES)?,
            status: stages.inlet(topics::STATUS)?,
            control_in: requests.inlet(topics::CONTROL)?,
            control: stages.outlet(topics::CONTROL, 1)?,
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

/// A running stage instance: how it runs (the core knows the rest).
struct StageProcess {
    pid: u32,
    child: Launch,
    /// A process's last lines on stderr (none for a thread).
    stderr: Option<stderr_tail::StderrTail>,
}

/// The shell: the run's connections, processes and records around the core.
pub(crate) struct Supervisor<'m> {
    /// Threads mode: the stages' channels (the supervisor's `bus` is on them too).
    hub: Option<LocalHub>,
    next_thread_id: u32,
    config: PipelineConfig,
    run_id: String,
    scope: Scope,
    run_dir: PathBuf,
    config_path: PathBuf,
    bin_dir: PathBuf,
    /// What the stage binaries are started through (`LINETRACK_STAGE_RUNNER`).
    stage_runner: StageRunner,
    /// The nodes and their code.
    pipeline: Pipeline,
    bus: Bus,
    ports: Ports,
    monitor: &'m mut Monitor,
    processes: Vec<StageProcess>,
    /// The optional processes the config turns on: the MCAP recorder, the ROS 2 output,
    /// the ground-station link (in that order; stopped in the reverse one).
    optional: Vec<OptionalProcess>,
    /// Every decision.
    core: Core,
    /// What every timer reads.
    clock: Clock,
    /// Writes `status.json` off the loop.
    status: StatusWriter,
}

impl<'m> Supervisor<'m> {
    pub(crate) fn new(
        config: &PipelineConfig,
        options: &RunOptions,
        pipeline: &Pipeline,
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
        let ros2_images = config.camera.ros2_images.enabled();
        if ros2_images && options.mode == Mode::Threads {
            bail!(
                "camera.ros2_images: frames from ROS 2 topics come through the {} process: run the stages as processes (without --single-process)",
                ROS2_SOURCE.0
            );
        }
        for stage in pipeline.nodes().iter().filter(|n| n.supervised()) {
            let stage = stage.stage;
            let bin = bin_dir.join(pipeline.binary(config, stage));
            if options.mode == Mode::Processes && !bin.is_file() {
                if ros2_images && stage == StageKind::FrameSource {
                    bail!(
                        "{} not found: frames from ROS 2 topics (camera.ros2_images, --ros2-images) need it, built with --features {}",
                        bin.display(),
                        ROS2_SOURCE.1
                    );
                }
                bail!(
                    "{} not found: build the stage binaries (cargo build --release --workspace) or set LINETRACK_BIN_DIR",
                    bin.display()
                );
            }
        }
        let optional = optional::processes(config, options.mode, &bin_dir, run_dir, monitor)?;
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
            ports.forward_poses = Some(bus.outlet(topics::POSES, 1)?);
            ports.output_status = Some(bus.inlet(topics::STATUS)?);
        }
        let status = StatusWriter::start(run_dir.to_path_buf())
            .context("starting the status.json writer")?;
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
            run_id: scope.run_id.clone(),
            scope,
            run_dir: run_dir.to_path_buf(),
            config_path,
            bin_dir: bin_dir.clone(),
            stage_runner,
            pipeline: pipeline.clone(),
            bus,
            ports,
            monitor,
            processes: Vec::new(),
            optional,
            core: Core::declared(config, options.live_status, pipeline.nodes()),
            clock: Clock::System,
            status,
        })
    }

    /// Starts an instance of `stage` (a restart: `restarted`) and tells the core.
    fn spawn(
        &mut self,
        stage: StageKind,
        detector: Option<DetectorKind>,
        standby: bool,
        restarted: bool,
    ) -> anyhow::Result<Option<End>> {
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
                let code = self
                    .pipeline
                    .code(stage)
                    .with_context(|| format!("{stage} has no code to run on a thread"))?;
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
        self.processes.push(StageProcess { pid, child, stderr });
        self.feed(Event::Spawned {
            stage,
            pid,
            detector,
            standby,
        })
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
        let bin = self.bin_dir.join(self.pipeline.binary(&self.config, stage));
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
        let now = self.clock.monotonic();
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

    /// Gives the core `event` (now) and carries out what it decides; the end of the run
    /// when it decided that.
    fn feed(&mut self, event: Event) -> anyhow::Result<Option<End>> {
        let now = self.clock.monotonic();
        let actions = self.core.on(event, now);
        self.perform(actions)
    }

    /// Carries out `actions` in order; stops at [`Action::Finish`] and returns its end.
    fn perform(&mut self, actions: Vec<Action>) -> anyhow::Result<Option<End>> {
        for action in actions {
            match action {
                Action::Spawn {
                    stage,
                    detector,
                    standby,
                    restarted,
                } => {
                    if let Some(end) = self.spawn(stage, detector, standby, restarted)? {
                        return Ok(Some(end));
                    }
                }
                Action::Kill { pid } => {
                    if let Some(p) = self.processes.iter_mut().find(|p| p.pid == pid) {
                        p.child.kill();
                    }
                }
                Action::Abandon { pid } => {
                    if let Some(i) = self.processes.iter().position(|p| p.pid == pid) {
                        let mut p = self.processes.remove(i);
                        p.child.kill();
                        p.child.reap();
                    }
                }
                Action::Send {
                    stage,
                    pid,
                    command,
                    value,
                    frame_id,
                } => self.ports.send(stage, pid, command, value, frame_id)?,
                Action::Record {
                    kind,
                    stage,
                    frame_id,
                    detail,
                } => self.monitor.event(kind, stage, frame_id, detail),
                Action::Report { report, stage } => {
                    self.monitor.on_report(&report, stage, &self.config.camera)
                }
                Action::PoseEstimatorDied(cause) => self.monitor.pose_estimator_died(cause),
                Action::WriteStatus => self.write_status(),
                Action::StatusLine => {
                    println!("{}", self.monitor.status_line(self.core.matcher_mode()))
                }
                Action::Log(Log::Info(line)) => tracing::info!("{line}"),
                Action::Log(Log::Warn(line)) => tracing::warn!("{line}"),
                Action::Finish(end) => return Ok(Some(end)),
                Action::StopOutputs => self.stop_outputs(),
            }
        }
        Ok(None)
    }

    fn write_status(&mut self) {
        self.status.offer(LiveStatus {
            run_id: self.run_id.clone(),
            ipc_prefix: self.scope.prefix.clone(),
            ipc_root: Some(self.scope.root.clone()),
            supervisor_pid: std::process::id(),
            stages: self
                .core
                .instances()
                .iter()
                .map(|p| StageEntry {
                    stage: p.stage.name().to_string(),
                    pid: p.pid,
                    ready: p.ready,
                    standby: p.standby,
                })
                .collect(),
            detector: self.core.detector().name().to_string(),
            frames: self.monitor.accounted(),
            state: RunEnd::Running,
            reason: None,
        });
        self.status_failed();
    }

    /// A write of `status.json` that failed (on the writer's thread) fails the records.
    fn status_failed(&mut self) {
        if let Some(e) = self.status.take_error() {
            self.monitor.file_failed(e);
        }
    }

    /// Supervises until the run ends, then stops every stage; returns whether it was
    /// interrupted. The caller closes the records.
    pub(crate) fn run(mut self, shutdown: &Shutdown) -> anyhow::Result<bool> {
        let result = self.supervise(shutdown);
        self.stop_all();
        // The last live status on disk before the run's end replaces it.
        if let Some(e) = self.status.close() {
            self.monitor.file_failed(e);
        }
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
        let mut end = self.feed(Event::Start)?;
        while end.is_none() {
            if shutdown.requested() {
                end = self.feed(Event::Interrupt)?;
                break;
            }
            self.ports.wake.wait(Duration::from_millis(50))?;
            end = self.turn(shutdown)?;
        }
        match end {
            Some(End::Completed) | None => Ok(false),
            Some(End::Interrupted) => Ok(true),
            Some(End::Failed(reason)) => bail!("{reason}"),
        }
    }

    /// One turn of the loop: the topics, the processes, the timers.
    fn turn(&mut self, shutdown: &Shutdown) -> anyhow::Result<Option<End>> {
        if let Some(end) = self.handle_status()? {
            return Ok(Some(end));
        }
        if let Some(end) = self.handle_poses()? {
            return Ok(Some(end));
        }
        if let Some(end) = self.handle_requests()? {
            return Ok(Some(end));
        }
        if let Some(end) = self.check_processes(shutdown)? {
            return Ok(Some(end));
        }
        self.supervise_optional();
        self.status_failed();
        let now = self.clock.monotonic();
        let optional_settled = if self.core.awaiting_source() {
            let mut settled = true;
            for process in &mut self.optional {
                settled &= process.settled(now, self.monitor);
            }
            settled
        } else {
            true
        };
        let progress = Progress {
            optional_settled,
            complete: self.monitor.complete(),
            records_failed: self.monitor.records_failed(),
        };
        self.feed(Event::Tick(progress))
    }

    fn handle_status(&mut self) -> anyhow::Result<Option<End>> {
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
            if let Some(end) = self.feed(Event::Status(report))? {
                return Ok(Some(end));
            }
        }
        Ok(None)
    }

    fn handle_poses(&mut self) -> anyhow::Result<Option<End>> {
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
            let first = self.monitor.on_pose(message.header(), &pose);
            let event = Event::Pose {
                header: *message.header(),
                pose: Box::new(pose),
                first,
            };
            if let Some(end) = self.feed(event)? {
                return Ok(Some(end));
            }
        }
        Ok(None)
    }

    fn handle_requests(&mut self) -> anyhow::Result<Option<End>> {
        for message in self.ports.control_in.receive_all()? {
            let Some(&c) = message.payload().first() else {
                continue;
            };
            if !c.is_for(StageKind::Supervisor, std::process::id()) {
                continue;
            }
            let request = match c.command.get() {
                Ok(Command::SwapDetector) => {
                    linetrack_msgs::decode(c.value).map(|d| Event::SwapRequest(detector_kind(d)))
                }
                Ok(Command::SwapStage) => linetrack_msgs::decode(c.value).map(Event::SwapStage),
                _ => continue,
            };
            let event = match request {
                Ok(event) => event,
                Err(unknown) => {
                    tracing::warn!("swap request refused: {unknown}");
                    continue;
                }
            };
            if let Some(end) = self.feed(event)? {
                return Ok(Some(end));
            }
        }
        Ok(None)
    }

    /// The instances that ended since the last poll: their ids, how they ended and
    /// whether they succeeded, in the reverse order of their start.
    fn exited(&mut self) -> Vec<(u32, String, bool)> {
        let mut exited = Vec::new();
        for p in &mut self.processes {
            match p.child.try_wait() {
                Ok(Some((status, success))) => exited.push((p.pid, status, success)),
                Ok(None) => {}
                Err(e) => {
                    let stage = self
                        .core
                        .instances()
                        .iter()
                        .find(|i| i.pid == p.pid)
                        .map_or("a stage", |i| i.stage.name());
                    tracing::warn!("cannot poll {stage} (pid {}): {e}", p.pid);
                }
            }
        }
        exited.reverse();
        exited
    }

    /// Reaps instance `pid` and returns its last lines on stderr when its exit was not
    /// expected.
    fn reap(&mut self, pid: u32, success: bool) -> String {
        let Some(i) = self.processes.iter().position(|p| p.pid == pid) else {
            return String::new();
        };
        let mut p = self.processes.remove(i);
        p.child.reap();
        if self.core.expects_exit(pid, success) {
            return String::new();
        }
        p.stderr
            .as_ref()
            .map(|tail| stderr_tail::last_words(&tail.lines(STDERR_END_WAIT)))
            .unwrap_or_default()
    }

    fn check_processes(&mut self, shutdown: &Shutdown) -> anyhow::Result<Option<End>> {
        let exited = self.exited();
        if exited.is_empty() {
            return Ok(None);
        }
        // What a stage said before it ended (a hand-over, the source's last frame) and
        // the poses it published are queued by now: read them before its exit is judged.
        if let Some(end) = self.handle_status()? {
            return Ok(Some(end));
        }
        if let Some(end) = self.handle_poses()? {
            return Ok(Some(end));
        }
        if shutdown.requested() {
            // Exits during a shutdown are no crashes.
            return self.feed(Event::Interrupt);
        }
        for (pid, status, success) in exited {
            let last_words = self.reap(pid, success);
            let event = Event::Exited {
                pid,
                status,
                success,
                last_words,
            };
            if let Some(end) = self.feed(event)? {
                return Ok(Some(end));
            }
        }
        Ok(None)
    }

    /// Asks every stage to exit, waits for the grace period, kills what is left, then stops
    /// the optional processes.
    fn stop_all(&mut self) {
        let now = self.clock.monotonic();
        let actions = self.core.on(Event::Stop, now);
        self.perform_stopping(actions);
        while !self.core.stopped() {
            for (pid, status, success) in self.exited() {
                self.reap(pid, success);
                let event = Event::Exited {
                    pid,
                    status,
                    success,
                    last_words: String::new(),
                };
                let actions = self.core.on(event, self.clock.monotonic());
                self.perform_stopping(actions);
            }
            let actions = self
                .core
                .on(Event::Tick(Progress::default()), self.clock.monotonic());
            self.perform_stopping(actions);
            if !self.core.stopped() {
                let _ = self.ports.wake.wait(Duration::from_millis(20));
            }
        }
    }

    /// Carries out the stop's actions; a command that cannot be sent is a warning.
    fn perform_stopping(&mut self, actions: Vec<Action>) {
        for action in actions {
            let what = match &action {
                Action::Send { stage, .. } => format!("shutdown command to {stage}"),
                _ => "stop".to_string(),
            };
            if let Err(e) = self.perform(vec![action]) {
                tracing::warn!("{what} not sent: {e}");
            }
        }
    }

    /// The optional processes last: they forward and record what the stages published
    /// to the end; the recorder, started first, stops last.
    fn stop_outputs(&mut self) {
        for process in self.optional.iter_mut().rev() {
            if let (StopBy::Command(stage), Some(pid)) = (process.rule().stop, process.pid())
                && let Err(e) = self.ports.send(stage, pid, Command::Shutdown, 0, 0)
            {
                tracing::warn!("shutdown command to {} not sent: {e}", process.rule().name);
            }
            process.stop(&self.clock, self.monitor);
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
