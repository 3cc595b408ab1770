//! MCAP recording (`[record] mcap = true`, the `linetrack-recorder` process) and replay
//! (`linetrack replay`), end to end with the real processes: the file is checked by an
//! independent reader (PyPI `mcap` + `mcap-protobuf-support`, `tests/scripts/check_mcap.py`,
//! installed by `cargo xtask setup|test`), and replaying it gives the run's poses again.
//!
//! They need the binaries built with the `mcap` feature (`cargo xtask test-features` does it).

use linetrack_e2e::{Records, base_sequence, bin_dir, scratch, signal, start_with_args};
use linetrack_ipc::Scope;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

const RUN_TIMEOUT: Duration = Duration::from_secs(240);

/// Runs whose poses are compared: nothing may depend on time (as `configs/emulation.toml`):
/// every frame processed however late, the matcher switched on match counts only (not on
/// its latency nor on the frame's end to end), the detector never swapped for its time
/// (LSD at 70 ms a frame on a loaded CI machine gave way to edgelines at frame 4 of the
/// recorded run and not in its replay), and at fastest pacing at most 11 frames (what a
/// stage holds), so both runs process every frame.
const DETERMINISTIC: &str = "[budget]\ndrop_late = false\n[matcher.fallback]\nover_budget = false\nend_to_end = false\n[detector_fallback]\nenabled = false\n[record]\nmcap = true\n";
const COMPARED_FRAMES: usize = 10;

/// The recorder's binary, built with the `mcap` feature.
fn recorder_built() {
    let bin = bin_dir().join("linetrack-recorder");
    assert!(
        bin.is_file(),
        "{} is missing: build with --features linetrack/mcap (`cargo xtask test-features` does it)",
        bin.display()
    );
}

/// The checker's Python (`$LINETRACK_MCAP_PYTHON`, else `target/mcap-check`).
fn checker_python() -> PathBuf {
    linetrack_e2e::peer_python("LINETRACK_MCAP_PYTHON", "mcap-check", "the MCAP checker")
}

/// What the independent checker read.
struct Checked {
    json: serde_json::Value,
}

impl Checked {
    fn count(&self, topic: &str) -> u64 {
        self.json["channels"][topic]["count"].as_u64().unwrap_or(0)
    }
    fn schema(&self, topic: &str) -> String {
        self.json["channels"][topic]["schema"]
            .as_str()
            .unwrap_or("none")
            .to_string()
    }
    fn sequences(&self, topic: &str) -> Vec<u64> {
        self.json["sequences"][topic]
            .as_array()
            .map(|a| a.iter().filter_map(|v| v.as_u64()).collect())
            .unwrap_or_default()
    }
}

fn check(file: &Path) -> Checked {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/check_mcap.py");
    let out = Command::new(checker_python())
        .arg(script)
        .arg(file)
        .output()
        .unwrap_or_else(|e| panic!("running the checker: {e}"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "the checker refused {}: {stderr}",
        file.display()
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("checker output: {e}: {stderr}"));
    Checked { json }
}

/// The checks every recording of a run with every frame's images passes: closed with its
/// summary, every message decoded, the Foxglove schemas on their channels, one pair of
/// images per frame id 0..n, and as many poses and latency records as `frames.csv` says.
fn assert_recording_matches(checked: &Checked, records: &Records, n: u64) {
    let json = &checked.json;
    assert_eq!(json["summary"], true, "no summary: the file was not closed");
    assert_eq!(
        json["errors"],
        serde_json::json!([]),
        "undecodable messages"
    );
    let schemas = [
        ("/cam0/image", "foxglove.RawImage"),
        ("/cam1/image", "foxglove.RawImage"),
        ("/cam0/calibration", "foxglove.CameraCalibration"),
        ("/cam1/calibration", "foxglove.CameraCalibration"),
        ("/cam0/segments", "foxglove.ImageAnnotations"),
        ("/cam1/segments", "foxglove.ImageAnnotations"),
        ("/cam0/matches", "foxglove.ImageAnnotations"),
        ("/cam1/matches", "foxglove.ImageAnnotations"),
        ("/pose", "foxglove.PoseInFrame"),
        ("/latency", "linetrack.FrameLatency"),
        ("/events", "linetrack.StageEvent"),
    ];
    for (topic, schema) in schemas {
        assert_eq!(checked.schema(topic), schema, "{topic}: {json}");
    }
    let ids: Vec<u64> = (0..n).collect();
    assert_eq!(checked.sequences("/cam0/image"), ids);
    assert_eq!(checked.sequences("/cam1/image"), ids);
    assert_eq!(checked.count("/cam0/calibration"), 1);
    let with_pose = records.frames.iter().filter(|f| f.has_pose()).count() as u64;
    assert!(with_pose > 0);
    assert_eq!(
        checked.count("/pose"),
        with_pose,
        "poses against frames.csv"
    );
    assert_eq!(
        checked.count("/latency"),
        records.frames.len() as u64,
        "one latency record per frame of frames.csv"
    );
    let processed = records
        .frames
        .iter()
        .filter(|f| f.outcome == "pose" || f.outcome == "lost")
        .count() as u64;
    assert_eq!(checked.count("/cam0/segments"), processed);
    assert_eq!(checked.count("/cam0/matches"), processed);
    assert_eq!(
        json["metadata"]["linetrack.recorder"]["frames_missed"], "0",
        "the recorder kept up"
    );
}

/// `poses.tum` of a run: timestamp → tx ty tz qx qy qz qw.
fn poses(run_dir: &Path) -> BTreeMap<String, Vec<f64>> {
    let text = std::fs::read_to_string(run_dir.join("poses.tum"))
        .unwrap_or_else(|e| panic!("{}: {e}", run_dir.display()));
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let mut words = l.split_whitespace();
            let stamp = words.next().unwrap_or_default().to_string();
            let values = words
                .map(|w| w.parse().unwrap_or_else(|e| panic!("{l}: {e}")))
                .collect();
            (stamp, values)
        })
        .collect()
}

