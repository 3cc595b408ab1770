//! The pipeline's one clock and one backoff.
//!
//! [`Clock`] is what every timer and stamp reads: the system's time, or in tests a clock
//! that moves only when told ([`Clock::manual`], [`Clock::advance`]), so that a test of a
//! policy (frame ages, budgets, heartbeats, hang detection, restart backoff) does not depend
//! on how loaded the machine is. It reads two times: [`Clock::now_ns`], UNIX-epoch
//! nanoseconds for the frames' stamps, and [`Clock::monotonic`], which a wall-clock step
//! does not move (the supervisor's timers: a step must not make a stage look hung).
//!
//! [`Backoff`] is the exponential backoff of every retry: the supervisor's restarts of a
//! stage or an optional process (scheduled at a time, up to a limit), and the camera's
//! reopening (a wait per attempt, reset by a success).

use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// The time the pipeline's policies read: the system's, or a manual one in tests.
#[derive(Debug, Clone, Default)]
pub enum Clock {
    /// The system's clocks.
    #[default]
    System,
    /// A clock that stands still until [`Clock::advance`] (or [`Clock::pause`]) moves it;
    /// clones share the time. Its epoch nanoseconds and its monotonic time are the same
    /// count.
    Manual(Arc<AtomicU64>),
}

/// The origin of the system's monotonic time: the first time this process read it.
fn origin() -> Instant {
    static ORIGIN: OnceLock<Instant> = OnceLock::new();
    *ORIGIN.get_or_init(Instant::now)
}

impl Clock {
    /// A manual clock reading `start_ns`.
    pub fn manual(start_ns: u64) -> Self {
        Clock::Manual(Arc::new(AtomicU64::new(start_ns)))
    }

    /// Now, UNIX-epoch nanoseconds.
    pub fn now_ns(&self) -> u64 {
        match self {
            Clock::System => linetrack_msgs::now_ns(),
            Clock::Manual(t) => t.load(Ordering::SeqCst),
        }
    }

    /// Monotonic time since the clock's origin (for the system's, this process's first
    /// reading); never goes back.
    pub fn monotonic(&self) -> Duration {
        match self {
            Clock::System => origin().elapsed(),
            Clock::Manual(t) => Duration::from_nanos(t.load(Ordering::SeqCst)),
        }
    }

    /// Moves a manual clock on (the system clock moves by itself).
    pub fn advance(&self, by: Duration) {
        if let Clock::Manual(t) = self {
            let ns = u64::try_from(by.as_nanos()).unwrap_or(u64::MAX);
            t.fetch_add(ns, Ordering::SeqCst);
        }
    }

    /// Waits `period` between two polls (a manual clock moves on by it instead).
    pub fn pause(&self, period: Duration) {
        match self {
            Clock::System => std::thread::sleep(period),
            Clock::Manual(_) => self.advance(period),
        }
    }

    /// Time since `earlier_ns` (zero if that is in the future).
    pub fn since(&self, earlier_ns: u64) -> Duration {
        Duration::from_nanos(self.now_ns().saturating_sub(earlier_ns))
    }
}

/// An exponential backoff: `first`, doubling per attempt, capped at `max`; optionally up
/// to a limit of attempts. Use it either as waits ([`Backoff::next_wait`], back to `first`
/// on [`Backoff::reset`]) or as a schedule ([`Backoff::schedule`] at a failure,
/// [`Backoff::take_due`] when the retry is due).
#[derive(Debug, Clone, Copy)]
pub struct Backoff {
    first: Duration,
    max: Duration,
    limit: u32,
    count: u32,
    due: Option<Duration>,
}

/// A process that failed once more than its limit allows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GivenUp {
    /// How many times it failed.
    pub deaths: u32,
    /// The limit.
    pub limit: u32,
}

impl Backoff {
    /// A backoff from `first` to `max` (at least `first`), without a limit.
    pub fn new(first: Duration, max: Duration) -> Self {
        Self {
            first,
            max: max.max(first),
            limit: u32::MAX,
            count: 0,
            due: None,
        }
    }

    /// The same, giving up after `limit` retries.
    pub fn with_limit(self, limit: u32) -> Self {
        Self { limit, ..self }
    }

    /// Retries so far.
    pub fn count(&self) -> u32 {
        self.count
    }

    /// The limit of retries.
    pub fn limit(&self) -> u32 {
        self.limit
    }

