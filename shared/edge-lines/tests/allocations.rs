//! A warm detector allocates nothing: this test binary counts every heap allocation with
//! its own global allocator (so it holds this one test only).

use linetrack_edge_lines::{EdgeLineDetector, GrayView, Params};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The system allocator, counting allocations.
struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call is forwarded unchanged to the system allocator, which upholds
// GlobalAlloc's contract; the counter has no effect on the memory handed out.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: the caller's layout is passed on as given.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `alloc` above with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: as for `alloc` and `dealloc`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn a_warm_detector_does_not_allocate() {
    let (w, h) = (752, 480);
    let pixels = linetrack_test_data::test_card(w, h);
    let view = GrayView::packed(&pixels, w, h).unwrap();
    let mut detector = EdgeLineDetector::new(Params::default());
    let mut out = Vec::new();
    detector.detect(view, &mut out);
    assert!(!out.is_empty());
    let first = out.clone();
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    for _ in 0..3 {
        detector.detect(view, &mut out);
    }
    let after = ALLOCATIONS.load(Ordering::Relaxed);
    assert_eq!(after - before, 0, "allocations in three warm detections");
    assert_eq!(out, first);
}
