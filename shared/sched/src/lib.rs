//! Per-stage CPU affinity, scheduling policy and nice value: the `[stages.<name>]` tables
//! of `configs/pipeline.toml`.
//!
//! [`SchedSettings`] is one stage's settings, range-checked when the config is read
//! ([`SchedSettings::validate`]). [`apply`] applies them to the calling thread: a stage
//! process calls it first thing in its `main` (every thread it starts later, OpenCV's and
//! iceoryx2's included, inherits them), a thread stage (`--single-process`) first thing in
//! its thread. [`probe`] tries them on a short-lived thread, so that the supervisor refuses
//! a CPU that does not exist, and warns about a policy it may not set, before any stage
//! starts.
//!
//! What the system may refuse, and what follows:
//! - a CPU this process may not run on (absent, offline, or outside the service's
//!   `CPUAffinity=`): an error ([`SchedError::CpuUnavailable`]), the stage does not start;
//! - a real-time policy (`fifo`, `rr`) or a negative nice without the privilege
//!   (`CAP_SYS_NICE`, or `LimitRTPRIO=` / `LimitNICE=` for a systemd service): a
//!   [`Refusal`], a warning; the stage runs with the policy it inherited. A pipeline that
//!   runs with less priority is better than no pipeline on a robot, and the warning says
//!   which setting was refused and what grants it.
//! - anything else the system refuses: an error naming the stage and the setting.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::io;

mod policy;

/// The highest real-time priority Linux allows for `fifo` and `rr`.
pub const MAX_RT_PRIORITY: i32 = 99;
/// The nice range Linux allows.
pub const NICE: std::ops::RangeInclusive<i32> = -20..=19;

/// A Linux scheduling policy a stage may ask for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Policy {
    /// `SCHED_OTHER`: the normal time-sharing policy (with `nice`).
    Other,
    /// `SCHED_FIFO`: real time, runs until it blocks or a higher priority wakes.
    Fifo,
    /// `SCHED_RR`: real time, round robin among equal priorities.
    Rr,
}

impl Policy {
    /// The name in the config (`other`, `fifo`, `rr`).
    pub fn name(self) -> &'static str {
        match self {
            Policy::Other => "other",
            Policy::Fifo => "fifo",
            Policy::Rr => "rr",
        }
    }

    /// Whether this is a real-time policy (takes a priority, not a nice value).
    pub fn is_realtime(self) -> bool {
        matches!(self, Policy::Fifo | Policy::Rr)
    }
}

/// One stage's scheduling settings; every key optional, a missing key leaves what the
/// stage inherited from the supervisor (which inherits from its service or shell).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SchedSettings {
    /// The CPUs the stage may run on, numbered as in `/proc/cpuinfo` (`[1]`, `[0, 1]`).
    pub cpus: Option<Vec<usize>>,
    /// `other`, `fifo` or `rr`.
    pub policy: Option<Policy>,
    /// The real-time priority, 1..=99, with `fifo` or `rr` (required with them).
    pub priority: Option<i32>,
    /// The nice value, -20..=19 (lower runs first), with `other` or no policy.
    pub nice: Option<i32>,
}

impl SchedSettings {
    /// Whether nothing is set (the stage keeps what it inherited).
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// The first bad value, named by its key under `prefix` (e.g. `stages.matcher`) with
    /// what is allowed.
    pub fn validate(&self, prefix: &str) -> Result<(), String> {
        if let Some(cpus) = &self.cpus {
            if cpus.is_empty() {
                return Err(format!(
                    "{prefix}.cpus = []: name at least one CPU, or leave the key out to run on every CPU"
                ));
            }
            let max = rustix::thread::CpuSet::MAX_CPU - 1;
            if let Some(cpu) = cpus.iter().find(|&&c| c > max) {
                return Err(format!(
                    "{prefix}.cpus: CPU {cpu} is out of range: allowed 0 ..= {max}"
                ));
            }
        }
        let realtime = self.policy.is_some_and(Policy::is_realtime);
        match (self.priority, realtime) {
            (Some(p), true) if !(1..=MAX_RT_PRIORITY).contains(&p) => {
                return Err(format!(
                    "{prefix}.priority = {p} is out of range: allowed 1 ..= {MAX_RT_PRIORITY}"
                ));
            }
            (None, true) => {
                return Err(format!(
                    "{prefix}.priority: policy {} needs a priority in 1 ..= {MAX_RT_PRIORITY}",
                    self.policy.map_or("", Policy::name)
                ));
            }
            (Some(p), false) => {
                return Err(format!(
                    "{prefix}.priority = {p}: a priority applies to policy \"fifo\" or \"rr\" only (use nice with \"other\")"
                ));
            }
            _ => {}
        }
        if let Some(nice) = self.nice {
            if realtime {
                return Err(format!(
                    "{prefix}.nice = {nice}: nice applies to policy \"other\" only (a real-time policy has a priority)"
                ));
            }
            if !NICE.contains(&nice) {
                return Err(format!(
                    "{prefix}.nice = {nice} is out of range: allowed {} ..= {}",
                    NICE.start(),
                    NICE.end()
                ));
            }
        }
        Ok(())
    }
}

