//! The extractor alone, no OpenCV around it: the odometry's 1500 points on the real EuRoC
//! 752×480 frame 0 (located as in the tests) at 8 levels of 1.2, 4 of 1.44 and one level.
//! `cargo bench -p linetrack-vision --bench frontend` times it beside OpenCV's ORB.

#![allow(clippy::expect_used, missing_docs)] // a bench on fixed inputs: failing loudly is right

use criterion::{Criterion, criterion_group, criterion_main};
use linetrack_corners::{CornerExtractor, Corners, GrayView, Params};
use std::hint::black_box;

fn bench_extract(c: &mut Criterion) {
    let (left, _) = linetrack_test_data::euroc_stereo_pair(0).expect("EuRoC excerpt");
    let euroc = image::open(&left).expect("EuRoC frame").to_luma8();
    let (width, height) = (euroc.width() as usize, euroc.height() as usize);
    let view = GrayView::packed(euroc.as_raw(), width, height).expect("view");
    let mut group = c.benchmark_group("corners");
    for (levels, scale_factor, name) in [(8, 1.2, "8x1.2"), (4, 1.44, "4x1.44"), (1, 1.2, "1x")] {
        let params = Params {
            max_corners: 1500,
            levels,
            scale_factor,
            ..Params::default()
        };
        let mut extractor = CornerExtractor::new(params).expect("params");
        let mut out = Corners::default();
        group.bench_function(format!("euroc/{name}"), |b| {
            b.iter(|| extractor.extract(black_box(view), &mut out))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_extract);
criterion_main!(benches);
