//! Records that survive a full disk. The run folder is a small tmpfs (mounted in a user and
//! mount namespace of its own, `unshare --user --map-root-user --mount`), filled to the last
//! byte by a `cat /dev/zero` once `frames.csv` holds 10 rows: the run must stop with an
//! error naming the file and the OS error, leave every record file ending at a whole row,
//! say `records-failed` in `status.json` and `summary.json`, leave no temporary file and no
//! invalid trace, and `linetrack report` on the folder must print what was recorded and
//! which frames were not.

use linetrack_e2e::*;
use linetrack_run_record::{RunEnd, Summary, read_events, read_frames};
use linetrack_test_data::Scratch;
use std::path::Path;
use std::process::{Command, Stdio};

const FRAMES: usize = 40;
/// Rows (header included) `frames.csv` holds before the disk is filled.
const ROWS_BEFORE_FULL: usize = 11;
/// Every frame processed however late: what fills the disk is the only fault.
const CONFIG: &str =
    "[supervisor]\nstatus_every_ms = 0\ndrain_timeout_ms = 30000\n[budget]\ndrop_late = false\n";

/// Mounts a 2 MiB tmpfs on `$1`, runs `$2 run` with config `$3` in the background, fills
/// the tmpfs once `$1/run/frames.csv` has `$5` lines, waits for the run, and copies its
/// folder to `$4/run` (the report is read outside, where there is room for its pictures).
const SCRIPT: &str = r#"
set -u
disk="$1"; bin="$2"; config="$3"; out="$4"; rows="$5"
mount -t tmpfs -o size=2m,mode=0700 tmpfs "$disk" || exit 90
"$bin" run --quiet --config "$config" > "$out/stdout" 2> "$out/stderr" &
run=$!
while [ "$(cat "$disk/run/frames.csv" 2>/dev/null | wc -l)" -lt "$rows" ]; do
    kill -0 "$run" 2>/dev/null || break
    sleep 0.05
done
cat /dev/zero > "$disk/filler" 2> "$out/filler.err"
wait "$run"; echo $? > "$out/exit"
rm -f "$disk/filler"
cp -a "$disk/run" "$out/run"
"#;

#[test]
fn a_run_whose_disk_fills_stops_naming_the_file_and_its_records_stay_readable() {
    let summary = run_on_a_disk_that_fills("full-disk-stop", "stop");
    assert!(
        summary.report.frames < FRAMES,
        "the pipeline ran on to the end: {} frames",
        summary.report.frames
    );
}

#[test]
fn with_continue_the_pipeline_runs_on_without_records_and_still_ends_records_failed() {
    let summary = run_on_a_disk_that_fills("full-disk-continue", "continue");
    assert_eq!(summary.report.frames, FRAMES, "every frame had an outcome");
    assert!(summary.report.poses > 0);
}

