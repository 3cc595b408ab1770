//! Two users' runs on one machine. iceoryx2's defaults put every user's bookkeeping in one
//! `/tmp/iceoryx2` and leave its management segment in /dev/shm world-writable: the first
//! user locked the others out, and any local user could write into another's run. Here a
//! second user's pipeline (user `nobody`) starts while ours runs; it completes with its own
//! shared memory and its own root folder, and it can write into neither of ours.
//!
//! Starting a process as another user needs root (CI runs the suite as root).

use linetrack_e2e::*;
use linetrack_test_data::Scratch;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

const FRAMES: usize = 40;
/// Their run: it only has to run beside ours and complete, not as long as ours.
const THEIR_FRAMES: usize = 20;
const RUN_TIMEOUT: Duration = Duration::from_secs(120);
/// Every frame processed however late (the drop policy has its own tests).
const CONFIG: &str = "[supervisor]\nrestart_backoff_ms = 100\nhang_timeout_ms = 2000\ndrain_timeout_ms = 30000\nstatus_every_ms = 0\n[budget]\ndrop_late = false\n";

/// Whether user `nobody` can append 16 bytes to `file` (`sh`'s `>>`: creating it if it
/// does not exist).
fn nobody_can_write(file: &Path, cwd: &Path) -> bool {
    nobody_succeeds(cwd, "printf 0123456789abcdef >> \"$1\"", file)
}

/// Whether user `nobody` can append 16 bytes to `file` if it exists, never creating it: a
/// file of our run that is gone by then (a run that ended, a segment replaced) is not one
/// the other user wrote into.
fn nobody_can_write_into(file: &Path, cwd: &Path) -> bool {
    nobody_succeeds(
        cwd,
        "printf 0123456789abcdef | dd of=\"$1\" oflag=append conv=notrunc,nocreat status=none",
        file,
    )
}

/// Whether `script` (`sh -c`, `$1` = `file`) succeeds as user `nobody`.
fn nobody_succeeds(cwd: &Path, script: &str, file: &Path) -> bool {
    as_nobody(Path::new("/bin/sh"), cwd)
        .args(["-c", script, "sh"])
        .arg(file)
        .stderr(Stdio::null())
        .status()
        .unwrap_or_else(|e| panic!("sh as nobody: {e}"))
        .success()
}

/// The files in /dev/shm whose names start with `prefix`.
fn shared_memory_files(prefix: &str) -> Vec<PathBuf> {
    std::fs::read_dir("/dev/shm")
        .unwrap_or_else(|e| panic!("/dev/shm: {e}"))
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
        .map(|e| e.path())
        .collect()
}

/// A folder everyone may read and enter (the other user's binaries and sequence).
fn open_dir(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o755))
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
}

/// Asserts every file is `owner`'s and readable and writable by its owner only. A file gone
/// since it was listed is passed over (iceoryx2 replaces a publisher's data segment when it
/// grows, and a run that ends removes its own): the e2e suite under two CPU hogs once
/// listed a `.dynamic` segment that was gone when looked at. At least one must be left.
fn assert_private(files: &[PathBuf], owner: u32) {
    let mut checked = 0;
    for file in files {
        let meta = match std::fs::symlink_metadata(file) {
            Ok(meta) => meta,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(e) => panic!("{}: {e}", file.display()),
        };
        checked += 1;
        assert_eq!(meta.uid(), owner, "{}", file.display());
        assert_eq!(
            meta.mode() & 0o077,
            0,
            "{} is mode {:o}",
            file.display(),
            meta.mode() & 0o777
        );
    }
    assert!(
        files.is_empty() || checked > 0,
        "every one of {files:?} was gone when looked at"
    );
}

