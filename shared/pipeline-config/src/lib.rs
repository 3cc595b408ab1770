//! The pipeline's configuration (`configs/pipeline.toml`): what the frame source reads and
//! how fast, which detector and matcher run, the latency budgets and drop policy, when the
//! matcher falls back to ℓ1 and comes back, and how the supervisor watches and restarts
//! stages. Every field has a default; [`PipelineConfig::validate`] names the first bad one.

use linetrack_odometry::OdometryConfig;
use linetrack_vision::DetectorKind;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Errors reading a pipeline config.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read {}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The TOML is malformed or has unknown keys.
    #[error("{origin}: {message}")]
    Parse {
        /// The file (or `<string>`).
        origin: String,
        /// The parser's message.
        message: String,
    },
    /// A value is out of range.
    #[error("{origin}: {message}")]
    Invalid {
        /// The file (or `<string>`).
        origin: String,
        /// Which key and why.
        message: String,
    },
}

/// How fast the frame source publishes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Pacing {
    /// At the sequence's own frame rate (its timestamps), as a camera would.
    Realtime,
    /// As fast as the source can read; late frames are then dropped by policy downstream.
    Fastest,
}

/// The frame source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SourceConfig {
    /// A EuRoC (`mav0/cam0`, `mav0/cam1`) or KITTI (`image_0`, `image_1`) sequence folder.
    pub sequence: PathBuf,
    /// Realtime or fastest.
    pub pacing: Pacing,
    /// Frames per second for realtime pacing; 0 = from the sequence's timestamps.
    pub rate_hz: f64,
    /// Publish at most this many frames (0 = all).
    pub max_frames: usize,
}

impl Default for SourceConfig {
    fn default() -> Self {
        Self {
            sequence: PathBuf::from("out/sequences/pipeline"),
            pacing: Pacing::Realtime,
            rate_hz: 0.0,
            max_frames: 0,
        }
    }
}

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
    /// Consecutive failing frames before switching to ℓ1.
    pub bad_frames: u32,
    /// In ℓ1 mode, the matcher also runs LBD on every n-th frame to see if it works again.
    pub probe_every: u32,
    /// A probe passes with at least this many LBD stereo matches (above
    /// `min_stereo_matches`: the hysteresis band).
    pub recover_stereo_matches: u32,
    /// Consecutive passing probes before switching back to LBD.
    pub recover_probes: u32,
}

