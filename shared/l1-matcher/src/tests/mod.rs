//! Behaviour of the whole matcher: hand-made cases, generated scenes with known truth
//! (precision and recall asserted, figures measured over the seeds named), degenerate
//! input, invariances and the shipped configuration files.

use super::*;
use linetrack_synthetic_segments::{
    SceneConfig, Score, SegmentPair, StereoRig, frame_pair, stereo_pair,
};
use proptest::prelude::*;

mod configs;
mod degenerate;
mod disparity;
mod invariances;
mod photometric;
mod scenes;

/// The seeds of the generated pairs a scene test scores.
const SEEDS: std::ops::Range<u64> = 0..30;

fn seg(x0: f64, y0: f64, x1: f64, y1: f64) -> Segment {
    Segment::from_coords(x0, y0, x1, y1)
}

fn run(
    config: MatcherConfig,
    case: MatchCase,
    first: &[Segment],
    second: &[Segment],
) -> (Vec<Match>, MatchStats) {
    let mut matcher = L1Matcher::new(config).unwrap();
    let mut out = Vec::new();
    let stats = matcher.match_segments(case, first, second, &mut out);
    (out, stats)
}

fn pairs(matches: &[Match]) -> Vec<(usize, usize)> {
    matches.iter().map(|m| (m.query, m.train)).collect()
}

/// Precision and recall summed over `seeds` generated pairs (100 segments per image,
/// as the paper caps its detectors).
fn score_over_seeds(
    config: &MatcherConfig,
    case: MatchCase,
    scene: &SceneConfig,
    seeds: std::ops::Range<u64>,
) -> Score {
    let rig = StereoRig::default();
    let mut matcher = L1Matcher::new(config.clone()).unwrap();
    let mut out = Vec::new();
    let mut total = Score {
        accepted: 0,
        correct: 0,
        matchable: 0,
    };
    for seed in seeds {
        let scene = SceneConfig {
            seed,
            max_segments: Some(100),
            ..scene.clone()
        };
        let pair: SegmentPair = match case {
            MatchCase::Stereo => stereo_pair(&rig, &scene),
            MatchCase::FrameToFrame => frame_pair(&rig, &scene),
        };
        matcher.match_segments(case, &pair.first.segments, &pair.second.segments, &mut out);
        let s = pair.score(pairs(&out));
        total.accepted += s.accepted;
        total.correct += s.correct;
        total.matchable += s.matchable;
    }
    eprintln!(
        "{case:?}: precision {:.3} recall {:.3} ({total:?})",
        total.precision(),
        total.recall()
    );
    total
}

fn assert_quality(score: Score, min_precision: f64, min_recall: f64) {
    assert!(
        score.precision() >= min_precision && score.recall() >= min_recall,
        "precision {:.3} (want ≥ {min_precision}), recall {:.3} (want ≥ {min_recall}): {score:?}",
        score.precision(),
        score.recall()
    );
}

// ---------------------------------------------------------------- hand-made cases

#[test]
fn three_vertical_segments_match_their_shifted_copies() {
    let left = [
        seg(100.0, 50.0, 100.0, 150.0),
        seg(300.0, 60.0, 305.0, 200.0),
        seg(500.0, 300.0, 480.0, 420.0),
    ];
    // Right image: shifted left by disparities 20, 12, 30, listed in another order.
    // The first one is given with its endpoints reversed.
    let right = [
        seg(470.0, 300.0, 450.0, 420.0).reversed(),
        seg(80.0, 50.0, 80.0, 150.0),
        seg(288.0, 60.0, 293.0, 200.0),
    ];
    let mut config = MatcherConfig::default();
    config.gates.same_polarity = false;
    let (matches, stats) = run(config, MatchCase::Stereo, &left, &right);
    assert_eq!(pairs(&matches), vec![(0, 1), (1, 2), (2, 0)], "{stats:?}");
    assert!(matches.iter().all(|m| m.weight > 0.0 && m.weight <= 1.0));
}

#[test]
fn two_equally_good_candidates_are_ambiguous() {
    let left = [seg(100.0, 50.0, 100.0, 150.0)];
    let right = [seg(80.0, 50.0, 80.0, 150.0), seg(60.0, 50.0, 60.0, 150.0)];
    let (matches, stats) = run(MatcherConfig::default(), MatchCase::Stereo, &left, &right);
    assert!(matches.is_empty());
    assert_eq!(stats.ambiguous, 1);
}

#[test]
fn polarity_gate_refuses_reversed_candidates_only_when_on() {
    let left = [seg(100.0, 50.0, 100.0, 150.0)];
    let right = [seg(80.0, 150.0, 80.0, 50.0)];
    let (on, stats) = run(MatcherConfig::default(), MatchCase::Stereo, &left, &right);
    assert!(on.is_empty(), "the gate is on by default");
    assert_eq!(stats.unsupported, 1);
    let mut config = MatcherConfig::default();
    config.gates.same_polarity = false;
    let (off, _) = run(config, MatchCase::Stereo, &left, &right);
    assert_eq!(pairs(&off), vec![(0, 0)]);
}

