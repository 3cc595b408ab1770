//! `linetrack-stereo-bench`: stereo segment matching scored on the real Middlebury pairs.

use anyhow::Context;
use clap::Parser;
use linetrack_stereo_bench::{Bench, Condition, MatcherEntry, aggregate, goals, markdown, plot};
use linetrack_vision::{DetectorKind, FrontendConfig, MatcherKind};
use std::path::PathBuf;
use std::process::ExitCode;

/// Command-line arguments.
#[derive(Debug, Parser)]
#[command(
    name = "linetrack-stereo-bench",
    version,
    about = "Score stereo segment matching (every detector × matcher) on real Middlebury pairs with ground-truth disparity, as photographed and under simulated illumination changes of the right image.",
    after_help = concat!("EXAMPLES:
    linetrack-stereo-bench                               # every pair, detector, matcher and condition
    linetrack-stereo-bench --condition as-is --detector lsd
    linetrack-stereo-bench --compare l1-paper=l1:configs/l1-matcher-paper.toml

A detector's stereo repeatability is the share of its left segments that some right segment
would correctly match (the same rule).

A match is correct when the left segment, shifted by the ground-truth disparity read along
it (either side of a depth edge, whichever surface fits), lies within 1 px of the right
segment's line and overlaps it. Precision = correct / judged matches; recall = correct /
matchable left segments (those some detected right segment would correctly match).

OUTPUT: <output>/stereo-bench.md (tables and goals), stereo-bench.csv (one row per pair ×
condition × detector × matcher), stereo-bench.png (precision against correct matches), and
with --matches, matches.jsonl (every match with its verdict).

", linetrack_progress::progress_help!("pairs"), "\n\n", linetrack_vision::images_help!())
)]
struct Args {
    /// Folder of the Middlebury scenes (default: ../shared/data/middlebury beside the workspace).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Detectors to run (repeatable; default: all, lsd, fld and edgelines).
    #[arg(long = "detector")]
    detectors: Vec<DetectorKind>,
    /// Conditions of the right image (repeatable; default: all).
    #[arg(long = "condition")]
    conditions: Vec<Condition>,
    /// Only these scenes (repeatable, by folder name).
    #[arg(long = "pair")]
    pairs: Vec<String>,
    /// Front-end configuration (TOML, see configs/frontend.toml) for detection and the
    /// `lbd` and `l1` matchers.
    #[arg(long)]
    config: Option<PathBuf>,
    /// An extra matcher column: LABEL=MATCHER:CONFIG, CONFIG a front-end TOML file or, for
    /// the l1 matcher, an l1-matcher TOML file (repeatable).
    #[arg(long = "compare", value_parser = parse_compare)]
    compare: Vec<(String, MatcherKind, PathBuf)>,
    /// Folder of the outputs.
    #[arg(long, default_value = "out/stereo-bench")]
    output: PathBuf,
    /// Also write every match with its verdict (matches.jsonl).
    #[arg(long)]
    matches: bool,
    /// No progress on stderr (by default a bar with the time left on a terminal, a line per
    /// tenth of the pairs otherwise).
    #[arg(long)]
    quiet: bool,
}

fn parse_compare(text: &str) -> Result<(String, MatcherKind, PathBuf), String> {
    let (label, rest) = text
        .split_once('=')
        .ok_or("expected LABEL=MATCHER:CONFIG")?;
    let (kind, path) = rest
        .split_once(':')
        .ok_or("expected LABEL=MATCHER:CONFIG")?;
    Ok((label.to_string(), kind.parse()?, PathBuf::from(path)))
}

fn main() -> ExitCode {
    match run() {
        Ok(summary) => {
            println!("{summary}");
            ExitCode::SUCCESS
        }
        Err(error) => {
            eprintln!("linetrack-stereo-bench: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> anyhow::Result<String> {
    let args = Args::parse();
    let data = match &args.data {
        Some(dir) => dir.clone(),
        None => linetrack_test_data::middlebury_dir().map_err(anyhow::Error::msg)?,
    };
    let pairs = linetrack_datasets::select_middlebury(&data, &args.pairs)?;
    let config = match &args.config {
        Some(path) => FrontendConfig::from_file(path)?,
        None => FrontendConfig::default(),
    };
    let mut matchers = MatcherEntry::defaults(&config);
    for (label, kind, path) in &args.compare {
        matchers.push(MatcherEntry {
            label: label.clone(),
            kind: *kind,
            config: linetrack_stereo_bench::config_for(&config, *kind, path)?,
        });
    }
    let bench = Bench {
        detectors: if args.detectors.is_empty() {
            DetectorKind::ALL.to_vec()
        } else {
            args.detectors.clone()
        },
        matchers,
        conditions: if args.conditions.is_empty() {
            Condition::ALL.to_vec()
        } else {
            args.conditions.clone()
        },
        detection: config,
        scorer: Default::default(),
    };
    let progress = linetrack_progress::Progress::new("pairs", pairs.len() as u64, args.quiet);
    let rows = linetrack_stereo_bench::evaluate(&pairs, &bench, |done, _, name| {
        progress.step(name);
        progress.set(done as u64);
    })?;
    progress.finish();
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("cannot create {}", args.output.display()))?;
    let aggregates = aggregate(&rows);
    let goals = goals(&aggregates, "l1", "lbd");
    let table = markdown(&aggregates, &goals, pairs.len());
    let md = args.output.join("stereo-bench.md");
    std::fs::write(
        &md,
        format!("# Stereo matching on real images (Middlebury)\n\n{table}"),
    )
    .with_context(|| format!("cannot write {}", md.display()))?;
    linetrack_stereo_bench::write_csv(&args.output.join("stereo-bench.csv"), &rows)?;
    plot(&args.output.join("stereo-bench.png"), &aggregates)?;
    if args.matches {
        linetrack_stereo_bench::write_matches(&args.output.join("matches.jsonl"), &rows)?;
    }
    let met = goals.iter().filter(|g| g.met).count();
    Ok(format!(
        "{table}\nwrote {} ({} pairs; goals met: {met} of {})",
        md.display(),
        pairs.len(),
        goals.len()
    ))
}
