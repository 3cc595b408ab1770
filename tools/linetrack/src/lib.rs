//! The `linetrack` command.
//!
//! - `linetrack run`: the pipeline end to end (one process per stage over shared memory, or
//!   `--single-process`), with a live status line and the final latency report.
//! - `linetrack replay FILE.mcap`: the same, its frames read from a recording (`[record]`).
//! - `linetrack ctl swap-detector fld`: hot-swaps the detector of a running pipeline;
//!   `linetrack ctl swap-matcher` swaps its matcher for a fresh instance.
//! - `linetrack report [RUN_DIR]`: the latency report of a run, with its latency pictures
//!   ([`latency_plots`]) and a picture of a few frames of its trace ([`trace_picture`]).
//! - `linetrack watch --connect tcp/HOST:PORT` (feature `link`): the far side of the
//!   ground-station link (`watch`).

pub mod latency_plots;
pub mod records_check;
pub mod trace_picture;
#[cfg(feature = "link")]
pub mod watch;

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use linetrack_ipc::{Bus, Scope, Shutdown};
use linetrack_msgs::{Command, Control, StageKind, topics};
use linetrack_pipeline_config::{MatcherPolicy, Pacing, PipelineConfig};
use linetrack_run_record::Report;
use linetrack_scene_render::Preset;
use linetrack_supervisor::{LiveStatus, Mode, RunOptions};
use linetrack_vision::DetectorKind;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Frames of the generated default sequence (5 s at 20 Hz).
const DEFAULT_FRAMES: usize = 100;

/// The command line.
#[derive(Debug, Parser)]
#[command(
    name = "linetrack",
    version,
    about = "Geometric line tracking for stereo visual odometry: the multi-process pipeline.",
    after_help = concat!("EXAMPLES:
    linetrack run                                   # generated sequence, live status, report
    linetrack run --dataset ../shared/data/euroc/V1_01_easy_micro --pacing fastest
    linetrack run --single-process                  # same stages on threads (baseline)
    linetrack run --camera 'v4l2src ! videoconvert ! video/x-raw,format=GRAY8 ! appsink' \\
        --calibration camchain.yaml --duration 60   # a live side-by-side stereo camera
    linetrack run --ros2-images /stereo/left/image_rect /stereo/right/image_rect
                                                    # a ROS 2 stereo driver's topics
    linetrack replay ~/.local/state/linetrack/runs/latest/recording.mcap   # a recorded run again
    linetrack ctl swap-detector fld                 # while a run is going, from another shell
    linetrack ctl swap-matcher                      # a fresh matcher takes over, likewise
    linetrack report                                # the newest run: latency report and pictures

A run folder holds frames.csv, events.csv, poses.tum (TUM), summary.json (how the run ended,
the report, and with ground truth `metrics`: the names of linetrack-vo's metrics.json).

", linetrack_vision::images_help!())
)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Cmd,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Cmd {
    /// Run the pipeline on a sequence and report.
    Run(RunArgs),
    /// Run the pipeline on the stereo frames of an MCAP recording (`[record] mcap = true`)
    /// and report; needs a build with the `mcap` feature.
    Replay(ReplayArgs),
    /// Steer a running pipeline.
    Ctl(CtlArgs),
    /// Latency report of a finished run.
    Report(ReportArgs),
    /// The far side of the ground-station link: live status and records of a remote run.
    #[cfg(feature = "link")]
    Watch(watch::WatchArgs),
}

/// `linetrack run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// Pipeline config (the service's: /etc/linetrack/pipeline.toml).
    #[arg(
        long,
        env = "LINETRACK_CONFIG",
        default_value = "configs/pipeline.toml"
    )]
    pub config: PathBuf,
    /// A EuRoC, KITTI odometry or KITTI raw sequence folder (default: the config's; the generated default
    /// sequence is rendered on first use).
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// A live stereo camera instead of a sequence: a V4L2 device (0, /dev/video0), a
    /// GStreamer pipeline ending in appsink, or numbered images (dir/%06d.png); both images
    /// side by side in one frame unless --camera-right is given. Needs --calibration.
    #[arg(long, value_name = "CAPTURE")]
    pub camera: Option<String>,
    /// The right camera, when left and right are two devices (--camera is then the left).
    #[arg(long, value_name = "CAPTURE", requires = "camera")]
    pub camera_right: Option<String>,
    /// The camera's calibration: a Kalibr camchain.yaml, or a folder with EuRoC
    /// cam0/sensor.yaml and cam1/sensor.yaml.
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    /// Frames from two ROS 2 `sensor_msgs/Image` topics (rectified, mono8, mono16, rgb8 or
    /// bgr8) paired by header stamp, the rig from their `CameraInfo` (`camera_info` beside
    /// each, or camera.ros2_images.left_info / right_info); DDS domain from [ros2]. Needs
    /// `linetrack-ros2-source` (--features linetrack-ros2-bridge/ros2).
    #[arg(long, num_args = 2, value_names = ["LEFT", "RIGHT"], conflicts_with_all = ["camera", "dataset"])]
    pub ros2_images: Option<Vec<String>>,
    /// With a camera or ROS 2 images: stop after this many seconds (default: the config's
    /// camera.duration_s; 0 = until Ctrl-C).
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// Stop after this many frames.
    #[arg(long)]
    pub frames: Option<usize>,
    /// The paper's illumination protocol on the sequence's images: a new gain U(0.5, 2.5)
    /// and bias U(0, 20) every this many seconds, as `linetrack-vo --gain-jumps` (default:
    /// the config's source.gain_jumps_s; 0 = off).
    #[arg(long, value_name = "SECONDS", conflicts_with = "camera")]
    pub gain_jumps: Option<f64>,
    /// The seed of the gain jumps' draws (`linetrack-vo --seed`).
    #[arg(long, value_name = "N")]
    pub gain_jumps_seed: Option<u64>,
    /// realtime (the sequence's rate) or fastest.
    #[arg(long)]
    pub pacing: Option<String>,
    /// Start with this detector (edgelines, lsd or fld).
    #[arg(long)]
    pub detector: Option<DetectorKind>,
    /// Matcher policy: l1, lbd, or auto (LBD falling back to l1).
    #[arg(long)]
    pub matcher: Option<MatcherPolicy>,
    /// Run folder (default: a new dated folder under the config's `output.runs_dir`, with
    /// `latest` pointing at it).
    #[arg(long)]
    pub run_dir: Option<PathBuf>,
    /// Run the stages as threads of this process over channels instead of processes over
    /// shared memory.
    #[arg(long)]
    pub single_process: bool,
    /// No live status line, and no progress while the default sequence is generated.
    #[arg(long)]
    pub quiet: bool,
    /// An MCAP recording to read the frames from (`linetrack replay`).
    #[arg(skip)]
    pub replay: Option<PathBuf>,
}

