//! One command that reproduces the paper's three tables over generated sequences (one per
//! illumination preset) and the real EuRoC excerpt, and writes a Markdown report with PNG
//! plots: Table I (tracking: matches per frame and inlier ratio), Table II (odometry: RPE,
//! ATE, drift and step ratio, with and without simulated illumination changes), Table III
//! (cost per frame), frame-to-frame line tracking judged against ground truth (`f2f_lines`),
//! and stereo matching scored on the real Middlebury pairs (`linetrack-stereo-bench`).
#![warn(missing_docs)]

mod f2f_lines;
mod line_truth;
mod odometry;
mod tracking;

use anyhow::Context;
use clap::Parser;
use linetrack_datasets::StereoSequence;
use linetrack_progress::Progress;
use linetrack_scene_render::{IlluminationConfig, Preset};
use linetrack_stereo_bench::{Bench, Condition, MatcherEntry};
use linetrack_vision::{DetectorKind, MatcherKind};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;
use tracking::{COMBINATIONS, TrackingResult, median};

/// Command-line arguments.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "linetrack-eval",
    version,
    about = "Reproduce the paper's tables (tracking, odometry, cost) in one Markdown report with plots.",
    after_help = concat!("EXAMPLES:
    linetrack-eval                 # full: 200 frames of every preset + the EuRoC excerpt (tens of minutes)
    linetrack-eval --quick         # CI-sized: 8 frames of three presets + 10 EuRoC frames
    linetrack-eval --no-generated --real-frames 50   # the real sequences only, their first 50 frames

Generated sequences are made on first use in <sequences>/<preset> and reused. The report is
<output>/report.md; plots are PNG files beside it; odometry-runs.csv holds every Table II run
(sequence, seed, configuration, lost frames, ATE, drift, step ratio), for comparing two
--odometry-config files run by run; f2f-lines.csv holds the frame-to-frame line benchmark
(matches judged against ground truth) per sequence, gain jumps or not, and matcher.\n\n", linetrack_progress::progress_help!("work"), "\n\n", linetrack_vision::images_help!())
)]
pub struct Args {
    /// Small settings: three presets, 8 frames each (the EuRoC excerpt: 10 frames).
    #[arg(long)]
    pub quick: bool,
    /// Frames per generated sequence (default: 200, or 8 with --quick).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Frames of each real sequence, from its start (default: all of them, or 10 with
    /// --quick).
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    pub real_frames: Option<usize>,
    /// Leave the generated sequences out: the real sequences (and Middlebury) only, nothing
    /// rendered.
    #[arg(long)]
    pub no_generated: bool,
    /// Where generated sequences are kept.
    #[arg(long, default_value = "out/eval/sequences")]
    pub sequences: PathBuf,
    /// Folder of the report.
    #[arg(long, default_value = "out/eval/report")]
    pub output: PathBuf,
    /// The EuRoC sequence folder (default: the excerpt beside the workspace, if present).
    #[arg(long)]
    pub euroc: Option<PathBuf>,
    /// Leave the EuRoC excerpt out.
    #[arg(long)]
    pub no_euroc: bool,
    /// The Middlebury folder for the real-image stereo section (default: the one beside the
    /// workspace, if present).
    #[arg(long)]
    pub middlebury: Option<PathBuf>,
    /// The KITTI raw drive for the real-motion rows (default: the one beside the workspace,
    /// if present).
    #[arg(long)]
    pub kitti_raw: Option<PathBuf>,
    /// Leave the KITTI raw drive out.
    #[arg(long)]
    pub no_kitti_raw: bool,
    /// Seeds per generated preset in Table II, reported as median and worst (default: 3,
    /// or 1 with --quick). Table I and the starred rows use seed 1.
    #[arg(long)]
    pub seeds: Option<u64>,
    /// Leave the Middlebury stereo section out.
    #[arg(long)]
    pub no_middlebury: bool,
    /// Leave the odometry (Table II) out: tracking, cost and the Middlebury section only.
    #[arg(long)]
    pub no_odometry: bool,
    /// Leave the frame-to-frame line benchmark against ground truth out (every sequence
    /// with and without the simulated gain jumps, both matchers).
    #[arg(long)]
    pub no_f2f_lines: bool,
    /// Front-end configuration for Table I and the Middlebury section (TOML, see
    /// configs/frontend.toml; default: the built-in defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Odometry settings for Table II (TOML, the keys of configs/odometry.toml; default: the
    /// built-in defaults). Each configuration's matcher and features are set over it.
    #[arg(long)]
    pub odometry_config: Option<PathBuf>,
    /// Simulated illumination changes for the starred rows: a new gain and bias every this
    /// many seconds (default: 2 s, or 0.15 s with --quick).
    #[arg(long)]
    pub jump_period_s: Option<f64>,
    /// No progress on stderr (by default a bar with the time left on a terminal, a line per
    /// tenth of the work otherwise); warnings (a data set left out) are still printed.
    #[arg(long)]
    pub quiet: bool,
}

