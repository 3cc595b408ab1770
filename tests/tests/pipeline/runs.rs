//! A run's life: single-process mode, the stage runner, a corrupt frame, a run that tracks
//! nothing, SIGTERM and a killed run cleaned up by the next, a busy run folder.

use super::*;

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

#[test]
fn l1_lines_only_at_road_speed_tracks_every_frame_as_the_odometry_does() {
    // KITTI raw moves ~1.3 m a frame: around their old positions the ℓ1 matcher finds the
    // segments that move least, and lines only lost frames 1 and 2 of the drive. The
    // pose estimator matches ℓ1 frames again where the motion predicts the last frame's
    // segments, as `linetrack-vo`'s own front end does, and every frame is tracked.
    let dir = scratch("l1-road");
    let drive = linetrack_test_data::kitti_raw_dir().unwrap_or_else(|e| panic!("{e}"));
    let extra = format!("{}[odometry]\nfeatures = \"lines-only\"\n", quick());
    let args = ["--pacing", "fastest", "--matcher", "l1", "--frames", "12"];
    let (status, out, records) = start_with_args(&dir, &drive, &extra, &args).finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_ids_accounted(&records, 12, &[]);
    let outcomes: Vec<&str> = records.frames.iter().map(|f| f.outcome.as_str()).collect();
    assert!(outcomes.iter().all(|o| *o == "pose"), "{outcomes:?}");
    assert!(records.frames.iter().all(|f| f.matcher == "l1"));
}

#[test]
fn with_auto_a_frame_lbd_would_lose_is_tracked_with_l1_and_counted() {
    // Lines only with LBD, the paper's gain jumps (seed 3): the matcher stage matches
    // around the segments' old positions, and frame 54's matches lose it (measured: the
    // only frame lost in the drive's 108). With `rescue_lost_frames` the pose estimator
    // matches it again with ℓ1 where the motion puts the last frame's segments, tracks it,
    // and the run counts an `l1-rescue`. Nothing depends on time: every frame is processed
    // (`drop_late = false`), and neither fallback acts on latency.
    let drive = linetrack_test_data::kitti_raw_dir().unwrap_or_else(|e| panic!("{e}"));
    let run = |rescue: bool| {
        let dir = scratch(&format!("lbd-rescue-{rescue}"));
        let extra = format!(
            "{}[odometry]\nfeatures = \"lines-only\"\n[detector_fallback]\nenabled = false\n\
             [matcher.fallback]\nover_budget = false\nend_to_end = false\nrescue_lost_frames = {rescue}\n",
            quick()
        );
        let args = [
            "--pacing",
            "fastest",
            "--matcher",
            "auto",
            "--detector",
            "lsd",
            "--gain-jumps",
            "0.5",
            "--gain-jumps-seed",
            "3",
            "--frames",
            "56",
        ];
        let (status, out, records) =
            start_with_args(&dir, &drive, &extra, &args).finish(RUN_TIMEOUT);
        assert!(status.success(), "{status}\n{out}");
        assert_ids_accounted(&records, 56, &[]);
        assert!(records.frames.iter().all(|f| f.matcher == "lbd"));
        let lost: Vec<u64> = (records.frames.iter())
            .filter(|f| f.outcome == "lost")
            .map(|f| f.frame_id)
            .collect();
        // A lost frame says why in frames.csv.
        for f in records.frames.iter().filter(|f| f.outcome == "lost") {
            assert_eq!(f.lost_reason, "too-few-inliers", "frame {}", f.frame_id);
        }
        let rescued: Vec<Option<u64>> = (records.events_of("l1-rescue").iter())
            .map(|e| e.frame_id)
            .collect();
        (lost, rescued)
    };
    assert_eq!(run(false), (vec![54], vec![]), "(lost, rescued) without");
    assert_eq!(run(true), (vec![], vec![Some(54)]), "(lost, rescued) with");
}

#[test]
fn a_rig_whose_disparities_read_a_pixel_short_is_self_calibrated_and_reported() {
    // The KITTI raw drive with its right images moved one pixel to the right: every
    // disparity one pixel short, every step ~9 % long. The pose estimator estimates the
    // offset from the frames (`[odometry.disparity_offset]`, the default) and subtracts it
    // once it is sure (measured on the whole drive: from frame 3, −0.98 px at the end); each
    // frame's offset is in frames.csv and the last one in the report.
    let dir = scratch("disparity-offset");
    let drive = linetrack_test_data::kitti_raw_with_right_images_moved(&dir.join("drive"), 1.0)
        .unwrap_or_else(|e| panic!("{e}"));
    // Nothing depends on time: every frame is processed and no fallback acts on latency.
    let extra = format!(
        "{}[detector_fallback]\nenabled = false\n[matcher.fallback]\nover_budget = false\nend_to_end = false\n",
        quick()
    );
    let args = ["--pacing", "fastest", "--frames", "30"];
    let (status, out, records) = start_with_args(&dir, &drive, &extra, &args).finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_ids_accounted(&records, 30, &[]);
    let offsets: Vec<f64> = records
        .frames
        .iter()
        .map(|f| f.disparity_offset_px)
        .collect();
    assert_eq!(offsets[0], 0.0, "{offsets:?}");
    let last = offsets[29];
    assert!((-1.2..=-0.75).contains(&last), "{offsets:?}");
    assert!(out.contains("disparity offset -"), "{out}");
}
