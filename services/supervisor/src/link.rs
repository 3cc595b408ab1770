//! The ground-station link's process (`linetrack-link`, when `[link] enabled`): started with
//! the stages, restarted with the stages' backoff when it exits (up to the same limit),
//! stopped after them so that it forwards the last frames. Nothing of the run waits for it:
//! a link that cannot start or keeps failing is recorded in `events.csv` and the run goes
//! on without it.

use crate::monitor::Monitor;
use linetrack_pipeline_config::SupervisorConfig;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

/// The link's binary name.
pub const BINARY: &str = "linetrack-link";

/// The link process and its restarts.
pub struct LinkProcess {
    bin: PathBuf,
    child: Option<Child>,
    restarts: u32,
    due: Option<Instant>,
    given_up: bool,
}

impl LinkProcess {
    /// The link of a run whose binaries are in `bin_dir`.
    pub fn new(bin_dir: &Path) -> Self {
        Self {
            bin: bin_dir.join(BINARY),
            child: None,
            restarts: 0,
            due: Some(Instant::now()),
            given_up: false,
        }
    }

    /// The binary.
    pub fn binary(&self) -> &Path {
        &self.bin
    }

    /// Whether [`LinkProcess::supervise`] would start it now (it then needs the command).
    pub fn wants_start(&self) -> bool {
        self.child.is_none() && self.due.is_some_and(|due| Instant::now() >= due)
    }

    /// Starts it with `command` (the binary with the run's arguments) when it is due; notes
    /// its exit and schedules the restart. Called on every turn of the supervisor's loop.
    pub fn supervise(
        &mut self,
        command: Option<Command>,
        config: &SupervisorConfig,
        monitor: &mut Monitor,
    ) {
        if let Some(child) = &mut self.child {
            let Ok(Some(status)) = child.try_wait() else {
                return;
            };
            self.child = None;
            monitor.event(
                "link-exit",
                "link",
                None,
                format!("{BINARY} ended ({status}); the pipeline goes on"),
            );
            self.schedule(config, monitor);
            return;
        }
        let Some(mut command) = command.filter(|_| self.wants_start()) else {
            return;
        };
        self.due = None;
        match command.spawn() {
            Ok(child) => {
                tracing::info!("link started (pid {})", child.id());
                self.child = Some(child);
            }
            Err(e) => {
                monitor.event(
                    "link-exit",
                    "link",
                    None,
                    format!(
                        "{} cannot be started: {e} (built with `--features linetrack/link`?); the pipeline goes on",
                        self.bin.display()
                    ),
                );
                self.schedule(config, monitor);
            }
        }
    }

    fn schedule(&mut self, config: &SupervisorConfig, monitor: &mut Monitor) {
        if self.given_up {
            return;
        }
        if self.restarts >= config.max_restarts {
            self.given_up = true;
            monitor.event(
                "link-given-up",
                "link",
                None,
                format!(
                    "{BINARY} failed {} times: the run goes on without the link",
                    self.restarts + 1
                ),
            );
            return;
        }
        let backoff = config
            .restart_backoff_ms
            .saturating_mul(1 << self.restarts.min(16))
            .min(config.restart_backoff_max_ms);
        self.restarts += 1;
        self.due = Some(Instant::now() + Duration::from_millis(backoff));
    }

    /// Asks it to stop (SIGTERM: it writes its counters) and waits up to `grace`, then
    /// kills it.
    pub fn stop(&mut self, grace: Duration) {
        let Some(mut child) = self.child.take() else {
            return;
        };
        if let Some(pid) = rustix::process::Pid::from_raw(child.id() as i32) {
            let _ = rustix::process::kill_process(pid, rustix::process::Signal::TERM);
        }
        let until = Instant::now() + grace;
        while Instant::now() < until {
            if let Ok(Some(_)) = child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        tracing::warn!("{BINARY} did not exit in time: killing it");
        let _ = child.kill();
        let _ = child.wait();
    }
}
