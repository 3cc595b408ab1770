//! The pipeline end to end: `linetrack run` starts the real stage processes, which talk
//! over iceoryx2 shared memory, on a generated 40-frame sequence (at 10 Hz).

use linetrack_e2e::*;
use std::collections::BTreeSet;
use std::time::Duration;

mod restarts;
mod runs;
mod swaps;

const FRAMES: usize = 40;
const RUN_TIMEOUT: Duration = Duration::from_secs(120);
/// Quick supervision for tests: short backoff, prompt hang detection. The drain after the
/// source's last frame ends as soon as every frame has an outcome; its 30 s are room for a
/// loaded machine's backlog (at 4 s, two CPU hogs left the last frames `missing`).
const SUPERVISION: &str = "[supervisor]\nrestart_backoff_ms = 100\nhang_timeout_ms = 2000\ndrain_timeout_ms = 30000\nstatus_every_ms = 0\n";
/// ... and every frame processed however late, so that a test machine's load cannot turn
/// a frame the test looks at into a policy drop (the policy has its own tests).
fn quick() -> String {
    format!("{SUPERVISION}[budget]\ndrop_late = false\n")
}

/// [`start`] with `--pacing fastest`: with `drop_late = false` the source waits for the
/// pipeline, so no frame is overwritten in a full queue (`skipped`) however loaded the
/// machine is. For tests that look at every frame and act on none mid-run (at 10 Hz, two
/// CPU hogs left LSD behind and frames were skipped).
fn start_every_frame(dir: &std::path::Path, sequence: &std::path::Path, extra: &str) -> Run {
    start_with_args(dir, sequence, extra, &["--pacing", "fastest"])
}

fn ids(records: &Records) -> Vec<u64> {
    records.frames.iter().map(|f| f.frame_id).collect()
}

/// Every frame of the sequence appears exactly once, with a pose or a counted drop.
fn assert_every_frame_accounted(records: &Records) {
    linetrack_e2e::assert_ids_accounted(records, FRAMES as u64, &[]);
}

#[test]
fn every_frame_gets_a_pose_and_the_run_leaves_no_shared_memory() {
    let dir = scratch("plain");
    // The default drop policy, with an end-to-end budget no load reaches: a frame with a
    // newer one queued behind it is a counted drop, and the last frame always goes through
    // (with the 100 ms default, a heavily loaded machine dropped all 40 as late and the run
    // failed with nothing tracked — the right verdict for the run, not for this test).
    let run = start(
        &dir,
        &base_sequence(FRAMES),
        &format!("{SUPERVISION}[budget]\nend_to_end_ms = 60000.0\n"),
    );
    let run_dir = run.run_dir.clone();
    let (status, out, records) = run.finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_every_frame_accounted(&records);
    let tracked = records
        .frames
        .iter()
        .filter(|f| f.outcome == "pose")
        .count();
    // Under load the policy drops frames left behind (counted above); of the frames that reached
    // the pose estimator, most are tracked.
    let estimated = records.frames.iter().filter(|f| f.has_pose()).count();
    assert!(
        estimated > 0 && tracked * 2 >= estimated,
        "only {tracked} of the {estimated} frames with a pose tracked:\n{out}"
    );
    // Per-stage latencies were measured in each process. On a loaded machine the matcher
    // may go over budget and fall back: then ℓ1 frames follow a recorded fallback.
    let first_fallback = records
        .events_of("fallback")
        .first()
        .and_then(|e| e.frame_id);
    for f in records.frames.iter().filter(|f| f.outcome == "pose") {
        assert!(
            f.stage_ms[1..]
                .iter()
                .all(|ms| ms.is_finite() && *ms >= 0.0),
            "frame {}: {:?}",
            f.frame_id,
            f.stage_ms
        );
        assert_eq!(f.detector, "lsd");
        match f.matcher.as_str() {
            "lbd" => {}
            "l1" => assert!(
                first_fallback.is_some_and(|at| at < f.frame_id),
                "frame {} matched by l1 without a fallback before it: {:?}",
                f.frame_id,
                records.events
            ),
            other => panic!("frame {}: matcher {other:?}", f.frame_id),
        }
    }
    assert_eq!(
        records.leftovers,
        Default::default(),
        "iceoryx2 nodes or services left behind"
    );
    // The report and the merged trace: spans of all four stage processes, with frame ids.
    assert!(out.contains("end-to-end") && out.contains("p99"), "{out}");
    let trace: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(run_dir.join("trace.json")).unwrap_or_default(),
    )
    .unwrap_or_default();
    let events = trace["traceEvents"].as_array().cloned().unwrap_or_default();
    let processes: BTreeSet<String> = events
        .iter()
        .filter(|e| e["ph"] == "M" && e["name"] == "process_name")
        .filter_map(|e| e["args"]["name"].as_str().map(String::from))
        .collect();
    assert_eq!(
        processes,
        ["frame-source", "line-detector", "matcher", "pose-estimator"]
            .map(String::from)
            .into_iter()
            .collect()
    );
    // A frame matched by LBD was described, and its spans say which frame (under load a
    // frame can lose its images and be matched by geometry: those have no `describe`).
    if let Some(f) = records
        .frames
        .iter()
        .find(|f| f.matcher == "lbd" && f.outcome == "pose")
    {
        assert!(
            events
                .iter()
                .any(|e| e["name"] == "describe" && e["args"]["frame_id"] == f.frame_id),
            "no describe span of frame {}",
            f.frame_id
        );
    }
    // Frame 5's flow: from the source through the detector and the matcher to the pose
    // estimator, one flow event in each process.
    let flow: Vec<(String, u64)> = events
        .iter()
        .filter(|e| e["cat"] == "frame" && e["id"] == 5)
        .map(|e| {
            (
                e["ph"].as_str().unwrap_or("").to_string(),
                e["pid"].as_u64().unwrap_or(0),
            )
        })
        .collect();
    let phases: Vec<&str> = flow.iter().map(|(ph, _)| ph.as_str()).collect();
    assert_eq!(phases, ["s", "t", "t", "f"], "frame 5's flow: {flow:?}");
    let pids: BTreeSet<u64> = flow.iter().map(|(_, pid)| *pid).collect();
    assert_eq!(pids.len(), 4, "frame 5's flow: {flow:?}");
    assert!(run_dir.join("latency.png").is_file());
    assert!(run_dir.join("latency-timeline.png").is_file());
    // The frames' paths through the four processes, drawn.
    assert!(run_dir.join("trace-overview.png").is_file());
}

