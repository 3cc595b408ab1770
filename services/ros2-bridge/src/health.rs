//! `diagnostic_msgs/DiagnosticArray` on `/diagnostics`: the pipeline's health as the bridge
//! sees it on the poses topic, once a second.
//!
//! Every frame reaches the poses topic, dropped or not (a dropped frame's header says why
//! and by which stage), with each stage's take/publish stamps, the matcher's mode and the
//! tracker's figures. [`Health`] gathers them between two reports and makes one status per
//! stage (latency p50/p99 over the frames of the last period, the budget, the misses of
//! the period and of the run), one for the pipeline (end-to-end latency, frames, drops by
//! reason), one for the matcher's mode (`linetrack: matcher mode`: mode, mode switches: the supervisor's fallbacks and
//! returns) and one for the tracking (inliers, observations, residual, conditioning, lost
//! frames). Levels: ERROR while tracking is lost, WARN when the period had budget misses,
//! drops or lost frames, OK otherwise. Time is a parameter: the caller says when it is.

use crate::ros_msgs::{DiagnosticArray, DiagnosticStatus, Header, KeyValue, Time};
use linetrack_msgs::{FrameStatus, MatcherMode, PoseRecord, StageKind, TracksHeader};
use linetrack_pipeline_config::BudgetConfig;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// How often a report goes out.
pub const PERIOD: Duration = Duration::from_secs(1);

/// `diagnostic_msgs/DiagnosticStatus` levels.
pub mod level {
    /// OK.
    pub const OK: u8 = 0;
    /// WARN.
    pub const WARN: u8 = 1;
    /// ERROR.
    pub const ERROR: u8 = 2;
}

/// Latencies of one stage (or end to end) over a period, and the misses of its budget.
#[derive(Debug, Clone, Default)]
struct Latency {
    /// Milliseconds, the period's frames.
    period_ms: Vec<f64>,
    /// Over budget, this period.
    period_misses: u64,
    /// Over budget, since the start.
    misses: u64,
}

impl Latency {
    fn add(&mut self, ms: f64, budget_ms: f64) {
        self.period_ms.push(ms);
        if ms > budget_ms {
            self.period_misses += 1;
            self.misses += 1;
        }
    }

    /// (p50, p99) of the period, `None` without frames.
    fn quantiles(&mut self) -> Option<(f64, f64)> {
        if self.period_ms.is_empty() {
            return None;
        }
        self.period_ms.sort_by(f64::total_cmp);
        let at = |q: f64| {
            let i = ((self.period_ms.len() - 1) as f64 * q).round() as usize;
            self.period_ms[i]
        };
        Some((at(0.5), at(0.99)))
    }

    fn values(&mut self, budget_ms: f64) -> Vec<KeyValue> {
        let (p50, p99) = self
            .quantiles()
            .map_or(("n/a".to_string(), "n/a".to_string()), |(a, b)| {
                (format!("{a:.2}"), format!("{b:.2}"))
            });
        vec![
            key("latency_p50_ms", p50),
            key("latency_p99_ms", p99),
            key("budget_ms", format!("{budget_ms:.1}")),
            key("budget_misses_last_period", self.period_misses),
            key("budget_misses", self.misses),
            key("frames_last_period", self.period_ms.len()),
        ]
    }

    fn next_period(&mut self) {
        self.period_ms.clear();
        self.period_misses = 0;
    }
}

fn key(name: &str, value: impl ToString) -> KeyValue {
    KeyValue {
        key: name.to_string(),
        value: value.to_string(),
    }
}

/// What the bridge saw of the run, for `/diagnostics`.
#[derive(Debug, Clone)]
pub struct Health {
    budget: BudgetConfig,
    stages: [Latency; 4],
    end_to_end: Latency,
    frames: u64,
    /// Drops by reason and stage: since the start, and this period.
    drops: BTreeMap<String, u64>,
    period_drops: u64,
    mode: Option<MatcherMode>,
    mode_switches: u64,
    last: Option<PoseRecord>,
    lost: u64,
    lost_streak: u64,
    period_lost: u64,
    next_report: Option<Instant>,
}

impl Health {
    /// Nothing seen yet; budgets from the run's config.
    pub fn new(budget: &BudgetConfig) -> Self {
        Self {
            budget: budget.clone(),
            stages: Default::default(),
            end_to_end: Latency::default(),
            frames: 0,
            drops: BTreeMap::new(),
            period_drops: 0,
            mode: None,
            mode_switches: 0,
            last: None,
            lost: 0,
            lost_streak: 0,
            period_lost: 0,
            next_report: None,
        }
    }

