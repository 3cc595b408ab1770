//! The pipeline end to end: `linetrack run` starts the real stage processes, which talk
//! over iceoryx2 shared memory, on a generated 40-frame sequence (at 10 Hz).

use linetrack_e2e::*;
use std::collections::BTreeSet;
use std::time::Duration;

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

fn kill_and_recover(stage: &str) {
    let dir = scratch(&format!("kill-{stage}"));
    // The source waits for the pipeline: the frames lost with the victim are the few in
    // flight, not a loaded machine's backlog (at 10 Hz, two CPU hogs and LSD: 23 of 40).
    let mut run = start_every_frame(&dir, &base_sequence(FRAMES), &quick());
    let status = run.wait_for("10 frames", RUN_TIMEOUT, |s| s.frames >= 10);
    let victim = status
        .stages
        .iter()
        .find(|s| s.stage == stage)
        .unwrap_or_else(|| panic!("no {stage} in {:?}", status.stages))
        .pid;
    signal(victim, "KILL");
    let (exit, out, records) = run.finish(RUN_TIMEOUT);
    assert!(exit.success(), "{exit}\n{out}");
    assert_every_frame_accounted(&records);
    let crashes = records.events_of("crash");
    assert!(
        crashes
            .iter()
            .any(|e| e.stage == stage && e.detail.contains(&victim.to_string())),
        "{:?}",
        records.events
    );
    assert!(
        records
            .events_of("restart")
            .iter()
            .any(|e| e.stage == stage),
        "{:?}",
        records.events
    );
    // Tracking goes on after the restart: the last frames have poses.
    let tail: Vec<&str> = records.frames[FRAMES - 5..]
        .iter()
        .map(|f| f.outcome.as_str())
        .collect();
    assert!(
        tail.iter().all(|o| *o == "pose" || *o == "lost"),
        "after the restart: {tail:?}"
    );
    let missing = records.frames.iter().filter(|f| !f.has_pose()).count();
    assert!(missing < FRAMES / 2, "{missing} frames without a pose");
    assert_eq!(
        records.leftovers,
        Default::default(),
        "the killed process's shared memory was not reclaimed"
    );
    assert_losses_explained(&records);
    // The last stage has no stage after it to see its losses: the supervisor names them,
    // and how it died.
    if stage == "pose-estimator"
        && records
            .frames
            .iter()
            .any(|f| f.outcome == "skipped" && f.dropped_by == stage)
    {
        assert!(
            records.events_of("skipped").iter().any(|e| e
                .detail
                .contains(&format!("died with the pose estimator (pid {victim} crash"))),
            "{:?}",
            records.events
        );
    }
}

/// Every frame lost with a stage (`skipped`) lies in the range `frames A..B` of a `skipped`
/// event of the stage that lost it, and none is `missing` (unexplained).
fn assert_losses_explained(records: &Records) {
    let ranges: Vec<(&str, std::ops::Range<u64>)> = records
        .events_of("skipped")
        .iter()
        .filter_map(|e| {
            let words = e.detail.strip_prefix("frames ")?;
            let (from, rest) = words.split_once("..")?;
            let to: String = rest.chars().take_while(char::is_ascii_digit).collect();
            Some((e.stage.as_str(), from.parse().ok()?..to.parse().ok()?))
        })
        .collect();
    for f in &records.frames {
        assert_ne!(f.outcome, "missing", "frame {} unexplained", f.frame_id);
        if f.outcome == "skipped" {
            assert!(
                ranges
                    .iter()
                    .any(|(stage, r)| *stage == f.dropped_by && r.contains(&f.frame_id)),
                "frame {} skipped by {} without an event: {:?}",
                f.frame_id,
                f.dropped_by,
                records.events
            );
        }
    }
}

#[test]
fn a_killed_line_detector_is_restarted_and_the_run_completes() {
    kill_and_recover("line-detector");
}

#[test]
fn a_killed_matcher_is_restarted_and_the_run_completes() {
    kill_and_recover("matcher");
}

#[test]
fn a_killed_pose_estimator_is_restarted_and_resumes_its_trajectory() {
    kill_and_recover("pose-estimator");
}

