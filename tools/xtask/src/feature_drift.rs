//! `cargo xtask feature-drift`: fails when building with an optional feature would
//! compile a shared dependency again with other features, and when a crate that must build
//! without OpenCV depends on it ([`crate::opencv_free`]).
//!
//! cargo compiles a crate once per feature set, and everything above it with it. When
//! zenoh (`link`), MCAP or ros2-client turn on a feature of a crate the whole workspace
//! uses (tracing-core, rustix, syn…), the feature tiers recompile most of the workspace:
//! minutes of every cold CI run. `tools/workspace-hack` turns those features on in every
//! build; this check keeps it complete.
//!
//! How: `cargo tree` lists each dependency with its features, once per feature set it is
//! built with (build-time and run-time copies apart when they differ). A dependency copy
//! of the default build whose exact feature set no longer appears with the optional
//! features is one that would be rebuilt. Copies the features add (new crates, new
//! build-time copies) are expected and not reported. The comparison is made twice: on the
//! run-time dependencies alone (no build dependencies, no procedural macros), then on
//! everything, which adds the build-time copies. A package built twice with the same
//! features shows once, so a change to one of two identical build-time copies can still go
//! unseen: the check catches drift, it does not prove its absence.

use anyhow::{Context, bail};
use std::collections::{BTreeMap, BTreeSet};
use std::process::{Command, ExitCode};

/// The optional feature sets CI builds, each compared with the default build.
pub const FEATURE_SETS: &[(&str, &str)] = &[
    ("test-features", crate::tiers::FEATURES),
    ("test-ros2", crate::tiers::ROS2_FEATURES),
];

/// A dependency whose features differ between the default build and a feature set.
#[derive(Debug, PartialEq)]
pub struct Drift {
    /// `name vX.Y.Z`.
    pub package: String,
    /// The default build's feature sets of the package that the feature build lacks.
    pub lost: Vec<String>,
    /// The feature build's sets of the package.
    pub with_features: Vec<String>,
}

/// Runs `cargo xtask feature-drift`.
pub fn run(rest: &[String]) -> anyhow::Result<ExitCode> {
    if let Some(arg) = rest.first() {
        if arg == "-h" || arg == "--help" {
            println!(
                "usage: cargo xtask feature-drift\n  fails, naming the crates, when an optional feature set ({}) changes the features of a dependency the default build compiles (add them to tools/workspace-hack), or when one of {} depends on OpenCV",
                FEATURE_SETS
                    .iter()
                    .map(|(name, _)| *name)
                    .collect::<Vec<_>>()
                    .join(", "),
                crate::opencv_free::CRATES.join(", ")
            );
            return Ok(ExitCode::SUCCESS);
        }
        bail!("cargo xtask feature-drift takes no arguments (got {arg:?})");
    }
    // Run-time copies alone first: a build-time copy with the same features would hide a
    // change to them from the second comparison.
    const EDGES: [&str; 2] = ["normal,dev,no-proc-macro", "normal,build,dev"];
    let defaults = EDGES.map(|edges| tree(edges, None));
    let mut failed = false;
    for (tier, features) in FEATURE_SETS {
        let mut drift: Vec<Drift> = Vec::new();
        for (edges, default) in EDGES.iter().zip(&defaults) {
            let default = default.as_ref().map_err(|e| anyhow::anyhow!("{e:#}"))?;
            for d in compare(default, &tree(edges, Some(features))?) {
                if !drift.iter().any(|seen| seen.package == d.package) {
                    drift.push(d);
                }
            }
        }
        if drift.is_empty() {
            eprintln!("xtask: feature-drift: {tier} ({features}) shares every dependency");
            continue;
        }
        failed = true;
        eprintln!("xtask: feature-drift: {tier} ({features}) would rebuild:");
        for d in &drift {
            eprintln!(
                "  {}: default build [{}], with the features [{}]",
                d.package,
                d.lost.join("] ["),
                d.with_features.join("] [")
            );
        }
    }
    if failed {
        eprintln!(
            "xtask: feature-drift: add the features these crates gain to tools/workspace-hack/Cargo.toml"
        );
    }
    if !crate::opencv_free::check()? {
        failed = true;
        eprintln!(
            "xtask: feature-drift: these crates must build without OpenCV: move what they use into an OpenCV-free crate (as the configs are in linetrack-vision-config and linetrack-odometry-config) or behind a feature they leave off"
        );
    }
    Ok(if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    })
}

