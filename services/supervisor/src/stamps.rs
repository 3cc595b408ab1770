//! What a frame's stamps say: how long a stage took on it, and whether the detector
//! detected it. Read by the records ([`crate::monitor`]) and both policies
//! ([`crate::fallback`], [`crate::detector_policy`]).

use linetrack_msgs::FrameHeader;

/// Milliseconds stage `i` (its stamp index) took on the frame; NaN when a stamp is missing.
pub fn stage_ms(header: &FrameHeader, i: usize) -> f64 {
    let s = header.stamps[i];
    if s.start_ns == 0 || s.end_ns < s.start_ns {
        f64::NAN
    } else {
        (s.end_ns - s.start_ns) as f64 * 1e-6
    }
}

/// Whether the detector (stamp index `detector`) detected the frame: not a frame dropped
/// before it or by it (its stamps then time the drop, not a detection).
pub fn detected(header: &FrameHeader, detector: usize) -> bool {
    header.is_ok()
        || header
            .status_by
            .get()
            .ok()
            .and_then(|s| s.stamp_index())
            .is_some_and(|by| by > detector)
}