#[test]
fn a_hung_pose_estimator_is_replaced_and_the_frames_lost_with_it_carry_an_event() {
    let dir = scratch("hang-pose-estimator");
    let mut run = start(&dir, &base_sequence(FRAMES), &quick());
    let status = run.wait_for("5 frames", RUN_TIMEOUT, |s| s.frames >= 5);
    let victim = status
        .stages
        .iter()
        .find(|s| s.stage == "pose-estimator")
        .unwrap_or_else(|| panic!("no pose estimator in {:?}", status.stages))
        .pid;
    // Stopped for good: the supervisor finds the silence (hang_timeout_ms 2000), kills it
    // and starts another.
    signal(victim, "STOP");
    let (exit, out, records) = run.finish(RUN_TIMEOUT);
    assert!(exit.success(), "{exit}\n{out}");
    assert_every_frame_accounted(&records);
    assert!(
        records
            .events_of("hang")
            .iter()
            .any(|e| e.stage == "pose-estimator" && e.detail.contains(&format!("pid {victim} "))),
        "{:?}",
        records.events
    );
    assert_losses_explained(&records);
    let lost = records
        .frames
        .iter()
        .filter(|f| f.outcome == "skipped" && f.dropped_by == "pose-estimator")
        .count();
    assert!(
        lost > 0,
        "a 2 s hang at 10 Hz lost no frame: {:?}",
        records.events
    );
    assert!(
        records.events_of("skipped").iter().any(|e| e
            .detail
            .contains(&format!("died with the pose estimator (pid {victim} hang"))),
        "{:?}",
        records.events
    );
}

#[test]
fn a_killed_frame_source_is_restarted_from_the_next_frame() {
    kill_and_recover("frame-source");
}

