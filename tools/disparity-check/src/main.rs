//! `linetrack-disparity-check`: the odometry's triangulated disparities against the
//! Middlebury ground truth, per disparity band.

use anyhow::Context;
use clap::Parser;
use linetrack_datasets::LoadedPair;
use linetrack_disparity_check::{
    RepeatCounts, RepeatRow, Row, TruthShift, check_pair, markdown, rendered_pair, repeat_markdown,
    repeatability, rows, truth_shift,
};
use linetrack_odometry::{OdometryConfig, SightingKind};
use linetrack_scene_render::Preset;
use linetrack_vision::{MatcherKind, OrbOptions, PointExtractorKind};
use std::path::PathBuf;
use std::process::ExitCode;

/// Command-line arguments.
#[derive(Debug, Parser)]
#[command(
    name = "linetrack-disparity-check",
    version,
    about = "Run the odometry's stereo front end on the real Middlebury pairs and compare every disparity it triangulates (stereo points, segment endpoints) with the ground truth: signed error per disparity band.",
    after_help = concat!("EXAMPLES:
    linetrack-disparity-check                         # every pair, LBD and l1
    linetrack-disparity-check --matcher l1 --pair Cones
    linetrack-disparity-check --config configs/odometry.toml
    linetrack-disparity-check --config rows.toml      # rows.toml: configs/odometry.toml with
                                                      # [frontend.orb] stereo = \"row-search\"
    linetrack-disparity-check --generated highway --generated normal --seed 2   # exact truth
    linetrack-disparity-check --repeatability --levels 1 --levels 8   # point extractors
    linetrack-disparity-check --truth-shift           # does each truth fit its own images?

The error is the odometry's disparity minus the ground truth under the left pixel
(bilinear between pixel centres). A sighting off by more than --inlier-px is a wrong match:
counted, and left out of the bias of the correct ones. A negative mean in a band is a depth
read too long there, by about |mean| / d. With --generated, the pairs are frames of generated
sequences (rendered in memory, 100 frames long, --frames of them evenly spaced) and the truth
is the renderer's exact depth at each pixel centre. Sightings over a depth edge (the four pixels around differ by
more than --max-spread-px) or over unknown ground truth are left out and counted.

With --repeatability, no odometry runs: both point extractors (orb-opencv, fast-brief), with
the config's [frontend.orb] settings and each --levels, find points in both images, and a
left point with ground truth counts as repeated when a right point lies within --radius-px
of its true position (x − d, y); the table gives the fraction and the mean distance of the
repeated ones (repeatability.md and .json). Our extractor keeps, image by image, as many
points as OpenCV's found there (more points would make a chance neighbour likelier).

With --truth-shift, no odometry runs either: for each pair, the constant that, added to
every disparity of the ground truth, best maps the right image onto the left (every pixel
with a horizontal gradient of 4 grey levels or more, truth away from depth edges, the right
row sampled with a cubic, residuals truncated at 16 grey levels; shifts of ±1 px searched
in 0.01 px steps, the best refined by a parabola). A truth in its images' own convention
gives about 0; one off by a constant gives that constant (truth-shift.md and .json).

OUTPUT: <output>/disparity-check.md (the table), disparity-check.json (the rows) and, with
--samples, samples.jsonl (every sighting: scene, matcher, kind, disparities, error).

