//! The crates that must build without OpenCV: what only reads the pipeline's configuration
//! (`linetrack-pipeline-config`) and the nodes that never look at pixels (the link, the
//! ROS 2 bridge), so that an onboard computer or a ground station that runs only them needs
//! no OpenCV and compiles none. Checked by `cargo xtask feature-drift` (which CI runs).
//!
//! How: `cargo tree -p <crate> --edges normal --all-features` lists what the crate's own
//! build compiles (no dev-dependencies, every optional feature on); `opencv` must not be
//! among it. On failure `cargo tree --invert opencv` names the chain that pulls it in.

use anyhow::{Context, bail};
use std::process::Command;

/// The crates that must not depend on OpenCV, with every feature of theirs on.
pub const CRATES: &[&str] = &[
    "linetrack-pipeline-config",
    "linetrack-link",
    "linetrack-ros2-bridge",
];

/// The package that must not appear in their trees.
const OPENCV: &str = "opencv";

/// Checks [`CRATES`]; `Ok(true)` when none depends on OpenCV, else `Ok(false)` after printing
/// each offender's chain.
pub fn check() -> anyhow::Result<bool> {
    let mut clean = true;
    for krate in CRATES {
        let tree = cargo_tree(krate, &[])?;
        if !depends_on(&tree, OPENCV) {
            eprintln!("xtask: feature-drift: {krate} builds without {OPENCV}");
            continue;
        }
        clean = false;
        let chain = cargo_tree(krate, &["--invert", OPENCV])?;
        eprintln!("xtask: feature-drift: {krate} depends on {OPENCV}, through:\n{chain}");
    }
    Ok(clean)
}

/// `cargo tree -p krate --edges normal --all-features` with `extra` arguments.
fn cargo_tree(krate: &str, extra: &[&str]) -> anyhow::Result<String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string());
    let output = Command::new(&cargo)
        .args([
            "tree",
            "--package",
            krate,
            "--edges",
            "normal",
            "--all-features",
        ])
        .args(extra)
        .output()
        .with_context(|| format!("cannot start {cargo} tree"))?;
    if !output.status.success() {
        bail!(
            "{cargo} tree --package {krate} failed: {}",
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    String::from_utf8(output.stdout).context("cargo tree printed something that is not UTF-8")
}

/// Whether the `cargo tree` output `tree` lists the package `name` (at any depth, under
/// the tree's drawing characters).
fn depends_on(tree: &str, name: &str) -> bool {
    tree.lines().any(|line| {
        line.split_whitespace()
            .find(|word| word.starts_with(|c: char| c.is_ascii_alphanumeric()))
            == Some(name)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const TREE: &str = "\
linetrack-link v0.1.0 (/src/services/link)
├── linetrack-stage-runtime v0.1.0 (/src/shared/stage-runtime)
│   └── linetrack-vision-config v0.1.0 (/src/shared/vision-config)
└── opencv-sys-free v1.0.0
";

    #[test]
    fn a_package_is_found_at_any_depth_by_its_whole_name() {
        assert!(depends_on(TREE, "linetrack-vision-config"));
        assert!(depends_on(TREE, "linetrack-link"));
        assert!(
            !depends_on(TREE, "opencv"),
            "a longer name is another package"
        );
        let deeper = format!("{TREE}    │   └── opencv v0.101.1\n");
        assert!(depends_on(&deeper, "opencv"));
    }
}
