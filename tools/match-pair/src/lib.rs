//! Detects and matches line segments between two images (a stereo pair or two consecutive
//! frames) with a chosen detector × matcher, optionally after a photometric perturbation of
//! the second image, and writes what it found: a side-by-side picture, the segments and
//! matches as JSON and CSV, and a one-line summary with counts and per-step milliseconds.
#![warn(missing_docs)]

use anyhow::Context;
use clap::{Parser, ValueEnum};
use linetrack_draw::{Side, SideBySide, palette, segment_matches};
use linetrack_geometry::{MatchCase, Point, Segment};
use linetrack_vision::{
    DetectorKind, FeatureMatch, FrontendConfig, GrayImage, LineFeatures, LinePairMatcher,
    MatcherKind, OrbExtractor, PairTimings, PointFeatures, PointMatcher, perturb,
};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Command-line arguments.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "linetrack-match-pair",
    version,
    about = "Detect and match line segments between two images; draw the matches and report timings.",
    after_help = concat!("EXAMPLES:
    # A EuRoC stereo pair with LSD + LBD (the defaults):
    linetrack-match-pair cam0/data/1403715273262142976.png cam1/data/1403715273262142976.png

    # Two consecutive frames, FLD + the geometric l1 matcher, ORB points too:
    linetrack-match-pair f0.png f1.png --mode frame-to-frame --detector fld --matcher l1 --points

    # The illumination-change case: the second image brightened (gain 2.2, bias 15):
    linetrack-match-pair left.png right.png --matcher l1 --gain 2.2 --bias 15

OUTPUT: <output>/matches.png (first image left, second right; a match has one colour in
both, unmatched segments are grey), <output>/matches.json (everything), <output>/matches.csv
(one row per match), and one summary line on stdout.

", linetrack_vision::images_help!())
)]
pub struct Args {
    /// First image (left, or frame k).
    pub first: PathBuf,
    /// Second image (right, or frame k+1).
    pub second: PathBuf,
    /// Whether the images are a stereo pair or consecutive frames.
    #[arg(long, value_enum, default_value_t = Mode::Stereo)]
    pub mode: Mode,
    /// Line detector (default: the config's, lsd).
    #[arg(long)]
    pub detector: Option<DetectorKind>,
    /// Segment matcher (default: the config's, lbd).
    #[arg(long)]
    pub matcher: Option<MatcherKind>,
    /// Also detect and match ORB points.
    #[arg(long)]
    pub points: bool,
    /// Multiply the second image by this gain before detection (clamped to 0..255).
    #[arg(long)]
    pub gain: Option<f64>,
    /// Add this bias to the second image before detection (after the gain).
    #[arg(long)]
    pub bias: Option<f64>,
    /// Front-end configuration (TOML, see configs/frontend.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Folder for matches.png, matches.json and matches.csv.
    #[arg(long, default_value = "out/match-pair")]
    pub output: PathBuf,
}

/// The kind of image pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Mode {
    /// Left and right image of one stereo frame.
    Stereo,
    /// Two consecutive frames of one camera.
    FrameToFrame,
}

impl Mode {
    fn case(self) -> MatchCase {
        match self {
            Mode::Stereo => MatchCase::Stereo,
            Mode::FrameToFrame => MatchCase::FrameToFrame,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Mode::Stereo => "stereo",
            Mode::FrameToFrame => "frame-to-frame",
        }
    }
}

/// Milliseconds per step.
#[derive(Debug, Default, Serialize)]
struct Timings {
    load: f64,
    perturb: f64,
    lines: PairTimings,
    points: Option<f64>,
}

#[derive(Debug, Serialize)]
struct PointsReport<'a> {
    first: &'a [Point],
    second: &'a [Point],
    matches: &'a [FeatureMatch],
}

#[derive(Debug, Serialize)]
struct Report<'a> {
    first_image: String,
    second_image: String,
    mode: &'static str,
    detector: &'static str,
    matcher: &'static str,
    gain: f64,
    bias: f64,
    first_segments: &'a [Segment],
    second_segments: &'a [Segment],
    matches: &'a [FeatureMatch],
    points: Option<PointsReport<'a>>,
    milliseconds: &'a Timings,
}

fn ms_since(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}

