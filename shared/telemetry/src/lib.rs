//! Observability shared by every process of the pipeline.
//!
//! - [`init`] sets up `tracing`: human-readable logs on stderr (filter from `RUST_LOG`, or
//!   the default given), and, when asked, a [`SpanRecorder`] that appends every closed span
//!   to a JSON-lines file as a complete event: name, process, thread, start (UNIX-epoch
//!   microseconds, so processes share one clock), duration and the span's `frame_id`.
//! - [`merge_traces`] joins the span files of all processes of a run into one Chrome trace
//!   (`trace.json`), which Perfetto and chrome://tracing open on one timeline.

use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{SystemTime, UNIX_EPOCH};
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
    /// The frame the span worked on, if it says.
    pub frame_id: Option<u64>,
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

/// A `tracing` layer that writes each closed span to a JSON-lines file.
pub struct SpanRecorder {
    process: String,
    pid: u32,
    out: Mutex<BufWriter<File>>,
}

impl SpanRecorder {
    /// Records the spans of process `process` into `path` (created or truncated).
    pub fn create(path: &Path, process: &str) -> Result<Self, TelemetryError> {
        if let Some(dir) = path.parent() {
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
            out: Mutex::new(BufWriter::new(file)),
        })
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
        let frame_id = timing.frame_id.or_else(|| {
            span.scope()
                .skip(1)
                .find_map(|p| p.extensions().get::<Timing>().and_then(|t| t.frame_id))
        });
        let event = SpanEvent {
            name: span.name().to_string(),
            process: self.process.clone(),
            pid: self.pid,
            tid: thread_number(),
            ts_us: timing.start_us,
            dur_us: epoch_us().saturating_sub(timing.start_us),
            frame_id,
        };
        if let (Ok(line), Ok(mut out)) = (serde_json::to_string(&event), self.out.lock()) {
            // Flushed per span: a stage killed mid-run keeps what it recorded.
            let _ = writeln!(out, "{line}").and_then(|_| out.flush());
        }
    }
}

/// Installs the process's `tracing` subscriber: logs to stderr at `default_filter` (or
/// `RUST_LOG`), and spans to `span_file` when given.
pub fn init(
    process: &str,
    default_filter: &str,
    span_file: Option<&Path>,
) -> Result<(), TelemetryError> {
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
    tracing_subscriber::registry()
        .with(logs)
        .with(recorder)
        .try_init()
        .map_err(|_| TelemetryError::AlreadyInitialised)
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

/// Writes `events` as a Chrome trace (JSON object format) to `path`; returns the number of
/// span events written.
pub fn write_chrome_trace(events: &[SpanEvent], path: &Path) -> Result<usize, TelemetryError> {
    let mut trace = Vec::with_capacity(events.len() + 8);
    let mut named = std::collections::BTreeSet::new();
    for e in events {
        if named.insert(e.pid) {
            trace.push(serde_json::json!({"ph": "M", "name": "process_name", "pid": e.pid, "tid": 0, "args": {"name": format!("{} ({})", e.process, e.pid)}}));
        }
        let mut args = serde_json::Map::new();
        if let Some(id) = e.frame_id {
            args.insert("frame_id".to_string(), id.into());
        }
        trace.push(serde_json::json!({"ph": "X", "cat": e.process, "name": e.name, "pid": e.pid, "tid": e.tid, "ts": e.ts_us, "dur": e.dur_us, "args": args}));
    }
    let json = serde_json::json!({"traceEvents": trace, "displayTimeUnit": "ms"});
    let file = File::create(path).map_err(|source| TelemetryError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::to_writer(BufWriter::new(file), &json).map_err(|e| TelemetryError::Io {
        path: path.to_path_buf(),
        source: e.into(),
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
        let dir = std::env::temp_dir().join(format!("linetrack-telemetry-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = span_file(&dir, "matcher", std::process::id());
        let recorder = SpanRecorder::create(&path, "matcher").unwrap_or_else(|e| panic!("{e}"));
        let subscriber = tracing_subscriber::registry().with(recorder);
        tracing::subscriber::with_default(subscriber, || {
            let frame = info_span!("match", frame_id = 17u64);
            let _entered = frame.enter();
            let inner = info_span!("describe");
            let _in = inner.enter();
            std::thread::sleep(std::time::Duration::from_millis(2));
        });
        // A torn last line, as from a killed process.
        std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .and_then(|mut f| f.write_all(b"{\"name\":\"tru"))
            .unwrap_or_else(|e| panic!("{e}"));
        let (events, skipped) = read_spans(&dir).unwrap_or_else(|e| panic!("{e}"));
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
        let outer = events
            .iter()
            .find(|e| e.name == "match")
            .unwrap_or_else(|| panic!("no match span"));
        assert!(outer.ts_us <= describe.ts_us && outer.dur_us >= describe.dur_us);
        assert_eq!(merge_traces(&dir).unwrap_or_else(|e| panic!("{e}")), 2);
        let trace: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join("trace.json")).unwrap_or_default(),
        )
        .unwrap_or_default();
        let events = trace["traceEvents"].as_array().cloned().unwrap_or_default();
        let name = format!("matcher ({})", std::process::id());
        assert!(
            events
                .iter()
                .any(|e| e["ph"] == "M" && e["args"]["name"] == name.as_str())
        );
        assert!(
            events
                .iter()
                .any(|e| e["ph"] == "X" && e["name"] == "describe" && e["args"]["frame_id"] == 17)
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
