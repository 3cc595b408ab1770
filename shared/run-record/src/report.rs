//! [`Report`]: what a run's records add up to, built one frame and event at a time ([`Tally`]).

use crate::latency::{LatencyHistogram, Percentiles};
use crate::rows::{EventRecord, FrameRecord};
use linetrack_msgs::StageKind;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// A run's report built up one frame and one event at a time, in memory that does not
/// grow with the run's length.
#[derive(Debug, Clone, Default)]
pub struct Tally {
    frames: usize,
    poses: usize,
    lost: usize,
    drops: BTreeMap<String, usize>,
    stage: [LatencyHistogram; 4],
    end_to_end: LatencyHistogram,
    deadline_misses: usize,
    l1_frames: usize,
    events: BTreeMap<String, usize>,
    /// The disparity offset of the latest frame (by number) with a pose: (frame, pixels).
    disparity_offset: Option<(u64, f64)>,
}

impl Tally {
    /// Counts a frame.
    pub fn add_frame(&mut self, f: &FrameRecord) {
        self.frames += 1;
        match f.outcome.as_str() {
            "pose" => self.poses += 1,
            "lost" => self.lost += 1,
            other => *self.drops.entry(other.to_string()).or_default() += 1,
        }
        // Latency over the frames every stage worked on: a dropped frame's near-zero
        // times would flatter the stages.
        if f.has_pose() {
            for (h, ms) in self.stage.iter_mut().zip(f.stage_ms) {
                h.record(ms);
            }
            self.end_to_end.record(f.end_to_end_ms);
            if f.disparity_offset_px.is_finite()
                && self.disparity_offset.is_none_or(|(k, _)| f.frame_id >= k)
            {
                self.disparity_offset = Some((f.frame_id, f.disparity_offset_px));
            }
        }
        self.deadline_misses += usize::from(f.deadline_miss);
        self.l1_frames += usize::from(f.matcher == "l1");
    }

    /// Counts an event.
    pub fn add_event(&mut self, e: &EventRecord) {
        *self.events.entry(e.kind.clone()).or_default() += 1;
    }

    /// Events of `kind` so far.
    pub fn events_of(&self, kind: &str) -> usize {
        self.events.get(kind).copied().unwrap_or(0)
    }

    /// Frames dropped as `outcome` (`capture-late`, `dropped-late`, ...) so far.
    pub fn dropped_as(&self, outcome: &str) -> usize {
        self.drops.get(outcome).copied().unwrap_or(0)
    }

    /// Frames counted so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Frames with a tracked pose.
    pub fn tracked(&self) -> usize {
        self.poses
    }

    /// Frames that got a pose (tracked or predicted).
    pub fn with_pose(&self) -> usize {
        self.poses + self.lost
    }

    /// Frames over some budget.
    pub fn deadline_misses(&self) -> usize {
        self.deadline_misses
    }

    /// The report so far.
    pub fn report(&self) -> Report {
        Report {
            frames: self.frames,
            poses: self.poses,
            lost: self.lost,
            drops: self.drops.iter().map(|(k, n)| (k.clone(), *n)).collect(),
            stage_latency: StageKind::PROCESSING
                .iter()
                .zip(&self.stage)
                .map(|(s, h)| (s.name().to_string(), h.percentiles()))
                .collect(),
            end_to_end: self.end_to_end.percentiles(),
            deadline_misses: self.deadline_misses,
            l1_frames: self.l1_frames,
            fallbacks: self.events_of("fallback"),
            recoveries: self.events_of("recover"),
            restarts: self.events_of("restart"),
            swaps: self.events_of("swap"),
            camera_losses: self.events_of("camera-lost"),
            l1_rescues: self.events_of("l1-rescue"),
            disparity_offset_px: self
                .disparity_offset
                .map(|(_, px)| px)
                .filter(|px| *px != 0.0),
        }
    }
}

