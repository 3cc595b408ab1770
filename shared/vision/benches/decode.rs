//! Decoding one EuRoC frame (752×480, 8-bit grey PNG), what the frame source does twice a
//! frame: `GrayImage::decode` (the `png` crate for 8-bit grey PNGs) beside OpenCV's
//! `imdecode` (libpng and zlib, what `GrayImage::decode` called for every image before),
//! in the same run.

#![allow(clippy::expect_used, missing_docs)] // a bench on fixed inputs: failing loudly is right

use criterion::{Criterion, criterion_group, criterion_main};
use linetrack_vision::GrayImage;
use opencv::core::Vector;
use opencv::imgcodecs;
use std::hint::black_box;

fn bench_decode(c: &mut Criterion) {
    let (left, _) = linetrack_test_data::euroc_stereo_pair(0).expect("EuRoC excerpt");
    let bytes = std::fs::read(&left).expect("EuRoC frame");
    let mut group = c.benchmark_group("decode");
    group.bench_function("opencv-imdecode", |b| {
        b.iter(|| {
            let buffer = Vector::<u8>::from_slice(black_box(&bytes));
            imgcodecs::imdecode(&buffer, imgcodecs::IMREAD_UNCHANGED).expect("decodes")
        })
    });
    group.bench_function("gray-image", |b| {
        b.iter(|| GrayImage::decode(black_box(&bytes), "frame").expect("decodes"))
    });
    group.finish();
}

criterion_group!(benches, bench_decode);
criterion_main!(benches);
