//! The optional processes beside the stages: the ROS 2 output (`linetrack-ros2`, `[ros2]
//! enabled`), the MCAP recorder (`linetrack-recorder`, `[record] mcap = true`) and the
//! ground-station link (`linetrack-link`, `[link] enabled`).
//!
//! None of them is part of the pipeline: one [`OptionalProcess`] starts each, waits (up to
//! a timeout) for the ones the frame source should wait for to report ready, notes an exit
//! in `events.csv`, restarts it with the stages' backoff or leaves the run to go on without
//! it (its [`Rule`]), and at the end asks it to stop, waits its grace period and kills it.
//! The events are `<prefix>-failed` (could not be started), `<prefix>-not-ready`,
//! `<prefix>-exit`, `<prefix>-given-up` (past the restart limit) and `<prefix>-killed` (did
//! not stop within its grace), with the process's name in the stage column.

use crate::Mode;
use crate::clock::{Backoff, Clock, restart_backoff};
use crate::monitor::Monitor;
use linetrack_msgs::StageKind;
use linetrack_msgs::pipeline::{Restart, declared};
use linetrack_pipeline_config::{PipelineConfig, SupervisorConfig};
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::Duration;

/// How an optional process is asked to stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopBy {
    /// SIGTERM.
    Signal,
    /// A `Shutdown` command on the control topic, addressed to this stage kind and its pid
    /// (the supervisor sends it).
    Command(StageKind),
}

/// What the supervisor does with one kind of optional process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rule {
    /// Its name in `events.csv`'s stage column.
    pub name: &'static str,
    /// The first word of its events' kinds.
    pub prefix: &'static str,
    /// Its binary, as the pipeline's declaration names it.
    pub binary: &'static str,
    /// What happens when it exits, as the declaration says: [`Restart::Output`], restarted
    /// with the stages' backoff up to their limit; anything else, the run goes on without it.
    pub restart: Restart,
    /// Whether the frame source waits for it to report ready.
    pub gates_source: bool,
    /// How it is asked to stop.
    pub stop: StopBy,
    /// What the run is without it.
    pub without: &'static str,
    /// The cargo feature its binary is built with.
    pub feature: &'static str,
}

/// The ROS 2 output: started before the frame source, which waits for it; left when it
/// exits.
pub const ROS2: Rule = Rule {
    name: "ros2",
    prefix: "output",
    binary: declared(StageKind::Ros2Bridge).binary,
    restart: declared(StageKind::Ros2Bridge).restart,
    gates_source: true,
    stop: StopBy::Signal,
    without: "the run goes on without it",
    feature: "linetrack-ros2-bridge/ros2",
};

/// The MCAP recorder: the frame source waits for it to open its file; left when it exits
/// (its file is unfinished); told to close its file at the end.
pub const RECORDER: Rule = Rule {
    name: "recorder",
    prefix: "recorder",
    binary: declared(StageKind::Recorder).binary,
    restart: declared(StageKind::Recorder).restart,
    gates_source: true,
    stop: StopBy::Command(StageKind::Recorder),
    without: "the run goes on without a recording",
    feature: "linetrack-recorder/mcap",
};

/// The ground-station link: nothing waits for it; restarted when it exits.
pub const LINK: Rule = Rule {
    name: "link",
    prefix: "link",
    binary: declared(StageKind::Link).binary,
    restart: declared(StageKind::Link).restart,
    gates_source: false,
    stop: StopBy::Signal,
    without: "the pipeline goes on",
    feature: "linetrack/link",
};

/// What an optional process needs to know of the run.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The folder of its binary.
    pub bin_dir: PathBuf,
    /// Arguments after the run's common ones.
    pub args: Vec<OsString>,
    /// How long the frame source waits for it to be ready (with [`Rule::gates_source`]).
    pub ready_timeout: Duration,
    /// How long it may take to stop before it is killed.
    pub grace: Duration,
}

/// A running child.
#[derive(Debug)]
struct Running {
    child: Child,
    pid: u32,
    started: Duration,
}

/// One optional process over the run: its child while it runs, its restarts.
#[derive(Debug)]
pub struct OptionalProcess {
    rule: Rule,
    settings: Settings,
    running: Option<Running>,
    /// It reported ready, or the source no longer waits for it.
    settled: bool,
    backoff: Backoff,
    /// Wants starting: at the beginning, or when a restart fell due.
    start_due: bool,
    /// Left for the rest of the run (exited without restart, or past the restart limit).
    done: bool,
}

