//! Frame-to-frame line tracking against ground truth: the paper's Table I on real motion.
//!
//! For each pair of consecutive frames (k − 1, k), the left images are stretched and their
//! segments detected as the odometry does (its detector, `max_contrast_gain` and front-end
//! settings), described by both matchers and matched frame to frame with
//! `SegmentMatcher::match_lines`, the odometry's call. Each match is judged with
//! [`line_truth::judge`]: the previous segment's 3-D samples — from the exact depth map
//! where the sequence has one, otherwise triangulated from its stereo partner (found by
//! both matchers alike, triangulated with the odometry's limits) — moved by the true
//! motion between the two frames and projected into frame k. Segments without such
//! samples, and frames without a ground-truth pose, are not judged. Each pair is matched
//! twice ([`Positions`]): the segments of frame k − 1 where they were, and where a
//! constant-velocity prediction puts them — the previous true step (k − 2 → k − 1) applied
//! to their 3-D samples, as the odometry predicts with its last estimated step — through
//! `SegmentMatcher::match_predicted` (segments without samples stay where they were),
//! with the front end's matcher settings as configured: ℓ1 narrows its gate around
//! predicted segments to the pair's own prediction error, as the lines-only odometry does
//! (`predicted_narrowing`).

use crate::line_truth::{self, Verdict};
use crate::tracking::{Illumination, left_depth, load_frame};
use anyhow::Context;
use linetrack_datasets::StereoSequence;
use linetrack_geometry::MatchCase;
use linetrack_odometry::OdometryConfig;
use linetrack_stereo_vo::TriangulationLimits;
use linetrack_vision::{
    ContrastStretch, FeatureMatch, GrayImage, LineDetector, LineFeatures, MatcherKind,
    SegmentMatcher, create_detector, create_segment_matcher,
};
use nalgebra::{Isometry3, Point3};
use std::fmt::Write as _;
use std::path::Path;

/// The matchers compared, in the table's order.
pub const MATCHERS: [MatcherKind; 2] = [MatcherKind::Lbd, MatcherKind::L1];

/// Where the previous frame's segments are given to the matchers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Positions {
    /// Where they were seen.
    AsSeen,
    /// Where the previous true step, repeated, moves them (as seen on the first pair).
    Predicted,
}

impl Positions {
    /// Both, in the table's order.
    pub const ALL: [Positions; 2] = [Positions::AsSeen, Positions::Predicted];

    /// The name in the table and the CSV.
    pub fn name(self) -> &'static str {
        match self {
            Positions::AsSeen => "as seen",
            Positions::Predicted => "predicted",
        }
    }
}

/// Counts of one matcher over a sequence.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Tally {
    /// Frame-to-frame matches.
    pub matches: usize,
    /// Matches with a ground truth for their previous segment.
    pub judged: usize,
    /// Judged matches on the same physical segment.
    pub correct: usize,
    /// Judged matches on the same straight line but not overlapping the segment (wrong,
    /// yet a line residual would not tell).
    pub disjoint: usize,
}

impl Tally {
    /// Correct over judged; `None` when nothing was judged.
    pub fn precision(&self) -> Option<f64> {
        (self.judged > 0).then(|| self.correct as f64 / self.judged as f64)
    }
}

/// One sequence's result: frame pairs with a ground-truth motion, and a tally per matcher
/// of [`MATCHERS`].
#[derive(Debug, Clone, Copy, Default)]
pub struct Outcome {
    /// Consecutive frame pairs judged (both poses known).
    pub pairs: usize,
    /// Per [`Positions`], per matcher.
    pub tallies: [[Tally; 2]; 2],
}

/// A frame as the next one is judged against: its left segments described by both
/// matchers, each segment's 3-D samples (if known) and the frame's pose.
struct Reference {
    features: LineFeatures,
    samples: Vec<Option<Vec<Point3<f64>>>>,
    pose: Option<Isometry3<f64>>,
    /// The true step that led to this frame (`p_this = step · p_before`), if known.
    step: Option<Isometry3<f64>>,
}

