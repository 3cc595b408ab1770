//! The runtime settings of `configs/pipeline.toml` on the real pipeline: a stage pinned with
//! `[stages.<name>] cpus = [0]` runs on CPU 0 only, as the kernel reports it
//! (`/proc/<pid>/status`, or the stage thread's `/proc/<pid>/task/<tid>/status` with
//! `--single-process`), while the other stages keep the supervisor's CPUs; the source reads
//! ahead at its `reader_nice`; a CPU that does
//! not exist stops the run before any stage starts, naming the stage and the CPU; the
//! shared memory's bookkeeping goes to the config's `[ipc] root`.

use linetrack_e2e::*;
use linetrack_test_data::Scratch;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

const FRAMES: usize = 40;
const RUN_TIMEOUT: Duration = Duration::from_secs(120);
const QUICK: &str = "[supervisor]\nrestart_backoff_ms = 100\nhang_timeout_ms = 2000\n\
    drain_timeout_ms = 30000\nstatus_every_ms = 0\n[budget]\ndrop_late = false\n";

/// `Cpus_allowed_list` of a process or thread status file.
fn cpus_allowed(status_file: &Path) -> String {
    let text = std::fs::read_to_string(status_file)
        .unwrap_or_else(|e| panic!("{}: {e}", status_file.display()));
    text.lines()
        .find_map(|l| l.strip_prefix("Cpus_allowed_list:"))
        .unwrap_or_else(|| panic!("no Cpus_allowed_list in {}", status_file.display()))
        .trim()
        .to_string()
}

/// The nice value in a process or thread `stat` file (the 19th field; the 2nd, the name in
/// parentheses, may hold spaces).
fn nice_of(stat_file: &Path) -> i32 {
    let text = std::fs::read_to_string(stat_file)
        .unwrap_or_else(|e| panic!("{}: {e}", stat_file.display()));
    // Fields from the 3rd on: the nice value is the 17th of them.
    text.rsplit_once(')')
        .and_then(|(_, after_name)| after_name.split_whitespace().nth(16))
        .and_then(|f| f.parse().ok())
        .unwrap_or_else(|| panic!("no nice value in {}: {text}", stat_file.display()))
}

fn proc_status(pid: u32) -> PathBuf {
    PathBuf::from(format!("/proc/{pid}/status"))
}

/// The status file of the thread named `name` in process `pid`.
fn thread_status(pid: u32, name: &str) -> Option<PathBuf> {
    std::fs::read_dir(format!("/proc/{pid}/task"))
        .ok()?
        .flatten()
        .find(|task| {
            std::fs::read_to_string(task.path().join("comm")).is_ok_and(|c| c.trim() == name)
        })
        .map(|task| task.path().join("status"))
}