impl OptionalProcess {
    /// A process of `rule`, to be started by [`OptionalProcess::start`].
    pub fn new(rule: Rule, settings: Settings, config: &SupervisorConfig) -> Self {
        Self {
            rule,
            settings,
            running: None,
            settled: !rule.gates_source,
            backoff: restart_backoff(config),
            start_due: true,
            done: false,
        }
    }

    /// Its rule.
    pub fn rule(&self) -> &Rule {
        &self.rule
    }

    /// Whether it is restarted when it exits.
    fn restarts(&self) -> bool {
        self.rule.restart == Restart::Output
    }

    /// Its binary.
    pub fn binary(&self) -> PathBuf {
        self.settings.bin_dir.join(self.rule.binary)
    }

    /// The arguments after the run's common ones.
    pub fn args(&self) -> &[OsString] {
        &self.settings.args
    }

    /// Its process id while it runs.
    pub fn pid(&self) -> Option<u32> {
        self.running.as_ref().map(|r| r.pid)
    }

    /// Whether it should be started now (the caller then builds its command for
    /// [`OptionalProcess::supervise`]).
    pub fn wants_start(&mut self, now: Duration) -> bool {
        if self.running.is_some() || self.done {
            return false;
        }
        if self.backoff.take_due(now).is_some() {
            self.start_due = true;
        }
        self.start_due
    }

    /// It reported ready (on the status topic, with its pid).
    pub fn set_ready(&mut self) {
        self.settled = true;
    }

    /// Whether the frame source may start as far as this process goes: it is ready, it is
    /// gone, or it had its ready timeout (then that is recorded and it is left running).
    pub fn settled(&mut self, now: Duration, monitor: &mut Monitor) -> bool {
        if self.settled || self.done {
            return true;
        }
        let Some(running) = &self.running else {
            // Not started (yet): a restart may be on its way; the source does not wait.
            return !self.backoff.pending() && !self.start_due;
        };
        let timeout = self.settings.ready_timeout;
        if now.saturating_sub(running.started) > timeout {
            monitor.event(
                &self.kind("not-ready"),
                self.rule.name,
                None,
                format!(
                    "pid {} not ready after {timeout:?}: the run starts without waiting for it",
                    running.pid
                ),
            );
            self.settled = true;
        }
        self.settled
    }

    fn kind(&self, what: &str) -> String {
        format!("{}-{what}", self.rule.prefix)
    }

    /// Starts it with `command` when one is given (see [`OptionalProcess::wants_start`]);
    /// notes its exit and, by its rule, schedules a restart or leaves it. Called on every
    /// turn of the supervisor's loop.
    pub fn supervise(&mut self, command: Option<Command>, now: Duration, monitor: &mut Monitor) {
        if let Some(running) = &mut self.running {
            let status = match running.child.try_wait() {
                Ok(Some(status)) => status,
                Ok(None) => return,
                Err(e) => {
                    tracing::warn!("cannot poll {} (pid {}): {e}", self.rule.name, running.pid);
                    return;
                }
            };
            let ran = now.saturating_sub(running.started);
            let pid = running.pid;
            self.running = None;
            tracing::warn!("{} (pid {pid}) exited: {status}", self.rule.name);
            let next = self.after_failure(now);
            monitor.event(
                &self.kind("exit"),
                self.rule.name,
                None,
                format!(
                    "pid {pid} {status} after {:.1} s (its error is in the log); {next}",
                    ran.as_secs_f64()
                ),
            );
            self.give_up_note(monitor);
            return;
        }
        let Some(mut command) = command else {
            return;
        };
        self.start_due = false;
        match command.spawn() {
            Ok(child) => {
                let pid = child.id();
                tracing::info!("started {} (pid {pid})", self.rule.name);
                self.settled = !self.rule.gates_source;
                self.running = Some(Running {
                    child,
                    pid,
                    started: now,
                });
            }
            Err(e) => {
                let next = self.after_failure(now);
                monitor.event(
                    &self.kind("failed"),
                    self.rule.name,
                    None,
                    format!(
                        "{} cannot be started: {e} (built with `--features {}`?); {next}",
                        self.binary().display(),
                        self.rule.feature
                    ),
                );
                self.give_up_note(monitor);
            }
        }
    }

