//! When the matcher falls back from LBD to ℓ1 and when it returns; the streaks with
//! hysteresis ([`Hysteresis`]) that this and the detector policy
//! ([`crate::detector_policy`]) switch on.

use crate::stamps::{end_ns, stage_ms};
use linetrack_msgs::{FrameHeader, FrameStatus, MatcherMode, PoseRecord, StageKind, TracksHeader};
use linetrack_pipeline_config::FallbackConfig;

/// How `header`'s frame missed the end-to-end budget `budget_ms`, if it did: dropped late
/// by a stage, or its pose published more than `budget_ms` after its capture. Both
/// policies count such frames ([`FallbackController`], [`crate::detector_policy`]), so that
/// the pipeline's deadline moves them, not only each stage's own budget.
pub fn end_to_end_miss(header: &FrameHeader, budget_ms: f64) -> Option<String> {
    match header.status.get().ok()? {
        FrameStatus::DroppedLate => Some(format!(
            "dropped late by {} (over the {budget_ms:.1} ms end-to-end budget)",
            header
                .status_by
                .get()
                .map_or("a stage", |stage| stage.name())
        )),
        FrameStatus::Ok => {
            let end = end_ns(header, StageKind::PoseEstimator);
            let ms = header.age_ms(end);
            (header.capture_ns > 0 && end >= header.capture_ns && ms > budget_ms)
                .then(|| format!("end to end {ms:.1} ms > {budget_ms:.1} ms"))
        }
        _ => None,
    }
}

/// Two states, normal and fallen back, and the streaks that move between them: `trip`
/// failing frames in a row in the normal state switch to the fallback, `recover` passing
/// frames in a row in the fallback switch back (the bars for failing and passing are the
/// caller's, apart: the hysteresis). The way back comes no sooner than `min_gap` frames
/// after the last switch; a recovery that trips again within `min_gap` frames failed, and
/// each failure in a row doubles the gap before the next way back (up to
/// 2^[`MAX_BACKOFF`] times `min_gap`). The way to the fallback is never held back: it is
/// the cheaper state. A frame that says nothing is not observed.
#[derive(Debug, Clone)]
pub struct Hysteresis {
    trip: u32,
    recover: u32,
    min_gap: u64,
    fallen_back: bool,
    streak: u32,
    last_switch: Option<u64>,
    /// The frame of the last way back, while in the normal state since.
    recovered_at: Option<u64>,
    /// Recoveries in a row that tripped again within `min_gap` frames.
    failed_recoveries: u32,
}

/// The most doublings of [`Hysteresis`]'s gap after failed recoveries.
pub const MAX_BACKOFF: u32 = 6;

impl Hysteresis {
    /// In the normal state.
    pub fn new(trip: u32, recover: u32, min_gap: u64) -> Self {
        Self {
            trip,
            recover,
            min_gap,
            fallen_back: false,
            streak: 0,
            last_switch: None,
            recovered_at: None,
            failed_recoveries: 0,
        }
    }

    /// Whether it is in the fallback state.
    pub fn fallen_back(&self) -> bool {
        self.fallen_back
    }

    /// The streak needed to switch from the present state.
    pub fn needed(&self) -> u32 {
        if self.fallen_back {
            self.recover
        } else {
            self.trip
        }
    }

    /// Frames the way back waits after the last switch: `min_gap`, doubled for each failed
    /// recovery in a row.
    pub fn gap(&self) -> u64 {
        self.min_gap
            .saturating_mul(1 << self.failed_recoveries.min(MAX_BACKOFF))
    }

    /// Takes frame `frame_id`: in the normal state `counts` says it failed, in the fallback
    /// state that it passed the bar for the way back. Returns whether the state switched
    /// (then the streak starts again).
    pub fn observe(&mut self, frame_id: u64, counts: bool) -> bool {
        self.streak = if counts {
            self.streak.saturating_add(1)
        } else {
            0
        };
        if self.streak < self.needed() {
            return false;
        }
        if self.fallen_back {
            let gap = self.gap();
            if self
                .last_switch
                .is_some_and(|last| frame_id < last.saturating_add(gap))
            {
                return false;
            }
            self.recovered_at = Some(frame_id);
        } else if let Some(recovered) = self.recovered_at.take() {
            self.failed_recoveries = if frame_id < recovered.saturating_add(self.min_gap) {
                self.failed_recoveries.saturating_add(1)
            } else {
                0
            };
        }
        self.fallen_back = !self.fallen_back;
        self.streak = 0;
        self.last_switch = Some(frame_id);
        true
    }