/// A sequence to evaluate.
struct Entry {
    name: String,
    dir: PathBuf,
    sequence: StereoSequence,
    frames: usize,
    /// Whether the starred (simulated illumination) row is run for it.
    perturb: bool,
    /// The same preset with further seeds (Table II only).
    more_seeds: Vec<StereoSequence>,
}

/// Opens `<sequences>/<preset>-<frames>[-seed<k>]`, generating it first when missing.
fn generated(
    args: &Args,
    preset: Preset,
    seed: u64,
    frames: usize,
) -> anyhow::Result<(PathBuf, StereoSequence)> {
    let suffix = if seed == 1 {
        String::new()
    } else {
        format!("-seed{seed}")
    };
    let dir = args
        .sequences
        .join(format!("{}-{frames}{suffix}", preset.name()));
    if !dir.join("mav0/cam0/data.csv").is_file() {
        if !args.quiet {
            eprintln!(
                "generating {} seed {seed} ({frames} frames) in {}",
                preset.name(),
                dir.display()
            );
        }
        linetrack_synth::generate(preset, seed, frames, &dir, args.quiet)?;
    }
    let sequence =
        StereoSequence::open(&dir).with_context(|| format!("cannot open {}", dir.display()))?;
    Ok((dir, sequence))
}

/// A real sequence found beside the workspace or given on the command line.
fn real_entry(
    name: &str,
    given: &Option<PathBuf>,
    found: Result<PathBuf, String>,
    quick_frames: usize,
    args: &Args,
) -> anyhow::Result<Option<Entry>> {
    let dir = match (given, found) {
        (Some(dir), _) => dir.clone(),
        (None, Ok(dir)) => dir,
        (None, Err(why)) => {
            eprintln!("{why}; {name} is left out");
            return Ok(None);
        }
    };
    let sequence =
        StereoSequence::open(&dir).with_context(|| format!("cannot open {}", dir.display()))?;
    let frames = args
        .real_frames
        .unwrap_or(if args.quick { quick_frames } else { usize::MAX })
        .min(sequence.frames.len());
    Ok(Some(Entry {
        name: format!("{name} {}", sequence.name),
        dir,
        sequence,
        frames,
        perturb: true,
        more_seeds: Vec::new(),
    }))
}

fn prepare(args: &Args, frames: usize) -> anyhow::Result<Vec<Entry>> {
    let presets: &[Preset] = if args.no_generated {
        &[]
    } else if args.quick {
        &[
            Preset::Normal,
            Preset::HdrFlicker,
            Preset::LeftRightMismatch,
        ]
    } else {
        &[
            Preset::Normal,
            Preset::HandheldGainJumps,
            Preset::HdrFlicker,
            Preset::HdrSaturation,
            Preset::LightsSwitching,
            Preset::LeftRightMismatch,
            Preset::Highway,
        ]
    };
    let seeds = args.seeds.unwrap_or(if args.quick { 1 } else { 3 }).max(1);
    let mut entries = Vec::new();
    for preset in presets {
        let (dir, sequence) = generated(args, *preset, 1, frames)?;
        let more_seeds = (2..=seeds)
            .map(|seed| Ok(generated(args, *preset, seed, frames)?.1))
            .collect::<anyhow::Result<_>>()?;
        entries.push(Entry {
            name: preset.name().to_string(),
            dir,
            sequence,
            frames,
            perturb: *preset == Preset::Normal,
            more_seeds,
        });
    }
    if !args.no_euroc {
        entries.extend(real_entry(
            "EuRoC",
            &args.euroc,
            linetrack_test_data::euroc_dir(),
            10,
            args,
        )?);
    }
    if !args.no_kitti_raw {
        entries.extend(real_entry(
            "KITTI raw",
            &args.kitti_raw,
            linetrack_test_data::kitti_raw_dir(),
            10,
            args,
        )?);
    }
    Ok(entries)
}

