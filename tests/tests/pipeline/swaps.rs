//! Hot swaps on command (the detector, the matcher) and by policy (LSD giving way to FLD,
//! the matcher falling back to l1), every frame once.

use super::*;

#[test]
fn a_hot_swap_to_fld_loses_and_duplicates_no_frame() {
    let dir = scratch("swap");
    // Every frame processed, however late: a loss could not hide as a policy drop.
    hot_swap(start_every_frame(&dir, &base_sequence(FRAMES), &quick()));
}

#[test]
fn a_hot_swap_of_the_matcher_loses_and_duplicates_no_frame_in_both_modes() {
    for threads in [false, true] {
        let dir = scratch(if threads { "mswap-threads" } else { "mswap" });
        // The light detector and matcher: a loaded machine keeps up at 10 Hz, so that a
        // frame lost would be the swap's. Not `--pacing fastest`: this light pipeline then
        // ran the 32 frames after the ask in less time than the standby took to start
        // (once in six suite runs under two CPU hogs: "the run finished before the swap").
        let mut args = vec!["--detector", "edgelines", "--matcher", "l1"];
        if threads {
            args.push("--single-process");
        }
        let mut run = start_with_args(&dir, &base_sequence(FRAMES), &quick(), &args);
        ctl_after_8_frames(&mut run, &["swap-matcher"]);
        let (status, out, records) = run.finish(RUN_TIMEOUT);
        assert!(status.success(), "{status}\n{out}");
        // Every frame recorded exactly once, each with a pose.
        assert_every_frame_accounted(&records);
        assert!(
            records.frames.iter().all(|f| f.has_pose()),
            "a frame without a pose (threads: {threads})"
        );
        let swaps = records.events_of("swap");
        assert_eq!(swaps.len(), 1, "{:?}", records.events);
        assert_eq!(swaps[0].stage, "matcher");
        let at = swaps[0]
            .frame_id
            .unwrap_or_else(|| panic!("swap without a frame"));
        assert!(at > 0 && at < FRAMES as u64, "swap at {at}");
        // The new matcher took over knowing the frame before: the hand-over frame is
        // tracked from it, as every frame after the first is.
        let handed = records
            .frames
            .iter()
            .find(|f| f.frame_id == at)
            .unwrap_or_else(|| panic!("no record of frame {at}"));
        assert!(
            handed.tracked_matches > 0,
            "frame {at}: no frame-to-frame match after the swap (threads: {threads})"
        );
    }
}

#[test]
fn lsd_missing_a_budget_no_detector_meets_gives_way_to_fld_after_its_streak() {
    let dir = scratch("detector-policy");
    // A 1 µs detector budget: every LSD frame misses it, so the policy swaps after exactly
    // `bad_frames` frames, whatever the machine's load; FLD never gets within a quarter of
    // it either, so it never swaps back.
    let config = format!(
        "{SUPERVISION}[budget]\ndrop_late = false\nline_detector_ms = 0.001\n\
         [detector_fallback]\nenabled = true\nto = \"fld\"\nbad_frames = 3\nmin_interval_frames = 0\nend_to_end = false\n"
    );
    let (status, out, records) =
        start_every_frame(&dir, &base_sequence(FRAMES), &config).finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_every_frame_accounted(&records);
    let fallbacks = records.events_of("detector-fallback");
    assert_eq!(fallbacks.len(), 1, "{:?}", records.events);
    assert!(
        fallbacks[0].detail.starts_with("lsd -> fld: lsd over its")
            && fallbacks[0].detail.contains("on 3 frames in a row"),
        "{}",
        fallbacks[0].detail
    );
    // It came on the third frame LSD detected.
    let lsd: Vec<u64> = records
        .frames
        .iter()
        .filter(|f| f.detector == "lsd")
        .map(|f| f.frame_id)
        .collect();
    assert_eq!(
        fallbacks[0].frame_id,
        lsd.get(2).copied(),
        "LSD frames {lsd:?}"
    );
    assert!(records.events_of("detector-recover").is_empty());
    // The hot swap carried it out: LSD before the hand-over frame, FLD from it to the end.
    let swaps = records.events_of("swap");
    assert_eq!(swaps.len(), 1, "{:?}", records.events);
    let at = swaps[0]
        .frame_id
        .unwrap_or_else(|| panic!("swap without a frame"));
    assert!(at < FRAMES as u64, "swap at {at}");
    for f in &records.frames {
        let expected = if f.frame_id < at { "lsd" } else { "fld" };
        assert_eq!(f.detector, expected, "frame {} (swap at {at})", f.frame_id);
    }
}