    /// After an exit or a failed start: schedules the restart or leaves it; what happens
    /// next, in words.
    fn after_failure(&mut self, now: Duration) -> String {
        if !self.restarts() {
            self.done = true;
            return self.rule.without.to_string();
        }
        match self.backoff.schedule(now) {
            Ok(delay) => format!(
                "{}; restart {} of {} in {delay:?}",
                self.rule.without,
                self.backoff.count() + 1,
                self.backoff.limit()
            ),
            Err(_) => {
                self.done = true;
                self.rule.without.to_string()
            }
        }
    }

    /// Records a restarting process that has just passed its limit.
    fn give_up_note(&self, monitor: &mut Monitor) {
        if self.restarts() && self.done {
            monitor.event(
                &self.kind("given-up"),
                self.rule.name,
                None,
                format!(
                    "{} failed {} times (restart limit {}): {}",
                    self.rule.binary,
                    self.backoff.count() + 1,
                    self.backoff.limit(),
                    self.rule.without
                ),
            );
        }
    }

    /// Stops it: SIGTERM unless its rule has the supervisor send a command (sent before
    /// this), then up to its grace period for it to exit, then kill. An unsuccessful end or
    /// a kill is recorded.
    pub fn stop(&mut self, clock: &Clock, monitor: &mut Monitor) {
        let Some(mut running) = self.running.take() else {
            return;
        };
        self.done = true;
        if self.rule.stop == StopBy::Signal
            && let Some(pid) = rustix::process::Pid::from_raw(running.pid as i32)
        {
            let _ = rustix::process::kill_process(pid, rustix::process::Signal::TERM);
        }
        let grace = self.settings.grace;
        let deadline = clock.monotonic().saturating_add(grace);
        loop {
            match running.child.try_wait() {
                Ok(Some(status)) if status.success() => {
                    tracing::info!("{} (pid {}) exited: {status}", self.rule.name, running.pid);
                    return;
                }
                Ok(Some(status)) => {
                    monitor.event(
                        &self.kind("exit"),
                        self.rule.name,
                        None,
                        format!("pid {} {status} while stopping", running.pid),
                    );
                    return;
                }
                Ok(None) | Err(_) if clock.monotonic() < deadline => clock.pause(POLL),
                _ => break,
            }
        }
        tracing::warn!(
            "{} (pid {}) did not stop within {grace:?}: killing it",
            self.rule.name,
            running.pid
        );
        let _ = running.child.kill();
        let _ = running.child.wait();
        monitor.event(
            &self.kind("killed"),
            self.rule.name,
            None,
            format!("pid {} did not stop within {grace:?}", running.pid),
        );
    }
}

/// How often a stopping process is polled.
const POLL: Duration = Duration::from_millis(20);

/// `bin_dir`'s binary of `rule`, which the config key `key` asks for; refused when it is
/// not there, saying how to build it.
pub fn require_binary(rule: &Rule, bin_dir: &Path, key: &str) -> anyhow::Result<PathBuf> {
    let bin = bin_dir.join(rule.binary);
    anyhow::ensure!(
        bin.is_file(),
        "{key} but {} is not there: build it with `cargo build --release --workspace --features {}` or set LINETRACK_BIN_DIR",
        bin.display(),
        rule.feature
    );
    Ok(bin)
}