#[test]
fn each_candidate_goes_to_the_query_with_the_lower_error() {
    // Two queries compete for one candidate; the one of equal length wins.
    let left = [
        seg(100.0, 50.0, 100.0, 150.0),
        seg(104.0, 60.0, 104.0, 130.0),
    ];
    let right = [seg(85.0, 50.0, 85.0, 150.0)];
    let (matches, stats) = run(MatcherConfig::default(), MatchCase::Stereo, &left, &right);
    assert_eq!(pairs(&matches), vec![(0, 0)]);
    assert_eq!(stats.conflicts, 1);
}

/// `run` for segments of which those flagged in `predicted` were placed by a motion.
fn run_predicted(
    config: MatcherConfig,
    first: &[Segment],
    predicted: &[bool],
    second: &[Segment],
) -> (Vec<Match>, MatchStats) {
    let mut matcher = L1Matcher::new(config).unwrap();
    let mut out = Vec::new();
    let stats = matcher.match_predicted(first, predicted, second, &mut out);
    (out, stats)
}

#[test]
fn predicted_queries_sit_out_the_flow_filter() {
    // Eight segments flow 10 px to the right, three 10 px up: a flow of two directions,
    // as a forward motion's radial flow is. Where they were, the filter drops the three
    // as outliers; placed by a motion, they are kept.
    let mut first = Vec::new();
    let mut second = Vec::new();
    for k in 0..11 {
        let x = 100.0 + 60.0 * f64::from(k);
        first.push(seg(x, 100.0, x, 200.0));
        second.push(if k < 8 {
            seg(x + 10.0, 100.0, x + 10.0, 200.0)
        } else {
            seg(x, 90.0, x, 190.0)
        });
    }
    let config = MatcherConfig::default();
    let (plain, stats) = run(config.clone(), MatchCase::FrameToFrame, &first, &second);
    assert_eq!(stats.outliers, 3, "{stats:?}");
    assert_eq!(plain.len(), 8);
    let (predicted, stats) = run_predicted(config.clone(), &first, &[true; 11], &second);
    assert_eq!(stats.outliers, 0, "{stats:?}");
    assert_eq!(
        pairs(&predicted),
        (0..11).map(|k| (k, k)).collect::<Vec<_>>()
    );
    // Unless asked for.
    let mut filtered = config;
    filtered.predicted.flow_filter = true;
    let (_, stats) = run_predicted(filtered, &first, &[true; 11], &second);
    assert_eq!(stats.outliers, 3, "{stats:?}");
}

#[test]
fn predicted_queries_have_their_own_displacement_gate() {
    // The partner lies 25 px off the query's line: within the plain gate (40 px), beyond
    // a predicted query's (15 px).
    let first = [seg(100.0, 100.0, 100.0, 200.0)];
    let second = [seg(125.0, 100.0, 125.0, 200.0)];
    let config = MatcherConfig::default();
    let (plain, _) = run_predicted(config.clone(), &first, &[false], &second);
    assert_eq!(pairs(&plain), vec![(0, 0)]);
    let (predicted, stats) = run_predicted(config.clone(), &first, &[true], &second);
    assert!(predicted.is_empty());
    assert_eq!(stats.unsupported, 1);
    let mut wide = config;
    wide.predicted.max_displacement_px = 30.0;
    let (predicted, _) = run_predicted(wide, &first, &[true], &second);
    assert_eq!(pairs(&predicted), vec![(0, 0)]);
}

/// Ten vertical predicted queries 60 px apart; the partners of the first nine lie
/// `offset(k)` px to the side of their queries. The last one's partner was not detected:
/// only a parallel edge 8 px beside it is there.
fn a_frame_with_a_distractor(offset: impl Fn(usize) -> f64) -> (Vec<Segment>, Vec<Segment>) {
    let x = |k: usize| 100.0 + 60.0 * k as f64;
    let first = (0..10).map(|k| seg(x(k), 100.0, x(k), 200.0)).collect();
    let mut second: Vec<Segment> = (0..9)
        .map(|k| seg(x(k) + offset(k), 101.0, x(k) + offset(k), 199.0))
        .collect();
    second.push(seg(x(9) + 8.0, 100.0, x(9) + 8.0, 200.0));
    (first, second)
}

