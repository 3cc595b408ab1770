//! What the supervisor knows of a run: every frame's outcome, the events, the matcher mode,
//! and whether the run is complete. Shared by the multi-process and the single-process
//! modes.

use crate::fallback::{FallbackController, Switch};
use linetrack_msgs::{FrameHeader, FrameStatus, MatcherMode, PoseRecord, StageKind};
use linetrack_pipeline_config::{MatcherPolicy, PipelineConfig};
use linetrack_run_record::{
    EventRecord, FrameRecord, Percentiles, Report, STAGES, write_events, write_frames,
};
use linetrack_stage_runtime::detector_from_code;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// The run's bookkeeping.
pub struct Monitor {
    config: PipelineConfig,
    started: Instant,
    records: BTreeMap<u64, FrameRecord>,
    sequence_ns: BTreeMap<u64, (u64, PoseRecord)>,
    duplicates: usize,
    events: Vec<EventRecord>,
    fallback: Option<FallbackController>,
    last_pose: Option<(u64, PoseRecord)>,
    first_frame: u64,
    source_last: Option<u64>,
    published: Option<u64>,
}

fn stage_ms(header: &FrameHeader, i: usize) -> f64 {
    let s = header.stamps[i];
    if s.start_ns == 0 || s.end_ns < s.start_ns {
        f64::NAN
    } else {
        (s.end_ns - s.start_ns) as f64 * 1e-6
    }
}

impl Monitor {
    /// A monitor for a run of `config` starting at frame `first_frame`.
    pub fn new(config: &PipelineConfig, first_frame: u64) -> Self {
        let fallback = (config.matcher.mode == MatcherPolicy::Auto).then(|| {
            FallbackController::new(config.matcher.fallback.clone(), config.budget.matcher_ms)
        });
        Self {
            config: config.clone(),
            started: Instant::now(),
            records: BTreeMap::new(),
            sequence_ns: BTreeMap::new(),
            duplicates: 0,
            events: Vec::new(),
            fallback,
            last_pose: None,
            first_frame,
            source_last: None,
            published: None,
        }
    }

    /// Records an event and logs it.
    pub fn event(&mut self, kind: &str, stage: &str, frame_id: Option<u64>, detail: String) {
        let at = frame_id
            .map(|f| format!(" at frame {f}"))
            .unwrap_or_default();
        tracing::info!("{kind} [{stage}]{at}: {detail}");
        self.events.push(EventRecord {
            time_s: self.started.elapsed().as_secs_f64(),
            kind: kind.to_string(),
            stage: stage.to_string(),
            frame_id,
            detail,
        });
    }

    /// Takes one pose message; returns a matcher mode switch when one is due.
    pub fn on_pose(&mut self, header: &FrameHeader, pose: &PoseRecord) -> Option<Switch> {
        let status = header.frame_status();
        let outcome = match status {
            FrameStatus::Ok if pose.lost == 1 => "lost",
            FrameStatus::Ok => "pose",
            other => other.name(),
        };
        let mut stage = [f64::NAN; 4];
        for (i, slot) in stage.iter_mut().enumerate() {
            *slot = stage_ms(header, i);
        }
        let pose_end = header.stamps[3].end_ns;
        let end_to_end_ms = if pose_end >= header.capture_ns && header.capture_ns > 0 {
            header.age_ms(pose_end)
        } else {
            f64::NAN
        };
        let budget = &self.config.budget;
        let over_stage = STAGES
            .iter()
            .zip(stage)
            .any(|(name, ms)| budget.stage_ms(name).is_some_and(|b| ms > b));
        let record = FrameRecord {
            frame_id: header.frame_id,
            outcome: outcome.to_string(),
            dropped_by: if status == FrameStatus::Ok {
                String::new()
            } else {
                StageKind::from_code(header.dropped_by)
                    .map(|s| s.name().to_string())
                    .unwrap_or_default()
            },
            stage_ms: stage,
            end_to_end_ms,
            matcher: if status == FrameStatus::Ok {
                MatcherMode::from_code(header.matcher_mode)
                    .map(|m| m.name().to_string())
                    .unwrap_or_default()
            } else {
                String::new()
            },
            detector: if header.stamps[1].end_ns > 0 {
                detector_from_code(header.detector)
                    .map(|d| d.name().to_string())
                    .unwrap_or_default()
            } else {
                String::new()
            },
            stereo_matches: header.stereo_matches,
            tracked_matches: header.tracked_matches,
            deadline_miss: over_stage
                || end_to_end_ms > budget.end_to_end_ms
                || status == FrameStatus::DroppedLate,
        };
        if self.records.contains_key(&header.frame_id) {
            self.duplicates += 1;
            tracing::warn!("frame {} reached the end twice", header.frame_id);
            return None;
        }
        self.records.insert(header.frame_id, record);
        if status != FrameStatus::Ok {
            return None;
        }
        self.last_pose = Some((header.frame_id, *pose));
        self.sequence_ns
            .insert(header.frame_id, (header.sequence_ns, *pose));
        let switch = self.fallback.as_mut().and_then(|f| f.observe(header, pose));
        if let Some(s) = &switch {
            let kind = if s.to == MatcherMode::L1 {
                "fallback"
            } else {
                "recover"
            };
            self.event(
                kind,
                "matcher",
                Some(header.frame_id),
                format!(
                    "{} -> {}: {}",
                    if s.to == MatcherMode::L1 { "lbd" } else { "l1" },
                    s.to.name(),
                    s.reason
                ),
            );
        }
        switch
    }

