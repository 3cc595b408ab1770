//! The automatic detector policy (`[detector_fallback]`): LSD gives way to a faster
//! detector when it misses its budget, and comes back with hysteresis.
//!
//! While the line detector runs LSD, `bad_frames` frames in a row over
//! `budget.line_detector_ms` ask for a hot swap to `to` (edgelines by default); while that one
//! runs after such a swap, `recover_frames` frames in a row within `recover_budget_fraction`
//! of the budget ask for LSD back. The way back comes no sooner than `min_interval_frames`
//! after the policy's last swap, twice as long after each recovery that gave way again
//! within that many frames; the way to the faster detector never waits (it can only help
//! the deadline). The streaks are the matcher fallback's ([`Hysteresis`]). The
//! detector's time is read from each frame's stamps, never from a clock, so tests inject
//! it; a frame the detector did not process says nothing.

use crate::fallback::Hysteresis;
use crate::stamps::{detected, end_ns, stage_ms};
use linetrack_msgs::{StageKind, TracksHeader};
use linetrack_pipeline_config::DetectorFallbackConfig;
use linetrack_stage_runtime::detector_kind;
use linetrack_vision::DetectorKind;

/// The detector the policy watches for its budget.
const SLOW: DetectorKind = DetectorKind::Lsd;

/// A swap the policy asks for.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorSwitch {
    /// The detector to swap to.
    pub to: DetectorKind,
    /// `detector-fallback` or `detector-recover` (its kind in `events.csv`).
    pub event: &'static str,
    /// Why, in words.
    pub reason: String,
}

/// Watches the detector's time on each frame and decides when to swap.
#[derive(Debug, Clone)]
pub struct DetectorPolicy {
    config: DetectorFallbackConfig,
    budget_ms: f64,
    end_to_end_budget_ms: f64,
    /// Fallen back: the faster detector.
    streaks: Hysteresis,
}

impl DetectorPolicy {
    /// The policy of `config` against a detector budget of `budget_ms`; `None` when it is
    /// switched off.
    pub fn new(
        config: &DetectorFallbackConfig,
        budget_ms: f64,
        end_to_end_budget_ms: f64,
    ) -> Option<Self> {
        config.enabled.then(|| Self {
            config: config.clone(),
            budget_ms,
            end_to_end_budget_ms,
            streaks: Hysteresis::new(
                config.bad_frames,
                config.recover_frames,
                config.min_interval_frames,
            ),
        })
    }