/// Errors applying a stage's settings.
#[derive(Debug, thiserror::Error)]
pub enum SchedError {
    /// A CPU the stage names is not one this process may run on.
    #[error(
        "stages.{stage}.cpus: CPU {cpu} is not available here (this process may run on CPUs {available})"
    )]
    CpuUnavailable {
        /// The stage.
        stage: String,
        /// The CPU asked for.
        cpu: usize,
        /// The CPUs this process may run on.
        available: String,
    },
    /// The system refused a setting for a reason other than a missing privilege.
    #[error("stages.{stage}.{setting} = {value}: the system refused it")]
    Refused {
        /// The stage.
        stage: String,
        /// `cpus`, `policy` or `nice`.
        setting: &'static str,
        /// The value asked for.
        value: String,
        /// What the system said.
        source: io::Error,
    },
    /// The probe thread could not be started or died.
    #[error("stages.{stage}: cannot try the settings on a thread")]
    Probe {
        /// The stage.
        stage: String,
        /// Why.
        source: io::Error,
    },
}

/// A setting the system refused for want of a privilege: the stage goes on without it.
#[derive(Debug)]
pub struct Refusal {
    /// The stage.
    pub stage: String,
    /// `policy` or `nice`.
    pub setting: &'static str,
    /// The value asked for (`fifo, priority 10`, `-5`).
    pub value: String,
    /// What the system said (EPERM, EACCES).
    pub source: io::Error,
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let grant = match self.setting {
            "policy" => {
                "CAP_SYS_NICE, or an RLIMIT_RTPRIO at least the priority (LimitRTPRIO= in the systemd unit)"
            }
            _ => "CAP_SYS_NICE, or an RLIMIT_NICE that allows it (LimitNICE= in the systemd unit)",
        };
        write!(
            f,
            "stages.{}.{} = {} not permitted ({}): needs {grant}; the stage runs with what it inherited",
            self.stage, self.setting, self.value, self.source
        )
    }
}

/// CPU numbers as a short list: `0-3, 6`.
fn cpu_list(set: &rustix::thread::CpuSet) -> String {
    let cpus: Vec<usize> = (0..rustix::thread::CpuSet::MAX_CPU)
        .filter(|&c| set.is_set(c))
        .collect();
    let mut parts = Vec::new();
    let mut i = 0;
    while i < cpus.len() {
        let start = cpus[i];
        let mut end = start;
        while i + 1 < cpus.len() && cpus[i + 1] == end + 1 {
            i += 1;
            end = cpus[i];
        }
        parts.push(if end == start {
            start.to_string()
        } else {
            format!("{start}-{end}")
        });
        i += 1;
    }
    parts.join(", ")
}

fn is_permission(error: &io::Error) -> bool {
    matches!(
        error.raw_os_error(),
        Some(code) if code == libc::EPERM || code == libc::EACCES
    )
}

/// Applies `settings` of stage `stage` to the calling thread: the CPUs, then the policy and
/// priority, then the nice value. Returns the settings refused for want of a privilege
/// (the caller logs them); a CPU this process may not use, or any other refusal, is an
/// error naming the stage and the setting.
pub fn apply(stage: &str, settings: &SchedSettings) -> Result<Vec<Refusal>, SchedError> {
    let mut refused = Vec::new();
    if let Some(cpus) = &settings.cpus {
        let allowed = rustix::thread::sched_getaffinity(None).map_err(|e| SchedError::Refused {
            stage: stage.to_string(),
            setting: "cpus",
            value: format!("{cpus:?}"),
            source: e.into(),
        })?;
        let mut set = rustix::thread::CpuSet::new();
        for &cpu in cpus {
            if cpu >= rustix::thread::CpuSet::MAX_CPU || !allowed.is_set(cpu) {
                return Err(SchedError::CpuUnavailable {
                    stage: stage.to_string(),
                    cpu,
                    available: cpu_list(&allowed),
                });
            }
            set.set(cpu);
        }
        rustix::thread::sched_setaffinity(None, &set).map_err(|e| SchedError::Refused {
            stage: stage.to_string(),
            setting: "cpus",
            value: format!("{cpus:?}"),
            source: e.into(),
        })?;
    }
    if let Some(policy) = settings.policy {
        let priority = settings.priority.unwrap_or(0);
        let value = if policy.is_realtime() {
            format!("{}, priority {priority}", policy.name())
        } else {
            policy.name().to_string()
        };
        if let Err(source) = policy::set_this_thread(policy, priority) {
            if is_permission(&source) {
                refused.push(Refusal {
                    stage: stage.to_string(),
                    setting: "policy",
                    value,
                    source,
                });
            } else {
                return Err(SchedError::Refused {
                    stage: stage.to_string(),
                    setting: "policy",
                    value,
                    source,
                });
            }
        }
    }
    if let Some(nice) = settings.nice {
        // On Linux the nice value is a thread's: `None` (0) is the calling thread.
        if let Err(e) = rustix::process::setpriority_process(None, nice) {
            let source: io::Error = e.into();
            if is_permission(&source) {
                refused.push(Refusal {
                    stage: stage.to_string(),
                    setting: "nice",
                    value: nice.to_string(),
                    source,
                });
            } else {
                return Err(SchedError::Refused {
                    stage: stage.to_string(),
                    setting: "nice",
                    value: nice.to_string(),
                    source,
                });
            }
        }
    }
    Ok(refused)
}

/// Tries `settings` on a thread started for it (and ended at once), so that a caller learns
/// what [`apply`] would say in a stage without changing its own threads.
pub fn probe(stage: &str, settings: &SchedSettings) -> Result<Vec<Refusal>, SchedError> {
    if settings.is_empty() {
        return Ok(Vec::new());
    }
    let probe_error = |source| SchedError::Probe {
        stage: stage.to_string(),
        source,
    };
    let (name, copy) = (stage.to_string(), settings.clone());
    std::thread::Builder::new()
        .name(format!("probe-{stage}"))
        .spawn(move || apply(&name, &copy))
        .map_err(probe_error)?
        .join()
        .map_err(|_| probe_error(io::Error::other("the probe thread panicked")))?
}

#[cfg(test)]
mod tests;
