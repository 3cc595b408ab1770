//! `[budget]`: each stage's latency budget and the end-to-end one, and the drop policy.

use crate::limits::{BUDGET_MS, in_range};
use linetrack_msgs::StageKind;
use serde::{Deserialize, Serialize};

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
            end_to_end_ms: 100.0,
            frame_source_ms: 30.0,
            line_detector_ms: 50.0,
            matcher_ms: 50.0,
            pose_estimator_ms: 50.0,
            drop_late: true,
        }
    }
}

impl BudgetConfig {
    /// The budget of `stage` (`None` for a stage without one: supervisor, recorder, ...).
    pub fn stage_ms(&self, stage: StageKind) -> Option<f64> {
        match stage {
            StageKind::FrameSource => Some(self.frame_source_ms),
            StageKind::LineDetector => Some(self.line_detector_ms),
            StageKind::Matcher => Some(self.matcher_ms),
            StageKind::PoseEstimator => Some(self.pose_estimator_ms),
            StageKind::Supervisor
            | StageKind::Recorder
            | StageKind::Ros2Bridge
            | StageKind::Link => None,
        }
    }
}

impl BudgetConfig {
    /// The first out-of-range budget.
    pub fn validate(&self) -> Result<(), String> {
        for (key, ms) in [
            ("budget.end_to_end_ms", self.end_to_end_ms),
            ("budget.frame_source_ms", self.frame_source_ms),
            ("budget.line_detector_ms", self.line_detector_ms),
            ("budget.matcher_ms", self.matcher_ms),
            ("budget.pose_estimator_ms", self.pose_estimator_ms),
        ] {
            in_range(key, ms, BUDGET_MS)?;
        }
        Ok(())
    }
}
