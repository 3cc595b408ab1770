//! [`Scope`]: where a run's shared-memory resources live and how they are named, found,
//! locked down to their owner and removed.

use crate::{IpcError, setup, transfer};
use iceoryx2::config::Config;
use iceoryx2::node::Node;
use iceoryx2::prelude::Path as IoxPath;
use iceoryx2::prelude::{FileName, SemanticString, ipc};
use std::fmt::Debug;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};

/// Where a run's shared-memory resources live: every file is named with `prefix`, every
/// service with `run_id`, so runs (and tests) side by side never meet, and a run's leftovers
/// are found by prefix. Both the prefix and the root folder of iceoryx2's bookkeeping
/// belong to the user who runs the pipeline (`linetrack_u<uid>_`, `$XDG_RUNTIME_DIR` or
/// `/dev/shm/linetrack-<uid>`), so runs of different users never block each other, and
/// [`Scope::lock_down`] keeps every file of the scope readable and writable by its owner
/// only.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Scope {
    /// File-name prefix of the iceoryx2 resources (`linetrack_u<uid>_` unless
    /// `LINETRACK_IPC_PREFIX` says otherwise).
    pub prefix: String,
    /// The run.
    pub run_id: String,
    /// The folder of iceoryx2's node and service descriptions (`LINETRACK_IPC_ROOT`, else
    /// `$XDG_RUNTIME_DIR/linetrack-iceoryx2`, else `/dev/shm/linetrack-<uid>`, or
    /// `/tmp/…` without `/dev/shm`).
    pub root: PathBuf,
}

/// Where POSIX shared memory lives on Linux.
pub(crate) const SHM_DIR: &str = "/dev/shm";

/// The longest path a unix socket may have (`sun_path`, less its closing NUL).
pub(crate) const SOCKET_PATH_MAX: usize = 107;
/// What iceoryx2 adds to the root folder and the prefix for an event's socket: `/`, a
/// decimal 128-bit hash (up to 39 digits) and `.event`.
pub(crate) const EVENT_SOCKET_SUFFIX: usize = 1 + 39 + ".event".len();

impl Scope {
    /// The environment variable that overrides the prefix.
    pub const PREFIX_VAR: &'static str = "LINETRACK_IPC_PREFIX";
    /// The environment variable that overrides the root folder.
    pub const ROOT_VAR: &'static str = "LINETRACK_IPC_ROOT";

    /// A scope for `run_id` with the prefix from the environment or this user's default.
    pub fn new(run_id: &str) -> Self {
        let prefix = std::env::var(Self::PREFIX_VAR)
            .ok()
            .filter(|p| !p.is_empty())
            .unwrap_or_else(|| format!("linetrack_u{}_", rustix::process::getuid().as_raw()));
        Self::with_prefix(&prefix, run_id)
    }

    /// This scope with its root folder from the config (see [`Scope::root_from`]).
    pub fn with_configured_root(mut self, configured: Option<&Path>) -> Self {
        self.root = Self::root_from(configured);
        self
    }

    /// This scope with an explicit root folder (`linetrack ctl` reaching a recorded run).
    pub fn with_root(mut self, root: PathBuf) -> Self {
        self.root = root;
        self
    }

    /// A scope with an explicit prefix (tests, `linetrack ctl` reaching a recorded run).
    pub fn with_prefix(prefix: &str, run_id: &str) -> Self {
        Self {
            prefix: prefix.to_string(),
            run_id: run_id.to_string(),
            root: Self::default_root(),
        }
    }

    /// This user's root folder for iceoryx2's bookkeeping.
    pub fn default_root() -> PathBuf {
        Self::root_from(None)
    }

    /// The root folder: `LINETRACK_IPC_ROOT`, else `configured` (the config's `ipc.root`),
    /// else `$XDG_RUNTIME_DIR/linetrack-iceoryx2`, else `/dev/shm/linetrack-<uid>`
    /// (in memory), or `/tmp/linetrack-<uid>/iceoryx2` on a system without `/dev/shm`.
    pub fn root_from(configured: Option<&Path>) -> PathBuf {
        let from_env = |var: &str| {
            std::env::var_os(var)
                .filter(|v| !v.is_empty())
                .map(PathBuf::from)
        };
        from_env(Self::ROOT_VAR)
            .or_else(|| configured.map(Path::to_path_buf))
            .or_else(|| {
                from_env("XDG_RUNTIME_DIR")
                    .filter(|dir| dir.is_dir())
                    .map(|dir| dir.join("linetrack-iceoryx2"))
            })
            .unwrap_or_else(|| {
                // In memory when it can be: iceoryx2 syncs each node's and service's
                // description to its file as it creates it, and on a busy disk such a
                // sync held a starting stage for seconds (a hot swap's standby, while LSD
                // missed every frame); on tmpfs a sync costs nothing.
                // There the folder is the root itself (no `iceoryx2` below it): the root's
                // length comes out of the room iceoryx2's socket paths have.
                let uid = rustix::process::getuid().as_raw();
                let memory = Path::new(SHM_DIR);
                if memory.is_dir() {
                    memory.join(format!("linetrack-{uid}"))
                } else {
                    PathBuf::from(format!("/tmp/linetrack-{uid}/iceoryx2"))
                }
            })
    }

