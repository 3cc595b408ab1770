//! `trace-overview.png`: a few frames of a run's merged trace as a picture — one track per
//! stage process, each frame's spans in its colour and joined from process to process, as
//! `trace.json` shows them in Perfetto with its flow arrows. It shows at a glance how the
//! stages overlap on consecutive frames and where a frame waits.

use linetrack_plot::{Bar, Tracks};
use linetrack_telemetry::{SpanEvent, frame_paths, processes};
use std::path::Path;

/// File name of the picture in a run folder.
pub const TRACE_PNG: &str = "trace-overview.png";

/// Frames shown.
const FRAMES: usize = 6;

/// The picture of frames from the middle of the run whose paths reach every process that
/// handled frames, with every span overlapping their time; `None` without such frames.
pub fn overview(events: &[SpanEvent]) -> Option<Tracks> {
    let tracks = processes(events);
    let paths = frame_paths(events);
    let longest = paths.values().map(Vec::len).max()?;
    let complete: Vec<u64> = paths
        .iter()
        .filter(|(_, spans)| spans.len() == longest)
        .map(|(id, _)| *id)
        .collect();
    let first = complete.len().saturating_sub(FRAMES) / 2;
    let shown = &complete[first..(first + FRAMES).min(complete.len())];
    let spans_of = |id: &u64| paths.get(id).map(Vec::as_slice).unwrap_or_default();
    let t0 = shown.iter().flat_map(spans_of).map(|e| e.ts_us).min()?;
    let t1 = shown
        .iter()
        .flat_map(spans_of)
        .map(|e| e.ts_us + e.dur_us)
        .max()?;
    let ms = |us: u64| (us as f64 - t0 as f64) / 1000.0;
    let in_window: Vec<&SpanEvent> = events
        .iter()
        .filter(|e| e.frame_id.is_some() && e.ts_us < t1 && e.ts_us + e.dur_us > t0)
        .collect();
    // The processes with spans in the window, in pipeline order (a stage swapped out
    // before it, or started after it, takes no room).
    let tracks: Vec<(u32, String)> = tracks
        .into_iter()
        .filter(|(pid, _)| in_window.iter().any(|e| e.pid == *pid))
        .collect();
    let track_of = |pid: u32| tracks.iter().position(|(p, _)| *p == pid).unwrap_or(0);
    let bars = in_window
        .iter()
        .filter_map(|e| {
            Some(Bar {
                track: track_of(e.pid),
                start: ms(e.ts_us.max(t0)),
                end: ms((e.ts_us + e.dur_us).min(t1)),
                group: e.frame_id?,
                nested: e.frame_depth > 0,
            })
        })
        .collect();
    let links = shown
        .iter()
        .map(|id| {
            let path = spans_of(id)
                .iter()
                .map(|e| (track_of(e.pid), ms(e.ts_us), ms(e.ts_us + e.dur_us)))
                .collect();
            (*id, path)
        })
        .collect();
    Some(Tracks {
        title: format!(
            "Frames {}–{} through the processes (trace.json; a frame's spans share a colour and are joined)",
            shown.first()?,
            shown.last()?
        ),
        x_label: "milliseconds".to_string(),
        tracks: tracks
            .iter()
            .map(|(pid, name)| format!("{name} ({pid})"))
            .collect(),
        bars,
        links,
    })
}

/// Writes the picture into `run_dir` when the run has spans of frames that crossed
/// processes; returns its path.
pub fn write(run_dir: &Path) -> anyhow::Result<Option<std::path::PathBuf>> {
    let (events, _) = linetrack_telemetry::read_spans(run_dir)?;
    let Some(tracks) = overview(&events) else {
        return Ok(None);
    };
    let path = run_dir.join(TRACE_PNG);
    tracks.write(&path)?;
    Ok(Some(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn span(process: &str, pid: u32, frame: u64, ts_us: u64, dur_us: u64) -> SpanEvent {
        SpanEvent {
            name: "work".to_string(),
            process: process.to_string(),
            pid,
            tid: 1,
            ts_us,
            dur_us,
            frame_id: Some(frame),
            thread: String::new(),
            frame_depth: 0,
        }
    }

    #[test]
    fn the_overview_shows_middle_frames_that_crossed_every_process() {
        let mut events = Vec::new();
        for frame in 0..20u64 {
            let t = 1_000_000 + frame * 50_000;
            events.push(span("frame-source", 10, frame, t, 100));
            // Frame 9 never reached the detector: its path is incomplete.
            if frame != 9 {
                events.push(span("line-detector", 20, frame, t + 500, 30_000));
            }
        }
        // A standby detector that handled a part of frame 0 only: outside the window.
        events.push(SpanEvent {
            frame_depth: 1,
            ..span("line-detector", 30, 0, 1_000_000, 100)
        });
        events.sort_by_key(|e| e.ts_us);
        let tracks = overview(&events).unwrap_or_else(|| panic!("no overview"));
        assert_eq!(
            tracks.tracks,
            ["frame-source (10)", "line-detector (20)"],
            "a process without spans in the window takes no track"
        );
        let shown: Vec<u64> = tracks.links.iter().map(|(id, _)| *id).collect();
        assert_eq!(
            shown,
            [6, 7, 8, 10, 11, 12],
            "complete paths from the middle"
        );
        assert_eq!(tracks.links[0].1.len(), 2);
        assert!(
            tracks
                .bars
                .iter()
                .all(|b| b.start >= 0.0 && b.end >= b.start)
        );
        assert!(overview(&events[..1]).is_none(), "one process: no paths");
    }
}
