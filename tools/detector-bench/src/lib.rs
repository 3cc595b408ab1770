//! Scores line detectors against ground truth on generated sequences
//! (`linetrack-synth`): the scene's 3-D segments (`mav0/scene/segments3d.csv`) are
//! projected into each left image with the frame's true pose, clipped to the image and
//! cut where the frame's depth map shows a nearer surface ([`truth`]); each detector's
//! segments are then matched to them ([`score`]).
//!
//! Per detector and sequence: **repeatability** (share of the true segments at least
//! the detector's minimum length that are found), **frame-to-frame repeatability** (of
//! the true segments found in frame k and asked for in frame k + 1, the share found in
//! k + 1 too), **localisation** (median and p90 perpendicular distance of matched
//! detections' endpoints to the true line), detections per frame and the share of
//! detections that fit no true segment.
#![warn(missing_docs)]

pub mod score;
pub mod truth;

use anyhow::Context;
use clap::Parser;
use linetrack_datasets::StereoSequence;
use linetrack_datasets::depth::read_depth_png;
use linetrack_vision::{DetectorKind, FrontendConfig, create_detector};
use nalgebra::Point3;
use score::{FrameScore, Rule, score_frame};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use truth::{DepthVisibility, project_segments};

/// Command-line arguments.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "linetrack-detector-bench",
    version,
    about = "Score line detectors (repeatability, localisation) against the ground-truth 3-D segments of generated sequences, projected with the true poses and depth maps.",
    after_help = "EXAMPLES:
    linetrack-synth --preset normal --seed 0 --frames 60 --output out/sequences/normal
    linetrack-detector-bench out/sequences/normal
    linetrack-detector-bench out/sequences/normal --detector edgelines --max-segments 1000

RULE: a detection fits a true segment when its direction is within --angle-deg of it, both
endpoints lie within --distance-px of its line and at least half of the detection projects
inside it. A true segment (visible piece at least the detector's minimum length) is found when
the detections fitting it cover at least half its length together. Localisation: the
endpoints' distances to the line of the true segment each matched detection fits best.
Unmatched: detections fitting no visible true segment of any length.

OUTPUT: one Markdown table row per sequence × detector on stdout."
)]
pub struct Args {
    /// Generated sequence folders (`linetrack-synth --output`).
    #[arg(required = true)]
    pub sequences: Vec<PathBuf>,
    /// Detectors (repeatable; default: lsd, fld and edgelines).
    #[arg(long = "detector")]
    pub detectors: Vec<DetectorKind>,
    /// Front-end configuration (TOML, see configs/frontend.toml): detector options and
    /// the kept segments (`lines`: at most 100, at least 15 px by default).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Keep at most this many segments per image instead of the configuration's.
    #[arg(long)]
    pub max_segments: Option<usize>,
    /// Largest angle between a detection and a true segment, degrees.
    #[arg(long, default_value_t = 3.0)]
    pub angle_deg: f64,
    /// Largest distance of a detection's endpoints to the true line, pixels.
    #[arg(long, default_value_t = 2.0)]
    pub distance_px: f64,
}

/// One detector over one sequence.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Summary {
    /// Frames scored.
    pub frames: usize,
    /// True segments asked for, summed over frames.
    pub asked: usize,
    /// Of those, found.
    pub found: usize,
    /// True segments found in a frame and asked for in the next.
    pub carried: usize,
    /// Of those, found in the next frame too.
    pub carried_found: usize,
    /// Detections, summed over frames.
    pub detections: usize,
    /// Detections fitting no true segment.
    pub unmatched: usize,
    /// Endpoint distances of matched detections, pixels.
    pub distances: Vec<f64>,
}

impl Summary {
    /// Adds a frame; `previous` is the score of the frame before, if any.
    pub fn add(&mut self, frame: &FrameScore, previous: Option<&FrameScore>) {
        self.frames += 1;
        self.asked += frame.asked.len();
        self.found += frame.found.len();
        self.detections += frame.detections;
        self.unmatched += frame.unmatched;
        self.distances.extend(&frame.endpoint_distances);
        if let Some(previous) = previous {
            for id in previous.found.iter().filter(|id| frame.asked.contains(id)) {
                self.carried += 1;
                self.carried_found += usize::from(frame.found.contains(id));
            }
        }
    }

    /// Found / asked.
    pub fn repeatability(&self) -> f64 {
        ratio(self.found, self.asked)
    }

    /// Found again in the next frame / found and asked for in the next frame.
    pub fn frame_to_frame(&self) -> f64 {
        ratio(self.carried_found, self.carried)
    }

    /// Unmatched / detections.
    pub fn unmatched_share(&self) -> f64 {
        ratio(self.unmatched, self.detections)
    }