    /// Takes one message of the poses topic.
    pub fn observe(&mut self, message: &TracksHeader, record: &PoseRecord) {
        let header = &message.frame;
        self.frames += 1;
        for (latency, stage) in self.stages.iter_mut().zip(StageKind::PROCESSING) {
            let Some(stamp) = header.stamp(stage) else {
                continue;
            };
            if stamp.end_ns >= stamp.start_ns && stamp.start_ns > 0 {
                let budget = self.budget.stage_ms(stage).unwrap_or(f64::INFINITY);
                latency.add((stamp.end_ns - stamp.start_ns) as f64 * 1e-6, budget);
            }
        }
        if !header.is_ok() {
            let reason = header.status.get().map_or("unknown", FrameStatus::name);
            let stage = header.status_by.get().map_or("unknown", StageKind::name);
            *self
                .drops
                .entry(format!("{reason} by {stage}"))
                .or_default() += 1;
            self.period_drops += 1;
            return;
        }
        if let Some(pose) = header.stamp(StageKind::PoseEstimator)
            && pose.end_ns > 0
        {
            self.end_to_end
                .add(header.age_ms(pose.end_ns), self.budget.end_to_end_ms);
        }
        if let Ok(mode) = message.matching.mode.get() {
            if self.mode.is_some_and(|m| m != mode) {
                self.mode_switches += 1;
            }
            self.mode = Some(mode);
        }
        if record.lost != 0 {
            self.lost += 1;
            self.lost_streak += 1;
            self.period_lost += 1;
        } else {
            self.lost_streak = 0;
        }
        self.last = Some(*record);
    }

    /// The report due at `now`, if one is (the first a period after the first call), stamped
    /// `stamp`; the next period starts.
    pub fn report_if_due(&mut self, now: Instant, stamp: Time) -> Option<DiagnosticArray> {
        let due = *self.next_report.get_or_insert(now + PERIOD);
        if now < due {
            return None;
        }
        self.next_report = Some(now + PERIOD);
        Some(self.report(stamp))
    }

    /// The report of the period so far, stamped `stamp`; the next period starts.
    pub fn report(&mut self, stamp: Time) -> DiagnosticArray {
        let mut status = Vec::new();
        for (latency, stage) in self.stages.iter_mut().zip(StageKind::PROCESSING) {
            let budget = self.budget.stage_ms(stage).unwrap_or(f64::INFINITY);
            status.push(DiagnosticStatus {
                level: if latency.period_misses > 0 {
                    level::WARN
                } else {
                    level::OK
                },
                name: format!("linetrack: {}", stage.name()),
                message: format!("{} over budget this period", latency.period_misses),
                hardware_id: String::new(),
                values: latency.values(budget),
            });
        }
        let mut values = self.end_to_end.values(self.budget.end_to_end_ms);
        values.push(key("frames", self.frames));
        values.push(key("dropped_last_period", self.period_drops));
        values.push(key("dropped", self.drops.values().sum::<u64>()));
        for (reason, n) in &self.drops {
            values.push(key(&format!("dropped: {reason}"), n));
        }
        let troubled = self.end_to_end.period_misses > 0 || self.period_drops > 0;
        status.push(DiagnosticStatus {
            level: if troubled { level::WARN } else { level::OK },
            name: "linetrack: pipeline".to_string(),
            message: format!(
                "{} frames, {} dropped, {} over the end-to-end budget this period",
                self.end_to_end.period_ms.len(),
                self.period_drops,
                self.end_to_end.period_misses
            ),
            hardware_id: String::new(),
            values,
        });
        let mode = self.mode.map_or("unknown", MatcherMode::name);
        status.push(DiagnosticStatus {
            level: level::OK,
            name: "linetrack: matcher mode".to_string(),
            message: format!("matching with {mode}"),
            hardware_id: String::new(),
            values: vec![key("mode", mode), key("mode_switches", self.mode_switches)],
        });
        status.push(self.tracking());
        for latency in self.stages.iter_mut().chain([&mut self.end_to_end]) {
            latency.next_period();
        }
        self.period_drops = 0;
        self.period_lost = 0;
        DiagnosticArray {
            header: Header {
                stamp,
                frame_id: String::new(),
            },
            status,
        }
    }

