//! The test tiers, each a `cargo xtask` command that prints its steps' wall times:
//!
//! - `cargo xtask test` — the README's test command: every unit, integration and
//!   end-to-end test of the default build (no optional feature), after building the
//!   binaries the end-to-end tests start.
//! - `cargo xtask test-features` — what the optional features `mcap` (recording, replay)
//!   and `link` (zenoh) add: the binaries rebuilt with them, then the tests of the crates
//!   whose code they change and the end-to-end tests that need them.
//! - `cargo xtask test-ros2` — the ROS 2 output (feature `ros2`) against a Cyclone DDS peer.
//!
//! The optional features' builds compile only what the features add: `tools/workspace-hack`
//! gives the shared dependencies the same features in every tier, and `cargo xtask
//! feature-drift` ([`crate::feature_drift`]) checks that it still does.
//!
//! Every tier builds with the `test-release` profile, so what one tier built the next one
//! (and `cargo xtask deb --check --profile test-release`, `cargo xtask cross
//! --native-profile test-release`, clippy with `--profile test-release`) reuses.

use crate::{cargo, install_system_packages, python_env};
use std::process::ExitCode;
use std::time::Instant;

/// The profile of every tier's build.
pub const PROFILE: &str = "test-release";

/// The features `cargo xtask test-features` turns on: MCAP recording and replay, the
/// ground-station link (zenoh), and the end-to-end tests that need them.
pub const FEATURES: &str = "linetrack/mcap,linetrack/link,linetrack-e2e/mcap,linetrack-e2e/link";

/// The features `cargo xtask test-ros2` turns on: the bridge's ROS 2 output and image
/// source, and the end-to-end tests that talk to them.
pub const ROS2_FEATURES: &str = "linetrack-ros2-bridge/ros2,linetrack-e2e/ros2";

/// The crates whose code the features change (their tests run again with them).
const FEATURE_PACKAGES: &[&str] = &[
    "linetrack",
    "linetrack-frame-source",
    "linetrack-link",
    "linetrack-recorder",
    "linetrack-supervisor",
];

/// The end-to-end test binaries that need the features (`required-features`).
const FEATURE_E2E_TESTS: &[&str] = &["link", "recording"];

/// A tier's steps, each timed; the times are printed as each ends and together at the end.
pub struct Steps {
    tier: &'static str,
    started: Instant,
    done: Vec<(String, f64)>,
}

impl Steps {
    pub fn new(tier: &'static str) -> Self {
        Steps {
            tier,
            started: Instant::now(),
            done: Vec::new(),
        }
    }

    /// Runs one step and records its wall time, whatever it returned.
    pub fn run<T>(&mut self, name: &str, step: impl FnOnce() -> T) -> T {
        let started = Instant::now();
        let result = step();
        let seconds = started.elapsed().as_secs_f64();
        eprintln!("xtask: {} / {name}: {seconds:.0} s", self.tier);
        self.done.push((name.to_string(), seconds));
        result
    }

    /// Runs the cargo commands one after the other, each a timed step, up to the first
    /// that fails; prints the summary and returns the first failure's code.
    pub fn cargo_steps(&mut self, steps: &[(&str, Vec<String>)]) -> anyhow::Result<ExitCode> {
        for (name, args) in steps {
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            let code = self.run(name, || cargo(&args, &[]))?;
            if code != ExitCode::SUCCESS {
                self.summary("failed");
                return Ok(code);
            }
        }
        self.summary("passed");
        Ok(ExitCode::SUCCESS)
    }

    /// Prints every step's time and the tier's total.
    pub fn summary(&self, verdict: &str) {
        eprintln!("xtask: {} {verdict}; wall time per step:", self.tier);
        for (name, seconds) in &self.done {
            eprintln!("  {name:<24} {seconds:>7.0} s");
        }
        eprintln!(
            "  {:<24} {:>7.0} s",
            "total",
            self.started.elapsed().as_secs_f64()
        );
    }
}

