//! Observability shared by every process of the pipeline.
//!
//! - [`init`] sets up `tracing`: human-readable logs on stderr (filter from `RUST_LOG`, or
//!   the default given), and, when asked, a [`SpanRecorder`] that appends every closed span
//!   to a JSON-lines file as a complete event: name, process, thread, start (UNIX-epoch
//!   microseconds, so processes share one clock), duration and the span's `frame_id`. The
//!   file is buffered: flushed when a span closes at least [`FLUSH_EVERY`] after the last
//!   flush, when the buffer fills, and when the [`FlushGuard`] that `init` returns drops, so
//!   a process killed outright loses at most its last [`FLUSH_EVERY`] of spans.
//! - [`merge_traces`] joins the span files of all processes of a run into one Chrome trace
//!   (`trace.json`), which Perfetto and chrome://tracing open on one timeline: one track per
//!   process named by its stage, and a flow (arrows) through each frame's spans across the
//!   processes, so selecting a frame's span shows where the frame went before and after.

use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use tracing::Subscriber;
use tracing::field::{Field, Visit};
use tracing::span::{Attributes, Id};
use tracing_subscriber::layer::{Context, SubscriberExt};
use tracing_subscriber::registry::LookupSpan;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{EnvFilter, Layer};

/// Telemetry errors.
#[derive(Debug, thiserror::Error)]
pub enum TelemetryError {
    /// A file could not be created, read or written.
    #[error("{}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A global subscriber was already installed.
    #[error("tracing is already initialised in this process")]
    AlreadyInitialised,
}

/// One recorded span.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpanEvent {
    /// Span name (the operation).
    pub name: String,
    /// Process name (the stage).
    pub process: String,
    /// Process id.
    pub pid: u32,
    /// Thread, as a small number.
    pub tid: u64,
    /// Start, UNIX-epoch microseconds.
    pub ts_us: u64,
    /// Duration, microseconds.
    pub dur_us: u64,
    /// The frame the span worked on, if it or an enclosing span says.
    pub frame_id: Option<u64>,
    /// The thread's name, when it has one.
    #[serde(default)]
    pub thread: String,
    /// How many enclosing spans carry a frame id of their own: 0 for the span in which
    /// this process handles a frame (the frame's span here), more for its parts.
    #[serde(default)]
    pub frame_depth: u32,
}

fn epoch_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_micros() as u64)
        .unwrap_or(0)
}

struct Timing {
    start_us: u64,
    frame_id: Option<u64>,
}

struct FrameIdVisitor(Option<u64>);

impl Visit for FrameIdVisitor {
    fn record_u64(&mut self, field: &Field, value: u64) {
        if field.name() == "frame_id" {
            self.0 = Some(value);
        }
    }

    fn record_i64(&mut self, field: &Field, value: i64) {
        if field.name() == "frame_id" {
            self.0 = u64::try_from(value).ok();
        }
    }

    fn record_debug(&mut self, _field: &Field, _value: &dyn std::fmt::Debug) {}
}

/// How often at most the span file is flushed while spans close: what a process killed
/// outright (SIGKILL) can lose.
pub const FLUSH_EVERY: Duration = Duration::from_millis(500);

/// A span file's buffered writer.
struct Sink {
    out: BufWriter<File>,
    last_flush: Instant,
    every: Duration,
}

impl Sink {
    fn write(&mut self, line: &str) {
        if writeln!(self.out, "{line}").is_ok() && self.last_flush.elapsed() >= self.every {
            self.flush();
        }
    }

    fn flush(&mut self) {
        // A span file is a diagnostic: a failing disk must not stop the stage.
        let _ = self.out.flush();
        self.last_flush = Instant::now();
    }
}

/// Flushes the span file when dropped (returned by [`init`] and
/// [`SpanRecorder::flush_guard`]): keep it alive for as long as the process records.
#[must_use = "the span file is flushed when the guard drops"]
#[derive(Default)]
pub struct FlushGuard {
    sink: Option<Arc<Mutex<Sink>>>,
}