    fn tracking(&self) -> DiagnosticStatus {
        let last = self.last.unwrap_or_default();
        let (level, message) = if self.last.is_none() {
            (level::WARN, "no pose yet".to_string())
        } else if self.lost_streak > 0 {
            (
                level::ERROR,
                format!("lost for {} frames", self.lost_streak),
            )
        } else if self.period_lost > 0 {
            (
                level::WARN,
                format!("tracking; {} frames lost this period", self.period_lost),
            )
        } else {
            (level::OK, "tracking".to_string())
        };
        DiagnosticStatus {
            level,
            name: "linetrack: tracking".to_string(),
            message,
            hardware_id: String::new(),
            values: vec![
                key(
                    "state",
                    if self.lost_streak > 0 {
                        "lost"
                    } else {
                        "tracking"
                    },
                ),
                key("inlier_points", last.inliers[0]),
                key("inlier_lines", last.inliers[1]),
                key("observed_points", last.observations[0]),
                key("observed_lines", last.observations[1]),
                key("rms_px", format!("{:.3}", last.rms_px)),
                key("conditioning", format!("{:.3e}", last.conditioning)),
                key("lost_frames", self.lost),
                key("lost_streak", self.lost_streak),
                key("lost_last_period", self.period_lost),
            ],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::FrameHeader;

    /// A frame captured at `capture_ms` whose stages each took `stage_ms`, one after another.
    fn frame(id: u64, capture_ms: u64, stage_ms: u64) -> TracksHeader {
        let mut header = FrameHeader::new(id, 0, capture_ms * 1_000_000);
        let mut t = capture_ms * 1_000_000;
        for stage in StageKind::PROCESSING {
            if let Some(s) = header.stamp_mut(stage) {
                s.start_ns = t;
                t += stage_ms * 1_000_000;
                s.end_ns = t;
            }
        }
        TracksHeader::from(header)
    }

    fn value<'a>(status: &'a DiagnosticStatus, key: &str) -> &'a str {
        status
            .values
            .iter()
            .find(|v| v.key == key)
            .map_or_else(|| panic!("no {key} in {status:?}"), |v| v.value.as_str())
    }

    fn named<'a>(report: &'a DiagnosticArray, name: &str) -> &'a DiagnosticStatus {
        report
            .status
            .iter()
            .find(|s| s.name == name)
            .unwrap_or_else(|| panic!("no {name}"))
    }

    #[test]
    fn a_report_a_second_with_latencies_drops_mode_and_tracking() {
        let budget = BudgetConfig::default(); // 30/50/50/50 ms, 100 ms end to end
        let mut health = Health::new(&budget);
        let start = Instant::now();
        assert!(health.report_if_due(start, Time::default()).is_none());
        // 9 frames at 10 ms a stage, one at 60 ms (over every stage budget, 240 ms end to end).
        let tracked = PoseRecord {
            inliers: [40, 12],
            conditioning: 0.02,
            ..PoseRecord::default()
        };
        for id in 0..9 {
            health.observe(&frame(id, id * 50, 10), &tracked);
        }
        health.observe(&frame(9, 450, 60), &tracked);
        let mut dropped = frame(10, 500, 10);
        dropped
            .frame
            .mark(FrameStatus::DroppedLate, StageKind::Matcher);
        health.observe(&dropped, &tracked);
        let mut l1 = frame(11, 550, 10);
        l1.matching.mode = MatcherMode::L1.into();
        health.observe(&l1, &PoseRecord { lost: 1, ..tracked });
        assert!(
            health
                .report_if_due(start + Duration::from_millis(999), Time::default())
                .is_none()
        );
        let report = health
            .report_if_due(start + PERIOD, Time::from_ns(7))
            .unwrap_or_else(|| panic!("no report after a period"));
        assert_eq!(report.header.stamp, Time::from_ns(7));
        let detector = named(&report, "linetrack: line-detector");
        assert_eq!(value(detector, "latency_p50_ms"), "10.00");
        assert_eq!(value(detector, "latency_p99_ms"), "60.00");
        assert_eq!(value(detector, "budget_misses"), "1");
        assert_eq!(detector.level, level::WARN);
        let pipeline = named(&report, "linetrack: pipeline");
        assert_eq!(value(pipeline, "dropped: dropped-late by matcher"), "1");
        assert_eq!(value(pipeline, "frames"), "12");
        assert_eq!(value(pipeline, "budget_misses"), "1");
        let matcher = named(&report, "linetrack: matcher mode");
        assert_eq!(
            (value(matcher, "mode"), value(matcher, "mode_switches")),
            ("l1", "1")
        );
        let tracking = named(&report, "linetrack: tracking");
        assert_eq!(tracking.level, level::ERROR);
        assert_eq!(value(tracking, "state"), "lost");
        assert_eq!(value(tracking, "lost_frames"), "1");
        assert_eq!(value(tracking, "inlier_points"), "40");
        assert_eq!(value(tracking, "conditioning"), "2.000e-2");
        // The next period starts empty but the run's counts stay.
        health.observe(&frame(12, 600, 10), &tracked);
        let report = health
            .report_if_due(start + 2 * PERIOD, Time::default())
            .unwrap_or_else(|| panic!("no second report"));
        let detector = named(&report, "linetrack: line-detector");
        assert_eq!(value(detector, "budget_misses_last_period"), "0");
        assert_eq!(value(detector, "budget_misses"), "1");
        assert_eq!(value(detector, "frames_last_period"), "1");
        assert_eq!(detector.level, level::OK);
        assert_eq!(named(&report, "linetrack: tracking").level, level::OK);
    }
}
