//! How a stage instance runs: a child process, or (single-process mode) a thread of the
//! supervisor's process running the same code its process's `main` runs.

use linetrack_ipc::Shutdown;
use std::process::Child;

/// Ids of thread stages start here (above any Linux pid), so that commands and status
/// reports name each instance as they name processes.
pub const THREAD_IDS: u32 = 1 << 30;

/// How a stage instance runs: a child process, or a thread of this process.
pub(crate) enum Launch {
    Process(Child),
    Thread {
        handle: Option<std::thread::JoinHandle<anyhow::Result<()>>>,
        stop: Shutdown,
    },
}

impl Launch {
    /// How it ended, if it has: a description and whether it succeeded.
    pub(crate) fn try_wait(&mut self) -> Result<Option<(String, bool)>, std::io::Error> {
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
    pub(crate) fn kill(&mut self) {
        match self {
            Launch::Process(child) => {
                let _ = child.kill();
            }
            Launch::Thread { stop, .. } => stop.request(),
        }
    }

    /// Reaps a process; a thread that has not ended is left behind.
    pub(crate) fn reap(&mut self) {
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