/// `linetrack replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The recording (`recording.mcap` of a run recorded with `[record] mcap = true` and
    /// `every_nth_image = 1`).
    pub file: PathBuf,
    /// The run's options (--dataset and --camera do not apply).
    #[command(flatten)]
    pub run: RunArgs,
}

/// `linetrack ctl`.
#[derive(Debug, clap::Args)]
pub struct CtlArgs {
    /// The running pipeline's run folder (default: the newest run of the default runs
    /// folder, `$XDG_STATE_HOME/linetrack/runs/latest` or
    /// `~/.local/state/linetrack/runs/latest`; the service's: /var/lib/linetrack/runs/latest).
    #[arg(long, env = "LINETRACK_RUN_DIR")]
    pub run_dir: Option<PathBuf>,
    /// The command.
    #[command(subcommand)]
    pub action: CtlAction,
}

/// Commands to a running pipeline.
#[derive(Debug, Subcommand)]
pub enum CtlAction {
    /// Replace the line detector without stopping (lsd, fld or edgelines); waits for the
    /// take-over.
    SwapDetector {
        /// The detector to switch to.
        detector: DetectorKind,
        /// How long to wait for the take-over, seconds.
        #[arg(long, default_value_t = 30.0)]
        timeout: f64,
    },
    /// Replace the matcher by a fresh instance without stopping (it takes over with the
    /// frame before the hand-over matched, as the old one had it); waits for the take-over.
    SwapMatcher {
        /// How long to wait for the take-over, seconds.
        #[arg(long, default_value_t = 30.0)]
        timeout: f64,
    },
}

/// `linetrack report`.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// Run folder (default: the newest run of the default runs folder,
    /// `$XDG_STATE_HOME/linetrack/runs/latest` or `~/.local/state/linetrack/runs/latest`;
    /// the service's: /var/lib/linetrack/runs/latest).
    #[arg(env = "LINETRACK_RUN_DIR")]
    pub run_dir: Option<PathBuf>,
}