    /// Back to the normal state without a switch of its own (something else switched).
    pub fn reset(&mut self) {
        self.fallen_back = false;
        self.streak = 0;
        self.recovered_at = None;
    }
}

/// A decision to switch the matcher's mode.
#[derive(Debug, Clone, PartialEq)]
pub struct Switch {
    /// The new mode.
    pub to: MatcherMode,
    /// Why, in words.
    pub reason: String,
}

/// Watches each frame's matching and motion results and decides the matcher's mode.
///
/// In LBD mode a frame fails when it has fewer stereo matches than
/// `min_stereo_matches`, when its line inlier ratio collapses below `min_inlier_ratio`, or
/// when the matcher stage ran over its budget; `bad_frames` failures in a row switch to ℓ1.
/// In ℓ1 mode the matcher probes LBD every few frames; `recover_probes` probes in a row
/// with at least `recover_stereo_matches` (a higher bar than the one for failing: the
/// hysteresis) and, with `over_budget`, the matcher stage within `recover_budget_fraction`
/// of its budget (a lower bar than the budget: the latency's hysteresis) switch back. So a
/// matcher that fell back for its latency stays on ℓ1 until LBD clearly fits again,
/// instead of flapping around the budget.
///
/// Latencies come from the frames' stamps, never from a clock: the tests inject them.
#[derive(Debug, Clone)]
pub struct FallbackController {
    config: FallbackConfig,
    matcher_budget_ms: f64,
    end_to_end_budget_ms: f64,
    /// Fallen back: ℓ1.
    streaks: Hysteresis,
}

impl Switch {
    /// Its kind in `events.csv` (`fallback` to ℓ1, `recover` to LBD) and its detail.
    pub fn event(&self) -> (&'static str, String) {
        let (kind, from) = if self.to == MatcherMode::L1 {
            ("fallback", "lbd")
        } else {
            ("recover", "l1")
        };
        (
            kind,
            format!("{from} -> {}: {}", self.to.name(), self.reason),
        )
    }
}

impl FallbackController {
    /// A controller starting in LBD mode.
    pub fn new(config: FallbackConfig, matcher_budget_ms: f64, end_to_end_budget_ms: f64) -> Self {
        let streaks = Hysteresis::new(config.bad_frames, config.recover_probes, 0);
        Self {
            config,
            matcher_budget_ms,
            end_to_end_budget_ms,
            streaks,
        }
    }

    /// The mode the controller wants.
    pub fn mode(&self) -> MatcherMode {
        if self.streaks.fallen_back() {
            MatcherMode::L1
        } else {
            MatcherMode::Lbd
        }
    }

    /// Milliseconds the matcher stage took on `header` (NaN without its stamps: then it
    /// is neither over a bar nor within one).
    fn matcher_ms(header: &FrameHeader) -> f64 {
        stage_ms(header, StageKind::Matcher)
    }

    /// Why an LBD probe does not pass, if it does not.
    fn probe_shortfall(&self, header: &FrameHeader, found: u32) -> Option<String> {
        let c = &self.config;
        if found < c.recover_stereo_matches {
            return Some(format!(
                "{found} < {} LBD stereo matches",
                c.recover_stereo_matches
            ));
        }
        let ms = Self::matcher_ms(header);
        let bar = c.recover_budget_fraction * self.matcher_budget_ms;
        if c.over_budget && !(ms <= bar) {
            return Some(format!("matcher {ms:.1} ms > {bar:.1} ms"));
        }
        let bar = c.recover_budget_fraction * self.end_to_end_budget_ms;
        c.end_to_end.then(|| end_to_end_miss(header, bar)).flatten()
    }

