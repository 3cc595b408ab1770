//! A stage that dies while it is being restarted. The matcher starts through a stage runner
//! (`LINETRACK_STAGE_RUNNER`) that runs it normally the first time and, every time after,
//! writes an error on stderr and kills itself (SIGKILL) before the stage is ready: the crash
//! loop that used to end the run at restart 1 of 5. After a `kill -9` of the running
//! matcher, every one of `max_restarts` restarts is used, each death is recorded with the
//! stage's last words on stderr, and the run then fails saying so.

use linetrack_e2e::*;
use std::time::Duration;

const FRAMES: usize = 40;
const RUN_TIMEOUT: Duration = Duration::from_secs(120);
const MAX_RESTARTS: usize = 3;
/// What the matcher says before it dies on each restart.
const LAST_WORDS: &str = "the camera bus is gone";

#[test]
fn a_crash_loop_before_ready_uses_every_restart_and_shows_the_stages_last_words() {
    let dir = scratch("crash-loop");
    let starts = dir.join("matcher-starts");
    let runner = format!(
        "sh -c 'case \"$0\" in *linetrack-matcher) n=$(cat {starts} 2>/dev/null || echo 0); echo $((n + 1)) > {starts}; if [ \"$n\" -ge 1 ]; then echo \"matcher: {LAST_WORDS} (start $((n + 1)))\" >&2; kill -9 $$; fi;; esac; exec \"$0\" \"$@\"'",
        starts = starts.display()
    );
    let config = format!(
        "[supervisor]\nrestart_backoff_ms = 100\nrestart_backoff_max_ms = 400\nmax_restarts = {MAX_RESTARTS}\nhang_timeout_ms = 2000\ndrain_timeout_ms = 30000\nstatus_every_ms = 0\n[budget]\ndrop_late = false\n"
    );
    let mut run = start_through_runner(&dir, &base_sequence(FRAMES), &config, &runner);
    let status = run.wait_for("5 frames", RUN_TIMEOUT, |s| s.frames >= 5);
    let victim = stage_pid(&status, "matcher");
    signal(victim, "KILL");
    let run_dir = run.run_dir.clone();
    let (exit, out, records) = run.finish(RUN_TIMEOUT);
    assert!(
        !exit.success(),
        "the run survived a matcher that cannot start\n{out}"
    );

    let restarts: Vec<&str> = records
        .events_of("restart")
        .iter()
        .filter(|e| e.stage == "matcher")
        .map(|e| e.detail.as_str())
        .collect();
    let expected: Vec<String> = (1..=MAX_RESTARTS)
        .map(|k| format!("restart {k} of {MAX_RESTARTS}"))
        .collect();
    assert_eq!(restarts, expected, "{:?}", records.events);
    let crashes: Vec<&str> = records
        .events_of("crash")
        .iter()
        .filter(|e| e.stage == "matcher")
        .map(|e| e.detail.as_str())
        .collect();
    assert_eq!(crashes.len(), MAX_RESTARTS + 1, "{crashes:?}");
    assert!(
        crashes[0].contains(&format!("pid {victim} ")),
        "{crashes:?}"
    );
    for (k, crash) in crashes.iter().enumerate().skip(1) {
        assert!(
            crash.contains("before it was ready")
                && crash.contains(&format!("{LAST_WORDS} (start {})", k + 1)),
            "restart {k}: {crash}"
        );
    }
    let summary = linetrack_run_record::Summary::read(&run_dir.join("summary.json"))
        .unwrap_or_else(|e| panic!("{e}"));
    let reason = summary.reason.unwrap_or_default();
    assert!(
        reason.contains(&format!(
            "matcher died {} times (restart limit {MAX_RESTARTS})",
            MAX_RESTARTS + 1
        )) && reason.contains(&format!("{LAST_WORDS} (start {})", MAX_RESTARTS + 1)),
        "{reason}"
    );
    // A failed run still prints its report, saying how it ended.
    assert!(
        out.contains("\nframes ") && out.contains("run ended failed: matcher died"),
        "{out}"
    );
    let started = std::fs::read_to_string(&starts).unwrap_or_default();
    assert_eq!(started.trim(), (MAX_RESTARTS + 1).to_string());
}
