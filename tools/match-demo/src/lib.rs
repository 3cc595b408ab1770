//! The l1 matcher demo: generates a stereo scene with known ground truth, matches its
//! segments stereo (left ↔ right) and frame to frame (frame k ↔ k+1) with the ℓ1
//! geometric matcher, prints how many matches were right, and draws them side by side.
//!
//! It then runs the real front end (LSD or FLD, LBD against ℓ1) on a stereo pair and a
//! pair of consecutive frames of a dataset (EuRoC or KITTI), or of a small generated
//! sequence made on first use. This is the README's first command until the full
//! pipeline exists.
#![warn(missing_docs)]

mod draw;
mod images;

pub use images::DEFAULT_SEQUENCE;

use anyhow::Context;
use clap::{Parser, ValueEnum};
use linetrack_geometry::MatchCase;
use linetrack_l1_matcher::{L1Matcher, Match, MatchStats, MatcherConfig};
use linetrack_synthetic_segments::{
    SceneConfig, Score, SegmentPair, StereoRig, frame_pair, stereo_pair,
};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// Command-line arguments.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "linetrack-match-demo",
    version,
    about = "Match line segments by geometry alone: on a generated segment scene scored against ground truth, then LBD against l1 on stereo images.",
    after_help = concat!("EXAMPLES:
    linetrack-match-demo                          # default scene, both cases, PNGs in out/match-demo
    linetrack-match-demo --seed 7 --case stereo   # another scene, stereo only
    linetrack-match-demo --config configs/l1-matcher-paper.toml   # the method as published
    linetrack-match-demo --segments 300 --noise-px 1.5 --list     # harder scene, list every match
    linetrack-match-demo --dataset ../shared/data/euroc/V1_01_easy_micro --detector fld   # real EuRoC images

In the pictures, each correct match has one colour in both images; wrong matches are red,
unmatched segments grey.

", linetrack_vision::images_help!())
)]
pub struct Args {
    /// Seed of the generated scene.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Which image pairs to match.
    #[arg(long, value_enum, default_value_t = CaseArg::Both)]
    pub case: CaseArg,
    /// Segments kept per image (longest first, as detectors are capped).
    #[arg(long, default_value_t = 100)]
    pub segments: usize,
    /// Gaussian noise on each endpoint coordinate, pixels.
    #[arg(long, default_value_t = 0.5)]
    pub noise_px: f64,
    /// Matcher configuration (TOML, see configs/l1-matcher.toml); built-in defaults if absent.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Folder for the PNG pictures and matches.json.
    #[arg(long, default_value = "out/match-demo")]
    pub output: PathBuf,
    /// Print every match, not only the summary.
    #[arg(long)]
    pub list: bool,
    /// A dataset folder for the image part: EuRoC (holding mav0/) or a KITTI odometry
    /// sequence. Default: a small generated sequence in out/sequences/default, made on
    /// first use.
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// Frame of the dataset to match (stereo), and the next one (frame to frame).
    #[arg(long, default_value_t = 0)]
    pub frame: usize,
    /// Line detector for the image part.
    #[arg(long, default_value = "lsd")]
    pub detector: linetrack_vision::DetectorKind,
    /// Skip the image part (segments only; needs no OpenCV work).
    #[arg(long)]
    pub no_images: bool,
}

/// The image pairs to match.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CaseArg {
    /// Left ↔ right of one stereo frame.
    Stereo,
    /// Left image of frame k ↔ frame k+1.
    FrameToFrame,
    /// Both.
    Both,
}

/// One case's result, as written to matches.json.
#[derive(Debug, Serialize)]
struct CaseResult<'a> {
    case: MatchCase,
    pair: &'a SegmentPair,
    matches: &'a [Match],
    stats: MatchStats,
    score: Score,
    milliseconds: f64,
}

