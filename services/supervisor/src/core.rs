//! The supervisor's decisions as a state machine: [`Core::on`] takes one [`Event`] at a
//! time (a stage spawned, reported, published a pose or exited, a swap asked for, a timer
//! tick, a signal, the stop) with the time it happened and returns the [`Action`]s to take
//! (spawn, kill, send a command, record, finish). It does no I/O and reads no clock: the
//! shell around it ([`crate::shell`]) polls the processes and the topics, turns what it sees
//! into events and carries the actions out; the tests drive it with a manual clock.
//!
//! What it decides: when the frame source starts (every other stage ready, the optional
//! processes settled) or the start-up has failed; restarts with backoff up to the limit
//! ([`Backoff`]); which exits end the run (a stage that never got ready, one past its
//! limit) and which are expected (handed over, finished); hangs ([`Watchdog`]); the hot
//! swap of a node declared `hot_swap`, the detector or the matcher (a standby started,
//! the running one asked to hand over, the standby told to take over, or abandoned when it
//! dies); the automatic detector swap
//! ([`DetectorPolicy`]); the matcher's LBD/ℓ1 mode ([`FallbackController`]); when the run is complete or its drain ran
//! out; and the ordered stop (every stage asked, killed after the grace, the optional
//! processes last).
//!
//! Which nodes it starts, when, in which order, and which it restarts or may hot-swap, it
//! reads from the pipeline's declaration ([`PIPELINE`]); a test hands it another one.

use crate::clock::{Backoff, Every, Timeout, Watchdog, restart_backoff};
use crate::detector_policy::DetectorPolicy;
use crate::fallback::FallbackController;
use linetrack_msgs::pipeline::{NodeDecl, PIPELINE, Restart, Start, node_in};
use linetrack_msgs::{
    Command, MatcherMode, PoseRecord, StageKind, StatusKind, StatusReport, TracksHeader,
};
use linetrack_pipeline_config::{MatcherPolicy, OnRecordError, PipelineConfig};
use linetrack_vision::DetectorKind;
use std::time::Duration;

/// How often `status.json` is rewritten while the run goes.
const STATUS_FILE_EVERY: Duration = Duration::from_millis(200);

/// Something that happened, as the shell saw it.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The run starts: the stages before the source are due.
    Start,
    /// The shell started an instance of `stage` (asked by [`Action::Spawn`]) as `pid`.
    Spawned {
        /// The stage.
        stage: StageKind,
        /// Its process id (a thread id in single-process mode).
        pid: u32,
        /// The detector it runs (the line detector).
        detector: Option<DetectorKind>,
        /// Started as a standby (a hot swap).
        standby: bool,
    },
    /// A stage's status report (ready, a heartbeat, a hand-over, the source's end, …).
    Status(StatusReport),
    /// A frame reached the end of the pipeline: the matcher's policy takes its first
    /// outcome, the detector policy every arrival.
    Pose {
        /// Its header.
        header: TracksHeader,
        /// Its pose (boxed: it carries two covariances, the largest variant by far).
        pose: Box<PoseRecord>,
        /// Its first outcome (not a frame that reached the end twice).
        first: bool,
    },
    /// `linetrack ctl` asked for a detector swap.
    SwapRequest(DetectorKind),
    /// `linetrack ctl` asked for a fresh instance of a stage declared `hot_swap` to take over
    /// from the running one.
    SwapStage(StageKind),
    /// An instance ended.
    Exited {
        /// Its id.
        pid: u32,
        /// How it ended, in words (`exit status: 1`, `signal: 9 (SIGKILL)`).
        status: String,
        /// Whether it ended successfully.
        success: bool,
        /// Its last lines on stderr, when its exit was not expected ([`Core::expects_exit`]).
        last_words: String,
    },
    /// Time passed; what the run's records say now.
    Tick(Progress),
    /// SIGINT or SIGTERM.
    Interrupt,
    /// The run is over: stop every stage.
    Stop,
}

/// What the records say at a [`Event::Tick`] (the shell asks the monitor and the optional
/// processes).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Progress {
    /// The optional processes the source waits for are ready or given up on.
    pub optional_settled: bool,
    /// Every frame the source published has an outcome.
    pub complete: bool,
    /// The first record that could not be written.
    pub records_failed: Option<String>,
}

/// Something the shell is to do.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Start an instance of `stage` (then report [`Event::Spawned`]).
    Spawn {
        /// The stage.
        stage: StageKind,
        /// The detector it is to run.
        detector: Option<DetectorKind>,
        /// As a standby (a hot swap).
        standby: bool,
        /// A restart: the pose estimator resumes from the last poses, the source from the
        /// next frame.
        restarted: bool,
    },
    /// Kill (a thread: ask to stop) instance `pid`; its exit comes as [`Event::Exited`].
    Kill {
        /// The instance.
        pid: u32,
    },
    /// Kill instance `pid`, reap it and forget it (the stop's grace ran out).
    Abandon {
        /// The instance.
        pid: u32,
    },
    /// Send a command on the control topic.
    Send {
        /// The stage it is for.
        stage: StageKind,
        /// The instance (0: every instance of the stage).
        pid: u32,
        /// The command.
        command: Command,
        /// Its value.
        value: u32,
        /// The frame it is about.
        frame_id: u64,
    },
    /// Record an event in `events.csv`.
    Record {
        /// Its kind.
        kind: &'static str,
        /// The stage it is about.
        stage: &'static str,
        /// The frame it is about.
        frame_id: Option<u64>,
        /// What happened.
        detail: String,
    },
    /// Pass a stage's report on to the records (frames published, camera events, …).
    Report {
        /// The report.
        report: StatusReport,
        /// Its stage.
        stage: StageKind,
    },
    /// The pose estimator died: the frames it held died with it.
    PoseEstimatorDied(String),
    /// Rewrite `status.json`.
    WriteStatus,
    /// Print the live status line.
    StatusLine,
    /// Log a line.
    Log(Log),
    /// The run is over, this way (the shell then sends [`Event::Stop`]).
    Finish(End),
    /// Every stage is gone: stop the optional processes (in the reverse of their start).
    StopOutputs,
}

/// A log line.
#[derive(Debug, Clone, PartialEq)]
pub enum Log {
    /// Information.
    Info(String),
    /// A warning.
    Warn(String),
}

/// How the supervision ended.
#[derive(Debug, Clone, PartialEq)]
pub enum End {
    /// Every frame has an outcome, or the drain after the source's last frame ran out.
    Completed,
    /// SIGINT or SIGTERM.
    Interrupted,
    /// Why the run failed.
    Failed(String),
}

/// One running instance of a stage, as the core knows it.
#[derive(Debug, Clone, PartialEq)]
pub struct Instance {
    /// The stage.
    pub stage: StageKind,
    /// Its process (or thread) id.
    pub pid: u32,
    /// When it was started.
    pub started: Duration,
    /// Its last report.
    pub last_seen: Duration,
    /// It reported ready.
    pub ready: bool,
    /// A detector waiting to take over.
    pub standby: bool,
    /// The detector it runs.
    pub detector: Option<DetectorKind>,
    /// Expected to exit (handed over, finished).
    pub retiring: bool,
    /// Killed for hanging (once).
    killed: bool,
}

