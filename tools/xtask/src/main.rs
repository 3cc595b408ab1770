//! `cargo xtask <command>`: the project's user-facing commands, with setup included.
//!
//! - `cargo xtask demo [ARGS…]` — install system packages if missing, build the pipeline's
//!   binaries and run `linetrack run ARGS…`: the multi-process pipeline on the default
//!   generated sequence (`cargo xtask demo --help` lists the options).
//! - `cargo xtask match-demo [ARGS…]` — the ℓ1 matcher demo on one scene and one stereo pair.
//! - `cargo xtask test [ARGS…]` — install system packages if missing, build the binaries the
//!   end-to-end tests start, then run every test of the default build (no optional
//!   feature) with cargo-nextest (or `cargo test` where nextest is not installed).
//! - `cargo xtask test-features [ARGS…]` — the same for what the `mcap` and `link` features
//!   add ([`tiers`]).
//! - `cargo xtask test-ros2 [ARGS…]` — the ROS 2 output (cargo feature `ros2`): install the
//!   DDS peer if missing ([`python_env`]), build `linetrack-ros2`, run its crate's tests and
//!   the end-to-end test in which Cyclone DDS receives the poses.
//! - `cargo xtask python [ARGS…]` — the Python package (`bindings/python`): its wheel built
//!   into a virtual environment under the target folder, installed, its pytest suite run
//!   (ARGS are pytest's) ([`python`]).
//! - `cargo xtask feature-drift` — fails when an optional feature set would compile a
//!   shared dependency with other features than the default build ([`feature_drift`]), or
//!   when a crate that must build without OpenCV depends on it ([`opencv_free`]).
//!
//! The test commands print each step's wall time.
//! - `cargo xtask setup` — only install the system packages, the MCAP checker and the DDS
//!   peer.
//! - `cargo xtask cross [--no-run]` — aarch64 release binaries of every service and tool,
//!   run under qemu on the EuRoC excerpt and compared with the native build ([`cross`]).
//! - `cargo xtask deb [--target TRIPLE] [--check]` — the Debian package ([`deb`]).
//!
//! Every command can be run again: packages already installed are not touched.

mod cross;
mod deb;
mod feature_drift;
mod opencv_free;
mod pose_diff;
mod python;
mod python_env;
mod tiers;

use anyhow::{Context, bail};
use std::process::{Command, ExitCode};

/// Debian packages the workspace builds against: OpenCV with its contrib modules
/// (LSD, FLD, LBD, ORB) and libclang for the `opencv` crate's binding generator; and
/// GStreamer's base and good plugins, which the live camera source's GStreamer pipelines
/// (`videotestsrc`, `compositor`, `appsink`, `videocrop`, `v4l2src`) and its tests need;
/// and Python's `venv`, for the tests' Python peers ([`python_env`]).
const SYSTEM_PACKAGES: &[&str] = &[
    "libopencv-dev",
    "libopencv-contrib-dev",
    "clang",
    "libclang-dev",
    "gstreamer1.0-plugins-base",
    "gstreamer1.0-plugins-good",
    "python3-venv",
];

const USAGE: &str = "usage: cargo xtask <demo|match-demo|test|setup> [ARGS…]
  demo        run the pipeline: `linetrack run ARGS…` (try `cargo xtask demo --help`)
  match-demo  the l1 matcher demo (ARGS are passed on)
  test        every test of the default build (ARGS are passed to cargo nextest run / cargo test)
  test-features  the tests the optional features mcap (recording) and link (zenoh) add
  test-ros2   the ROS 2 output's tests (feature `ros2`) against a Cyclone DDS subscriber
  python      build the Python package's wheel into a venv, install it, run its pytest suite
  feature-drift  fails when an optional feature set would recompile a shared dependency,
                 or when the config crate, the link or the ROS 2 bridge would need OpenCV
  setup       install the system packages and the DDS peer of test-ros2
  cross       aarch64 release binaries, checked under qemu (try `cargo xtask cross --help`)
  deb         the Debian package; --check unpacks and checks it (`cargo xtask deb --help`)";

