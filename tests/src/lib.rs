//! Helpers of the end-to-end tests: generated sequences (made once, then copied and
//! altered), a pipeline run started as a user would (`linetrack run` in its own process,
//! with its own shared-memory prefix), and its records.

pub mod pose_counter;

use linetrack_ipc::{Resources, Scope};
use linetrack_run_record::{EventRecord, FrameRecord, read_events, read_frames};
use linetrack_scene_render::Preset;
use linetrack_supervisor::LiveStatus;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The binaries a plain `linetrack run` needs: the command and its four stages.
pub const RUN_BINARIES: [&str; 5] = [
    "linetrack",
    "linetrack-frame-source",
    "linetrack-line-detector",
    "linetrack-matcher",
    "linetrack-pose-estimator",
];

/// The folder holding the workspace's binaries (`linetrack`, the stages): the test binary
/// lives in its `deps/`.
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap_or_else(|e| panic!("current_exe: {e}"));
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .unwrap_or_else(|| panic!("no bin folder above {}", exe.display()))
        .to_path_buf();
    for name in RUN_BINARIES {
        assert!(
            dir.join(name).is_file(),
            "{} is missing: build the binaries first (`cargo build --workspace --bins --profile test-release`; `cargo xtask test` does it)",
            dir.join(name).display()
        );
    }
    dir
}

/// Where the tests keep their files: beside the binaries, in `e2e-tmp/`.
fn tmp_root() -> PathBuf {
    let exe = std::env::current_exe().unwrap_or_else(|e| panic!("current_exe: {e}"));
    exe.parent()
        .and_then(Path::parent)
        .unwrap_or_else(|| panic!("no folder above {}", exe.display()))
        .join("e2e-tmp")
}

/// A scratch folder for one test, emptied, under the build folder (not the system temp
/// folder). Kept after the test on purpose: the run folders in it (records, status, logs)
/// are what one reads after a failing end-to-end run, and each test's fixed name means a
/// rerun replaces them instead of piling up.
pub fn scratch(name: &str) -> PathBuf {
    let dir = tmp_root().join("runs").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    dir
}