/// Runs `linetrack replay FILE` with `config`'s settings into `run_dir`.
fn replay(
    file: &Path,
    config: &Path,
    run_dir: &Path,
    prefix: &str,
    frames: Option<usize>,
) -> std::process::Output {
    let mut command = Command::new(bin_dir().join("linetrack"));
    command
        .arg("replay")
        .arg(file)
        .args(["--quiet", "--pacing", "fastest", "--config"])
        .arg(config)
        .arg("--run-dir")
        .arg(run_dir)
        .env(Scope::PREFIX_VAR, prefix)
        .stdin(Stdio::null());
    if let Some(n) = frames {
        command.args(["--frames", &n.to_string()]);
    }
    command
        .output()
        .unwrap_or_else(|e| panic!("starting linetrack replay: {e}"))
}

/// Records `frames` of `sequence`, checks the file, replays it and compares the poses;
/// returns the recording.
fn record_check_and_replay(name: &str, sequence: &Path) -> PathBuf {
    recorder_built();
    let dir = scratch(name);
    let frames = COMPARED_FRAMES.to_string();
    let run = start_with_args(
        &dir,
        sequence,
        DETERMINISTIC,
        &["--pacing", "fastest", "--frames", &frames],
    );
    let run_dir = run.run_dir.clone();
    let (status, out, records) = run.finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    linetrack_e2e::assert_ids_accounted(&records, COMPARED_FRAMES as u64, &[]);
    let file = run_dir.join("recording.mcap");
    let checked = check(&file);
    assert_recording_matches(&checked, &records, COMPARED_FRAMES as u64);

    let replay_dir = dir.join("replay");
    let prefix = format!(
        "lte2e{}_{}replay_",
        std::process::id(),
        name.replace('-', "")
    );
    let out = replay(
        &file,
        &dir.join("pipeline.toml"),
        &replay_dir,
        &prefix,
        None,
    );
    assert!(
        out.status.success(),
        "replay failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let replayed = Records::read(&replay_dir, &prefix);
    linetrack_e2e::assert_ids_accounted(&replayed, COMPARED_FRAMES as u64, &[]);
    assert_eq!(replayed.leftovers, Default::default(), "shared memory left");
    let (original, again) = (poses(&run_dir), poses(&replay_dir));
    assert_eq!(
        original.keys().collect::<Vec<_>>(),
        again.keys().collect::<Vec<_>>(),
        "the same frames got poses"
    );
    let max_difference = original
        .iter()
        .flat_map(|(stamp, a)| a.iter().zip(&again[stamp]).map(|(x, y)| (x - y).abs()))
        .fold(0.0f64, f64::max);
    eprintln!(
        "{name}: {} poses replayed, largest difference of a poses.tum value {max_difference:e}",
        original.len()
    );
    // poses.tum is written to 1 µm and 1e-6 per quaternion component: a replay that took
    // any other decision (another inlier set, another matcher mode) would differ by more.
    assert!(
        max_difference <= 1e-6,
        "replayed poses differ by {max_difference}"
    );
    // The replay recorded itself too (the same config): the same frames.
    let rechecked = check(&replay_dir.join("recording.mcap"));
    assert_recording_matches(&rechecked, &replayed, COMPARED_FRAMES as u64);
    file
}

#[test]
fn a_recorded_run_passes_the_independent_checker_and_its_replay_gives_the_same_poses() {
    let file = record_check_and_replay("record-generated", &base_sequence(40));

    // A recording cut short (a crashed recorder, a copy cut off) is refused naming the
    // file, before any stage starts.
    let dir = scratch("record-broken");
    let bytes = std::fs::read(&file).unwrap_or_else(|e| panic!("{e}"));
    let truncated = dir.join("truncated.mcap");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap_or_else(|e| panic!("{e}"));
    let garbage = dir.join("garbage.mcap");
    std::fs::write(&garbage, b"not a recording at all").unwrap_or_else(|e| panic!("{e}"));
    let config = dir.join("pipeline.toml");
    std::fs::write(&config, "").unwrap_or_else(|e| panic!("{e}"));
    for (file, says) in [
        (&truncated, "truncated or not closed"),
        (&garbage, "not an MCAP file"),
        (&dir.join("absent.mcap"), "No such file"),
    ] {
        let run_dir = dir.join(format!("run-{}", file.display().to_string().len()));
        let out = replay(file, &config, &run_dir, "lte2e_broken_", None);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{} replayed", file.display());
        assert!(
            stderr.contains(&file.display().to_string()) && stderr.contains(says),
            "{stderr}"
        );
        assert!(
            !run_dir.join("frames.csv").exists(),
            "a run started on {}",
            file.display()
        );
    }
}

#[test]
fn real_data_euroc_excerpt_recorded_checked_and_replayed_gives_the_same_poses() {
    let euroc = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
    record_check_and_replay("record-euroc", &euroc);
}

/// The pid of `parent`'s child process named `name` (its first 15 bytes, as /proc has it).
fn child_named(parent: u32, name: &str) -> Option<u32> {
    let comm: String = name.chars().take(15).collect();
    std::fs::read_dir("/proc")
        .ok()?
        .flatten()
        .find_map(|entry| {
            let pid: u32 = entry.file_name().to_str()?.parse().ok()?;
            let stat = std::fs::read_to_string(entry.path().join("stat")).ok()?;
            // "pid (comm) state ppid ..."
            let (head, rest) = stat.rsplit_once(") ")?;
            let ppid: u32 = rest.split_whitespace().nth(1)?.parse().ok()?;
            (ppid == parent && head.ends_with(&format!("({comm}"))).then_some(pid)
        })
}

#[test]
fn a_killed_recorder_is_recorded_and_the_run_goes_on() {
    recorder_built();
    let dir = scratch("record-killed");
    // Every frame processed however late: on a loaded machine LSD's frames would all be
    // dropped late and the run would track nothing, which is not what this test is about.
    let config = "[record]\nmcap = true\n[budget]\ndrop_late = false\n";
    let mut run = start_with_args(&dir, &base_sequence(40), config, &[]);
    // The source starts once the recorder is ready: frames flowing means it is up.
    run.wait_for("frames", Duration::from_secs(120), |s| s.frames >= 5);
    let supervisor = run.status().map(|s| s.supervisor_pid).unwrap_or_default();
    let recorder = child_named(supervisor, "linetrack-recorder")
        .unwrap_or_else(|| panic!("no recorder under the supervisor {supervisor}"));
    signal(recorder, "KILL");
    let run_dir = run.run_dir.clone();
    let (status, out, records) = run.finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    linetrack_e2e::assert_ids_accounted(&records, 40, &[]);
    let exited = records.events_of("recorder-exit");
    assert_eq!(exited.len(), 1, "{:?}", records.events);
    assert!(
        exited[0].detail.contains(&recorder.to_string()),
        "{:?}",
        exited[0]
    );
    assert_eq!(records.leftovers, Default::default(), "shared memory left");
    // Its file was left unfinished: a replay refuses it.
    let out = replay(
        &run_dir.join("recording.mcap"),
        &dir.join("pipeline.toml"),
        &dir.join("replay"),
        "lte2e_killedreplay_",
        None,
    );
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("truncated or not closed"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