impl Reference {
    /// The features with each segment that has 3-D samples moved by the frame's own step
    /// (constant velocity) and projected, and which were moved; `None` without a step.
    fn predicted(&self, rig: &linetrack_geometry::StereoRig) -> Option<(LineFeatures, Vec<bool>)> {
        let step = self.step?;
        let mut features = self.features.clone();
        let mut moved = vec![false; features.segments.len()];
        for ((segment, samples), moved) in features
            .segments
            .iter_mut()
            .zip(&self.samples)
            .zip(&mut moved)
        {
            let Some([first, last]) = samples
                .as_ref()
                .and_then(|s| Some([*s.first()?, *s.last()?]))
            else {
                continue;
            };
            if let [Some(a), Some(b)] = [first, last].map(|x| rig.project_left(&(step * x))) {
                *segment = linetrack_geometry::Segment::new(a, b);
                *moved = true;
            }
        }
        Some((features, moved))
    }
}

/// The benchmark's detector, matchers and buffers, built from an odometry configuration.
pub struct Benchmark {
    detector: Box<dyn LineDetector>,
    matchers: Vec<Box<dyn SegmentMatcher>>,
    stretch: ContrastStretch,
    max_gain: f64,
    limits: TriangulationLimits,
}

impl Benchmark {
    /// The odometry's detector and both matchers, with its settings.
    pub fn new(config: &OdometryConfig) -> anyhow::Result<Self> {
        Ok(Self {
            detector: create_detector(config.detector, &config.frontend)?,
            matchers: MATCHERS
                .iter()
                .map(|kind| create_segment_matcher(*kind, &config.frontend))
                .collect::<Result<_, _>>()?,
            stretch: ContrastStretch::new(),
            max_gain: config.max_contrast_gain,
            limits: TriangulationLimits {
                min_sin_from_horizontal: config.min_line_angle_deg.to_radians().sin(),
                ..TriangulationLimits::default()
            },
        })
    }

    /// Segments of `image` (stretched as the odometry does), described by both matchers.
    fn features(&mut self, image: &GrayImage) -> anyhow::Result<LineFeatures> {
        let seen = self.stretch.apply(image, self.max_gain)?;
        let mut features = LineFeatures::default();
        self.detector.detect(seen, &mut features.segments)?;
        for matcher in &mut self.matchers {
            matcher.describe(seen, &mut features)?;
        }
        Ok(features)
    }

    /// 3-D samples of each left segment from the stereo matches both matchers agree on.
    fn stereo_samples(
        &mut self,
        rig: &linetrack_geometry::StereoRig,
        left: &LineFeatures,
        right_image: &GrayImage,
    ) -> anyhow::Result<Vec<Option<Vec<Point3<f64>>>>> {
        let right = self.features(right_image)?;
        let mut partners: Vec<Option<usize>> = vec![None; left.segments.len()];
        let mut matches: Vec<FeatureMatch> = Vec::new();
        for (k, matcher) in self.matchers.iter_mut().enumerate() {
            matcher.match_lines(MatchCase::Stereo, left, &right, &mut matches);
            let mut agreed = vec![None; left.segments.len()];
            for m in &matches {
                let agrees = k == 0 || partners.get(m.query) == Some(&Some(m.train));
                if agrees && let Some(slot) = agreed.get_mut(m.query) {
                    *slot = Some(m.train);
                }
            }
            partners = agreed;
        }
        Ok(left
            .segments
            .iter()
            .zip(&partners)
            .map(|(l, partner)| {
                let r = right.segments.get((*partner)?)?;
                line_truth::samples_from_stereo(rig, l, r, &self.limits)
            })
            .collect())
    }

