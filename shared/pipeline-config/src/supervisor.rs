//! `[supervisor]`: heartbeats, hang and start-up timeouts, restarts, draining and stopping.

use crate::limits::{
    HEARTBEAT_MS, MAX_RESTARTS, MAX_STATUS_EVERY_MS, MAX_WAIT_MS, MIN_STARTUP_MS, in_range,
};
use serde::{Deserialize, Serialize};

/// Supervision.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SupervisorConfig {
    /// Stages report alive this often.
    pub heartbeat_ms: u64,
    /// A stage silent this long is hung: it is killed and restarted.
    pub hang_timeout_ms: u64,
    /// Stages must report ready within this.
    pub startup_timeout_ms: u64,
    /// First restart delay; doubles on each restart of the same stage.
    pub restart_backoff_ms: u64,
    /// Longest restart delay.
    pub restart_backoff_max_ms: u64,
    /// Restarts per stage before the run is abandoned.
    pub max_restarts: u32,
    /// After the source finishes, wait this long for the last poses.
    pub drain_timeout_ms: u64,
    /// On shutdown, wait this long for a stage to exit before killing it.
    pub shutdown_grace_ms: u64,
    /// Print a live status line this often (0 = never).
    pub status_every_ms: u64,
}

impl Default for SupervisorConfig {
    fn default() -> Self {
        Self {
            heartbeat_ms: 200,
            hang_timeout_ms: 3000,
            startup_timeout_ms: 30_000,
            restart_backoff_ms: 200,
            restart_backoff_max_ms: 5000,
            max_restarts: 5,
            drain_timeout_ms: 5000,
            shutdown_grace_ms: 3000,
            status_every_ms: 1000,
        }
    }
}

impl SupervisorConfig {
    /// The first out-of-range key of `[supervisor]`.
    pub fn validate(&self) -> Result<(), String> {
        in_range("supervisor.heartbeat_ms", self.heartbeat_ms, HEARTBEAT_MS)?;
        in_range(
            "supervisor.hang_timeout_ms",
            self.hang_timeout_ms,
            2 * self.heartbeat_ms + 1..=MAX_WAIT_MS,
        )
        .map_err(|e| format!("{e}: more than twice heartbeat_ms"))?;
        in_range(
            "supervisor.startup_timeout_ms",
            self.startup_timeout_ms,
            MIN_STARTUP_MS..=MAX_WAIT_MS,
        )?;
        in_range(
            "supervisor.restart_backoff_ms",
            self.restart_backoff_ms,
            1..=MAX_WAIT_MS,
        )?;
        in_range(
            "supervisor.restart_backoff_max_ms",
            self.restart_backoff_max_ms,
            self.restart_backoff_ms..=MAX_WAIT_MS,
        )
        .map_err(|e| format!("{e}: at least restart_backoff_ms"))?;
        in_range(
            "supervisor.max_restarts",
            self.max_restarts,
            0..=MAX_RESTARTS,
        )?;
        in_range(
            "supervisor.drain_timeout_ms",
            self.drain_timeout_ms,
            0..=MAX_WAIT_MS,
        )?;
        in_range(
            "supervisor.shutdown_grace_ms",
            self.shutdown_grace_ms,
            0..=MAX_WAIT_MS,
        )?;
        in_range(
            "supervisor.status_every_ms",
            self.status_every_ms,
            0..=MAX_STATUS_EVERY_MS,
        )
    }
}
