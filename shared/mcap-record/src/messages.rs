//! The JSON messages of a recording's own channels: a frame's latencies and a stage event,
//! with their JSON schemas.

use linetrack_msgs::{FrameHeader, StageKind};
use serde::Serialize;
use std::collections::BTreeMap;

/// One frame's latencies, as the [`LATENCY`] channel holds them (milliseconds; a stage
/// that did not handle the frame has none).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct FrameLatency {
    /// The frame.
    pub frame_id: u64,
    /// `ok`, or the reason it was dropped (`dropped-late`, …).
    pub outcome: String,
    /// Frame source, line detector, matcher, pose estimator: publish − take, ms.
    pub stages_ms: BTreeMap<String, f64>,
    /// Capture to the pose estimator's publish, ms.
    pub end_to_end_ms: f64,
}

impl FrameLatency {
    /// The latencies `header` (a pose message's) records.
    pub fn of(header: &FrameHeader) -> Self {
        let mut stages_ms = BTreeMap::new();
        for stage in StageKind::PROCESSING {
            if let Some(slot) = stage.stamp_slot() {
                let s = header.stamps[slot];
                if s.end_ns >= s.start_ns && s.start_ns > 0 {
                    stages_ms.insert(
                        stage.name().to_string(),
                        (s.end_ns - s.start_ns) as f64 * 1e-6,
                    );
                }
            }
        }
        let last = header.stamps.iter().map(|s| s.end_ns).max().unwrap_or(0);
        Self {
            frame_id: header.frame_id,
            outcome: header
                .status
                .get()
                .map_or_else(|unknown| unknown.to_string(), |s| s.name().to_string()),
            stages_ms,
            end_to_end_ms: header.age_ms(last),
        }
    }
}

pub(crate) const LATENCY_JSON_SCHEMA: &str = r#"{"type":"object","properties":{"frame_id":{"type":"integer"},"outcome":{"type":"string"},"stages_ms":{"type":"object","additionalProperties":{"type":"number"}},"end_to_end_ms":{"type":"number"}},"required":["frame_id","outcome","stages_ms","end_to_end_ms"]}"#;
pub(crate) const EVENT_JSON_SCHEMA: &str = r#"{"type":"object","properties":{"stage":{"type":"string"},"pid":{"type":"integer"},"kind":{"type":"integer"},"detail":{"type":"integer"},"frame_id":{"type":"integer"},"value":{"type":"integer"}},"required":["stage","pid","kind","frame_id","value"]}"#;

/// A stage event as the [`EVENTS`] channel holds it.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct StageEvent {
    pub(crate) stage: String,
    pub(crate) pid: u32,
    pub(crate) kind: u32,
    pub(crate) detail: u32,
    pub(crate) frame_id: u64,
    pub(crate) value: u64,
}
