//! `cargo xtask cross`: aarch64 release binaries of every service and tool, built on this
//! x86-64 Debian 12 machine and checked under emulation against the native build.
//!
//! What it does, each step skipped when already done:
//!
//! 1. installs the host packages: the native build's ([`crate::SYSTEM_PACKAGES`]), the
//!    aarch64 cross compilers, `qemu-user-static` and `mmdebstrap`; and the Rust target
//!    `aarch64-unknown-linux-gnu` (rustup);
//! 2. makes an arm64 Debian 12 sysroot (`target/aarch64-sysroot`, or
//!    `$LINETRACK_AARCH64_SYSROOT`) with `mmdebstrap --variant=extract`: the OpenCV module
//!    packages the workspace links against, unpacked, never installed on the host (the arm64
//!    OpenCV cannot be installed next to the amd64 one through multiarch: its imgcodecs
//!    depends on GDAL, which is not co-installable);
//! 3. builds `cargo build --release --target aarch64-unknown-linux-gnu` (or the profile
//!    `--profile` names) of every binary but xtask, with the opencv crate, its C++ glue and
//!    the linker pointed at the sysroot;
//! 4. unless `--no-run`: builds the native binaries (release, or the profile
//!    `--native-profile` names: CI compares with the `test-release` binaries its tests
//!    built, which compute the same), runs the same commands with
//!    both (`linetrack run --pacing fastest` with [`RUN_CONFIG`] on the first frames of the
//!    EuRoC excerpt, and `linetrack-vo` on them; the aarch64 ones under
//!    `qemu-aarch64-static`), and compares the poses: it fails when they differ by more than
//!    [`TOLERANCE`]. The aarch64 pipeline runs twice, with `--single-process` and as
//!    processes (the supervisor starting each aarch64 stage through
//!    `LINETRACK_STAGE_RUNNER`, iceoryx2 between emulated processes); the native reference
//!    runs single-process.

use crate::pose_diff::{self, PoseDifference, Tolerance};
use anyhow::{Context, bail};
use clap::Parser;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};
use std::time::Instant;

/// The Rust target.
pub const TARGET: &str = "aarch64-unknown-linux-gnu";

/// Host packages for the cross build and the emulated runs.
const HOST_PACKAGES: &[&str] = &[
    "gcc-aarch64-linux-gnu",
    "g++-aarch64-linux-gnu",
    "qemu-user-static",
    "mmdebstrap",
];

/// arm64 packages unpacked into the sysroot, with their dependencies: the C and C++ headers
/// and libraries, and the OpenCV modules of the workspace's `opencv` features (core, imgproc,
/// flann, features2d, calib3d, imgcodecs, videoio; ximgproc and line_descriptor are in
/// contrib406).
const SYSROOT_PACKAGES: &[&str] = &[
    "libc6-dev",
    "libstdc++-12-dev",
    "libopencv-core-dev",
    "libopencv-imgproc-dev",
    "libopencv-flann-dev",
    "libopencv-features2d-dev",
    "libopencv-calib3d-dev",
    "libopencv-imgcodecs-dev",
    "libopencv-videoio-dev",
    "libopencv-contrib406",
];

/// The contrib modules' headers and `.so` links: unpacked alone, without the dependencies of
/// this package (every OpenCV -dev package, VTK's and GDAL's included, gigabytes).
const SYSROOT_HEADERS_ONLY: &str = "libopencv-contrib-dev";

/// Debian 12 archives the sysroot comes from (the suites this machine's OpenCV comes from).
const MIRRORS: &[&str] = &[
    "deb http://deb.debian.org/debian bookworm main",
    "deb http://deb.debian.org/debian bookworm-updates main",
    "deb http://deb.debian.org/debian-security bookworm-security main",
];

/// Links the alternatives system makes when BLAS/LAPACK are installed (libopencv_core needs
/// `liblapack.so.3` and `libblas.so.3`); an extracted sysroot has only their targets.
const ALTERNATIVES: &[(&str, &str)] = &[
    (
        "usr/lib/aarch64-linux-gnu/liblapack.so.3",
        "lapack/liblapack.so.3",
    ),
    (
        "usr/lib/aarch64-linux-gnu/libblas.so.3",
        "blas/libblas.so.3",
    ),
];

