//! Stereo segment matching scored on real images: the Middlebury pairs with ground-truth
//! disparity, every detector × matcher, each pair as photographed and under simulated
//! illumination changes of the right image ([`Condition`]).
//!
//! Per pair and in aggregate it counts matches, correct matches (the rule of [`score`]:
//! the left segment carried by the true disparity lies within 1 px of the right segment's
//! line and overlaps it), precision over the judged matches, and recall of the matchable
//! left segments (those some detected right segment would correctly match). The same
//! numbers feed `linetrack-eval`'s report; `linetrack-stereo-bench` runs them alone.
#![warn(missing_docs)]

mod conditions;
mod report;
pub mod score;

pub use conditions::Condition;
pub use report::{Aggregate, Goal, aggregate, goals, markdown, plot, write_csv};

use linetrack_datasets::{LoadedPair, MiddleburyPair};
use linetrack_geometry::{MatchCase, Segment};
use linetrack_vision::{
    DetectorKind, FeatureMatch, FrontendConfig, GrayImage, LineDetector, LineFeatures, MatcherKind,
    SegmentMatcher, VisionError, create_detector, create_segment_matcher,
};
use score::{Scorer, Verdict};
use serde::Serialize;
use std::time::Instant;

/// A matcher to evaluate: a kind with its configuration, under a label.
#[derive(Debug, Clone)]
pub struct MatcherEntry {
    /// Name in tables (`lbd`, `l1`, `l1-paper`, …).
    pub label: String,
    /// The matcher.
    pub kind: MatcherKind,
    /// Its configuration (`[lbd]`, `[appearance_gates]`, `[l1]`).
    pub config: FrontendConfig,
}

impl MatcherEntry {
    /// The LBD and ℓ1 matchers of `config`, labelled `lbd` and `l1`.
    pub fn defaults(config: &FrontendConfig) -> Vec<MatcherEntry> {
        MatcherKind::ALL
            .into_iter()
            .map(|kind| MatcherEntry {
                label: kind.name().to_string(),
                kind,
                config: config.clone(),
            })
            .collect()
    }
}

/// What to run.
#[derive(Debug, Clone)]
pub struct Bench {
    /// Detectors, each run with `detection` options.
    pub detectors: Vec<DetectorKind>,
    /// Matchers.
    pub matchers: Vec<MatcherEntry>,
    /// Conditions of the right image.
    pub conditions: Vec<Condition>,
    /// Detection options (`[lines]`, `[lsd]`, `[fld]`).
    pub detection: FrontendConfig,
    /// The scoring rule.
    pub scorer: Scorer,
}

/// One match and its verdict (for error analysis).
#[derive(Debug, Clone, Copy)]
pub struct JudgedMatch {
    /// Left segment.
    pub left: Segment,
    /// Right segment.
    pub right: Segment,
    /// Whether it is correct.
    pub verdict: Verdict,
}

impl JudgedMatch {
    /// The verdict as a word.
    pub fn verdict_name(&self) -> &'static str {
        match self.verdict {
            Verdict::Correct => "correct",
            Verdict::Wrong => "wrong",
            Verdict::Unjudged => "unjudged",
        }
    }
}

/// The counts of one pair × condition × detector × matcher.
#[derive(Debug, Clone, Serialize)]
pub struct PairRow {
    /// Scene name.
    pub pair: String,
    /// Condition name.
    pub condition: Condition,
    /// Detector name.
    pub detector: &'static str,
    /// Matcher label.
    pub matcher: String,
    /// Segments detected in the left image.
    pub left_segments: usize,
    /// Segments detected in the right image.
    pub right_segments: usize,
    /// Left segments that some right segment would correctly match.
    pub matchable: usize,
    /// Matches returned.
    pub matches: usize,
    /// Correct matches.
    pub correct: usize,
    /// Judged and wrong.
    pub wrong: usize,
    /// Not judged (no ground truth under the left segment).
    pub unjudged: usize,
    /// Milliseconds of description (both images) and matching.
    pub match_ms: f64,
    /// Every match with its verdict.
    #[serde(skip)]
    pub judged: Vec<JudgedMatch>,
}

