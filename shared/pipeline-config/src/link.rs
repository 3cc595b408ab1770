//! `[link]`: the ground-station link's endpoint, topics and image thinning.

use crate::limits::{MAX_STREAK_FRAMES, in_range};
use serde::{Deserialize, Serialize};

/// The ground-station link (`linetrack-link`, built with the `link` feature): an optional
/// process the supervisor starts that forwards the allowed topics to zenoh. It never slows
/// the pipeline: when the link is down or slow, messages are dropped and counted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LinkConfig {
    /// Start the link process with the run.
    pub enabled: bool,
    /// The zenoh endpoint the onboard side listens on (`tcp/HOST:PORT`); `linetrack watch
    /// --connect` names the same.
    pub listen: String,
    /// The topics forwarded: any of `poses`, `status`, `segments`, `tracks`, `images`.
    pub topics: Vec<String>,
    /// The zenoh key prefix the topics are published under (`<key_prefix>/poses`, ...).
    pub key_prefix: String,
    /// `images`: the left image shrunk by this factor in each direction (box average).
    pub image_scale: u32,
    /// `images`: one image every this many frames.
    pub image_every: u32,
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            listen: "tcp/127.0.0.1:7447".to_string(),
            topics: ["poses", "status"].map(String::from).to_vec(),
            key_prefix: "linetrack".to_string(),
            image_scale: 4,
            image_every: 10,
        }
    }
}

impl LinkConfig {
    /// The topics `topics` may name.
    pub const TOPICS: [&'static str; 5] = ["poses", "status", "segments", "tracks", "images"];

    /// Whether `topic` is on the allow-list.
    pub fn allows(&self, topic: &str) -> bool {
        self.topics.iter().any(|t| t == topic)
    }

    /// The first bad key of `[link]`: an unknown topic, an endpoint or key prefix that
    /// zenoh would refuse, an image scale or period out of range.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(unknown) = self
            .topics
            .iter()
            .find(|t| !Self::TOPICS.contains(&t.as_str()))
        {
            return Err(format!(
                "link.topics: unknown topic {unknown:?}: allowed {:?}",
                Self::TOPICS
            ));
        }
        in_range("link.image_scale", self.image_scale, 1..=64)?;
        in_range("link.image_every", self.image_every, 1..=MAX_STREAK_FRAMES)?;
        if self.listen.is_empty() || !self.listen.contains('/') {
            return Err(format!(
                "link.listen = {:?}: expected a zenoh endpoint such as tcp/0.0.0.0:7447",
                self.listen
            ));
        }
        if self.key_prefix.is_empty()
            || self.key_prefix.starts_with('/')
            || self.key_prefix.ends_with('/')
            || self.key_prefix.contains(['*', '$', '?', '#'])
        {
            return Err(format!(
                "link.key_prefix = {:?}: expected words separated by '/', no wildcards",
                self.key_prefix
            ));
        }
        Ok(())
    }
}
