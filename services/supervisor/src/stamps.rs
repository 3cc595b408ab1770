//! What a frame's stamps say: how long a stage took on it, and whether the detector
//! detected it. Read by the records ([`crate::monitor`]) and both policies
//! ([`crate::fallback`], [`crate::detector_policy`]).

use linetrack_msgs::{FrameHeader, StageKind};

/// Milliseconds `stage` took on the frame; NaN when its stamp is missing (or it stamps no
/// frame).
pub fn stage_ms(header: &FrameHeader, stage: StageKind) -> f64 {
    match header.stamp(stage) {
        Some(s) if s.start_ns != 0 && s.end_ns >= s.start_ns => {
            (s.end_ns - s.start_ns) as f64 * 1e-6
        }
        _ => f64::NAN,
    }
}

/// When `stage` finished its work on the frame (0 when it did not stamp it).
pub fn end_ns(header: &FrameHeader, stage: StageKind) -> u64 {
    header.stamp(stage).map_or(0, |s| s.end_ns)
}

/// Whether `detector` (the line detector) detected the frame: not a frame dropped before it
/// or by it (its stamps then time the drop, not a detection).
pub fn detected(header: &FrameHeader, detector: StageKind) -> bool {
    let after = |by: StageKind| match (by.stamp_slot(), detector.stamp_slot()) {
        (Some(by), Some(detector)) => by.index() > detector.index(),
        _ => false,
    };
    header.is_ok() || header.status_by.get().ok().is_some_and(after)
}