    /// Why an LBD frame failed, if it did.
    fn failure(&self, header: &TracksHeader, pose: &PoseRecord) -> Option<String> {
        let c = &self.config;
        let stereo_matches = header.matching.stereo_matches;
        if stereo_matches < c.min_stereo_matches {
            return Some(format!(
                "too few LBD stereo matches ({stereo_matches} < {})",
                c.min_stereo_matches
            ));
        }
        let observed = pose.observations[1];
        if observed >= c.min_observations
            && f64::from(pose.inliers[1]) < c.min_inlier_ratio * f64::from(observed)
        {
            return Some(format!(
                "line inlier ratio collapsed ({}/{} < {:.2})",
                pose.inliers[1], observed, c.min_inlier_ratio
            ));
        }
        let ms = Self::matcher_ms(&header.frame);
        if c.over_budget && ms > self.matcher_budget_ms {
            return Some(format!(
                "matcher over budget ({ms:.1} ms > {:.1} ms)",
                self.matcher_budget_ms
            ));
        }
        if c.end_to_end
            && let Some(miss) = end_to_end_miss(&header.frame, self.end_to_end_budget_ms)
        {
            return Some(format!("{miss} with LBD taking {ms:.1} ms"));
        }
        None
    }

    /// Takes a frame some stage dropped late: in LBD mode (with `end_to_end`) a failure
    /// like a late pose, in ℓ1 mode the end of a streak of passing probes. Returns a switch
    /// when one is due.
    pub fn observe_dropped_late(&mut self, header: &FrameHeader) -> Option<Switch> {
        if !self.config.end_to_end {
            return None;
        }
        let miss = end_to_end_miss(header, self.end_to_end_budget_ms)?;
        match self.mode() {
            MatcherMode::Lbd => self.streaks.observe(header.frame_id, true).then(|| Switch {
                to: MatcherMode::L1,
                reason: format!("{miss}, {} frames in a row", self.config.bad_frames),
            }),
            MatcherMode::L1 => {
                self.streaks.observe(header.frame_id, false);
                None
            }
        }
    }

    /// Takes the first outcome of a frame that reached the end: a frame dropped late
    /// ([`FallbackController::observe_dropped_late`]) or a processed one
    /// ([`FallbackController::observe`]); other drops say nothing. Returns a switch when one
    /// is due.
    pub fn observe_outcome(&mut self, header: &TracksHeader, pose: &PoseRecord) -> Option<Switch> {
        match header.frame.status.get().ok()? {
            FrameStatus::DroppedLate => self.observe_dropped_late(&header.frame),
            FrameStatus::Ok => self.observe(header, pose),
            _ => None,
        }
    }

