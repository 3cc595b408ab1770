//! Disparity consistency between neighbouring matches, and the second-best error.

use super::*;

#[test]
fn a_match_no_neighbour_agrees_with_is_dropped_and_a_lone_one_kept() {
    // Five vertical segments on one surface (disparity 20), a sixth among them whose right
    // partner is 35 px away, and a seventh far from all others at disparity 50.
    let mut left = Vec::new();
    let mut right = Vec::new();
    for (k, x) in [100.0, 120.0, 140.0, 160.0, 180.0].into_iter().enumerate() {
        let top = 20.0 + 7.0 * k as f64;
        left.push(seg(x, top, x + 2.0, top + 60.0));
        right.push(seg(x - 20.0, top, x - 18.0, top + 60.0));
    }
    left.push(seg(150.0, 40.0, 149.0, 100.0));
    right.push(seg(115.0, 40.0, 114.0, 100.0));
    left.push(seg(600.0, 30.0, 600.0, 90.0));
    right.push(seg(550.0, 30.0, 550.0, 90.0));

    let mut config = MatcherConfig::default();
    config.gates.same_polarity = false;
    config.consistency.enabled = false;
    let (all, _) = run(config.clone(), MatchCase::Stereo, &left, &right);
    assert_eq!(all.len(), 7, "{all:?}");
    config.consistency.enabled = true;
    let (kept, stats) = run(config, MatchCase::Stereo, &left, &right);
    assert_eq!(stats.inconsistent, 1);
    assert!(!pairs(&kept).contains(&(5, 5)), "{kept:?}");
    assert!(
        pairs(&kept).contains(&(6, 6)),
        "the lone segment has no neighbour to disagree"
    );
}

#[test]
fn lowest_other_error_is_the_more_precise_second_best() {
    // Measured precision / recall: stereo 0.972 / 0.681 vs 0.938 / 0.710, frame-to-frame
    // 0.983 / 0.727 vs 0.955 / 0.777 (the lasso-weight runner-up trades precision for recall).
    let scene = SceneConfig::default();
    let lasso_second = MatcherConfig {
        second_best: SecondBest::SecondLassoWeight,
        ..Default::default()
    };
    for case in [MatchCase::Stereo, MatchCase::FrameToFrame] {
        let ours = score_over_seeds(&MatcherConfig::default(), case, &scene, SEEDS);
        let other = score_over_seeds(&lasso_second, case, &scene, SEEDS);
        assert!(
            ours.precision() > other.precision(),
            "{case:?}: {ours:?} vs {other:?}"
        );
    }
}