/// What a run's records add up to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Frames accounted for.
    pub frames: usize,
    /// Frames with a tracked pose.
    pub poses: usize,
    /// Frames whose pose is a prediction (tracking lost).
    pub lost: usize,
    /// Dropped frames by outcome (corrupt, dropped-late, ...), sorted by name.
    pub drops: Vec<(String, usize)>,
    /// Per stage in [`StageKind::PROCESSING`] order, over the frames that got a pose.
    pub stage_latency: Vec<(String, Option<Percentiles>)>,
    /// End to end.
    pub end_to_end: Option<Percentiles>,
    /// Frames over some budget.
    pub deadline_misses: usize,
    /// Frames the matcher handled in ℓ1 mode.
    pub l1_frames: usize,
    /// Switches to ℓ1.
    pub fallbacks: usize,
    /// Switches back to LBD.
    pub recoveries: usize,
    /// Stage restarts.
    pub restarts: usize,
    /// Detector hot swaps.
    pub swaps: usize,
    /// Times the live camera failed and was reopened (`camera-lost` events).
    #[serde(default)]
    pub camera_losses: usize,
    /// Frames LBD's matches would have lost that the pose estimator tracked with ℓ1
    /// (`l1-rescue` events, `[matcher.fallback] rescue_lost_frames`).
    #[serde(default)]
    pub l1_rescues: usize,
    /// The disparity offset the pose estimator subtracted at the last frame with a pose,
    /// pixels, when it is not zero (`[odometry.disparity_offset]`: given, or
    /// self-calibrated).
    #[serde(default)]
    pub disparity_offset_px: Option<f64>,
}

impl Report {
    /// The report of `frames` and `events` (percentiles as [`LatencyHistogram`] gives them).
    pub fn new(frames: &[FrameRecord], events: &[EventRecord]) -> Self {
        let mut tally = Tally::default();
        frames.iter().for_each(|f| tally.add_frame(f));
        events.iter().for_each(|e| tally.add_event(e));
        tally.report()
    }

    /// Frames dropped, all reasons.
    pub fn dropped(&self) -> usize {
        self.drops.iter().map(|(_, n)| n).sum()
    }

    /// The report as a text table.
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "frames {}: {} tracked, {} predicted (tracking lost), {} dropped",
            self.frames,
            self.poses,
            self.lost,
            self.dropped()
        );
        for (why, n) in &self.drops {
            let _ = writeln!(out, "  dropped {why}: {n}");
        }
        let _ = writeln!(
            out,
            "{:<16} {:>6} {:>9} {:>9} {:>9} {:>9}",
            "latency (ms)", "n", "p50", "p90", "p99", "max"
        );
        let row = |out: &mut String, name: &str, p: &Option<Percentiles>| {
            let _ = match p {
                Some(p) => writeln!(
                    out,
                    "{name:<16} {:>6} {:>9.2} {:>9.2} {:>9.2} {:>9.2}",
                    p.count, p.p50, p.p90, p.p99, p.max
                ),
                None => writeln!(out, "{name:<16} {:>6}", 0),
            };
        };
        for (name, p) in &self.stage_latency {
            row(&mut out, name, p);
        }
        row(&mut out, "end-to-end", &self.end_to_end);
        let _ = writeln!(
            out,
            "deadline misses {}   l1 frames {}   fallbacks {}   recoveries {}   restarts {}   detector swaps {}",
            self.deadline_misses,
            self.l1_frames,
            self.fallbacks,
            self.recoveries,
            self.restarts,
            self.swaps
        );
        if self.l1_rescues > 0 {
            let _ = writeln!(
                out,
                "l1 rescues {} (frames LBD's matches would have lost, tracked with l1; events.csv)",
                self.l1_rescues
            );
        }
        if let Some(px) = self.disparity_offset_px {
            let _ = writeln!(
                out,
                "disparity offset {px:+.2} px at the end (subtracted before triangulating: \
                 [odometry.disparity_offset]; frames.csv has it per frame)"
            );
        }
        if self.camera_losses > 0 {
            let _ = writeln!(
                out,
                "camera lost {} times (reopened with backoff; events.csv names the device)",
                self.camera_losses
            );
        }
        out
    }
}
