//! A warm detector allocates nothing: this test binary counts every heap allocation with
//! its own global allocator (so it holds this one test only).

use linetrack_edge_lines::{EdgeLineDetector, GrayView, Params};
use linetrack_test_data::CountingAllocator;

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator::new(0);

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
    let before = ALLOCATOR.count();
    for _ in 0..3 {
        detector.detect(view, &mut out);
    }
    let after = ALLOCATOR.count();
    assert_eq!(after - before, 0, "allocations in three warm detections");
    assert_eq!(out, first);
}
