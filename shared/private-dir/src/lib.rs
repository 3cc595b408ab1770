//! Folders no other user can subvert: a run's folder (`linetrack run`'s records) and the
//! root of iceoryx2's bookkeeping (the shared-memory root) are reached through
//! [`private_dir`], which resolves the path one component at a time from `/`:
//!
//! - a link on the way is followed only when this user or root owns it (another user's
//!   link in `/tmp` could point anywhere);
//! - every folder above the target belongs to this user or root, and is writable by group
//!   or others only when it is sticky (`/tmp`: others may add names there but not move or
//!   delete this user's);
//! - the target folder belongs to this user and is writable by nobody else;
//! - missing folders are created owner-only (mode 0700) with `mkdir`, which never follows a
//!   link planted at the new name.
//!
//! The path returned has no link left in it and no folder another user could change, so
//! whatever the caller opens below it later is what was checked. Errors name the path.

use std::ffi::OsString;
use std::os::unix::fs::{DirBuilderExt as _, MetadataExt as _, OpenOptionsExt as _};
use std::path::{Component, Path, PathBuf};

/// Permission bits of a folder this crate creates: the owner's only.
pub const DIR_MODE: u32 = 0o700;
/// Links followed while resolving one path (as the kernel's `MAXSYMLINKS`).
const MAX_LINKS: usize = 40;
/// The write bits of group and others.
const WRITABLE_BY_OTHERS: u32 = 0o022;
/// The sticky bit: others' names in the folder cannot be moved or deleted by another user.
const STICKY: u32 = 0o1000;
/// Root's uid: what root owns, root could change anyway.
const ROOT: u32 = 0;

/// Why a folder was refused.
#[derive(Debug, thiserror::Error)]
pub enum DirError {
    /// A folder or a link on the way belongs to another user.
    #[error(
        "{}: belongs to user {owner}, not to this user ({me}) or root: another user could put anything there; choose a folder of yours",
        path.display()
    )]
    ForeignOwner {
        /// The folder or link.
        path: PathBuf,
        /// Its owner.
        owner: u32,
        /// This user.
        me: u32,
    },
    /// The folder, or a folder above it that is not sticky, is writable by other users.
    #[error(
        "{}: writable by other users (mode {mode:o}){}",
        path.display(),
        if *target { "; make it 0700 or choose another folder" } else { " and not sticky: another user could replace what is below it" }
    )]
    OpenToOthers {
        /// The folder.
        path: PathBuf,
        /// Its permission bits.
        mode: u32,
        /// Whether it is the folder asked for (not one above it).
        target: bool,
    },
    /// Something other than a folder where a folder must be.
    #[error("{}: not a folder", path.display())]
    NotAFolder {
        /// The path.
        path: PathBuf,
    },
    /// More links than the kernel would follow.
    #[error("{}: more than {MAX_LINKS} links on the way", path.display())]
    TooManyLinks {
        /// The path asked for.
        path: PathBuf,
    },
    /// The file system refused (the OS error is the source).
    #[error("{}", path.display())]
    Io {
        /// The path.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

/// Whether missing folders are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Create {
    /// Missing folders (the target and those above it) are created, mode 0700.
    Missing,
    /// A missing folder is an error.
    No,
}

/// Who may own what: this user (the effective uid).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Owner {
    /// This user's uid.
    pub me: u32,
}

impl Owner {
    /// The user this process runs as.
    pub fn current() -> Self {
        Self {
            me: rustix::process::geteuid().as_raw(),
        }
    }

    fn trusted(self, uid: u32) -> bool {
        uid == self.me || uid == ROOT
    }
}

/// `path` (relative to the current folder when relative) as a folder no other user can
/// subvert (see the crate's documentation), created when missing and `create` says so;
/// returns it with every link resolved.
pub fn private_dir(path: &Path, create: Create) -> Result<PathBuf, DirError> {
    private_dir_for(path, create, Owner::current())
}