#[test]
fn a_good_prediction_narrows_the_gate_and_leaves_a_parallel_edge_out() {
    let config = MatcherConfig::default();
    assert!(config.predicted.narrow_factor > 0.0);
    // Partners within half a pixel: the gate narrows to its 4 px floor, and the edge
    // 8 px beside the last query no longer passes.
    let (first, second) = a_frame_with_a_distractor(|k| if k % 2 == 0 { 0.5 } else { -0.4 });
    let (narrowed, _) = run_predicted(config.clone(), &first, &[true; 10], &second);
    assert_eq!(pairs(&narrowed), (0..9).map(|k| (k, k)).collect::<Vec<_>>());
    // Without narrowing it is taken for the query's partner.
    let mut wide = config.clone();
    wide.predicted.narrow_factor = 0.0;
    let (plain, _) = run_predicted(wide, &first, &[true; 10], &second);
    assert_eq!(pairs(&plain), (0..10).map(|k| (k, k)).collect::<Vec<_>>());
    // Too few matches to measure the prediction by: nothing narrows.
    let mut few = config;
    few.predicted.narrow_min_matches = 11;
    let (kept, _) = run_predicted(few, &first, &[true; 10], &second);
    assert_eq!(kept.len(), 10);
}

#[test]
fn a_poor_prediction_keeps_the_wide_gate() {
    // Every partner 6–9 px off: the median says the prediction is off by that much, and
    // three times it is wider than the configured gate, which stays.
    let (first, second) = a_frame_with_a_distractor(|k| 6.0 + (k % 4) as f64);
    let (matches, _) = run_predicted(MatcherConfig::default(), &first, &[true; 10], &second);
    assert_eq!(pairs(&matches), (0..10).map(|k| (k, k)).collect::<Vec<_>>());
}

#[test]
fn pieces_of_one_edge_are_no_rivals_with_collinear_px() {
    // The predicted query's edge was detected in two pieces this frame, both on its line:
    // equally good partners, so the ratio test finds the query ambiguous.
    let first = [seg(100.0, 100.0, 100.0, 200.0)];
    let second = [
        seg(100.3, 100.0, 100.3, 148.0),
        seg(100.2, 152.0, 100.2, 200.0),
    ];
    let config = MatcherConfig::default();
    let (plain, stats) = run_predicted(config.clone(), &first, &[true], &second);
    assert!(plain.is_empty());
    assert_eq!(stats.ambiguous, 1);
    // With `collinear_px` the two pieces are one edge: the query takes one of them.
    let mut pieces = config.clone();
    pieces.predicted.collinear_px = 1.0;
    let (matched, _) = run_predicted(pieces.clone(), &first, &[true], &second);
    assert_eq!(matched.len(), 1);
    // A parallel edge 3 px off is still a rival.
    let beside = [
        seg(100.3, 100.0, 100.3, 148.0),
        seg(103.2, 102.0, 103.2, 146.0),
    ];
    let (none, stats) = run_predicted(pieces.clone(), &first, &[true], &beside);
    assert!(none.is_empty(), "{none:?}");
    assert_eq!(stats.ambiguous, 1);
    // A query matched where it was (not predicted) keeps the plain ratio test.
    let (unpredicted, _) = run_predicted(pieces, &first, &[false], &second);
    assert!(unpredicted.is_empty());
}

#[test]
fn a_predicted_query_outranks_a_plain_one_for_a_candidate() {
    // Query 1 fits the candidate better (the same length), but query 0 was placed there
    // by the motion.
    let first = [
        seg(100.0, 100.0, 100.0, 200.0),
        seg(104.0, 100.0, 104.0, 190.0),
    ];
    let second = [seg(102.0, 100.0, 102.0, 190.0)];
    let config = MatcherConfig::default();
    let (plain, _) = run_predicted(config.clone(), &first, &[false, false], &second);
    assert_eq!(pairs(&plain), vec![(1, 0)]);
    let (predicted, stats) = run_predicted(config, &first, &[true, false], &second);
    assert_eq!(pairs(&predicted), vec![(0, 0)]);
    assert_eq!(stats.conflicts, 1);
}

#[test]
fn near_horizontal_gate_skips_flat_queries() {
    let left = [
        seg(100.0, 100.0, 200.0, 105.0),
        seg(300.0, 50.0, 310.0, 150.0),
    ];
    let right = [
        seg(90.0, 100.0, 190.0, 105.0),
        seg(290.0, 50.0, 300.0, 150.0),
    ];
    let (all, _) = run(MatcherConfig::default(), MatchCase::Stereo, &left, &right);
    assert_eq!(pairs(&all), vec![(0, 0), (1, 1)]);
    let mut config = MatcherConfig::default();
    config.gates.min_angle_from_horizontal_deg = 10.0;
    let (gated, stats) = run(config, MatchCase::Stereo, &left, &right);
    assert_eq!(pairs(&gated), vec![(1, 1)]);
    assert_eq!(stats.near_horizontal, 1);
}