    /// The iceoryx2 configuration of this scope (the root folder is created, owner-only,
    /// when missing).
    pub fn config(&self) -> Result<Config, IpcError> {
        let root = self.root.to_string_lossy();
        let socket_len = root.trim_end_matches('/').len() + self.prefix.len() + EVENT_SOCKET_SUFFIX;
        if socket_len > SOCKET_PATH_MAX {
            return Err(setup("iceoryx2 root folder", &root)(format!(
                "too long for iceoryx2's event sockets: the folder and the prefix {:?} take {} bytes \
                 of a socket path's {SOCKET_PATH_MAX}, {EVENT_SOCKET_SUFFIX} are needed after them; \
                 choose a shorter folder (`[ipc] root` in the config, or {})",
                self.prefix,
                socket_len - EVENT_SOCKET_SUFFIX,
                Self::ROOT_VAR
            )));
        }
        private_dir(&self.root).map_err(|message| setup("iceoryx2 root folder", &root)(message))?;
        let mut config = Config::default();
        config.global.prefix = FileName::new(self.prefix.as_bytes())
            .map_err(|e| setup("iceoryx2 prefix", &self.prefix)(format!("{e:?}")))?;
        let with_slash = format!("{}/", root.trim_end_matches('/'));
        let path = IoxPath::new(with_slash.as_bytes())
            .map_err(|e| setup("iceoryx2 root folder", &root)(format!("{e:?}")))?;
        config.global.set_root_path(&path);
        Ok(config)
    }

    /// Checks the scope's shared-memory files: one owned by another user is an error naming
    /// it (it would lock this user's runs out); one that others may read or write is made
    /// owner-only (iceoryx2 creates its global management segment world-writable).
    /// Returns how many files were tightened.
    pub fn lock_down(&self) -> Result<usize, IpcError> {
        lock_down_files(
            Path::new(SHM_DIR),
            &self.prefix,
            rustix::process::getuid().as_raw(),
        )
        .map_err(|message| setup("locking down shared memory", &self.prefix)(message))
    }
}

/// [`Scope::lock_down`] over the files of `dir` whose names start with `prefix`, for user `me`.
pub(crate) fn lock_down_files(dir: &Path, prefix: &str, me: u32) -> Result<usize, String> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut tightened = 0;
    for entry in entries.flatten() {
        if !entry.file_name().to_string_lossy().starts_with(prefix) {
            continue;
        }
        let path = entry.path();
        // A file that went away between listing and reading belonged to a node that ended.
        let Ok(meta) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        if meta.uid() != me {
            return Err(format!(
                "{} belongs to user {}, not to this user ({me}): another user's file in this \
                 user's namespace; remove it or set {} to another prefix",
                path.display(),
                meta.uid(),
                Scope::PREFIX_VAR
            ));
        }
        if meta.mode() & 0o077 != 0 {
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600))
                .map_err(|e| format!("{}: {e}", path.display()))?;
            tightened += 1;
        }
    }
    Ok(tightened)
}

/// Makes sure `dir` is a folder only this user can change, reached through folders and
/// links no other user can change ([`linetrack_private_dir`]): created (mode 0700, parents
/// too) when missing; refused, naming the path, when it or a folder or link above it is
/// another user's, or writable by others.
pub(crate) fn private_dir(dir: &Path) -> Result<(), String> {
    linetrack_private_dir::private_dir(dir, linetrack_private_dir::Create::Missing)
        .map(|_| ())
        .map_err(|e| {
            let cause = std::error::Error::source(&e)
                .map(|source| format!(": {source}"))
                .unwrap_or_default();
            format!("{e}{cause} (set {} to a folder of yours)", Scope::ROOT_VAR)
        })
}

/// iceoryx2 resources left in a scope: nodes (alive or dead) and services.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Resources {
    /// Nodes registered under the prefix.
    pub nodes: usize,
    /// Services whose static description exists under the prefix.
    pub services: usize,
}

impl Scope {
    /// Counts the nodes and services that exist under this scope's prefix (of any run).
    pub fn resources(&self) -> Result<Resources, IpcError> {
        use iceoryx2::prelude::{CallbackProgression, Service as _};
        let config = self.config()?;
        let mut found = Resources::default();
        Node::<ipc::Service>::list(&config, |_| {
            found.nodes += 1;
            CallbackProgression::Continue
        })
        .map_err(|e| transfer("listing nodes", &self.prefix)(format!("{e:?}")))?;
        ipc::Service::list(&config, |_| {
            found.services += 1;
            CallbackProgression::Continue
        })
        .map_err(|e| transfer("listing services", &self.prefix)(format!("{e:?}")))?;
        Ok(found)
    }
}

impl Scope {
    /// Counts the nodes of processes that died without removing their resources.
    pub fn dead_nodes(&self) -> Result<usize, IpcError> {
        use iceoryx2::prelude::{CallbackProgression, NodeState};
        let config = self.config()?;
        let mut dead = 0;
        Node::<ipc::Service>::list(&config, |state| {
            if matches!(state, NodeState::Dead(_)) {
                dead += 1;
            }
            CallbackProgression::Continue
        })
        .map_err(|e| transfer("listing nodes", &self.prefix)(format!("{e:?}")))?;
        Ok(dead)
    }
}