#[test]
fn both_policies_act_on_frames_that_miss_the_end_to_end_budget_alone() {
    let dir = scratch("end-to-end-policies");
    // Every frame misses a 1 µs end-to-end budget, whatever the machine's load, while LSD and
    // the matcher stay within budgets of a minute and LBD finds its one stereo match: only
    // the pipeline's deadline can move either policy.
    let config = format!(
        "{SUPERVISION}[budget]\ndrop_late = false\nend_to_end_ms = 0.001\nline_detector_ms = 60000.0\n\
         matcher_ms = 60000.0\n[matcher.fallback]\nmin_stereo_matches = 1\nrecover_stereo_matches = 2\n\
         min_inlier_ratio = 0.0\n[detector_fallback]\nenabled = true\nto = \"fld\"\nbad_frames = 3\n"
    );
    let (status, out, records) = start(&dir, &base_sequence(FRAMES), &config).finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_every_frame_accounted(&records);
    let fallbacks = records.events_of("fallback");
    assert!(
        fallbacks
            .first()
            .is_some_and(|e| e.detail.starts_with("lbd -> l1: end to end ")
                && e.detail.contains("> 0.0 ms with LBD taking")),
        "{:?}",
        records.events
    );
    let swaps = records.events_of("detector-fallback");
    assert!(
        swaps.first().is_some_and(|e| e
            .detail
            .starts_with("lsd -> fld: frames missed the 0.0 ms end-to-end budget while lsd ran")),
        "{:?}",
        records.events
    );
}

#[test]
fn matching_falls_back_to_l1_when_the_right_image_turns_unmatchable() {
    let dir = scratch("fallback");
    let sequence = sequence_copy(FRAMES, &dir);
    // From frame 10 the right camera sees inverted intensities: every edge keeps its place
    // (geometry) but flips its gradient, so appearance descriptors no longer match.
    for path in &images(&sequence, 1)[10..] {
        let mut image = image::open(path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .into_luma8();
        image::imageops::invert(&mut image);
        image
            .save(path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
    // This scene gives LBD ~80 stereo matches a frame; a few dozen chance matches survive
    // the inversion, so the test sets its bar between the two.
    // Only the matches decide here: a loaded test machine must not trigger the budget rules
    // (the matcher's own, the end-to-end one).
    let thresholds = "[matcher.fallback]\nmin_stereo_matches = 45\nrecover_stereo_matches = 60\nover_budget = false\nend_to_end = false\n";
    let (status, out, records) =
        start_every_frame(&dir, &sequence, &format!("{}{thresholds}", quick())).finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_every_frame_accounted(&records);
    let fallbacks = records.events_of("fallback");
    assert_eq!(fallbacks.len(), 1, "{:?}", records.events);
    let at = fallbacks[0]
        .frame_id
        .unwrap_or_else(|| panic!("fallback without a frame"));
    assert!((10..20).contains(&at), "fell back at frame {at}");
    assert!(
        fallbacks[0].detail.contains("lbd -> l1"),
        "{}",
        fallbacks[0].detail
    );
    assert!(
        records.frames[..10].iter().all(|f| f.matcher == "lbd"),
        "before the change"
    );
    // The switch reaches the matcher while the frames after `at` are on their way: the
    // matcher may be ahead of the pose by as many frames as the tracks' queue holds (more
    // under load). Within that it switches, and stays. (Under load a frame whose images
    // were released before its segments came is matched by geometry even in LBD mode.)
    let after: Vec<&str> = records.frames[at as usize + 1..]
        .iter()
        .map(|f| f.matcher.as_str())
        .collect();
    let switched = after.iter().rposition(|m| *m == "lbd").map_or(0, |k| k + 1);
    assert!(
        switched <= linetrack_msgs::Topic::Tracks.queue_depth() && switched < after.len(),
        "after the fallback at {at}: {after:?}"
    );
    assert!(
        records.events_of("recover").is_empty(),
        "LBD cannot recover on inverted images: {:?}",
        records.events
    );
}
