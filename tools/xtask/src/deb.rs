//! `cargo xtask deb`: the Debian package of linetrack (cargo-deb, metadata in
//! `tools/linetrack/Cargo.toml`, files in `packaging/`), and `--check`, which unpacks it into
//! a scratch root and checks what it installs.
//!
//! - `cargo xtask deb` builds the release binaries and `target/debian/linetrack_<v>_amd64.deb`.
//! - `cargo xtask deb --target aarch64-unknown-linux-gnu` packages the aarch64 binaries
//!   already in `target/aarch64-unknown-linux-gnu/release` (built by `cargo xtask cross`),
//!   without building or stripping them (the host's `strip` cannot read them), with the
//!   dependencies the `cross` variant of the metadata names (dpkg-shlibdeps cannot see a
//!   cross sysroot's libraries).
//! - `cargo xtask deb --check [--profile test-release]` packages the binaries of that
//!   profile (CI: the test build `cargo xtask test` made, no second build), unpacks the
//!   package with `dpkg-deb -x` into a scratch root, checks the tree (every binary, the
//!   conffiles, the unit, the user created in postinst), runs `systemd-analyze verify` on
//!   the unit inside that root, and runs the installed `linetrack` on a generated
//!   sequence: the supervisor finds the stages beside it in `usr/bin`.
//!
//! cargo-deb is installed with `cargo install cargo-deb --locked` when missing; the system
//! packages it needs (`dpkg-dev` for the dependencies, `systemd` for `systemd-analyze`)
//! with apt-get, like the build's.

use anyhow::{Context, bail, ensure};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The Debian packages `cargo xtask deb` needs besides the build's.
pub const DEB_PACKAGES: &[&str] = &["dpkg-dev", "systemd"];

/// The version of cargo-deb installed when it is missing (the one the metadata was
/// written for).
const CARGO_DEB_VERSION: &str = "^3.8";

/// Every binary the package installs in `/usr/bin`: the command, the services, the tools.
pub const BINARIES: &[&str] = &[
    "linetrack",
    "linetrack-supervisor",
    "linetrack-frame-source",
    "linetrack-line-detector",
    "linetrack-matcher",
    "linetrack-pose-estimator",
    "linetrack-vo",
    "linetrack-eval",
    "linetrack-synth",
    "linetrack-match-pair",
    "linetrack-match-demo",
    "linetrack-stereo-bench",
    "linetrack-detector-bench",
    "linetrack-pipeline-bench",
];

/// The files that must be conffiles (kept across upgrades when edited).
const CONFFILES: &[&str] = &["/etc/linetrack/pipeline.toml", "/etc/default/linetrack"];

/// Where the unit is installed.
const UNIT: &str = "usr/lib/systemd/system/linetrack.service";

const USAGE: &str =
    "usage: cargo xtask deb [--target TRIPLE] [--profile PROFILE] [--output DIR] [--check]
  (no option)      build the release binaries and target/debian/linetrack_<version>_amd64.deb
  --target TRIPLE  package prebuilt binaries of TRIPLE (e.g. aarch64-unknown-linux-gnu, from
                   `cargo xtask cross`) found in target/TRIPLE/release; nothing is built
  --profile NAME   package the binaries of this cargo profile (default release)
  --output DIR     write the package into DIR (default target/debian, or target/TRIPLE/debian)
  --check          package, then unpack into a scratch root and check the tree, the unit
                   (systemd-analyze verify) and a run of the installed binaries";

/// What `cargo xtask deb` was asked.
#[derive(Debug, Default)]
struct Options {
    target: Option<String>,
    profile: Option<String>,
    output: Option<PathBuf>,
    check: bool,
}

fn parse(args: &[String]) -> anyhow::Result<Option<Options>> {
    let mut options = Options::default();
    let mut args = args.iter();
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--target" => {
                options.target = Some(args.next().context("--target needs a triple")?.clone());
            }
            "--profile" => {
                options.profile = Some(args.next().context("--profile needs a name")?.clone());
            }
            "--output" => {
                options.output = Some(PathBuf::from(
                    args.next().context("--output needs a folder")?,
                ));
            }
            "--check" => options.check = true,
            "-h" | "--help" => return Ok(None),
            other => bail!("deb: unknown argument {other:?}\n{USAGE}"),
        }
    }
    Ok(Some(options))
}