    /// Takes one frame that reached the end while `running` is the running detector;
    /// returns a swap when one is due. Only frames of the running detector count (not
    /// those still on their way from the one before a swap).
    pub fn observe(
        &mut self,
        message: &TracksHeader,
        running: DetectorKind,
    ) -> Option<DetectorSwitch> {
        let header = &message.frame;
        if running == SLOW && self.streaks.fallen_back() {
            // LSD runs again without this policy (`linetrack ctl`, an abandoned swap):
            // watch it afresh.
            self.streaks.reset();
        }
        let detected_here = end_ns(header, StageKind::LineDetector) != 0
            && detected(header, StageKind::LineDetector)
            && message
                .detection
                .detector
                .get()
                .is_ok_and(|d| detector_kind(d) == running);
        let c = &self.config;
        // The pipeline's deadline: a frame LSD ran for (or that was dropped late while it
        // ran) and that missed the end-to-end budget.
        let late = (c.end_to_end && running == SLOW)
            .then(|| crate::fallback::end_to_end_miss(header, self.end_to_end_budget_ms))
            .flatten();
        if !detected_here && late.is_none() {
            return None;
        }
        let ms = stage_ms(header, StageKind::LineDetector);
        let kind = running;
        let budget = self.budget_ms;
        if kind == SLOW {
            let over = (detected_here && ms > budget) || late.is_some();
            return self
                .streaks
                .observe(header.frame_id, over)
                .then(|| DetectorSwitch {
                    to: c.to,
                    event: "detector-fallback",
                    reason: match &late {
                        Some(miss) if !(ms > budget) => format!(
                            "frames missed the {:.1} ms end-to-end budget while {} ran, {} in a row (last {miss})",
                            self.end_to_end_budget_ms,
                            SLOW.name(),
                            c.bad_frames
                        ),
                        _ => format!(
                            "{} over its {budget:.1} ms budget on {} frames in a row (last {ms:.1} ms)",
                            SLOW.name(),
                            c.bad_frames
                        ),
                    },
                });
        }
        if !detected_here {
            return None;
        }
        if kind != c.to || !self.streaks.fallen_back() {
            return None;
        }
        let bar = c.recover_budget_fraction * budget;
        let within = ms <= bar;
        self.streaks
            .observe(header.frame_id, within)
            .then(|| DetectorSwitch {
                to: SLOW,
                event: "detector-recover",
                reason: format!(
                    "{} within {bar:.1} ms ({} of the {budget:.1} ms budget) on {} frames in a row (last {ms:.1} ms)",
                    c.to.name(),
                    c.recover_budget_fraction,
                    c.recover_frames
                ),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::FrameStatus;
    use linetrack_msgs::StampSlot;
    use linetrack_stage_runtime::detector_on_wire;

    /// Frame `id` detected by `kind` in `ms` milliseconds (from its stamps).
    fn frame(id: u64, kind: DetectorKind, ms: f64) -> TracksHeader {
        let mut h = TracksHeader::default();
        h.frame.frame_id = id;
        h.detection.detector = detector_on_wire(kind).into();
        let stamp = &mut h.frame.stamps[StampSlot::LineDetector];
        stamp.start_ns = 5_000_000_000 + id * 50_000_000;
        stamp.end_ns = stamp.start_ns + (ms * 1e6) as u64;
        h
    }

    fn policy(min_interval_frames: u64) -> DetectorPolicy {
        DetectorPolicy::new(
            &DetectorFallbackConfig {
                bad_frames: 3,
                recover_frames: 4,
                recover_budget_fraction: 0.5,
                min_interval_frames,
                to: DetectorKind::Fld,
                ..DetectorFallbackConfig::default()
            },
            50.0,
            100.0,
        )
        .unwrap_or_else(|| panic!("enabled by default"))
    }

    #[test]
    fn lsd_within_its_budget_gives_way_when_frames_miss_the_end_to_end_budget() {
        let mut p = policy(0);
        let late = |id: u64| {
            let mut h = frame(id, LSD, 30.0);
            h.frame.capture_ns = 5_000_000_000 + id * 50_000_000;
            h.frame.stamps[StampSlot::PoseEstimator].end_ns = h.frame.capture_ns + 150_000_000;
            h
        };
        assert!(p.observe(&late(0), LSD).is_none());
        // Dropped late by the detector itself: never detected, still a miss while LSD runs.
        let mut dropped = TracksHeader::default();
        dropped.frame.frame_id = 1;
        dropped
            .frame
            .mark(FrameStatus::DroppedLate, StageKind::LineDetector);
        assert!(p.observe(&dropped, LSD).is_none());
        let switch = p
            .observe(&late(2), LSD)
            .unwrap_or_else(|| panic!("no swap on three end-to-end misses"));
        assert_eq!(switch.to, DetectorKind::Fld);
        assert_eq!(
            switch.reason,
            "frames missed the 100.0 ms end-to-end budget while lsd ran, 3 in a row (last end to end 150.0 ms > 100.0 ms)"
        );
        // With the end to end off, only LSD's own budget counts.
        let mut own = DetectorPolicy::new(
            &DetectorFallbackConfig {
                bad_frames: 3,
                end_to_end: false,
                ..DetectorFallbackConfig::default()
            },
            50.0,
            100.0,
        )
        .unwrap_or_else(|| panic!("enabled"));
        for id in 0..10 {
            assert!(own.observe(&late(id), LSD).is_none());
            assert!(own.observe(&dropped, LSD).is_none());
        }
    }

    /// Feeds `(detector, ms)` frames from `first` on, each while its detector runs; the
    /// ids of the frames that switched.
    fn run(
        p: &mut DetectorPolicy,
        first: u64,
        frames: &[(DetectorKind, f64)],
    ) -> Vec<(u64, DetectorSwitch)> {
        frames
            .iter()
            .zip(first..)
            .filter_map(|(&(kind, ms), id)| p.observe(&frame(id, kind, ms), kind).map(|s| (id, s)))
            .collect()
    }

    const LSD: DetectorKind = DetectorKind::Lsd;
    const FLD: DetectorKind = DetectorKind::Fld;

    #[test]
    fn lsd_over_budget_on_n_frames_in_a_row_swaps_to_fld_and_not_before() {
        let mut p = policy(0);
        // Two over, one within (exactly the budget is within): no swap.
        assert!(run(&mut p, 0, &[(LSD, 60.0), (LSD, 51.0), (LSD, 50.0)]).is_empty());
        let switches = run(&mut p, 3, &[(LSD, 55.0), (LSD, 80.0), (LSD, 50.1)]);
        assert_eq!(switches.len(), 1);
        let (id, s) = &switches[0];
        assert_eq!((*id, s.to, s.event), (5, FLD, "detector-fallback"));
        assert!(
            s.reason
                .contains("lsd over its 50.0 ms budget on 3 frames in a row (last 50.1 ms)"),
            "{}",
            s.reason
        );
        // LSD frames still on their way once FLD runs change nothing.
        for id in 6..16 {
            assert_eq!(p.observe(&frame(id, LSD, 90.0), FLD), None);
        }
        assert!(run(&mut p, 16, &[(FLD, 12.0); 3]).is_empty(), "3 of 4");
    }

    #[test]
    fn fld_comes_back_only_after_m_frames_within_the_fraction() {
        let mut p = policy(0);
        run(&mut p, 0, &[(LSD, 60.0); 3]);
        // Within the budget but above half of it: never back (the hysteresis band).
        assert!(run(&mut p, 3, &[(FLD, 30.0); 50]).is_empty());
        // Three within, one above: the count starts again.
        let mixed = [(FLD, 20.0), (FLD, 25.0), (FLD, 10.0), (FLD, 25.1)];
        assert!(run(&mut p, 53, &mixed).is_empty());
        let switches = run(&mut p, 57, &[(FLD, 12.0); 4]);
        assert_eq!(switches.len(), 1);
        let (id, s) = &switches[0];
        assert_eq!((*id, s.to, s.event), (60, LSD, "detector-recover"));
        assert!(
            s.reason.contains(
                "fld within 25.0 ms (0.5 of the 50.0 ms budget) on 4 frames in a row (last 12.0 ms)"
            ),
            "{}",
            s.reason
        );
    }

    /// LSD over its budget 3 frames of every 8 (`bad_frames` 3), FLD always fast, for
    /// `frames` frames; the frames that switched, with the detector switched to.
    fn load_around_the_budget(p: &mut DetectorPolicy, frames: u64) -> Vec<(u64, DetectorKind)> {
        let mut detector = LSD;
        let mut switches = Vec::new();
        for id in 0..frames {
            let ms = match detector {
                LSD if id % 8 < 3 => 60.0,
                LSD => 40.0,
                _ => 5.0,
            };
            if let Some(s) = p.observe(&frame(id, detector, ms), detector) {
                detector = s.to;
                switches.push((id, s.to));
            }
        }
        switches
    }

    #[test]
    fn lsd_gives_way_at_once_and_comes_back_after_a_gap_that_doubles_while_it_fails() {
        // Without an interval it swaps back and forth every few frames.
        let free = load_around_the_budget(&mut policy(0), 400);
        assert!(free.len() > 50, "{free:?}");
        // With 100 frames: each way back waits 100, 200, 400, 800 frames after the swap
        // before it (every recovery gives way again within 8 frames: it failed); each way
        // to FLD comes on the third LSD frame over the budget.
        let spaced = load_around_the_budget(&mut policy(100), 2000);
        let waits: Vec<u64> = spaced
            .windows(2)
            .filter(|w| w[1].1 == LSD)
            .map(|w| w[1].0 - w[0].0)
            .collect();
        assert_eq!(waits.len(), 4, "{spaced:?}");
        for (k, wait) in waits.iter().enumerate() {
            assert!(
                (100 << k..(100 << k) + 8).contains(wait),
                "recovery {k} after {wait} frames: {spaced:?}"
            );
        }
        assert!(
            spaced
                .windows(2)
                .filter(|w| w[1].1 == FLD)
                .all(|w| w[1].0 - w[0].0 <= 8),
            "{spaced:?}"
        );
    }

    #[test]
    fn frames_the_detector_dropped_say_nothing_and_those_dropped_after_it_count() {
        // Overloaded LSD: it detects every third frame (slowly) and drops the ones that
        // queued behind meanwhile (in no time); the matcher drops the detected ones late.
        let mut p = policy(0);
        let mut switches = Vec::new();
        for id in 0..9u64 {
            let mut h = frame(id, LSD, if id % 3 == 0 { 150.0 } else { 0.001 });
            if id % 3 == 0 {
                h.frame.mark(FrameStatus::DroppedLate, StageKind::Matcher);
            } else {
                h.frame
                    .mark(FrameStatus::DroppedBehind, StageKind::LineDetector);
            }
            switches.extend(p.observe(&h, LSD).map(|s| (id, s.to)));
        }
        assert_eq!(switches, [(6, FLD)], "the third detected frame");
    }

    #[test]
    fn other_detectors_and_unprocessed_frames_say_nothing_and_off_means_off() {
        let mut p = policy(0);
        assert!(run(&mut p, 0, &[(DetectorKind::EdgeLines, 500.0); 20]).is_empty());
        assert!(
            run(&mut p, 20, &[(FLD, 500.0); 20]).is_empty(),
            "not fallen back"
        );
        let mut unprocessed = frame(40, LSD, 90.0);
        unprocessed.frame.stamps[StampSlot::LineDetector].end_ns = 0;
        for _ in 0..10 {
            assert_eq!(p.observe(&unprocessed, LSD), None);
        }
        // A fallback, then LSD back by `linetrack ctl`: watched afresh.
        assert_eq!(run(&mut p, 41, &[(LSD, 60.0); 3]).len(), 1);
        assert_eq!(run(&mut p, 44, &[(LSD, 60.0); 3]).len(), 1);
        assert!(
            DetectorPolicy::new(
                &DetectorFallbackConfig {
                    enabled: false,
                    ..DetectorFallbackConfig::default()
                },
                50.0,
                100.0
            )
            .is_none()
        );
    }
}
