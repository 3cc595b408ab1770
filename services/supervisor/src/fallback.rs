//! When the matcher falls back from LBD to ℓ1 and when it returns.

use linetrack_msgs::{FrameHeader, MatcherMode, PoseRecord, StageKind};
use linetrack_pipeline_config::FallbackConfig;

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
/// hysteresis) switch back.
#[derive(Debug, Clone)]
pub struct FallbackController {
    config: FallbackConfig,
    matcher_budget_ms: f64,
    mode: MatcherMode,
    bad_streak: u32,
    good_probes: u32,
}

impl FallbackController {
    /// A controller starting in LBD mode.
    pub fn new(config: FallbackConfig, matcher_budget_ms: f64) -> Self {
        Self {
            config,
            matcher_budget_ms,
            mode: MatcherMode::Lbd,
            bad_streak: 0,
            good_probes: 0,
        }
    }

    /// The mode the controller wants.
    pub fn mode(&self) -> MatcherMode {
        self.mode
    }

    /// Why an LBD frame failed, if it did.
    fn failure(&self, header: &FrameHeader, pose: &PoseRecord) -> Option<String> {
        let c = &self.config;
        if header.stereo_matches < c.min_stereo_matches {
            return Some(format!(
                "too few LBD stereo matches ({} < {})",
                header.stereo_matches, c.min_stereo_matches
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
        let stamp = header.stamps[StageKind::Matcher.stamp_index().unwrap_or(2)];
        let ms = stamp.end_ns.saturating_sub(stamp.start_ns) as f64 * 1e-6;
        if c.over_budget && ms > self.matcher_budget_ms {
            return Some(format!(
                "matcher over budget ({ms:.1} ms > {:.1} ms)",
                self.matcher_budget_ms
            ));
        }
        None
    }

    /// Takes one processed frame's results; returns a switch when one is due.
    pub fn observe(&mut self, header: &FrameHeader, pose: &PoseRecord) -> Option<Switch> {
        match self.mode {
            MatcherMode::Lbd => {
                // Frames matched by ℓ1 for lack of images say nothing about LBD.
                if MatcherMode::from_code(header.matcher_mode) != Some(MatcherMode::Lbd) {
                    return None;
                }
                match self.failure(header, pose) {
                    Some(reason) => {
                        self.bad_streak += 1;
                        if self.bad_streak >= self.config.bad_frames {
                            self.mode = MatcherMode::L1;
                            self.bad_streak = 0;
                            self.good_probes = 0;
                            let reason =
                                format!("{reason}, {} frames in a row", self.config.bad_frames);
                            return Some(Switch {
                                to: MatcherMode::L1,
                                reason,
                            });
                        }
                    }
                    None => self.bad_streak = 0,
                }
                None
            }
            MatcherMode::L1 => {
                let Ok(found) = u32::try_from(header.lbd_probe_matches) else {
                    return None;
                };
                if found >= self.config.recover_stereo_matches {
                    self.good_probes += 1;
                } else {
                    self.good_probes = 0;
                }
                if self.good_probes >= self.config.recover_probes {
                    self.mode = MatcherMode::Lbd;
                    self.good_probes = 0;
                    let reason = format!(
                        "LBD probes found >= {} stereo matches on {} probes in a row (last {found})",
                        self.config.recover_stereo_matches, self.config.recover_probes
                    );
                    return Some(Switch {
                        to: MatcherMode::Lbd,
                        reason,
                    });
                }
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(mode: MatcherMode, stereo: u32, probe: i32, matcher_ms: u64) -> FrameHeader {
        let mut h = FrameHeader::new(0, 0, 0);
        h.matcher_mode = mode as u32;
        h.stereo_matches = stereo;
        h.lbd_probe_matches = probe;
        h.stamps[2].start_ns = 1_000_000;
        h.stamps[2].end_ns = 1_000_000 + matcher_ms * 1_000_000;
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
        )
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
}