/// Frames whose illumination differs from the previous frame's (generated sequences).
fn illumination_events(dir: &Path) -> Vec<f64> {
    let Ok(text) = std::fs::read_to_string(dir.join("mav0/scene/illumination.csv")) else {
        return Vec::new();
    };
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .skip(1)
                .filter_map(|v| v.parse().ok())
                .collect()
        })
        .collect();
    rows.windows(2)
        .enumerate()
        .filter(|(_, w)| {
            w[0].iter()
                .zip(&w[1])
                .enumerate()
                .any(|(c, (a, b))| (a - b).abs() > if c % 2 == 1 { 0.5 } else { 0.02 })
        })
        .map(|(k, _)| (k + 1) as f64)
        .collect()
}

fn cell(counts: &[tracking::FrameCount]) -> String {
    match TrackingResult::summary(counts) {
        (mean, Some(ratio)) => format!("{mean:.1} / {ratio:.2}"),
        (mean, None) => format!("{mean:.1} / –"),
    }
}

/// Scenes of the quick Middlebury section (small, varied).
const QUICK_PAIRS: [&str; 3] = ["Cones", "Tsukuba", "Venus"];

/// The real-image stereo section: every detector × matcher on the Middlebury pairs (three
/// of them, as photographed and over-exposed, with --quick), its table and plot.
fn middlebury_section(
    args: &Args,
    config: &linetrack_vision::FrontendConfig,
) -> anyhow::Result<String> {
    if args.no_middlebury {
        return Ok(String::new());
    }
    let dir = match &args.middlebury {
        Some(dir) => dir.clone(),
        None => match linetrack_test_data::middlebury_dir() {
            Ok(dir) => dir,
            Err(why) => {
                eprintln!("{why}; the Middlebury section is left out (give --middlebury DIR)");
                return Ok(String::new());
            }
        },
    };
    let mut pairs = linetrack_datasets::list_middlebury(&dir)?;
    let conditions = if args.quick {
        pairs.retain(|p| QUICK_PAIRS.contains(&p.name.as_str()));
        vec![Condition::AsIs, Condition::OverExposed]
    } else {
        Condition::ALL.to_vec()
    };
    let bench = Bench {
        detectors: DetectorKind::ALL.to_vec(),
        matchers: MatcherEntry::defaults(config),
        conditions,
        detection: config.clone(),
        scorer: Default::default(),
    };
    let progress = Progress::new("middlebury pairs", pairs.len() as u64, args.quiet);
    let rows = linetrack_stereo_bench::evaluate(&pairs, &bench, |done, _, name| {
        progress.step(name);
        progress.set(done as u64);
    })?;
    progress.finish();
    let aggregates = linetrack_stereo_bench::aggregate(&rows);
    let goals = linetrack_stereo_bench::goals(&aggregates, "l1", "lbd");
    linetrack_stereo_bench::write_csv(&args.output.join("stereo-bench.csv"), &rows)?;
    linetrack_stereo_bench::plot(&args.output.join("stereo-bench.png"), &aggregates)?;
    Ok(format!(
        "\n## Stereo matching on real images (Middlebury)\n\nReal rectified pairs with structured-light ground-truth \
         disparity; the right image as photographed and under simulated illumination changes. A match is correct when the \
         left segment, carried by the true disparity, lies within 1 px of the right segment's line and overlaps it. Per pair: \
         `stereo-bench.csv`.\n\n{}\n![stereo-bench.png](stereo-bench.png)\n",
        linetrack_stereo_bench::markdown(&aggregates, &goals, pairs.len())
    ))
}

