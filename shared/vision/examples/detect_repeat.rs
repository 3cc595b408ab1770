//! Runs one line detector on one image a given number of times and prints the segment
//! count and the median time: a fixed workload for instruction counters, e.g.
//!
//! ```sh
//! cargo build --release -p linetrack-vision --example detect_repeat
//! valgrind --tool=callgrind target/release/examples/detect_repeat fld IMAGE.png 10
//! ```
//!
//! (compare the inclusive cost of `LineDetector::detect` between detectors, or the totals of
//! a run with N and with 0 repetitions).

#![allow(clippy::expect_used)] // a measuring tool on fixed inputs: failing loudly is right

use linetrack_vision::{DetectorKind, FrontendConfig, GrayImage, create_detector};
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let usage = "usage: detect_repeat lsd|fld|edgelines IMAGE [REPETITIONS]";
    let kind: DetectorKind = args.next().expect(usage).parse().expect(usage);
    let image = GrayImage::load(args.next().expect(usage).as_ref()).expect("image");
    let repetitions: usize = args.next().map_or(20, |n| n.parse().expect(usage));
    let mut detector = create_detector(kind, &FrontendConfig::default()).expect("detector");
    let mut segments = Vec::new();
    let mut times_ms = Vec::with_capacity(repetitions);
    for _ in 0..repetitions {
        let start = Instant::now();
        detector.detect(&image, &mut segments).expect("detection");
        times_ms.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times_ms.sort_by(f64::total_cmp);
    let median = times_ms.get(repetitions / 2).copied().unwrap_or(f64::NAN);
    println!(
        "{}: {} segments, median {median:.3} ms over {repetitions}",
        kind.name(),
        segments.len()
    );
}