/// `cargo xtask test ARGS…`: the default build's whole suite.
pub fn default_suite(rest: &[String]) -> anyhow::Result<ExitCode> {
    let mut steps = Steps::new("test");
    steps.run("system packages", install_system_packages)?;
    let nextest = steps.run("find cargo-nextest", has_nextest);
    let real_data = real_data_present();
    let build = test_build(&[]);
    let tests = if nextest {
        let mut args = words(&["nextest", "run", "--workspace", "--cargo-profile", PROFILE]);
        if !real_data {
            args.extend(words(&["-E", "not test(/real_data/)"]));
        }
        args
    } else {
        eprintln!("xtask: cargo-nextest not found, running `cargo test` instead");
        let mut args = words(&["test", "--workspace", "--profile", PROFILE]);
        args.extend(rest.iter().cloned());
        if !real_data {
            args.extend(words(&["--", "--skip", "real_data"]));
        }
        return steps.cargo_steps(&[("build binaries", build), ("tests", args)]);
    };
    let tests = tests.into_iter().chain(rest.iter().cloned()).collect();
    steps.cargo_steps(&[("build binaries", build), ("tests", tests)])
}

/// `cargo xtask test-features ARGS…`: the binaries with MCAP and the link, and the tests
/// those features change or need.
pub fn feature_suite(rest: &[String]) -> anyhow::Result<ExitCode> {
    let mut steps = Steps::new("test-features");
    steps.run("system packages", install_system_packages)?;
    steps.run("MCAP checker", || python_env::MCAP_CHECKER.install())?;
    let real_data = real_data_present();
    let build = test_build(&["--features", FEATURES]);
    let mut tests = if steps.run("find cargo-nextest", has_nextest) {
        let mut filter = FEATURE_PACKAGES
            .iter()
            .map(|p| format!("package({p})"))
            .chain(
                FEATURE_E2E_TESTS
                    .iter()
                    .map(|t| format!("binary_id(linetrack-e2e::{t})")),
            )
            .collect::<Vec<_>>()
            .join(" | ");
        if !real_data {
            filter = format!("({filter}) & not test(/real_data/)");
        }
        let mut args = words(&["nextest", "run", "--workspace", "--cargo-profile", PROFILE]);
        args.extend(words(&["--features", FEATURES, "-E"]));
        args.push(filter);
        args
    } else {
        eprintln!("xtask: cargo-nextest not found, running `cargo test` instead");
        let mut args = words(&["test", "--profile", PROFILE, "--features", FEATURES]);
        for package in FEATURE_PACKAGES {
            args.extend(words(&["--package", package]));
        }
        let mut e2e = words(&[
            "test",
            "--profile",
            PROFILE,
            "--features",
            FEATURES,
            "--package",
            "linetrack-e2e",
        ]);
        for test in FEATURE_E2E_TESTS {
            e2e.extend(words(&["--test", test]));
        }
        return steps.cargo_steps(&[
            ("build binaries", build),
            ("crate tests", args),
            ("end-to-end tests", e2e),
        ]);
    };
    tests.extend(rest.iter().cloned());
    steps.cargo_steps(&[("build binaries", build), ("tests", tests)])
}

