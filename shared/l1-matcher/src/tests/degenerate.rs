//! Degenerate input: empty sides, degenerate segments, lopsided sets, any input (proptest).

use super::*;

#[test]
fn empty_sets_on_either_side_give_no_matches() {
    let some = [seg(0.0, 0.0, 0.0, 50.0)];
    for case in [MatchCase::Stereo, MatchCase::FrameToFrame] {
        for (a, b) in [
            (&[][..], &some[..]),
            (&some[..], &[][..]),
            (&[][..], &[][..]),
        ] {
            let (matches, stats) = run(MatcherConfig::default(), case, a, b);
            assert!(matches.is_empty());
            assert_eq!(stats.matches, 0);
        }
    }
}

#[test]
fn degenerate_segments_are_counted_and_never_matched_and_do_not_disturb_the_rest() {
    let rig = StereoRig::default();
    let pair = stereo_pair(
        &rig,
        &SceneConfig {
            seed: 11,
            max_segments: Some(100),
            ..Default::default()
        },
    );
    let (clean, _) = run(
        MatcherConfig::default(),
        MatchCase::Stereo,
        &pair.first.segments,
        &pair.second.segments,
    );
    let junk = [
        seg(10.0, 10.0, 10.0, 10.0),
        seg(f64::NAN, 0.0, 5.0, 5.0),
        seg(0.0, f64::INFINITY, 5.0, 5.0),
        seg(-f64::MAX, 0.0, f64::MAX, 0.0),
        seg(0.0, 0.0, 1e-9, 0.0),
    ];
    let first: Vec<Segment> = pair.first.segments.iter().chain(&junk).copied().collect();
    let second: Vec<Segment> = pair.second.segments.iter().chain(&junk).copied().collect();
    let (dirty, stats) = run(MatcherConfig::default(), MatchCase::Stereo, &first, &second);
    assert_eq!(pairs(&dirty), pairs(&clean));
    assert_eq!(
        (stats.invalid_first, stats.invalid_second),
        (junk.len(), junk.len())
    );
}

#[test]
fn one_side_much_larger_than_the_other() {
    let rig = StereoRig::default();
    let big = stereo_pair(
        &rig,
        &SceneConfig {
            seed: 5,
            segments: 3000,
            clutter: 500,
            ..Default::default()
        },
    );
    let few = &big.first.segments[..5];
    for case in [MatchCase::Stereo, MatchCase::FrameToFrame] {
        let (matches, _) = run(MatcherConfig::default(), case, few, &big.second.segments);
        assert!(
            matches.len() <= 5
                && matches
                    .iter()
                    .all(|m| m.query < 5 && m.train < big.second.segments.len())
        );
        let (matches, _) = run(MatcherConfig::default(), case, &big.second.segments, few);
        assert!(matches.len() <= 5 && matches.iter().all(|m| m.train < 5));
    }
}

fn any_segment() -> impl Strategy<Value = Segment> {
    let coord = prop_oneof![
        8 => -100.0..900.0f64,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(0.0),
    ];
    (coord.clone(), coord.clone(), coord.clone(), coord).prop_map(|(a, b, c, d)| seg(a, b, c, d))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn any_input_gives_a_valid_one_to_one_result(
        first in prop::collection::vec(any_segment(), 0..40),
        second in prop::collection::vec(any_segment(), 0..40),
        stereo in any::<bool>(),
        paper in any::<bool>(),
    ) {
        let case = if stereo { MatchCase::Stereo } else { MatchCase::FrameToFrame };
        let config = if paper { MatcherConfig::paper() } else { MatcherConfig::default() };
        let (matches, stats) = run(config, case, &first, &second);
        prop_assert_eq!(stats.matches, matches.len());
        let mut trains: Vec<usize> = matches.iter().map(|m| m.train).collect();
        trains.sort_unstable();
        trains.dedup();
        prop_assert_eq!(trains.len(), matches.len(), "a candidate matched twice");
        prop_assert!(matches.windows(2).all(|w| w[0].query < w[1].query));
        for m in &matches {
            prop_assert!(first[m.query].is_finite() && second[m.train].is_finite());
            prop_assert!(m.weight > 0.0 && m.weight <= 1.0 + 1e-12 && m.error.is_finite());
        }
    }
}
