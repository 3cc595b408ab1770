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
    /// a frame with a newer one queued behind it as [`BudgetConfig::behind`] says; otherwise
    /// process every frame.
    pub drop_late: bool,
    /// With `drop_late`, which frame with a newer one queued behind it a stage drops.
    pub behind: BehindRule,
}

/// What a stage does, with `drop_late`, with a frame that has a newer one queued behind it
/// (`[budget] behind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BehindRule {
    /// Drops it only when it cannot make the end-to-end budget: its age plus what the
    /// pipeline still needs for it (the stage's recent time a frame times the stages left,
    /// itself included) is over `end_to_end_ms`. Before the stage has timed a frame, as
    /// `Newest`.
    #[default]
    Deadline,
    /// Always drops it: the newest frame wins, however young the older one is.
    Newest,
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
            behind: BehindRule::Deadline,
        }
    }
}

impl BudgetConfig {
    /// The budget of `stage`: the one under the `[budget]` key the pipeline's declaration
    /// gives it (`None` for a node declared without one: supervisor, recorder, ...).
    pub fn stage_ms(&self, stage: StageKind) -> Option<f64> {
        stage.decl()?.budget.and_then(|key| self.by_key(key))
    }

    /// The budget under `[budget]` named `key` (`None` for a key it does not have).
    pub fn by_key(&self, key: &str) -> Option<f64> {
        match key {
            "end_to_end_ms" => Some(self.end_to_end_ms),
            "frame_source_ms" => Some(self.frame_source_ms),
            "line_detector_ms" => Some(self.line_detector_ms),
            "matcher_ms" => Some(self.matcher_ms),
            "pose_estimator_ms" => Some(self.pose_estimator_ms),
            _ => None,
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

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::PIPELINE;

    /// A stage's budget is the `[budget]` key its declaration names: each declared key is a
    /// field, and a stage reads its own (distinct values, so a swapped key shows).
    #[test]
    fn a_stage_reads_the_budget_its_declaration_names() {
        let budget = BudgetConfig {
            end_to_end_ms: 1.0,
            frame_source_ms: 2.0,
            line_detector_ms: 3.0,
            matcher_ms: 4.0,
            pose_estimator_ms: 5.0,
            drop_late: true,
            behind: BehindRule::Newest,
        };
        for node in PIPELINE {
            if let Some(key) = node.budget {
                assert!(
                    budget.by_key(key).is_some(),
                    "{}: [budget] {key}",
                    node.stage
                );
            }
        }
        assert_eq!(budget.stage_ms(StageKind::FrameSource), Some(2.0));
        assert_eq!(budget.stage_ms(StageKind::LineDetector), Some(3.0));
        assert_eq!(budget.stage_ms(StageKind::Matcher), Some(4.0));
        assert_eq!(budget.stage_ms(StageKind::PoseEstimator), Some(5.0));
        for stage in [
            StageKind::Supervisor,
            StageKind::Recorder,
            StageKind::Link,
            StageKind::Observer,
        ] {
            assert_eq!(budget.stage_ms(stage), None, "{stage}");
        }
        assert_eq!(budget.by_key("drop_late"), None);
        assert_eq!(budget.by_key("behind"), None);
    }

    #[test]
    fn the_behind_rule_is_read_by_name_and_a_wrong_one_is_refused() {
        let read = |text: &str| {
            crate::PipelineConfig::from_toml_str(text, "p.toml").map(|c| c.budget.behind)
        };
        assert_eq!(read("").ok(), Some(BehindRule::Deadline), "the default");
        assert_eq!(
            read("[budget]\nbehind = \"newest\"\n").ok(),
            Some(BehindRule::Newest)
        );
        assert_eq!(
            read("[budget]\nbehind = \"deadline\"\n").ok(),
            Some(BehindRule::Deadline)
        );
        let err = read("[budget]\nbehind = \"oldest\"\n")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains("p.toml: line 2") && err.contains("oldest") && err.contains("newest"),
            "{err}"
        );
    }
}