impl FlushGuard {
    /// Writes what is buffered now.
    pub fn flush(&self) {
        if let Some(Ok(mut sink)) = self.sink.as_ref().map(|s| s.lock()) {
            sink.flush();
        }
    }
}

impl Drop for FlushGuard {
    fn drop(&mut self) {
        self.flush();
    }
}

/// A `tracing` layer that writes each closed span to a JSON-lines file.
pub struct SpanRecorder {
    process: String,
    pid: u32,
    sink: Arc<Mutex<Sink>>,
}

impl SpanRecorder {
    /// Records the spans of process `process` into `path` (created or truncated), flushed
    /// every [`FLUSH_EVERY`].
    pub fn create(path: &Path, process: &str) -> Result<Self, TelemetryError> {
        // A folder that exists is not made again: mkdir locks the folder above even then,
        // and waits while another process holds that lock (a standby detector waited
        // seconds so in `mkdir`, under load, while LSD missed every frame).
        if let Some(dir) = path.parent()
            && !dir.is_dir()
        {
            std::fs::create_dir_all(dir).map_err(|source| TelemetryError::Io {
                path: dir.to_path_buf(),
                source,
            })?;
        }
        let file = File::create(path).map_err(|source| TelemetryError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Ok(Self {
            process: process.to_string(),
            pid: std::process::id(),
            sink: Arc::new(Mutex::new(Sink {
                out: BufWriter::new(file),
                last_flush: Instant::now(),
                every: FLUSH_EVERY,
            })),
        })
    }

    /// The same recorder, flushing when a span closes `every` after the last flush
    /// (`Duration::ZERO`: at every span).
    pub fn with_flush_every(self, every: Duration) -> Self {
        if let Ok(mut sink) = self.sink.lock() {
            sink.every = every;
        }
        self
    }

    /// A guard that flushes this recorder's file when dropped.
    pub fn flush_guard(&self) -> FlushGuard {
        FlushGuard {
            sink: Some(Arc::clone(&self.sink)),
        }
    }
}

fn thread_number() -> u64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    static NEXT: AtomicU64 = AtomicU64::new(1);
    thread_local!(static NUMBER: u64 = NEXT.fetch_add(1, Ordering::Relaxed));
    NUMBER.with(|n| *n)
}

impl<S: Subscriber + for<'a> LookupSpan<'a>> Layer<S> for SpanRecorder {
    fn on_new_span(&self, attrs: &Attributes<'_>, id: &Id, ctx: Context<'_, S>) {
        let mut visitor = FrameIdVisitor(None);
        attrs.record(&mut visitor);
        if let Some(span) = ctx.span(id) {
            span.extensions_mut().insert(Timing {
                start_us: epoch_us(),
                frame_id: visitor.0,
            });
        }
    }

    fn on_close(&self, id: Id, ctx: Context<'_, S>) {
        let Some(span) = ctx.span(&id) else { return };
        let extensions = span.extensions();
        let Some(timing) = extensions.get::<Timing>() else {
            return;
        };
        // A span without its own frame id inherits its parent's.
        let ancestor_frames: Vec<u64> = span
            .scope()
            .skip(1)
            .filter_map(|p| p.extensions().get::<Timing>().and_then(|t| t.frame_id))
            .collect();
        let event = SpanEvent {
            name: span.name().to_string(),
            process: self.process.clone(),
            pid: self.pid,
            tid: thread_number(),
            ts_us: timing.start_us,
            dur_us: epoch_us().saturating_sub(timing.start_us),
            frame_id: timing.frame_id.or(ancestor_frames.first().copied()),
            thread: std::thread::current().name().unwrap_or("").to_string(),
            frame_depth: ancestor_frames.len() as u32,
        };
        if let (Ok(line), Ok(mut sink)) = (serde_json::to_string(&event), self.sink.lock()) {
            sink.write(&line);
        }
    }
}

