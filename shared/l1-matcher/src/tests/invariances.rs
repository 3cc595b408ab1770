//! Invariances: endpoint order, wide-open gates, a matcher reused across calls.

use super::*;

#[test]
fn endpoint_order_does_not_change_the_matches_without_polarity() {
    let rig = StereoRig::default();
    for case in [MatchCase::Stereo, MatchCase::FrameToFrame] {
        let scene = SceneConfig {
            seed: 21,
            max_segments: Some(100),
            ..Default::default()
        };
        let pair = if case == MatchCase::Stereo {
            stereo_pair(&rig, &scene)
        } else {
            frame_pair(&rig, &scene)
        };
        let flipped: Vec<Segment> = pair
            .second
            .segments
            .iter()
            .enumerate()
            .map(|(k, s)| if k % 2 == 0 { s.reversed() } else { *s })
            .collect();
        let mut config = MatcherConfig::default();
        config.gates.same_polarity = false;
        let (a, _) = run(
            config.clone(),
            case,
            &pair.first.segments,
            &pair.second.segments,
        );
        let (b, _) = run(config, case, &pair.first.segments, &flipped);
        assert!(!a.is_empty());
        assert_eq!(pairs(&a), pairs(&b), "{case:?}");
    }
}

#[test]
fn wide_open_gates_change_nothing() {
    let rig = StereoRig::default();
    for seed in 0..4 {
        for case in [MatchCase::Stereo, MatchCase::FrameToFrame] {
            let scene = SceneConfig {
                seed,
                max_segments: Some(60),
                ..Default::default()
            };
            let pair = if case == MatchCase::Stereo {
                stereo_pair(&rig, &scene)
            } else {
                frame_pair(&rig, &scene)
            };
            let open = MatcherConfig {
                gates: Gates::wide_open(),
                ..Default::default()
            };
            let off = MatcherConfig {
                gates: Gates {
                    enabled: false,
                    ..Gates::default()
                },
                ..Default::default()
            };
            let (a, sa) = run(open, case, &pair.first.segments, &pair.second.segments);
            let (b, sb) = run(off, case, &pair.first.segments, &pair.second.segments);
            assert_eq!(a, b);
            assert_eq!(sa, sb);
            // Every valid pair entered the lasso.
            assert_eq!(
                sa.candidate_pairs,
                pair.first.segments.len() * pair.second.segments.len()
            );
        }
    }
}

#[test]
fn the_matcher_is_reusable_across_calls() {
    let rig = StereoRig::default();
    let mut matcher = L1Matcher::new(MatcherConfig::default()).unwrap();
    let mut out = Vec::new();
    let a = stereo_pair(
        &rig,
        &SceneConfig {
            seed: 1,
            ..Default::default()
        },
    );
    let b = stereo_pair(
        &rig,
        &SceneConfig {
            seed: 2,
            segments: 10,
            ..Default::default()
        },
    );
    matcher.match_segments(
        MatchCase::Stereo,
        &a.first.segments,
        &a.second.segments,
        &mut out,
    );
    let first_run = out.clone();
    matcher.match_segments(
        MatchCase::Stereo,
        &b.first.segments,
        &b.second.segments,
        &mut out,
    );
    matcher.match_segments(
        MatchCase::Stereo,
        &a.first.segments,
        &a.second.segments,
        &mut out,
    );
    assert_eq!(out, first_run);
}