fn main() -> ExitCode {
    match run() {
        Ok(code) => code,
        Err(error) => {
            eprintln!("xtask: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> anyhow::Result<ExitCode> {
    let mut args = std::env::args().skip(1);
    let command = args.next().unwrap_or_default();
    let rest: Vec<String> = args.collect();
    match command.as_str() {
        "setup" => {
            install_system_packages()?;
            python_env::MCAP_CHECKER.install()?;
            python_env::DDS_PEER.install()?;
            Ok(ExitCode::SUCCESS)
        }
        "test-ros2" => tiers::ros2_suite(&rest),
        "demo" => {
            install_system_packages()?;
            // The supervisor starts the stage binaries from its own folder: build them all.
            let built = cargo(
                &["build", "--release", "--quiet", "--workspace", "--bins"],
                &[],
            )?;
            if built != ExitCode::SUCCESS {
                return Ok(built);
            }
            let target = python_env::target_dir();
            let mut linetrack_args = vec!["run".to_string()];
            linetrack_args.extend(rest);
            let status = Command::new(target.join("release/linetrack"))
                .args(&linetrack_args)
                .status()
                .context("cannot start linetrack")?;
            Ok(if status.success() {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            })
        }
        "match-demo" => {
            install_system_packages()?;
            cargo(
                &[
                    "run",
                    "--release",
                    "--quiet",
                    "--package",
                    "linetrack-match-demo",
                    "--",
                ],
                &rest,
            )
        }
        "test" => tiers::default_suite(&rest),
        "test-features" => tiers::feature_suite(&rest),
        "python" => python::suite(&rest),
        "feature-drift" => feature_drift::run(&rest),
        "cross" => cross::run(&rest),
        "deb" => {
            install_system_packages()?;
            deb::run(&rest, install_packages)?;
            Ok(ExitCode::SUCCESS)
        }
        "-h" | "--help" | "help" => {
            println!("{USAGE}");
            Ok(ExitCode::SUCCESS)
        }
        other => bail!("unknown command {other:?}\n{USAGE}"),
    }
}

/// Runs cargo with `fixed` then `extra` arguments; returns its exit code.
fn cargo(fixed: &[&str], extra: &[String]) -> anyhow::Result<ExitCode> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string());
    let status = Command::new(&cargo)
        .args(fixed)
        .args(extra)
        .status()
        .with_context(|| format!("cannot start {cargo}"))?;
    Ok(match status.code() {
        Some(0) => ExitCode::SUCCESS,
        Some(code) => ExitCode::from(u8::try_from(code).unwrap_or(1)),
        None => ExitCode::FAILURE,
    })
}

/// Installs the missing ones of [`SYSTEM_PACKAGES`] with apt-get (through sudo when not
/// root). Does nothing when all are installed.
fn install_system_packages() -> anyhow::Result<()> {
    install_packages(SYSTEM_PACKAGES)
}

/// Installs the missing ones of `packages` with apt-get (through sudo when not root),
/// waiting up to 10 minutes for another apt to finish. Does nothing when all are installed.
fn install_packages(packages: &[&str]) -> anyhow::Result<()> {
    let missing: Vec<&str> = packages
        .iter()
        .copied()
        .filter(|p| !is_installed(p))
        .collect();
    if missing.is_empty() {
        return Ok(());
    }
    eprintln!("xtask: installing system packages: {}", missing.join(" "));
    if Command::new("apt-get").arg("--version").output().is_err() {
        bail!(
            "apt-get is not available; install these packages with your system's package manager: {}",
            missing.join(" ")
        );
    }
    let as_root = Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| o.stdout.starts_with(b"0"));
    let run_apt = |apt_args: &[&str]| -> anyhow::Result<()> {
        let mut command = if as_root {
            Command::new("apt-get")
        } else {
            Command::new("sudo")
        };
        if !as_root {
            command.arg("apt-get");
        }
        let status = command
            .args(["-o", "DPkg::Lock::Timeout=600"])
            .args(apt_args)
            .env("DEBIAN_FRONTEND", "noninteractive")
            .status()
            .context("cannot run apt-get")?;
        if !status.success() {
            bail!("apt-get {} failed ({status})", apt_args.join(" "));
        }
        Ok(())
    };
    // Another apt (an engineer's, unattended upgrades) may hold the lock: wait for it.
    run_apt(&["-o", "DPkg::Lock::Timeout=600", "update", "-qq"])?;
    let mut install = vec![
        "-o",
        "DPkg::Lock::Timeout=600",
        "install",
        "-y",
        "-qq",
        "--no-install-recommends",
    ];
    install.extend(&missing);
    run_apt(&install)?;
    let still_missing: Vec<&str> = missing.into_iter().filter(|p| !is_installed(p)).collect();
    if !still_missing.is_empty() {
        bail!(
            "apt-get finished but these packages are still not installed: {}",
            still_missing.join(" ")
        );
    }
    Ok(())
}

fn is_installed(package: &str) -> bool {
    Command::new("dpkg-query")
        .args(["-W", "-f=${Status}", package])
        .output()
        .is_ok_and(|o| {
            o.status.success()
                && String::from_utf8_lossy(&o.stdout).contains("install ok installed")
        })
}
