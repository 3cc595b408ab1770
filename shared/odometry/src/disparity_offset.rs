//! The rig's disparity offset as the frames go: a running, information-weighted mean of
//! the frames' evidence ([`OffsetEvidence`]), which triangulation subtracts from every
//! disparity (see [`DisparityOffsetConfig`]).

use linetrack_odometry_config::DisparityOffsetConfig;
use linetrack_stereo_vo::OffsetEvidence;

/// An information-weighted running mean of the frames' offsets.
#[derive(Debug, Clone, Copy, PartialEq)]
struct RunningMean {
    /// Measured minus true disparity, pixels.
    px: f64,
    /// Inverse variance of `px`, 1/px².
    information: f64,
}

impl RunningMean {
    /// Takes in a frame that puts the offset at `seen` with `information`; the mean stays
    /// within `±max_px` and never surer than `most`.
    fn take(&mut self, seen: f64, information: f64, max_px: f64, most: f64) {
        let gain = information / (self.information + information);
        self.px = (self.px + gain * (seen - self.px)).clamp(-max_px, max_px);
        self.information = (self.information + information).min(most);
    }
}

/// The offset believed now, how sure of it, and the one applied.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct DisparityOffset {
    config: DisparityOffsetConfig,
    /// The running estimate, starting at `initial_px` with `initial_sigma_px`: it decides
    /// whether an offset is applied.
    estimate: RunningMean,
    /// The same mean of the frames without that start: the value applied. The start holds
    /// the estimate back until the evidence outweighs it; past that, it would only keep
    /// pulling the offset applied towards `initial_px` (a rig one pixel off read −0.52 px
    /// when first applied and −0.93 px ten frames later).
    frames: RunningMean,
    /// What triangulation subtracts: `initial_px` until the estimate departs from it by
    /// more than `departure_sigmas` of its standard deviation and more than `min_px`, then
    /// the estimate for as long as it stays more than half of `min_px` away.
    applied_px: f64,
}

impl DisparityOffset {
    pub(crate) fn new(config: DisparityOffsetConfig) -> Self {
        Self {
            estimate: RunningMean {
                px: config.initial_px,
                information: config.initial_sigma_px.powi(-2),
            },
            frames: RunningMean {
                px: config.initial_px,
                information: 0.0,
            },
            applied_px: config.initial_px,
            config,
        }
    }

    /// The offset to subtract from a measured disparity, pixels.
    pub(crate) fn value_px(&self) -> f64 {
        self.applied_px
    }

    /// The running estimate, pixels: the frames' alone while applied, else held by the
    /// start.
    pub(crate) fn estimate_px(&self) -> f64 {
        if self.is_applied() {
            self.frames.px
        } else {
            self.estimate.px
        }
    }

    /// Whether an estimate is applied (the offset is not `initial_px`).
    fn is_applied(&self) -> bool {
        self.applied_px != self.config.initial_px
    }

