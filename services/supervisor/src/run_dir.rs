//! The run folder: which one a run writes into, and a lock so that two runs never share one.
//!
//! By default every run gets a new folder under `output.runs_dir` (unset: the user's state
//! folder, `$XDG_STATE_HOME/linetrack/runs` or `~/.local/state/linetrack/runs`), named by
//! its UTC start time (`2026-11-23T12-00-00`, `-2` appended when two runs start in one
//! second), and `latest` beside it becomes a symlink to it, so `linetrack report` and
//! `linetrack ctl` find the newest run. `output.run_dir` (`--run-dir`) names a fixed folder
//! instead.
//!
//! Both are reached through [`linetrack_private_dir`]: made owner-only when missing,
//! refused (naming the path) when another user owns them or a folder above them, could
//! write into them, or planted a link on the way; the path used from then on has no link
//! left in it. Every file the run writes there is created owner-only and never through a
//! link ([`linetrack_run_record::files`]).
//!
//! The run holds an exclusive lock on `run.lock` in its folder (`flock`, through
//! `File::try_lock`) for as long as it runs: a second run into the same folder is refused,
//! naming the pid written in the lock file. The kernel drops the lock when the process
//! ends, however it ends, so a crashed run never blocks the next one.

use anyhow::{Context, bail};
use linetrack_pipeline_config::OutputConfig;
use linetrack_private_dir::{Create, DIR_MODE, private_dir};
use linetrack_run_record::files::FILE_MODE;
use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read as _, Write as _};
use std::os::unix::fs::{DirBuilderExt as _, OpenOptionsExt as _};
use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// The lock file in a run folder.
pub const LOCK_FILE: &str = "run.lock";
/// The symlink to the newest dated run folder.
pub const LATEST: &str = "latest";
/// Runs starting in the same second get `-2`, `-3`, ... up to this.
const MAX_SAME_SECOND: u32 = 1000;

