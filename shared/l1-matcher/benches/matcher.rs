//! Time of one whole matching call (features, gates, geometric terms, one lasso per query,
//! ratio test, one-to-one assignment, outlier filter) on generated scenes of 100 × 100 and
//! 300 × 300 segments, stereo and frame to frame, with the default and the paper's
//! configuration.

#![allow(clippy::expect_used)] // a bench on a fixed, valid configuration

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use linetrack_l1_matcher::{L1Matcher, MatchCase, MatcherConfig};
use linetrack_synthetic_segments::{SceneConfig, StereoRig, frame_pair, stereo_pair};
use std::hint::black_box;

fn bench_match(c: &mut Criterion) {
    let rig = StereoRig::default();
    let mut group = c.benchmark_group("l1_match");
    for (config_name, config) in [
        ("default", MatcherConfig::default()),
        ("paper", MatcherConfig::paper()),
    ] {
        for size in [100usize, 300] {
            for case in [MatchCase::Stereo, MatchCase::FrameToFrame] {
                let scene = SceneConfig {
                    seed: 1,
                    segments: 2 * size,
                    max_segments: Some(size),
                    ..Default::default()
                };
                let pair = match case {
                    MatchCase::Stereo => stereo_pair(&rig, &scene),
                    MatchCase::FrameToFrame => frame_pair(&rig, &scene),
                };
                let mut matcher = L1Matcher::new(config.clone()).expect("valid config");
                let mut out = Vec::with_capacity(size);
                let name = format!("{config_name}/{case:?}");
                group.bench_with_input(BenchmarkId::new(name, size), &pair, |bench, pair| {
                    bench.iter(|| {
                        matcher.match_segments(
                            case,
                            black_box(&pair.first.segments),
                            black_box(&pair.second.segments),
                            &mut out,
                        )
                    })
                });
            }
        }
    }
    group.finish();
}

criterion_group!(benches, bench_match);
criterion_main!(benches);