", linetrack_progress::progress_help!("pairs"))
)]
struct Args {
    /// Folder of the Middlebury scenes (default: ../shared/data/middlebury beside the workspace).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Only these scenes (repeatable, by folder name).
    #[arg(long = "pair")]
    pairs: Vec<String>,
    /// Check frames of this generated sequence preset instead of Middlebury (repeatable).
    #[arg(long = "generated")]
    generated: Vec<Preset>,
    /// Seed of the generated sequences.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Frames checked per generated sequence, evenly spaced over its 100.
    #[arg(long, default_value_t = 5)]
    frames: usize,
    /// Segment matchers to run the odometry with (repeatable; default: lbd and l1).
    #[arg(long = "matcher")]
    matchers: Vec<MatcherKind>,
    /// Odometry configuration (TOML, see configs/odometry.toml; default: the defaults).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Ground truth whose four pixels around a sighting differ by more than this is a depth
    /// edge: the sighting is left out, pixels.
    #[arg(long, default_value_t = 1.0)]
    max_spread_px: f64,
    /// Folder of the outputs.
    #[arg(long, default_value = "out/disparity-check")]
    output: PathBuf,
    /// A sighting off the ground truth by more than this is a wrong match (counted apart,
    /// left out of the bias), pixels.
    #[arg(long, default_value_t = 2.0)]
    inlier_px: f64,
    /// Score the point extractors' repeatability instead of the odometry's disparities.
    #[arg(long)]
    repeatability: bool,
    /// Repeatability: a left point is repeated when a right point lies this close to its
    /// true position, pixels.
    #[arg(long, default_value_t = 1.5)]
    radius_px: f64,
    /// Repeatability: pyramid levels to run both extractors with (repeatable; default: the
    /// config's).
    #[arg(long = "levels")]
    levels: Vec<i32>,
    /// Check the ground truth against its own images instead: the shift of the truth that
    /// best maps the right image onto the left, per pair.
    #[arg(long, conflicts_with = "repeatability")]
    truth_shift: bool,
    /// Also write every sighting with its error (samples.jsonl).
    #[arg(long)]
    samples: bool,
    /// No progress on stderr.
    #[arg(long)]
    quiet: bool,
}