/// Errors of the benchmark.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A pair could not be loaded.
    #[error(transparent)]
    Dataset(#[from] linetrack_datasets::DatasetError),
    /// Detection, description or a condition failed.
    #[error(transparent)]
    Vision(#[from] VisionError),
}

struct Detected {
    kind: DetectorKind,
    detector: Box<dyn LineDetector>,
}

/// Runs the benchmark over `pairs`, calling `progress(done, total, pair)` after each pair.
pub fn evaluate(
    pairs: &[MiddleburyPair],
    bench: &Bench,
    mut progress: impl FnMut(usize, usize, &str),
) -> Result<Vec<PairRow>, BenchError> {
    let mut detectors: Vec<Detected> = bench
        .detectors
        .iter()
        .map(|&kind| {
            Ok(Detected {
                kind,
                detector: create_detector(kind, &bench.detection)?,
            })
        })
        .collect::<Result<_, VisionError>>()?;
    let mut matchers: Vec<(String, Box<dyn SegmentMatcher>)> = bench
        .matchers
        .iter()
        .map(|m| Ok((m.label.clone(), create_segment_matcher(m.kind, &m.config)?)))
        .collect::<Result<_, VisionError>>()?;
    let mut rows = Vec::new();
    for (index, pair) in pairs.iter().enumerate() {
        let loaded = pair.load()?;
        let left_by_detector: Vec<Vec<Segment>> = detectors
            .iter_mut()
            .map(|d| detect(d.detector.as_mut(), &loaded.left))
            .collect::<Result<_, _>>()?;
        for &condition in &bench.conditions {
            let right = condition.apply(&loaded.right, index)?;
            for (detected, left_segments) in detectors.iter_mut().zip(&left_by_detector) {
                let right_segments = detect(detected.detector.as_mut(), &right)?;
                let matchable = bench
                    .scorer
                    .matchable(left_segments, &right_segments, &loaded.disparity)
                    .into_iter()
                    .filter(|&m| m)
                    .count();
                for (label, matcher) in &mut matchers {
                    let mut row = PairRow {
                        pair: pair.name.clone(),
                        condition,
                        detector: detected.kind.name(),
                        matcher: label.clone(),
                        left_segments: left_segments.len(),
                        right_segments: right_segments.len(),
                        matchable,
                        matches: 0,
                        correct: 0,
                        wrong: 0,
                        unjudged: 0,
                        match_ms: 0.0,
                        judged: Vec::new(),
                    };
                    let started = Instant::now();
                    let matches = run_matcher(
                        matcher.as_mut(),
                        (&loaded.left, &right),
                        (left_segments, &right_segments),
                    )?;
                    row.match_ms = started.elapsed().as_secs_f64() * 1e3;
                    tally(
                        &mut row,
                        &matches,
                        left_segments,
                        &right_segments,
                        &loaded,
                        bench,
                    );
                    rows.push(row);
                }
            }
        }
        progress(index + 1, pairs.len(), &pair.name);
    }
    Ok(rows)
}

fn detect(detector: &mut dyn LineDetector, image: &GrayImage) -> Result<Vec<Segment>, VisionError> {
    let mut segments = Vec::new();
    detector.detect(image, &mut segments)?;
    Ok(segments)
}

fn run_matcher(
    matcher: &mut dyn SegmentMatcher,
    (left_image, right_image): (&GrayImage, &GrayImage),
    (left, right): (&[Segment], &[Segment]),
) -> Result<Vec<FeatureMatch>, VisionError> {
    let mut first = LineFeatures {
        segments: left.to_vec(),
        ..LineFeatures::default()
    };
    let mut second = LineFeatures {
        segments: right.to_vec(),
        ..LineFeatures::default()
    };
    matcher.describe(left_image, &mut first)?;
    matcher.describe(right_image, &mut second)?;
    let mut matches = Vec::new();
    matcher.match_lines(MatchCase::Stereo, &first, &second, &mut matches);
    Ok(matches)
}

fn tally(
    row: &mut PairRow,
    matches: &[FeatureMatch],
    left: &[Segment],
    right: &[Segment],
    loaded: &LoadedPair,
    bench: &Bench,
) {
    row.matches = matches.len();
    for m in matches {
        let (l, r) = (left[m.query], right[m.train]);
        let verdict = bench.scorer.judge(&l, &r, &loaded.disparity);
        match verdict {
            Verdict::Correct => row.correct += 1,
            Verdict::Wrong => row.wrong += 1,
            Verdict::Unjudged => row.unjudged += 1,
        }
        row.judged.push(JudgedMatch {
            left: l,
            right: r,
            verdict,
        });
    }
}

/// `base` with the matcher options of `path`: a front-end TOML file, or for the ℓ1
/// matcher an l1-matcher TOML file (which replaces `[l1]`).
pub fn config_for(
    base: &FrontendConfig,
    kind: MatcherKind,
    path: &std::path::Path,
) -> anyhow::Result<FrontendConfig> {
    match FrontendConfig::from_file(path) {
        Ok(config) => Ok(config),
        Err(frontend_error) if kind == MatcherKind::L1 => {
            let l1 = linetrack_l1_matcher::MatcherConfig::from_file(path).map_err(|l1_error| {
                anyhow::anyhow!(
                    "{}: neither a front-end config ({frontend_error}) nor an l1-matcher config ({l1_error})",
                    path.display()
                )
            })?;
            Ok(FrontendConfig { l1, ..base.clone() })
        }
        Err(error) => Err(error.into()),
    }
}

/// Every match of `rows` with its verdict, one JSON object per line.
pub fn write_matches(path: &std::path::Path, rows: &[PairRow]) -> anyhow::Result<()> {
    use std::io::Write as _;
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    for row in rows {
        for m in &row.judged {
            let line = serde_json::json!({
                "pair": row.pair,
                "condition": row.condition,
                "detector": row.detector,
                "matcher": row.matcher,
                "left": m.left,
                "right": m.right,
                "verdict": m.verdict_name(),
            });
            writeln!(out, "{line}")?;
        }
    }
    out.flush()?;
    Ok(())
}