/// `cargo tree` of the workspace's test build (the dependency kinds `edges` names) with
/// `features`: one line per dependency copy, `name vX.Y.Z features`.
fn tree(edges: &str, features: Option<&str>) -> anyhow::Result<String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string());
    let mut command = Command::new(&cargo);
    command.args([
        "tree",
        "--workspace",
        "--edges",
        edges,
        "--format",
        "{p} {f}",
        "--prefix",
        "none",
    ]);
    if let Some(features) = features {
        command.args(["--features", features]);
    }
    let output = command
        .output()
        .with_context(|| format!("cannot start {cargo} tree"))?;
    if !output.status.success() {
        bail!(
            "{cargo} tree{} failed: {}",
            features
                .map(|f| format!(" --features {f}"))
                .unwrap_or_default(),
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    String::from_utf8(output.stdout).context("cargo tree printed something that is not UTF-8")
}

/// Feature sets per third-party package (`name vX.Y.Z`) in `cargo tree` output. Workspace
/// packages (a path after the version) are left out: their features are the point.
fn feature_sets(tree: &str) -> BTreeMap<String, BTreeSet<String>> {
    let mut sets: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for line in tree.lines() {
        // `(*)` marks a repeated subtree; `(proc-macro)` a kind; neither is a feature.
        let words: Vec<&str> = line
            .split_whitespace()
            .filter(|w| !(w.starts_with('(') && w.ends_with(')')))
            .collect();
        let [name, version, rest @ ..] = words.as_slice() else {
            continue;
        };
        if line.contains(" (/") || line.contains(" (file://") {
            continue;
        }
        let features = rest.first().copied().unwrap_or("").to_string();
        sets.entry(format!("{name} {version}"))
            .or_default()
            .insert(features);
    }
    sets
}

/// The packages of `default` with a feature set that `with_features` does not have.
pub fn compare(default: &str, with_features: &str) -> Vec<Drift> {
    let before = feature_sets(default);
    let after = feature_sets(with_features);
    let mut drift = Vec::new();
    for (package, sets) in &before {
        let Some(now) = after.get(package) else {
            // Not in the feature build at all: cargo tree resolved it away (cannot happen
            // for a build that only adds features), nothing would be rebuilt.
            continue;
        };
        let lost: Vec<String> = sets.difference(now).cloned().collect();
        if !lost.is_empty() {
            drift.push(Drift {
                package: package.clone(),
                lost,
                with_features: now.iter().cloned().collect(),
            });
        }
    }
    drift
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEFAULT: &str = "\
linetrack v0.1.0 (/src/tools/linetrack)
tracing-core v0.1.36 once_cell,std
syn v3.0.9 clone-impls,derive (proc-macro)
memchr v2.8.3 alloc,std
memchr v2.8.3 alloc,std (*)
itoa v1.0.15
";

    #[test]
    fn added_crates_and_added_copies_are_not_drift() {
        let with = format!(
            "{DEFAULT}zenoh v1.5.0 default\nmemchr v2.8.3 alloc\nlinetrack v0.1.0 (/src/tools/linetrack) link\n"
        );
        assert_eq!(compare(DEFAULT, &with), Vec::new());
    }

    #[test]
    fn a_shared_crate_with_more_features_is_named_with_both_sets() {
        let with = DEFAULT.replace("once_cell,std", "default,once_cell,std");
        assert_eq!(
            compare(DEFAULT, &with),
            vec![Drift {
                package: "tracing-core v0.1.36".to_string(),
                lost: vec!["once_cell,std".to_string()],
                with_features: vec!["default,once_cell,std".to_string()],
            }]
        );
    }

    #[test]
    fn a_featureless_crate_gaining_one_and_a_procedural_macros_dependency_are_seen() {
        let with = DEFAULT
            .replace("itoa v1.0.15", "itoa v1.0.15 std")
            .replace("clone-impls,derive", "clone-impls,derive,visit-mut");
        let packages: Vec<String> = compare(DEFAULT, &with)
            .into_iter()
            .map(|d| d.package)
            .collect();
        assert_eq!(packages, ["itoa v1.0.15", "syn v3.0.9"]);
    }

    #[test]
    fn workspace_packages_are_not_compared() {
        let with = DEFAULT.replace(
            "linetrack v0.1.0 (/src/tools/linetrack)",
            "linetrack v0.1.0 (/src/tools/linetrack) link,mcap",
        );
        assert_eq!(compare(DEFAULT, &with), Vec::new());
    }
}