fn main() -> ExitCode {
    match run() {
        Ok(table) => {
            print!("{table}");
            ExitCode::SUCCESS
        }
        Err(error) => {
            eprintln!("linetrack-disparity-check: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> anyhow::Result<String> {
    let args = Args::parse();
    if !(args.max_spread_px.is_finite() && args.max_spread_px >= 0.0) {
        anyhow::bail!("--max-spread-px {}: must be ≥ 0", args.max_spread_px);
    }
    if !(args.inlier_px.is_finite() && args.inlier_px > 0.0) {
        anyhow::bail!("--inlier-px {}: must be > 0", args.inlier_px);
    }
    let pairs = sources(&args)?;
    let config = match &args.config {
        Some(path) => OdometryConfig::from_file(path)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--config {}", path.display()))?,
        None => OdometryConfig::default(),
    };
    if args.repeatability {
        return run_repeatability(&args, &pairs, &config.frontend.orb);
    }
    if args.truth_shift {
        return run_truth_shift(&args, &pairs);
    }
    let matchers = if args.matchers.is_empty() {
        vec![MatcherKind::Lbd, MatcherKind::L1]
    } else {
        args.matchers.clone()
    };
    let progress = linetrack_progress::Progress::new("pairs", pairs.len() as u64, args.quiet);
    // Points do not depend on the segment matcher: they are taken from the first run.
    let mut points = Vec::new();
    let mut endpoints = vec![Vec::new(); matchers.len()];
    let mut without_truth = 0;
    let mut all_samples = Vec::new();
    for (done, pair) in pairs.iter().enumerate() {
        progress.step(pair.name.as_str());
        let loaded = (pair.load)().with_context(|| format!("scene {}", pair.name))?;
        for (m, &matcher) in matchers.iter().enumerate() {
            let found = check_pair(&loaded, &config, matcher, args.max_spread_px)
                .with_context(|| format!("scene {} with {}", pair.name, matcher.name()))?;
            for sample in found.samples {
                if args.samples {
                    all_samples.push(serde_json::json!({
                        "scene": pair.name,
                        "matcher": matcher.name(),
                        "sample": sample,
                        "error_px": sample.error_px(),
                    }));
                }
                match sample.kind {
                    SightingKind::Point if m == 0 => points.push(sample),
                    SightingKind::Point => {}
                    SightingKind::SegmentEndpoint => endpoints[m].push(sample),
                }
            }
            without_truth += found.without_truth;
        }
        progress.set(done as u64 + 1);
    }
    progress.finish();
    let mut table: Vec<Row> = rows(SightingKind::Point, "(any)", &points, args.inlier_px);
    for (matcher, samples) in matchers.iter().zip(&endpoints) {
        table.extend(rows(
            SightingKind::SegmentEndpoint,
            matcher.name(),
            samples,
            args.inlier_px,
        ));
    }
    let text = format!(
        "{}\n{} pairs; {without_truth} sightings without ground truth (unknown or a depth edge) left out.\n",
        markdown(&table),
        pairs.len()
    );
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let md = args.output.join("disparity-check.md");
    std::fs::write(&md, &text).with_context(|| format!("writing {}", md.display()))?;
    let json = args.output.join("disparity-check.json");
    std::fs::write(&json, serde_json::to_string_pretty(&table)?)
        .with_context(|| format!("writing {}", json.display()))?;
    if args.samples {
        let path = args.output.join("samples.jsonl");
        let lines: String = all_samples.iter().map(|v| format!("{v}\n")).collect();
        std::fs::write(&path, lines).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(text)
}

/// The repeatability table of both point extractors at each of `args.levels` over `pairs`.
fn run_repeatability(args: &Args, pairs: &[Source], orb: &OrbOptions) -> anyhow::Result<String> {
    if !(args.radius_px.is_finite() && args.radius_px > 0.0) {
        anyhow::bail!("--radius-px {}: must be > 0", args.radius_px);
    }
    let levels = match args.levels.is_empty() {
        true => vec![orb.levels],
        false => args.levels.clone(),
    };
    let variants: Vec<OrbOptions> = levels
        .iter()
        .flat_map(|&levels| {
            PointExtractorKind::ALL.map(|extractor| OrbOptions {
                extractor,
                levels,
                ..*orb
            })
        })
        .collect();
    let mut totals = vec![RepeatCounts::default(); variants.len()];
    let progress = linetrack_progress::Progress::new("pairs", pairs.len() as u64, args.quiet);
    for (done, pair) in pairs.iter().enumerate() {
        progress.step(pair.name.as_str());
        let loaded = (pair.load)().with_context(|| format!("scene {}", pair.name))?;
        // OpenCV's first at each depth; ours then held to its counts.
        let mut found = None;
        for (options, total) in variants.iter().zip(&mut totals) {
            let counts = match options.extractor {
                PointExtractorKind::OrbOpenCv => None,
                PointExtractorKind::FastBrief => found,
            };
            let (counts, points) =
                repeatability(&loaded, options, counts, args.radius_px, args.max_spread_px)
                    .with_context(|| {
                        format!("scene {} with {}", pair.name, options.extractor.name())
                    })?;
            if options.extractor == PointExtractorKind::OrbOpenCv {
                found = Some(points);
            }
            total.add(&counts);
        }
        progress.set(done as u64 + 1);
    }
    progress.finish();
    let rows: Vec<RepeatRow> = variants
        .iter()
        .zip(&totals)
        .map(|(options, counts)| RepeatRow {
            extractor: options.extractor.name().to_string(),
            levels: options.levels,
            counts: *counts,
            repeatability: counts.repeatability(),
            mean_distance_px: counts.mean_distance_px(),
        })
        .collect();
    let text = format!(
        "{}\n{} pairs, {} points an image.\n",
        repeat_markdown(&rows, args.radius_px),
        pairs.len(),
        orb.features
    );
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let md = args.output.join("repeatability.md");
    std::fs::write(&md, &text).with_context(|| format!("writing {}", md.display()))?;
    let json = args.output.join("repeatability.json");
    std::fs::write(&json, serde_json::to_string_pretty(&rows)?)
        .with_context(|| format!("writing {}", json.display()))?;
    Ok(text)
}

/// The shift of each pair's truth that best maps its right image onto its left one.
fn run_truth_shift(args: &Args, pairs: &[Source]) -> anyhow::Result<String> {
    #[derive(serde::Serialize)]
    struct ShiftRow {
        pair: String,
        #[serde(flatten)]
        shift: TruthShift,
    }
    let progress = linetrack_progress::Progress::new("pairs", pairs.len() as u64, args.quiet);
    let mut rows = Vec::new();
    for (done, pair) in pairs.iter().enumerate() {
        progress.step(pair.name.as_str());
        let loaded = (pair.load)().with_context(|| format!("scene {}", pair.name))?;
        if let Some(shift) = truth_shift(&loaded, &loaded.disparity, args.max_spread_px)
            .with_context(|| format!("scene {}", pair.name))?
        {
            rows.push(ShiftRow {
                pair: pair.name.clone(),
                shift,
            });
        }
        progress.set(done as u64 + 1);
    }
    progress.finish();
    let mut text = String::from(
        "| pair | truth shift (px) | pixels compared | rms residual (grey) |\n|---|---|---|---|\n",
    );
    for row in &rows {
        text += &format!(
            "| {} | {:+.3} | {} | {:.1} |\n",
            row.pair, row.shift.shift_px, row.shift.pixels, row.shift.rms_grey
        );
    }
    let mut shifts: Vec<f64> = rows.iter().map(|r| r.shift.shift_px).collect();
    shifts.sort_by(f64::total_cmp);
    if let (Some(first), Some(last)) = (shifts.first(), shifts.last()) {
        text += &format!(
            "\n{} pairs: mean {:+.3} px, median {:+.3} px, from {first:+.3} to {last:+.3}. Positive: the truth reads smaller than the disparity its images fit best.\n",
            shifts.len(),
            shifts.iter().sum::<f64>() / shifts.len() as f64,
            shifts[shifts.len() / 2],
        );
    }
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let md = args.output.join("truth-shift.md");
    std::fs::write(&md, &text).with_context(|| format!("writing {}", md.display()))?;
    let json = args.output.join("truth-shift.json");
    std::fs::write(&json, serde_json::to_string_pretty(&rows)?)
        .with_context(|| format!("writing {}", json.display()))?;
    Ok(text)
}

/// One stereo pair to check: its name and how to load it.
struct Source {
    name: String,
    load: Box<dyn Fn() -> anyhow::Result<LoadedPair>>,
}

/// The pairs `args` asks for: frames of the generated presets, or the Middlebury scenes.
fn sources(args: &Args) -> anyhow::Result<Vec<Source>> {
    const SEQUENCE_FRAMES: usize = 100;
    if !args.generated.is_empty() {
        if !(1..=SEQUENCE_FRAMES).contains(&args.frames) {
            anyhow::bail!("--frames {}: must be 1 to {SEQUENCE_FRAMES}", args.frames);
        }
        let seed = args.seed;
        let step = SEQUENCE_FRAMES / args.frames;
        return Ok(args
            .generated
            .iter()
            .flat_map(|&preset| {
                (0..args.frames).map(move |k| Source {
                    name: format!("{} seed {seed} frame {}", preset.name(), k * step),
                    load: Box::new(move || rendered_pair(preset, seed, SEQUENCE_FRAMES, k * step)),
                })
            })
            .collect());
    }
    let data = match &args.data {
        Some(dir) => dir.clone(),
        None => linetrack_test_data::middlebury_dir().map_err(anyhow::Error::msg)?,
    };
    Ok(linetrack_datasets::select_middlebury(&data, &args.pairs)?
        .into_iter()
        .map(|pair| Source {
            name: pair.name.clone(),
            load: Box::new(move || Ok(pair.load()?)),
        })
        .collect())
}