/// The OpenCV libraries the workspace links (`OPENCV_LINK_LIBS`).
const OPENCV_LIBS: &[&str] = &[
    "opencv_core",
    "opencv_imgproc",
    "opencv_flann",
    "opencv_features2d",
    "opencv_calib3d",
    "opencv_imgcodecs",
    "opencv_videoio",
    "opencv_ximgproc",
    "opencv_line_descriptor",
];

/// The sysroot's completion mark: written last, holding the package lists it was made with.
const SYSROOT_MARK: &str = ".linetrack-sysroot";

/// The emulator, from `qemu-user-static` (works without binfmt_misc: given the binary).
const QEMU: &str = "qemu-aarch64-static";

/// The pipeline config of the compared runs: every frame processed however late, the matcher
/// switched by match counts only (not by time), generous timeouts for emulation.
const RUN_CONFIG: &str = "configs/emulation.toml";

/// The most frames a compared pipeline run may have: the frames a stage holds
/// (`linetrack_stage_runtime::HELD_FRAMES`, the frame topic's queue depth less one). At
/// fastest pacing the source publishes every frame at once; a run of more frames than a
/// stage holds releases some before their segments arrive, which ones depending on the
/// stages' speeds (measured: 9 of 30 frames lost natively, others under qemu). Up to this
/// many, every frame waits its turn whatever the speed, so both runs process the same frames.
const MAX_PIPELINE_FRAMES: usize = 11;

/// How far the aarch64 poses may lie from the native ones (the same commands, the same
/// frames). Measured on the EuRoC excerpt (docs/development.md, "Cross-building for aarch64"): the
/// pipeline's poses (`poses.tum`, written to 1 µm and 1e-6 per quaternion component) were
/// equal, `linetrack-vo`'s (to 1 nm) differed by at most 3.3e-9 m and 2.0e-7° over 30
/// frames (7.8e-9 m, 2.3e-7° over all 95): floating point's last bits (likely GCC's fused
/// multiply-adds in the arm64 OpenCV, and libm). The tolerance is over 1000 times that, and
/// still 1/500 of the 5 mm the camera moves in the first 30 frames, so that a run that took
/// another decision (another RANSAC inlier set, another matcher mode) would most likely
/// not pass.
pub const TOLERANCE: Tolerance = Tolerance {
    position_m: 1e-5,
    rotation_deg: 1e-3,
};

/// `cargo xtask cross` options.
#[derive(Debug, Parser)]
#[command(
    name = "cargo xtask cross",
    about = "Build aarch64 release binaries of every service and tool, run them under qemu on the EuRoC excerpt and compare their poses with the native build's."
)]
struct Args {
    /// Only build (no native build, no emulated runs).
    #[arg(long)]
    no_run: bool,
    /// Only install the packages and make the sysroot, then print the environment of the
    /// cross build (shell `export` lines) for running cargo by hand.
    #[arg(long, conflicts_with = "no_run")]
    sysroot_only: bool,
    /// Frames of the compared pipeline runs (at most 11: see `MAX_PIPELINE_FRAMES`).
    #[arg(long, default_value_t = 10)]
    frames: usize,
    /// Frames of the compared `linetrack-vo` runs.
    #[arg(long, default_value_t = 30)]
    vo_frames: usize,
    /// The sequence of the compared runs (default: $LINETRACK_EUROC_DIR, else
    /// ../shared/data/euroc/V1_01_easy_micro beside the workspace).
    #[arg(long)]
    dataset: Option<PathBuf>,
    /// Where the runs write (default: target/cross-check).
    #[arg(long)]
    output: Option<PathBuf>,
    /// The cargo profile of the native binaries compared with (`test-release` reuses the
    /// test build's: the same code and optimisation, with overflow checks, so the same
    /// poses).
    #[arg(long, default_value = "release")]
    native_profile: String,
    /// The cargo profile of the aarch64 build. CI checks the `test-release` build (the
    /// orchestration crates at optimisation level 1: a cold build some minutes shorter);
    /// the package is made from the `release` one.
    #[arg(long, default_value = "release")]
    profile: String,
}

