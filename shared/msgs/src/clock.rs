//! The clock the pipeline's policies read: the system's, or a manual one in tests.

/// The time the pipeline's policies read (frame ages, budgets, heartbeats, hang detection):
/// the system's wall clock, or in tests a clock that moves only when told, so that a test of
/// a policy does not depend on how loaded the machine is.
#[derive(Debug, Clone, Default)]
pub enum Clock {
    /// UNIX-epoch nanoseconds from the system.
    #[default]
    System,
    /// A clock that stands still until [`Clock::advance`].
    Manual(std::sync::Arc<std::sync::atomic::AtomicU64>),
}

impl Clock {
    /// A manual clock reading `start_ns`.
    pub fn manual(start_ns: u64) -> Self {
        Clock::Manual(std::sync::Arc::new(std::sync::atomic::AtomicU64::new(
            start_ns,
        )))
    }

    /// Now, UNIX-epoch nanoseconds.
    pub fn now_ns(&self) -> u64 {
        match self {
            Clock::System => now_ns(),
            Clock::Manual(t) => t.load(std::sync::atomic::Ordering::SeqCst),
        }
    }

    /// Moves a manual clock on (the system clock moves by itself).
    pub fn advance(&self, by: std::time::Duration) {
        if let Clock::Manual(t) = self {
            let ns = u64::try_from(by.as_nanos()).unwrap_or(u64::MAX);
            t.fetch_add(ns, std::sync::atomic::Ordering::SeqCst);
        }
    }

    /// Time since `earlier_ns` (zero if that is in the future).
    pub fn since(&self, earlier_ns: u64) -> std::time::Duration {
        std::time::Duration::from_nanos(self.now_ns().saturating_sub(earlier_ns))
    }
}

/// Wall-clock time as UNIX-epoch nanoseconds (0 if the clock is before 1970).
pub fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}