    /// Takes in a frame's evidence (nothing when `estimate` is off): the features it was
    /// fitted to had their disparities corrected by `applied`, and the evidence says by how
    /// much more they should have been, so that frame puts the offset at `applied` plus
    /// it. The estimate is the information-weighted running mean of those.
    pub(crate) fn update(&mut self, applied: f64, evidence: Option<OffsetEvidence>) {
        let Some(evidence) = evidence.filter(|_| self.config.estimate) else {
            return;
        };
        let c = &self.config;
        let variance = evidence.variance_px2 + c.frame_sigma_px * c.frame_sigma_px;
        if !(variance.is_finite() && evidence.correction_px.is_finite()) {
            return;
        }
        let frame_information = 1.0 / variance;
        let seen = applied + evidence.correction_px.clamp(-1.0, 1.0);
        let most = c.floor_sigma_px.powi(-2);
        for mean in [&mut self.estimate, &mut self.frames] {
            mean.take(seen, frame_information, c.max_px, most);
        }
        let departure = (self.estimate.px - c.initial_px).abs();
        let sure = departure * self.estimate.information.sqrt() > c.departure_sigmas;
        // Once applied, it stays while the estimate keeps more than half of `min_px` (the
        // KITTI raw drive moved by a pixel, before the landmarks were moved with the
        // offset: applied at −0.77 px, the next frames said −0.74 … −0.70 before it settled
        // at −1.04, and without this it went off and on again).
        let needed = if self.is_applied() {
            0.5 * c.min_px
        } else {
            c.min_px
        };
        self.applied_px = if sure && departure > needed {
            self.frames.px
        } else {
            c.initial_px
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn evidence(correction_px: f64) -> Option<OffsetEvidence> {
        Some(OffsetEvidence {
            correction_px,
            variance_px2: 0.01,
        })
    }

    #[test]
    fn steady_evidence_is_followed_and_noise_is_averaged() {
        let mut offset = DisparityOffset::new(DisparityOffsetConfig::default());
        // A rig one pixel off: each frame says "a bit more" until the estimate is there.
        for _ in 0..200 {
            let applied = offset.value_px();
            offset.update(applied, evidence(-1.0 - applied));
        }
        assert!(
            (offset.value_px() + 1.0).abs() < 0.01,
            "{}",
            offset.value_px()
        );
        // Alternating evidence of ±0.3 px around the truth moves it little.
        for k in 0..200 {
            let applied = offset.value_px();
            offset.update(
                applied,
                evidence(-1.0 - applied + if k % 2 == 0 { 0.3 } else { -0.3 }),
            );
        }
        assert!(
            (offset.value_px() + 1.0).abs() < 0.05,
            "{}",
            offset.value_px()
        );
    }

    /// The start holds the estimate back until the frames outweigh it; the offset then
    /// applied is the frames' own mean, not one still pulled towards the start.
    #[test]
    fn once_the_evidence_outweighs_the_start_the_frames_alone_say_the_offset() {
        let mut offset = DisparityOffset::new(DisparityOffsetConfig::default());
        let mut frames = 0;
        while offset.value_px() == 0.0 {
            assert!(frames < 20, "never applied: {}", offset.estimate_px());
            let applied = offset.value_px();
            offset.update(applied, evidence(-1.0 - applied));
            frames += 1;
        }
        // With the start in it, the mean after those frames is still well short of −1.
        let c = DisparityOffsetConfig::default();
        let frame_information = 1.0 / (0.01 + c.frame_sigma_px.powi(2));
        let start_information = c.initial_sigma_px.powi(-2);
        let held = -f64::from(frames) * frame_information
            / (f64::from(frames) * frame_information + start_information);
        assert!(held > -0.7, "{held}");
        assert!(
            (offset.value_px() + 1.0).abs() < 1e-9,
            "applied {} after {frames} frames",
            offset.value_px()
        );
        assert_eq!(offset.estimate_px(), offset.value_px());
    }

    #[test]
    fn an_estimate_within_its_noise_of_the_start_is_not_applied() {
        let mut offset = DisparityOffset::new(DisparityOffsetConfig::default());
        // A steady 0.04 px: within three standard deviations however long it lasts.
        for _ in 0..500 {
            offset.update(offset.value_px(), evidence(0.04));
        }
        assert_eq!(offset.value_px(), 0.0);
        // A steady 0.9 of `min_px` is sure enough but under it.
        let floor = DisparityOffsetConfig::default().min_px;
        for _ in 0..500 {
            offset.update(offset.value_px(), evidence(0.9 * floor));
        }
        assert!(
            (offset.estimate_px() - 0.9 * floor).abs() < 0.01,
            "{}",
            offset.estimate_px()
        );
        assert_eq!(offset.value_px(), 0.0);
        // One frame saying twice `min_px` is not enough either.
        let mut offset = DisparityOffset::new(DisparityOffsetConfig::default());
        offset.update(0.0, evidence(2.0 * floor));
        assert_eq!(offset.value_px(), 0.0);
    }

    #[test]
    fn once_applied_it_holds_down_to_half_the_floor() {
        let mut offset = DisparityOffset::new(DisparityOffsetConfig::default());
        let settle_at = |offset: &mut DisparityOffset, seen_px: f64| {
            for _ in 0..500 {
                let applied = offset.value_px();
                offset.update(applied, evidence(seen_px - applied));
            }
        };
        let floor = DisparityOffsetConfig::default().min_px;
        settle_at(&mut offset, -2.0 * floor);
        assert!((offset.value_px() + 2.0 * floor).abs() < 0.01);
        // Under the floor, over half of it: still applied.
        settle_at(&mut offset, -0.8 * floor);
        assert!(
            (offset.value_px() + 0.8 * floor).abs() < 0.01,
            "{}",
            offset.value_px()
        );
        // Under half of it: let go.
        settle_at(&mut offset, -0.4 * floor);
        assert_eq!(offset.value_px(), 0.0);
        assert!((offset.estimate_px() + 0.4 * floor).abs() < 0.01);
    }

    #[test]
    fn off_it_keeps_the_given_offset_and_one_frame_is_bounded() {
        let fixed = DisparityOffsetConfig {
            estimate: false,
            initial_px: 0.4,
            ..DisparityOffsetConfig::default()
        };
        let mut offset = DisparityOffset::new(fixed);
        offset.update(0.4, evidence(2.0));
        assert_eq!(offset.value_px(), 0.4);
        let mut offset = DisparityOffset::new(DisparityOffsetConfig {
            initial_sigma_px: 100.0,
            ..DisparityOffsetConfig::default()
        });
        offset.update(0.0, evidence(50.0));
        assert!(offset.value_px() <= 1.0, "{}", offset.value_px());
        offset.update(0.0, evidence(f64::NAN));
        assert!(offset.value_px().is_finite());
    }
}