/// The optional processes `config` turns on, in the order they start (the recorder, the
/// ROS 2 output, the link); a binary the config needs and that is not there is refused.
pub(crate) fn processes(
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
        require_binary(&RECORDER, bin_dir, "[record] mcap = true")?;
        tracing::info!("recording into {}", config.record.file(run_dir).display());
        let settings = Settings {
            bin_dir: bin_dir.to_path_buf(),
            args: in_run_dir.clone(),
            ready_timeout: Duration::from_millis(config.record.startup_timeout_ms),
            grace: Duration::from_millis(config.record.close_timeout_ms),
        };
        processes.push(OptionalProcess::new(RECORDER, settings, supervisor));
    }
    if config.ros2.enabled {
        require_binary(&ROS2, bin_dir, "ros2.enabled = true")?;
        let settings = Settings {
            bin_dir: bin_dir.to_path_buf(),
            args: in_run_dir.clone(),
            ready_timeout: Duration::from_millis(supervisor.startup_timeout_ms),
            grace,
        };
        processes.push(OptionalProcess::new(ROS2, settings, supervisor));
    }
    if config.link.enabled && mode == Mode::Processes {
        let settings = Settings {
            bin_dir: bin_dir.to_path_buf(),
            args: in_run_dir,
            ready_timeout: Duration::ZERO,
            grace,
        };
        processes.push(OptionalProcess::new(LINK, settings, supervisor));
    }
    Ok(processes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::Clock;
    use linetrack_test_data::Scratch;

    fn monitor(dir: &Path) -> Monitor {
        let config = linetrack_pipeline_config::PipelineConfig::default();
        Monitor::new(&config, 0, dir).unwrap_or_else(|e| panic!("{e}"))
    }

    fn settings(dir: &Path) -> Settings {
        Settings {
            bin_dir: dir.to_path_buf(),
            args: Vec::new(),
            ready_timeout: Duration::from_secs(10),
            grace: Duration::from_secs(3),
        }
    }

    /// A scratch folder, a monitor recording into it and a manual clock. The folder comes
    /// first so that it is dropped last, after the monitor and the processes.
    fn setup(name: &str) -> (Scratch, Monitor, Clock) {
        let dir = Scratch::new("supervisor", name);
        let monitor = monitor(&dir);
        (dir, monitor, Clock::manual(0))
    }

    /// `rule`'s process started with `command` at the clock's time.
    fn started(
        rule: Rule,
        command: Command,
        dir: &Path,
        clock: &Clock,
        monitor: &mut Monitor,
    ) -> OptionalProcess {
        let mut p = OptionalProcess::new(rule, settings(dir), &SupervisorConfig::default());
        assert!(p.wants_start(clock.monotonic()));
        p.supervise(Some(command), clock.monotonic(), monitor);
        p
    }

    /// `events.csv` once the monitor's writer has written every event recorded so far.
    fn events_of(monitor: &Monitor, dir: &Path) -> String {
        monitor.flush_records();
        std::fs::read_to_string(dir.join("events.csv")).unwrap_or_default()
    }

    fn sh(script: &str) -> Command {
        let mut command = Command::new("sh");
        command.arg("-c").arg(script);
        command
    }

    /// Waits for the child's exit (a real process's, not on the manual clock), then lets
    /// the handler see it.
    fn reap(p: &mut OptionalProcess, clock: &Clock, monitor: &mut Monitor) {
        if let Some(r) = &mut p.running {
            let _ = r.child.wait();
        }
        p.supervise(None, clock.monotonic(), monitor);
        assert_eq!(p.pid(), None);
    }

    #[test]
    fn a_restarting_process_comes_back_after_its_backoff_and_is_given_up_past_its_limit() {
        let (dir, mut monitor, clock) = setup("optional-restart");
        let config = SupervisorConfig {
            restart_backoff_ms: 100,
            restart_backoff_max_ms: 150,
            max_restarts: 2,
            ..SupervisorConfig::default()
        };
        let mut link = OptionalProcess::new(LINK, settings(&dir), &config);
        let mut starts = 0;
        for _ in 0..3 {
            assert!(link.wants_start(clock.monotonic()));
            link.supervise(Some(sh("exit 3")), clock.monotonic(), &mut monitor);
            starts += 1;
            assert!(link.pid().is_some());
            reap(&mut link, &clock, &mut monitor);
            assert!(
                !link.wants_start(clock.monotonic()),
                "not before its backoff"
            );
            clock.advance(Duration::from_millis(150));
        }
        assert_eq!(starts, 3);
        assert!(!link.wants_start(clock.monotonic()), "given up");
        let events = events_of(&monitor, &dir);
        assert_eq!(events.matches("link-exit").count(), 3, "{events}");
        assert_eq!(events.matches("link-given-up").count(), 1, "{events}");
        assert!(events.contains("restart 1 of 2 in 100ms"), "{events}");
        assert!(events.contains("restart 2 of 2 in 150ms"), "{events}");
        assert!(events.contains("exit status: 3"), "{events}");
    }

    /// The rules say what the declaration says: the link restarted, the others left.
    #[test]
    fn the_rules_restart_and_binary_are_the_declarations() {
        for (rule, stage) in [
            (ROS2, StageKind::Ros2Bridge),
            (RECORDER, StageKind::Recorder),
            (LINK, StageKind::Link),
        ] {
            let node = declared(stage);
            assert_eq!((rule.binary, rule.restart), (node.binary, node.restart));
        }
        assert_eq!(LINK.restart, Restart::Output);
        assert_eq!(RECORDER.restart, Restart::Never);
        assert_eq!(ROS2.restart, Restart::Never);
    }

    /// The link declared without restarts is left at its first exit.
    #[test]
    fn a_process_declared_without_restarts_is_left_at_its_first_exit() {
        let (dir, mut monitor, clock) = setup("optional-never");
        let rule = Rule {
            restart: Restart::Never,
            ..LINK
        };
        let mut link = OptionalProcess::new(rule, settings(&dir), &SupervisorConfig::default());
        assert!(link.wants_start(clock.monotonic()));
        link.supervise(Some(sh("exit 3")), clock.monotonic(), &mut monitor);
        reap(&mut link, &clock, &mut monitor);
        clock.advance(Duration::from_secs(60));
        assert!(!link.wants_start(clock.monotonic()), "left");
        let events = events_of(&monitor, &dir);
        assert_eq!(events.matches("link-exit").count(), 1, "{events}");
        assert!(!events.contains("restart 1"), "{events}");
    }

    #[test]
    fn a_process_that_is_not_restarted_is_recorded_and_left() {
        let (dir, mut monitor, clock) = setup("optional-left");
        let mut recorder = started(RECORDER, sh("exit 9"), &dir, &clock, &mut monitor);
        assert!(
            !recorder.settled(clock.monotonic(), &mut monitor),
            "not ready yet"
        );
        reap(&mut recorder, &clock, &mut monitor);
        clock.advance(Duration::from_secs(3600));
        assert!(!recorder.wants_start(clock.monotonic()));
        assert!(
            recorder.settled(clock.monotonic(), &mut monitor),
            "gone: no wait"
        );
        let events = events_of(&monitor, &dir);
        assert!(
            events.contains("recorder-exit")
                && events.contains("exit status: 9")
                && events.contains("without a recording"),
            "{events}"
        );
        // A binary that cannot be started is recorded the same way.
        let no_binary = Command::new(dir.join("no-such-binary"));
        let mut ros2 = started(ROS2, no_binary, &dir, &clock, &mut monitor);
        assert!(!ros2.wants_start(clock.monotonic()));
        assert!(
            events_of(&monitor, &dir).contains("output-failed"),
            "{}",
            events_of(&monitor, &dir)
        );
    }

    #[test]
    fn the_source_waits_for_readiness_up_to_the_ready_timeout_only() {
        let (dir, mut monitor, clock) = setup("optional-ready");
        let mut ros2 = started(ROS2, sh("exec sleep 30"), &dir, &clock, &mut monitor);
        clock.advance(Duration::from_secs(10));
        assert!(!ros2.settled(clock.monotonic(), &mut monitor));
        clock.advance(Duration::from_millis(1));
        assert!(ros2.settled(clock.monotonic(), &mut monitor));
        assert!(events_of(&monitor, &dir).contains("output-not-ready"));
        // The link does not gate the source at all.
        let link = OptionalProcess::new(LINK, settings(&dir), &SupervisorConfig::default());
        assert!(link.settled);
        ros2.stop(&clock, &mut monitor);
    }

    #[test]
    fn a_missing_binary_is_refused_saying_how_to_build_it() {
        let dir = Scratch::new("supervisor", "optional-binary");
        let err = require_binary(&ROS2, &dir, "ros2.enabled = true")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.starts_with("ros2.enabled = true but")
                && err.contains("linetrack-ros2 is not there")
                && err.contains("--features linetrack-ros2-bridge/ros2"),
            "{err}"
        );
        std::fs::write(dir.join(ROS2.binary), "").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            require_binary(&ROS2, &dir, "ros2.enabled = true").ok(),
            Some(dir.join(ROS2.binary))
        );
    }

    #[test]
    fn a_process_that_ignores_the_stop_is_killed_after_its_grace() {
        let (dir, mut monitor, clock) = setup("optional-grace");
        // Ignores SIGTERM (it says so once the trap is set); the grace runs on the manual
        // clock (each poll moves it 20 ms).
        let mut command = sh("trap '' TERM; echo trapped; while :; do sleep 0.1; done");
        command.stdout(std::process::Stdio::piped());
        let mut ros2 = started(ROS2, command, &dir, &clock, &mut monitor);
        let stdout = ros2
            .running
            .as_mut()
            .and_then(|r| r.child.stdout.take())
            .unwrap_or_else(|| panic!("no stdout"));
        let mut line = String::new();
        std::io::BufRead::read_line(&mut std::io::BufReader::new(stdout), &mut line)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(line, "trapped\n");
        let before = clock.monotonic();
        ros2.stop(&clock, &mut monitor);
        let waited = clock.monotonic() - before;
        assert!(
            waited >= Duration::from_secs(3) && waited <= Duration::from_millis(3020),
            "{waited:?}"
        );
        let events = events_of(&monitor, &dir);
        assert!(
            events.contains("output-killed") && events.contains("did not stop within 3s"),
            "{events}"
        );
    }
}