/// `run_dir`, or the newest run of the default runs folder.
fn run_dir_or_latest(run_dir: Option<&Path>) -> anyhow::Result<PathBuf> {
    match run_dir {
        Some(dir) => Ok(dir.to_path_buf()),
        None => linetrack_pipeline_config::default_runs_dir()
            .map(|runs| runs.join("latest"))
            .map_err(|e| anyhow::anyhow!("{e}")),
    }
}

/// Runs a command.
pub fn main(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Cmd::Run(args) => run(&args).map(|_| ()),
        Cmd::Replay(args) => {
            anyhow::ensure!(
                args.run.dataset.is_none()
                    && args.run.camera.is_none()
                    && args.run.ros2_images.is_none(),
                "linetrack replay reads its frames from {}: --dataset, --camera and --ros2-images do not apply",
                args.file.display()
            );
            let run_args = RunArgs {
                replay: Some(args.file),
                ..args.run
            };
            run(&run_args).map(|_| ())
        }
        Cmd::Ctl(args) => ctl(&args),
        Cmd::Report(args) => {
            print!("{}", report(&run_dir_or_latest(args.run_dir.as_deref())?)?);
            Ok(())
        }
        #[cfg(feature = "link")]
        Cmd::Watch(args) => watch::watch(&args),
    }
}

/// The run's config: the file with the command line's overrides.
pub fn effective_config(args: &RunArgs) -> anyhow::Result<PipelineConfig> {
    let mut config = PipelineConfig::from_file(&args.config)?;
    if let Some(dataset) = &args.dataset {
        config.source.sequence = dataset.clone();
    }
    if let Some(file) = &args.replay {
        config.source.replay = file.clone();
        config.camera.capture.clear();
    }
    if let Some(camera) = &args.camera {
        anyhow::ensure!(
            args.dataset.is_none(),
            "--camera and --dataset exclude each other: a run reads one source"
        );
        config.camera.capture = camera.clone();
        config.camera.capture_right = args.camera_right.clone().unwrap_or_default();
    }
    if let Some(topics) = &args.ros2_images {
        let images = &mut config.camera.ros2_images;
        images.left = topics.first().cloned().unwrap_or_default();
        images.right = topics.get(1).cloned().unwrap_or_default();
        config.camera.capture.clear();
        config.camera.capture_right.clear();
    }
    if let Some(calibration) = &args.calibration {
        config.camera.calibration = calibration.clone();
    }
    if let Some(duration) = args.duration {
        config.camera.duration_s = duration;
    }
    if let Some(period) = args.gain_jumps {
        config.source.gain_jumps_s = period;
    }
    if let Some(seed) = args.gain_jumps_seed {
        config.source.gain_jumps_seed = seed;
    }
    // The overrides are checked like the file (`camera.duration_s` range, a camera
    // without a calibration, ...).
    config
        .validate()
        .map_err(|e| anyhow::anyhow!("{}: {e}", args.config.display()))?;
    if let Some(frames) = args.frames {
        config.source.max_frames = frames;
    }
    if let Some(pacing) = &args.pacing {
        config.source.pacing = match pacing.as_str() {
            "realtime" => Pacing::Realtime,
            "fastest" => Pacing::Fastest,
            other => bail!("--pacing {other:?}: expected realtime or fastest"),
        };
    }
    if let Some(detector) = args.detector {
        config.detector = detector;
    }
    if let Some(policy) = args.matcher {
        config.matcher.mode = policy;
    }
    if let Some(dir) = &args.run_dir {
        config.output.run_dir = Some(dir.clone());
    }
    Ok(config)
}

