//! The Python tools some tests run as independent peers, each pinned in its own virtual
//! environment under the target folder, where the tests look for it: the MCAP checker
//! (`target/mcap-check`, PyPI `mcap`) and the DDS peer of the ROS 2 output's test
//! (`target/dds-peer`, Eclipse Cyclone DDS's Python binding, whose wheel carries the C
//! library); and the Python package's build and test environment (`target/python-env`).
//! Nothing is done when an environment already imports its modules.

use anyhow::{Context, bail};
use std::path::{Path, PathBuf};
use std::process::Command;

/// One tool: where it lives, what it installs and what proves it is there.
pub struct PythonTool {
    /// What it is, for messages.
    pub name: &'static str,
    /// Its folder under the target folder.
    pub folder: &'static str,
    /// The pinned PyPI packages.
    pub packages: &'static [&'static str],
    /// A Python statement that succeeds once they are installed.
    pub check: &'static str,
}

/// The independent MCAP checker the recording tests run (`tests/scripts/check_mcap.py`):
/// the PyPI `mcap` reader and its protobuf decoder.
pub const MCAP_CHECKER: PythonTool = PythonTool {
    name: "the MCAP checker",
    folder: "mcap-check",
    packages: &["mcap==1.6.0", "mcap-protobuf-support==0.6.0"],
    check: "import mcap, mcap_protobuf",
};

/// The DDS peer of `tests/tests/ros2.rs`.
pub const DDS_PEER: PythonTool = PythonTool {
    name: "the DDS peer",
    folder: "dds-peer",
    packages: &["cyclonedds==11.0.1"],
    check: "import cyclonedds.domain",
};

/// The Python package's build and test environment (`cargo xtask python`): maturin, pytest,
/// and what the tests and the README example import (numpy, Pillow, matplotlib).
pub const PYTHON_PACKAGE: PythonTool = PythonTool {
    name: "the Python package's build and test environment",
    folder: "python-env",
    packages: &[
        "maturin==1.16.0",
        "pytest==9.2.0",
        "numpy==2.4.6",
        "pillow==13.0.0",
        "matplotlib==3.11.2",
    ],
    check: "import maturin, pytest, numpy, PIL, matplotlib",
};

/// The target folder (`CARGO_TARGET_DIR` when set).
pub fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target"),
        PathBuf::from,
    )
}

impl PythonTool {
    /// Makes the environment and installs the packages, unless it imports them already.
    pub fn install(&self) -> anyhow::Result<()> {
        let dir = target_dir().join(self.folder);
        let python = dir.join("bin/python3");
        let ready = || {
            Command::new(&python)
                .args(["-c", self.check])
                .output()
                .is_ok_and(|o| o.status.success())
        };
        if ready() {
            return Ok(());
        }
        let packages = self.packages.join(" ");
        eprintln!(
            "xtask: installing {} ({packages}) into {}",
            self.name,
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
            ])
            .args(self.packages)
            .status()
            .with_context(|| format!("cannot run {} -m pip", python.display()))?;
        if !status.success() {
            bail!(
                "pip install {packages} into {} failed ({status})",
                dir.display()
            );
        }
        if !ready() {
            bail!(
                "{packages} installed into {} but `{}` fails",
                dir.display(),
                self.check
            );
        }
        Ok(())
    }
}
