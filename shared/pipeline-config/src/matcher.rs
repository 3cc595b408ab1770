//! `[matcher]`: the matcher stage's policy and when it falls back from LBD to ℓ1 and back.

use crate::limits::{MAX_MATCHES, check_hysteresis, in_range};
use serde::{Deserialize, Serialize};

/// Which segment matcher the matcher stage uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MatcherPolicy {
    /// LBD, falling back to ℓ1 when descriptor matching fails, with hysteresis.
    Auto,
    /// LBD only.
    Lbd,
    /// ℓ1 only.
    L1,
}

/// When the supervisor switches LBD → ℓ1 and back.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FallbackConfig {
    /// LBD is failing on a frame with fewer stereo segment matches than this.
    pub min_stereo_matches: u32,
    /// ... or when fewer than this fraction of the frame-to-frame line observations are
    /// inliers of the motion estimate (with at least `min_observations` observations).
    pub min_inlier_ratio: f64,
    /// Observations needed before the inlier ratio is judged.
    pub min_observations: u32,
    /// ... or when the matcher stage goes over its budget.
    pub over_budget: bool,
    /// ... or when the frame misses `budget.end_to_end_ms` (processed late, or dropped late
    /// by any stage): the pipeline's deadline, not only the matcher's own. With it, a probe
    /// passes only when its frame's end to end is within `recover_budget_fraction` of that
    /// budget too.
    pub end_to_end: bool,
    /// Consecutive failing frames before switching to ℓ1.
    pub bad_frames: u32,
    /// In ℓ1 mode, the matcher also runs LBD on every n-th frame to see if it works again.
    pub probe_every: u32,
    /// A probe passes with at least this many LBD stereo matches (above
    /// `min_stereo_matches`: the hysteresis band).
    pub recover_stereo_matches: u32,
    /// Consecutive passing probes before switching back to LBD.
    pub recover_probes: u32,
    /// With `over_budget`, a probe also passes only when the matcher stage (ℓ1 and the LBD
    /// probe together) took at most this fraction of its budget: below the failing bar
    /// (the budget itself), the latency's hysteresis band.
    pub recover_budget_fraction: f64,
    /// Lines only: while LBD matches, a frame whose LBD segment matches would be lost is
    /// matched again by the pose estimator with ℓ1 where the motion predicts the last
    /// frame's segments (and, failing that, as `[odometry.lost] rescue_*` rescue an ℓ1
    /// frame), and tracked with those if they give a believed estimate: the fallback for
    /// the one frame, which the switch above only makes after `bad_frames`. Each such frame
    /// is an `l1-rescue` event. With points it does nothing.
    pub rescue_lost_frames: bool,
}

impl Default for FallbackConfig {
    fn default() -> Self {
        Self {
            min_stereo_matches: 12,
            min_inlier_ratio: 0.25,
            min_observations: 10,
            over_budget: true,
            end_to_end: true,
            bad_frames: 3,
            probe_every: 5,
            recover_stereo_matches: 24,
            recover_probes: 2,
            recover_budget_fraction: 0.8,
            rescue_lost_frames: true,
        }
    }
}

/// Matcher stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MatcherConfig {
    /// auto, lbd or l1.
    pub mode: MatcherPolicy,
    /// Fallback rules for `auto`.
    pub fallback: FallbackConfig,
}

impl MatcherPolicy {
    /// `auto`, `lbd` or `l1`, as in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            MatcherPolicy::Auto => "auto",
            MatcherPolicy::Lbd => "lbd",
            MatcherPolicy::L1 => "l1",
        }
    }
}

impl std::str::FromStr for MatcherPolicy {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        [MatcherPolicy::L1, MatcherPolicy::Lbd, MatcherPolicy::Auto]
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| format!("{s:?}: expected l1, lbd or auto"))
    }
}

impl MatcherConfig {
    /// `auto`, `lbd` or `l1`.
    pub fn mode_name(&self) -> &'static str {
        self.mode.name()
    }
}

impl Default for MatcherConfig {
    fn default() -> Self {
        Self {
            mode: MatcherPolicy::L1,
            fallback: FallbackConfig::default(),
        }
    }
}

impl MatcherConfig {
    /// The first out-of-range key of `[matcher]` (its fallback rules).
    pub fn validate(&self) -> Result<(), String> {
        let f = &self.fallback;
        in_range(
            "matcher.fallback.min_stereo_matches",
            f.min_stereo_matches,
            1..=MAX_MATCHES,
        )?;
        in_range(
            "matcher.fallback.min_inlier_ratio",
            f.min_inlier_ratio,
            0.0..=1.0,
        )?;
        in_range(
            "matcher.fallback.min_observations",
            f.min_observations,
            0..=MAX_MATCHES,
        )?;
        check_hysteresis(
            "matcher.fallback",
            &[
                ("bad_frames", f.bad_frames),
                ("probe_every", f.probe_every),
                ("recover_probes", f.recover_probes),
            ],
            f.recover_budget_fraction,
        )?;
        in_range(
            "matcher.fallback.recover_stereo_matches",
            f.recover_stereo_matches,
            f.min_stereo_matches.saturating_add(1)..=MAX_MATCHES,
        )
        .map_err(|e| format!("{e}: above min_stereo_matches, that gap is the hysteresis"))
    }
}
