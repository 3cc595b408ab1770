//! `[stages.<name>]`: each stage's CPUs and scheduling policy.

use linetrack_msgs::StageKind;
use linetrack_sched::SchedSettings;
use serde::{Deserialize, Serialize};

/// Each stage's CPUs and scheduling policy (`[stages.line-detector]` ...); a stage left out
/// keeps what it inherits from the supervisor. Unknown stage names are refused.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default, rename_all = "kebab-case")]
pub struct StagesConfig {
    /// `[stages.frame-source]`.
    #[serde(skip_serializing_if = "SchedSettings::is_empty")]
    pub frame_source: SchedSettings,
    /// `[stages.line-detector]` (a standby detector of a hot swap too).
    #[serde(skip_serializing_if = "SchedSettings::is_empty")]
    pub line_detector: SchedSettings,
    /// `[stages.matcher]`.
    #[serde(skip_serializing_if = "SchedSettings::is_empty")]
    pub matcher: SchedSettings,
    /// `[stages.pose-estimator]`.
    #[serde(skip_serializing_if = "SchedSettings::is_empty")]
    pub pose_estimator: SchedSettings,
}

impl StagesConfig {
    /// The processing stages, in pipeline order, with their settings.
    pub fn all(&self) -> [(StageKind, &SchedSettings); 4] {
        [
            (StageKind::FrameSource, &self.frame_source),
            (StageKind::LineDetector, &self.line_detector),
            (StageKind::Matcher, &self.matcher),
            (StageKind::PoseEstimator, &self.pose_estimator),
        ]
    }

    /// The settings of `stage` (`None` for a stage without any: supervisor, recorder, ...).
    pub fn of(&self, stage: StageKind) -> Option<&SchedSettings> {
        self.all()
            .into_iter()
            .find(|(kind, _)| *kind == stage)
            .map(|(_, settings)| settings)
    }
}

impl StagesConfig {
    /// The first bad setting of any stage, named `stages.<name>.<key>`.
    pub fn validate(&self) -> Result<(), String> {
        for (stage, settings) in self.all() {
            settings.validate(&format!("stages.{}", stage.name()))?;
        }
        Ok(())
    }
}