/// Installs the process's `tracing` subscriber: logs to stderr at `default_filter` (or
/// `RUST_LOG`), and spans to `span_file` when given. The guard flushes the span file when
/// dropped: hold it until the process's work is done.
pub fn init(
    process: &str,
    default_filter: &str,
    span_file: Option<&Path>,
) -> Result<FlushGuard, TelemetryError> {
    let filter =
        EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default_filter));
    let logs = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_target(false)
        .with_filter(filter);
    let recorder = match span_file {
        Some(path) => Some(SpanRecorder::create(path, process)?),
        None => None,
    };
    let guard = recorder
        .as_ref()
        .map(SpanRecorder::flush_guard)
        .unwrap_or_default();
    tracing_subscriber::registry()
        .with(logs)
        .with(recorder)
        .try_init()
        .map_err(|_| TelemetryError::AlreadyInitialised)?;
    Ok(guard)
}

/// The span file of process `process` (pid `pid`) in `run_dir`.
pub fn span_file(run_dir: &Path, process: &str, pid: u32) -> PathBuf {
    run_dir.join("spans").join(format!("{process}-{pid}.jsonl"))
}

/// Reads every span file of `run_dir` (lines that do not parse — a process killed
/// mid-write — are skipped and counted).
pub fn read_spans(run_dir: &Path) -> Result<(Vec<SpanEvent>, usize), TelemetryError> {
    let dir = run_dir.join("spans");
    let mut events = Vec::new();
    let mut skipped = 0;
    let entries = match std::fs::read_dir(&dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok((events, 0)),
        Err(source) => return Err(TelemetryError::Io { path: dir, source }),
    };
    let mut paths: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "jsonl"))
        .collect();
    paths.sort();
    for path in paths {
        let file = File::open(&path).map_err(|source| TelemetryError::Io {
            path: path.clone(),
            source,
        })?;
        for line in BufReader::new(file).lines() {
            let line = line.map_err(|source| TelemetryError::Io {
                path: path.clone(),
                source,
            })?;
            match serde_json::from_str::<SpanEvent>(&line) {
                Ok(event) => events.push(event),
                Err(_) => skipped += 1,
            }
        }
    }
    events.sort_by_key(|e| e.ts_us);
    Ok((events, skipped))
}

/// The processes of `events` (sorted by start) as `(pid, process name)`, in order of
/// their first span: pipeline order, since frames start at the frame source.
pub fn processes(events: &[SpanEvent]) -> Vec<(u32, String)> {
    let mut seen = std::collections::BTreeSet::new();
    events
        .iter()
        .filter(|e| seen.insert(e.pid))
        .map(|e| (e.pid, e.process.clone()))
        .collect()
}

/// Name of the span in which a stage works on a frame's images ahead of the frame's turn
/// (the pose estimator's corners): part of the frame's record, not of its path.
pub const PREPARE_SPAN: &str = "prepare";

/// Each frame's path through the processes: for every frame handled by more than one
/// process, its frame spans (`frame_depth` 0, one per process that handled it, the work
/// done ahead of its turn left out), in time order.
pub fn frame_paths(events: &[SpanEvent]) -> std::collections::BTreeMap<u64, Vec<&SpanEvent>> {
    let mut frames: std::collections::BTreeMap<u64, Vec<&SpanEvent>> = Default::default();
    for e in events
        .iter()
        .filter(|e| e.frame_depth == 0 && e.name != PREPARE_SPAN)
    {
        if let Some(id) = e.frame_id {
            frames.entry(id).or_default().push(e);
        }
    }
    frames.retain(|_, spans| {
        spans.sort_by_key(|e| (e.ts_us, e.pid));
        spans.iter().any(|e| e.pid != spans[0].pid)
    });
    frames
}