impl Default for FallbackConfig {
    fn default() -> Self {
        Self {
            min_stereo_matches: 12,
            min_inlier_ratio: 0.25,
            min_observations: 10,
            over_budget: true,
            bad_frames: 3,
            probe_every: 5,
            recover_stereo_matches: 24,
            recover_probes: 2,
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

impl MatcherConfig {
    /// `auto`, `lbd` or `l1`.
    pub fn mode_name(&self) -> &'static str {
        match self.mode {
            MatcherPolicy::Auto => "auto",
            MatcherPolicy::Lbd => "lbd",
            MatcherPolicy::L1 => "l1",
        }
    }
}

impl Default for MatcherConfig {
    fn default() -> Self {
        Self {
            mode: MatcherPolicy::Auto,
            fallback: FallbackConfig::default(),
        }
    }
}

/// Latency budgets, milliseconds, and what happens to late frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BudgetConfig {
    /// From the source starting to read a frame to its pose being published.
    pub end_to_end_ms: f64,
    /// Frame source: read, decode and publish.
    pub frame_source_ms: f64,
    /// Line detector: both images.
    pub line_detector_ms: f64,
    /// Matcher: description and stereo + frame-to-frame matching.
    pub matcher_ms: f64,
    /// Pose estimator.
    pub pose_estimator_ms: f64,
    /// Drop a frame that is already over the end-to-end budget when a stage takes it, and
    /// any frame with a newer one queued behind it; otherwise process every frame.
    pub drop_late: bool,
}

impl Default for BudgetConfig {
    fn default() -> Self {
        Self {
            end_to_end_ms: 250.0,
            frame_source_ms: 30.0,
            line_detector_ms: 80.0,
            matcher_ms: 80.0,
            pose_estimator_ms: 60.0,
            drop_late: true,
        }
    }
}

impl BudgetConfig {
    /// The budget of the stage named `stage_name` (`frame-source`, `line-detector`, ...).
    pub fn stage_ms(&self, stage_name: &str) -> Option<f64> {
        match stage_name {
            "frame-source" => Some(self.frame_source_ms),
            "line-detector" => Some(self.line_detector_ms),
            "matcher" => Some(self.matcher_ms),
            "pose-estimator" => Some(self.pose_estimator_ms),
            _ => None,
        }
    }
}

/// Supervision.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SupervisorConfig {
    /// Stages report alive this often.
    pub heartbeat_ms: u64,
    /// A stage silent this long is hung: it is killed and restarted.
    pub hang_timeout_ms: u64,
    /// Stages must report ready within this.
    pub startup_timeout_ms: u64,
    /// First restart delay; doubles on each restart of the same stage.
    pub restart_backoff_ms: u64,
    /// Longest restart delay.
    pub restart_backoff_max_ms: u64,
    /// Restarts per stage before the run is abandoned.
    pub max_restarts: u32,
    /// After the source finishes, wait this long for the last poses.
    pub drain_timeout_ms: u64,
    /// On shutdown, wait this long for a stage to exit before killing it.
    pub shutdown_grace_ms: u64,
    /// Print a live status line this often (0 = never).
    pub status_every_ms: u64,
}

impl Default for SupervisorConfig {
    fn default() -> Self {
        Self {
            heartbeat_ms: 200,
            hang_timeout_ms: 3000,
            startup_timeout_ms: 30_000,
            restart_backoff_ms: 200,
            restart_backoff_max_ms: 5000,
            max_restarts: 5,
            drain_timeout_ms: 5000,
            shutdown_grace_ms: 3000,
            status_every_ms: 1000,
        }
    }
}

/// Where the run's records go.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// Each run gets a new folder here named by its UTC start time
    /// (`2026-11-23T12-00-00`), and `latest` here is a symlink to the newest.
    pub runs_dir: PathBuf,
    /// A fixed run folder instead (`linetrack run --run-dir`): frames.csv, events.csv,
    /// poses (TUM), summary.json, trace files. Locked while a run writes into it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub run_dir: Option<PathBuf>,
    /// Write per-process span files and the merged Chrome/Perfetto trace.
    pub trace: bool,
}

impl Default for OutputConfig {
    fn default() -> Self {
        Self {
            runs_dir: PathBuf::from("out/runs"),
            run_dir: None,
            trace: true,
        }
    }
}

/// The whole pipeline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PipelineConfig {
    /// Frame source.
    pub source: SourceConfig,
    /// Line detector at start (swappable at run time).
    pub detector: DetectorKind,
    /// Matcher policy.
    pub matcher: MatcherConfig,
    /// Budgets and drop policy.
    pub budget: BudgetConfig,
    /// Supervision.
    pub supervisor: SupervisorConfig,
    /// Records.
    pub output: OutputConfig,
    /// Front end and motion estimation (its `detector` and `matcher` keys are ignored:
    /// the ones above rule).
    pub odometry: OdometryConfig,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            source: SourceConfig::default(),
            detector: DetectorKind::Lsd,
            matcher: MatcherConfig::default(),
            budget: BudgetConfig::default(),
            supervisor: SupervisorConfig::default(),
            output: OutputConfig::default(),
            odometry: OdometryConfig::default(),
        }
    }
}

