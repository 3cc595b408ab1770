//! `sched_setscheduler(2)` on the calling thread: the one call rustix does not offer.

use crate::Policy;
use std::io;

/// Sets the calling thread's scheduling policy and priority (0 for [`Policy::Other`]).
pub(crate) fn set_this_thread(policy: Policy, priority: i32) -> io::Result<()> {
    let raw = match policy {
        Policy::Other => libc::SCHED_OTHER,
        Policy::Fifo => libc::SCHED_FIFO,
        Policy::Rr => libc::SCHED_RR,
    };
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: `param` is an initialised `sched_param` that lives for the whole call, which
    // only reads it; pid 0 is the calling thread (Linux applies the policy per thread).
    #[allow(unsafe_code)]
    let result = unsafe { libc::sched_setscheduler(0, raw, &param) };
    if result == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

/// The calling thread's policy as the kernel reports it, for tests.
#[cfg(test)]
pub(crate) fn of_this_thread() -> io::Result<libc::c_int> {
    // SAFETY: no pointer is passed; pid 0 is the calling thread.
    #[allow(unsafe_code)]
    let result = unsafe { libc::sched_getscheduler(0) };
    if result < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(result)
    }
}