/// Runs detection and matching; writes the files; returns the summary line.
pub fn run(args: &Args) -> anyhow::Result<String> {
    let config = match &args.config {
        Some(path) => FrontendConfig::from_file(path)?,
        None => FrontendConfig::default(),
    };
    let detector_kind = args.detector.unwrap_or(config.detector);
    let matcher_kind = args.matcher.unwrap_or(config.matcher);
    let (gain, bias) = (args.gain.unwrap_or(1.0), args.bias.unwrap_or(0.0));
    let mut timings = Timings::default();

    let started = Instant::now();
    let first = GrayImage::load(&args.first)?;
    let second = GrayImage::load(&args.second)?;
    first.ensure_same_size(&second)?;
    timings.load = ms_since(started);
    let second = if args.gain.is_some() || args.bias.is_some() {
        let started = Instant::now();
        let perturbed = perturb(&second, gain, bias)?;
        timings.perturb = ms_since(started);
        perturbed
    } else {
        second
    };

    let mut pair = LinePairMatcher::new(detector_kind, matcher_kind, &config)?;
    let result = pair.run(args.mode.case(), &first, &second)?;
    let (lines_a, lines_b, matches) = (&result.first, &result.second, &result.matches);
    timings.lines = result.timings;

    let mut point_sets = None;
    let mut point_matches = Vec::new();
    if args.points {
        let started = Instant::now();
        let mut orb = OrbExtractor::new(&config.orb)?;
        let (mut a, mut b) = (PointFeatures::default(), PointFeatures::default());
        orb.extract(&first, &mut a)?;
        orb.extract(&second, &mut b)?;
        let gates = &config.appearance_gates;
        PointMatcher::new().match_points(
            args.mode.case(),
            &a,
            &b,
            gates,
            config.orb.min_distance_ratio,
            &mut point_matches,
        );
        timings.points = Some(ms_since(started));
        point_sets = Some((a, b));
    }

    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("cannot create output folder {}", args.output.display()))?;
    let picture_path = args.output.join("matches.png");
    draw(
        &first,
        &second,
        lines_a,
        lines_b,
        matches,
        point_sets.as_ref(),
        &point_matches,
    )
    .save(&picture_path)
    .with_context(|| format!("cannot write {}", picture_path.display()))?;
    let report = Report {
        first_image: args.first.display().to_string(),
        second_image: args.second.display().to_string(),
        mode: args.mode.name(),
        detector: detector_kind.name(),
        matcher: matcher_kind.name(),
        gain,
        bias,
        first_segments: &lines_a.segments,
        second_segments: &lines_b.segments,
        matches,
        points: point_sets.as_ref().map(|(a, b)| PointsReport {
            first: &a.points,
            second: &b.points,
            matches: &point_matches,
        }),
        milliseconds: &timings,
    };
    write_file(
        &args.output.join("matches.json"),
        &serde_json::to_string_pretty(&report)?,
    )?;
    write_file(
        &args.output.join("matches.csv"),
        &matches_csv(&lines_a.segments, &lines_b.segments, matches),
    )?;

    let mut line = format!(
        "{}+{} {}: {}|{} segments, {} matches | load {:.1} ms, detect {:.1}+{:.1} ms, describe {:.1}+{:.1} ms, match {:.2} ms",
        detector_kind.name(),
        matcher_kind.name(),
        args.mode.name(),
        lines_a.segments.len(),
        lines_b.segments.len(),
        matches.len(),
        timings.load,
        timings.lines.detect_ms[0],
        timings.lines.detect_ms[1],
        timings.lines.describe_ms[0],
        timings.lines.describe_ms[1],
        timings.lines.match_ms
    );
    if let (Some((a, b)), Some(ms)) = (&point_sets, timings.points) {
        write!(
            line,
            " | orb {}|{} points, {} matches, {ms:.1} ms",
            a.points.len(),
            b.points.len(),
            point_matches.len()
        )?;
    }
    if args.gain.is_some() || args.bias.is_some() {
        write!(line, " | second image × {gain} + {bias}")?;
    }
    Ok(line)
}

fn write_file(path: &Path, text: &str) -> anyhow::Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// One row per match: indices, distance, and both segments' endpoints.
fn matches_csv(first: &[Segment], second: &[Segment], matches: &[FeatureMatch]) -> String {
    let mut csv = String::from(
        "query,train,distance,x0_first,y0_first,x1_first,y1_first,x0_second,y0_second,x1_second,y1_second\n",
    );
    for m in matches {
        let (a, b) = (first[m.query], second[m.train]);
        let _ = writeln!(
            csv,
            "{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3}",
            m.query,
            m.train,
            m.distance,
            a.start.x,
            a.start.y,
            a.end.x,
            a.end.y,
            b.start.x,
            b.start.y,
            b.end.x,
            b.end.y
        );
    }
    csv
}

fn draw(
    first: &GrayImage,
    second: &GrayImage,
    lines_a: &LineFeatures,
    lines_b: &LineFeatures,
    matches: &[FeatureMatch],
    points: Option<&(PointFeatures, PointFeatures)>,
    point_matches: &[FeatureMatch],
) -> SideBySide {
    let size = (first.width().max(0) as u32, first.height().max(0) as u32);
    let mut picture = segment_matches(
        size,
        [first.pixels(), second.pixels()],
        [&lines_a.segments, &lines_b.segments],
        matches.iter().map(|m| (m.query, m.train)),
    );
    if let Some((a, b)) = points {
        for (k, m) in point_matches.iter().enumerate() {
            picture.point(
                Side::First,
                a.points[m.query],
                palette(k + matches.len()),
                3,
            );
            picture.point(
                Side::Second,
                b.points[m.train],
                palette(k + matches.len()),
                3,
            );
        }
    }
    picture
}