impl PipelineConfig {
    /// Parses and validates TOML text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let config: Self = toml::from_str(text).map_err(|e| ConfigError::Parse {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        config.validate().map_err(|message| ConfigError::Invalid {
            origin: origin.to_string(),
            message,
        })?;
        Ok(config)
    }

    /// Reads and validates a config file.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// The first out-of-range value, named by its key.
    pub fn validate(&self) -> Result<(), String> {
        let positive = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{key} must be a positive number, got {v}"))
            }
        };
        let b = &self.budget;
        positive("budget.end_to_end_ms", b.end_to_end_ms)?;
        positive("budget.frame_source_ms", b.frame_source_ms)?;
        positive("budget.line_detector_ms", b.line_detector_ms)?;
        positive("budget.matcher_ms", b.matcher_ms)?;
        positive("budget.pose_estimator_ms", b.pose_estimator_ms)?;
        if !(self.source.rate_hz.is_finite() && self.source.rate_hz >= 0.0) {
            return Err(format!(
                "source.rate_hz must be >= 0 (0 = the sequence's rate), got {}",
                self.source.rate_hz
            ));
        }
        let f = &self.matcher.fallback;
        if !(0.0..=1.0).contains(&f.min_inlier_ratio) {
            return Err(format!(
                "matcher.fallback.min_inlier_ratio must be in [0, 1], got {}",
                f.min_inlier_ratio
            ));
        }
        if f.bad_frames == 0 || f.probe_every == 0 || f.recover_probes == 0 {
            return Err(
                "matcher.fallback.bad_frames, probe_every and recover_probes must be at least 1"
                    .to_string(),
            );
        }
        if f.recover_stereo_matches <= f.min_stereo_matches {
            return Err(format!(
                "matcher.fallback.recover_stereo_matches ({}) must exceed min_stereo_matches ({}): that gap is the hysteresis",
                f.recover_stereo_matches, f.min_stereo_matches
            ));
        }
        let s = &self.supervisor;
        if s.heartbeat_ms == 0 || s.hang_timeout_ms <= 2 * s.heartbeat_ms {
            return Err(format!(
                "supervisor.hang_timeout_ms ({}) must be more than twice heartbeat_ms ({}), which must be positive",
                s.hang_timeout_ms, s.heartbeat_ms
            ));
        }
        if s.restart_backoff_ms == 0 || s.restart_backoff_max_ms < s.restart_backoff_ms {
            return Err(
                "supervisor.restart_backoff_ms must be positive and at most restart_backoff_max_ms"
                    .to_string(),
            );
        }
        self.odometry
            .validate()
            .map_err(|e| format!("odometry.{e}"))?;
        Ok(())
    }

    /// The odometry settings with the pipeline's detector applied.
    pub fn odometry_config(&self) -> OdometryConfig {
        OdometryConfig {
            detector: self.detector,
            ..self.odometry.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_config_is_the_default() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/pipeline.toml");
        let shipped = PipelineConfig::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(shipped, PipelineConfig::default());
    }

    #[test]
    fn unknown_keys_and_bad_values_are_named() {
        let err = PipelineConfig::from_toml_str("[budget]\nend_to_end_mz = 3\n", "x.toml")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains("x.toml") && err.contains("end_to_end_mz"),
            "{err}"
        );
        let err = PipelineConfig::from_toml_str("[budget]\nmatcher_ms = nan\n", "x.toml")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("budget.matcher_ms"), "{err}");
        let err = PipelineConfig::from_toml_str(
            "[matcher.fallback]\nrecover_stereo_matches = 5\n",
            "x.toml",
        )
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
        assert!(err.contains("hysteresis"), "{err}");
        let err = PipelineConfig::from_toml_str("detector = \"sift\"\n", "x.toml")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("sift"), "{err}");
    }

    #[test]
    fn odometry_follows_the_pipeline_detector() {
        let config = PipelineConfig::from_toml_str("detector = \"fld\"\n", "x")
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(config.odometry_config().detector, DetectorKind::Fld);
    }
}