#[test]
fn a_stage_pinned_to_cpu_0_runs_there_and_the_ipc_root_comes_from_the_config() {
    let dir = scratch("pinned");
    // Short: iceoryx2's event sockets live under it, and a socket path holds 107 bytes.
    // Declared before the run, so the run is finished before the guard drops.
    let ipc_root = Scratch::new("e2e", "ipc");
    let extra = format!(
        "{QUICK}[stages.line-detector]\ncpus = [0]\n[ipc]\nroot = {:?}\n",
        ipc_root.display().to_string()
    );
    let mut run = start(&dir, &base_sequence(FRAMES), &extra);
    let status = run.wait_for("3 frames", RUN_TIMEOUT, |s| s.frames >= 3);
    let supervisor_cpus = cpus_allowed(&proc_status(status.supervisor_pid));
    assert_eq!(
        cpus_allowed(&proc_status(stage_pid(&status, "line-detector"))),
        "0"
    );
    // Every thread of the pinned stage (iceoryx2's, OpenCV's) inherited it.
    let tasks = std::fs::read_dir(format!(
        "/proc/{}/task",
        stage_pid(&status, "line-detector")
    ))
    .unwrap_or_else(|e| panic!("{e}"));
    for task in tasks.flatten() {
        assert_eq!(cpus_allowed(&task.path().join("status")), "0");
    }
    // The source reads ahead at `source.reader_nice` (0 by default: set, not inherited, so
    // under a niced supervisor the two differ), and publishes at the nice value it
    // inherited from the supervisor.
    let source = stage_pid(&status, "frame-source");
    let reader = thread_status(source, "frame-reader")
        .unwrap_or_else(|| panic!("no thread named frame-reader in process {source}"));
    let stat = |pid: u32| PathBuf::from(format!("/proc/{pid}/stat"));
    assert_eq!(nice_of(&reader.with_file_name("stat")), 0);
    assert_eq!(
        nice_of(&stat(source)),
        nice_of(&stat(status.supervisor_pid))
    );
    for unpinned in ["frame-source", "matcher", "pose-estimator"] {
        assert_eq!(
            cpus_allowed(&proc_status(stage_pid(&status, unpinned))),
            supervisor_cpus,
            "{unpinned}"
        );
    }
    if std::env::var_os(linetrack_ipc::Scope::ROOT_VAR).is_none() {
        assert_eq!(status.ipc_root.as_deref(), Some(ipc_root.path()));
        let entries = std::fs::read_dir(&ipc_root)
            .map(|d| d.count())
            .unwrap_or_else(|e| panic!("{}: {e}", ipc_root.display()));
        assert!(entries > 0, "nothing in {}", ipc_root.display());
    }
    let (exit, out, records) = run.finish(RUN_TIMEOUT);
    assert!(exit.success(), "{exit}\n{out}");
    assert_eq!(records.frames.len(), FRAMES);
    assert!(
        records.events_of("sched-refused").is_empty(),
        "{:?}",
        records.events
    );
}

#[test]
fn a_thread_stage_pinned_to_cpu_0_runs_there_in_single_process_mode() {
    let dir = scratch("pinned-threads");
    let extra = format!("{QUICK}[stages.matcher]\ncpus = [0]\n");
    let mut run = start_single_process(&dir, &base_sequence(FRAMES), &extra);
    let status = run.wait_for("3 frames", RUN_TIMEOUT, |s| s.frames >= 3);
    let pid = status.supervisor_pid;
    let matcher = thread_status(pid, "matcher")
        .unwrap_or_else(|| panic!("no thread named matcher in process {pid}"));
    let detector = thread_status(pid, "line-detector")
        .unwrap_or_else(|| panic!("no thread named line-detector in process {pid}"));
    assert_eq!(cpus_allowed(&matcher), "0");
    assert_eq!(cpus_allowed(&detector), cpus_allowed(&proc_status(pid)));
    let (exit, out, _) = run.finish(RUN_TIMEOUT);
    assert!(exit.success(), "{exit}\n{out}");
}

#[test]
fn a_cpu_that_does_not_exist_stops_the_run_before_any_stage_naming_it() {
    let dir = scratch("no-such-cpu");
    let config = dir.join("pipeline.toml");
    let text = format!(
        "[stages.matcher]\ncpus = [1023]\n[source]\nsequence = {:?}\n[output]\nrun_dir = {:?}\n",
        base_sequence(FRAMES).display().to_string(),
        dir.join("run").display().to_string()
    );
    std::fs::write(&config, text).unwrap_or_else(|e| panic!("{e}"));
    let output = Command::new(bin_dir().join("linetrack"))
        .args(["run", "--quiet", "--config"])
        .arg(&config)
        .env(
            linetrack_ipc::Scope::PREFIX_VAR,
            format!("lte2e{}_nocpu_", std::process::id()),
        )
        .stdin(Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("starting linetrack: {e}"));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(
        stderr.contains("stages.matcher.cpus: CPU 1023 is not available here"),
        "{stderr}"
    );
    // Refused before the run began: no run folder, no stage.
    assert!(!dir.join("run").exists());
}
