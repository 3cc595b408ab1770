//! Another user is user `nobody` (uid 65534): files are handed to it with `lchown`, which
//! needs root (CI runs the suite as root, as the two-user end-to-end test does).

use super::*;
use linetrack_test_data::Scratch;
use std::os::unix::fs::{PermissionsExt as _, lchown, symlink};

const NOBODY: u32 = 65534;

/// A scratch folder, removed when dropped, with the usual mode 755 (not tempfile's 700).
fn scratch(name: &str) -> Scratch {
    let scratch = Scratch::new("private-dir", name);
    chmod(scratch.path(), 0o755);
    scratch
}

fn as_root() {
    assert_eq!(
        rustix::process::geteuid().as_raw(),
        0,
        "these tests hand files to another user (nobody, uid {NOBODY}) with lchown: run them as root"
    );
}

fn give_to_nobody(path: &Path) {
    lchown(path, Some(NOBODY), Some(NOBODY)).unwrap_or_else(|e| panic!("{e}"));
}

fn chmod(path: &Path, mode: u32) {
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))
        .unwrap_or_else(|e| panic!("{e}"));
}

fn refusal(path: &Path, create: Create) -> String {
    private_dir(path, create)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_else(|| format!("{} was accepted", path.display()))
}

#[test]
fn missing_folders_are_made_owner_only_and_own_links_are_resolved() {
    let scratch = scratch("made");
    let dir = scratch.path();
    let target = dir.join("a/b/runs");
    assert_eq!(
        private_dir(&target, Create::Missing).ok(),
        Some(target.clone())
    );
    for made in [dir.join("a"), dir.join("a/b"), target.clone()] {
        let mode = std::fs::metadata(&made)
            .map(|m| m.mode() & 0o777)
            .unwrap_or(0);
        assert_eq!(mode, DIR_MODE, "{}", made.display());
    }
    // This user's own link is followed; the path comes back without it.
    symlink(dir.join("a/b"), dir.join("mine")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        private_dir(&dir.join("mine/runs/../runs"), Create::No).ok(),
        Some(target.clone())
    );
    // Not made unless asked; not a folder.
    assert!(refusal(&dir.join("absent"), Create::No).contains("absent"));
    std::fs::write(dir.join("file"), "").unwrap_or_else(|e| panic!("{e}"));
    assert!(refusal(&dir.join("file"), Create::Missing).contains("not a folder"));
}

#[test]
fn another_users_link_or_folder_on_the_way_is_refused_naming_it_and_nothing_is_made_beyond() {
    as_root();
    let scratch = scratch("foreign");
    let dir = scratch.path();
    // A link another user planted (as /tmp/out was), pointing at a folder of theirs.
    let theirs = dir.join("theirs");
    std::fs::create_dir(&theirs).unwrap_or_else(|e| panic!("{e}"));
    give_to_nobody(&theirs);
    let planted = dir.join("out");
    symlink(&theirs, &planted).unwrap_or_else(|e| panic!("{e}"));
    give_to_nobody(&planted);
    let err = refusal(&planted.join("runs"), Create::Missing);
    assert!(
        err.contains(&planted.display().to_string()) && err.contains("user 65534"),
        "{err}"
    );
    assert!(!theirs.join("runs").exists(), "made a folder in theirs");
    // Their folder itself, as the target or above it.
    let err = refusal(&theirs, Create::Missing);
    assert!(err.contains(&theirs.display().to_string()), "{err}");
    let err = refusal(&theirs.join("runs"), Create::Missing);
    assert!(err.contains(&theirs.display().to_string()), "{err}");
    assert!(!theirs.join("runs").exists());
    // A link of theirs pointing at a folder of ours: still not followed.
    let ours = dir.join("ours");
    std::fs::create_dir(&ours).unwrap_or_else(|e| panic!("{e}"));
    let lure = dir.join("lure");
    symlink(&ours, &lure).unwrap_or_else(|e| panic!("{e}"));
    give_to_nobody(&lure);
    assert!(refusal(&lure, Create::No).contains("lure"));
}

#[test]
fn a_folder_others_can_write_is_refused_unless_it_is_a_sticky_one_above() {
    let scratch = scratch("open");
    let dir = scratch.path();
    let target = dir.join("run");
    std::fs::create_dir(&target).unwrap_or_else(|e| panic!("{e}"));
    chmod(&target, 0o777);
    let err = refusal(&target, Create::Missing);
    assert!(
        err.contains("run: writable by other users (mode 777)"),
        "{err}"
    );
    chmod(&target, 0o770);
    assert!(refusal(&target, Create::No).contains("mode 770"));
    // Above the target: refused when others could move what is below it...
    chmod(&target, 0o700);
    chmod(dir, 0o777);
    let err = refusal(&target, Create::No);
    assert!(err.contains("not sticky"), "{err}");
    // ... and accepted when they cannot (/tmp's 1777).
    chmod(dir, 0o1777);
    assert_eq!(private_dir(&target, Create::No).ok(), Some(target.clone()));
    chmod(dir, 0o755);
}

#[test]
fn the_errors_name_the_path_for_any_user() {
    let scratch = scratch("owner");
    let dir = scratch.path();
    // Seen from another uid, a folder of this user is another user's.
    let me = rustix::process::geteuid().as_raw();
    let other = Owner { me: me + 1 };
    let err = private_dir_for(dir, Create::No, other)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        err.contains(&dir.display().to_string()) && err.contains(&format!("user {me}")),
        "{err}"
    );
}
