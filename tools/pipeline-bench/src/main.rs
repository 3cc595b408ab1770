//! `linetrack-pipeline-bench`: in one run, (1) the cost of one hop of a 752×480 stereo
//! frame between two processes over iceoryx2 shared memory, against the same hop between
//! two threads over the local channels, and (2) the pipeline's end-to-end latency with one
//! process per stage against all stages on threads of one process, on the same generated
//! sequence, runs alternating so that load drifts hit both.

use anyhow::{Context, bail};
use clap::Parser;
use linetrack_ipc::{Bus, Scope, Shutdown};
use linetrack_msgs::{FrameHeader, PoseRecord, StageKind, TracksHeader, now_ns, topics};
use linetrack_odometry::Features;
use linetrack_pipeline_config::{MatcherPolicy, Pacing, PipelineConfig};
use linetrack_run_record::{FrameRecord, Percentiles, read_frames};
use linetrack_scene_render::Preset;
use linetrack_supervisor::{Mode, RunOptions};
use linetrack_vision::DetectorKind;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::process::{Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

/// Benchmarks the pipeline's transport and end-to-end latency.
#[derive(Parser)]
#[command(
    after_help = "Writes the tables to stdout and to <output>/pipeline-bench.md.

EXAMPLES:
    linetrack-pipeline-bench --sequence ../shared/data/euroc/V1_01_easy_micro --frames 95
    linetrack-pipeline-bench --sequence ../shared/data/euroc/V1_01_easy_micro --detector lsd --matcher lbd

The critical path: a frame's end-to-end latency is the sum, over the four stages, of the time
it waited before the stage took it (transport, and queueing while the stage was busy with an
earlier frame) and the stage's own work on it. For each frame the largest of these eight parts
is its bottleneck; the table counts the frames per bottleneck.

Detector per frame: with `--detector lsd`, the automatic policy ([detector_fallback], on by
default) swaps LSD for a faster detector when LSD misses its budget; the figures then mix
the two, and this line says how many frames each worked on. To measure LSD alone, pass a
--config with `[detector_fallback] enabled = false`."
)]
struct Args {
    /// Round trips per transport for the hop cost.
    #[arg(long, default_value_t = 500)]
    round_trips: usize,
    /// Frames per pipeline run.
    #[arg(long, default_value_t = 100)]
    frames: usize,
    /// Pipeline runs per mode (alternating).
    #[arg(long, default_value_t = 2)]
    repeats: usize,
    /// Generated sequence to use (rendered if missing), or any EuRoC / KITTI sequence folder
    /// (e.g. ../shared/data/euroc/V1_01_easy_micro).
    #[arg(long, default_value = "out/sequences/pipeline")]
    sequence: PathBuf,
    /// Pipeline config to run with (default: the built-in defaults, as configs/pipeline.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Line detector, overriding the config's: edgelines, lsd or fld.
    #[arg(long)]
    detector: Option<DetectorKind>,
    /// Matcher policy, overriding the config's: l1, lbd or auto.
    #[arg(long)]
    matcher: Option<MatcherPolicy>,
    /// Output folder.
    #[arg(long, default_value = "out/bench")]
    output: PathBuf,
    /// Internal: be the echo peer of the hop benchmark in run `echo`.
    #[arg(long, hide = true)]
    echo: Option<String>,
}

const WIDTH: usize = 752;
const HEIGHT: usize = 480;

/// The peer: returns every frame's header as a pose, after reading the frame in place.
fn echo(run_id: &str, hub: Option<linetrack_ipc::LocalHub>, count: usize) -> anyhow::Result<()> {
    let bus = match hub {
        Some(h) => h.bus(),
        None => Bus::shared_memory(&Scope::new(run_id), "bench-echo")?,
    };
    let mut frames = bus.inlet::<u8, FrameHeader>(topics::FRAMES)?;
    let mut pongs = bus.outlet::<PoseRecord, TracksHeader>(topics::POSES, 1)?;
    let wake = bus.wake(StageKind::LineDetector)?;
    pongs.publish(
        &TracksHeader::from(FrameHeader::new(u64::MAX, 0, 0)),
        &[&[PoseRecord::default()]],
    )?; // ready
    let mut seen = 0;
    let deadline = Instant::now() + Duration::from_secs(120);
    while seen < count && Instant::now() < deadline {
        wake.wait(Duration::from_millis(100))?;
        while let Some(frame) = frames.receive()? {
            // Read the images where they are: one byte per cache line.
            let checksum: u64 = frame
                .payload()
                .iter()
                .step_by(64)
                .map(|&b| u64::from(b))
                .sum();
            let mut header = TracksHeader::from(*frame.header());
            header.frame.sequence_ns = checksum;
            pongs.publish(&header, &[&[PoseRecord::default()]])?;
            seen += 1;
        }
    }
    Ok(())
}