/// `linetrack run`: returns the run folder.
pub fn run(args: &RunArgs) -> anyhow::Result<PathBuf> {
    let _logs = linetrack_telemetry::init("supervisor", "info", None)?;
    let config = effective_config(args)?;
    let sequence = &config.source.sequence;
    if !config.camera.enabled()
        && !config.camera.ros2_images.enabled()
        && config.source.replay().is_none()
        && args.dataset.is_none()
        && !sequence.join("mav0/cam0/data.csv").is_file()
        && sequence.ends_with("out/sequences/pipeline")
    {
        if !args.quiet {
            eprintln!(
                "generating the default sequence ({DEFAULT_FRAMES} frames, preset normal) in {} (first run only)",
                sequence.display()
            );
        }
        linetrack_synth::generate(Preset::Normal, 1, DEFAULT_FRAMES, sequence, args.quiet)?;
    }
    let mode = if args.single_process {
        Mode::Threads
    } else {
        Mode::Processes
    };
    println!(
        "linetrack: {} on {} ({}, {}), detector {}, matcher {}, points {}",
        if args.single_process {
            "single process"
        } else {
            "one process per stage"
        },
        if config.camera.enabled() {
            format!(
                "camera {:?}{} ({}, calibration {})",
                config.camera.capture,
                config
                    .camera
                    .right()
                    .map_or_else(|| " side by side".to_string(), |r| format!(" + {r:?}")),
                if config.camera.duration_s > 0.0 {
                    format!("{} s", config.camera.duration_s)
                } else {
                    "until Ctrl-C".to_string()
                },
                config.camera.calibration.display()
            )
        } else if let Some(file) = config.source.replay() {
            format!("recording {}", file.display())
        } else if config.camera.ros2_images.enabled() {
            let images = &config.camera.ros2_images;
            format!("ROS 2 images {} + {}", images.left, images.right)
        } else {
            sequence.display().to_string()
        },
        match config.source.pacing {
            Pacing::Realtime => "realtime",
            Pacing::Fastest => "fastest",
        },
        if config.source.max_frames > 0 {
            format!("{} frames", config.source.max_frames)
        } else {
            "all frames".to_string()
        },
        config.detector.name(),
        config.matcher.mode_name(),
        config.points_text(),
    );
    let options = RunOptions {
        mode,
        bin_dir: None,
        live_status: !args.quiet,
    };
    let outcome = match linetrack_supervisor::run(&config, &options, &Shutdown::on_signals()?) {
        Ok(outcome) => outcome,
        Err(e) => {
            // A run that failed once it had a folder still has a report: print it first.
            if let Some(linetrack_supervisor::RunFolder(dir)) = e.downcast_ref() {
                match report(dir) {
                    Ok(text) => print!("\n{text}"),
                    Err(unreadable) => eprintln!("no report of {}: {unreadable:#}", dir.display()),
                }
            }
            return Err(e);
        }
    };
    println!();
    print!("{}", report(&outcome.run_dir)?);
    if outcome.interrupted {
        println!("(interrupted)");
    }
    Ok(outcome.run_dir)
}

/// `linetrack report`: the text, after writing the latency pictures and the trace overview
/// into the run folder.
///
/// A folder cut short (a full disk, a killed supervisor) is read up to its last whole row;
/// the text then says which row was cut, which frames have no row and how the run ended
/// ([`records_check`]).
pub fn report(run_dir: &Path) -> anyhow::Result<String> {
    let records = records_check::RunRecords::read(run_dir)
        .with_context(|| format!("{} holds no run records", run_dir.display()))?;
    let (frames, events) = (&records.frames, &records.events);
    let report = Report::new(frames, events);
    let config = PipelineConfig::from_file(&run_dir.join("pipeline.toml")).ok();
    let budget = config.as_ref().map(|c| c.budget.clone());
    // The pictures are not records: one that cannot be written (a full disk, the file size
    // limit) is named in the report, which is still printed.
    let pictures = latency_plots::write(run_dir, frames, events, budget.as_ref());
    let points = config.as_ref().map_or_else(
        || "unknown (no readable pipeline.toml)".to_string(),
        PipelineConfig::points_text,
    );
    let mut text = format!(
        "run {}\npoints: {points}\n{}",
        run_dir.display(),
        report.to_text()
    );
    text.push_str(&records.gaps_text());
    for e in events.iter().filter(|e| e.kind != "stale-cleanup") {
        let at = e
            .frame_id
            .map(|f| format!(" frame {f}"))
            .unwrap_or_default();
        text.push_str(&format!(
            "  {:7.2} s {} [{}]{at}: {}\n",
            e.time_s, e.kind, e.stage, e.detail
        ));
    }
    let overview = trace_picture::write(run_dir);
    let trace = run_dir.join("trace.json");
    match pictures {
        Ok([distributions, timeline]) => text.push_str(&format!(
            "latency: {}\nlatency per frame: {}\n",
            distributions.display(),
            timeline.display()
        )),
        Err(e) => text.push_str(&format!("no latency pictures: {e:#}\n")),
    }
    if trace.is_file() {
        text.push_str(&format!(
            "trace (open in ui.perfetto.dev or chrome://tracing): {}\n",
            trace.display()
        ));
    }
    match overview {
        Ok(Some(path)) => text.push_str(&format!("trace overview: {}\n", path.display())),
        Ok(None) => {}
        Err(e) => text.push_str(&format!("no trace overview: {e:#}\n")),
    }
    Ok(text)
}

