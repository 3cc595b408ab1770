//! The supervisor's timers.
//!
//! Every timer of the supervisor (a stage's hang and startup timeouts, restart backoff,
//! the drain after the last frame, the status period, an optional process's grace) takes
//! its time from the stage runtime's [`Clock`] ([`Clock::monotonic`]: a wall-clock step
//! must not make a stage look hung) instead of `Instant::now()`, so that tests move time by
//! hand ([`Clock::manual`]) and never sleep or measure.
//!
//! Times are [`Duration`]s since the clock's origin.

use linetrack_pipeline_config::SupervisorConfig;
pub use linetrack_stage_runtime::{Backoff, Clock, GivenUp};
use std::time::Duration;

/// The restarts of one process by `[supervisor]`: exponential backoff from
/// `restart_backoff_ms`, doubling per restart, capped at `restart_backoff_max_ms`, up to
/// `max_restarts`.
pub fn restart_backoff(config: &SupervisorConfig) -> Backoff {
    Backoff::new(
        Duration::from_millis(config.restart_backoff_ms),
        Duration::from_millis(config.restart_backoff_max_ms),
    )
    .with_limit(config.max_restarts)
}

/// How long a stage may stay silent: `startup_timeout_ms` until it is ready, then
/// `hang_timeout_ms` between two reports.
#[derive(Debug, Clone, Copy)]
pub struct Watchdog {
    hang: Duration,
    startup: Duration,
}

impl Watchdog {
    /// The timeouts of `[supervisor]`.
    pub fn new(config: &SupervisorConfig) -> Self {
        Self {
            hang: Duration::from_millis(config.hang_timeout_ms),
            startup: Duration::from_millis(config.startup_timeout_ms),
        }
    }

    /// How long a stage silent since `last_seen` has been silent at `now`, when that is
    /// longer than it may be.
    pub fn overdue(&self, last_seen: Duration, now: Duration, ready: bool) -> Option<Duration> {
        let silent = now.saturating_sub(last_seen);
        let limit = if ready { self.hang } else { self.startup };
        (silent > limit).then_some(silent)
    }
}

/// A timeout that starts the first time it is asked about (the drain after the source's
/// last frame).
#[derive(Debug, Clone, Copy)]
pub struct Timeout {
    length: Duration,
    since: Option<Duration>,
}

impl Timeout {
    /// A timeout of `length`, not started.
    pub fn new(length: Duration) -> Self {
        Self {
            length,
            since: None,
        }
    }

    /// Starts it at `now` if it has not started; whether it has run out.
    pub fn expired(&mut self, now: Duration) -> bool {
        let since = *self.since.get_or_insert(now);
        now.saturating_sub(since) > self.length
    }
}

/// Something done every `period` (the status line, `status.json`).
#[derive(Debug, Clone, Copy)]
pub struct Every {
    period: Duration,
    next: Duration,
}

impl Every {
    /// Every `period`, the first time at once.
    pub fn new(period: Duration) -> Self {
        Self {
            period,
            next: Duration::ZERO,
        }
    }

    /// Whether it is due at `now`; if so the next time is one period on.
    pub fn due(&mut self, now: Duration) -> bool {
        if now < self.next {
            return false;
        }
        self.next = now.saturating_add(self.period);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> SupervisorConfig {
        SupervisorConfig {
            hang_timeout_ms: 3000,
            startup_timeout_ms: 30_000,
            restart_backoff_ms: 200,
            restart_backoff_max_ms: 1000,
            max_restarts: 5,
            ..SupervisorConfig::default()
        }
    }

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn a_stage_silent_for_the_hang_timeout_is_hung_and_one_silent_for_less_is_not() {
        let clock = Clock::manual(0);
        let watchdog = Watchdog::new(&config());
        clock.advance(Duration::from_secs(7));
        let last_seen = clock.monotonic();
        clock.advance(3000 * MS);
        assert_eq!(
            watchdog.overdue(last_seen, clock.monotonic(), true),
            None,
            "exactly the timeout is not more than it"
        );
        clock.advance(MS);
        assert_eq!(
            watchdog.overdue(last_seen, clock.monotonic(), true),
            Some(3001 * MS)
        );
        // Before it is ready, the startup timeout applies.
        assert_eq!(watchdog.overdue(last_seen, clock.monotonic(), false), None);
        clock.advance(27_000 * MS);
        assert_eq!(
            watchdog.overdue(last_seen, clock.monotonic(), false),
            Some(30_001 * MS)
        );
        // A report in between starts the silence again.
        let last_seen = clock.monotonic();
        clock.advance(2999 * MS);
        assert_eq!(watchdog.overdue(last_seen, clock.monotonic(), true), None);
    }

    #[test]
    fn restarts_follow_the_supervisor_config() {
        let mut backoff = restart_backoff(&config());
        let mut delays = Vec::new();
        while let Ok(delay) = backoff.schedule(Duration::ZERO) {
            delays.push(delay.as_millis());
            assert_eq!(backoff.take_due(delay), Some(backoff.count()));
        }
        assert_eq!(
            delays,
            [200, 400, 800, 1000, 1000],
            "5 restarts, capped at 1 s"
        );
    }

    #[test]
    fn the_drain_ends_at_its_timeout_counted_from_when_it_started() {
        let clock = Clock::manual(0);
        clock.advance(Duration::from_secs(60));
        let mut drain = Timeout::new(5000 * MS);
        assert!(!drain.expired(clock.monotonic()), "starts now");
        clock.advance(5000 * MS);
        assert!(!drain.expired(clock.monotonic()));
        clock.advance(MS);
        assert!(drain.expired(clock.monotonic()));
        let mut none = Timeout::new(Duration::ZERO);
        assert!(!none.expired(clock.monotonic()));
        clock.advance(MS);
        assert!(none.expired(clock.monotonic()));
    }

    #[test]
    fn a_periodic_task_is_due_once_per_period() {
        let clock = Clock::manual(0);
        let mut every = Every::new(1000 * MS);
        let mut due = 0;
        for _ in 0..3500 {
            due += usize::from(every.due(clock.monotonic()));
            clock.advance(MS);
        }
        assert_eq!(due, 4, "at 0, 1, 2 and 3 s");
    }
}