    /// Quantile `q` of the endpoint distances (nearest rank), pixels.
    pub fn distance_quantile(&self, q: f64) -> f64 {
        let mut d = self.distances.clone();
        if d.is_empty() {
            return f64::NAN;
        }
        d.sort_by(f64::total_cmp);
        d[((q * d.len() as f64).ceil() as usize).clamp(1, d.len()) - 1]
    }
}

fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 {
        f64::NAN
    } else {
        a as f64 / b as f64
    }
}

/// Reads `segments3d.csv` (`x0,y0,z0,x1,y1,z1` per line, `#` comments).
pub fn read_segments3d(path: &Path) -> anyhow::Result<Vec<[Point3<f64>; 2]>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let v: Vec<f64> = line
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(|| format!("{}:{}: not numbers", path.display(), n + 1))?;
        let [x0, y0, z0, x1, y1, z1] = v[..] else {
            anyhow::bail!("{}:{}: expected 6 values", path.display(), n + 1);
        };
        out.push([Point3::new(x0, y0, z0), Point3::new(x1, y1, z1)]);
    }
    Ok(out)
}

/// Scores every detector of `args` over every sequence; returns the Markdown report.
pub fn run(args: &Args) -> anyhow::Result<String> {
    let mut config = match &args.config {
        Some(path) => FrontendConfig::from_file(path)?,
        None => FrontendConfig::default(),
    };
    if let Some(n) = args.max_segments {
        config.lines.max_segments = n;
    }
    let detectors = if args.detectors.is_empty() {
        DetectorKind::ALL.to_vec()
    } else {
        args.detectors.clone()
    };
    let rule = Rule {
        angle_deg: args.angle_deg,
        distance_px: args.distance_px,
        min_length_px: config.lines.min_length_px,
        ..Rule::default()
    };
    let mut report = format!(
        "Rule: angle ≤ {}°, endpoints ≤ {} px from the true line, true segments ≥ {} px found when \
         covered ≥ {:.0} %; at most {} detections per image.\n\n\
         | sequence | detector | frames | true segments / frame | repeatability | frame-to-frame | \
         median / p90 endpoint distance (px) | detections / frame | unmatched |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|\n",
        rule.angle_deg,
        rule.distance_px,
        rule.min_length_px,
        100.0 * rule.coverage,
        config.lines.max_segments
    );
    for dir in &args.sequences {
        let summaries = score_sequence(dir, &detectors, &config, &rule)?;
        let name = dir.file_name().map_or_else(
            || dir.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        for (kind, s) in detectors.iter().zip(&summaries) {
            let per_frame = |x: usize| x as f64 / s.frames.max(1) as f64;
            writeln!(
                report,
                "| {name} | {} | {} | {:.1} | {:.3} | {:.3} | {:.2} / {:.2} | {:.1} | {:.3} |",
                kind.name(),
                s.frames,
                per_frame(s.asked),
                s.repeatability(),
                s.frame_to_frame(),
                s.distance_quantile(0.5),
                s.distance_quantile(0.9),
                per_frame(s.detections),
                s.unmatched_share()
            )?;
        }
    }
    Ok(report)
}

/// Scores `detectors` over the left images of the generated sequence in `dir`.
pub fn score_sequence(
    dir: &Path,
    detectors: &[DetectorKind],
    config: &FrontendConfig,
    rule: &Rule,
) -> anyhow::Result<Vec<Summary>> {
    let sequence = StereoSequence::open_euroc(dir)?;
    let segments = read_segments3d(&dir.join("mav0/scene/segments3d.csv"))?;
    let mut detectors = detectors
        .iter()
        .map(|k| create_detector(*k, config))
        .collect::<Result<Vec<_>, _>>()?;
    let mut summaries = vec![Summary::default(); detectors.len()];
    let mut previous: Vec<Option<FrameScore>> = vec![None; detectors.len()];
    let mut found = Vec::new();
    for entry in &sequence.frames {
        let frame = sequence
            .load_frame(entry.index)
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let pose = frame
            .pose
            .with_context(|| format!("frame {} has no ground-truth pose", entry.index))?;
        let depth_path = dir.join(format!("mav0/depth0/data/{}.png", entry.timestamp_ns));
        let depth = read_depth_png(&depth_path)?;
        let visibility = DepthVisibility {
            width: depth.width,
            height: depth.height,
            metres: &depth.metres,
        };
        let truth = project_segments(&segments, &pose, &sequence.rig, &visibility);
        for (k, detector) in detectors.iter_mut().enumerate() {
            detector.detect(&frame.left, &mut found)?;
            let score = score_frame(&truth, &found, rule);
            summaries[k].add(&score, previous[k].as_ref());
            previous[k] = Some(score);
        }
    }
    Ok(summaries)
}

#[cfg(test)]
mod tests;
