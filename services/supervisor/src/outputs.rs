//! Optional output processes the config turns on: `linetrack-ros2` (`[ros2] enabled`).
//!
//! An output reads the `poses` topic itself and reports ready on `status` (with its pid,
//! no stage code); the frame source starts once it is ready, so no pose is published
//! before it listens. It is not part of the pipeline: when it cannot start, is not ready
//! within the startup timeout or exits, that is recorded in `events.csv` and the run goes
//! on without it (no restart). At the end it gets SIGTERM after the stages have stopped,
//! publishes what is still queued, and is killed after the grace period.

use crate::monitor::Monitor;
use anyhow::Context;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

/// The ROS 2 output's binary (built with the cargo feature `ros2`).
pub const ROS2_BINARY: &str = "linetrack-ros2";
/// Its name in `events.csv`.
const ROS2_NAME: &str = "ros2";

/// The ROS 2 output's binary in `bin_dir`, refused when it is not there.
pub fn ros2_binary(bin_dir: &Path) -> anyhow::Result<PathBuf> {
    let bin = bin_dir.join(ROS2_BINARY);
    anyhow::ensure!(
        bin.is_file(),
        "ros2.enabled = true but {} is not there: build it with the ros2 feature (cargo build --release --workspace --features linetrack-ros2-bridge/ros2) or set LINETRACK_BIN_DIR",
        bin.display()
    );
    Ok(bin)
}

/// A running output process.
pub struct Output {
    child: Child,
    pid: u32,
    started: Instant,
    ready: bool,
}

impl Output {
    /// Starts `bin` with `command` (the supervisor's, for a child of this run); a failure
    /// to start is recorded and gives `None`.
    pub fn start(mut command: Command, bin: &Path, monitor: &mut Monitor) -> Option<Self> {
        match command
            .spawn()
            .with_context(|| format!("starting {}", bin.display()))
        {
            Ok(child) => {
                let pid = child.id();
                tracing::info!("started {ROS2_NAME} output (pid {pid})");
                Some(Self {
                    child,
                    pid,
                    started: Instant::now(),
                    ready: false,
                })
            }
            Err(e) => {
                monitor.event(
                    "output-failed",
                    ROS2_NAME,
                    None,
                    format!("{e:#}; the run goes on without it"),
                );
                None
            }
        }
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.pid
    }

    /// It said it is ready.
    pub fn set_ready(&mut self) {
        self.ready = true;
    }

    /// Whether the frame source may start: it is ready, or it had `startup` to get there
    /// (then it is recorded and left running).
    pub fn settled(&mut self, startup: Duration, monitor: &mut Monitor) -> bool {
        if !self.ready && self.started.elapsed() > startup {
            monitor.event(
                "output-not-ready",
                ROS2_NAME,
                None,
                format!(
                    "pid {} not ready after {startup:?}: the run starts without waiting for it",
                    self.pid
                ),
            );
            self.ready = true;
        }
        self.ready
    }

    /// Whether it is still running; an exit is recorded.
    pub fn alive(&mut self, monitor: &mut Monitor) -> bool {
        match self.child.try_wait() {
            Ok(None) => true,
            Ok(Some(status)) => {
                monitor.event(
                    "output-exit",
                    ROS2_NAME,
                    None,
                    format!(
                        "pid {} {status} after {:.1} s (its error is in the log); the run goes on without it",
                        self.pid,
                        self.started.elapsed().as_secs_f64()
                    ),
                );
                false
            }
            Err(e) => {
                tracing::warn!("cannot poll the {ROS2_NAME} output (pid {}): {e}", self.pid);
                true
            }
        }
    }

    /// Asks it to stop (SIGTERM: it publishes what is queued), waits up to `grace`, then
    /// kills it.
    pub fn stop(mut self, grace: Duration) {
        if let Ok(Some(_)) = self.child.try_wait() {
            return;
        }
        if let Some(pid) = rustix::process::Pid::from_raw(self.pid as i32) {
            let _ = rustix::process::kill_process(pid, rustix::process::Signal::TERM);
        }
        let deadline = Instant::now() + grace;
        while Instant::now() < deadline {
            if let Ok(Some(status)) = self.child.try_wait() {
                tracing::info!("{ROS2_NAME} output (pid {}) exited: {status}", self.pid);
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        tracing::warn!(
            "{ROS2_NAME} output (pid {}) did not exit in time: killing it",
            self.pid
        );
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_bridge_binary_is_refused_saying_how_to_build_it() {
        let dir = std::env::temp_dir().join(format!("ltsup-outputs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let err = ros2_binary(&dir)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains("linetrack-ros2 is not there")
                && err.contains("--features linetrack-ros2-bridge/ros2"),
            "{err}"
        );
        std::fs::write(dir.join(ROS2_BINARY), "").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(ros2_binary(&dir).ok(), Some(dir.join(ROS2_BINARY)));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
