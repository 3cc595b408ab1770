//! The supervisor's time, and the timers that read it.
//!
//! Every timer of the supervisor (a stage's hang and startup timeouts, restart backoff,
//! the drain after the last frame, the status period, an optional process's grace) reads a
//! [`Clock`] instead of `Instant::now()`, so that tests move time by hand
//! ([`ManualClock`]) and never sleep or measure. The idea is the stage runtime's
//! `linetrack_msgs::Clock`; that one reads UNIX-epoch nanoseconds for the frames' stamps,
//! this one is monotonic (a wall-clock step must not make a stage look hung).
//!
//! Times are [`Duration`]s since the clock's origin.

use linetrack_pipeline_config::SupervisorConfig;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Where the supervisor's timers read the time.
pub trait Clock: Send + Sync {
    /// Time since the clock's origin; never goes back.
    fn now(&self) -> Duration;
    /// Waits `period` between two polls (a manual clock moves on by it instead).
    fn pause(&self, period: Duration);
}

/// The monotonic system clock.
#[derive(Debug, Clone, Copy)]
pub struct SystemClock {
    origin: Instant,
}

impl Default for SystemClock {
    fn default() -> Self {
        Self {
            origin: Instant::now(),
        }
    }
}

impl Clock for SystemClock {
    fn now(&self) -> Duration {
        self.origin.elapsed()
    }

    fn pause(&self, period: Duration) {
        std::thread::sleep(period);
    }
}

/// A clock that stands still until [`ManualClock::advance`] (or a
/// [`Clock::pause`]) moves it; clones share the time.
#[derive(Debug, Clone, Default)]
pub struct ManualClock {
    nanos: Arc<AtomicU64>,
}

impl ManualClock {
    /// Moves the clock on by `by`.
    pub fn advance(&self, by: Duration) {
        let ns = u64::try_from(by.as_nanos()).unwrap_or(u64::MAX);
        self.nanos.fetch_add(ns, Ordering::SeqCst);
    }
}

impl Clock for ManualClock {
    fn now(&self) -> Duration {
        Duration::from_nanos(self.nanos.load(Ordering::SeqCst))
    }

    fn pause(&self, period: Duration) {
        self.advance(period);
    }
}

/// Restarts of one process: exponential backoff from `restart_backoff_ms`, doubling per
/// restart, capped at `restart_backoff_max_ms`, up to `max_restarts`.
#[derive(Debug, Clone, Copy)]
pub struct Backoff {
    first: Duration,
    max: Duration,
    limit: u32,
    count: u32,
    due: Option<Duration>,
}

/// A process that died once more than its restart limit allows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GivenUp {
    /// How many times it died.
    pub deaths: u32,
    /// The limit.
    pub limit: u32,
}

impl Backoff {
    /// The backoff of `[supervisor]`.
    pub fn new(config: &SupervisorConfig) -> Self {
        Self {
            first: Duration::from_millis(config.restart_backoff_ms),
            max: Duration::from_millis(config.restart_backoff_max_ms),
            limit: config.max_restarts,
            count: 0,
            due: None,
        }
    }

    /// Restarts so far.
    pub fn count(&self) -> u32 {
        self.count
    }

    /// The restart limit.
    pub fn limit(&self) -> u32 {
        self.limit
    }

    /// The delay before the next restart: the first delay doubled per restart so far,
    /// capped.
    pub fn delay(&self) -> Duration {
        self.first
            .saturating_mul(1 << self.count.min(16))
            .min(self.max)
    }

    /// The process died at `now`: its restart is due after [`Backoff::delay`], or it is
    /// past its limit.
    pub fn schedule(&mut self, now: Duration) -> Result<Duration, GivenUp> {
        if self.count >= self.limit {
            return Err(GivenUp {
                deaths: self.count + 1,
                limit: self.limit,
            });
        }
        let delay = self.delay();
        self.due = Some(now.saturating_add(delay));
        Ok(delay)
    }