/// `cargo xtask test-ros2 ARGS…`: the binaries the end-to-end test starts, the bridge with
/// its `ros2` feature among them, then the bridge crate's tests and the end-to-end test in
/// one run. The whole workspace is built with [`ROS2_FEATURES`]: `tools/workspace-hack`
/// turns on the features ros2-client's dependencies add to shared crates, so this build
/// compiles only ros2-client and the bridge and reuses the default tier's binaries.
pub fn ros2_suite(rest: &[String]) -> anyhow::Result<ExitCode> {
    let mut steps = Steps::new("test-ros2");
    steps.run("system packages", install_system_packages)?;
    steps.run("DDS peer", || python_env::DDS_PEER.install())?;
    let nextest = steps.run("find cargo-nextest", has_nextest);
    let features = ["--features", ROS2_FEATURES];
    if !nextest {
        eprintln!("xtask: cargo-nextest not found, running `cargo test` instead");
        let mut bridge = words(&[
            "test",
            "--profile",
            PROFILE,
            "--package",
            "linetrack-ros2-bridge",
        ]);
        bridge.extend(words(&features));
        bridge.extend(rest.iter().cloned());
        let mut e2e = words(&["test", "--profile", PROFILE, "--package", "linetrack-e2e"]);
        e2e.extend(words(&features));
        e2e.extend(words(&["--test", "ros2"]));
        e2e.extend(rest.iter().cloned());
        return steps.cargo_steps(&[
            ("build binaries", test_build(&features)),
            ("bridge tests", bridge),
            ("end-to-end test", e2e),
        ]);
    }
    let mut tests = words(&["nextest", "run", "--workspace", "--cargo-profile", PROFILE]);
    tests.extend(words(&features));
    tests.extend(words(&[
        "-E",
        "package(linetrack-ros2-bridge) | binary_id(linetrack-e2e::ros2)",
    ]));
    tests.extend(rest.iter().cloned());
    steps.cargo_steps(&[("build binaries", test_build(&features)), ("tests", tests)])
}

/// The one build of the `test-release` binaries: every binary with every test target,
/// `extra` (features) added. Binaries and tests in one cargo call share one feature
/// resolution (dev-dependencies turn on features of shared crates, e.g. rand's `os_rng`,
/// rustix's `fs`): built apart, half the workspace was compiled twice. `cargo xtask deb
/// --profile test-release` and `cargo xtask cross --native-profile test-release` build
/// through this too, so they find the tests' binaries fresh. With `LINETRACK_BUILD_TIMINGS`
/// set, cargo writes its build report (`--timings`) to `target/cargo-timings/`.
pub fn test_build(extra: &[&str]) -> Vec<String> {
    let mut args = words(&[
        "build",
        "--workspace",
        "--bins",
        "--tests",
        "--profile",
        PROFILE,
    ]);
    // cargo's build report (which crate took how long, on how many cores) in
    // target/cargo-timings/, when asked for.
    if std::env::var_os("LINETRACK_BUILD_TIMINGS").is_some() {
        args.push("--timings".to_string());
    }
    args.extend(words(extra));
    args
}

fn words(words: &[&str]) -> Vec<String> {
    words.iter().map(|w| w.to_string()).collect()
}

pub fn has_nextest() -> bool {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string());
    std::process::Command::new(cargo)
        .args(["nextest", "--version"])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// The real data the `real_data_*` tests read: what it is, the environment variable that
/// names its folder, the default folder beside the workspace, and a file that must be in it.
const REAL_DATA: &[(&str, &str, &str, &str)] = &[
    (
        "EuRoC excerpt",
        "LINETRACK_EUROC_DIR",
        "../shared/data/euroc/V1_01_easy_micro",
        "mav0/cam0/data.csv",
    ),
    (
        "Middlebury pairs",
        "LINETRACK_MIDDLEBURY_DIR",
        "../shared/data/middlebury",
        "2001-2003/Tsukuba/imL.png",
    ),
    (
        "KITTI raw drive",
        "LINETRACK_KITTI_RAW_DIR",
        "../shared/data/kitti-raw/2011_09_26/2011_09_26_drive_0001_sync",
        "image_00/timestamps.txt",
    ),
];

/// Whether every real data set the `real_data_*` tests read is on this machine (each at its
/// environment variable, else beside the workspace). When one is not, says so: those
/// tests are left out and counted as skipped.
fn real_data_present() -> bool {
    let workspace = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut present = true;
    for (what, env, default, marker) in REAL_DATA {
        let dir = std::env::var_os(env)
            .map(std::path::PathBuf::from)
            .unwrap_or_else(|| workspace.join(default));
        if !dir.join(marker).is_file() {
            eprintln!(
                "xtask: {what} not found at {} (set {env}); the real_data tests are left out and reported as skipped",
                dir.display()
            );
            present = false;
        }
    }
    present
}