/// Reads a running pipeline's `status.json`.
pub fn live_status(run_dir: &Path) -> anyhow::Result<LiveStatus> {
    let path = run_dir.join("status.json");
    let text = std::fs::read_to_string(&path).with_context(|| {
        format!(
            "no running pipeline in {} (cannot read {})",
            run_dir.display(),
            path.display()
        )
    })?;
    serde_json::from_str(&text).with_context(|| format!("{} is damaged", path.display()))
}

/// `linetrack ctl`.
pub fn ctl(args: &CtlArgs) -> anyhow::Result<()> {
    let run_dir = run_dir_or_latest(args.run_dir.as_deref())?;
    let status = live_status(&run_dir)?;
    if status.finished() {
        bail!("the run in {} has finished", run_dir.display());
    }
    match &args.action {
        CtlAction::SwapDetector { detector, timeout } => {
            if status.detector == detector.name() {
                println!("detector is already {}", detector.name());
                return Ok(());
            }
            let code = linetrack_supervisor::detector_wire_code(*detector);
            let took_over = |now: &LiveStatus| now.detector == detector.name();
            let asked = format!("swap {} -> {}", status.detector, detector.name());
            let done = format!("{} took over", detector.name());
            let _asking = request(&status, (Command::SwapDetector, code), &asked)?;
            wait_for(&run_dir, *timeout, took_over, &done)
        }
        CtlAction::SwapMatcher { timeout } => {
            let matchers = |s: &LiveStatus| -> Vec<u32> {
                let matcher = StageKind::Matcher.name();
                s.stages
                    .iter()
                    .filter(|e| e.stage == matcher && !e.standby)
                    .map(|e| e.pid)
                    .collect()
            };
            let before = matchers(&status);
            let took_over = |now: &LiveStatus| {
                let running = matchers(now);
                running.len() == 1 && !before.contains(&running[0])
            };
            let code = u32::from(StageKind::Matcher);
            let asked = format!("swap the matcher (pid {before:?}) for a fresh one");
            let _asking = request(&status, (Command::SwapStage, code), &asked)?;
            wait_for(&run_dir, *timeout, took_over, "a fresh matcher took over")
        }
    }
}

/// Sends `command` with `value` to the run's supervisor; `asked` says what. Returns the
/// request's publisher: keep it until the request is answered.
fn request(
    status: &LiveStatus,
    (command, value): (Command, u32),
    asked: &str,
) -> anyhow::Result<(Bus, linetrack_ipc::Outlet<Control, ()>)> {
    let mut scope = Scope::with_prefix(&status.ipc_prefix, &status.run_id);
    if let Some(root) = &status.ipc_root {
        scope = scope.with_root(root.clone());
    }
    let bus = Bus::shared_memory(&scope, &format!("ctl-{}", std::process::id()))?;
    let mut control = bus.outlet::<Control, ()>(topics::CONTROL, 1)?;
    let request = Control::new(
        command,
        StageKind::Supervisor,
        status.supervisor_pid,
        value,
        0,
    );
    control.publish(&(), &[&[request]])?;
    println!(
        "asked the supervisor (pid {}) to {asked}",
        status.supervisor_pid
    );
    Ok((bus, control))
}

/// Waits up to `timeout` seconds until the run's status says `took_over`; prints `done`.
fn wait_for(
    run_dir: &Path,
    timeout: f64,
    took_over: impl Fn(&LiveStatus) -> bool,
    done: &str,
) -> anyhow::Result<()> {
    let deadline = Instant::now() + Duration::from_secs_f64(timeout.max(0.1));
    while Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
        let now = live_status(run_dir)?;
        if took_over(&now) {
            println!("{done}");
            return Ok(());
        }
        if now.finished() {
            bail!("the run finished before the swap");
        }
    }
    bail!("no take-over within {timeout} s (see the supervisor's log)")
}