/// Runs the demo; returns the text to print.
pub fn run(args: &Args) -> anyhow::Result<String> {
    let config = match &args.config {
        Some(path) => MatcherConfig::from_file(path)?,
        None => MatcherConfig::default(),
    };
    let mut matcher = L1Matcher::new(config)?;
    let rig = StereoRig::default();
    let scene = SceneConfig {
        seed: args.seed,
        segments: args.segments.saturating_mul(2).max(20),
        max_segments: Some(args.segments),
        endpoint_noise_px: args.noise_px,
        ..SceneConfig::default()
    };
    let cases: &[MatchCase] = match args.case {
        CaseArg::Stereo => &[MatchCase::Stereo],
        CaseArg::FrameToFrame => &[MatchCase::FrameToFrame],
        CaseArg::Both => &[MatchCase::Stereo, MatchCase::FrameToFrame],
    };
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("cannot create output folder {}", args.output.display()))?;

    let mut text = String::new();
    let config_name = args
        .config
        .as_ref()
        .map_or("built-in defaults".to_string(), |p| p.display().to_string());
    writeln!(
        text,
        "linetrack ℓ1 match demo: generated scene seed {}, {} segments per image, {:.1} px noise, config {config_name}",
        args.seed, args.segments, args.noise_px
    )?;
    let mut results_json = Vec::new();
    let mut pictures = Vec::new();
    for &case in cases {
        let pair = match case {
            MatchCase::Stereo => stereo_pair(&rig, &scene),
            MatchCase::FrameToFrame => frame_pair(&rig, &scene),
        };
        let mut matches = Vec::new();
        let started = Instant::now();
        let stats = matcher.match_segments(
            case,
            &pair.first.segments,
            &pair.second.segments,
            &mut matches,
        );
        let milliseconds = started.elapsed().as_secs_f64() * 1e3;
        let score = pair.score(matches.iter().map(|m| (m.query, m.train)));
        let name = case_name(case);
        writeln!(
            text,
            "{name:>15}: {:3} matches, {:3} correct — precision {:.3}, recall {:.3} of {} matchable; {:.3} ms",
            score.accepted,
            score.correct,
            score.precision(),
            score.recall(),
            score.matchable,
            milliseconds
        )?;
        writeln!(
            text,
            "{:>15}  rejected: {} ambiguous, {} without support, {} conflicts, {} flow outliers, {} degenerate",
            "",
            stats.ambiguous,
            stats.unsupported,
            stats.conflicts,
            stats.outliers,
            stats.invalid_first + stats.invalid_second
        )?;
        if args.list {
            for m in &matches {
                let truth = if pair.first.labels[m.query].is_some()
                    && pair.first.labels[m.query] == pair.second.labels[m.train]
                {
                    "correct"
                } else {
                    "WRONG"
                };
                writeln!(
                    text,
                    "{:>15}  {:3} → {:3}  error {:.4}  weight {:.3}  {truth}",
                    "", m.query, m.train, m.error, m.weight
                )?;
            }
        }
        let png = args.output.join(format!("{name}.png"));
        draw::matches_side_by_side(&pair, &matches, &png)?;
        pictures.push(png);
        results_json.push(serde_json::to_value(CaseResult {
            case,
            pair: &pair,
            matches: &matches,
            stats,
            score,
            milliseconds,
        })?);
    }
    let json_path = args.output.join("matches.json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&results_json)?)
        .with_context(|| format!("cannot write {}", json_path.display()))?;
    let shown: Vec<String> = pictures
        .iter()
        .chain([&json_path])
        .map(|p| p.display().to_string())
        .collect();
    writeln!(text, "wrote {}", shown.join(", "))?;
    if !args.no_images {
        text.push_str(&images::run(
            args.dataset.as_deref(),
            args.frame,
            args.detector,
            &args.output,
        )?);
    }
    Ok(text)
}

fn case_name(case: MatchCase) -> &'static str {
    match case {
        MatchCase::Stereo => "stereo",
        MatchCase::FrameToFrame => "frame-to-frame",
    }
}
