//! What a run folder's records hold and what they lack, for `linetrack report`: a folder
//! cut short (a full disk, a killed supervisor) is read up to its last whole row, and the
//! report says which row was cut, which frames have no row, and how the run ended — from
//! `summary.json`, or, without one, from `status.json` and whether its supervisor still
//! lives.

use linetrack_run_record::{
    CutRow, EventRecord, FrameRecord, RunEnd, Summary, read_events_to_cut, read_frames_to_cut,
    unrecorded,
};
use linetrack_supervisor::LiveStatus;
use std::fmt::Write as _;
use std::path::Path;

/// Ranges of unrecorded frames listed one by one; more are summed up.
const LISTED_RANGES: usize = 12;

/// A run folder's records as far as they go.
pub struct RunRecords {
    /// `frames.csv`'s whole rows, in frame order.
    pub frames: Vec<FrameRecord>,
    /// `events.csv`'s whole rows.
    pub events: Vec<EventRecord>,
    /// The cut last rows, if any.
    pub cut: Vec<CutRow>,
    /// `summary.json`, when the run wrote it.
    pub summary: Option<Summary>,
    /// `status.json`, when there is one.
    pub status: Option<LiveStatus>,
}

impl RunRecords {
    /// Reads `run_dir`; a missing or damaged `frames.csv` / `events.csv` (other than a cut
    /// last row) is an error naming the file and the line.
    pub fn read(run_dir: &Path) -> Result<Self, linetrack_run_record::RecordError> {
        let (frames, frames_cut) = read_frames_to_cut(&run_dir.join("frames.csv"))?;
        let (events, events_cut) = read_events_to_cut(&run_dir.join("events.csv"))?;
        let summary = Summary::read(&run_dir.join("summary.json")).ok();
        let status = std::fs::read_to_string(run_dir.join("status.json"))
            .ok()
            .and_then(|text| serde_json::from_str(&text).ok());
        Ok(Self {
            frames,
            events,
            cut: frames_cut.into_iter().chain(events_cut).collect(),
            summary,
            status,
        })
    }

    /// Frames the run had, as far as it is known: its summary's count, else one past the
    /// highest recorded frame.
    pub fn expected_frames(&self) -> u64 {
        let recorded = self.frames.last().map_or(0, |f| f.frame_id + 1);
        self.summary
            .as_ref()
            .map_or(recorded, |s| (s.report.frames as u64).max(recorded))
    }

    /// What is missing from the records and how the run ended, a line each; empty for a
    /// run that ended with whole records.
    pub fn gaps_text(&self) -> String {
        let mut out = String::new();
        for cut in &self.cut {
            let _ = writeln!(out, "records: {cut}");
        }
        let expected = self.expected_frames();
        let gaps = unrecorded(&self.frames, expected);
        if !gaps.is_empty() {
            let missing: u64 = gaps.iter().map(|g| g.end - g.start).sum();
            let listed: Vec<String> = gaps
                .iter()
                .take(LISTED_RANGES)
                .map(|g| match g.end - g.start {
                    1 => g.start.to_string(),
                    _ => format!("{}-{}", g.start, g.end - 1),
                })
                .collect();
            let more = gaps.len().saturating_sub(LISTED_RANGES);
            let _ = writeln!(
                out,
                "records: {missing} of {expected} frames have no row in frames.csv: {}{}",
                listed.join(", "),
                if more > 0 {
                    format!(" and {more} more ranges")
                } else {
                    String::new()
                }
            );
        }
        let incomplete = !out.is_empty();
        match (&self.summary, &self.status) {
            (Some(summary), _) if summary.end == RunEnd::Completed && out.is_empty() => {}
            (Some(summary), _) => {
                let _ = writeln!(
                    out,
                    "run ended {}{}",
                    end_name(summary.end),
                    summary
                        .reason
                        .as_ref()
                        .map(|r| format!(": {r}"))
                        .unwrap_or_default()
                );
                // The run's own count, when the records do not add up to it.
                if summary.end == RunEnd::RecordsFailed || incomplete {
                    let r = &summary.report;
                    let _ = writeln!(
                        out,
                        "the run's own count (summary.json): frames {}: {} tracked, {} predicted, {} dropped",
                        r.frames,
                        r.poses,
                        r.lost,
                        r.dropped()
                    );
                }
            }
            (None, Some(status)) if status.state == RunEnd::Running => {
                let alive = Path::new(&format!("/proc/{}", status.supervisor_pid)).exists();
                let _ = writeln!(
                    out,
                    "summary.json is missing and status.json still says running: {}",
                    if alive {
                        format!(
                            "the run may still be going (supervisor pid {} is alive)",
                            status.supervisor_pid
                        )
                    } else {
                        format!(
                            "its supervisor (pid {}) is gone: the run was killed, its records end at the last row above",
                            status.supervisor_pid
                        )
                    }
                );
            }
            (None, _) => {
                let _ = writeln!(
                    out,
                    "summary.json is missing: the run did not end cleanly (killed, or no room left to write it)"
                );
            }
        }
        out
    }
}

/// How `summary.json` spells `end`.
fn end_name(end: RunEnd) -> String {
    serde_json::to_value(end)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_else(|| format!("{end:?}"))
}
