//! Stages killed, hung or stalled mid-run: restarted (or caught up), every frame accounted
//! for, and the restart limit ending the run with its records.

use super::*;

fn kill_and_recover(stage: &str) {
    let dir = scratch(&format!("kill-{stage}"));
    // The source waits for the pipeline: the frames lost with the victim are the few in
    // flight, not a loaded machine's backlog (at 10 Hz, two CPU hogs and LSD: 23 of 40).
    let mut run = start_every_frame(&dir, &base_sequence(FRAMES), &quick());
    let status = run.wait_for("10 frames", RUN_TIMEOUT, |s| s.frames >= 10);
    let victim = stage_pid(&status, stage);
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
    let victim = stage_pid(&status, "pose-estimator");
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
    let pid = stage_pid(status, stage);
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
fn the_restart_limit_ends_the_run_with_its_records_and_the_reason() {
    let dir = scratch("restart-limit");
    let extra = quick().replace("[supervisor]\n", "[supervisor]\nmax_restarts = 0\n");
    let mut run = start(&dir, &base_sequence(FRAMES), &extra);
    let status = run.wait_for("5 frames", RUN_TIMEOUT, |s| s.frames >= 5);
    let victim = stage_pid(&status, "matcher");
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