/// The folder under `target/TRIPLE/` that cargo writes `profile`'s binaries to.
fn profile_dir(profile: &str) -> &str {
    if profile == "dev" { "debug" } else { profile }
}

/// Runs `cargo xtask cross ARGS…`.
pub fn run(args: &[String]) -> anyhow::Result<ExitCode> {
    let args = match Args::try_parse_from(
        std::iter::once("cross".to_string()).chain(args.iter().cloned()),
    ) {
        Ok(args) => args,
        Err(e) if !e.use_stderr() => {
            print!("{e}");
            return Ok(ExitCode::SUCCESS);
        }
        Err(e) => bail!("{e}"),
    };
    if args.frames == 0 || args.frames > MAX_PIPELINE_FRAMES {
        bail!(
            "--frames {}: the compared pipeline runs take 1 to {MAX_PIPELINE_FRAMES} frames (more, at fastest pacing, drop frames depending on speed)",
            args.frames
        );
    }
    if args.vo_frames == 0 {
        bail!("--vo-frames 0: the compared linetrack-vo runs need frames");
    }
    let workspace = workspace_root();
    let target_dir = target_dir(&workspace);
    crate::install_system_packages()?;
    crate::install_packages(HOST_PACKAGES)?;
    add_rust_target()?;
    let sysroot = std::env::var_os("LINETRACK_AARCH64_SYSROOT")
        .map_or_else(|| target_dir.join("aarch64-sysroot"), PathBuf::from);
    make_sysroot(&sysroot)?;
    if args.sysroot_only {
        for (key, value) in cross_env(&path_text(&sysroot)?) {
            println!("export {key}={}", shell_words(&[value]));
        }
        return Ok(ExitCode::SUCCESS);
    }

    let started = Instant::now();
    cross_build(&workspace, &sysroot, &args.profile)?;
    let bin_dir = target_dir.join(TARGET).join(profile_dir(&args.profile));
    eprintln!(
        "xtask: aarch64 {} build: {:.1} s; binaries in {}",
        args.profile,
        started.elapsed().as_secs_f64(),
        bin_dir.display()
    );
    if args.no_run {
        return Ok(ExitCode::SUCCESS);
    }
    let dataset = match &args.dataset {
        Some(dir) => {
            std::path::absolute(dir).with_context(|| format!("--dataset {}", dir.display()))?
        }
        None => std::env::var_os("LINETRACK_EUROC_DIR").map_or_else(
            || workspace.join("../shared/data/euroc/V1_01_easy_micro"),
            PathBuf::from,
        ),
    };
    if !dataset.join("mav0").is_dir() {
        if args.dataset.is_some() {
            bail!("{} is no EuRoC sequence (no mav0/)", dataset.display());
        }
        // As `cargo xtask test` does with the real_data tests: say so, leave them out.
        eprintln!(
            "xtask: EuRoC excerpt not found at {} (set LINETRACK_EUROC_DIR or --dataset): built only, the emulated runs are left out",
            dataset.display()
        );
        return Ok(ExitCode::SUCCESS);
    }
    let started = Instant::now();
    let profile = args.native_profile.as_str();
    // The tests' profile is built as the tests build it, so their binaries are reused.
    let build = if profile == crate::tiers::PROFILE {
        crate::tiers::test_build(&["--quiet"])
    } else {
        [
            "build",
            "--profile",
            profile,
            "--quiet",
            "--workspace",
            "--bins",
        ]
        .map(String::from)
        .to_vec()
    };
    let built = crate::cargo(&build.iter().map(String::as_str).collect::<Vec<_>>(), &[])?;
    if built != ExitCode::SUCCESS {
        bail!("the native {profile} build failed");
    }
    eprintln!(
        "xtask: native {profile} build: {:.1} s",
        started.elapsed().as_secs_f64()
    );

    // Absolute: the runs start from the workspace, maybe not the folder cargo started in.
    let output = match &args.output {
        Some(dir) => {
            std::path::absolute(dir).with_context(|| format!("--output {}", dir.display()))?
        }
        None => target_dir.join("cross-check"),
    };
    let native = Machine {
        name: "x86-64",
        bin_dir: target_dir.join(profile),
        runner: Vec::new(),
    };
    let emulated = Machine {
        name: "aarch64 (qemu)",
        bin_dir,
        runner: vec![QEMU.to_string(), "-L".to_string(), path_text(&sysroot)?],
    };
    let check = Check {
        workspace: &workspace,
        dataset: &dataset,
        frames: args.frames,
        vo_frames: args.vo_frames,
        output: &output,
    };
    let mut failures = Vec::new();
    let mut compare = |what: &str, file: &str, native_dir: &Path, emulated_dir: &Path| {
        match pose_diff::compare_files(&native_dir.join(file), &emulated_dir.join(file)) {
            Ok(difference) => {
                println!("{what}: {difference}");
                if !difference.within(&TOLERANCE) {
                    failures.push(over(what, &difference));
                }
            }
            Err(e) => failures.push(format!("{what}: {e:#}")),
        }
    };

    let native_run = check.pipeline(&native, "native/pipeline", false)?;
    let emulated_run = check.pipeline(&emulated, "aarch64/pipeline", false)?;
    compare(
        "linetrack run --single-process",
        "poses.tum",
        &native_run,
        &emulated_run,
    );
    let emulated_processes = check.pipeline(&emulated, "aarch64/pipeline-processes", true)?;
    compare(
        "linetrack run (processes)",
        "poses.tum",
        &native_run,
        &emulated_processes,
    );
    let native_vo = check.vo(&native, "native/vo")?;
    let emulated_vo = check.vo(&emulated, "aarch64/vo")?;
    compare("linetrack-vo", "trajectory.txt", &native_vo, &emulated_vo);

    if failures.is_empty() {
        println!(
            "aarch64 poses equal the native ones within {} m and {}° (runs in {})",
            TOLERANCE.position_m,
            TOLERANCE.rotation_deg,
            output.display()
        );
        Ok(ExitCode::SUCCESS)
    } else {
        bail!(
            "the aarch64 binaries' poses differ from the native ones:\n  {}",
            failures.join("\n  ")
        )
    }
}

