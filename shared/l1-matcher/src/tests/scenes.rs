//! Generated scenes with known truth: precision and recall over named seeds.
//!
//! Each test scores 30 generated pairs ([`SEEDS`], 100 segments per image) and asserts
//! precision and recall a little below the figures measured when the test was written,
//! which are given in the test's comment as precision / recall.

use super::*;

fn both_cases(config: &MatcherConfig, scene: &SceneConfig) -> (Score, Score) {
    (
        score_over_seeds(config, MatchCase::Stereo, scene, SEEDS),
        score_over_seeds(config, MatchCase::FrameToFrame, scene, SEEDS),
    )
}

#[test]
fn default_config_on_typical_scenes() {
    // Noise 0.5 px, 8 % truncation, 8 % missed, 5 % split, 6 clutter, 3 repetitive groups.
    // Geometry alone (no images): measured stereo 0.977 / 0.655, frame-to-frame 0.984 / 0.728.
    let (stereo, f2f) = both_cases(&MatcherConfig::default(), &SceneConfig::default());
    assert_quality(stereo, 0.96, 0.63);
    assert_quality(f2f, 0.96, 0.70);
}

#[test]
fn paper_config_on_typical_scenes() {
    // The method as published: measured stereo 0.906 / 0.454, frame-to-frame 0.787 / 0.214.
    let (stereo, f2f) = both_cases(&MatcherConfig::paper(), &SceneConfig::default());
    assert_quality(stereo, 0.89, 0.42);
    assert_quality(f2f, 0.77, 0.18);
}

#[test]
fn repetitive_parallel_structures() {
    // 10 groups of 8 parallel copies 6 cm apart plus 60 lone segments.
    // Measured: stereo 0.896 / 0.489, frame-to-frame 0.887 / 0.404.
    let scene = SceneConfig {
        segments: 60,
        repetitive_groups: 10,
        group_size: 8,
        ..Default::default()
    };
    let (stereo, f2f) = both_cases(&MatcherConfig::default(), &scene);
    assert_quality(stereo, 0.86, 0.43);
    assert_quality(f2f, 0.87, 0.37);
}

#[test]
fn split_segments() {
    // 40 % of detections split in two. Measured: stereo 0.915 / 0.515, frame-to-frame 0.903 / 0.525.
    let scene = SceneConfig {
        split_probability: 0.4,
        ..Default::default()
    };
    let (stereo, f2f) = both_cases(&MatcherConfig::default(), &scene);
    assert_quality(stereo, 0.89, 0.49);
    assert_quality(f2f, 0.88, 0.49);
}

#[test]
fn missing_and_extra_detections() {
    // 30 % missed per view, 40 clutter segments per view.
    // Measured: stereo 0.899 / 0.680, frame-to-frame 0.900 / 0.745.
    let scene = SceneConfig {
        miss_probability: 0.3,
        clutter: 40,
        ..Default::default()
    };
    let (stereo, f2f) = both_cases(&MatcherConfig::default(), &scene);
    assert_quality(stereo, 0.88, 0.65);
    assert_quality(f2f, 0.87, 0.71);
}

#[test]
fn noisy_endpoints() {
    // 1.5 px endpoint noise, 15 % truncation. Measured: stereo 0.964 / 0.529 (the stereo
    // row-overlap gate of 0.4, chosen on real images, costs recall here), frame-to-frame
    // 0.965 / 0.724.
    let scene = SceneConfig {
        endpoint_noise_px: 1.5,
        max_truncation: 0.15,
        ..Default::default()
    };
    let (stereo, f2f) = both_cases(&MatcherConfig::default(), &scene);
    assert_quality(stereo, 0.94, 0.50);
    assert_quality(f2f, 0.94, 0.69);
}

#[test]
fn larger_frame_to_frame_motion() {
    // 8 cm and 3° between frames. Measured: 0.981 / 0.654.
    let scene = SceneConfig {
        motion_translation_m: 0.08,
        motion_rotation_deg: 3.0,
        ..Default::default()
    };
    let f2f = score_over_seeds(
        &MatcherConfig::default(),
        MatchCase::FrameToFrame,
        &scene,
        SEEDS,
    );
    assert_quality(f2f, 0.96, 0.62);
}

#[test]
fn polarity_gate_needs_a_detector_with_polarity() {
    // Endpoint order scrambled, as a detector without gradient polarity gives it: the
    // default gate then refuses about half the true pairs; switched off it does not.
    let scrambled = SceneConfig {
        random_endpoint_order: true,
        ..SceneConfig::default()
    };
    let (gated, _) = both_cases(&MatcherConfig::default(), &scrambled);
    let off = MatcherConfig {
        gates: Gates {
            same_polarity: false,
            ..Gates::default()
        },
        ..Default::default()
    };
    let (open, _) = both_cases(&off, &scrambled);
    // Measured: gated stereo recall 0.360, open 0.971 / 0.661.
    assert!(
        gated.recall() < 0.7 * open.recall(),
        "{gated:?} vs {open:?}"
    );
    assert_quality(open, 0.95, 0.63);
}

#[test]
fn near_horizontal_gate_on_typical_scenes() {
    // Gate at 10°. Measured: stereo 0.968 / 0.453.
    let config = MatcherConfig {
        gates: Gates {
            min_angle_from_horizontal_deg: 10.0,
            ..Gates::default()
        },
        ..Default::default()
    };
    let stereo = score_over_seeds(&config, MatchCase::Stereo, &SceneConfig::default(), SEEDS);
    assert_quality(stereo, 0.95, 0.43);
}

#[test]
fn default_config_beats_the_paper_config_on_both_measures() {
    let scene = SceneConfig::default();
    for case in [MatchCase::Stereo, MatchCase::FrameToFrame] {
        let ours = score_over_seeds(&MatcherConfig::default(), case, &scene, 0..10);
        let paper = score_over_seeds(&MatcherConfig::paper(), case, &scene, 0..10);
        assert!(
            ours.precision() > paper.precision() && ours.recall() > paper.recall(),
            "{case:?}: {ours:?} vs {paper:?}"
        );
    }
}