/// The section of the frame-to-frame line benchmark (`f2f_lines`), its table from `results`.
fn f2f_section(results: &[(String, bool, f2f_lines::Outcome)], period_s: f64) -> String {
    format!(
        "\n## Frame-to-frame line tracking against ground truth\n\nLSD segments of the left images of consecutive \
         frames (stretched as the odometry does), matched frame to frame by each matcher as the odometry matches them: \
         *as seen*, from where they were; *predicted*, from where the previous true step, repeated, puts those with a \
         3-D position (constant velocity, as the odometry predicts with its last estimate; the first pair as seen). A match is judged when its previous segment has a 3-D position: \
         from the exact depth map (generated sequences; depths beyond 13.1 m are not stored, so far segments are not \
         judged), or triangulated from the stereo partner both matchers agree on (real sequences; segments within the \
         odometry's angle of horizontal are not triangulated). It is correct when that segment, moved by the \
         ground-truth motion and projected into the current frame, lies within {} px of the matched segment's line \
         (median over points along it) and overlaps it; *disjoint*: wrong, on that line but not overlapping it (another \
         part of the same straight edge, which a line residual does not tell apart). Gain jumps: a gain α ~ U(0.5, 2.5) and bias β ~ U(0, 20) every \
         {period_s} s on both images (the starred rows' changes). Per sequence: `f2f-lines.csv`.\n\n{}",
        line_truth::MAX_ERROR_PX,
        f2f_lines::markdown(results)
    )
}

/// The work of Tables I and II in frames (one frame through one configuration), for the
/// progress: every detector × matcher over each sequence, the frame-to-frame line
/// benchmark with and without gain jumps, then every odometry configuration over each
/// sequence, its starred variant and its further seeds.
fn work_units(args: &Args, entries: &[Entry]) -> u64 {
    entries
        .iter()
        .map(|entry| {
            let tracking = COMBINATIONS.len();
            let odometry = if args.no_odometry {
                0
            } else {
                let runs_per_configuration =
                    1 + entry.more_seeds.len() + usize::from(entry.perturb);
                odometry::CONFIGURATIONS.len() * runs_per_configuration
            };
            let f2f_lines = if args.no_f2f_lines { 0 } else { 2 };
            ((tracking + odometry + f2f_lines) * entry.frames) as u64
        })
        .sum()
}

