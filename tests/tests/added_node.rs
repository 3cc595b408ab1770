//! Adding a node to the pipeline: an observer that is in no shipped declaration
//! (`linetrack_e2e::pose_counter`, one [`NodeDecl`] and its `Sink` impl) is added with
//! `Pipeline::with_node` and run through the real supervisor — as its own process
//! (`linetrack-pose-counter`, over iceoryx2 shared memory, beside the real stage
//! processes) and as a thread (`--single-process`) — on a generated 40-frame sequence. The
//! supervisor starts it with the stages, waits for it before the source, and stops it at
//! the end; it sees every frame's pose once.

use linetrack_e2e::pose_counter::{self, FILE, NODE};
use linetrack_e2e::{assert_ids_accounted, base_sequence, bin_dir, scratch, write_config};
use linetrack_ipc::Shutdown;
use linetrack_pipeline_config::{Pacing, PipelineConfig};
use linetrack_run_record::read_events;
use linetrack_supervisor::{Mode, Pipeline, RunOptions, THREAD_IDS, run_pipeline};

const FRAMES: usize = 40;

/// Runs the pipeline with the pose counter added, in `mode`; returns the id the counter
/// ran as and the frame ids of the poses it saw.
fn run_with_counter(name: &str, mode: Mode) -> (u32, Vec<u64>) {
    let dir = scratch(name);
    let sequence = base_sequence(FRAMES);
    // Every frame processed however loaded the machine (the source waits for the
    // pipeline), quick supervision.
    let (config, run_dir) = write_config(
        &dir,
        &sequence,
        "[budget]\ndrop_late = false\n[supervisor]\nrestart_backoff_ms = 100\ndrain_timeout_ms = 30000\nstatus_every_ms = 0\n",
    );
    let mut config = PipelineConfig::from_file(&config).unwrap_or_else(|e| panic!("{e}"));
    config.source.pacing = Pacing::Fastest;
    let pipeline = Pipeline::default()
        .with_node(NODE, pose_counter::run)
        .unwrap_or_else(|e| panic!("{e:#}"));
    let options = RunOptions {
        mode,
        bin_dir: Some(bin_dir()),
        live_status: false,
    };
    let outcome = run_pipeline(&config, &options, &pipeline, &Shutdown::default())
        .unwrap_or_else(|e| panic!("{e:#}"));
    assert_eq!(outcome.run_dir, run_dir);
    assert!(!outcome.interrupted);
    assert_eq!(outcome.report.frames, FRAMES);
    let records = linetrack_e2e::Records {
        frames: linetrack_run_record::read_frames(&run_dir.join("frames.csv"))
            .unwrap_or_else(|e| panic!("{e}")),
        events: read_events(&run_dir.join("events.csv")).unwrap_or_else(|e| panic!("{e}")),
        leftovers: Default::default(),
    };
    assert_ids_accounted(&records, FRAMES as u64, &[]);
    // Nothing about the observer went wrong: no restart, no crash, no hang.
    let observer_events: Vec<_> = records
        .events
        .iter()
        .filter(|e| e.stage == "observer")
        .map(|e| format!("{} {}", e.kind, e.detail))
        .collect();
    assert!(observer_events.is_empty(), "{observer_events:?}");
    let text = std::fs::read_to_string(run_dir.join(FILE))
        .unwrap_or_else(|e| panic!("{}: {e}", run_dir.join(FILE).display()));
    let mut lines = text.lines();
    let id = lines
        .next()
        .and_then(|l| l.strip_prefix("id "))
        .and_then(|id| id.parse().ok())
        .unwrap_or_else(|| panic!("{FILE}: no id line: {text}"));
    let frame_ids = lines
        .map(|l| l.parse().unwrap_or_else(|e| panic!("{FILE}: {l:?}: {e}")))
        .collect();
    (id, frame_ids)
}

#[test]
fn an_added_observer_runs_as_a_process_and_sees_every_pose_once() {
    let (id, frame_ids) = run_with_counter("added-node-processes", Mode::Processes);
    assert_eq!(frame_ids, (0..FRAMES as u64).collect::<Vec<_>>());
    assert!(
        id != std::process::id() && id < THREAD_IDS,
        "ran as a process of its own: {id}"
    );
}

#[test]
fn an_added_observer_runs_as_a_thread_and_sees_every_pose_once() {
    let (id, frame_ids) = run_with_counter("added-node-threads", Mode::Threads);
    assert_eq!(frame_ids, (0..FRAMES as u64).collect::<Vec<_>>());
    assert!(id >= THREAD_IDS, "ran as a thread stage: {id}");
}