#[test]
fn a_killed_supervisor_takes_its_stages_with_it() {
    let dir = scratch("kill-supervisor");
    let mut run = start(&dir, &base_sequence(FRAMES), &quick());
    let status = run.wait_for("5 frames", RUN_TIMEOUT, |s| s.frames >= 5);
    signal(status.supervisor_pid, "KILL");
    let _ = run.child.wait();
    // The kernel ends each stage with its parent (the parent-death signal): none is left
    // running; the wait is bounded only so that a failure does not hang the suite.
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    for s in &status.stages {
        while !proc_is_zombie_or_gone(s.pid) {
            assert!(
                std::time::Instant::now() < deadline,
                "stage {} (pid {}) outlived its supervisor",
                s.stage,
                s.pid
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    // What the supervisor recorded before it died is on disk.
    let records = Records::read(&run.run_dir, &run.prefix);
    assert!(records.frames.len() >= 5, "{} frames", records.frames.len());
    // The report reads it and says the run was killed.
    let report = std::process::Command::new(bin_dir().join("linetrack"))
        .arg("report")
        .arg(&run.run_dir)
        .output()
        .unwrap_or_else(|e| panic!("linetrack report: {e}"));
    let text = String::from_utf8_lossy(&report.stdout);
    assert!(report.status.success(), "{text}");
    assert!(
        text.contains(&format!(
            "its supervisor (pid {}) is gone: the run was killed",
            status.supervisor_pid
        )),
        "{text}"
    );
    // A next run into the folder says whose records it replaces.
    let next = start(&dir, &base_sequence(FRAMES), &quick());
    let (exit, out, records) = next.finish(RUN_TIMEOUT);
    assert!(exit.success(), "{exit}\n{out}");
    let replaced = records.events_of("earlier-run-replaced");
    assert!(
        replaced.len() == 1
            && replaced[0].detail.contains(&format!(
                "its supervisor (pid {}) gone: it was killed",
                status.supervisor_pid
            )),
        "{:?}",
        records.events
    );
}

/// Stops `stage` (SIGSTOP) for a while shorter than the hang timeout, then resumes it.
fn stall(status: &linetrack_supervisor::LiveStatus, stage: &str, for_how_long: Duration) -> u32 {
    let pid = status
        .stages
        .iter()
        .find(|s| s.stage == stage)
        .unwrap_or_else(|| panic!("no {stage} in {:?}", status.stages))
        .pid;
    signal(pid, "STOP");
    std::thread::sleep(for_how_long);
    signal(pid, "CONT");
    pid
}

#[test]
fn a_stage_stalled_shorter_than_the_hang_timeout_catches_up_without_a_crash() {
    let dir = scratch("stall");
    // 1.5 s stops at 10 Hz: 15 frames queue up, more than a subscriber buffers or a stage
    // holds. The hang timeout (5 s) is well past the stop: no restart is due.
    let extra = quick().replace("hang_timeout_ms = 2000", "hang_timeout_ms = 5000");
    let mut run = start(&dir, &base_sequence(FRAMES), &extra);
    let status = run.wait_for("3 frames", RUN_TIMEOUT, |s| s.frames >= 3);
    let matcher = stall(&status, "matcher", Duration::from_millis(1500));
    let pose_estimator = stall(&status, "pose-estimator", Duration::from_millis(1500));
    let (exit, out, records) = run.finish(RUN_TIMEOUT);
    assert!(exit.success(), "{exit}\n{out}");
    assert_every_frame_accounted(&records);
    for kind in ["crash", "hang", "restart"] {
        assert!(
            records.events_of(kind).is_empty(),
            "{kind} after stalls of pids {matcher} and {pose_estimator}: {:?}",
            records.events
        );
    }
    // Frames overwritten in a full queue are drops with their reason, not `missing`.
    let missing: Vec<u64> = records
        .frames
        .iter()
        .filter(|f| f.outcome == "missing")
        .map(|f| f.frame_id)
        .collect();
    assert!(
        missing.is_empty(),
        "missing: {missing:?}\n{:?}",
        records.events
    );
    for f in records.frames.iter().filter(|f| f.outcome == "skipped") {
        assert!(
            records
                .events_of("skipped")
                .iter()
                .any(|e| e.stage == f.dropped_by),
            "frame {} dropped by {} without an event",
            f.frame_id,
            f.dropped_by
        );
    }
    // The stages went on after the stalls: the last frames have poses.
    let tail: Vec<&str> = records.frames[FRAMES - 3..]
        .iter()
        .map(|f| f.outcome.as_str())
        .collect();
    assert!(
        tail.iter().all(|o| *o == "pose" || *o == "lost"),
        "after the stalls: {tail:?}"
    );
    assert_eq!(
        records.leftovers,
        Default::default(),
        "iceoryx2 nodes or services left behind"
    );
}

#[test]
fn a_corrupt_frame_is_skipped_and_counted() {
    let dir = scratch("corrupt");
    let sequence = sequence_copy(FRAMES, &dir);
    let victim = &images(&sequence, 0)[12];
    std::fs::write(victim, b"\x89PNG\r\n\x1a\n this is not an image")
        .unwrap_or_else(|e| panic!("{e}"));
    let (status, out, records) = start_every_frame(&dir, &sequence, &quick()).finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_every_frame_accounted(&records);
    let frame = &records.frames[12];
    assert_eq!(
        (frame.outcome.as_str(), frame.dropped_by.as_str()),
        ("corrupt", "frame-source")
    );
    assert!(out.contains("dropped corrupt: 1"), "{out}");
    assert!(
        records.frames[13..]
            .iter()
            .filter(|f| f.outcome == "pose")
            .count()
            >= FRAMES - 13 - 2,
        "tracking did not go on"
    );
}

#[test]
fn a_run_that_tracks_nothing_exits_non_zero_saying_so() {
    let dir = scratch("nothing-tracked");
    let sequence = sequence_copy(FRAMES, &dir);
    for image in images(&sequence, 0) {
        std::fs::write(&image, b"\x89PNG\r\n\x1a\n this is not an image")
            .unwrap_or_else(|e| panic!("{e}"));
    }
    // How long the run is does not change its verdict: half the sequence is enough.
    let frames = FRAMES / 2;
    let run = start_with_args(
        &dir,
        &sequence,
        &quick(),
        &["--frames", &frames.to_string()],
    );
    let run_dir = run.run_dir.clone();
    let (status, out, records) = run.finish(RUN_TIMEOUT);
    assert!(!status.success(), "rc 0 with nothing tracked\n{out}");
    assert_ids_accounted(&records, frames as u64, &[]);
    assert!(records.frames.iter().all(|f| f.outcome == "corrupt"));
    let summary = linetrack_run_record::Summary::read(&run_dir.join("summary.json"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(summary.end, linetrack_run_record::RunEnd::Failed);
    let reason = summary.reason.unwrap_or_default();
    assert!(reason.contains("nothing was tracked"), "{reason}");
    assert_eq!(
        records.leftovers,
        Default::default(),
        "iceoryx2 nodes or services left behind"
    );
}

#[test]
fn a_hot_swap_to_fld_loses_and_duplicates_no_frame() {
    let dir = scratch("swap");
    // Every frame processed, however late: a loss could not hide as a policy drop.
    hot_swap(start_every_frame(&dir, &base_sequence(FRAMES), &quick()));
}

#[test]
fn a_hot_swap_of_the_matcher_loses_and_duplicates_no_frame_in_both_modes() {
    for threads in [false, true] {
        let dir = scratch(if threads { "mswap-threads" } else { "mswap" });
        // The light detector and matcher: a loaded machine keeps up at 10 Hz, so that a
        // frame lost would be the swap's. Not `--pacing fastest`: this light pipeline then
        // ran the 32 frames after the ask in less time than the standby took to start
        // (once in six suite runs under two CPU hogs: "the run finished before the swap").
        let mut args = vec!["--detector", "edgelines", "--matcher", "l1"];
        if threads {
            args.push("--single-process");
        }
        let mut run = start_with_args(&dir, &base_sequence(FRAMES), &quick(), &args);
        ctl_after_8_frames(&mut run, &["swap-matcher"]);
        let (status, out, records) = run.finish(RUN_TIMEOUT);
        assert!(status.success(), "{status}\n{out}");
        // Every frame recorded exactly once, each with a pose.
        assert_every_frame_accounted(&records);
        assert!(
            records.frames.iter().all(|f| f.has_pose()),
            "a frame without a pose (threads: {threads})"
        );
        let swaps = records.events_of("swap");
        assert_eq!(swaps.len(), 1, "{:?}", records.events);
        assert_eq!(swaps[0].stage, "matcher");
        let at = swaps[0]
            .frame_id
            .unwrap_or_else(|| panic!("swap without a frame"));
        assert!(at > 0 && at < FRAMES as u64, "swap at {at}");
        // The new matcher took over knowing the frame before: the hand-over frame is
        // tracked from it, as every frame after the first is.
        let handed = records
            .frames
            .iter()
            .find(|f| f.frame_id == at)
            .unwrap_or_else(|| panic!("no record of frame {at}"));
        assert!(
            handed.tracked_matches > 0,
            "frame {at}: no frame-to-frame match after the swap (threads: {threads})"
        );
    }
}

#[test]
fn single_process_mode_is_supervised_the_same_way() {
    // The same supervision core runs thread stages: `linetrack ctl` swaps the detector of
    // a `--single-process` run too, and its records are the same.
    let dir = scratch("threads");
    let mut run = start_with_args(
        &dir,
        &base_sequence(FRAMES),
        &quick(),
        &["--single-process", "--pacing", "fastest"],
    );
    let status = run.wait_for("four stages", RUN_TIMEOUT, |s| s.stages.len() == 4);
    assert!(
        status
            .stages
            .iter()
            .all(|s| s.pid >= linetrack_supervisor::THREAD_IDS && s.pid != status.supervisor_pid),
        "{:?}",
        status.stages
    );
    hot_swap(run);
}

#[test]
fn stages_start_through_the_stage_runner() {
    // LINETRACK_STAGE_RUNNER puts a command before each stage binary (qemu-aarch64-static
    // for aarch64 binaries on x86, see `cargo xtask cross`). Here the runner is a shell that
    // notes the binary and execs it: the stage keeps the pid the supervisor started.
    let dir = scratch("runner");
    let log = dir.join("runner.log");
    let runner = format!(
        "sh -c 'echo \"$0\" >> {}; exec \"$0\" \"$@\"'",
        log.display()
    );
    let run = start_through_runner(&dir, &base_sequence(FRAMES), &quick(), &runner);
    let (status, out, records) = run.finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_every_frame_accounted(&records);
    assert!(records.frames.iter().any(|f| f.has_pose()), "{out}");
    assert!(
        records.events_of("restart").is_empty(),
        "{:?}",
        records.events
    );
    let text = std::fs::read_to_string(&log).unwrap_or_else(|e| panic!("{}: {e}", log.display()));
    let mut started: Vec<String> = text
        .lines()
        .map(|l| {
            std::path::Path::new(l)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        })
        .collect();
    started.sort();
    assert_eq!(
        started,
        [
            "linetrack-frame-source",
            "linetrack-line-detector",
            "linetrack-matcher",
            "linetrack-pose-estimator"
        ],
        "each stage started once, through the runner"
    );
}

#[test]
fn an_unparsable_stage_runner_is_refused_naming_the_variable() {
    let dir = scratch("bad-runner");
    let config = dir.join("pipeline.toml");
    std::fs::write(&config, SUPERVISION).unwrap_or_else(|e| panic!("{e}"));
    let output = std::process::Command::new(bin_dir().join("linetrack"))
        .args(["run", "--quiet", "--frames", "2", "--config"])
        .arg(&config)
        .arg("--dataset")
        .arg(base_sequence(FRAMES))
        .arg("--run-dir")
        .arg(dir.join("run"))
        .env(
            linetrack_ipc::Scope::PREFIX_VAR,
            format!("lte2e{}_badrunner_", std::process::id()),
        )
        .env("LINETRACK_STAGE_RUNNER", "sh -c 'exec")
        .output()
        .unwrap_or_else(|e| panic!("starting linetrack: {e}"));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(
        stderr.contains("LINETRACK_STAGE_RUNNER") && stderr.contains("unbalanced quotes"),
        "the error names the variable and the fault:\n{stderr}"
    );
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

#[test]
fn lsd_missing_a_budget_no_detector_meets_gives_way_to_fld_after_its_streak() {
    let dir = scratch("detector-policy");
    // A 1 µs detector budget: every LSD frame misses it, so the policy swaps after exactly
    // `bad_frames` frames, whatever the machine's load; FLD never gets within a quarter of
    // it either, so it never swaps back.
    let config = format!(
        "{SUPERVISION}[budget]\ndrop_late = false\nline_detector_ms = 0.001\n\
         [detector_fallback]\nenabled = true\nbad_frames = 3\nmin_interval_frames = 0\nend_to_end = false\n"
    );
    let (status, out, records) =
        start_every_frame(&dir, &base_sequence(FRAMES), &config).finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_every_frame_accounted(&records);
    let fallbacks = records.events_of("detector-fallback");
    assert_eq!(fallbacks.len(), 1, "{:?}", records.events);
    assert!(
        fallbacks[0].detail.starts_with("lsd -> fld: lsd over its")
            && fallbacks[0].detail.contains("on 3 frames in a row"),
        "{}",
        fallbacks[0].detail
    );
    // It came on the third frame LSD detected.
    let lsd: Vec<u64> = records
        .frames
        .iter()
        .filter(|f| f.detector == "lsd")
        .map(|f| f.frame_id)
        .collect();
    assert_eq!(
        fallbacks[0].frame_id,
        lsd.get(2).copied(),
        "LSD frames {lsd:?}"
    );
    assert!(records.events_of("detector-recover").is_empty());
    // The hot swap carried it out: LSD before the hand-over frame, FLD from it to the end.
    let swaps = records.events_of("swap");
    assert_eq!(swaps.len(), 1, "{:?}", records.events);
    let at = swaps[0]
        .frame_id
        .unwrap_or_else(|| panic!("swap without a frame"));
    assert!(at < FRAMES as u64, "swap at {at}");
    for f in &records.frames {
        let expected = if f.frame_id < at { "lsd" } else { "fld" };
        assert_eq!(f.detector, expected, "frame {} (swap at {at})", f.frame_id);
    }
}

#[test]
fn both_policies_act_on_frames_that_miss_the_end_to_end_budget_alone() {
    let dir = scratch("end-to-end-policies");
    // Every frame misses a 1 µs end-to-end budget, whatever the machine's load, while LSD and
    // the matcher stay within budgets of a minute and LBD finds its one stereo match: only
    // the pipeline's deadline can move either policy.
    let config = format!(
        "{SUPERVISION}[budget]\ndrop_late = false\nend_to_end_ms = 0.001\nline_detector_ms = 60000.0\n\
         matcher_ms = 60000.0\n[matcher.fallback]\nmin_stereo_matches = 1\nrecover_stereo_matches = 2\n\
         min_inlier_ratio = 0.0\n[detector_fallback]\nenabled = true\nbad_frames = 3\n"
    );
    let (status, out, records) = start(&dir, &base_sequence(FRAMES), &config).finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_every_frame_accounted(&records);
    let fallbacks = records.events_of("fallback");
    assert!(
        fallbacks
            .first()
            .is_some_and(|e| e.detail.starts_with("lbd -> l1: end to end ")
                && e.detail.contains("> 0.0 ms with LBD taking")),
        "{:?}",
        records.events
    );
    let swaps = records.events_of("detector-fallback");
    assert!(
        swaps.first().is_some_and(|e| e
            .detail
            .starts_with("lsd -> fld: frames missed the 0.0 ms end-to-end budget while lsd ran")),
        "{:?}",
        records.events
    );
}

#[test]
fn matching_falls_back_to_l1_when_the_right_image_turns_unmatchable() {
    let dir = scratch("fallback");
    let sequence = sequence_copy(FRAMES, &dir);
    // From frame 10 the right camera sees inverted intensities: every edge keeps its place
    // (geometry) but flips its gradient, so appearance descriptors no longer match.
    for path in &images(&sequence, 1)[10..] {
        let mut image = image::open(path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .into_luma8();
        image::imageops::invert(&mut image);
        image
            .save(path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
    // This scene gives LBD ~80 stereo matches a frame; a few dozen chance matches survive
    // the inversion, so the test sets its bar between the two.
    // Only the matches decide here: a loaded test machine must not trigger the budget rules
    // (the matcher's own, the end-to-end one).
    let thresholds = "[matcher.fallback]\nmin_stereo_matches = 45\nrecover_stereo_matches = 60\nover_budget = false\nend_to_end = false\n";
    let (status, out, records) =
        start_every_frame(&dir, &sequence, &format!("{}{thresholds}", quick())).finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_every_frame_accounted(&records);
    let fallbacks = records.events_of("fallback");
    assert_eq!(fallbacks.len(), 1, "{:?}", records.events);
    let at = fallbacks[0]
        .frame_id
        .unwrap_or_else(|| panic!("fallback without a frame"));
    assert!((10..20).contains(&at), "fell back at frame {at}");
    assert!(
        fallbacks[0].detail.contains("lbd -> l1"),
        "{}",
        fallbacks[0].detail
    );
    assert!(
        records.frames[..10].iter().all(|f| f.matcher == "lbd"),
        "before the change"
    );
    // The switch reaches the matcher while the frames after `at` are on their way: the
    // matcher may be ahead of the pose by as many frames as the tracks' queue holds (more
    // under load). Within that it switches, and stays. (Under load a frame whose images
    // were released before its segments came is matched by geometry even in LBD mode.)
    let after: Vec<&str> = records.frames[at as usize + 1..]
        .iter()
        .map(|f| f.matcher.as_str())
        .collect();
    let switched = after.iter().rposition(|m| *m == "lbd").map_or(0, |k| k + 1);
    assert!(
        switched <= linetrack_msgs::Topic::Tracks.queue_depth() && switched < after.len(),
        "after the fallback at {at}: {after:?}"
    );
    assert!(
        records.events_of("recover").is_empty(),
        "LBD cannot recover on inverted images: {:?}",
        records.events
    );
}

#[test]
fn sigterm_stops_the_run_cleanly_and_a_killed_run_is_cleaned_up_by_the_next() {
    let dir = scratch("signals");
    let sequence = base_sequence(FRAMES);
    // A run killed outright (supervisor and stages) leaves its shared memory behind ...
    let mut killed = start(&dir, &sequence, &quick());
    let status = killed.wait_for("5 frames", RUN_TIMEOUT, |s| s.frames >= 5);
    // Frozen first, so that no process of the run sees another die (a stage would end
    // cleanly on its supervisor's death and tidy up), then all killed at once.
    let pids: Vec<String> = std::iter::once(status.supervisor_pid)
        .chain(status.stages.iter().map(|s| s.pid))
        .map(|pid| pid.to_string())
        .collect();
    for sig in ["-STOP", "-KILL"] {
        // A stage may already be on its way out: `kill` then fails for that pid only.
        let _ = std::process::Command::new("kill")
            .arg(sig)
            .args(&pids)
            .status();
    }
    let _ = killed.child.wait();
    // What the killed supervisor had recorded is on disk, and reports.
    let survived = Records::read(&killed.run_dir, &killed.prefix);
    assert!(
        survived.frames.len() >= 5,
        "{} frames recorded by the killed run",
        survived.frames.len()
    );
    report_of(&killed.run_dir);
    std::thread::sleep(Duration::from_millis(300));
    let left = linetrack_ipc::Scope::with_prefix(&killed.prefix, "")
        .resources()
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        left.nodes > 0,
        "a killed run should leave nodes behind: {left:?}"
    );
    // ... which the next run with the same prefix removes; SIGTERM then ends it cleanly.
    let mut next = start_with_prefix(
        &scratch("signals-next"),
        &sequence,
        &quick(),
        &killed.prefix,
    );
    let status = next.wait_for("3 frames", RUN_TIMEOUT, |s| s.frames >= 3);
    signal(status.supervisor_pid, "TERM");
    let (exit, out, records) = next.finish(RUN_TIMEOUT);
    assert!(exit.success(), "{exit}\n{out}");
    assert!(out.contains("(interrupted)"), "{out}");
    assert!(
        !records.events_of("stale-cleanup").is_empty(),
        "{:?}",
        records.events
    );
    assert!(!records.events_of("interrupted").is_empty());
    assert_eq!(
        records.leftovers,
        Default::default(),
        "resources left after SIGTERM"
    );
    for s in &status.stages {
        assert!(
            !std::path::Path::new(&format!("/proc/{}", s.pid)).exists()
                || proc_is_zombie_or_gone(s.pid),
            "stage {} (pid {}) still running",
            s.stage,
            s.pid
        );
    }
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

#[test]
fn the_restart_limit_ends_the_run_with_its_records_and_the_reason() {
    let dir = scratch("restart-limit");
    let extra = quick().replace("[supervisor]\n", "[supervisor]\nmax_restarts = 0\n");
    let mut run = start(&dir, &base_sequence(FRAMES), &extra);
    let status = run.wait_for("5 frames", RUN_TIMEOUT, |s| s.frames >= 5);
    let victim = status
        .stages
        .iter()
        .find(|s| s.stage == "matcher")
        .unwrap_or_else(|| panic!("no matcher in {:?}", status.stages))
        .pid;
    signal(victim, "KILL");
    let run_dir = run.run_dir.clone();
    let (exit, out, records) = run.finish(RUN_TIMEOUT);
    assert!(!exit.success(), "the run gave up but exited {exit}\n{out}");
    // Every frame the source published has a row, in order from 0, and the crash is an event.
    let recorded = ids(&records);
    assert!(recorded.len() >= 5, "{recorded:?}");
    assert_eq!(recorded, (0..recorded.len() as u64).collect::<Vec<_>>());
    assert!(
        records
            .events_of("crash")
            .iter()
            .any(|e| e.stage == "matcher"),
        "{:?}",
        records.events
    );
    let summary = linetrack_run_record::Summary::read(&run_dir.join("summary.json"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(summary.end, linetrack_run_record::RunEnd::Failed);
    let reason = summary.reason.unwrap_or_default();
    assert!(
        reason.contains("matcher") && reason.contains("restart limit 0"),
        "{reason}"
    );
    assert_eq!(summary.report.frames, recorded.len());
    let status: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(run_dir.join("status.json")).unwrap_or_default(),
    )
    .unwrap_or_default();
    assert_eq!(status["state"], "failed", "{status}");
    assert_eq!(status["stages"], serde_json::json!([]), "{status}");
    let report = report_of(&run_dir);
    assert!(
        report.contains(&format!("frames {}", recorded.len())),
        "{report}"
    );
    assert_eq!(
        records.leftovers,
        Default::default(),
        "iceoryx2 nodes or services left behind"
    );
}

#[test]
fn a_second_run_into_a_busy_run_folder_is_refused_naming_the_first() {
    let dir = scratch("locked");
    let mut first = start(&dir, &base_sequence(FRAMES), &quick());
    let status = first.wait_for("3 frames", RUN_TIMEOUT, |s| s.frames >= 3);
    // The same config, so the same run folder, from another shell.
    let second = std::process::Command::new(bin_dir().join("linetrack"))
        .args(["run", "--quiet", "--config"])
        .arg(dir.join("pipeline.toml"))
        .env(
            linetrack_ipc::Scope::PREFIX_VAR,
            format!("{}second_", first.prefix),
        )
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("starting the second run: {e}"));
    let err = String::from_utf8_lossy(&second.stderr);
    assert!(!second.status.success(), "the second run ran: {err}");
    assert!(
        err.contains("in use by another run")
            && err.contains(&format!("pid {}", status.supervisor_pid)),
        "{err}"
    );
    // The first run was not disturbed.
    let (exit, out, records) = first.finish(RUN_TIMEOUT);
    assert!(exit.success(), "{exit}\n{out}");
    assert_every_frame_accounted(&records);
}

fn proc_is_zombie_or_gone(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .map_or(true, |s| s.split_whitespace().nth(2) == Some("Z"))
}