    /// Takes one processed frame's results; returns a switch when one is due.
    pub fn observe(&mut self, header: &TracksHeader, pose: &PoseRecord) -> Option<Switch> {
        let frame = &header.frame;
        match self.mode() {
            MatcherMode::Lbd => {
                // Frames matched by ℓ1 for lack of images say nothing about LBD.
                if !header.matching.mode.is(MatcherMode::Lbd) {
                    return None;
                }
                let failure = self.failure(header, pose);
                if !self.streaks.observe(frame.frame_id, failure.is_some()) {
                    return None;
                }
                let reason = format!(
                    "{}, {} frames in a row",
                    failure.unwrap_or_default(),
                    self.config.bad_frames
                );
                Some(Switch {
                    to: MatcherMode::L1,
                    reason,
                })
            }
            MatcherMode::L1 => {
                let Ok(found) = u32::try_from(header.matching.lbd_probe_matches) else {
                    return None;
                };
                let passed = self.probe_shortfall(frame, found).is_none();
                if !self.streaks.observe(frame.frame_id, passed) {
                    return None;
                }
                let c = &self.config;
                let latency = if c.over_budget {
                    format!(
                        " with the matcher within {:.1} ms",
                        c.recover_budget_fraction * self.matcher_budget_ms
                    )
                } else {
                    String::new()
                };
                let reason = format!(
                    "LBD probes found >= {} stereo matches{latency} on {} probes in a row (last {found}, {:.1} ms)",
                    c.recover_stereo_matches,
                    c.recover_probes,
                    Self::matcher_ms(frame)
                );
                Some(Switch {
                    to: MatcherMode::Lbd,
                    reason,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::StampSlot;

    fn frame(mode: MatcherMode, stereo: u32, probe: i32, matcher_ms: u64) -> TracksHeader {
        let mut h = TracksHeader::default();
        h.matching.mode = mode.into();
        h.matching.stereo_matches = stereo;
        h.matching.lbd_probe_matches = probe;
        h.frame.stamps[StampSlot::Matcher].start_ns = 1_000_000;
        h.frame.stamps[StampSlot::Matcher].end_ns = 1_000_000 + matcher_ms * 1_000_000;
        h
    }

    fn pose(inliers: u32, observations: u32) -> PoseRecord {
        PoseRecord {
            inliers: [0, inliers],
            observations: [0, observations],
            ..PoseRecord::default()
        }
    }

    fn controller() -> FallbackController {
        FallbackController::new(
            FallbackConfig {
                bad_frames: 3,
                recover_probes: 2,
                min_stereo_matches: 12,
                recover_stereo_matches: 24,
                ..FallbackConfig::default()
            },
            50.0,
            100.0,
        )
    }

    /// `h` captured at 1 s and its pose published `end_to_end_ms` later.
    fn timed(mut h: TracksHeader, end_to_end_ms: u64) -> TracksHeader {
        h.frame.capture_ns = 1_000_000_000;
        h.frame.stamps[StampSlot::PoseEstimator].start_ns = h.frame.capture_ns;
        h.frame.stamps[StampSlot::PoseEstimator].end_ns =
            h.frame.capture_ns + end_to_end_ms * 1_000_000;
        h
    }

    #[test]
    fn lbd_within_its_own_budget_falls_back_when_frames_miss_the_end_to_end_budget() {
        let mut c = controller();
        let late = |id: u64| {
            let mut h = timed(frame(MatcherMode::Lbd, 40, -1, 30), 150);
            h.frame.frame_id = id;
            h
        };
        // Within the matcher's 50 ms, and in time: nothing.
        assert!(
            c.observe(
                &timed(frame(MatcherMode::Lbd, 40, -1, 30), 90),
                &pose(10, 10)
            )
            .is_none()
        );
        // Late poses and frames dropped late by the detector, mixed: one streak.
        assert!(c.observe(&late(1), &pose(10, 10)).is_none());
        let mut dropped = FrameHeader::new(2, 0, 1);
        dropped.mark(FrameStatus::DroppedLate, StageKind::LineDetector);
        assert!(c.observe_dropped_late(&dropped).is_none());
        let switch = c
            .observe(&late(3), &pose(10, 10))
            .unwrap_or_else(|| panic!("no fallback on three end-to-end misses"));
        assert_eq!(switch.to, MatcherMode::L1);
        assert_eq!(
            switch.reason,
            "end to end 150.0 ms > 100.0 ms with LBD taking 30.0 ms, 3 frames in a row"
        );
        // Back only when probes find matches and their frames are within 0.8 of the
        // end-to-end budget (80 ms), twice in a row.
        let probe = |id: u64, e2e: u64| {
            let mut h = timed(frame(MatcherMode::L1, 40, 40, 5), e2e);
            h.frame.frame_id = id;
            h
        };
        assert!(c.observe(&probe(4, 90), &pose(10, 10)).is_none());
        assert!(c.observe(&probe(5, 50), &pose(10, 10)).is_none());
        assert!(
            c.observe(&probe(6, 90), &pose(10, 10)).is_none(),
            "the streak broke"
        );
        assert!(c.observe(&probe(7, 50), &pose(10, 10)).is_none());
        let back = c.observe(&probe(8, 50), &pose(10, 10));
        assert_eq!(back.map(|s| s.to), Some(MatcherMode::Lbd));
        // Switched off, the end to end is not the matcher's business.
        let mut own = FallbackController::new(
            FallbackConfig {
                end_to_end: false,
                ..controller().config
            },
            50.0,
            100.0,
        );
        for id in 1..10 {
            assert!(own.observe(&late(id), &pose(10, 10)).is_none());
            assert!(own.observe_dropped_late(&dropped).is_none());
        }
    }

    #[test]
    fn hysteresis_needs_whole_streaks_and_keeps_its_minimum_gap_on_the_way_back() {
        let mut h = Hysteresis::new(3, 2, 10);
        let mut frame = 0..;
        let mut feed = |h: &mut Hysteresis, counts: &[bool]| -> Vec<bool> {
            counts
                .iter()
                .map(|&c| h.observe(frame.next().unwrap_or_default(), c))
                .collect()
        };
        assert_eq!(feed(&mut h, &[true, true, false]), [false; 3]);
        assert_eq!(feed(&mut h, &[true, true, true]), [false, false, true]);
        assert!(h.fallen_back());
        // Frame 5 switched: the way back waits for frame 15 even with a streak of passes.
        assert_eq!(feed(&mut h, &[true; 9]), [false; 9]);
        assert!(h.fallen_back());
        assert_eq!(feed(&mut h, &[true]), [true], "frame 15, streak 10 >= 2");
        assert!(!h.fallen_back());
        // The way to the fallback is not held back by the gap: frames 16-18 trip it.
        assert_eq!(feed(&mut h, &[true; 3]), [false, false, true], "frame 18");
        assert!(h.fallen_back());
        h.reset();
        assert!(!h.fallen_back());
        assert_eq!(h.needed(), 3);
    }

    #[test]
    fn each_recovery_that_trips_again_within_the_gap_doubles_the_gap_and_one_that_holds_ends_it() {
        let mut h = Hysteresis::new(1, 1, 10);
        // Trip at 0; back at 10; tripped again at 11 (within 10 of the way back): failed.
        assert!(h.observe(0, true));
        assert!(!h.observe(9, true));
        assert!(h.observe(10, true));
        assert!(h.observe(11, true));
        assert_eq!(h.gap(), 20);
        assert!(!h.observe(30, true), "11 + 20 = 31");
        assert!(h.observe(31, true));
        // Failed again (32 < 31 + 10): 40 frames.
        assert!(h.observe(32, true));
        assert_eq!(h.gap(), 40);
        assert!(!h.observe(71, true));
        assert!(h.observe(72, true));
        // This one holds 10 frames: the next failure starts from the plain gap.
        assert!(!h.observe(81, false));
        assert!(h.observe(82, true));
        assert_eq!(h.gap(), 10);
        // The doubling stops at 2^MAX_BACKOFF.
        let mut h = Hysteresis::new(1, 1, 10);
        let mut at = 0;
        for _ in 0..20 {
            assert!(h.observe(at, true));
            at += h.gap();
            assert!(h.observe(at, true));
            at += 1;
        }
        assert_eq!(h.gap(), 10 << MAX_BACKOFF);
        // No gap (the matcher's policy): nothing waits.
        let mut h = Hysteresis::new(1, 1, 0);
        assert!((0..6).all(|id| h.observe(id, true)));
    }

    #[test]
    fn falls_back_after_consecutive_failures_only() {
        let mut c = controller();
        let good = frame(MatcherMode::Lbd, 40, -1, 5);
        let few = frame(MatcherMode::Lbd, 3, -1, 5);
        assert_eq!(c.observe(&few, &pose(20, 30)), None);
        assert_eq!(c.observe(&few, &pose(20, 30)), None);
        assert_eq!(
            c.observe(&good, &pose(20, 30)),
            None,
            "a good frame resets the streak"
        );
        assert_eq!(c.observe(&few, &pose(20, 30)), None);
        assert_eq!(c.observe(&few, &pose(20, 30)), None);
        let switch = c
            .observe(&few, &pose(20, 30))
            .unwrap_or_else(|| panic!("no fallback"));
        assert_eq!(switch.to, MatcherMode::L1);
        assert!(
            switch
                .reason
                .contains("too few LBD stereo matches (3 < 12)"),
            "{}",
            switch.reason
        );
        assert_eq!(c.mode(), MatcherMode::L1);
    }

    #[test]
    fn inlier_collapse_and_budget_are_failures_too() {
        let mut c = controller();
        for _ in 0..2 {
            assert_eq!(
                c.observe(&frame(MatcherMode::Lbd, 40, -1, 5), &pose(2, 30)),
                None
            );
        }
        let s = c
            .observe(&frame(MatcherMode::Lbd, 40, -1, 5), &pose(2, 30))
            .unwrap_or_else(|| panic!("no fallback"));
        assert!(s.reason.contains("inlier ratio"), "{}", s.reason);
        let mut c = controller();
        for _ in 0..2 {
            c.observe(&frame(MatcherMode::Lbd, 40, -1, 80), &pose(20, 30));
        }
        let s = c
            .observe(&frame(MatcherMode::Lbd, 40, -1, 80), &pose(20, 30))
            .unwrap_or_else(|| panic!("no fallback"));
        assert!(s.reason.contains("over budget"), "{}", s.reason);
        // Few observations: the ratio is not judged.
        let mut c = controller();
        for _ in 0..5 {
            assert_eq!(
                c.observe(&frame(MatcherMode::Lbd, 40, -1, 5), &pose(0, 5)),
                None
            );
        }
    }

    #[test]
    fn returns_to_lbd_with_hysteresis() {
        let mut c = controller();
        for _ in 0..3 {
            c.observe(&frame(MatcherMode::Lbd, 3, -1, 5), &pose(0, 0));
        }
        assert_eq!(c.mode(), MatcherMode::L1);
        // Frames without a probe, and probes between the two thresholds, do not bring it back.
        assert_eq!(
            c.observe(&frame(MatcherMode::L1, 50, -1, 5), &pose(0, 0)),
            None
        );
        assert_eq!(
            c.observe(&frame(MatcherMode::L1, 50, 18, 5), &pose(0, 0)),
            None
        );
        assert_eq!(
            c.observe(&frame(MatcherMode::L1, 50, 30, 5), &pose(0, 0)),
            None
        );
        assert_eq!(
            c.observe(&frame(MatcherMode::L1, 50, 18, 5), &pose(0, 0)),
            None,
            "a failed probe resets the count"
        );
        assert_eq!(
            c.observe(&frame(MatcherMode::L1, 50, 30, 5), &pose(0, 0)),
            None
        );
        let back = c
            .observe(&frame(MatcherMode::L1, 50, 31, 5), &pose(0, 0))
            .unwrap_or_else(|| panic!("no recovery"));
        assert_eq!(back.to, MatcherMode::Lbd);
        assert_eq!(c.mode(), MatcherMode::Lbd);
    }

    #[test]
    fn recovery_waits_for_the_budget_too_so_a_slow_matcher_does_not_flap() {
        // Budget 50 ms, recovery bar 0.8 × 50 = 40 ms.
        let mut c = controller();
        for _ in 0..3 {
            c.observe(&frame(MatcherMode::Lbd, 40, -1, 60), &pose(0, 0));
        }
        assert_eq!(c.mode(), MatcherMode::L1, "over budget: fallback");
        // Probes with plenty of LBD matches but the matcher between the bar and the budget:
        // no recovery, however many.
        for _ in 0..20 {
            assert_eq!(
                c.observe(&frame(MatcherMode::L1, 50, 40, 45), &pose(0, 0)),
                None
            );
        }
        // Within the bar: back after `recover_probes` probes in a row; one slow probe
        // between them starts the count again.
        assert_eq!(
            c.observe(&frame(MatcherMode::L1, 50, 40, 30), &pose(0, 0)),
            None
        );
        assert_eq!(
            c.observe(&frame(MatcherMode::L1, 50, 40, 41), &pose(0, 0)),
            None
        );
        assert_eq!(
            c.observe(&frame(MatcherMode::L1, 50, 40, 30), &pose(0, 0)),
            None
        );
        let back = c
            .observe(&frame(MatcherMode::L1, 50, 40, 40), &pose(0, 0))
            .unwrap_or_else(|| panic!("no recovery"));
        assert!(back.reason.contains("within 40.0 ms"), "{}", back.reason);
    }

    #[test]
    fn latency_around_the_budget_switches_once_not_back_and_forth() {
        // A matcher hovering around its budget (LBD 45–60 ms; the probe frames, ℓ1 and LBD
        // together, 45–55 ms) with LBD matching well: one fallback, no recovery.
        let mut c = controller();
        let mut switches = 0;
        for i in 0..200u64 {
            let ms = 45 + (i * 7) % 16;
            let header = match c.mode() {
                MatcherMode::Lbd => frame(MatcherMode::Lbd, 40, -1, ms),
                _ => frame(
                    MatcherMode::L1,
                    50,
                    if i % 5 == 0 { 40 } else { -1 },
                    ms.min(55),
                ),
            };
            switches += usize::from(c.observe(&header, &pose(20, 30)).is_some());
        }
        assert_eq!(switches, 1);
        // With a recovery bar the probes clear (as when only counts mattered), it flaps.
        let mut loose = FallbackController::new(
            FallbackConfig {
                recover_budget_fraction: 0.95,
                ..controller().config
            },
            50.0,
            100.0,
        );
        let mut switches = 0;
        for i in 0..200u64 {
            let ms = 45 + (i * 7) % 16;
            let header = match loose.mode() {
                MatcherMode::Lbd => frame(MatcherMode::Lbd, 40, -1, ms),
                _ => frame(MatcherMode::L1, 50, if i % 5 == 0 { 40 } else { -1 }, 45),
            };
            switches += usize::from(loose.observe(&header, &pose(20, 30)).is_some());
        }
        assert!(switches > 2, "{switches}: the comparison should flap");
    }
}