/// Runs everything and writes the report; returns a summary.
pub fn run(args: &Args) -> anyhow::Result<String> {
    let started = Instant::now();
    let frames = args.frames.unwrap_or(if args.quick { 8 } else { 200 });
    let seeds = args.seeds.unwrap_or(if args.quick { 1 } else { 3 }).max(1);
    let period = args
        .jump_period_s
        .unwrap_or(if args.quick { 0.15 } else { 2.0 });
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("cannot create {}", args.output.display()))?;
    let frontend = match &args.config {
        Some(path) => linetrack_vision::FrontendConfig::from_file(path)?,
        None => linetrack_vision::FrontendConfig::default(),
    };
    let odometry_base = match &args.odometry_config {
        Some(path) => linetrack_odometry::OdometryConfig::from_file(path)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--odometry-config {}", path.display()))?,
        None => linetrack_odometry::OdometryConfig::default(),
    };
    let mut odometry_rows: Vec<odometry::RunRow> = Vec::new();
    let entries = prepare(args, frames)?;
    let jumps = IlluminationConfig {
        seed: 7,
        gain_jump_period_s: Some(period),
        ..IlluminationConfig::default()
    };
    let simulated = move |t: f64| {
        let il = jumps.at(t, 0);
        (il.gain[0], il.bias[0])
    };

    let combination_names: Vec<String> = COMBINATIONS
        .iter()
        .map(|(d, m)| {
            let matcher = match m {
                MatcherKind::L1 => "ℓ1",
                other => &other.name().to_uppercase(),
            };
            format!("{}+{matcher}", d.name().to_uppercase())
        })
        .collect();
    let mut table1 = format!(
        "| sequence | case | {} |\n|---|---|{}\n",
        combination_names.join(" | "),
        "---|".repeat(COMBINATIONS.len())
    );
    let mut costs: Vec<(Vec<f64>, Vec<f64>)> = vec![(Vec::new(), Vec::new()); COMBINATIONS.len()];
    let mut table2 = String::from(
        "| sequence | P+L, LBD | step ratio | P+L, ℓ1 | step ratio | L, LBD | step ratio | L, ℓ1 | step ratio |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut plots = Vec::new();
    let mut baselines = String::new();
    let mut f2f_benchmark = if args.no_f2f_lines {
        None
    } else {
        Some(f2f_lines::Benchmark::new(&odometry_base)?)
    };
    let (mut f2f_results, mut f2f_rows) = (Vec::new(), Vec::new());
    let progress = Progress::new("eval frames", work_units(args, &entries), args.quiet);
    for entry in &entries {
        progress.step(format!("tracking {}", entry.name));
        let results: Vec<TrackingResult> = COMBINATIONS
            .iter()
            .map(|c| {
                let result = tracking::evaluate(
                    &entry.dir,
                    &entry.sequence,
                    &frontend,
                    *c,
                    entry.frames,
                    None,
                );
                progress.inc(entry.frames as u64);
                result
            })
            .collect::<anyhow::Result<_>>()?;
        for (case, pick) in [("stereo", 0usize), ("frame to frame", 1)] {
            let cells: Vec<String> = results
                .iter()
                .map(|r| {
                    cell(if pick == 0 {
                        &r.stereo
                    } else {
                        &r.frame_to_frame
                    })
                })
                .collect();
            writeln!(
                table1,
                "| {} | {case} | {} |",
                entry.name,
                cells.join(" | ")
            )?;
        }
        for (k, r) in results.iter().enumerate() {
            costs[k].0.extend(&r.mono_ms);
            costs[k].1.extend(&r.stereo_ms);
        }
        let slug = entry.name.replace(' ', "-");
        let events = illumination_events(&entry.dir);
        let per_frame = |r: &TrackingResult, ratio: bool| -> Vec<(f64, f64)> {
            r.frame_to_frame
                .iter()
                .enumerate()
                .map(|(k, c)| {
                    (
                        k as f64,
                        if ratio {
                            if c.judged > 0 {
                                c.inliers as f64 / c.judged as f64
                            } else {
                                f64::NAN
                            }
                        } else {
                            c.matches as f64
                        },
                    )
                })
                .collect()
        };
        let path = args.output.join(format!("tracking-{slug}.png"));
        let series = vec![
            ("LSD+LBD matches".to_string(), per_frame(&results[0], false)),
            ("LSD+l1 matches".to_string(), per_frame(&results[1], false)),
        ];
        linetrack_plot::lines(
            &path,
            &format!(
                "{}: frame-to-frame matches (dashed: illumination events)",
                entry.name
            ),
            "frame",
            "matches",
            &series,
            &events,
            false,
        )?;
        plots.push(path);
        if results[0].frame_to_frame.iter().any(|c| c.judged > 0) {
            let path = args.output.join(format!("inliers-{slug}.png"));
            let series = vec![
                (
                    "LSD+LBD inlier ratio".to_string(),
                    per_frame(&results[0], true),
                ),
                (
                    "LSD+l1 inlier ratio".to_string(),
                    per_frame(&results[1], true),
                ),
            ];
            linetrack_plot::lines(
                &path,
                &format!(
                    "{}: frame-to-frame inlier ratio (dashed: illumination events)",
                    entry.name
                ),
                "frame",
                "inlier ratio",
                &series,
                &events,
                false,
            )?;
            plots.push(path);
        }

        if let Some(benchmark) = &mut f2f_benchmark {
            progress.step(format!("frame-to-frame lines {}", entry.name));
            let with_jumps: tracking::Illumination<'_> = Some(&simulated);
            for (jumps, illumination) in [(false, None), (true, with_jumps)] {
                let outcome =
                    benchmark.run(&entry.dir, &entry.sequence, entry.frames, illumination)?;
                progress.inc(entry.frames as u64);
                f2f_rows.extend(f2f_lines::Row::of(&entry.name, jumps, &outcome));
                f2f_results.push((entry.name.clone(), jumps, outcome));
            }
        }

        if args.no_odometry {
            continue;
        }
        progress.step(format!("odometry {}", entry.name));
        let variants: Vec<(String, tracking::Illumination<'_>)> = if entry.perturb {
            vec![
                (entry.name.clone(), None),
                (format!("{}*", entry.name), Some(&simulated)),
            ]
        } else {
            vec![(entry.name.clone(), None)]
        };
        for (row_name, illumination) in variants {
            let mut cells = Vec::new();
            let mut trajectories = Vec::new();
            for (label, features, matcher) in odometry::CONFIGURATIONS {
                let run = odometry::run(
                    &entry.sequence,
                    (&odometry_base, features, matcher),
                    entry.frames,
                    illumination,
                )?;
                progress.inc(entry.frames as u64);
                if illumination.is_none()
                    && let Some(m) = &run.metrics
                    && trajectories.is_empty()
                    && entry.name.starts_with(char::is_uppercase)
                {
                    writeln!(
                        baselines,
                        "- {}: path {:.2} m; staying put (zero motion) scores ATE {:.1} cm.",
                        entry.name,
                        m.path_m,
                        m.zero_motion_ate_m.unwrap_or(f64::NAN) * 1e2
                    )?;
                }
                let mut runs = vec![run];
                if illumination.is_none() {
                    for sequence in &entry.more_seeds {
                        runs.push(odometry::run(
                            sequence,
                            (&odometry_base, features, matcher),
                            entry.frames,
                            None,
                        )?);
                        progress.inc(entry.frames as u64);
                    }
                }
                cells.push(odometry::cell(&runs));
                cells.push(odometry::step_ratio_cell(&runs));
                odometry_rows.extend(
                    runs.iter()
                        .enumerate()
                        .map(|(k, run)| odometry::RunRow::new(&row_name, k as u64 + 1, label, run)),
                );
                let run = &runs[0];
                if trajectories.is_empty()
                    && let Some(truth) = &run.truth
                {
                    trajectories.push((
                        "ground truth".to_string(),
                        truth
                            .iter()
                            .map(|p| (p.translation.x, p.translation.z))
                            .collect(),
                    ));
                }
                trajectories.push((
                    label.replace('ℓ', "l"),
                    run.estimate
                        .iter()
                        .map(|p| (p.translation.x, p.translation.z))
                        .collect::<Vec<_>>(),
                ));
            }
            writeln!(table2, "| {row_name} | {} |", cells.join(" | "))?;
            let path = args.output.join(format!(
                "trajectory-{}.png",
                row_name.replace(' ', "-").replace('*', "-perturbed")
            ));
            linetrack_plot::lines(
                &path,
                &format!(
                    "{row_name}: top view of the left camera (x right, z forward of the first frame)"
                ),
                "x [m]",
                "z [m]",
                &trajectories,
                &[],
                true,
            )?;
            plots.push(path);
        }
    }

    progress.finish();
    // The paper's figures, by combination (it has none for our own detector).
    let paper = |d: DetectorKind, m: MatcherKind| match (d, m) {
        (DetectorKind::Lsd, MatcherKind::Lbd) => ("39.3", "51.3"),
        (DetectorKind::Lsd, MatcherKind::L1) => ("25.9", "35.8"),
        (DetectorKind::Fld, MatcherKind::Lbd) => ("18.1", "33.3"),
        (DetectorKind::Fld, MatcherKind::L1) => ("7.7", "23.4"),
        _ => ("–", "–"),
    };
    let mut table3 = String::from(
        "| detector + matcher | mono ms/frame | stereo ms/frame | paper mono | paper stereo |\n|---|---|---|---|---|\n",
    );
    for (k, (d, m)) in COMBINATIONS.iter().enumerate() {
        writeln!(
            table3,
            "| {}+{} | {:.1} | {:.1} | {} | {} |",
            d.name().to_uppercase(),
            m.name(),
            median(&costs[k].0),
            median(&costs[k].1),
            paper(*d, *m).0,
            paper(*d, *m).1
        )?;
    }
    let plot_list: Vec<String> = plots
        .iter()
        .filter_map(|p| p.file_name())
        .map(|n| format!("![{0}]({0})", n.to_string_lossy()))
        .collect();
    let real: Vec<&str> = entries
        .iter()
        .filter(|e| e.name.starts_with(char::is_uppercase))
        .map(|e| e.name.as_str())
        .collect();
    let real_names = if real.is_empty() {
        String::new()
    } else {
        format!(
            "; real sequences (rectified on load where needed): {}",
            real.join(", ")
        )
    };
    let (min_step_cm, min_steps) = (
        linetrack_odometry::metrics::MIN_RATIO_STEP_M * 1e2,
        linetrack_odometry::metrics::MIN_RATIO_STEPS,
    );
    let report = format!(
        "# linetrack evaluation\n\n\
         Settings: {frames} frames per generated sequence (seed 1, 20 Hz, 752×480, 11 cm baseline){}; starred rows add simulated \
         illumination changes (a gain α ~ U(0.5, 2.5) and bias β ~ U(0, 20) drawn every {period} s, applied to both images). \
         Command: `linetrack-eval{}`. Run time: {:.0} s.\n\n\
         ## Table I — tracking\n\nMean matches per frame / inlier ratio, for each detector + matcher. {}\n\n{table1}\n\
         ## Table II — visual odometry\n\nTranslational RPE RMSE per frame (step 1) / ATE RMSE / drift, LSD segments; P+L = ORB \
         points and segments, L = segments only. Generated presets: {seeds} seed(s), the median ATE and its drift, then the worst \
         ATE and the worst drift. Beside each configuration its step ratio: overall / median (p10–p90), and over seeds those of \
         the median-ATE seed, then the overall ratio furthest from 1. A lost frame keeps the last motion as a prediction; lost frames are counted in bold (summed over \
         seeds).\n\n{table2}\n{baselines}\n\
         Definitions (as the TUM benchmark tools): RPE over pose pairs one frame apart, E_i = (Q_i⁻¹Q_{{i+1}})⁻¹(P_i⁻¹P_{{i+1}}), RMSE \
         of ‖trans(E_i)‖; ATE after aligning both trajectories at their first pose (no scale, no least-squares fit), RMSE of \
         ‖trans(Q₀⁻¹Q_i) − trans(P₀⁻¹P_i)‖; drift: final position error over the true path length, not given under 1 m; step \
         ratio: estimated over true step length ‖trans(P_i⁻¹P_{{i+1}})‖ / ‖trans(Q_i⁻¹Q_{{i+1}})‖ of each pair of consecutive frames, \
         steps where the truth moves under {min_step_cm} cm left out (none with fewer than {min_steps} steps left: –), overall = sum of estimated over \
         sum of true step lengths, percentiles by nearest rank; 1 is unbiased, above 1 the estimate moves too far. P: \
         estimate, Q: ground truth.\n\n\
         ## Table III — cost\n\nMedian milliseconds per frame over all frames and sequences of Table I, this machine. Mono = detect + \
         describe one image + frame-to-frame match; stereo = both images + stereo match + frame-to-frame match, processed one after \
         the other.\n\n{table3}\n## Plots\n\n{}\n",
        real_names,
        if args.quick { " --quick" } else { "" },
        started.elapsed().as_secs_f64(),
        "Inlier: the segment, carried into the other image by ground-truth depth and pose, lies within 1 px of the matched segment's \
         line (median over five points along it). The real excerpt has no depth maps: its inlier ratio is not judged (–).",
        plot_list.join("\n")
    );
    let f2f_section = if args.no_f2f_lines {
        String::new()
    } else {
        f2f_section(&f2f_results, period)
    };
    let stereo_section = middlebury_section(args, &frontend)?;
    let report = format!("{report}{f2f_section}{stereo_section}");
    let report_path = args.output.join("report.md");
    std::fs::write(&report_path, report)
        .with_context(|| format!("cannot write {}", report_path.display()))?;
    if !f2f_rows.is_empty() {
        odometry::write_rows(&args.output.join("f2f-lines.csv"), &f2f_rows)?;
    }
    if !odometry_rows.is_empty() {
        odometry::write_rows(&args.output.join("odometry-runs.csv"), &odometry_rows)?;
    }
    Ok(format!(
        "wrote {} ({} sequences, {} plots) in {:.0} s",
        report_path.display(),
        entries.len(),
        plots.len(),
        started.elapsed().as_secs_f64()
    ))
}