/// A run with `output.on_record_error = policy` whose disk fills after 10 rows: checks
/// what both policies share and returns its summary.
fn run_on_a_disk_that_fills(name: &str, policy: &str) -> Summary {
    let dir = scratch(name);
    let sequence = base_sequence(FRAMES);
    let disk = dir.join("disk");
    let out = dir.join("out");
    for d in [&disk, &out] {
        std::fs::create_dir_all(d).unwrap_or_else(|e| panic!("{e}"));
    }
    let run_dir = disk.join("run");
    let config = write_config_for(&dir, &sequence, CONFIG, &run_dir);
    // `[output]` is the config's last table.
    let mut text = std::fs::read_to_string(&config).unwrap_or_default();
    text.push_str(&format!("on_record_error = {policy:?}\n"));
    std::fs::write(&config, text).unwrap_or_else(|e| panic!("{e}"));
    let prefix = format!("lte2e{}_{}_", std::process::id(), name.replace('-', ""));
    // Short enough for iceoryx2's socket paths; the run's processes are all waited for
    // (`status()` below) before the guard drops.
    let ipc_root = Scratch::new("e2e", "ipc");
    let status = Command::new("unshare")
        .args([
            "--user",
            "--map-root-user",
            "--mount",
            "sh",
            "-c",
            SCRIPT,
            "sh",
        ])
        .arg(&disk)
        .arg(bin_dir().join("linetrack"))
        .arg(&config)
        .arg(&out)
        .arg(ROWS_BEFORE_FULL.to_string())
        .env(linetrack_ipc::Scope::PREFIX_VAR, &prefix)
        .env(linetrack_ipc::Scope::ROOT_VAR, &ipc_root)
        .stdin(Stdio::null())
        .status()
        .unwrap_or_else(|e| panic!("unshare: {e}"));
    assert!(
        status.code() != Some(90),
        "no tmpfs in a user and mount namespace here (unshare --user --map-root-user --mount)"
    );
    assert!(status.success(), "the script failed: {status}");
    let read = |name: &str| std::fs::read_to_string(out.join(name)).unwrap_or_default();
    let stderr = read("stderr");
    assert_ne!(
        read("exit").trim(),
        "0",
        "the run said it succeeded:\n{stderr}"
    );
    assert!(
        read("filler.err").contains("No space left on device"),
        "the disk was not filled: {}",
        read("filler.err")
    );
    // The error names a file of the run folder and the OS error.
    let named = stderr.lines().any(|line| {
        line.contains("No space left on device") && line.contains(&run_dir.display().to_string())
    });
    assert!(
        named,
        "no error naming the file and the OS error:\n{stderr}"
    );

    let copy = out.join("run");
    let summary = Summary::read(&copy.join("summary.json")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(summary.end, RunEnd::RecordsFailed);
    let reason = summary.reason.clone().unwrap_or_default();
    assert!(reason.contains("No space left on device"), "{reason}");
    let live: linetrack_supervisor::LiveStatus = serde_json::from_str(
        &std::fs::read_to_string(copy.join("status.json")).unwrap_or_default(),
    )
    .unwrap_or_else(|e| panic!("status.json: {e}"));
    assert_eq!(live.state, RunEnd::RecordsFailed);
    // Every record file ends at a whole row: read strictly, nothing cut.
    let frames = read_frames(&copy.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
    read_events(&copy.join("events.csv")).unwrap_or_else(|e| panic!("{e}"));
    linetrack_trajectory_check(&copy.join("poses.tum"));
    assert!(
        frames.len() >= ROWS_BEFORE_FULL - 1,
        "{} frames recorded",
        frames.len()
    );
    assert!(
        frames.len() < FRAMES,
        "every frame recorded: the disk never filled"
    );
    assert!(
        stderr.contains(&format!("output.on_record_error = \"{policy}\"")),
        "{stderr}"
    );
    let mut ids: Vec<u64> = frames.iter().map(|f| f.frame_id).collect();
    ids.dedup();
    assert_eq!(ids.len(), frames.len(), "a frame recorded twice");
    // No temporary file, no reserve, no invalid trace left.
    for entry in std::fs::read_dir(&copy).into_iter().flatten().flatten() {
        let name = entry.file_name().to_string_lossy().to_string();
        assert!(
            !name.ends_with(".tmp") && name != ".space-reserve",
            "{name} left in the run folder"
        );
    }
    if let Ok(trace) = std::fs::read_to_string(copy.join("trace.json")) {
        serde_json::from_str::<serde_json::Value>(&trace)
            .unwrap_or_else(|e| panic!("trace.json is not valid JSON: {e}"));
    }

    // The report reads the folder and says which frames were not recorded.
    let text = assert_reports_a_cut_run(&copy, frames.len());
    let expected = summary.report.frames as u64;
    let missing = linetrack_run_record::unrecorded(&frames, expected);
    let missing_count: u64 = missing.iter().map(|r| r.end - r.start).sum();
    // Exactly the frames the run counted and did not record are listed (none when it
    // stopped with every counted frame written: a stop can fall between frames).
    let listed = text.contains(&format!(
        "{missing_count} of {expected} frames have no row in frames.csv"
    ));
    assert_eq!(
        listed,
        missing_count > 0,
        "{missing_count} unrecorded:\n{text}"
    );
    if policy == "continue" {
        assert!(missing_count > 0, "the frames after the failure: {text}");
    }
    let scope = linetrack_ipc::Scope::with_prefix(&prefix, "").with_root(ipc_root.to_path_buf());
    let leftovers = scope.resources().unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(leftovers, linetrack_ipc::Resources::default());
    summary
}

/// Every line of `poses.tum` after its header is a whole pose.
fn linetrack_trajectory_check(path: &Path) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        text.is_empty() || text.ends_with('\n'),
        "poses.tum ends in a cut line"
    );
    for (k, line) in text.lines().enumerate().skip(1) {
        assert_eq!(
            line.split_whitespace()
                .filter(|w| w.parse::<f64>().is_ok())
                .count(),
            8,
            "poses.tum:{}: {line:?}",
            k + 1
        );
    }
}
