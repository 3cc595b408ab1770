//! Records that meet the file size limit (`RLIMIT_FSIZE`, `ulimit -f`). Once `frames.csv`
//! holds 10 rows, the `linetrack run` process's limit is set (`prlimit --pid`) to 3 KiB:
//! room for `summary.json`, not for every frame's row. The kernel would kill the process
//! with SIGXFSZ; it must instead see the write fail ("File too large"), end with an error
//! naming the file, exit as an error (not by a signal), and leave a folder that
//! `linetrack report` reads. The limit is set on the running process and not at its start
//! because the shared memory every process sizes is subject to it too: a limit small
//! enough for the records to meet it would refuse the shared memory first.

use linetrack_e2e::*;
use linetrack_run_record::{RunEnd, Summary, read_frames};
use std::os::unix::process::ExitStatusExt as _;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const FRAMES: usize = 40;
/// Lines (header included) `frames.csv` holds before the limit is set.
const ROWS_BEFORE_LIMIT: usize = 11;
/// The limit in bytes: over `frames.csv` with 10 rows (about 1 KiB) and `summary.json`
/// (under 2 KiB), under `frames.csv` with 40 rows (about 4 KiB).
const LIMIT: usize = 3072;
const RUN_TIMEOUT: Duration = Duration::from_secs(120);
const CONFIG: &str =
    "[supervisor]\nstatus_every_ms = 0\ndrain_timeout_ms = 30000\n[budget]\ndrop_late = false\n";

#[test]
fn records_over_the_file_size_limit_end_the_run_with_an_error_not_a_signal() {
    let dir = scratch("file-size-limit");
    let (config, run_dir) = write_config(&dir, &base_sequence(FRAMES), CONFIG);
    let prefix = format!("lte2e{}_fsize_", std::process::id());
    let mut child = Command::new(bin_dir().join("linetrack"))
        .args(["run", "--quiet", "--config"])
        .arg(&config)
        .env(linetrack_ipc::Scope::PREFIX_VAR, &prefix)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        // A pipe: a file would be under the limit too.
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("starting linetrack: {e}"));
    let mut pipe = child.stderr.take().unwrap_or_else(|| panic!("no stderr"));
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = std::io::Read::read_to_string(&mut pipe, &mut text);
        text
    });

    let frames_csv = run_dir.join("frames.csv");
    let deadline = Instant::now() + RUN_TIMEOUT;
    loop {
        let text = std::fs::read_to_string(&frames_csv).unwrap_or_default();
        if text.lines().count() >= ROWS_BEFORE_LIMIT {
            assert!(text.len() < LIMIT, "{} bytes already", text.len());
            break;
        }
        if let Ok(Some(status)) = child.try_wait() {
            panic!("the run ended ({status}) before frames.csv had {ROWS_BEFORE_LIMIT} lines");
        }
        assert!(Instant::now() < deadline, "frames.csv never filled");
        std::thread::sleep(Duration::from_millis(50));
    }
    let set = Command::new("prlimit")
        .arg("--pid")
        .arg(child.id().to_string())
        .arg(format!("--fsize={LIMIT}"))
        .status()
        .unwrap_or_else(|e| panic!("prlimit: {e}"));
    assert!(set.success(), "prlimit failed: {set}");

    let status = loop {
        if let Ok(Some(status)) = child.try_wait() {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("the run did not end within {RUN_TIMEOUT:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let stderr = reader.join().unwrap_or_default();
    let mut stdout = String::new();
    if let Some(mut out) = child.stdout.take() {
        let _ = std::io::Read::read_to_string(&mut out, &mut stdout);
    }
    assert_eq!(
        status.signal(),
        None,
        "the run was killed by a signal:\n{stderr}"
    );
    assert_eq!(status.code(), Some(1), "not a clean error:\n{stderr}");
    // Whichever record reached the limit first (frames.csv or events.csv) is named.
    let named = stderr.lines().any(|line| {
        line.contains("File too large") && line.contains(&run_dir.display().to_string())
    });
    assert!(
        named,
        "no error naming the file and the OS error:\n{stderr}"
    );

    let summary = Summary::read(&run_dir.join("summary.json")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(summary.end, RunEnd::RecordsFailed);
    let reason = summary.reason.clone().unwrap_or_default();
    assert!(reason.contains("File too large"), "{reason}");
    // frames.csv ends at its last whole row.
    let frames = read_frames(&frames_csv).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        frames.len() >= ROWS_BEFORE_LIMIT - 1,
        "{} rows",
        frames.len()
    );
    assert!(frames.len() < FRAMES, "every frame recorded: no limit met");
    // The run still prints its report; the pictures it could not write are named, not
    // left cut short.
    assert!(
        stdout.contains("run ended records-failed"),
        "{stdout}\n{stderr}"
    );
    assert!(stdout.contains("no latency pictures"), "{stdout}");
    assert!(
        !run_dir.join("latency.png").exists(),
        "a cut latency.png left"
    );
    let live: linetrack_supervisor::LiveStatus = serde_json::from_str(
        &std::fs::read_to_string(run_dir.join("status.json")).unwrap_or_default(),
    )
    .unwrap_or_else(|e| panic!("status.json: {e}"));
    assert_eq!(live.state, RunEnd::RecordsFailed);

    assert_reports_a_cut_run(&run_dir, frames.len());
}
