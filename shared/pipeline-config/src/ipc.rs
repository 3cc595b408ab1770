//! `[ipc]`: where the shared memory's bookkeeping lives.

use crate::limits::not_empty_path;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Shared memory.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IpcConfig {
    /// The folder of iceoryx2's node and service descriptions (created owner-only). Unset:
    /// `$XDG_RUNTIME_DIR/linetrack-iceoryx2`, else `/dev/shm/linetrack-<uid>` (in
    /// memory: iceoryx2 syncs these files as it writes them, which a busy disk makes slow),
    /// else `/tmp/linetrack-<uid>/iceoryx2`. The environment variable `LINETRACK_IPC_ROOT`
    /// overrides it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub root: Option<PathBuf>,
}

impl IpcConfig {
    /// An empty or relative `root` (every stage must find the same folder).
    pub fn validate(&self) -> Result<(), String> {
        not_empty_path("ipc.root", self.root.as_deref())?;
        if let Some(root) = &self.root
            && !root.is_absolute()
        {
            return Err(format!(
                "ipc.root = {:?}: an absolute folder (every stage must find the same one)",
                root.display().to_string()
            ));
        }
        Ok(())
    }
}
