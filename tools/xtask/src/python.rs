//! `cargo xtask python [PYTEST ARGS…]`: the Python package (`bindings/python`) built, installed
//! and tested, each step timed:
//!
//! 1. the environment `target/python-env` with maturin, pytest and the tests' packages
//!    (pinned, [`python_env::PYTHON_PACKAGE`]), made once;
//! 2. the Rust CLI the tests compare with (`linetrack-match-pair`), by the same cargo call
//!    as `cargo xtask test`'s build ([`tiers::test_build`]), so after that tier it builds
//!    nothing;
//! 3. the bindings' formatting and lints (their own workspace: the main one's `cargo fmt`
//!    and clippy do not see them);
//! 4. the abi3 wheel, by maturin into `target/wheels/`, compiled in `target/python-bindings`
//!    (pyo3 and numpy never enter the main workspace's build);
//! 5. the wheel installed into the environment, replacing the last one;
//! 6. pytest on `bindings/python/tests`, with the CLI named by `LINETRACK_MATCH_PAIR`.

use crate::python_env::{self, target_dir};
use crate::tiers::{PROFILE, Steps, test_build};
use crate::{cargo, install_system_packages};
use anyhow::{Context, bail};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

/// The folder of the bindings' crate and tests, from the workspace root.
const BINDINGS: &str = "bindings/python";

/// Where the wheel is compiled, under the target folder.
const CARGO_FOLDER: &str = "python-bindings";

/// `cargo xtask python ARGS…`.
pub fn suite(rest: &[String]) -> anyhow::Result<ExitCode> {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let bindings = workspace.join(BINDINGS);
    let target = target_dir();
    let env_dir = target.join(python_env::PYTHON_PACKAGE.folder);
    let wheels = target.join("wheels");
    let mut steps = Steps::new("python");
    steps.run("system packages", install_system_packages)?;
    steps.run("Python environment", || {
        python_env::PYTHON_PACKAGE.install()
    })?;

    let build = test_build(&[]);
    let build: Vec<&str> = build.iter().map(String::as_str).collect();
    let manifest = bindings.join("Cargo.toml");
    let manifest = manifest.to_str().context("non-UTF-8 path")?;
    let bindings_target = target.join(CARGO_FOLDER);
    let in_bindings = |command: &mut Command| {
        command.env("CARGO_TARGET_DIR", &bindings_target);
    };
    let cargo_bin = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string());
    let checks: [(&str, Command); 2] = [
        ("fmt", {
            let mut c = Command::new(&cargo_bin);
            c.args(["fmt", "--check", "--manifest-path", manifest]);
            c
        }),
        ("clippy", {
            let mut c = Command::new(&cargo_bin);
            c.args(["clippy", "--all-targets", "--manifest-path", manifest]);
            c.args(["--", "-D", "warnings"]);
            in_bindings(&mut c);
            c
        }),
    ];
    if steps.run("build CLI", || cargo(&build, &[]))? != ExitCode::SUCCESS {
        steps.summary("failed");
        return Ok(ExitCode::FAILURE);
    }
    for (name, mut command) in checks {
        if !steps.run(name, || succeeds(&mut command))? {
            steps.summary("failed");
            return Ok(ExitCode::FAILURE);
        }
    }

    let python = env_dir.join("bin/python3");
    let wheel = steps.run("wheel", || {
        build_wheel(&env_dir, &python, manifest, &wheels, &bindings_target)
    })?;
    let mut install = Command::new(&python);
    install.args([
        "-m",
        "pip",
        "install",
        "--quiet",
        "--disable-pip-version-check",
    ]);
    install.args(["--force-reinstall", "--no-deps"]).arg(&wheel);
    if !steps.run("install wheel", || succeeds(&mut install))? {
        steps.summary("failed");
        return Ok(ExitCode::FAILURE);
    }

    let mut pytest = Command::new(&python);
    pytest
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
        .arg(bindings.join("tests"))
        .args(rest)
        .env(
            "LINETRACK_MATCH_PAIR",
            target.join(PROFILE).join("linetrack-match-pair"),
        );
    let passed = steps.run("pytest", || succeeds(&mut pytest))?;
    steps.summary(if passed { "passed" } else { "failed" });
    Ok(if passed {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// Builds the wheel with the environment's maturin into `wheels` (old `linetrack-*.whl`
/// removed first); returns its path.
fn build_wheel(
    env_dir: &Path,
    python: &Path,
    manifest: &str,
    wheels: &Path,
    cargo_target: &Path,
) -> anyhow::Result<PathBuf> {
    let ours = |path: &Path| {
        path.file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with("linetrack-") && n.ends_with(".whl"))
    };
    let listed = |dir: &Path| -> anyhow::Result<Vec<PathBuf>> {
        Ok(match std::fs::read_dir(dir) {
            Ok(entries) => entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| ours(p))
                .collect(),
            Err(_) => Vec::new(),
        })
    };
    for old in listed(wheels)? {
        std::fs::remove_file(&old).with_context(|| format!("cannot remove {}", old.display()))?;
    }
    let mut maturin = Command::new(env_dir.join("bin/maturin"));
    maturin
        .args(["build", "--release", "--quiet", "--manifest-path", manifest])
        .arg("--out")
        .arg(wheels)
        .arg("--interpreter")
        .arg(python)
        .env("CARGO_TARGET_DIR", cargo_target);
    if !succeeds(&mut maturin)? {
        bail!("maturin build failed");
    }
    match listed(wheels)?.as_slice() {
        [wheel] => Ok(wheel.clone()),
        found => bail!(
            "maturin built {} linetrack wheels into {}, expected one",
            found.len(),
            wheels.display()
        ),
    }
}

/// Runs `command`; whether it exited 0.
fn succeeds(command: &mut Command) -> anyhow::Result<bool> {
    let status = command
        .status()
        .with_context(|| format!("cannot start {:?}", command.get_program()))?;
    Ok(status.success())
}