/// The pinging side's ports: made before the peer starts, so its ready message is heard.
struct Pinger {
    frames: linetrack_ipc::Outlet<u8, FrameHeader>,
    pongs: linetrack_ipc::Inlet<PoseRecord, TracksHeader>,
    wake: linetrack_ipc::Wake,
}

impl Pinger {
    fn new(bus: &Bus) -> anyhow::Result<Self> {
        Ok(Self {
            frames: bus.outlet::<u8, FrameHeader>(topics::FRAMES, 2 * WIDTH * HEIGHT)?,
            pongs: bus.inlet::<PoseRecord, TracksHeader>(topics::POSES)?,
            wake: bus.wake(StageKind::Supervisor)?,
        })
    }
}

/// One-way latencies (half round trips), microseconds.
fn ping(pinger: Pinger, round_trips: usize) -> anyhow::Result<Vec<f64>> {
    let Pinger {
        mut frames,
        mut pongs,
        wake,
    } = pinger;
    let deadline = Instant::now() + Duration::from_secs(30);
    // Wait for the peer's ready message.
    loop {
        wake.wait(Duration::from_millis(100))?;
        if pongs.receive()?.is_some() {
            break;
        }
        if Instant::now() > deadline {
            bail!("the echo peer did not start");
        }
    }
    let pixels: Vec<u8> = (0..2 * WIDTH * HEIGHT)
        .map(|i| (i * 31 % 251) as u8)
        .collect();
    let (left, right) = pixels.split_at(WIDTH * HEIGHT);
    let mut one_way = Vec::with_capacity(round_trips);
    for k in 0..round_trips + 20 {
        let mut header = FrameHeader::new(k as u64, 0, now_ns());
        header.width = WIDTH as u32;
        header.height = HEIGHT as u32;
        let sent = Instant::now();
        frames.publish(&header, &[left, right])?;
        let back = loop {
            wake.wait(Duration::from_secs(5))?;
            if let Some(p) = pongs.receive()? {
                break p;
            }
            if sent.elapsed() > Duration::from_secs(5) {
                bail!("no echo of frame {k}");
            }
        };
        let rtt = sent.elapsed();
        anyhow::ensure!(
            back.header().frame.frame_id == k as u64,
            "echo of frame {} for {k}",
            back.header().frame.frame_id
        );
        if k >= 20 {
            // The first round trips warm up caches and page mappings.
            one_way.push(rtt.as_secs_f64() * 1e6 / 2.0);
        }
    }
    Ok(one_way)
}

fn hop_shm(round_trips: usize) -> anyhow::Result<Vec<f64>> {
    let run_id = format!("bench{}", std::process::id());
    let bus = Bus::shared_memory(&Scope::new(&run_id), "bench-ping")?;
    let pinger = Pinger::new(&bus)?;
    let exe = std::env::current_exe()?;
    let mut peer = Command::new(exe)
        .args([
            "--echo",
            &run_id,
            "--round-trips",
            &(round_trips + 20).to_string(),
        ])
        .stdout(Stdio::null())
        .spawn()
        .context("starting the echo peer")?;
    let result = ping(pinger, round_trips);
    let _ = peer.wait();
    result
}

fn hop_local(round_trips: usize) -> anyhow::Result<Vec<f64>> {
    let bus = Bus::local();
    let hub = bus.local_hub().context("local hub")?;
    let pinger = Pinger::new(&bus)?;
    let peer = std::thread::spawn(move || echo("local", Some(hub), round_trips + 20));
    let result = ping(pinger, round_trips);
    peer.join()
        .map_err(|_| anyhow::anyhow!("echo thread panicked"))??;
    result
}