/// The supervisor's state.
#[derive(Debug)]
pub struct Core {
    /// The pipeline's declaration: what is started when, restarted and hot-swappable.
    nodes: &'static [NodeDecl],
    instances: Vec<Instance>,
    /// Each stage's restarts, by stage (a stage not in it has not died yet).
    restarts: Vec<(StageKind, Backoff)>,
    /// The backoff a stage's restarts start from.
    first_backoff: Backoff,
    watchdog: Watchdog,
    detector: DetectorKind,
    /// The stage whose hot swap is under way.
    swapping: Option<StageKind>,
    /// The detector a detector swap starts.
    swap_to: Option<DetectorKind>,
    detector_policy: Option<DetectorPolicy>,
    /// The matcher's LBD/ℓ1 policy (`matcher.mode = "auto"`).
    matcher: Option<FallbackController>,
    startup: Duration,
    waiting: Timeout,
    source_started: bool,
    source_done: bool,
    drain: Timeout,
    stop_on_record_error: bool,
    status_file: Every,
    status_line: Option<Every>,
    grace: Duration,
    /// Stopping: the time the grace runs out, and whether the outputs were told to stop.
    stopping: Option<(Duration, bool)>,
}

impl Core {
    /// The core of a run of `config` of [`PIPELINE`]; `live_status`: print the status line.
    pub fn new(config: &PipelineConfig, live_status: bool) -> Self {
        Self::declared(config, live_status, PIPELINE)
    }

    /// The core of a run of `config` of the pipeline `nodes` declares.
    pub fn declared(
        config: &PipelineConfig,
        live_status: bool,
        nodes: &'static [NodeDecl],
    ) -> Self {
        let supervisor = &config.supervisor;
        let status_every = Duration::from_millis(supervisor.status_every_ms);
        Self {
            nodes,
            instances: Vec::new(),
            restarts: Vec::new(),
            first_backoff: restart_backoff(supervisor),
            watchdog: Watchdog::new(supervisor),
            detector: config.detector,
            swapping: None,
            swap_to: None,
            detector_policy: DetectorPolicy::new(
                &config.detector_fallback,
                config.budget.line_detector_ms,
                config.budget.end_to_end_ms,
            ),
            matcher: (config.matcher.mode == MatcherPolicy::Auto).then(|| {
                FallbackController::new(
                    config.matcher.fallback.clone(),
                    config.budget.matcher_ms,
                    config.budget.end_to_end_ms,
                )
            }),
            startup: Duration::from_millis(supervisor.startup_timeout_ms),
            waiting: Timeout::new(Duration::from_millis(supervisor.startup_timeout_ms)),
            source_started: false,
            source_done: false,
            drain: Timeout::new(Duration::from_millis(supervisor.drain_timeout_ms)),
            stop_on_record_error: config.output.on_record_error == OnRecordError::Stop,
            status_file: Every::new(STATUS_FILE_EVERY),
            status_line: (live_status && status_every > Duration::ZERO)
                .then(|| Every::new(status_every)),
            grace: Duration::from_millis(supervisor.shutdown_grace_ms),
            stopping: None,
        }
    }

    /// The running instances.
    pub fn instances(&self) -> &[Instance] {
        &self.instances
    }

    /// The running (or, during a swap, the last promoted) detector.
    pub fn detector(&self) -> DetectorKind {
        self.detector
    }

    /// The mode the matcher's policy chose (`matcher.mode = "auto"`).
    pub fn matcher_mode(&self) -> Option<MatcherMode> {
        self.matcher.as_ref().map(|m| m.mode())
    }

    /// Whether the frame source is still waiting to be started (the shell then asks the
    /// optional processes whether they settled).
    pub fn awaiting_source(&self) -> bool {
        !self.source_started
    }

    /// Whether the stop is over: every stage gone, the outputs told to stop.
    pub fn stopped(&self) -> bool {
        self.stopping.is_some_and(|(_, outputs)| outputs)
    }

    /// Whether instance `pid` ending now (successfully or not) is expected: it was retiring,
    /// it is the finished source, or the run is stopping. An unexpected exit is judged
    /// (the shell then reads its last words).
    pub fn expects_exit(&self, pid: u32, success: bool) -> bool {
        self.stopping.is_some()
            || self
                .instances
                .iter()
                .find(|i| i.pid == pid)
                .is_none_or(|i| {
                    i.retiring || (i.stage == StageKind::FrameSource && success && self.source_done)
                })
    }

    /// Takes `event`, which happened at `now`; returns what to do, in order.
    pub fn on(&mut self, event: Event, now: Duration) -> Vec<Action> {
        let mut actions = Vec::new();
        match event {
            Event::Start => {
                for stage in self.started(Start::WithStages) {
                    actions.push(self.spawn(stage, false));
                }
                self.waiting.expired(now);
            }
            Event::Spawned {
                stage,
                pid,
                detector,
                standby,
            } => {
                self.instances.push(Instance {
                    stage,
                    pid,
                    started: now,
                    last_seen: now,
                    ready: false,
                    standby,
                    detector,
                    retiring: false,
                    killed: false,
                });
                actions.push(Action::WriteStatus);
            }
            Event::Status(report) => self.on_status(report, now, &mut actions),
            Event::Pose {
                header,
                pose,
                first,
            } => self.on_pose(&header, &pose, first, &mut actions),
            Event::SwapRequest(kind) => self.on_swap_request(kind, &mut actions),
            Event::SwapStage(stage) => self.on_swap_stage(stage, &mut actions),
            Event::Exited {
                pid,
                status,
                success,
                last_words,
            } => self.on_exit(pid, &status, success, &last_words, now, &mut actions),
            Event::Tick(progress) => self.on_tick(&progress, now, &mut actions),
            Event::Interrupt => {
                actions.push(Action::Log(Log::Info("shutdown requested".to_string())));
                actions.push(Action::Finish(End::Interrupted));
            }
            Event::Stop => self.on_stop(now, &mut actions),
        }
        actions
    }

    /// A spawn of `stage` (the line detector with the running detector, or `standby`'s).
    fn spawn(&self, stage: StageKind, standby: bool) -> Action {
        let detector = match (stage, standby, self.swap_to) {
            (StageKind::LineDetector, true, Some(kind)) => Some(kind),
            (StageKind::LineDetector, _, _) => Some(self.detector),
            _ => None,
        };
        Action::Spawn {
            stage,
            detector,
            standby,
            restarted: self.restarts_of(stage) > 0,
        }
    }

    fn on_status(&mut self, report: StatusReport, now: Duration, actions: &mut Vec<Action>) {
        let Some(i) = self.instances.iter().position(|p| p.pid == report.pid) else {
            return;
        };
        let process = &mut self.instances[i];
        process.last_seen = now;
        let (stage, standby) = (process.stage, process.standby);
        match report.kind.get().ok() {
            Some(StatusKind::Ready) => {
                process.ready = true;
                if standby {
                    self.on_standby_ready(stage, &report, actions);
                }
                // A matcher, standby or not, runs the mode the policy chose.
                if stage == StageKind::Matcher
                    && let Some(mode) = self.matcher_mode()
                    && mode != MatcherMode::Lbd
                {
                    actions.push(Action::Send {
                        stage: StageKind::Matcher,
                        pid: report.pid,
                        command: Command::SetMatcherMode,
                        value: mode.into(),
                        frame_id: 0,
                    });
                }
                actions.push(Action::WriteStatus);
            }
            Some(StatusKind::HandedOver) => {
                process.retiring = true;
                let old_kind = process.detector;
                self.on_handed_over(stage, old_kind, &report, actions);
            }
            Some(StatusKind::SourceFinished) => {
                process.retiring = true;
                self.source_done = true;
                actions.push(Action::Report { report, stage });
            }
            _ => actions.push(Action::Report { report, stage }),
        }
    }