/// The Chrome-trace events of `events` (sorted by start): a named track per process
/// (`process_name` = its stage, ordered by first appearance) and per thread, a complete
/// event (`X`) per span, and per frame handled by more than one process a flow — `s` on
/// its first process's frame span, `t` on each next one, `f` on the last, all with the
/// frame id as flow id — binding the frame's spans across processes.
pub fn chrome_trace_events(events: &[SpanEvent]) -> Vec<serde_json::Value> {
    use serde_json::json;
    let mut trace = Vec::with_capacity(events.len() + 16);
    for (order, (pid, process)) in processes(events).into_iter().enumerate() {
        trace.push(json!({"ph": "M", "name": "process_name", "pid": pid, "tid": 0, "args": {"name": process}}));
        trace.push(json!({"ph": "M", "name": "process_sort_index", "pid": pid, "tid": 0, "args": {"sort_index": order + 1}}));
    }
    let mut threads = std::collections::BTreeSet::new();
    for e in events {
        if threads.insert((e.pid, e.tid)) {
            let name = match e.thread.as_str() {
                "" | "main" => e.process.clone(),
                thread => format!("{}: {thread}", e.process),
            };
            trace.push(json!({"ph": "M", "name": "thread_name", "pid": e.pid, "tid": e.tid, "args": {"name": name}}));
        }
        let mut args = serde_json::Map::new();
        if let Some(id) = e.frame_id {
            args.insert("frame_id".to_string(), id.into());
        }
        trace.push(json!({"ph": "X", "cat": e.process, "name": e.name, "pid": e.pid, "tid": e.tid, "ts": e.ts_us, "dur": e.dur_us, "args": args}));
    }
    for (id, spans) in frame_paths(events) {
        let last = spans.len() - 1;
        for (k, e) in spans.iter().enumerate() {
            // Inside the span, so the flow binds to it and not to a neighbour: the flow
            // leaves the first span where it ends and enters the others where they start.
            let inside = |at: u64| at.clamp(e.ts_us, e.ts_us + e.dur_us.saturating_sub(1));
            let mut flow =
                json!({"cat": "frame", "name": "frame", "id": id, "pid": e.pid, "tid": e.tid});
            let (ph, ts) = match k {
                0 => ("s", inside(e.ts_us + e.dur_us.saturating_sub(1))),
                k if k == last => ("f", inside(e.ts_us + 1)),
                _ => ("t", inside(e.ts_us + 1)),
            };
            flow["ph"] = ph.into();
            flow["ts"] = ts.into();
            if ph != "s" {
                flow["bp"] = "e".into();
            }
            trace.push(flow);
        }
    }
    trace
}

/// Writes `events` as a Chrome trace (JSON object format, [`chrome_trace_events`]) to
/// `path`, whole or not at all: into `<path>.tmp`, renamed over `path` once complete, so a
/// write cut short (a full disk) leaves no invalid JSON (the span files it was made from
/// stay). Returns the number of span events written.
pub fn write_chrome_trace(events: &[SpanEvent], path: &Path) -> Result<usize, TelemetryError> {
    let json =
        serde_json::json!({"traceEvents": chrome_trace_events(events), "displayTimeUnit": "ms"});
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let written = File::create(&tmp).and_then(|file| {
        let mut out = BufWriter::new(file);
        serde_json::to_writer(&mut out, &json)?;
        out.into_inner().map_err(|e| e.into_error())?.sync_data()?;
        std::fs::rename(&tmp, path)
    });
    written.map_err(|source| {
        let _ = std::fs::remove_file(&tmp);
        TelemetryError::Io {
            path: path.to_path_buf(),
            source,
        }
    })?;
    Ok(events.len())
}