    /// The mode the matcher should be in (re-sent to a restarted matcher).
    pub fn matcher_mode(&self) -> Option<MatcherMode> {
        self.fallback.as_ref().map(|f| f.mode())
    }

    /// The source published everything up to `last_frame`.
    pub fn source_finished(&mut self, last_frame: u64) {
        self.source_last = Some(last_frame);
    }

    /// Whether the source has finished.
    pub fn source_done(&self) -> bool {
        self.source_last.is_some()
    }

    /// The source published frame `frame_id`.
    pub fn published(&mut self, frame_id: u64) {
        self.published = Some(self.published.map_or(frame_id, |p| p.max(frame_id)));
    }

    /// The frame a restarted source starts from.
    pub fn next_source_frame(&self) -> u64 {
        self.published
            .map_or(self.first_frame, |p| p + 1)
            .max(self.records.keys().next_back().map_or(0, |k| k + 1))
    }

    /// The last tracked pose, as `--resume-pose` text.
    pub fn resume_pose(&self) -> Option<String> {
        self.last_pose.map(|(frame, p)| {
            let [tx, ty, tz] = p.translation;
            let [qx, qy, qz, qw] = p.rotation_xyzw;
            format!("{frame},{tx},{ty},{tz},{qx},{qy},{qz},{qw}")
        })
    }

    /// Whether every frame the source published has an outcome.
    pub fn complete(&self) -> bool {
        self.source_last
            .is_some_and(|last| (self.first_frame..=last).all(|f| self.records.contains_key(&f)))
    }

    /// Frames with an outcome.
    pub fn accounted(&self) -> usize {
        self.records.len()
    }

    /// The one-line live status.
    pub fn status_line(&self) -> String {
        let elapsed = self.started.elapsed().as_secs_f64();
        let recent: Vec<&FrameRecord> = self.records.values().rev().take(100).collect();
        let e2e = Percentiles::of(
            recent
                .iter()
                .filter(|f| f.has_pose())
                .map(|f| f.end_to_end_ms),
        );
        let rate = self.records.len() as f64 / elapsed.max(1e-3);
        let drops = self.records.values().filter(|f| !f.has_pose()).count();
        let misses = self.records.values().filter(|f| f.deadline_miss).count();
        let mode = self.fallback.as_ref().map_or_else(
            || self.config.matcher.mode_name().to_string(),
            |f| format!("auto:{}", f.mode().name()),
        );
        let mut line = format!(
            "[{elapsed:6.1} s] frames {:>5}  {rate:5.1} fps  ",
            self.records.len()
        );
        match e2e {
            Some(p) => {
                let _ = write!(
                    line,
                    "e2e p50 {:.1} p90 {:.1} p99 {:.1} ms  ",
                    p.p50, p.p90, p.p99
                );
            }
            None => line.push_str("e2e -  "),
        }
        let restarts = self.events.iter().filter(|e| e.kind == "restart").count();
        let _ = write!(
            line,
            "matcher {mode}  drops {drops}  misses {misses}  restarts {restarts}"
        );
        line
    }

    /// Fills in frames that never arrived, writes the records to `run_dir` and returns the
    /// report.
    pub fn finish(mut self, run_dir: &Path, interrupted: bool) -> anyhow::Result<Report> {
        let last = self
            .source_last
            .or(self.published)
            .or(self.records.keys().next_back().copied());
        if let Some(last) = last {
            for f in self.first_frame..=last {
                self.records
                    .entry(f)
                    .or_insert_with(|| FrameRecord::missing(f));
            }
        }
        if self.duplicates > 0 {
            let n = self.duplicates;
            self.event(
                "duplicate",
                "supervisor",
                None,
                format!("{n} frames reached the end twice (first outcome kept)"),
            );
        }
        if interrupted {
            self.event(
                "interrupted",
                "supervisor",
                None,
                "stopped before the sequence ended".to_string(),
            );
        }
        let frames: Vec<FrameRecord> = self.records.into_values().collect();
        write_frames(&run_dir.join("frames.csv"), &frames)?;
        write_events(&run_dir.join("events.csv"), &self.events)?;
        let mut tum = String::from(
            "# timestamp tx ty tz qx qy qz qw (left camera in the first frame's world)\n",
        );
        for (sequence_ns, p) in self.sequence_ns.values() {
            let [tx, ty, tz] = p.translation;
            let [qx, qy, qz, qw] = p.rotation_xyzw;
            let _ = writeln!(
                tum,
                "{:.9} {tx:.6} {ty:.6} {tz:.6} {qx:.6} {qy:.6} {qz:.6} {qw:.6}",
                *sequence_ns as f64 * 1e-9
            );
        }
        std::fs::write(run_dir.join("poses.tum"), tum)?;
        let report = Report::new(&frames, &self.events);
        std::fs::write(
            run_dir.join("summary.json"),
            serde_json::to_string_pretty(&report)?,
        )?;
        Ok(report)
    }
}