    fn on_pose(
        &mut self,
        header: &TracksHeader,
        pose: &PoseRecord,
        first: bool,
        actions: &mut Vec<Action>,
    ) {
        if first
            && let Some(switch) = self
                .matcher
                .as_mut()
                .and_then(|m| m.observe_outcome(header, pose))
        {
            let (kind, detail) = switch.event();
            actions.push(Action::Record {
                kind,
                stage: "matcher",
                frame_id: Some(header.frame.frame_id),
                detail,
            });
            actions.push(Action::Send {
                stage: StageKind::Matcher,
                pid: 0,
                command: Command::SetMatcherMode,
                value: switch.to.into(),
                frame_id: 0,
            });
        }
        // The detector policy waits while a swap is under way (its own or one asked for).
        if self.swapping.is_none()
            && let Some(switch) = self
                .detector_policy
                .as_mut()
                .and_then(|p| p.observe(header, self.detector))
            && switch.to != self.detector
        {
            actions.push(Action::Record {
                kind: switch.event,
                stage: "line-detector",
                frame_id: Some(header.frame.frame_id),
                detail: format!(
                    "{} -> {}: {}",
                    self.detector.name(),
                    switch.to.name(),
                    switch.reason
                ),
            });
            self.start_swap(switch.to, actions);
        }
    }

    fn on_exit(
        &mut self,
        pid: u32,
        status: &str,
        success: bool,
        last_words: &str,
        now: Duration,
        actions: &mut Vec<Action>,
    ) {
        let expected = self.expects_exit(pid, success);
        let Some(i) = self.instances.iter().position(|p| p.pid == pid) else {
            return;
        };
        let p = self.instances.remove(i);
        if expected {
            actions.push(Action::Log(Log::Info(format!(
                "{} (pid {}) exited: {status}",
                p.stage, p.pid
            ))));
            if self.stopping.is_some() {
                self.outputs_when_stopped(actions);
            }
            return;
        }
        let restarting = self.restarts_of(p.stage) > 0;
        if !p.ready && !p.standby && !restarting {
            // A stage that cannot start at all will not start on a retry either; one
            // that ran before and dies while restarting is a crash like any other.
            actions.push(Action::Finish(End::Failed(format!(
                "{} (pid {}) exited before it was ready ({status}){last_words}",
                p.stage, p.pid
            ))));
            return;
        }
        let silent = self.watchdog.overdue(p.last_seen, now, p.ready).is_some();
        let kind = if silent { "hang" } else { "crash" };
        actions.push(Action::Record {
            kind,
            stage: p.stage.name(),
            frame_id: None,
            detail: format!(
                "pid {} {status} after {:.1} s{}{last_words}",
                p.pid,
                now.saturating_sub(p.started).as_secs_f64(),
                if p.ready { "" } else { ", before it was ready" }
            ),
        });
        if p.standby {
            actions.push(Action::Record {
                kind: "swap-abandoned",
                stage: p.stage.name(),
                frame_id: None,
                detail: format!("the standby {} died before taking over", p.stage),
            });
            self.swapping = None;
            self.swap_to = None;
            return;
        }
        if p.stage == StageKind::PoseEstimator {
            actions.push(Action::PoseEstimatorDied(format!(
                "pid {} {kind}: {status}",
                p.pid
            )));
        }
        if !self.restartable(p.stage) {
            actions.push(Action::Finish(End::Failed(format!(
                "{} (pid {}) died and is not declared restartable: {status}{last_words}",
                p.stage, p.pid
            ))));
            return;
        }
        if let Err(given_up) = self.backoff_of(p.stage).schedule(now) {
            actions.push(Action::Finish(End::Failed(format!(
                "{} died {} times (restart limit {}): giving up; the last time {status}{last_words}",
                p.stage, given_up.deaths, given_up.limit
            ))));
            return;
        }
        actions.push(Action::WriteStatus);
    }

    fn on_tick(&mut self, progress: &Progress, now: Duration, actions: &mut Vec<Action>) {
        if let Some((grace_until, _)) = self.stopping {
            if now >= grace_until {
                for p in self.instances.drain(..) {
                    actions.push(Action::Log(Log::Warn(format!(
                        "{} (pid {}) did not exit in time: killing it",
                        p.stage, p.pid
                    ))));
                    actions.push(Action::Abandon { pid: p.pid });
                }
            }
            self.outputs_when_stopped(actions);
            return;
        }
        for p in &mut self.instances {
            if !p.retiring
                && !p.killed
                && let Some(silent) = self.watchdog.overdue(p.last_seen, now, p.ready)
            {
                actions.push(Action::Log(Log::Warn(format!(
                    "{} (pid {}) silent for {silent:?}: killing it",
                    p.stage, p.pid
                ))));
                actions.push(Action::Kill { pid: p.pid });
                p.killed = true;
            }
        }
        for i in 0..self.restarts.len() {
            let (stage, backoff) = &mut self.restarts[i];
            let stage = *stage;
            if let Some(count) = backoff.take_due(now) {
                let limit = backoff.limit();
                actions.push(Action::Record {
                    kind: "restart",
                    stage: stage.name(),
                    frame_id: None,
                    detail: format!("restart {count} of {limit}"),
                });
                actions.push(self.spawn(stage, false));
            }
        }
        if !self.source_started {
            if progress.optional_settled && self.all_ready(&self.started(Start::WithStages)) {
                for stage in self.started(Start::AfterStages) {
                    actions.push(self.spawn(stage, false));
                }
                self.source_started = true;
            } else if self.waiting.expired(now) {
                let not_ready: Vec<&str> = self
                    .instances
                    .iter()
                    .filter(|p| !p.ready)
                    .map(|p| p.stage.name())
                    .collect();
                actions.push(Action::Finish(End::Failed(format!(
                    "stages not ready after {:?}: {}",
                    self.startup,
                    not_ready.join(", ")
                ))));
                return;
            }
        }
        if let Some(records) = &progress.records_failed
            && self.stop_on_record_error
        {
            actions.push(Action::Finish(End::Failed(format!(
                "run records: {records}: the pipeline stops (output.on_record_error = \"stop\")"
            ))));
            return;
        }
        if progress.complete {
            actions.push(Action::Log(match &progress.records_failed {
                None => Log::Info("every frame accounted for".to_string()),
                Some(records) => Log::Warn(format!(
                    "every frame has an outcome, but the records end early: {records}"
                )),
            }));
            actions.push(Action::Finish(End::Completed));
            return;
        }
        if self.source_done && self.drain.expired(now) {
            actions.push(Action::Log(Log::Warn(
                "drain timeout: frames still missing are recorded as missing".to_string(),
            )));
            actions.push(Action::Finish(End::Completed));
            return;
        }
        if self.status_file.due(now) {
            actions.push(Action::WriteStatus);
        }
        if let Some(line) = &mut self.status_line
            && line.due(now)
        {
            actions.push(Action::StatusLine);
        }
    }