/// The run folder of a run starting at `now`: `output.run_dir` when set, otherwise a new
/// dated folder under `output.runs_dir`, with `latest` pointed at it.
pub fn resolve(output: &OutputConfig, now: SystemTime) -> anyhow::Result<PathBuf> {
    if let Some(dir) = &output.run_dir {
        return private_dir(dir, Create::Missing).context("run folder (output.run_dir)");
    }
    let runs = output
        .runs_dir()
        .map_err(|e| anyhow::anyhow!("{e}"))
        .and_then(|runs| private_dir(&runs, Create::Missing).context("output.runs_dir"))?;
    let runs = &runs;
    let stamp = humantime::format_rfc3339_seconds(now)
        .to_string()
        .trim_end_matches('Z')
        .replace(':', "-");
    for n in 1..=MAX_SAME_SECOND {
        let name = if n == 1 {
            stamp.clone()
        } else {
            format!("{stamp}-{n}")
        };
        let dir = runs.join(&name);
        // mkdir never follows a link at the new name; the folder is then checked like any.
        match std::fs::DirBuilder::new().mode(DIR_MODE).create(&dir) {
            Ok(()) => {
                let dir = private_dir(&dir, Create::No).context("run folder")?;
                point_latest(runs, &name)?;
                return Ok(dir);
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => {
                return Err(e).with_context(|| format!("creating run folder {}", dir.display()));
            }
        }
    }
    bail!(
        "{}: {MAX_SAME_SECOND} runs started in the second {stamp}",
        runs.display()
    )
}

/// Makes `runs/latest` a symlink to `name` (replaced in one rename: readers see the old or
/// the new one). A real folder named `latest` (runs before they were dated) is moved aside
/// to `latest-before-<name>`.
fn point_latest(runs: &Path, name: &str) -> anyhow::Result<()> {
    let latest = runs.join(LATEST);
    if latest.is_dir() && !latest.is_symlink() {
        let aside = runs.join(format!("{LATEST}-before-{name}"));
        std::fs::rename(&latest, &aside).with_context(|| {
            format!(
                "moving the old run folder {} aside to {}",
                latest.display(),
                aside.display()
            )
        })?;
        tracing::info!(
            "{} was a run folder: moved to {}",
            latest.display(),
            aside.display()
        );
    }
    let tmp = runs.join(format!(".{LATEST}-{}", std::process::id()));
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(name, &tmp)
        .with_context(|| format!("creating the symlink {}", tmp.display()))?;
    std::fs::rename(&tmp, &latest).with_context(|| format!("replacing {}", latest.display()))
}

/// Takes the run folder's lock (held while the returned file is open) and writes this
/// process's pid into it; refuses when another live process holds it.
pub fn lock(run_dir: &Path) -> anyhow::Result<File> {
    let path = run_dir.join(LOCK_FILE);
    let mut file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .mode(FILE_MODE)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(&path)
        .with_context(|| format!("opening {}", path.display()))?;
    match file.try_lock() {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) => {
            let mut holder = String::new();
            let _ = file.read_to_string(&mut holder);
            let holder = holder.trim();
            bail!(
                "run folder {} is in use by another run (pid {}): wait for it to end or choose another --run-dir",
                run_dir.display(),
                if holder.is_empty() { "unknown" } else { holder }
            );
        }
        Err(TryLockError::Error(e)) => {
            return Err(e).with_context(|| format!("locking {}", path.display()));
        }
    }
    file.set_len(0)
        .and_then(|()| writeln!(file, "{}", std::process::id()))
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(file)
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_test_data::Scratch;
    use std::time::Duration;

    #[test]
    fn a_locked_run_folder_is_refused_naming_the_holder_until_it_is_released() {
        let dir = Scratch::new("supervisor", "run-lock");
        let held = lock(&dir).unwrap_or_else(|e| panic!("{e:#}"));
        // flock locks belong to the open file: a second open, even here, is refused.
        let err = lock(&dir)
            .err()
            .map(|e| format!("{e:#}"))
            .unwrap_or_default();
        assert!(
            err.contains(&format!("pid {}", std::process::id()))
                && err.contains(&dir.display().to_string()),
            "{err}"
        );
        drop(held);
        let again = lock(&dir);
        assert!(again.is_ok(), "the lock outlived its holder");
    }

    #[test]
    fn each_run_gets_a_dated_folder_and_latest_follows() {
        let runs = Scratch::new("supervisor", "runs-dated");
        // An old-style `latest` folder is moved aside, not lost.
        std::fs::create_dir_all(runs.join("latest")).unwrap_or_else(|e| panic!("{e}"));
        std::fs::write(runs.join("latest/frames.csv"), "old").unwrap_or_else(|e| panic!("{e}"));
        let output = OutputConfig {
            runs_dir: Some(runs.to_path_buf()),
            ..OutputConfig::default()
        };
        let t = SystemTime::UNIX_EPOCH + Duration::from_secs(1_795_435_200);
        let first = resolve(&output, t).unwrap_or_else(|e| panic!("{e:#}"));
        let second = resolve(&output, t).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(first, runs.join("2026-11-23T12-00-00"));
        assert_eq!(second, runs.join("2026-11-23T12-00-00-2"));
        assert_eq!(
            std::fs::read_link(runs.join("latest")).ok(),
            Some(PathBuf::from("2026-11-23T12-00-00-2"))
        );
        assert!(
            runs.join("latest-before-2026-11-23T12-00-00/frames.csv")
                .is_file()
        );
        // A fixed folder is used as it is, and `latest` is left alone.
        let fixed = runs.join("mine");
        let output = OutputConfig {
            run_dir: Some(fixed.clone()),
            ..output
        };
        assert_eq!(resolve(&output, t).ok(), Some(fixed.clone()));
        assert!(fixed.is_dir());
        assert_eq!(
            std::fs::read_link(runs.join("latest")).ok(),
            Some(PathBuf::from("2026-11-23T12-00-00-2"))
        );
    }
}