/// `cargo xtask deb ARGS…`.
pub fn run(args: &[String], install: impl Fn(&[&str]) -> anyhow::Result<()>) -> anyhow::Result<()> {
    let Some(options) = parse(args)? else {
        println!("{USAGE}");
        return Ok(());
    };
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .context("locating the workspace")?;
    let started = std::time::Instant::now();
    let target_dir = std::env::var_os("CARGO_TARGET_DIR")
        .map_or_else(|| workspace.join("target"), PathBuf::from);
    install(DEB_PACKAGES)?;
    ensure_cargo_deb()?;
    ensure!(
        !(options.check && options.target.is_some()),
        "--check runs the package's binaries: it checks a package for this machine only"
    );
    let profile = options.profile.as_deref().unwrap_or("release");
    let mut deb_args: Vec<String> = vec![
        "deb".into(),
        "--package".into(),
        "linetrack".into(),
        "--no-build".into(),
    ];
    if profile != "release" {
        deb_args.extend(["--profile".into(), profile.into()]);
    }
    match &options.target {
        Some(triple) => {
            let dir = target_dir.join(triple).join(profile);
            let missing: Vec<&str> = BINARIES
                .iter()
                .copied()
                .filter(|b| !dir.join(b).is_file())
                .collect();
            ensure!(
                missing.is_empty(),
                "{} lacks {}: build the {triple} binaries first (`cargo xtask cross`)",
                dir.display(),
                missing.join(", ")
            );
            // The host's strip cannot read another architecture's binaries, nor can
            // dpkg-shlibdeps find their libraries: the `cross` variant names them.
            deb_args.extend([
                "--target".into(),
                triple.clone(),
                "--no-strip".into(),
                "--variant".into(),
                "cross".into(),
            ]);
        }
        None => {
            // The tests' profile is built as the tests build it (so CI's test build is
            // reused, not redone with another feature resolution).
            let build = if profile == crate::tiers::PROFILE {
                crate::tiers::test_build(&["--quiet"])
            } else {
                [
                    "build",
                    "--workspace",
                    "--bins",
                    "--quiet",
                    "--profile",
                    profile,
                ]
                .map(String::from)
                .to_vec()
            };
            cargo(&build.iter().map(String::as_str).collect::<Vec<_>>())?;
            // The release profile keeps line tables (`debug = "line-tables-only"`), which
            // cargo-deb would then package: 135 MB instead of a stripped package.
            deb_args.push("--strip".into());
        }
    }
    if options.check {
        let out = target_dir.join("debian-check");
        let _ = std::fs::remove_dir_all(&out);
        // A package only unpacked here: the fast compression.
        deb_args.extend([
            "--output".into(),
            out.display().to_string(),
            "--fast".into(),
        ]);
    } else if let Some(out) = &options.output {
        deb_args.extend(["--output".into(), out.display().to_string()]);
    }
    let deb = cargo_deb(&deb_args)?;
    println!(
        "package: {} ({:.0} s)",
        deb.display(),
        started.elapsed().as_secs_f64()
    );
    if options.check {
        let scratch = target_dir.join("debian-check/root");
        let result = check(&deb, &scratch);
        // The scratch root holds a copy of every binary: never leave it behind.
        let _ = std::fs::remove_dir_all(target_dir.join("debian-check"));
        result?;
        println!("deb check done in {:.0} s", started.elapsed().as_secs_f64());
    }
    Ok(())
}

/// Installs cargo-deb when `cargo deb` is not there.
fn ensure_cargo_deb() -> anyhow::Result<()> {
    let present = Command::new(cargo_program())
        .args(["deb", "--version"])
        .output()
        .is_ok_and(|o| o.status.success());
    if present {
        return Ok(());
    }
    eprintln!("xtask: installing cargo-deb ({CARGO_DEB_VERSION})");
    cargo(&[
        "install",
        "cargo-deb",
        "--locked",
        "--version",
        CARGO_DEB_VERSION,
    ])
}

fn cargo_program() -> String {
    std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string())
}

fn cargo(args: &[&str]) -> anyhow::Result<()> {
    let status = Command::new(cargo_program())
        .args(args)
        .status()
        .with_context(|| format!("cannot start cargo {}", args.join(" ")))?;
    ensure!(
        status.success(),
        "cargo {} failed ({status})",
        args.join(" ")
    );
    Ok(())
}

/// Runs cargo-deb; returns the package it wrote (the last line it prints).
fn cargo_deb(args: &[String]) -> anyhow::Result<PathBuf> {
    let output = Command::new(cargo_program())
        .args(args)
        .stderr(std::process::Stdio::inherit())
        .output()
        .context("cannot start cargo deb")?;
    ensure!(
        output.status.success(),
        "cargo {} failed ({})",
        args.join(" "),
        output.status
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    let path = stdout
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.ends_with(".deb"))
        .with_context(|| format!("cargo deb named no package: {stdout}"))?;
    Ok(PathBuf::from(path))
}

