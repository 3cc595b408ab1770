//! A global allocator for tests that count heap allocations.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The system allocator, counting the allocations and reallocations of at least
/// `min_bytes`. A test binary installs it as its global allocator, so it should hold the
/// counting test alone:
///
/// ```text
/// #[global_allocator]
/// static ALLOCATOR: CountingAllocator = CountingAllocator::new(0);
/// ```
pub struct CountingAllocator {
    min_bytes: usize,
    count: AtomicUsize,
}

impl CountingAllocator {
    /// Counts allocations of at least `min_bytes` (0: every one).
    pub const fn new(min_bytes: usize) -> Self {
        Self {
            min_bytes,
            count: AtomicUsize::new(0),
        }
    }

    /// Allocations counted so far, from every thread.
    pub fn count(&self) -> usize {
        self.count.load(Ordering::Relaxed)
    }

    fn note(&self, bytes: usize) {
        if bytes >= self.min_bytes {
            self.count.fetch_add(1, Ordering::Relaxed);
        }
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator, which upholds
// GlobalAlloc's contract; the counter has no effect on the memory handed out.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        self.note(layout.size());
        // SAFETY: the caller's layout is passed on as given.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `alloc` above with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        self.note(new_size);
        // SAFETY: as for `alloc` and `dealloc`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}
