//! `[detector_fallback]`: the line detector's hot swap from LSD to a faster one under
//! budget pressure, and back.

use crate::limits::{MAX_FRAMES, check_hysteresis, in_range};
use linetrack_vision_config::DetectorKind;
use serde::{Deserialize, Serialize};

/// When the supervisor hot-swaps the line detector from LSD to a faster one under budget
/// pressure, and back (`[detector_fallback]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DetectorFallbackConfig {
    /// The off switch: false leaves the detector to the config and `linetrack ctl`.
    pub enabled: bool,
    /// The faster detector LSD gives way to (not LSD). Edgelines by default: the cheapest
    /// (2.7 ms an image against FLD's 11.8 on EuRoC). `linetrack run` on 1,200 EuRoC frames
    /// with LSD, `--matcher auto` and two CPU hogs on a 2-core machine dropped 23 % giving
    /// way to FLD and 8.1 and 12.8 % (two runs) giving way to edgelines, but those runs went
    /// at 7-8 frames a second, not 20 (the reader at `source.reader_nice = 10` starved by the
    /// hogs); at a real 20 Hz (`reader_nice = 0`) 47.9 % were dropped, 29.8 % with OpenCV on
    /// one thread (docs/pipeline.md).
    pub to: DetectorKind,
    /// Consecutive LSD frames over `budget.line_detector_ms` before the swap.
    pub bad_frames: u32,
    /// Consecutive frames of the faster detector within `recover_budget_fraction` of the
    /// budget before the swap back to LSD.
    pub recover_frames: u32,
    /// The fraction (< 1: the hysteresis band) of `budget.line_detector_ms` the faster
    /// detector must stay within for the swap back: about its share of LSD's time, so that
    /// LSD would fit again. 0.075 for edgelines (2.7 against 36 ms an image); about 0.25
    /// for FLD. With 0.25 and edgelines, LSD came back beside two CPU hogs and missed its
    /// budget again (docs/pipeline.md).
    pub recover_budget_fraction: f64,
    /// Frames after the policy's last swap before a swap back to LSD, at least; doubled
    /// after each swap back that gave way again within that many frames (up to 64 times),
    /// back to this after one that held. The swap away from LSD never waits.
    pub min_interval_frames: u64,
    /// An LSD frame that misses `budget.end_to_end_ms` (processed late, or dropped late by
    /// any stage) counts as over budget too: the pipeline's deadline, not only LSD's own.
    pub end_to_end: bool,
}

impl Default for DetectorFallbackConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            to: DetectorKind::EdgeLines,
            bad_frames: 5,
            recover_frames: 40,
            recover_budget_fraction: 0.075,
            min_interval_frames: 200,
            end_to_end: true,
        }
    }
}

impl DetectorFallbackConfig {
    /// The first out-of-range key of `[detector_fallback]`.
    pub fn validate(&self) -> Result<(), String> {
        if self.to == DetectorKind::Lsd {
            return Err(
                "detector_fallback.to = \"lsd\": the detector LSD gives way to must be a faster one (fld or edgelines)"
                    .to_string(),
            );
        }
        check_hysteresis(
            "detector_fallback",
            &[
                ("bad_frames", self.bad_frames),
                ("recover_frames", self.recover_frames),
            ],
            self.recover_budget_fraction,
        )?;
        in_range(
            "detector_fallback.min_interval_frames",
            self.min_interval_frames,
            0..=MAX_FRAMES as u64,
        )
    }
}
