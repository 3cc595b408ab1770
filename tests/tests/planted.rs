//! Paths another user prepared. User `nobody` (uid 65534) pre-creates the run folder in a
//! shared sticky folder (mode 777) with links named like the files a run writes, pointing
//! at root-owned 0600 files and at paths that do not exist; plants a link where the runs
//! folder would be; and pre-creates the shared-memory root's parent. Each run is refused
//! before any stage starts, with an error naming the path and the other user, and nothing
//! outside the run folder changes.
//!
//! Starting a process as another user needs root (CI runs the suite as root).

use linetrack_e2e::*;
use linetrack_test_data::Scratch;
use std::os::unix::fs::{MetadataExt as _, PermissionsExt as _};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

const FRAMES: usize = 40;
/// The files a run writes into its folder, planted as links.
const PLANTED: [&str; 6] = [
    "run.lock",
    "pipeline.toml",
    "status.json.tmp",
    "summary.json.tmp",
    "frames.csv",
    "latency.png",
];

/// Runs `script` (`sh -c`, `$1`.. = `args`) as user `nobody`; panics when it fails.
fn as_nobody_sh(cwd: &Path, script: &str, args: &[&Path]) {
    let status = as_nobody(Path::new("/bin/sh"), cwd)
        .args(["-c", script, "sh"])
        .args(args)
        .status()
        .unwrap_or_else(|e| panic!("sh as nobody: {e}"));
    assert!(status.success(), "as nobody: {script}: {status}");
}

/// `linetrack run` on `config` with `env`; returns whether it succeeded and its stderr.
fn run(config: &Path, env: &[(&str, &Path)]) -> (bool, String) {
    let out = Command::new(bin_dir().join("linetrack"))
        .args(["run", "--quiet", "--config"])
        .arg(config)
        .envs(env.iter().map(|(k, v)| (*k, v.as_os_str())))
        .stdin(Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("linetrack run: {e}"));
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The content, owner and mode of every file under `dir` (links as their targets' names).
fn snapshot(dir: &Path) -> Vec<(PathBuf, String, u32, u32)> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = entry.path();
        let meta = std::fs::symlink_metadata(&path).unwrap_or_else(|e| panic!("{e}"));
        if meta.is_dir() {
            files.extend(snapshot(&path));
            continue;
        }
        let text = if meta.file_type().is_symlink() {
            format!(
                "-> {}",
                std::fs::read_link(&path).unwrap_or_default().display()
            )
        } else {
            std::fs::read_to_string(&path).unwrap_or_default()
        };
        files.push((path, text, meta.uid(), meta.mode()));
    }
    files.sort();
    files
}

#[test]
fn folders_and_links_another_user_prepared_are_refused_naming_them_and_nothing_changes() {
    let dir = scratch("planted");
    let sequence = base_sequence(FRAMES);
    // Their world lies outside the build folder, which may sit in a private home where user
    // nobody cannot enter (CI's work tree does): a folder of root's everyone may enter.
    let world = Scratch::new("e2e", "planted");
    std::fs::set_permissions(&world, std::fs::Permissions::from_mode(0o755))
        .unwrap_or_else(|e| panic!("{e}"));
    // Root's files the other user aims at, and a shared sticky folder like /tmp.
    let victims = world.join("victims");
    std::fs::create_dir(&victims).unwrap_or_else(|e| panic!("{e}"));
    for name in PLANTED {
        let victim = victims.join(name);
        std::fs::write(&victim, format!("root's {name}")).unwrap_or_else(|e| panic!("{e}"));
        std::fs::set_permissions(&victim, std::fs::Permissions::from_mode(0o600))
            .unwrap_or_else(|e| panic!("{e}"));
    }
    let shared = world.join("shared");
    std::fs::create_dir(&shared).unwrap_or_else(|e| panic!("{e}"));
    std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o1777))
        .unwrap_or_else(|e| panic!("{e}"));
    // Their run folder: mode 777, links to root's files (and dangling ones).
    let theirs = shared.join("run");
    as_nobody_sh(
        &world,
        r#"mkdir -m 777 "$1" && for f in run.lock pipeline.toml status.json.tmp summary.json.tmp frames.csv latency.png; do ln -s "$2/$f" "$1/$f"; done && ln -s "$2/created-by-root" "$1/events.csv""#,
        &[&theirs, &victims],
    );
    // A link where our runs folder would be (the planted /tmp/out), to root's folder.
    let out_link = shared.join("out");
    as_nobody_sh(&world, r#"ln -s "$2" "$1""#, &[&out_link, &victims]);
    let watched = || [snapshot(&victims), snapshot(&shared)];
    let before = watched();

    let cases = [
        (
            "their run folder",
            format!("[output]\nrun_dir = {:?}\n", theirs.display().to_string()),
            theirs.clone(),
        ),
        (
            "a runs folder behind their link",
            format!(
                "[output]\nruns_dir = {:?}\n",
                out_link.join("runs").display().to_string()
            ),
            out_link.clone(),
        ),
    ];
    for (what, output, named) in cases {
        let config = dir.join("pipeline.toml");
        std::fs::write(
            &config,
            format!(
                "detector = \"lsd\"\n[source]\nsequence = {:?}\n{output}",
                sequence.display().to_string()
            ),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let (ok, stderr) = run(&config, &[]);
        assert!(!ok, "{what}: the run was not refused");
        assert!(
            stderr.contains(&named.display().to_string()) && stderr.contains("user 65534"),
            "{what}: the error does not name {} and its owner:\n{stderr}",
            named.display()
        );
        assert!(
            !stderr.contains("started"),
            "{what}: a stage started:\n{stderr}"
        );
    }
    assert_eq!(watched(), before, "something changed outside our folders");
    assert!(!victims.join("created-by-root").exists());
    assert!(!victims.join("runs").exists());

    // The shared-memory root's parent made by them (`/tmp/linetrack-<uid>` squatted), in a
    // sticky folder like /tmp: one of its own, short (the root must leave room for
    // iceoryx2's socket names), removed with everything in it when its guard drops.
    let sticky = Scratch::new("e2e", "squat");
    std::fs::set_permissions(&sticky, std::fs::Permissions::from_mode(0o1777))
        .unwrap_or_else(|e| panic!("{e}"));
    let squatted = sticky.join("s");
    as_nobody_sh(&world, r#"mkdir -m 755 "$1""#, &[&squatted]);
    let run_dir = dir.join("ours");
    let config = dir.join("pipeline.toml");
    std::fs::write(
        &config,
        format!(
            "detector = \"lsd\"\n[source]\nsequence = {:?}\n[output]\nrun_dir = {:?}\n",
            sequence.display().to_string(),
            run_dir.display().to_string()
        ),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let ipc_root = squatted.join("iceoryx2");
    let (ok, stderr) = run(&config, &[(linetrack_ipc::Scope::ROOT_VAR, &ipc_root)]);
    assert!(!ok, "a shared-memory root under their folder was accepted");
    assert!(
        stderr.contains(&squatted.display().to_string()) && stderr.contains("user 65534"),
        "{stderr}"
    );
    assert!(!ipc_root.exists(), "made a folder in theirs");
    // Our own run folder, made by the refused run, is ours and owner-only.
    let meta = std::fs::metadata(&run_dir).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((meta.uid(), meta.mode() & 0o777), (0, 0o700));
}
