//! `[stages.<name>]`: each stage's CPUs and scheduling policy, for every node the pipeline's
//! declaration ([`linetrack_msgs::PIPELINE`]) marks `scheduled`.

use linetrack_msgs::{PIPELINE, StageKind};
use linetrack_sched::SchedSettings;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Each stage's CPUs and scheduling policy (`[stages.line-detector]` ...); a stage left out
/// keeps what it inherits from the supervisor. A name that is no node declared `scheduled`
/// is refused, naming it and the names allowed.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(
    try_from = "BTreeMap<String, SchedSettings>",
    into = "BTreeMap<String, SchedSettings>"
)]
pub struct StagesConfig {
    /// The settings given, by stage (none empty).
    by_stage: BTreeMap<String, SchedSettings>,
}

/// The stages `[stages.<name>]` may name, in the declaration's order.
fn scheduled() -> impl Iterator<Item = StageKind> {
    PIPELINE.iter().filter(|n| n.scheduled).map(|n| n.stage)
}

impl TryFrom<BTreeMap<String, SchedSettings>> for StagesConfig {
    type Error = String;

    fn try_from(by_stage: BTreeMap<String, SchedSettings>) -> Result<Self, String> {
        for name in by_stage.keys() {
            if !scheduled().any(|s| s.name() == name) {
                let allowed: Vec<&str> = scheduled().map(StageKind::name).collect();
                return Err(format!(
                    "unknown stage `{name}` in [stages]: expected one of {}",
                    allowed.join(", ")
                ));
            }
        }
        Ok(Self {
            by_stage: by_stage
                .into_iter()
                .filter(|(_, s)| !s.is_empty())
                .collect(),
        })
    }
}

impl From<StagesConfig> for BTreeMap<String, SchedSettings> {
    fn from(config: StagesConfig) -> Self {
        config.by_stage
    }
}

impl StagesConfig {
    /// The settings of `stage` (`None` for a node no `[stages.<name>]` may set: supervisor,
    /// recorder, ...; empty settings for one left out).
    pub fn of(&self, stage: StageKind) -> Option<&SchedSettings> {
        static NONE: SchedSettings = SchedSettings {
            cpus: None,
            policy: None,
            priority: None,
            nice: None,
        };
        scheduled()
            .any(|s| s == stage)
            .then(|| self.by_stage.get(stage.name()).unwrap_or(&NONE))
    }

    /// Sets the settings of `stage` (a node declared `scheduled`; others are ignored).
    pub fn set(&mut self, stage: StageKind, settings: SchedSettings) {
        if scheduled().any(|s| s == stage) {
            self.by_stage.insert(stage.name().to_string(), settings);
        }
    }

    /// The scheduled stages, in the declaration's order, with their settings.
    pub fn all(&self) -> Vec<(StageKind, &SchedSettings)> {
        scheduled()
            .filter_map(|s| self.of(s).map(|settings| (s, settings)))
            .collect()
    }

    /// The first bad setting of any stage, named `stages.<name>.<key>`.
    pub fn validate(&self) -> Result<(), String> {
        for (stage, settings) in self.all() {
            settings.validate(&format!("stages.{}", stage.name()))?;
        }
        Ok(())
    }
}