/// The eight parts of the frames' end-to-end paths (waiting for and working in each
/// stage): how many frames each was the largest part of, and its mean share of the frame's
/// end to end, in path order.
fn bottlenecks(frames: &[&FrameRecord]) -> Vec<(String, usize, f64)> {
    let mut parts: Vec<(String, usize, f64)> = StageKind::PROCESSING
        .iter()
        .flat_map(|name| [format!("waiting for {name}"), format!("{name} working")])
        .map(|part| (part, 0, 0.0))
        .collect();
    let mut counted = 0;
    for f in frames {
        let values: Vec<f64> = (0..4).flat_map(|i| [f.wait_ms[i], f.stage_ms[i]]).collect();
        let total: f64 = values.iter().filter(|v| v.is_finite()).sum();
        if total <= 0.0 {
            continue;
        }
        counted += 1;
        let largest = (0..values.len())
            .filter(|&k| values[k].is_finite())
            .max_by(|&a, &b| values[a].total_cmp(&values[b]));
        if let Some(k) = largest {
            parts[k].1 += 1;
        }
        for (part, v) in parts.iter_mut().zip(&values) {
            if v.is_finite() {
                part.2 += v / total;
            }
        }
    }
    for part in &mut parts {
        part.2 /= f64::from(counted.max(1));
    }
    parts
}

/// Which detector worked on the frames, all of them (dropped ones too), e.g. "detector per
/// frame: fld 86, lsd 9 (swapped during the run: …)": a run asked for LSD can run mostly
/// FLD once the automatic policy (`[detector_fallback]`) swaps it, and its figures are then
/// mostly FLD's.
fn detectors_used(frames: &[FrameRecord]) -> String {
    let mut counts = std::collections::BTreeMap::<&str, usize>::new();
    for f in frames {
        let name = if f.detector.is_empty() {
            "none recorded"
        } else {
            f.detector.as_str()
        };
        *counts.entry(name).or_default() += 1;
    }
    let listed: Vec<String> = counts.iter().map(|(k, n)| format!("{k} {n}")).collect();
    let swapped = counts.keys().filter(|k| **k != "none recorded").count() > 1;
    format!(
        "detector per frame: {}{}",
        listed.join(", "),
        if swapped {
            " (swapped during the run: the figures mix the detectors; see `[detector_fallback]`)"
        } else {
            ""
        }
    )
}

fn row(out: &mut String, name: &str, p: &Percentiles, unit: &str) {
    let _ = writeln!(
        out,
        "| {name} | {} | {:.1} | {:.1} | {:.1} | {:.1} {unit} |",
        p.count, p.p50, p.p90, p.p99, p.max
    );
}

