//! The ranges the sections' keys are checked against, and the checks they share.

use std::path::Path;

/// Allowed latency budgets, milliseconds: above zero, at most a minute.
pub(crate) const BUDGET_MS: std::ops::RangeInclusive<f64> = 0.001..=60_000.0;
/// Allowed realtime rates, frames per second (0 = the sequence's own rate).
pub(crate) const RATE_HZ: std::ops::RangeInclusive<f64> = 0.01..=1000.0;
/// The most frames a run may be limited to.
pub(crate) const MAX_FRAMES: usize = 1_000_000_000;
/// The largest match and observation counts the fallback rules may name.
pub(crate) const MAX_MATCHES: u32 = 100_000;
/// Allowed streak lengths and probe periods of the fallback rules, frames.
pub(crate) const STREAK: std::ops::RangeInclusive<u32> = 1..=1000;
/// Allowed fractions of the matcher budget a recovering probe may take (below 1: hysteresis).
pub(crate) const RECOVER_BUDGET_FRACTION: std::ops::RangeInclusive<f64> = 0.05..=0.95;
/// Allowed heartbeat periods, milliseconds.
pub(crate) const HEARTBEAT_MS: std::ops::RangeInclusive<u64> = 10..=10_000;
/// The shortest startup timeout, milliseconds (a stage loads its detector first).
pub(crate) const MIN_STARTUP_MS: u64 = 100;
/// The longest timeout, backoff, drain or grace period, milliseconds (10 minutes).
pub(crate) const MAX_WAIT_MS: u64 = 600_000;
/// The longest image period of the link, frames.
pub(crate) const MAX_STREAK_FRAMES: u32 = 10_000;
/// The most restarts per stage.
pub(crate) const MAX_RESTARTS: u32 = 1000;
/// The longest camera run, seconds (a year).
pub(crate) const MAX_DURATION_S: f64 = 31_536_000.0;
/// The longest live-status period, milliseconds (an hour).
pub(crate) const MAX_STATUS_EVERY_MS: u64 = 3_600_000;

/// `key = value` inside `range`, or an error naming both (NaN is never inside).
pub(crate) fn in_range<T: PartialOrd + std::fmt::Debug>(
    key: &str,
    value: T,
    range: std::ops::RangeInclusive<T>,
) -> Result<(), String> {
    if range.contains(&value) {
        Ok(())
    } else {
        Err(format!(
            "{key} = {value:?} is out of range: allowed {:?} ..= {:?}",
            range.start(),
            range.end()
        ))
    }
}

/// The keys of a policy that switches with hysteresis (the matcher's fallback, the
/// detector's): its streaks of frames and its recovery fraction of a budget.
pub(crate) fn check_hysteresis(
    table: &str,
    streaks: &[(&str, u32)],
    recover_budget_fraction: f64,
) -> Result<(), String> {
    for &(key, frames) in streaks {
        in_range(&format!("{table}.{key}"), frames, STREAK)?;
    }
    in_range(
        &format!("{table}.recover_budget_fraction"),
        recover_budget_fraction,
        RECOVER_BUDGET_FRACTION,
    )
}

/// An error for `key = ""` (an empty path would be the current folder); unset is fine.
pub(crate) fn not_empty_path(key: &str, path: Option<&Path>) -> Result<(), String> {
    if path.is_some_and(|p| p.as_os_str().is_empty()) {
        return Err(format!(
            "{key} = \"\": an empty path would be the current folder; leave the key out for the default"
        ));
    }
    Ok(())
}