#[test]
fn another_users_run_beside_ours_completes_and_cannot_write_into_ours() {
    let dir = scratch("users");
    let mut ours = start(&dir, &base_sequence(FRAMES), CONFIG);
    ours.wait_for("3 frames", RUN_TIMEOUT, |s| s.frames >= 3);

    // The other user's world, outside the build folder (which may sit in a private home).
    let theirs_dir = Scratch::new("e2e", "users");
    open_dir(&theirs_dir);
    let bin = theirs_dir.join("bin");
    open_dir(&bin);
    for name in RUN_BINARIES {
        std::fs::copy(bin_dir().join(name), bin.join(name))
            .unwrap_or_else(|e| panic!("copying {name}: {e}"));
    }
    let sequence = sequence_copy(FRAMES, &theirs_dir);
    let home = theirs_dir.join("home");
    open_dir(&home);
    let (config, their_run_dir) = write_config(&home, &sequence, CONFIG);
    std::os::unix::fs::chown(&home, Some(NOBODY), Some(NOBODY))
        .unwrap_or_else(|e| panic!("{}: {e}", home.display()));
    let their_prefix = format!("linetrack_u{NOBODY}_");
    let mut theirs = Run {
        child: as_nobody(&bin.join("linetrack"), &home)
            .args([
                "run",
                "--quiet",
                "--frames",
                &THEIR_FRAMES.to_string(),
                "--config",
            ])
            .arg(&config)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap_or_else(|e| panic!("starting linetrack as nobody: {e}")),
        run_dir: their_run_dir,
        prefix: their_prefix.clone(),
    };
    theirs.wait_for("their 3 frames", RUN_TIMEOUT, |s| s.frames >= 3);

    // Both running: each user's shared memory is its own and closed to the other.
    let our_files = shared_memory_files(&ours.prefix);
    let their_files = shared_memory_files(&their_prefix);
    assert!(!our_files.is_empty() && !their_files.is_empty());
    assert_private(&our_files, 0);
    assert_private(&their_files, NOBODY);
    let mut refused = 0;
    for file in &our_files {
        assert!(
            !nobody_can_write_into(file, &home),
            "user nobody wrote into {}",
            file.display()
        );
        // Still there and still ours: the write was refused, not missed.
        refused += usize::from(std::fs::symlink_metadata(file).is_ok_and(|m| m.uid() == 0));
    }
    // iceoryx2's management segment stays for the next run even once ours has ended.
    assert!(refused > 0, "none of {our_files:?} was left to try");
    // Our iceoryx2 bookkeeping: a folder of ours the other user cannot even enter.
    let our_root = linetrack_ipc::Scope::default_root();
    let root_meta =
        std::fs::metadata(&our_root).unwrap_or_else(|e| panic!("{}: {e}", our_root.display()));
    assert_eq!(
        (root_meta.uid(), root_meta.mode() & 0o077),
        (0, 0),
        "{}",
        our_root.display()
    );
    assert!(!nobody_can_write(&our_root.join("intruder"), &home));
    // Their default root (no XDG_RUNTIME_DIR for them), in memory as ours.
    let their_root = PathBuf::from(format!("/dev/shm/linetrack-{NOBODY}"));
    let their_root_meta = std::fs::metadata(&their_root)
        .unwrap_or_else(|e| panic!("their root folder {}: {e}", their_root.display()));
    assert_eq!(
        (their_root_meta.uid(), their_root_meta.mode() & 0o777),
        (NOBODY, 0o700)
    );

    // Neither run noticed the other.
    let (status, out, records) = ours.finish(RUN_TIMEOUT);
    assert!(status.success(), "our run: {status}\n{out}");
    assert_ids_accounted(&records, FRAMES as u64, &[]);
    assert!(records.frames.iter().any(|f| f.outcome == "pose"), "{out}");
    let (status, out, records) = theirs.finish(RUN_TIMEOUT);
    assert!(status.success(), "their run: {status}\n{out}");
    assert_ids_accounted(&records, THEIR_FRAMES as u64, &[]);
    assert!(records.frames.iter().any(|f| f.outcome == "pose"), "{out}");
    // What stays (iceoryx2's management segment, kept for the user's next run) stays theirs
    // alone: iceoryx2 creates it world-writable.
    assert_private(&shared_memory_files(&their_prefix), NOBODY);
}