    /// Runs both matchers over the first `frames` frames of `sequence` (stored in
    /// `dataset`), images perturbed by `illumination` when given.
    pub fn run(
        &mut self,
        dataset: &Path,
        sequence: &StereoSequence,
        frames: usize,
        illumination: Illumination<'_>,
    ) -> anyhow::Result<Outcome> {
        let rig = sequence.rig;
        let mut outcome = Outcome::default();
        let mut previous: Option<Reference> = None;
        let mut matches = Vec::new();
        for k in 0..frames.min(sequence.frames.len()) {
            let frame = load_frame(sequence, k, illumination)
                .with_context(|| format!("{}: frame {k}", sequence.name))?;
            let features = self.features(&frame.left)?;
            let samples = match left_depth(dataset, frame.timestamp_ns) {
                Some(depth) => features
                    .segments
                    .iter()
                    .map(|s| line_truth::samples_from_depth(&rig, &depth, s))
                    .collect(),
                None => self.stereo_samples(&rig, &features, &frame.right)?,
            };
            let mut step = None;
            if let Some(before) = previous.take() {
                let motion = before.pose.zip(frame.pose).map(|(a, b)| b.inverse() * a);
                step = motion;
                outcome.pairs += usize::from(motion.is_some());
                let predicted = before.predicted(&rig);
                for (positions, tallies) in Positions::ALL.into_iter().zip(&mut outcome.tallies) {
                    for (matcher, tally) in self.matchers.iter_mut().zip(tallies) {
                        match (positions, &predicted) {
                            (Positions::Predicted, Some((moved_features, moved))) => matcher
                                .match_predicted(moved_features, moved, &features, &mut matches),
                            _ => matcher.match_lines(
                                MatchCase::FrameToFrame,
                                &before.features,
                                &features,
                                &mut matches,
                            ),
                        }
                        tally.matches += matches.len();
                        let Some(motion) = &motion else { continue };
                        for m in &matches {
                            let (Some(Some(samples)), Some(seen)) =
                                (before.samples.get(m.query), features.segments.get(m.train))
                            else {
                                continue;
                            };
                            let Some(verdict) = line_truth::judge(&rig, samples, motion, seen)
                            else {
                                continue;
                            };
                            tally.judged += 1;
                            tally.correct += usize::from(verdict == Verdict::Correct);
                            tally.disjoint += usize::from(verdict == Verdict::Disjoint);
                        }
                    }
                }
            }
            previous = Some(Reference {
                features,
                samples,
                pose: frame.pose,
                step,
            });
        }
        Ok(outcome)
    }
}

/// One row of `f2f-lines.csv`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    /// Sequence.
    pub sequence: String,
    /// Whether the paper's gain jumps were applied.
    pub gain_jumps: bool,
    /// Where the previous segments were given ([`Positions::name`]).
    pub positions: &'static str,
    /// Matcher.
    pub matcher: &'static str,
    /// Frame pairs with a ground-truth motion.
    pub frame_pairs: usize,
    /// Matches.
    pub matches: usize,
    /// Judged matches.
    pub judged: usize,
    /// Correct matches.
    pub correct: usize,
    /// Wrong matches on the right line, disjoint from the segment.
    pub disjoint: usize,
    /// Correct over judged.
    pub precision: Option<f64>,
}

impl Row {
    /// The rows of one sequence's outcome, one per matcher.
    pub fn of(sequence: &str, gain_jumps: bool, outcome: &Outcome) -> Vec<Self> {
        Positions::ALL
            .iter()
            .zip(&outcome.tallies)
            .flat_map(|(positions, tallies)| {
                MATCHERS.iter().zip(tallies).map(move |t| (positions, t))
            })
            .map(|(positions, (kind, tally))| Self {
                sequence: sequence.to_string(),
                gain_jumps,
                positions: positions.name(),
                matcher: kind.name(),
                frame_pairs: outcome.pairs,
                matches: tally.matches,
                judged: tally.judged,
                correct: tally.correct,
                disjoint: tally.disjoint,
                precision: tally.precision(),
            })
            .collect()
    }
}

/// The report's table: a line per sequence and illumination, both matchers side by side.
pub fn markdown(results: &[(String, bool, Outcome)]) -> String {
    let mut table = String::from(
        "| sequence | gain jumps | positions | pairs | LBD matches | judged | correct | disjoint | precision | ℓ1 matches | judged | correct | disjoint | precision |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for (sequence, jumps, outcome) in results {
        for (positions, tallies) in Positions::ALL.iter().zip(&outcome.tallies) {
            let cells: Vec<String> = tallies
                .iter()
                .map(|t| {
                    let precision = t.precision().map_or("–".to_string(), |p| format!("{p:.3}"));
                    format!(
                        "{} | {} | {} | {} | {precision}",
                        t.matches, t.judged, t.correct, t.disjoint
                    )
                })
                .collect();
            let _ = writeln!(
                table,
                "| {sequence} | {} | {} | {} | {} |",
                if *jumps { "yes" } else { "no" },
                positions.name(),
                outcome.pairs,
                cells.join(" | ")
            );
        }
    }
    table
}
