//! The wall clock the frames' stamps read (the clock the policies read, system or
//! manual, is the stage runtime's `Clock`).

/// Wall-clock time as UNIX-epoch nanoseconds (0 if the clock is before 1970).
pub fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}
