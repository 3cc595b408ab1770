//! The DDS peer of the ROS 2 output's test: Eclipse Cyclone DDS's Python binding (PyPI
//! `cyclonedds`, its wheel carries the C library) in a virtual environment at
//! `target/dds-peer`, where `tests/tests/ros2.rs` looks for it. Installed by
//! `cargo xtask setup` and `cargo xtask test-ros2`; nothing is done when it is there.

use anyhow::{Context, bail};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The Debian packages it needs: Python and its `venv` module.
pub const SYSTEM_PACKAGES: &[&str] = &["python3", "python3-venv"];
/// The pinned binding.
const PACKAGE: &str = "cyclonedds==11.0.1";

/// The environment's folder: `target/dds-peer` (of `CARGO_TARGET_DIR` when set).
pub fn venv_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map_or_else(
            || Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target"),
            PathBuf::from,
        )
        .join("dds-peer")
}

/// Whether `python` imports the binding.
fn has_binding(python: &Path) -> bool {
    Command::new(python)
        .args(["-c", "import cyclonedds.domain"])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Makes the environment and installs the binding, unless it is there already.
pub fn install() -> anyhow::Result<()> {
    let dir = venv_dir();
    let python = dir.join("bin/python3");
    if has_binding(&python) {
        return Ok(());
    }
    eprintln!(
        "xtask: installing the DDS peer ({PACKAGE}) into {}",
        dir.display()
    );
    // Debian's Python (python3-venv is its venv module), else the one on PATH.
    let system = Path::new("/usr/bin/python3");
    let base = if system.is_file() {
        system.as_os_str()
    } else {
        "python3".as_ref()
    };
    let status = Command::new(base)
        .args(["-m", "venv", "--clear"])
        .arg(&dir)
        .status()
        .context("cannot run python3 -m venv")?;
    if !status.success() {
        bail!("python3 -m venv {} failed ({status})", dir.display());
    }
    let status = Command::new(&python)
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            PACKAGE,
        ])
        .status()
        .with_context(|| format!("cannot run {} -m pip", python.display()))?;
    if !status.success() {
        bail!(
            "pip install {PACKAGE} into {} failed ({status})",
            dir.display()
        );
    }
    if !has_binding(&python) {
        bail!(
            "{PACKAGE} installed into {} but `import cyclonedds.domain` fails",
            dir.display()
        );
    }
    Ok(())
}