/// One check's verdict, printed as it goes.
struct Checks {
    passed: usize,
    failed: Vec<String>,
}

impl Checks {
    fn check(&mut self, what: &str, ok: bool, detail: impl FnOnce() -> String) {
        if ok {
            self.passed += 1;
            println!("  ok    {what}");
        } else {
            let detail = detail();
            println!("  FAIL  {what}: {detail}");
            self.failed.push(format!("{what}: {detail}"));
        }
    }
}

fn run_output(command: &mut Command) -> anyhow::Result<(bool, String)> {
    let output = command
        .output()
        .with_context(|| format!("cannot start {command:?}"))?;
    let mut text = String::from_utf8_lossy(&output.stdout).into_owned();
    text.push_str(&String::from_utf8_lossy(&output.stderr));
    Ok((output.status.success(), text))
}

/// Unpacks `deb` into `root` and checks what it installs.
fn check(deb: &Path, root: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(root).with_context(|| format!("creating {}", root.display()))?;
    let (ok, text) = run_output(Command::new("dpkg-deb").arg("-x").arg(deb).arg(root))?;
    ensure!(ok, "dpkg-deb -x {}: {text}", deb.display());
    let control = root.join("DEBIAN");
    let (ok, text) = run_output(Command::new("dpkg-deb").arg("-e").arg(deb).arg(&control))?;
    ensure!(ok, "dpkg-deb -e {}: {text}", deb.display());
    println!(
        "deb check: {} unpacked into {}",
        deb.display(),
        root.display()
    );
    let mut checks = Checks {
        passed: 0,
        failed: Vec::new(),
    };
    for bin in BINARIES {
        let path = root.join("usr/bin").join(bin);
        let executable = std::fs::metadata(&path)
            .is_ok_and(|m| std::os::unix::fs::PermissionsExt::mode(&m.permissions()) & 0o111 != 0);
        checks.check(&format!("/usr/bin/{bin}"), executable, || {
            "missing or not executable".to_string()
        });
    }
    let conffiles = std::fs::read_to_string(control.join("conffiles")).unwrap_or_default();
    for conf in CONFFILES {
        let present = root.join(conf.trim_start_matches('/')).is_file();
        let listed = conffiles.lines().any(|l| l.trim() == *conf);
        checks.check(&format!("{conf} (conffile)"), present && listed, || {
            format!("in the tree: {present}, in DEBIAN/conffiles: {listed}")
        });
    }
    // The README's book: every page of docs/ beside it, so its links resolve.
    let pages = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs");
    let mut names: Vec<std::ffi::OsString> = std::fs::read_dir(&pages)
        .with_context(|| format!("listing {}", pages.display()))?
        .filter_map(|entry| entry.ok().map(|e| e.file_name()))
        .filter(|name| Path::new(name).extension().is_some_and(|e| e == "md"))
        .collect();
    names.sort();
    for name in &names {
        let installed = Path::new("usr/share/doc/linetrack/docs").join(name);
        checks.check(
            &format!("/{}", installed.display()),
            root.join(&installed).is_file(),
            || "missing".to_string(),
        );
    }
    let unit = root.join(UNIT);
    let unit_text = std::fs::read_to_string(&unit).unwrap_or_default();
    checks.check(&format!("/{UNIT}"), !unit_text.is_empty(), || {
        "missing".to_string()
    });
    for line in [
        "User=linetrack",
        "StateDirectory=linetrack",
        "WorkingDirectory=/var/lib/linetrack",
        "RuntimeDirectory=linetrack",
        "Restart=on-failure",
        "EnvironmentFile=-/etc/default/linetrack",
        "ExecStart=/usr/bin/linetrack run --config ${LINETRACK_CONFIG} $LINETRACK_ARGS",
        "LimitRTPRIO=50",
        "#CPUAffinity=",
        "#CPUSchedulingPolicy=fifo",
    ] {
        checks.check(
            &format!("the unit says {line}"),
            unit_text.lines().any(|l| l.starts_with(line)),
            || "not in the unit".to_string(),
        );
    }
    let postinst = std::fs::read_to_string(control.join("postinst")).unwrap_or_default();
    checks.check(
        "postinst creates the system user linetrack",
        postinst.contains("adduser --system --group --home /var/lib/linetrack"),
        || "no adduser --system in DEBIAN/postinst".to_string(),
    );
    // The unit as systemd reads it, inside the unpacked root (ExecStart's binary is the
    // installed one). `verify` fails on errors in the unit; its warnings are printed.
    let (ok, text) = run_output(
        Command::new("systemd-analyze")
            .arg("verify")
            .arg(format!("--root={}", root.display()))
            .arg("--man=no")
            .arg("--recursive-errors=no")
            .arg(format!("/{UNIT}")),
    )?;
    if !text.trim().is_empty() {
        println!("systemd-analyze verify said:\n{}", text.trim());
    }
    let about_unit: Vec<&str> = text
        .lines()
        .filter(|l| l.contains("linetrack.service"))
        .collect();
    checks.check(
        "systemd-analyze verify accepts linetrack.service",
        ok && about_unit.is_empty(),
        || text.trim().to_string(),
    );
    // The installed layout runs: the installed `linetrack` finds its stages beside it.
    run_installed(root, &mut checks)?;
    println!(
        "deb check: {} passed, {} failed",
        checks.passed,
        checks.failed.len()
    );
    ensure!(
        checks.failed.is_empty(),
        "the package failed {} checks:\n{}",
        checks.failed.len(),
        checks.failed.join("\n")
    );
    Ok(())
}