/// The failure line of a difference over the tolerance.
fn over(what: &str, difference: &PoseDifference) -> String {
    format!(
        "{what}: {difference}; tolerance {} m, {}°",
        TOLERANCE.position_m, TOLERANCE.rotation_deg
    )
}

/// Where a set of binaries runs: natively, or through an emulator command.
struct Machine {
    name: &'static str,
    bin_dir: PathBuf,
    runner: Vec<String>,
}

impl Machine {
    /// The command running `binary` of this set.
    fn command(&self, binary: &str) -> Command {
        let program = self.bin_dir.join(binary);
        match self.runner.split_first() {
            None => Command::new(program),
            Some((runner, args)) => {
                let mut command = Command::new(runner);
                command.args(args).arg(program);
                command
            }
        }
    }
}

/// The compared runs' common settings.
struct Check<'a> {
    workspace: &'a Path,
    dataset: &'a Path,
    frames: usize,
    vo_frames: usize,
    output: &'a Path,
}

impl Check<'_> {
    /// `linetrack run` into OUTPUT/`name`; returns the run folder.
    fn pipeline(&self, machine: &Machine, name: &str, processes: bool) -> anyhow::Result<PathBuf> {
        let run_dir = self.fresh_dir(name)?;
        let mut command = machine.command("linetrack");
        command.args([
            "run", "--config", RUN_CONFIG, "--pacing", "fastest", "--quiet",
        ]);
        command.arg("--dataset").arg(self.dataset);
        command.args(["--frames", &self.frames.to_string()]);
        command.arg("--run-dir").arg(&run_dir);
        // The supervisor takes the stage binaries from beside its own, this set's.
        command.env_remove("LINETRACK_BIN_DIR");
        if processes {
            command.env("LINETRACK_STAGE_RUNNER", shell_words(&machine.runner));
        } else {
            command.arg("--single-process");
        }
        let mode = if processes {
            "processes"
        } else {
            "single process"
        };
        self.timed(
            &format!(
                "{}: linetrack run ({mode}), {} frames",
                machine.name, self.frames
            ),
            command,
            &run_dir.join("console.txt"),
        )?;
        Ok(run_dir)
    }

    /// `linetrack-vo` into OUTPUT/`name`; returns its output folder.
    fn vo(&self, machine: &Machine, name: &str) -> anyhow::Result<PathBuf> {
        let out = self.fresh_dir(name)?;
        let mut command = machine.command("linetrack-vo");
        command
            .arg(self.dataset)
            .args(["--frames", &self.vo_frames.to_string(), "--quiet"]);
        command.arg("--output").arg(&out);
        self.timed(
            &format!("{}: linetrack-vo, {} frames", machine.name, self.vo_frames),
            command,
            &out.join("console.txt"),
        )?;
        Ok(out)
    }

    /// OUTPUT/`name`, emptied (a run refuses a folder an earlier run locked).
    fn fresh_dir(&self, name: &str) -> anyhow::Result<PathBuf> {
        let dir = self.output.join(name);
        if dir.exists() {
            std::fs::remove_dir_all(&dir).with_context(|| format!("emptying {}", dir.display()))?;
        }
        if let Some(parent) = dir.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("creating {}", parent.display()))?;
        }
        Ok(dir)
    }

    /// Runs `command` from the workspace, its output into `log`; prints how long it took.
    fn timed(&self, what: &str, mut command: Command, log: &Path) -> anyhow::Result<()> {
        let started = Instant::now();
        let output = command
            .current_dir(self.workspace)
            .output()
            .with_context(|| format!("{what}: cannot start {:?}", command.get_program()))?;
        let seconds = started.elapsed().as_secs_f64();
        if let Some(dir) = log.parent() {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        let mut text = output.stdout.clone();
        text.extend_from_slice(&output.stderr);
        std::fs::write(log, &text).with_context(|| format!("writing {}", log.display()))?;
        if !output.status.success() {
            bail!(
                "{what} failed ({}); its output:\n{}",
                output.status,
                String::from_utf8_lossy(&text)
            );
        }
        println!("{what}: {seconds:.1} s");
        Ok(())
    }
}