    /// Asks every stage to exit; the grace starts now.
    fn on_stop(&mut self, now: Duration, actions: &mut Vec<Action>) {
        if self.stopping.is_some() {
            return;
        }
        for stage in self.supervised() {
            actions.push(Action::Send {
                stage,
                pid: 0,
                command: Command::Shutdown,
                value: 0,
                frame_id: 0,
            });
        }
        self.stopping = Some((now.saturating_add(self.grace), false));
        self.outputs_when_stopped(actions);
    }

    /// Once every stage is gone, the optional processes are told to stop (once).
    fn outputs_when_stopped(&mut self, actions: &mut Vec<Action>) {
        if let Some((_, outputs)) = &mut self.stopping
            && !*outputs
            && self.instances.is_empty()
        {
            *outputs = true;
            actions.push(Action::StopOutputs);
        }
    }

    /// How many times `stage` was restarted.
    fn restarts_of(&self, stage: StageKind) -> u32 {
        self.restarts
            .iter()
            .find(|(s, _)| *s == stage)
            .map_or(0, |(_, b)| b.count())
    }

    /// The restarts of `stage`, from the first backoff the first time it dies.
    fn backoff_of(&mut self, stage: StageKind) -> &mut Backoff {
        let i = match self.restarts.iter().position(|(s, _)| *s == stage) {
            Some(i) => i,
            None => {
                // Kept in the declaration's order: restarts due at once start in that order.
                let order = |s: StageKind| {
                    self.nodes
                        .iter()
                        .position(|n| n.stage == s)
                        .unwrap_or(usize::MAX)
                };
                let at = self
                    .restarts
                    .iter()
                    .position(|(s, _)| order(*s) > order(stage))
                    .unwrap_or(self.restarts.len());
                self.restarts.insert(at, (stage, self.first_backoff));
                at
            }
        };
        &mut self.restarts[i].1
    }

    /// The nodes declared to start at `start`, in the declaration's order.
    fn started(&self, start: Start) -> Vec<StageKind> {
        self.nodes
            .iter()
            .filter(|n| n.start == start)
            .map(|n| n.stage)
            .collect()
    }

    /// The nodes the supervisor starts and stops, in the declaration's order.
    fn supervised(&self) -> Vec<StageKind> {
        self.nodes
            .iter()
            .filter(|n| n.supervised())
            .map(|n| n.stage)
            .collect()
    }

    /// Whether `stage` is declared restartable with backoff.
    fn restartable(&self, stage: StageKind) -> bool {
        node_in(self.nodes, stage).is_some_and(|n| n.restart == Restart::Backoff)
    }

    /// Whether `stage` is declared hot-swappable.
    fn hot_swappable(&self, stage: StageKind) -> bool {
        node_in(self.nodes, stage).is_some_and(|n| n.hot_swap)
    }

    fn all_ready(&self, stages: &[StageKind]) -> bool {
        stages.iter().all(|s| {
            self.instances
                .iter()
                .any(|p| p.stage == *s && p.ready && !p.standby)
        })
    }
}