/// Runs the installed `linetrack run` for a few frames of a small generated sequence, with
/// the installed config (its run folder and shared-memory root moved into scratch folders).
fn run_installed(root: &Path, checks: &mut Checks) -> anyhow::Result<()> {
    let bin = root.join("usr/bin");
    let work = root.join("var/lib/linetrack");
    std::fs::create_dir_all(&work).with_context(|| format!("creating {}", work.display()))?;
    let sequence = work.join("sequence");
    let (ok, text) = run_output(
        Command::new(bin.join("linetrack-synth"))
            .args(["--preset", "normal", "--frames", "8", "--quiet", "--output"])
            .arg(&sequence),
    )?;
    ensure!(ok, "the installed linetrack-synth failed: {text}");
    // iceoryx2's event sockets live under the root: a unix socket's path is limited to
    // 108 bytes, so a short folder outside the scratch tree (the service's is
    // /run/linetrack/iceoryx2).
    // The installed config, with every frame processed however late: on a loaded machine
    // the drop policy could leave nothing tracked (a failed run) in 8 frames.
    let config = work.join("pipeline.toml");
    let installed = std::fs::read_to_string(root.join("etc/linetrack/pipeline.toml"))
        .context("reading the installed config")?;
    std::fs::write(
        &config,
        format!("{installed}\n[budget]\ndrop_late = false\n"),
    )
    .with_context(|| format!("writing {}", config.display()))?;
    let ipc_root = std::env::temp_dir().join(format!("ltdeb-{}", std::process::id()));
    let run_dir = work.join("runs/check");
    let (ok, text) = run_output(
        Command::new(bin.join("linetrack"))
            .args(["run", "--quiet", "--pacing", "fastest", "--dataset"])
            .arg(&sequence)
            .arg("--run-dir")
            .arg(&run_dir)
            .env("LINETRACK_CONFIG", &config)
            .env("LINETRACK_IPC_ROOT", &ipc_root)
            .env(
                "LINETRACK_IPC_PREFIX",
                format!("ltdeb{}_", std::process::id()),
            )
            .env_remove("LINETRACK_BIN_DIR"),
    )?;
    let _ = std::fs::remove_dir_all(&ipc_root);
    let summary = std::fs::read_to_string(run_dir.join("summary.json")).unwrap_or_default();
    checks.check(
        "the installed linetrack runs the pipeline from /usr/bin (8 frames)",
        ok && summary.contains("\"completed\""),
        || text.trim().to_string(),
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_packaged_binary_is_an_asset_and_every_asset_binary_is_checked() {
        let manifest = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../linetrack/Cargo.toml"),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let assets: Vec<&str> = manifest
            .lines()
            .filter_map(|l| l.trim().strip_prefix("[\"target/release/"))
            .filter_map(|l| l.split('"').next())
            .collect();
        assert_eq!(assets, BINARIES);
    }

    #[test]
    fn unknown_arguments_are_refused_by_name() {
        let err = parse(&["--chek".to_string()])
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("--chek"), "{err}");
        let parsed = parse(&[
            "--target".to_string(),
            "aarch64-unknown-linux-gnu".to_string(),
            "--check".to_string(),
        ])
        .unwrap_or_else(|e| panic!("{e}"))
        .unwrap_or_default();
        assert_eq!(parsed.target.as_deref(), Some("aarch64-unknown-linux-gnu"));
        assert!(parsed.check);
    }
}