/// `words` as one shell command line (what LINETRACK_STAGE_RUNNER reads).
fn shell_words(words: &[String]) -> String {
    words
        .iter()
        .map(|w| {
            if !w.is_empty()
                && w.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@".contains(c))
            {
                w.clone()
            } else {
                format!("'{}'", w.replace('\'', r"'\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// The workspace root (xtask lives in tools/xtask).
fn workspace_root() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest
        .ancestors()
        .nth(2)
        .map_or_else(|| manifest.join("../.."), Path::to_path_buf)
}

/// cargo's target folder: `$CARGO_TARGET_DIR` or the workspace's `target`.
fn target_dir(workspace: &Path) -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| workspace.join("target"), PathBuf::from)
}

/// A path as UTF-8 text (for environment variables read as text).
fn path_text(path: &Path) -> anyhow::Result<String> {
    path.to_str()
        .map(str::to_string)
        .with_context(|| format!("{} is not valid UTF-8", path.display()))
}

/// `rustup target add aarch64-unknown-linux-gnu` unless installed.
fn add_rust_target() -> anyhow::Result<()> {
    let installed = Command::new("rustup")
        .args(["target", "list", "--installed"])
        .output()
        .context(
            "cannot run rustup (the aarch64 standard library comes from `rustup target add`)",
        )?;
    if String::from_utf8_lossy(&installed.stdout)
        .lines()
        .any(|l| l.trim() == TARGET)
    {
        return Ok(());
    }
    eprintln!("xtask: rustup target add {TARGET}");
    let status = Command::new("rustup")
        .args(["target", "add", TARGET])
        .status()
        .context("cannot run rustup")?;
    if !status.success() {
        bail!("rustup target add {TARGET} failed ({status})");
    }
    Ok(())
}

/// The mark's text: what a sysroot made now would hold.
fn sysroot_mark_text() -> String {
    format!(
        "{}\n{SYSROOT_HEADERS_ONLY}\n{}\n",
        SYSROOT_PACKAGES.join(" "),
        MIRRORS.join("\n")
    )
}

/// Makes the arm64 sysroot unless one with the same packages is there.
fn make_sysroot(sysroot: &Path) -> anyhow::Result<()> {
    let mark = sysroot.join(SYSROOT_MARK);
    if std::fs::read_to_string(&mark).is_ok_and(|text| text == sysroot_mark_text()) {
        return Ok(());
    }
    if sysroot.exists() {
        eprintln!(
            "xtask: replacing the incomplete or outdated sysroot {}",
            sysroot.display()
        );
        std::fs::remove_dir_all(sysroot)
            .with_context(|| format!("removing {}", sysroot.display()))?;
    }
    if let Some(parent) = sysroot.parent() {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    eprintln!(
        "xtask: making the arm64 sysroot {} (mmdebstrap, about 760 MB)",
        sysroot.display()
    );
    let hook = format!(
        "cd \"$1/tmp\" && APT_CONFIG=\"$MMDEBSTRAP_APT_CONFIG\" apt-get download -q {SYSROOT_HEADERS_ONLY} \
         && dpkg-deb --extract {SYSROOT_HEADERS_ONLY}_*.deb \"$1\" && rm {SYSROOT_HEADERS_ONLY}_*.deb"
    );
    let status = Command::new("mmdebstrap")
        .args(["--variant=extract", "--architectures=arm64", "--quiet"])
        .arg(format!("--include={}", SYSROOT_PACKAGES.join(",")))
        .arg(format!("--extract-hook={hook}"))
        .arg("bookworm")
        .arg(sysroot)
        .args(MIRRORS)
        .status()
        .context("cannot run mmdebstrap")?;
    if !status.success() {
        bail!("mmdebstrap failed ({status}) making {}", sysroot.display());
    }
    for (link, target) in ALTERNATIVES {
        let link = sysroot.join(link);
        let resolved = link.parent().map(|dir| dir.join(target));
        if !resolved.as_deref().is_some_and(Path::exists) {
            bail!(
                "{} is not in the sysroot: the BLAS/LAPACK packages changed",
                link.display()
            );
        }
        if link.symlink_metadata().is_err() {
            std::os::unix::fs::symlink(target, &link)
                .with_context(|| format!("linking {}", link.display()))?;
        }
    }
    let header = sysroot.join("usr/include/opencv4/opencv2/line_descriptor.hpp");
    if !header.is_file() {
        bail!(
            "{} is missing: {SYSROOT_HEADERS_ONLY} was not unpacked",
            header.display()
        );
    }
    std::fs::write(&mark, sysroot_mark_text())
        .with_context(|| format!("writing {}", mark.display()))?;
    Ok(())
}

/// `cargo build --profile PROFILE --target aarch64-unknown-linux-gnu` of every binary but
/// xtask.
fn cross_build(workspace: &Path, sysroot: &Path, profile: &str) -> anyhow::Result<()> {
    let sysroot_text = path_text(sysroot)?;
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string());
    let status = Command::new(&cargo)
        .current_dir(workspace)
        .args([
            "build",
            "--profile",
            profile,
            "--target",
            TARGET,
            "--workspace",
            "--bins",
        ])
        .args(["--exclude", "xtask", "--exclude", "linetrack-e2e"])
        .envs(cross_env(&sysroot_text))
        .status()
        .with_context(|| format!("cannot start {cargo}"))?;
    if !status.success() {
        bail!("the aarch64 build failed ({status})");
    }
    Ok(())
}

/// The environment of the cross build: the linker and C/C++ compilers for aarch64 with the
/// sysroot, and the opencv crate's library (`OPENCV_*`, no pkg-config: the sysroot has no
/// `opencv4.pc`, it is in the `libopencv-dev` meta-package). The crate's binding generator
/// parses the arm64 headers with the host's clang for the host (it adds the host's C++
/// include folders, which `--target=aarch64-linux-gnu` cannot use): the Rust declarations
/// it writes are the same for both LP64 Linux targets, and the C++ glue it writes is then
/// compiled for aarch64 against the sysroot.
pub fn cross_env(sysroot: &str) -> Vec<(String, String)> {
    let sysroot_flag = format!("--sysroot={sysroot}");
    [
        (
            "CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER",
            "aarch64-linux-gnu-gcc".to_string(),
        ),
        (
            "CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUSTFLAGS",
            format!("-C link-arg={sysroot_flag}"),
        ),
        (
            "CC_aarch64_unknown_linux_gnu",
            "aarch64-linux-gnu-gcc".to_string(),
        ),
        (
            "CXX_aarch64_unknown_linux_gnu",
            "aarch64-linux-gnu-g++".to_string(),
        ),
        ("CFLAGS_aarch64_unknown_linux_gnu", sysroot_flag.clone()),
        ("CXXFLAGS_aarch64_unknown_linux_gnu", sysroot_flag.clone()),
        // The headers, and the multiarch folder of `cvconfig.h` (the build features).
        (
            "OPENCV_INCLUDE_PATHS",
            format!(
                "{sysroot}/usr/include/opencv4,{sysroot}/usr/include/aarch64-linux-gnu/opencv4"
            ),
        ),
        (
            "OPENCV_LINK_PATHS",
            format!("{sysroot}/usr/lib/aarch64-linux-gnu"),
        ),
        ("OPENCV_LINK_LIBS", OPENCV_LIBS.join(",")),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pipeline_runs_longer_than_a_stage_holds_are_refused_before_any_work() {
        let error = run(&["--frames".to_string(), "12".to_string()]).unwrap_err();
        assert!(error.to_string().contains("--frames 12"), "{error}");
        let error = run(&["--vo-frames".to_string(), "0".to_string()]).unwrap_err();
        assert!(error.to_string().contains("--vo-frames 0"), "{error}");
        let error = run(&["--no-such-option".to_string()]).unwrap_err();
        assert!(error.to_string().contains("--no-such-option"), "{error}");
    }

    #[test]
    fn runner_words_survive_the_shell_split() {
        let words = vec![
            "qemu-aarch64-static".to_string(),
            "-L".to_string(),
            "/opt/arm 64/it's".to_string(),
        ];
        let line = shell_words(&words);
        assert_eq!(line, r"qemu-aarch64-static -L '/opt/arm 64/it'\''s'");
        assert_eq!(shlex::split(&line).unwrap(), words);
    }

    #[test]
    fn the_cross_environment_points_everything_at_the_sysroot() {
        let env = cross_env("/s");
        let get = |k: &str| {
            env.iter()
                .find(|(key, _)| key == k)
                .map(|(_, v)| v.as_str())
        };
        assert_eq!(
            get("OPENCV_INCLUDE_PATHS"),
            Some("/s/usr/include/opencv4,/s/usr/include/aarch64-linux-gnu/opencv4")
        );
        assert_eq!(
            get("CXXFLAGS_aarch64_unknown_linux_gnu"),
            Some("--sysroot=/s")
        );
        assert_eq!(
            get("CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUSTFLAGS"),
            Some("-C link-arg=--sysroot=/s")
        );
        assert!(get("OPENCV_LINK_LIBS").is_some_and(|l| l.contains("opencv_line_descriptor")));
    }

    #[test]
    fn the_mark_names_the_packages_so_a_changed_list_remakes_the_sysroot() {
        assert!(sysroot_mark_text().contains("libopencv-contrib406"));
        assert!(sysroot_mark_text().contains(SYSROOT_HEADERS_ONLY));
    }
}