    /// Whether a restart is scheduled and not yet due.
    pub fn pending(&self) -> bool {
        self.due.is_some()
    }

    /// Whether a scheduled restart is due at `now`; if so it is counted (the caller starts
    /// the process) and its number returned.
    pub fn take_due(&mut self, now: Duration) -> Option<u32> {
        let due = self.due?;
        if now < due {
            return None;
        }
        self.due = None;
        self.count += 1;
        Some(self.count)
    }
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
        let clock = ManualClock::default();
        let watchdog = Watchdog::new(&config());
        clock.advance(Duration::from_secs(7));
        let last_seen = clock.now();
        clock.advance(3000 * MS);
        assert_eq!(
            watchdog.overdue(last_seen, clock.now(), true),
            None,
            "exactly the timeout is not more than it"
        );
        clock.advance(MS);
        assert_eq!(
            watchdog.overdue(last_seen, clock.now(), true),
            Some(3001 * MS)
        );
        // Before it is ready, the startup timeout applies.
        assert_eq!(watchdog.overdue(last_seen, clock.now(), false), None);
        clock.advance(27_000 * MS);
        assert_eq!(
            watchdog.overdue(last_seen, clock.now(), false),
            Some(30_001 * MS)
        );
        // A report in between starts the silence again.
        let last_seen = clock.now();
        clock.advance(2999 * MS);
        assert_eq!(watchdog.overdue(last_seen, clock.now(), true), None);
    }

    #[test]
    fn backoff_doubles_per_restart_caps_and_gives_up_past_the_limit() {
        let clock = ManualClock::default();
        let mut backoff = Backoff::new(&config());
        let mut delays = Vec::new();
        for restart in 1..=5 {
            let delay = backoff
                .schedule(clock.now())
                .unwrap_or_else(|e| panic!("{e:?}"));
            delays.push(delay.as_millis());
            clock.advance(delay - MS);
            assert_eq!(backoff.take_due(clock.now()), None, "not due a ms early");
            assert!(backoff.pending());
            clock.advance(MS);
            assert_eq!(backoff.take_due(clock.now()), Some(restart));
            assert_eq!(backoff.take_due(clock.now()), None, "counted once");
        }
        assert_eq!(delays, [200, 400, 800, 1000, 1000]);
        assert_eq!(
            backoff.schedule(clock.now()),
            Err(GivenUp {
                deaths: 6,
                limit: 5
            })
        );
    }

    #[test]
    fn a_huge_backoff_saturates_instead_of_overflowing() {
        let mut backoff = Backoff::new(&SupervisorConfig {
            restart_backoff_ms: 600_000,
            restart_backoff_max_ms: 600_000,
            max_restarts: 1000,
            ..config()
        });
        for _ in 0..40 {
            let now = Duration::MAX - Duration::from_secs(1);
            assert_eq!(backoff.schedule(now), Ok(Duration::from_secs(600)));
            assert_eq!(backoff.take_due(Duration::MAX), Some(backoff.count()));
        }
    }

    #[test]
    fn the_drain_ends_at_its_timeout_counted_from_when_it_started() {
        let clock = ManualClock::default();
        clock.advance(Duration::from_secs(60));
        let mut drain = Timeout::new(5000 * MS);
        assert!(!drain.expired(clock.now()), "starts now");
        clock.advance(5000 * MS);
        assert!(!drain.expired(clock.now()));
        clock.advance(MS);
        assert!(drain.expired(clock.now()));
        let mut none = Timeout::new(Duration::ZERO);
        assert!(!none.expired(clock.now()));
        clock.advance(MS);
        assert!(none.expired(clock.now()));
    }

    #[test]
    fn a_periodic_task_is_due_once_per_period() {
        let clock = ManualClock::default();
        let mut every = Every::new(1000 * MS);
        let mut due = 0;
        for _ in 0..3500 {
            due += usize::from(every.due(clock.now()));
            clock.advance(MS);
        }
        assert_eq!(due, 4, "at 0, 1, 2 and 3 s");
    }
}