fn main() -> ExitCode {
    let args = Args::parse();
    if let Some(run_id) = &args.echo {
        return match echo(run_id, None, args.round_trips) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("echo: {e:#}");
                ExitCode::FAILURE
            }
        };
    }
    match bench(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("linetrack-pipeline-bench: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn bench(args: &Args) -> anyhow::Result<()> {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "## One hop of a {WIDTH}×{HEIGHT} stereo frame ({} KiB), one way (half the round trip), µs\n",
        2 * WIDTH * HEIGHT / 1024
    );
    let _ = writeln!(
        out,
        "| transport | n | p50 | p90 | p99 | max |\n|---|---|---|---|---|---|"
    );
    eprintln!("hop cost: {} round trips per transport", args.round_trips);
    let shm = Percentiles::of(hop_shm(args.round_trips)?).context("no shared-memory samples")?;
    let local = Percentiles::of(hop_local(args.round_trips)?).context("no local samples")?;
    row(&mut out, "iceoryx2 shared memory, two processes", &shm, "");
    row(&mut out, "crossbeam channels, two threads", &local, "");
    let _ = writeln!(
        out,
        "\nshared memory / channels, medians: {:.2}\n",
        shm.p50 / local.p50
    );

    let is_dataset = args.sequence.join("mav0").is_dir() || args.sequence.join("image_0").is_dir();
    if !is_dataset {
        eprintln!(
            "generating {} ({} frames)",
            args.sequence.display(),
            args.frames.max(100)
        );
        linetrack_synth::generate(
            Preset::Normal,
            1,
            args.frames.max(100),
            &args.sequence,
            false,
        )?;
    }
    let mut base = match &args.config {
        Some(path) => PipelineConfig::from_file(path)?,
        None => PipelineConfig::default(),
    };
    if let Some(detector) = args.detector {
        base.detector = detector;
    }
    if let Some(policy) = args.matcher {
        base.matcher.mode = policy;
    }
    let mut runs: [Vec<FrameRecord>; 2] = [Vec::new(), Vec::new()];
    for repeat in 0..args.repeats {
        for (m, mode) in [Mode::Processes, Mode::Threads].into_iter().enumerate() {
            let mut config = base.clone();
            config.source.sequence = args.sequence.clone();
            config.source.max_frames = args.frames;
            config.source.pacing = Pacing::Realtime;
            config.output.trace = false;
            config.output.run_dir = Some(args.output.join(format!(
                "run-{}-{repeat}",
                if m == 0 { "processes" } else { "threads" }
            )));
            eprintln!("pipeline run {}/{}: {:?}", repeat + 1, args.repeats, mode);
            let outcome = linetrack_supervisor::run(
                &config,
                &RunOptions {
                    mode,
                    bin_dir: None,
                    live_status: false,
                },
                &Shutdown::default(),
            )?;
            runs[m].extend(read_frames(&outcome.run_dir.join("frames.csv"))?);
        }
    }
    let _ = writeln!(
        out,
        "## End to end, {} frames × {} runs per mode, `{}` at its own rate, {} + {}, {}, ms\n\npoints: {}\n",
        args.frames,
        args.repeats,
        args.sequence.display(),
        base.detector.name(),
        base.matcher.mode.name(),
        match base.odometry.features {
            Features::PointsAndLines => "points and lines",
            Features::LinesOnly => "lines only",
        },
        base.points_text()
    );
    let names = [
        "one process per stage (iceoryx2)",
        "one process, threads (channels)",
    ];
    let mut medians = [f64::NAN; 2];
    for (m, frames) in runs.iter().enumerate() {
        let _ = writeln!(out, "### {}\n", names[m]);
        let _ = writeln!(
            out,
            "| stage | n | work p50 | work p99 | waited p50 | waited p99 | deadline misses |\n|---|---|---|---|---|---|---|"
        );
        let posed: Vec<&FrameRecord> = frames.iter().filter(|f| f.has_pose()).collect();
        let budget = &base.budget;
        for (i, &stage) in StageKind::PROCESSING.iter().enumerate() {
            let work = Percentiles::of(posed.iter().map(|f| f.stage_ms[i]));
            let waited = Percentiles::of(posed.iter().map(|f| f.wait_ms[i]));
            let misses = budget
                .stage_ms(stage)
                .map_or(0, |b| posed.iter().filter(|f| f.stage_ms[i] > b).count());
            let cell = |p: &Option<Percentiles>, f: fn(&Percentiles) -> f64| {
                p.as_ref()
                    .map_or("–".to_string(), |p| format!("{:.2}", f(p)))
            };
            let _ = writeln!(
                out,
                "| {stage} | {} | {} | {} | {} | {} | {misses} |",
                work.as_ref().map_or(0, |p| p.count),
                cell(&work, |p| p.p50),
                cell(&work, |p| p.p99),
                cell(&waited, |p| p.p50),
                cell(&waited, |p| p.p99),
            );
        }
        let p = Percentiles::of(posed.iter().map(|f| f.end_to_end_ms))
            .context("no frame reached the end")?;
        medians[m] = p.p50;
        let e2e_misses = posed
            .iter()
            .filter(|f| f.end_to_end_ms > budget.end_to_end_ms)
            .count();
        let _ = writeln!(
            out,
            "| **end to end** | {} | {:.2} | {:.2} | | | {e2e_misses} |",
            p.count, p.p50, p.p99
        );
        let dropped = frames.len() - posed.len();
        let _ = writeln!(
            out,
            "\nframes: {} with a pose, {dropped} dropped or missing; end to end p90 {:.2}, max {:.2} ms\n",
            posed.len(),
            p.p90,
            p.max
        );
        let _ = writeln!(out, "{}\n", detectors_used(frames));
        let _ = writeln!(
            out,
            "Critical path: frames per bottleneck (the largest part of the frame's end to end), and the parts' mean share of it\n\n| part | frames | mean share |\n|---|---|---|"
        );
        for (part, frames, share) in bottlenecks(&posed) {
            let _ = writeln!(out, "| {part} | {frames} | {:.0} % |", 100.0 * share);
        }
        let _ = writeln!(out);
    }
    let _ = writeln!(
        out,
        "end-to-end median, processes / threads: {:.3}",
        medians[0] / medians[1]
    );
    print!("{out}");
    std::fs::create_dir_all(&args.output)?;
    std::fs::write(args.output.join("pipeline-bench.md"), &out)?;
    Ok(())
}
