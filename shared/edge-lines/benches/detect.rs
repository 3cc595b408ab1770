//! The detector alone, no OpenCV around it: the generated test card and the real EuRoC
//! 752×480 frame 0 (located as in the tests). `cargo bench -p linetrack-vision` times it
//! beside LSD, FLD and OpenCV's EdgeDrawing on the same frame.

#![allow(clippy::expect_used, missing_docs)] // a bench on fixed inputs: failing loudly is right

use criterion::{Criterion, criterion_group, criterion_main};
use linetrack_edge_lines::{EdgeLineDetector, GrayView, Params};
use std::hint::black_box;

fn bench_detect(c: &mut Criterion) {
    let (w, h) = (752, 480);
    let card = linetrack_test_data::test_card(w, h);
    let (left, _) = linetrack_test_data::euroc_stereo_pair(0).expect("EuRoC excerpt");
    let euroc = image::open(&left).expect("EuRoC frame").to_luma8();
    let mut detector = EdgeLineDetector::new(Params::default());
    let mut out = Vec::new();
    let mut group = c.benchmark_group("edge-lines");
    for (name, pixels, width, height) in [
        ("test-card", card.as_slice(), w, h),
        (
            "euroc",
            euroc.as_raw().as_slice(),
            euroc.width() as usize,
            euroc.height() as usize,
        ),
    ] {
        let view = GrayView::packed(pixels, width, height).expect("view");
        group.bench_function(name, |b| {
            b.iter(|| detector.detect(black_box(view), &mut out))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_detect);
criterion_main!(benches);
