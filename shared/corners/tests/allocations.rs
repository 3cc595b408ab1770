//! A warm extractor allocates nothing: this test binary counts every heap allocation with
//! its own global allocator (so it holds this one test only).

use linetrack_corners::{CornerExtractor, Corners, GrayView, Params};
use linetrack_test_data::CountingAllocator;

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator::new(0);

#[test]
fn a_warm_extractor_does_not_allocate() {
    let (w, h) = (752, 480);
    let pixels = linetrack_test_data::test_card(w, h);
    let view = GrayView::packed(&pixels, w, h).unwrap();
    let params = Params {
        max_corners: 1500,
        fast_threshold: 10,
        ..Params::default()
    };
    let mut extractor = CornerExtractor::new(params).unwrap();
    let mut out = Corners::default();
    extractor.extract(view, &mut out);
    assert!(!out.is_empty());
    let first = out.clone();
    let before = ALLOCATOR.count();
    for _ in 0..3 {
        extractor.extract(view, &mut out);
    }
    let after = ALLOCATOR.count();
    assert_eq!(after - before, 0, "allocations in three warm extractions");
    assert_eq!(out, first);
}