/// Merges the span files of `run_dir` into `run_dir/trace.json`; returns the span count.
pub fn merge_traces(run_dir: &Path) -> Result<usize, TelemetryError> {
    let (events, _) = read_spans(run_dir)?;
    write_chrome_trace(&events, &run_dir.join("trace.json"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tracing::info_span;
    use tracing_subscriber::layer::SubscriberExt;

    #[test]
    fn spans_are_recorded_with_their_frame_and_merged_into_a_chrome_trace() {
        let scratch = linetrack_test_data::Scratch::new("telemetry", "spans");
        let dir = scratch.path();
        let path = span_file(dir, "matcher", std::process::id());
        let recorder = SpanRecorder::create(&path, "matcher").unwrap_or_else(|e| panic!("{e}"));
        let guard = recorder.flush_guard();
        let subscriber = tracing_subscriber::registry().with(recorder);
        tracing::subscriber::with_default(subscriber, || {
            let frame = info_span!("match", frame_id = 17u64);
            let _entered = frame.enter();
            let inner = info_span!("describe");
            let _in = inner.enter();
            std::thread::sleep(std::time::Duration::from_millis(2));
        });
        drop(guard);
        // A torn last line, as from a killed process.
        std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .and_then(|mut f| f.write_all(b"{\"name\":\"tru"))
            .unwrap_or_else(|e| panic!("{e}"));
        let (events, skipped) = read_spans(dir).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(skipped, 1);
        assert_eq!(events.len(), 2);
        let describe = events
            .iter()
            .find(|e| e.name == "describe")
            .unwrap_or_else(|| panic!("no describe span"));
        assert_eq!(
            describe.frame_id,
            Some(17),
            "inherits the frame of its parent"
        );
        assert!(describe.dur_us >= 2000);
        assert_eq!(describe.frame_depth, 1, "a part of the frame's span");
        let outer = events
            .iter()
            .find(|e| e.name == "match")
            .unwrap_or_else(|| panic!("no match span"));
        assert!(outer.ts_us <= describe.ts_us && outer.dur_us >= describe.dur_us);
        assert_eq!(outer.frame_depth, 0, "the frame's span in this process");
        assert_eq!(merge_traces(dir).unwrap_or_else(|e| panic!("{e}")), 2);
        let trace: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join("trace.json")).unwrap_or_default(),
        )
        .unwrap_or_default();
        let events = trace["traceEvents"].as_array().cloned().unwrap_or_default();
        assert!(
            events
                .iter()
                .any(|e| e["name"] == "process_name" && e["args"]["name"] == "matcher")
        );
        assert!(
            events
                .iter()
                .any(|e| e["ph"] == "X" && e["name"] == "describe" && e["args"]["frame_id"] == 17)
        );
    }

    fn span_file_lines(path: &Path) -> usize {
        std::fs::read_to_string(path)
            .unwrap_or_default()
            .lines()
            .count()
    }

    #[test]
    fn spans_are_buffered_until_due_and_flushed_by_the_guard() {
        let scratch = linetrack_test_data::Scratch::new("telemetry", "flush");
        let dir = scratch.path();
        for (every, written_at_once) in [(Duration::MAX, 0), (Duration::ZERO, 1)] {
            let path = span_file(dir, "detector", every.as_secs() as u32);
            let recorder = SpanRecorder::create(&path, "detector")
                .unwrap_or_else(|e| panic!("{e}"))
                .with_flush_every(every);
            let guard = recorder.flush_guard();
            let subscriber = tracing_subscriber::registry().with(recorder);
            tracing::subscriber::with_default(subscriber, || {
                drop(info_span!("detect", frame_id = 3u64).entered());
                // What a process killed now would leave in its file.
                assert_eq!(
                    span_file_lines(&path),
                    written_at_once,
                    "flush every {every:?}"
                );
                guard.flush();
                assert_eq!(span_file_lines(&path), 1, "flushed by the guard");
                drop(info_span!("detect", frame_id = 4u64).entered());
                drop(guard);
                assert_eq!(span_file_lines(&path), 2, "flushed when the guard drops");
            });
        }
    }

    fn span(process: &str, pid: u32, name: &str, ts_us: u64, dur_us: u64) -> SpanEvent {
        SpanEvent {
            name: name.to_string(),
            process: process.to_string(),
            pid,
            tid: 1,
            ts_us,
            dur_us,
            frame_id: Some(7),
            thread: "main".to_string(),
            frame_depth: 0,
        }
    }

    #[test]
    fn work_ahead_of_a_frames_turn_is_not_part_of_its_path() {
        let events = [
            span("frame-source", 100, "publish_frame", 1_000, 20),
            span("pose-estimator", 400, PREPARE_SPAN, 1_030, 500),
            span("line-detector", 200, "frame", 1_040, 900),
            span("pose-estimator", 400, "frame", 2_000, 400),
        ];
        let paths = frame_paths(&events);
        let path: Vec<&str> = paths[&7].iter().map(|e| e.process.as_str()).collect();
        assert_eq!(path, ["frame-source", "line-detector", "pose-estimator"]);
    }

    #[test]
    fn a_frame_is_one_flow_through_the_processes_on_tracks_named_by_stage() {
        let scratch = linetrack_test_data::Scratch::new("telemetry", "flow");
        let dir = scratch.path();
        let mut describe = span("matcher", 300, "describe", 2_100, 50);
        describe.frame_depth = 1;
        let mut other_frame = span("frame-source", 100, "publish_frame", 3_000, 10);
        other_frame.frame_id = Some(8);
        let mut helper = span("line-detector", 200, "detect", 1_050, 100);
        (helper.tid, helper.thread, helper.frame_id) = (2, "standby".to_string(), None);
        let files = [
            (
                "frame-source",
                100,
                vec![
                    span("frame-source", 100, "publish_frame", 1_000, 20),
                    other_frame,
                ],
            ),
            (
                "line-detector",
                200,
                vec![span("line-detector", 200, "frame", 1_040, 900), helper],
            ),
            (
                "matcher",
                300,
                vec![span("matcher", 300, "match", 2_000, 400), describe],
            ),
        ];
        for (process, pid, events) in &files {
            let path = span_file(dir, process, *pid);
            let _ = std::fs::create_dir_all(dir.join("spans"));
            let lines: Vec<String> = events
                .iter()
                .map(|e| serde_json::to_string(e).unwrap_or_default())
                .collect();
            std::fs::write(&path, lines.join("\n")).unwrap_or_else(|e| panic!("{e}"));
        }
        assert_eq!(merge_traces(dir).unwrap_or_else(|e| panic!("{e}")), 6);
        let trace: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join("trace.json")).unwrap_or_default(),
        )
        .unwrap_or_default();
        let events = trace["traceEvents"].as_array().cloned().unwrap_or_default();
        let meta = |name: &str| -> Vec<(u64, u64, String)> {
            events
                .iter()
                .filter(|e| e["ph"] == "M" && e["name"] == name)
                .map(|e| {
                    (
                        e["pid"].as_u64().unwrap_or(0),
                        e["tid"].as_u64().unwrap_or(0),
                        e["args"]["name"].as_str().unwrap_or("").to_string(),
                    )
                })
                .collect()
        };
        assert_eq!(
            meta("process_name"),
            vec![
                (100, 0, "frame-source".to_string()),
                (200, 0, "line-detector".to_string()),
                (300, 0, "matcher".to_string()),
            ]
        );
        let threads = meta("thread_name");
        assert!(
            threads.contains(&(200, 1, "line-detector".to_string())),
            "{threads:?}"
        );
        assert!(
            threads.contains(&(200, 2, "line-detector: standby".to_string())),
            "{threads:?}"
        );
        let flows: Vec<&serde_json::Value> = events
            .iter()
            .filter(|e| ["s", "t", "f"].iter().any(|ph| e["ph"] == *ph))
            .collect();
        let path: Vec<(String, u64)> = flows
            .iter()
            .map(|e| {
                assert_eq!(e["id"], 7, "one flow per frame, the frame id its id: {e}");
                (
                    e["ph"].as_str().unwrap_or("").to_string(),
                    e["pid"].as_u64().unwrap_or(0),
                )
            })
            .collect();
        assert_eq!(
            path,
            vec![
                ("s".to_string(), 100),
                ("t".to_string(), 200),
                ("f".to_string(), 300)
            ],
            "frame 7 goes source -> detector -> matcher; frame 8 met one process only"
        );
        // Each flow event lies inside the frame's span it binds to.
        let within = |e: &serde_json::Value, start: u64, dur: u64| {
            let ts = e["ts"].as_u64().unwrap_or(0);
            assert!(ts >= start && ts < start + dur, "{e} outside {start}+{dur}");
        };
        within(flows[0], 1_000, 20);
        within(flows[1], 1_040, 900);
        within(flows[2], 2_000, 400);
        assert_eq!(flows[1]["bp"], "e");
        assert_eq!(flows[2]["bp"], "e");
    }
}