    /// The delay before the next retry: the first delay doubled per retry so far, capped.
    pub fn delay(&self) -> Duration {
        self.first
            .saturating_mul(1 << self.count.min(16))
            .min(self.max)
    }

    /// The wait before the next attempt, and the attempt's number (1-based).
    pub fn next_wait(&mut self) -> (Duration, u64) {
        let wait = self.delay();
        self.count = self.count.saturating_add(1);
        (wait, u64::from(self.count))
    }

    /// After a success: the next wait is the first again.
    pub fn reset(&mut self) {
        self.count = 0;
        self.due = None;
    }

    /// A failure at `now`: the retry is due after [`Backoff::delay`], or it is past its
    /// limit.
    pub fn schedule(&mut self, now: Duration) -> Result<Duration, GivenUp> {
        if self.count >= self.limit {
            return Err(GivenUp {
                deaths: self.count.saturating_add(1),
                limit: self.limit,
            });
        }
        let delay = self.delay();
        self.due = Some(now.saturating_add(delay));
        Ok(delay)
    }

    /// Whether a retry is scheduled and not yet due.
    pub fn pending(&self) -> bool {
        self.due.is_some()
    }

    /// Whether a scheduled retry is due at `now`; if so it is counted (the caller retries)
    /// and its number returned.
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

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn a_manual_clock_moves_only_when_told_and_clones_share_it() {
        let clock = Clock::manual(5_000);
        let shared = clock.clone();
        assert_eq!((clock.now_ns(), clock.monotonic()), (5_000, 5 * MS / 1000));
        shared.advance(2 * MS);
        shared.pause(MS);
        assert_eq!(clock.monotonic(), 3 * MS + Duration::from_nanos(5_000));
        assert_eq!(clock.since(5_000), 3 * MS);
        assert_eq!(clock.since(u64::MAX), Duration::ZERO, "a future time");
        let system = Clock::System;
        let before = system.monotonic();
        system.advance(Duration::from_secs(3600));
        assert!(system.monotonic() < before + Duration::from_secs(3600));
    }

    #[test]
    fn waits_double_to_their_maximum_and_reset() {
        let mut b = Backoff::new(100 * MS, 350 * MS);
        let waits: Vec<(u128, u64)> = (0..4)
            .map(|_| {
                let (w, n) = b.next_wait();
                (w.as_millis(), n)
            })
            .collect();
        assert_eq!(waits, [(100, 1), (200, 2), (350, 3), (350, 4)]);
        b.reset();
        assert_eq!(b.next_wait(), (100 * MS, 1));
        // A maximum below the first wait is the first wait.
        let mut low = Backoff::new(100 * MS, 10 * MS);
        assert_eq!(low.next_wait().0, 100 * MS);
        assert_eq!(low.next_wait().0, 100 * MS);
    }

    #[test]
    fn a_schedule_doubles_per_retry_caps_and_gives_up_past_the_limit() {
        let clock = Clock::manual(0);
        let mut backoff = Backoff::new(200 * MS, 1000 * MS).with_limit(5);
        let mut delays = Vec::new();
        for retry in 1..=5 {
            let delay = backoff
                .schedule(clock.monotonic())
                .unwrap_or_else(|e| panic!("{e:?}"));
            delays.push(delay.as_millis());
            clock.advance(delay - MS);
            assert_eq!(
                backoff.take_due(clock.monotonic()),
                None,
                "not due a ms early"
            );
            assert!(backoff.pending());
            clock.advance(MS);
            assert_eq!(backoff.take_due(clock.monotonic()), Some(retry));
            assert_eq!(backoff.take_due(clock.monotonic()), None, "counted once");
        }
        assert_eq!(delays, [200, 400, 800, 1000, 1000]);
        assert_eq!(
            backoff.schedule(clock.monotonic()),
            Err(GivenUp {
                deaths: 6,
                limit: 5
            })
        );
    }

    #[test]
    fn a_huge_backoff_saturates_instead_of_overflowing() {
        let mut backoff =
            Backoff::new(Duration::from_secs(600), Duration::from_secs(600)).with_limit(1000);
        for _ in 0..40 {
            let now = Duration::MAX - Duration::from_secs(1);
            assert_eq!(backoff.schedule(now), Ok(Duration::from_secs(600)));
            assert_eq!(backoff.take_due(Duration::MAX), Some(backoff.count()));
        }
        let mut waits = Backoff::new(Duration::from_secs(600), Duration::from_secs(600));
        for _ in 0..40 {
            assert_eq!(waits.next_wait().0, Duration::from_secs(600));
        }
    }
}