/// [`private_dir`] for the user `owner`.
pub fn private_dir_for(path: &Path, create: Create, owner: Owner) -> Result<PathBuf, DirError> {
    let io = |at: &Path| {
        let at = at.to_path_buf();
        move |source| DirError::Io { path: at, source }
    };
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().map_err(io(path))?.join(path)
    };
    let mut pending: Vec<OsString> = components(&absolute);
    pending.reverse();
    let mut resolved = PathBuf::from("/");
    check_folder(&resolved, &lstat(&resolved)?, false, owner)?;
    let mut links = 0;
    while let Some(name) = pending.pop() {
        if name == ".." {
            // `resolved` holds no link: its parent is the real one.
            resolved.pop();
            continue;
        }
        let next = resolved.join(&name);
        let meta = match std::fs::symlink_metadata(&next) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound && create == Create::Missing => {
                match std::fs::DirBuilder::new().mode(DIR_MODE).create(&next) {
                    Ok(()) => {}
                    // Made by someone else meanwhile: judged below like any other.
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                    Err(e) => return Err(io(&next)(e)),
                }
                lstat(&next)?
            }
            other => other.map_err(io(&next))?,
        };
        if meta.file_type().is_symlink() {
            if !owner.trusted(meta.uid()) {
                return Err(DirError::ForeignOwner {
                    path: next,
                    owner: meta.uid(),
                    me: owner.me,
                });
            }
            links += 1;
            if links > MAX_LINKS {
                return Err(DirError::TooManyLinks {
                    path: path.to_path_buf(),
                });
            }
            let target = std::fs::read_link(&next).map_err(io(&next))?;
            if target.is_absolute() {
                resolved = PathBuf::from("/");
            }
            pending.extend(components(&target).into_iter().rev());
            continue;
        }
        check_folder(&next, &meta, pending.is_empty(), owner)?;
        resolved = next;
    }
    // The target itself, opened without following a link: still the folder checked.
    let checked = lstat(&resolved)?;
    let opened = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_DIRECTORY | libc::O_CLOEXEC)
        .open(&resolved)
        .and_then(|dir| dir.metadata())
        .map_err(io(&resolved))?;
    if (opened.dev(), opened.ino()) != (checked.dev(), checked.ino()) {
        return Err(io(&resolved)(std::io::Error::other(
            "replaced while it was being checked",
        )));
    }
    check_folder(&resolved, &opened, true, owner)?;
    Ok(resolved)
}

/// The names of `path`'s components (`/` and `.` left out, `..` kept).
fn components(path: &Path) -> Vec<OsString> {
    path.components()
        .filter_map(|c| match c {
            Component::Normal(name) => Some(name.to_os_string()),
            Component::ParentDir => Some(OsString::from("..")),
            Component::RootDir | Component::CurDir | Component::Prefix(_) => None,
        })
        .collect()
}

fn lstat(path: &Path) -> Result<std::fs::Metadata, DirError> {
    std::fs::symlink_metadata(path).map_err(|source| DirError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// A folder on the way (`target`: the one asked for) passes the rules of the crate.
fn check_folder(
    path: &Path,
    meta: &std::fs::Metadata,
    target: bool,
    owner: Owner,
) -> Result<(), DirError> {
    if !meta.is_dir() {
        return Err(DirError::NotAFolder {
            path: path.to_path_buf(),
        });
    }
    let owned = if target {
        meta.uid() == owner.me
    } else {
        owner.trusted(meta.uid())
    };
    if !owned {
        return Err(DirError::ForeignOwner {
            path: path.to_path_buf(),
            owner: meta.uid(),
            me: owner.me,
        });
    }
    let mode = meta.mode() & 0o7777;
    let open = mode & WRITABLE_BY_OTHERS != 0;
    if open && (target || mode & STICKY == 0) {
        return Err(DirError::OpenToOthers {
            path: path.to_path_buf(),
            mode,
            target,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests;