/// `linetrack report` on a run folder: it succeeds; its output.
fn report_of(run_dir: &std::path::Path) -> String {
    let out = std::process::Command::new(bin_dir().join("linetrack"))
        .arg("report")
        .arg(run_dir)
        .output()
        .unwrap_or_else(|e| panic!("linetrack report: {e}"));
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "linetrack report {}: {}\n{text}{}",
        run_dir.display(),
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

fn proc_is_zombie_or_gone(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .map_or(true, |s| s.split_whitespace().nth(2) == Some("Z"))
}

/// `linetrack ctl <action>` on `run`, once 8 frames have an outcome; it must succeed.
fn ctl_after_8_frames(run: &mut Run, action: &[&str]) {
    run.wait_for("8 frames", RUN_TIMEOUT, |s| s.frames >= 8);
    let ctl = std::process::Command::new(bin_dir().join("linetrack"))
        .args(["ctl", "--run-dir"])
        .arg(&run.run_dir)
        .args(action)
        .env(linetrack_ipc::Scope::PREFIX_VAR, &run.prefix)
        .output()
        .unwrap_or_else(|e| panic!("linetrack ctl: {e}"));
    assert!(
        ctl.status.success(),
        "ctl: {}{}",
        String::from_utf8_lossy(&ctl.stdout),
        String::from_utf8_lossy(&ctl.stderr)
    );
}

fn hot_swap(mut run: Run) {
    ctl_after_8_frames(&mut run, &["swap-detector", "fld"]);
    let (status, out, records) = run.finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_every_frame_accounted(&records);
    let outcomes: Vec<(u64, &str)> = records
        .frames
        .iter()
        .map(|f| (f.frame_id, f.outcome.as_str()))
        .collect();
    assert!(
        records.frames.iter().all(|f| f.has_pose()),
        "a frame without a pose: {outcomes:?}"
    );
    let swaps = records.events_of("swap");
    assert_eq!(swaps.len(), 1, "{:?}", records.events);
    let at = swaps[0]
        .frame_id
        .unwrap_or_else(|| panic!("swap without a frame"));
    assert!(at > 0 && at < FRAMES as u64, "swap at {at}");
    for f in &records.frames {
        let expected = if f.frame_id < at { "lsd" } else { "fld" };
        assert_eq!(f.detector, expected, "frame {} (swap at {at})", f.frame_id);
    }
}