/// The shared generated sequence of `frames` frames (preset normal), rendered on first use.
pub fn base_sequence(frames: usize) -> PathBuf {
    let dir = tmp_root().join(format!("sequence-{frames}"));
    if dir.join("mav0/cam1/data.csv").is_file() {
        return dir;
    }
    let partial = tmp_root().join(format!("sequence-{frames}.partial-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&partial);
    linetrack_synth::generate(Preset::Normal, 1, frames, &partial, true)
        .unwrap_or_else(|e| panic!("generating the sequence: {e:#}"));
    // Another test may have finished first: either copy is the same sequence.
    if std::fs::rename(&partial, &dir).is_err() {
        let _ = std::fs::remove_dir_all(&partial);
    }
    dir
}

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap_or_else(|e| panic!("{}: {e}", to.display()));
    for entry in std::fs::read_dir(from)
        .unwrap_or_else(|e| panic!("{}: {e}", from.display()))
        .flatten()
    {
        let target = to.join(entry.file_name());
        if entry.path().is_dir() {
            copy_tree(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target)
                .unwrap_or_else(|e| panic!("{}: {e}", target.display()));
        }
    }
}

/// A copy of the base sequence in `dir`, for tests that alter images.
pub fn sequence_copy(frames: usize, dir: &Path) -> PathBuf {
    let target = dir.join("sequence");
    copy_tree(&base_sequence(frames).join("mav0"), &target.join("mav0"));
    target
}

/// The image files of camera `cam` (0 left, 1 right) of a sequence, in time order.
pub fn images(sequence: &Path, cam: u32) -> Vec<PathBuf> {
    let dir = sequence.join(format!("mav0/cam{cam}/data"));
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .flatten()
        .map(|e| e.path())
        .collect();
    // Named by timestamp (not zero-padded): order by the number.
    files.sort_by_key(|p| {
        p.file_stem()
            .and_then(|s| s.to_str())
            .and_then(|s| s.parse::<u64>().ok())
            .unwrap_or(u64::MAX)
    });
    files
}

/// A pipeline run in its own process.
pub struct Run {
    /// The `linetrack run` process.
    pub child: Child,
    /// Its run folder.
    pub run_dir: PathBuf,
    /// Its shared-memory prefix.
    pub prefix: String,
}

/// Writes a pipeline config for `sequence` into `dir` with `extra` TOML appended to the
/// test defaults (LSD, the LBD→ℓ1 policy, 10 Hz, quick supervision), and starts
/// `linetrack run` on it.
pub fn start(dir: &Path, sequence: &Path, extra: &str) -> Run {
    let prefix = format!(
        "lte2e{}_{}_",
        std::process::id(),
        dir.file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("x")
            .replace('-', "")
    );
    start_with_prefix(dir, sequence, extra, &prefix)
}

/// [`start`] with a given shared-memory prefix.
pub fn start_with_prefix(dir: &Path, sequence: &Path, extra: &str, prefix: &str) -> Run {
    launch(dir, sequence, extra, prefix, &[])
}

/// [`start`] with more `linetrack run` arguments (`--frames 30`, ...).
pub fn start_with_args(dir: &Path, sequence: &Path, extra: &str, args: &[&str]) -> Run {
    let prefix = format!(
        "lte2e{}_{}_",
        std::process::id(),
        dir.file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("x")
            .replace('-', "")
    );
    launch(dir, sequence, extra, &prefix, args)
}

/// [`start`] with the stages on threads of one process (`--single-process`).
pub fn start_single_process(dir: &Path, sequence: &Path, extra: &str) -> Run {
    let prefix = format!("lte2e{}_threads_", std::process::id());
    launch(dir, sequence, extra, &prefix, &["--single-process"])
}

/// [`start`] with the stages started through `runner` (`LINETRACK_STAGE_RUNNER`).
pub fn start_through_runner(dir: &Path, sequence: &Path, extra: &str, runner: &str) -> Run {
    let prefix = format!("lte2e{}_runner_", std::process::id());
    launch_with(
        dir,
        sequence,
        extra,
        &prefix,
        &[],
        &[("LINETRACK_STAGE_RUNNER", runner)],
        Stdio::inherit(),
    )
}

/// [`start`] with more environment variables for the supervisor and its children.
pub fn start_with_env(dir: &Path, sequence: &Path, extra: &str, env: &[(&str, &str)]) -> Run {
    let prefix = format!("lte2e{}_env_", std::process::id());
    launch_with(dir, sequence, extra, &prefix, &[], env, Stdio::inherit())
}

fn launch(dir: &Path, sequence: &Path, extra: &str, prefix: &str, args: &[&str]) -> Run {
    launch_with(dir, sequence, extra, prefix, args, &[], Stdio::inherit())
}

/// [`start_with_args`] with the run's stderr (the supervisor's and, passed on, every
/// stage's) written to `dir/stderr.log`, for a test that checks a warning.
pub fn start_logging(dir: &Path, sequence: &Path, extra: &str, args: &[&str]) -> Run {
    let prefix = format!("lte2e{}_log_", std::process::id());
    let log = dir.join("stderr.log");
    let file = std::fs::File::create(&log).unwrap_or_else(|e| panic!("{}: {e}", log.display()));
    launch_with(dir, sequence, extra, &prefix, args, &[], Stdio::from(file))
}

fn launch_with(
    dir: &Path,
    sequence: &Path,
    extra: &str,
    prefix: &str,
    args: &[&str],
    env: &[(&str, &str)],
    stderr: Stdio,
) -> Run {
    let prefix = prefix.to_string();
    let (config, run_dir) = write_config(dir, sequence, extra);
    let child = Command::new(bin_dir().join("linetrack"))
        .args(["run", "--quiet"])
        .args(args)
        .arg("--config")
        .arg(&config)
        .env(Scope::PREFIX_VAR, &prefix)
        .envs(env.iter().copied())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(stderr)
        .spawn()
        .unwrap_or_else(|e| panic!("starting linetrack: {e}"));
    Run {
        child,
        run_dir,
        prefix,
    }
}

/// Writes `dir/pipeline.toml` for `sequence`: `extra` TOML appended to the test defaults
/// (LSD, the LBD→ℓ1 policy, 10 Hz), the run folder `dir/run`. Returns both paths.
pub fn write_config(dir: &Path, sequence: &Path, extra: &str) -> (PathBuf, PathBuf) {
    let run_dir = dir.join("run");
    let config = write_config_for(dir, sequence, extra, &run_dir);
    (config, run_dir)
}

/// [`write_config`] with the run folder `run_dir`; returns the config's path.
pub fn write_config_for(dir: &Path, sequence: &Path, extra: &str, run_dir: &Path) -> PathBuf {
    let config = dir.join("pipeline.toml");
    // The tests check LSD's hot swap to FLD and LBD's fallback to l1: they pin the detector
    // and the matcher policy (the shipped defaults are edgelines and l1). The automatic
    // detector policy would swap LSD away on a loaded machine: only a test that names it
    // has it.
    let policy = if extra.contains("[detector_fallback]") {
        ""
    } else {
        "[detector_fallback]\nenabled = false\n"
    };
    let text = format!(
        "detector = \"lsd\"\n{policy}[matcher]\nmode = \"auto\"\n{extra}\n[source]\nsequence = {:?}\nrate_hz = 10.0\n[output]\nrun_dir = {:?}\n",
        sequence.display().to_string(),
        run_dir.display().to_string()
    );
    std::fs::write(&config, text).unwrap_or_else(|e| panic!("{e}"));
    config
}

impl Run {
    /// The run's live status, once the supervisor wrote it.
    pub fn status(&self) -> Option<LiveStatus> {
        let text = std::fs::read_to_string(self.run_dir.join("status.json")).ok()?;
        serde_json::from_str(&text).ok()
    }

    /// Waits until `ready(status)` holds, or panics after `timeout`.
    pub fn wait_for(
        &mut self,
        what: &str,
        timeout: Duration,
        ready: impl Fn(&LiveStatus) -> bool,
    ) -> LiveStatus {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(s) = self.status()
                && ready(&s)
            {
                return s;
            }
            if let Ok(Some(status)) = self.child.try_wait() {
                panic!("the run exited ({status}) before {what}");
            }
            assert!(Instant::now() < deadline, "no {what} within {timeout:?}");
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Waits for the run to end (panics after `timeout`); returns its stdout.
    pub fn finish(mut self, timeout: Duration) -> (std::process::ExitStatus, String, Records) {
        let deadline = Instant::now() + timeout;
        let status = loop {
            if let Ok(Some(status)) = self.child.try_wait() {
                break status;
            }
            if Instant::now() > deadline {
                let _ = self.child.kill();
                panic!("the run did not finish within {timeout:?}");
            }
            std::thread::sleep(Duration::from_millis(50));
        };
        let mut out = String::new();
        if let Some(mut stdout) = self.child.stdout.take() {
            use std::io::Read;
            let _ = stdout.read_to_string(&mut out);
        }
        let records = Records::read(&self.run_dir, &self.prefix);
        (status, out, records)
    }
}

/// What a run left.
pub struct Records {
    /// Per frame.
    pub frames: Vec<FrameRecord>,
    /// Events.
    pub events: Vec<EventRecord>,
    /// iceoryx2 resources left under the run's prefix.
    pub leftovers: Resources,
}

impl Records {
    /// Reads a run folder.
    pub fn read(run_dir: &Path, prefix: &str) -> Self {
        let frames = read_frames(&run_dir.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
        let events = read_events(&run_dir.join("events.csv")).unwrap_or_else(|e| panic!("{e}"));
        let scope = Scope::with_prefix(prefix, "");
        let leftovers = scope.resources().unwrap_or_else(|e| panic!("{e}"));
        Self {
            frames,
            events,
            leftovers,
        }
    }

    /// The events of `kind`.
    pub fn events_of(&self, kind: &str) -> Vec<&EventRecord> {
        self.events.iter().filter(|e| e.kind == kind).collect()
    }
}

/// The other user of the two-user tests.
pub const NOBODY: u32 = 65534;

/// `program` as user `nobody`, with the environment of a fresh login (no `XDG_RUNTIME_DIR`,
/// no `LINETRACK_IPC_*`), in `cwd`. Starting a process as another user needs root (CI runs
/// the suite as root): the test fails saying so otherwise.
pub fn as_nobody(program: &Path, cwd: &Path) -> Command {
    use std::os::unix::fs::MetadataExt as _;
    use std::os::unix::process::CommandExt as _;
    let me = std::fs::metadata("/proc/self").map_or(u32::MAX, |m| m.uid());
    assert_eq!(
        me, 0,
        "this test starts a second user's processes (user nobody, uid {NOBODY}): run it as root"
    );
    let mut command = Command::new(program);
    command
        .uid(NOBODY)
        .gid(NOBODY)
        .env_clear()
        .env("PATH", "/usr/bin:/bin")
        .env("HOME", cwd)
        .current_dir(cwd)
        .stdin(Stdio::null());
    command
}

/// `linetrack report` on a cut run folder: it must succeed, list the `frames` recorded and
/// say the run ended `records-failed`. Returns its output for further checks.
pub fn assert_reports_a_cut_run(run_dir: &Path, frames: usize) -> String {
    let report = Command::new(bin_dir().join("linetrack"))
        .arg("report")
        .arg(run_dir)
        .output()
        .unwrap_or_else(|e| panic!("linetrack report: {e}"));
    let text = String::from_utf8_lossy(&report.stdout).into_owned();
    assert!(
        report.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&report.stderr)
    );
    assert!(text.contains(&format!("frames {frames}:")), "{text}");
    assert!(text.contains("run ended records-failed"), "{text}");
    text
}

/// The pid of `stage`'s running process (not a standby detector) in `status`; panics
/// naming the stage and the stages listed when there is none.
pub fn stage_pid(status: &LiveStatus, stage: &str) -> u32 {
    status
        .stages
        .iter()
        .find(|s| s.stage == stage && !s.standby)
        .unwrap_or_else(|| panic!("no {stage} in {:?}", status.stages))
        .pid
}

/// Sends `signal` (e.g. "KILL", "TERM") to `pid` with kill(1).
pub fn signal(pid: u32, signal: &str) {
    let status = Command::new("kill")
        .arg(format!("-{signal}"))
        .arg(pid.to_string())
        .status()
        .unwrap_or_else(|e| panic!("kill: {e}"));
    assert!(status.success(), "kill -{signal} {pid} failed");
}

/// Frame ids 0..n appear once each, in order, each with an outcome a dataset run records or
/// one of `also` (a camera's `capture-dropped`, `capture-late`).
pub fn assert_ids_accounted(records: &Records, n: u64, also: &[&str]) {
    let ids: Vec<u64> = records.frames.iter().map(|f| f.frame_id).collect();
    assert_eq!(
        ids,
        (0..n).collect::<Vec<_>>(),
        "every frame once, in order"
    );
    let known = [
        "pose",
        "lost",
        "corrupt",
        "dropped-late",
        "dropped-behind",
        "stage-error",
        "skipped",
        "missing",
    ];
    for f in &records.frames {
        let outcome = f.outcome.as_str();
        assert!(
            known.contains(&outcome) || also.contains(&outcome),
            "frame {}: outcome {outcome:?}",
            f.frame_id
        );
    }
}

/// The Python of a test peer installed by `cargo xtask setup`: `$variable` when set, else
/// `target/<venv>/bin/python3`; a missing one fails the test saying how to install it.
pub fn peer_python(variable: &str, venv: &str, what: &str) -> PathBuf {
    let python = std::env::var_os(variable).map_or_else(
        || {
            bin_dir()
                .parent()
                .map(|target| target.join(venv).join("bin/python3"))
                .unwrap_or_default()
        },
        PathBuf::from,
    );
    assert!(
        python.is_file(),
        "{} is missing: `cargo xtask setup` installs {what} (or set {variable} to a Python with it)",
        python.display()
    );
    python
}