mod swap;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::Clock;
    use linetrack_msgs::pipeline::Role;
    use linetrack_msgs::{FrameHeader, FrameStatus};
    use linetrack_msgs::{StampSlot, Topic};
    use linetrack_pipeline_config::SupervisorConfig;
    use linetrack_stage_runtime::detector_on_wire;

    const MS: Duration = Duration::from_millis(1);

    fn config() -> PipelineConfig {
        let mut config = PipelineConfig {
            supervisor: SupervisorConfig {
                hang_timeout_ms: 3000,
                startup_timeout_ms: 30_000,
                restart_backoff_ms: 200,
                restart_backoff_max_ms: 1000,
                max_restarts: 2,
                drain_timeout_ms: 5000,
                shutdown_grace_ms: 2000,
                status_every_ms: 0,
                ..SupervisorConfig::default()
            },
            detector: DetectorKind::Lsd,
            ..PipelineConfig::default()
        };
        config.detector_fallback.enabled = false;
        config
    }

    /// The core, a manual clock, and the instances the tests "spawned".
    struct Run {
        core: Core,
        clock: Clock,
        next_pid: u32,
        pids: Vec<(StageKind, u32)>,
    }

    /// The nodes of [`PIPELINE`] started at `start`, in its order.
    fn declared(start: Start) -> Vec<StageKind> {
        PIPELINE
            .iter()
            .filter(|n| n.start == start)
            .map(|n| n.stage)
            .collect()
    }

    impl Run {
        fn new(config: &PipelineConfig) -> Self {
            Self::of(config, PIPELINE)
        }

        /// A run of the pipeline `nodes` declares.
        fn of(config: &PipelineConfig, nodes: &'static [NodeDecl]) -> Self {
            Self {
                core: Core::declared(config, false, nodes),
                clock: Clock::manual(0),
                next_pid: 100,
                pids: Vec::new(),
            }
        }

        /// Takes `event` now; every spawn it asks for is started (as the shell does).
        fn on(&mut self, event: Event) -> Vec<Action> {
            let actions = self.core.on(event, self.clock.monotonic());
            for action in &actions {
                if let Action::Spawn {
                    stage,
                    detector,
                    standby,
                    ..
                } = *action
                {
                    self.next_pid += 1;
                    let pid = self.next_pid;
                    self.pids.push((stage, pid));
                    let spawned = Event::Spawned {
                        stage,
                        pid,
                        detector,
                        standby,
                    };
                    assert_eq!(
                        self.core.on(spawned, self.clock.monotonic()),
                        [Action::WriteStatus]
                    );
                }
            }
            actions
        }

        /// The newest instance of `stage`.
        fn pid(&self, stage: StageKind) -> u32 {
            self.pids
                .iter()
                .rev()
                .find(|(s, _)| *s == stage)
                .map(|(_, pid)| *pid)
                .unwrap_or_else(|| panic!("no {stage} started"))
        }

        fn report(&mut self, pid: u32, kind: StatusKind, frame_id: u64) -> Vec<Action> {
            self.on(Event::Status(StatusReport {
                pid,
                kind: kind.into(),
                frame_id,
                ..StatusReport::default()
            }))
        }

        fn tick(&mut self) -> Vec<Action> {
            self.on(Event::Tick(Progress {
                optional_settled: true,
                ..Progress::default()
            }))
        }

        fn exit(&mut self, pid: u32, success: bool) -> Vec<Action> {
            self.on(Event::Exited {
                pid,
                status: if success {
                    "exit status: 0"
                } else {
                    "exit status: 1"
                }
                .to_string(),
                success,
                last_words: String::new(),
            })
        }

        /// Every stage started and ready, the source running.
        fn running(config: &PipelineConfig) -> Self {
            let mut run = Self::new(config);
            run.on(Event::Start);
            for stage in declared(Start::WithStages) {
                run.report(run.pid(stage), StatusKind::Ready, 0);
            }
            let started = spawns(&run.tick());
            assert_eq!(started, [(StageKind::FrameSource, None, false, false)]);
            run.report(run.pid(StageKind::FrameSource), StatusKind::Ready, 0);
            run
        }
    }

    /// The spawns among `actions`: stage, detector, standby, restarted.
    fn spawns(actions: &[Action]) -> Vec<(StageKind, Option<DetectorKind>, bool, bool)> {
        actions
            .iter()
            .filter_map(|a| match *a {
                Action::Spawn {
                    stage,
                    detector,
                    standby,
                    restarted,
                } => Some((stage, detector, standby, restarted)),
                _ => None,
            })
            .collect()
    }

    /// The events recorded among `actions`: kind and detail.
    fn records(actions: &[Action]) -> Vec<(&'static str, String)> {
        actions
            .iter()
            .filter_map(|a| match a {
                Action::Record { kind, detail, .. } => Some((*kind, detail.clone())),
                _ => None,
            })
            .collect()
    }

    /// The commands sent among `actions`: command, stage, pid, frame.
    fn sent(actions: &[Action]) -> Vec<(Command, StageKind, u32, u64)> {
        actions
            .iter()
            .filter_map(|a| match *a {
                Action::Send {
                    command,
                    stage,
                    pid,
                    frame_id,
                    ..
                } => Some((command, stage, pid, frame_id)),
                _ => None,
            })
            .collect()
    }

    /// The spawns of [`Event::Start`] with [`PIPELINE`] and the test config.
    fn stages_spawned() -> Vec<(StageKind, Option<DetectorKind>, bool, bool)> {
        vec![
            (
                StageKind::LineDetector,
                Some(DetectorKind::Lsd),
                false,
                false,
            ),
            (StageKind::Matcher, None, false, false),
            (StageKind::PoseEstimator, None, false, false),
        ]
    }

    fn finish(actions: &[Action]) -> Option<End> {
        actions.iter().find_map(|a| match a {
            Action::Finish(end) => Some(end.clone()),
            _ => None,
        })
    }

    #[test]
    fn the_source_starts_once_the_stages_are_ready_and_the_outputs_settled_or_the_start_fails() {
        let mut run = Run::new(&config());
        let started = spawns(&run.on(Event::Start));
        assert_eq!(started, stages_spawned());
        run.report(run.pid(StageKind::LineDetector), StatusKind::Ready, 0);
        run.report(run.pid(StageKind::Matcher), StatusKind::Ready, 0);
        assert!(
            spawns(&run.tick()).is_empty(),
            "the pose estimator is not ready"
        );
        run.report(run.pid(StageKind::PoseEstimator), StatusKind::Ready, 0);
        let unsettled = run.on(Event::Tick(Progress::default()));
        assert!(
            spawns(&unsettled).is_empty(),
            "an output the source waits for"
        );
        assert_eq!(spawns(&run.tick()).len(), 1);
        assert!(!run.core.awaiting_source());
        assert!(spawns(&run.tick()).is_empty(), "started once");

        // A stage that never gets ready ends the run at the startup timeout, not before.
        let mut stuck = Run::new(&config());
        stuck.on(Event::Start);
        stuck.report(stuck.pid(StageKind::Matcher), StatusKind::Ready, 0);
        // The watchdog's startup timeout is the same 30 s: reports keep them alive here.
        stuck.clock.advance(30_000 * MS);
        for stage in declared(Start::WithStages) {
            stuck.report(stuck.pid(stage), StatusKind::Heartbeat, 0);
        }
        assert_eq!(finish(&stuck.tick()), None);
        stuck.clock.advance(MS);
        assert_eq!(
            finish(&stuck.tick()),
            Some(End::Failed(
                "stages not ready after 30s: line-detector, pose-estimator".to_string()
            ))
        );
    }

    #[test]
    fn a_crashed_stage_restarts_after_a_doubling_backoff_and_past_the_limit_the_run_fails() {
        let mut run = Run::running(&config());
        run.clock.advance(Duration::from_secs(5));
        let matcher = run.pid(StageKind::Matcher);
        // It reported a moment ago: a crash, not a hang.
        run.report(matcher, StatusKind::Heartbeat, 0);
        let crashed = run.exit(matcher, false);
        assert_eq!(
            records(&crashed),
            [("crash", format!("pid {matcher} exit status: 1 after 5.0 s"))]
        );
        assert_eq!(finish(&crashed), None);
        assert!(spawns(&crashed).is_empty(), "not before its backoff");
        for (restart, backoff_ms) in [(1, 200), (2, 400)] {
            run.clock.advance((backoff_ms - 1) * MS);
            assert!(
                spawns(&run.tick()).is_empty(),
                "restart {restart} a ms early"
            );
            run.clock.advance(MS);
            let restarted = run.tick();
            assert_eq!(
                spawns(&restarted),
                [(StageKind::Matcher, None, false, true)]
            );
            assert_eq!(
                records(&restarted),
                [("restart", format!("restart {restart} of 2"))]
            );
            let matcher = run.pid(StageKind::Matcher);
            run.report(matcher, StatusKind::Ready, 0);
            let crashed = run.exit(matcher, false);
            if restart == 1 {
                assert_eq!(finish(&crashed), None);
            } else {
                assert_eq!(
                    finish(&crashed),
                    Some(End::Failed(
                        "matcher died 3 times (restart limit 2): giving up; the last time exit status: 1"
                            .to_string()
                    ))
                );
            }
        }
    }

    /// An observer node the shipped pipeline does not have, woken by the poses, started
    /// with the stages and restarted with backoff; `hot_swap` as given. (A node needs a
    /// wire code: [`StageKind::Observer`], the kind for nodes added besides the shipped ones.)
    fn with_observer(hot_swap: bool) -> &'static [NodeDecl] {
        let observer = NodeDecl {
            wakes_on: &[Topic::Poses, Topic::Control],
            start: Start::WithStages,
            restart: Restart::Backoff,
            hot_swap,
            ..NodeDecl::new(StageKind::Observer, Role::Observer, "linetrack-observer")
        };
        let mut nodes: Vec<NodeDecl> = PIPELINE
            .iter()
            .filter(|n| n.stage != observer.stage)
            .copied()
            .collect();
        nodes.push(observer);
        Vec::leak(nodes)
    }

    /// Adding a node is one entry in the declaration: the core starts it with the stages,
    /// waits for it before the source, restarts it on its own backoff (the other stages'
    /// restarts untouched), hot-swaps it only when declared so, and stops it with the rest.
    #[test]
    fn a_declared_observer_is_started_waited_for_restarted_and_stopped_like_a_stage() {
        let observer = StageKind::Observer;
        let mut run = Run::of(&config(), with_observer(false));
        let started = spawns(&run.on(Event::Start));
        let mut expected = stages_spawned();
        expected.push((observer, None, false, false));
        assert_eq!(started, expected);
        for stage in declared(Start::WithStages) {
            run.report(run.pid(stage), StatusKind::Ready, 0);
        }
        assert!(spawns(&run.tick()).is_empty(), "the observer is not ready");
        run.report(run.pid(observer), StatusKind::Ready, 0);
        assert_eq!(
            spawns(&run.tick()),
            [(StageKind::FrameSource, None, false, false)]
        );
        run.report(run.pid(StageKind::FrameSource), StatusKind::Ready, 0);

        // The matcher has used one restart.
        run.exit(run.pid(StageKind::Matcher), false);
        run.clock.advance(200 * MS);
        assert_eq!(
            records(&run.tick()),
            [("restart", "restart 1 of 2".to_string())]
        );
        run.report(run.pid(StageKind::Matcher), StatusKind::Ready, 0);
        // The observer and the source die at once: both restart after the first backoff,
        // each its first restart, in the declaration's order.
        for pid in [run.pid(observer), run.pid(StageKind::FrameSource)] {
            let crashed = run.exit(pid, false);
            assert_eq!(finish(&crashed), None, "{crashed:?}");
        }
        run.clock.advance(199 * MS);
        assert!(spawns(&run.tick()).is_empty());
        run.clock.advance(MS);
        let restarted = run.tick();
        assert_eq!(
            spawns(&restarted),
            [
                (StageKind::FrameSource, None, false, true),
                (observer, None, false, true)
            ]
        );
        assert_eq!(
            records(&restarted),
            [
                ("restart", "restart 1 of 2".to_string()),
                ("restart", "restart 1 of 2".to_string())
            ]
        );
        // The matcher's next death is its second.
        run.exit(run.pid(StageKind::Matcher), false);
        run.clock.advance(399 * MS);
        assert!(spawns(&run.tick()).is_empty(), "400 ms: the second backoff");
        run.clock.advance(MS);
        assert_eq!(
            records(&run.tick()),
            [("restart", "restart 2 of 2".to_string())]
        );
        run.report(run.pid(StageKind::Matcher), StatusKind::Ready, 0);

        // Not declared hot-swappable: a swap is refused.
        let refused = run.on(Event::SwapStage(observer));
        assert!(spawns(&refused).is_empty() && records(&refused).is_empty());
        // Stopped with the stages, in the declaration's order.
        let stop = run.on(Event::Stop);
        assert_eq!(
            sent(&stop),
            [
                StageKind::FrameSource,
                StageKind::LineDetector,
                StageKind::Matcher,
                StageKind::PoseEstimator,
                observer
            ]
            .map(|s| (Command::Shutdown, s, 0, 0))
        );

        // Declared hot-swappable, it hands over to a standby like the matcher.
        let mut swappable = Run::of(&config(), with_observer(true));
        swappable.on(Event::Start);
        for stage in declared(Start::WithStages).into_iter().chain([observer]) {
            swappable.report(swappable.pid(stage), StatusKind::Ready, 0);
        }
        let old = swappable.pid(observer);
        let asked = swappable.on(Event::SwapStage(observer));
        assert_eq!(spawns(&asked), [(observer, None, true, false)]);
        let standby = swappable.pid(observer);
        let ready = swappable.report(standby, StatusKind::Ready, 7);
        assert_eq!(sent(&ready), [(Command::HandOver, observer, old, 7)]);
        let handed = swappable.report(old, StatusKind::HandedOver, 7);
        assert_eq!(sent(&handed), [(Command::TakeOver, observer, standby, 7)]);
        assert!(swappable.core.expects_exit(old, true));

        // A node declared without restarts ends the run when it dies.
        let mut outputs = Run::running(&config());
        outputs.on(Event::Spawned {
            stage: StageKind::Recorder,
            pid: 900,
            detector: None,
            standby: false,
        });
        outputs.report(900, StatusKind::Ready, 0);
        let died = outputs.exit(900, false);
        assert_eq!(
            finish(&died),
            Some(End::Failed(
                "recorder (pid 900) died and is not declared restartable: exit status: 1"
                    .to_string()
            ))
        );
    }

    #[test]
    fn a_stage_that_dies_while_being_restarted_uses_its_restarts_instead_of_ending_the_run() {
        let mut run = Run::running(&config());
        let pose = run.pid(StageKind::PoseEstimator);
        let crashed = run.exit(pose, false);
        assert_eq!(
            crashed
                .iter()
                .find(|a| matches!(a, Action::PoseEstimatorDied(_))),
            Some(&Action::PoseEstimatorDied(format!(
                "pid {pose} crash: exit status: 1"
            )))
        );
        run.clock.advance(200 * MS);
        assert_eq!(
            spawns(&run.tick()),
            [(StageKind::PoseEstimator, None, false, true)]
        );
        // Its successor dies before it is ready: a crash like any other, restarted again.
        let successor = run.pid(StageKind::PoseEstimator);
        let died = run.exit(successor, false);
        assert_eq!(finish(&died), None, "{died:?}");
        assert_eq!(
            records(&died),
            [(
                "crash",
                format!("pid {successor} exit status: 1 after 0.0 s, before it was ready")
            )]
        );
        run.clock.advance(400 * MS);
        assert_eq!(spawns(&run.tick()).len(), 1, "restart 2 of 2");

        // On its first start, dying before it is ready ends the run at once: a retry
        // would not start either.
        let mut first = Run::new(&config());
        first.on(Event::Start);
        let matcher = first.pid(StageKind::Matcher);
        let died = first.on(Event::Exited {
            pid: matcher,
            status: "exit status: 2".to_string(),
            success: false,
            last_words: ": no such config".to_string(),
        });
        assert_eq!(
            finish(&died),
            Some(End::Failed(format!(
                "matcher (pid {matcher}) exited before it was ready (exit status: 2): no such config"
            )))
        );
    }

    #[test]
    fn a_silent_stage_is_killed_once_after_the_hang_timeout_and_restarted_as_hung() {
        let mut run = Run::running(&config());
        let (detector, matcher) = (
            run.pid(StageKind::LineDetector),
            run.pid(StageKind::Matcher),
        );
        run.clock.advance(2000 * MS);
        for stage in [
            StageKind::FrameSource,
            StageKind::LineDetector,
            StageKind::PoseEstimator,
        ] {
            run.report(run.pid(stage), StatusKind::Heartbeat, 0);
        }
        run.clock.advance(1000 * MS);
        assert!(
            !run.tick().iter().any(|a| matches!(a, Action::Kill { .. })),
            "exactly the hang timeout is not more than it"
        );
        run.clock.advance(MS);
        let killed: Vec<u32> = run
            .tick()
            .iter()
            .filter_map(|a| match a {
                Action::Kill { pid } => Some(*pid),
                _ => None,
            })
            .collect();
        assert_eq!(killed, [matcher], "only the silent one");
        assert!(
            !run.tick().iter().any(|a| matches!(a, Action::Kill { .. })),
            "killed once"
        );
        assert_ne!(detector, matcher);
        let exited = run.on(Event::Exited {
            pid: matcher,
            status: "signal: 9 (SIGKILL)".to_string(),
            success: false,
            last_words: String::new(),
        });
        assert_eq!(
            records(&exited),
            [(
                "hang",
                format!("pid {matcher} signal: 9 (SIGKILL) after 3.0 s")
            )]
        );
        run.clock.advance(200 * MS);
        assert_eq!(spawns(&run.tick()).len(), 1);
    }

    #[test]
    fn a_swap_hands_over_from_the_running_detector_to_the_standby() {
        let mut run = Run::running(&config());
        let old = run.pid(StageKind::LineDetector);
        let asked = run.on(Event::SwapRequest(DetectorKind::Fld));
        assert_eq!(
            records(&asked),
            [("swap-requested", "lsd -> fld".to_string())]
        );
        assert_eq!(
            spawns(&asked),
            [(
                StageKind::LineDetector,
                Some(DetectorKind::Fld),
                true,
                false
            )]
        );
        let standby = run.pid(StageKind::LineDetector);
        let again = run.on(Event::SwapRequest(DetectorKind::EdgeLines));
        assert!(spawns(&again).is_empty(), "one swap at a time: {again:?}");
        // Ready holding frames from 40: the running one is asked to hand over at 40.
        let ready = run.report(standby, StatusKind::Ready, 40);
        assert_eq!(
            sent(&ready),
            [(Command::HandOver, StageKind::LineDetector, old, 40)]
        );
        assert_eq!(run.core.detector(), DetectorKind::Lsd, "not yet");
        let handed = run.report(old, StatusKind::HandedOver, 41);
        assert_eq!(
            sent(&handed),
            [(Command::TakeOver, StageKind::LineDetector, standby, 41)]
        );
        assert_eq!(
            records(&handed),
            [("swap", format!("lsd (pid {old}) -> fld (pid {standby})"))]
        );
        assert_eq!(run.core.detector(), DetectorKind::Fld);
        // The old one's exit was expected: no crash, no restart.
        assert!(run.core.expects_exit(old, true));
        let exited = run.exit(old, true);
        assert!(
            records(&exited).is_empty() && finish(&exited).is_none(),
            "{exited:?}"
        );
        run.clock.advance(Duration::from_secs(10));
        for stage in StageKind::PROCESSING {
            run.report(run.pid(stage), StatusKind::Heartbeat, 0);
        }
        assert!(spawns(&run.tick()).is_empty());
        let same = run.on(Event::SwapRequest(DetectorKind::Fld));
        assert!(spawns(&same).is_empty(), "already running");
        // A restart of the detector now runs FLD.
        let fld = run.pid(StageKind::LineDetector);
        run.exit(fld, false);
        run.clock.advance(200 * MS);
        assert_eq!(
            spawns(&run.tick()),
            [(
                StageKind::LineDetector,
                Some(DetectorKind::Fld),
                false,
                true
            )]
        );
    }

    #[test]
    fn the_matcher_hot_swaps_to_a_fresh_instance_warmed_on_the_frame_before() {
        let mut run = Run::running(&config());
        let refused = run.on(Event::SwapStage(StageKind::PoseEstimator));
        assert!(
            spawns(&refused).is_empty() && records(&refused).is_empty(),
            "not hot-swappable: {refused:?}"
        );
        let old = run.pid(StageKind::Matcher);
        let asked = run.on(Event::SwapStage(StageKind::Matcher));
        assert_eq!(
            records(&asked),
            [("swap-requested", "a fresh instance".to_string())]
        );
        assert_eq!(spawns(&asked), [(StageKind::Matcher, None, true, false)]);
        let standby = run.pid(StageKind::Matcher);
        let detector = run.on(Event::SwapRequest(DetectorKind::Fld));
        assert!(
            spawns(&detector).is_empty(),
            "one swap at a time: {detector:?}"
        );
        // Ready holding frames from 40: the old one hands over at 41, so that the new one
        // has frame 40 to match frame 41 with.
        let ready = run.report(standby, StatusKind::Ready, 40);
        let hand_over: Vec<_> = sent(&ready)
            .into_iter()
            .filter(|s| s.0 == Command::HandOver)
            .collect();
        assert_eq!(
            hand_over,
            [(Command::HandOver, StageKind::Matcher, old, 41)]
        );
        let handed = run.report(old, StatusKind::HandedOver, 41);
        assert_eq!(
            sent(&handed),
            [(Command::TakeOver, StageKind::Matcher, standby, 41)]
        );
        assert_eq!(
            records(&handed),
            [("swap", format!("pid {old} -> pid {standby}"))]
        );
        assert!(run.core.expects_exit(old, true));
        let exited = run.exit(old, true);
        assert!(
            records(&exited).is_empty() && finish(&exited).is_none(),
            "{exited:?}"
        );
        // Over: the detector may be swapped now.
        assert_eq!(
            spawns(&run.on(Event::SwapRequest(DetectorKind::Fld))).len(),
            1
        );
    }

    #[test]
    fn a_standby_that_dies_before_taking_over_abandons_the_swap_and_the_detector_stays() {
        let mut run = Run::running(&config());
        run.on(Event::SwapRequest(DetectorKind::Fld));
        let standby = run.pid(StageKind::LineDetector);
        let died = run.exit(standby, false);
        let kinds: Vec<&str> = records(&died).iter().map(|(k, _)| *k).collect();
        assert_eq!(kinds, ["crash", "swap-abandoned"]);
        assert_eq!(finish(&died), None, "the run goes on");
        assert_eq!(run.core.detector(), DetectorKind::Lsd);
        run.clock.advance(Duration::from_secs(1));
        assert!(spawns(&run.tick()).is_empty(), "a standby is not restarted");
        // A new swap may be asked for.
        assert_eq!(
            spawns(&run.on(Event::SwapRequest(DetectorKind::Fld))).len(),
            1
        );
    }

    #[test]
    fn the_detector_policy_swaps_lsd_out_on_a_streak_over_budget_and_waits_during_a_swap() {
        let mut config = config();
        config.detector_fallback.enabled = true;
        config.detector_fallback.bad_frames = 3;
        config.detector_fallback.end_to_end = false;
        config.detector_fallback.to = DetectorKind::Fld;
        let mut run = Run::running(&config);
        let slow = |id: u64| {
            let mut h = TracksHeader::from(FrameHeader::new(id, 0, 1));
            h.detection.detector = detector_on_wire(DetectorKind::Lsd).into();
            h.frame.stamps[StampSlot::LineDetector].start_ns = 1_000_000_000;
            h.frame.stamps[StampSlot::LineDetector].end_ns = 1_080_000_000;
            h
        };
        assert!(spawns(&pose(&mut run, slow(0), true)).is_empty());
        assert!(spawns(&pose(&mut run, slow(1), true)).is_empty());
        let swap = pose(&mut run, slow(2), true);
        assert_eq!(
            spawns(&swap),
            [(
                StageKind::LineDetector,
                Some(DetectorKind::Fld),
                true,
                false
            )]
        );
        assert_eq!(records(&swap)[0].0, "detector-fallback");
        for id in 3..10 {
            assert!(
                spawns(&pose(&mut run, slow(id), true)).is_empty(),
                "swap under way"
            );
        }
        let mut late = slow(10);
        late.frame
            .mark(FrameStatus::DroppedLate, StageKind::Matcher);
        assert!(spawns(&pose(&mut run, late, true)).is_empty());
    }

    /// Frame `id` matched in `mode` with `stereo` stereo matches (`probe`: the LBD probe's,
    /// -1 for none).
    fn matched(id: u64, mode: MatcherMode, stereo: u32, probe: i32) -> TracksHeader {
        let mut h = TracksHeader::from(FrameHeader::new(id, 0, 1));
        h.matching.mode = mode.into();
        h.matching.stereo_matches = stereo;
        h.matching.lbd_probe_matches = probe;
        h
    }

    fn pose(run: &mut Run, header: TracksHeader, first: bool) -> Vec<Action> {
        run.on(Event::Pose {
            header,
            pose: Box::default(),
            first,
        })
    }

    #[test]
    fn the_matcher_falls_back_on_a_streak_of_bad_frames_and_recovers_only_past_the_higher_bar() {
        let mut config = config();
        config.matcher.mode = MatcherPolicy::Auto;
        config.matcher.fallback.bad_frames = 3;
        config.matcher.fallback.recover_probes = 2;
        config.matcher.fallback.min_stereo_matches = 12;
        config.matcher.fallback.recover_stereo_matches = 24;
        config.matcher.fallback.over_budget = false;
        config.matcher.fallback.end_to_end = false;
        let mut run = Run::running(&config);
        let lbd = |id| matched(id, MatcherMode::Lbd, 5, -1);
        let mut id = 0..;
        let mut next = || id.next().unwrap_or_default();
        // Two bad, one good, two bad, and a bad one arriving twice: no streak of three.
        for header in [lbd(next()), lbd(next())] {
            assert!(pose(&mut run, header, true).is_empty());
        }
        assert!(pose(&mut run, matched(next(), MatcherMode::Lbd, 40, -1), true).is_empty());
        for header in [lbd(next()), lbd(next())] {
            assert!(pose(&mut run, header, true).is_empty());
        }
        assert!(
            pose(&mut run, lbd(4), false).is_empty(),
            "a duplicate says nothing"
        );
        let fell = pose(&mut run, lbd(next()), true);
        assert_eq!(
            records(&fell),
            [(
                "fallback",
                "lbd -> l1: too few LBD stereo matches (5 < 12), 3 frames in a row".to_string()
            )]
        );
        assert_eq!(
            sent(&fell),
            [(Command::SetMatcherMode, StageKind::Matcher, 0, 0)]
        );
        assert_eq!(run.core.matcher_mode(), Some(MatcherMode::L1));
        // Probes between the two bars (12 and 24) never bring LBD back: the hysteresis.
        for _ in 0..10 {
            let probe = matched(next(), MatcherMode::L1, 50, 20);
            assert!(pose(&mut run, probe, true).is_empty());
        }
        // A restarted matcher is told the mode.
        run.exit(run.pid(StageKind::Matcher), false);
        run.clock.advance(200 * MS);
        run.tick();
        let matcher = run.pid(StageKind::Matcher);
        let ready = run.report(matcher, StatusKind::Ready, 0);
        assert_eq!(
            ready.iter().find(|a| matches!(a, Action::Send { .. })),
            Some(&Action::Send {
                stage: StageKind::Matcher,
                pid: matcher,
                command: Command::SetMatcherMode,
                value: MatcherMode::L1.into(),
                frame_id: 0,
            })
        );
        // One good probe, one in the band: the streak starts again; two good: back.
        for probe in [30, 20, 30] {
            let header = matched(next(), MatcherMode::L1, 50, probe);
            assert!(pose(&mut run, header, true).is_empty());
        }
        let back = pose(&mut run, matched(next(), MatcherMode::L1, 50, 30), true);
        assert_eq!(records(&back)[0].0, "recover");
        assert_eq!(run.core.matcher_mode(), Some(MatcherMode::Lbd));
        assert_eq!(
            back.iter().find(|a| matches!(a, Action::Send { .. })),
            Some(&Action::Send {
                stage: StageKind::Matcher,
                pid: 0,
                command: Command::SetMatcherMode,
                value: MatcherMode::Lbd.into(),
                frame_id: 0,
            })
        );
    }

    #[test]
    fn the_run_completes_when_every_frame_has_an_outcome_or_its_drain_runs_out() {
        let mut run = Run::running(&config());
        let source = run.pid(StageKind::FrameSource);
        let finished = run.report(source, StatusKind::SourceFinished, 94);
        assert!(
            matches!(
                finished.as_slice(),
                [Action::Report {
                    stage: StageKind::FrameSource,
                    ..
                }]
            ),
            "{finished:?}"
        );
        // The source ends after its last frame: expected.
        let exited = run.exit(source, true);
        assert!(records(&exited).is_empty() && finish(&exited).is_none());
        assert_eq!(finish(&run.tick()), None, "the drain starts");
        run.clock.advance(5000 * MS);
        for stage in declared(Start::WithStages) {
            run.report(run.pid(stage), StatusKind::Heartbeat, 0);
        }
        assert_eq!(finish(&run.tick()), None);
        run.clock.advance(MS);
        assert_eq!(finish(&run.tick()), Some(End::Completed));

        let mut complete = Run::running(&config());
        let done = complete.on(Event::Tick(Progress {
            optional_settled: true,
            complete: true,
            records_failed: None,
        }));
        assert_eq!(finish(&done), Some(End::Completed));
        assert_eq!(
            finish(&complete.on(Event::Interrupt)),
            Some(End::Interrupted)
        );

        // Records that fail stop the run when the config says so.
        let mut config = config();
        config.output.on_record_error = OnRecordError::Stop;
        let mut strict = Run::running(&config);
        let failed = strict.on(Event::Tick(Progress {
            optional_settled: true,
            complete: false,
            records_failed: Some("frames.csv: disk full".to_string()),
        }));
        assert_eq!(
            finish(&failed),
            Some(End::Failed(
                "run records: frames.csv: disk full: the pipeline stops (output.on_record_error = \"stop\")"
                    .to_string()
            ))
        );
    }

    #[test]
    fn an_ordered_stop_asks_every_stage_kills_the_late_ones_and_stops_the_outputs_last() {
        let mut run = Run::running(&config());
        let stop = run.on(Event::Stop);
        assert_eq!(
            sent(&stop),
            StageKind::PROCESSING.map(|s| (Command::Shutdown, s, 0, 0))
        );
        assert!(!stop.contains(&Action::StopOutputs), "the stages first");
        // Two exit in time, unjudged (even unsuccessfully); no restart.
        for stage in [StageKind::FrameSource, StageKind::Matcher] {
            let pid = run.pid(stage);
            assert!(run.core.expects_exit(pid, false));
            let exited = run.exit(pid, false);
            assert!(records(&exited).is_empty() && finish(&exited).is_none());
            assert!(!exited.contains(&Action::StopOutputs));
        }
        run.clock.advance(1999 * MS);
        assert!(
            run.tick()
                .iter()
                .all(|a| !matches!(a, Action::Abandon { .. }))
        );
        assert!(!run.core.stopped());
        run.clock.advance(MS);
        let late = run.tick();
        let abandoned: Vec<u32> = late
            .iter()
            .filter_map(|a| match a {
                Action::Abandon { pid } => Some(*pid),
                _ => None,
            })
            .collect();
        assert_eq!(
            abandoned,
            [
                run.pid(StageKind::LineDetector),
                run.pid(StageKind::PoseEstimator)
            ]
        );
        assert_eq!(late.last(), Some(&Action::StopOutputs), "the outputs last");
        assert!(run.core.stopped());
        assert!(spawns(&run.tick()).is_empty() && !run.tick().contains(&Action::StopOutputs));

        // Every stage gone within the grace: the outputs stop on the last exit.
        let mut quick = Run::running(&config());
        quick.on(Event::Stop);
        let pids: Vec<u32> = quick.core.instances().iter().map(|i| i.pid).collect();
        let mut last = Vec::new();
        for pid in pids {
            last = quick.exit(pid, true);
        }
        assert_eq!(last.last(), Some(&Action::StopOutputs));
        assert!(quick.core.stopped());
    }
}
