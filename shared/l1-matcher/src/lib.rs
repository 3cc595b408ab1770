//! The geometric ℓ1 line segment matcher of Gomez-Ojeda & Gonzalez-Jimenez (IROS 2018):
//! segments are matched by direction, epipolar consistency, overlap and length alone, so
//! matching keeps working when illumination changes defeat appearance descriptors.
//!
//! For each query segment `i` of the first image the matcher
//! 1. gates the second image's segments with cheap tests ([`Gates`]: angle, overlap,
//!    length ratio, disparity range or displacement, near-horizontal, polarity);
//! 2. builds the 4 × n matrix `A_i` of the survivors' weighted term vectors
//!    β_ij = [θ, θ^epip, ρ, μ] (see `linetrack-geometry`) and solves the lasso
//!    `min λ‖ω‖₁ + ½‖A_i ω − b‖²`, b = [0, 0, 1, 1], with the homotopy solver of
//!    `linetrack-lasso`;
//! 3. takes the candidate with the largest weight and accepts it only if its error
//!    `e_ij = ‖β_ij − b‖` is at most `1 / error_ratio` of the second best's.
//!
//! Each candidate is then kept by at most one query (the one with the lower error), and a
//! robust filter drops matches whose midpoint flow direction is more than 2σ from the
//! others' ([`OutlierFilter`]). Both the stereo (left ↔ right) and the frame-to-frame
//! (k ↔ k+1) cases are handled; they differ in the epipolar axis and overlap definition.
//!
//! Degenerate segments (zero length, NaN or infinite coordinates) are never matched and
//! are counted in [`MatchStats`]; empty inputs give no matches. The matcher keeps its
//! buffers between calls, so matching a stream of frames does not allocate once warm.
#![warn(missing_docs)]

mod config;
mod consistency;
mod gates;
mod outliers;
mod profiles;

pub use config::{
    ConfigError, Consistency, Gates, MatcherConfig, OutlierFilter, Photometric, PredictedSettings,
    SecondBest, StereoSettings, TermWeights,
};
pub use linetrack_geometry::{MatchCase, Segment};
pub use profiles::{GrayView, PROFILE_LEN, ROW_STEP, SegmentProfiles, Similarity, ViewError};

use gates::{CandidateTable, GateLimits};
use linetrack_geometry::{self as geometry, IDEAL_TERMS, SegmentFeatures};
use linetrack_lasso::Homotopy;
use serde::{Deserialize, Serialize};

/// One accepted correspondence.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Match {
    /// Index of the segment in the first set.
    pub query: usize,
    /// Index of the segment in the second set.
    pub train: usize,
    /// Weighted geometric error ‖W(β − b)‖ of the pair.
    pub error: f64,
    /// The pair's lasso weight divided by the ℓ1 norm of the query's weights, in (0, 1].
    pub weight: f64,
}

/// What happened to the segments of one matching call.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct MatchStats {
    /// First-set segments refused as degenerate (zero length or non-finite).
    pub invalid_first: usize,
    /// Second-set segments refused as degenerate.
    pub invalid_second: usize,
    /// Queries not matched because they are near-horizontal (stereo gate).
    pub near_horizontal: usize,
    /// (query, candidate) pairs that passed the gates and entered a lasso.
    pub candidate_pairs: usize,
    /// Valid queries with no candidate, or whose lasso gave every candidate zero weight.
    pub unsupported: usize,
    /// Queries whose best candidate failed the ratio test against the second best.
    pub ambiguous: usize,
    /// Queries whose lasso could not be solved (counted, never fatal).
    pub solver_failures: usize,
    /// Matches dropped because another query claimed the same candidate with lower error.
    pub conflicts: usize,
    /// Matches dropped by the flow-direction outlier filter.
    pub outliers: usize,
    /// Stereo matches dropped because no neighbour has about their disparity.
    pub inconsistent: usize,
    /// Stereo matches dropped because the image content sits off the candidate's line.
    pub misaligned: usize,
    /// Candidates discarded by the photometric check (correlation below the minimum).
    pub photometric_rejections: usize,
    /// Matches returned.
    pub matches: usize,
}

/// A gated candidate of the current query.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    index: usize,
    error: f64,
}

/// The ℓ1 geometric matcher; see the crate documentation.
#[derive(Debug, Clone)]
pub struct L1Matcher {
    config: MatcherConfig,
    limits: Limits,
    gate_limits: GateLimits,
    /// The gates of queries placed where the predicted motion puts them.
    predicted_limits: GateLimits,
    table: CandidateTable,
    admitted: Vec<usize>,
    solver: Homotopy<ROWS>,
    first: Vec<Option<SegmentFeatures>>,
    second: Vec<Option<SegmentFeatures>>,
    candidates: Vec<Candidate>,
    columns: Vec<[f64; ROWS]>,
    weights: Vec<f64>,
    owner: Vec<Option<usize>>,
    tentative: Vec<Match>,
    /// The tentative matches of predicted queries while the others are filtered.
    set_aside: Vec<Match>,
    /// Scratch: predicted partners' distances from their queries' lines.
    offsets: Vec<f64>,
    filter: outliers::FlowFilter,
    consistency: consistency::DisparityCheck,
}

/// Rows of A: the four geometric terms and the photometric dissimilarity.
const ROWS: usize = 5;

/// The ideal column: [`IDEAL_TERMS`] and no dissimilarity.
const IDEAL: [f64; ROWS] = [
    IDEAL_TERMS[0],
    IDEAL_TERMS[1],
    IDEAL_TERMS[2],
    IDEAL_TERMS[3],
    0.0,
];

/// The dissimilarity of a candidate that cannot be compared (flat or clipped rows): that
/// of an uncorrelated one.
const UNKNOWN_DISSIMILARITY: f64 = 0.5;

/// Row weights and the weighted ideal b, fixed at construction.
#[derive(Debug, Clone, Copy)]
struct Limits {
    weights: [f64; ROWS],
    weighted_ideal: [f64; ROWS],
}

impl Limits {
    fn new(config: &MatcherConfig) -> Self {
        let [angle, epipolar, overlap, length] = config.term_weights.to_array();
        let photometric = if config.photometric.enabled {
            config.photometric.weight
        } else {
            0.0
        };
        let weights = [angle, epipolar, overlap, length, photometric];
        Self {
            weights,
            weighted_ideal: std::array::from_fn(|r| weights[r] * IDEAL[r]),
        }
    }
}

impl L1Matcher {
    /// A matcher for `config`, refused if a field is out of range.
    pub fn new(config: MatcherConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(Self {
            limits: Limits::new(&config),
            gate_limits: GateLimits::new(&config.gates),
            predicted_limits: GateLimits::new(&Gates {
                max_displacement_px: config.predicted.max_displacement_px,
                ..config.gates
            }),
            table: CandidateTable::default(),
            admitted: Vec::new(),
            filter: outliers::FlowFilter::new(config.outlier_filter),
            consistency: consistency::DisparityCheck::new(config.consistency),
            config,
            solver: Homotopy::new(),
            first: Vec::new(),
            second: Vec::new(),
            candidates: Vec::new(),
            columns: Vec::new(),
            weights: Vec::new(),
            owner: Vec::new(),
            tentative: Vec::new(),
            set_aside: Vec::new(),
            offsets: Vec::new(),
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &MatcherConfig {
        &self.config
    }

    /// The image step of matching: replaces `out` with the row profiles of `segments` in
    /// `image` that the photometric check compares, or empties it when the check is off or
    /// there is no image to read. The OpenCV front end and the Python bindings both call
    /// this, so they compare the same profiles.
    pub fn describe(
        &self,
        image: Option<GrayView<'_>>,
        segments: &[Segment],
        out: &mut SegmentProfiles,
    ) {
        let photometric = self.config.photometric;
        match image {
            Some(view) if photometric.enabled => {
                out.extract(view, segments, photometric.min_angle_from_horizontal_deg)
            }
            _ => out.clear(),
        }
    }

    /// Matches `first` against `second` by geometry alone, replacing the contents of
    /// `out` with the accepted matches in increasing query order.
    pub fn match_segments(
        &mut self,
        case: MatchCase,
        first: &[Segment],
        second: &[Segment],
        out: &mut Vec<Match>,
    ) -> MatchStats {
        self.match_with_profiles(case, first, second, None, out)
    }

    /// As [`L1Matcher::match_segments`], with the photometric check of stereo candidates
    /// when `profiles` holds the row profiles of `first` and `second` (extracted from the
    /// two images, [`SegmentProfiles::extract`]) and the config enables it. Profiles that
    /// do not have one entry per segment are ignored.
    pub fn match_with_profiles(
        &mut self,
        case: MatchCase,
        first: &[Segment],
        second: &[Segment],
        profiles: Option<(&SegmentProfiles, &SegmentProfiles)>,
        out: &mut Vec<Match>,
    ) -> MatchStats {
        self.run(case, first, second, profiles, &[], out)
    }

    /// Frame to frame, with the first frame's segments where the camera's predicted motion
    /// puts them in the second frame: `predicted[i]` says whether `first[i]` was moved so
    /// (missing entries: no). A predicted query is gated by
    /// [`PredictedSettings::max_displacement_px`] around its predicted place and its match
    /// is left out of the flow-direction filter (unless
    /// [`PredictedSettings::flow_filter`]); the others are matched as by
    /// [`L1Matcher::match_segments`]. Both kinds compete for the same candidates.
    pub fn match_predicted(
        &mut self,
        first: &[Segment],
        predicted: &[bool],
        second: &[Segment],
        out: &mut Vec<Match>,
    ) -> MatchStats {
        let stats = self.run(MatchCase::FrameToFrame, first, second, None, predicted, out);
        let Some(width) = self.narrowed_gate(predicted, out) else {
            return stats;
        };
        let wide = self.predicted_limits;
        self.predicted_limits = GateLimits::new(&Gates {
            max_displacement_px: width,
            ..self.config.gates
        });
        let stats = self.run(MatchCase::FrameToFrame, first, second, None, predicted, out);
        self.predicted_limits = wide;
        stats
    }

    /// The gate for predicted queries narrowed to this frame's prediction error
    /// ([`PredictedSettings::narrow_factor`]), from the matches `out` of the last run;
    /// `None` when narrowing is off, too few predicted queries were matched, or it would
    /// not narrow.
    fn narrowed_gate(&mut self, predicted: &[bool], out: &[Match]) -> Option<f64> {
        let settings = self.config.predicted;
        if !(settings.narrow_factor > 0.0) {
            return None;
        }
        let (first, second) = (&self.first, &self.second);
        let offsets = &mut self.offsets;
        offsets.clear();
        offsets.extend(
            out.iter()
                .filter(|m| predicted.get(m.query).copied().unwrap_or(false))
                .filter_map(|m| {
                    let (query, partner) = (
                        first.get(m.query)?.as_ref()?,
                        second.get(m.train)?.as_ref()?,
                    );
                    let from = partner.mid - query.mid;
                    Some((query.dir.x * from.y - query.dir.y * from.x).abs())
                }),
        );
        if offsets.len() < settings.narrow_min_matches.max(1) {
            return None;
        }
        let middle = offsets.len() / 2;
        let (_, median, _) = offsets.select_nth_unstable_by(middle, f64::total_cmp);
        let width = (settings.narrow_factor * *median).max(settings.narrow_min_px);
        (width < settings.max_displacement_px).then_some(width)
    }

    fn run(
        &mut self,
        case: MatchCase,
        first: &[Segment],
        second: &[Segment],
        profiles: Option<(&SegmentProfiles, &SegmentProfiles)>,
        predicted: &[bool],
        out: &mut Vec<Match>,
    ) -> MatchStats {
        out.clear();
        let is_predicted = |i: usize| predicted.get(i).copied().unwrap_or(false);
        let profiles = profiles.filter(|(a, b)| {
            self.config.photometric.enabled
                && case == MatchCase::Stereo
                && a.len() == first.len()
                && b.len() == second.len()
        });
        let photometric = self.config.photometric;
        let (min_overlap, error_ratio) = match case {
            MatchCase::Stereo => (
                self.config.gates.stereo_min_overlap,
                self.config.stereo.error_ratio,
            ),
            MatchCase::FrameToFrame => (self.config.gates.min_overlap, self.config.error_ratio),
        };
        let mut stats = MatchStats {
            invalid_first: prepare(first, &mut self.first),
            invalid_second: prepare(second, &mut self.second),
            ..MatchStats::default()
        };
        self.table.fill(case, &self.gate_limits, &self.second);
        self.owner.clear();
        self.owner.resize(second.len(), None);
        self.tentative.clear();

        for i in 0..self.first.len() {
            let Some(query) = self.first[i] else { continue };
            let query = &query;
            if !self.gate_limits.usable(case, query) {
                stats.near_horizontal += 1;
                continue;
            }
            self.candidates.clear();
            self.columns.clear();
            self.admitted.clear();
            let gate_limits = if is_predicted(i) {
                &self.predicted_limits
            } else {
                &self.gate_limits
            };
            self.table
                .admit(case, gate_limits, query, &mut self.admitted);
            let query_rows = profiles.is_some_and(|(a, _)| a.has_profile(i));
            let query_columns = profiles.is_some_and(|(a, _)| a.has_column_profile(i));
            for &j in &self.admitted {
                let Some(candidate) = &self.second[j] else {
                    continue;
                };
                let overlap = geometry::overlap(query, candidate, case);
                if self.config.gates.enabled && overlap < min_overlap {
                    continue;
                }
                // The epipolar angle costs an atan2; skip it where its row weighs nothing.
                let epipolar = if self.limits.weights[1] == 0.0 {
                    0.0
                } else {
                    geometry::epipolar_angle(query, candidate, case)
                };
                let correlation = match profiles {
                    Some((a, b)) if query_rows => a
                        .similarity(i, b, j, photometric.min_rows)
                        .map(|s| s.correlation),
                    Some((a, b)) if query_columns => a.column_similarity(i, b, j),
                    _ => None,
                };
                let dissimilarity = match correlation {
                    Some(c) if c < photometric.min_correlation => {
                        stats.photometric_rejections += 1;
                        continue;
                    }
                    Some(c) => 0.5 * (1.0 - c),
                    None if query_rows || query_columns => UNKNOWN_DISSIMILARITY,
                    None => 0.0,
                };
                let beta = [
                    geometry::direction_angle(query, candidate),
                    epipolar,
                    overlap,
                    geometry::length_ratio(query, candidate),
                    dissimilarity,
                ];
                let column: [f64; ROWS] = std::array::from_fn(|r| self.limits.weights[r] * beta[r]);
                let error = column
                    .iter()
                    .zip(&self.limits.weighted_ideal)
                    .map(|(c, b)| (c - b) * (c - b))
                    .sum::<f64>()
                    .sqrt();
                self.candidates.push(Candidate { index: j, error });
                self.columns.push(column);
            }
            stats.candidate_pairs += self.candidates.len();
            let collinear_px = if is_predicted(i) {
                self.config.predicted.collinear_px
            } else {
                0.0
            };
            match self.choose(error_ratio, collinear_px) {
                Ok(Some(m)) if self.misaligned(profiles, query_rows, i, m.train) => {
                    stats.misaligned += 1;
                }
                Ok(Some(m)) => {
                    let m = Match { query: i, ..m };
                    // A predicted query's claim outranks a plain one's (its partner was
                    // found where the motion puts it); within a kind, the lower error wins.
                    let rank = |m: &Match| (!is_predicted(m.query), m.error);
                    match self.owner[m.train] {
                        Some(k) if rank(&self.tentative[k]) <= rank(&m) => stats.conflicts += 1,
                        Some(k) => {
                            stats.conflicts += 1;
                            self.tentative[k] = m;
                        }
                        None => {
                            self.owner[m.train] = Some(self.tentative.len());
                            self.tentative.push(m);
                        }
                    }
                }
                Ok(None) if self.candidates.is_empty() => stats.unsupported += 1,
                Ok(None) => stats.ambiguous += 1,
                Err(Unsupported) => stats.unsupported += 1,
                Err(SolverFailed) => stats.solver_failures += 1,
            }
        }

        self.tentative.sort_unstable_by_key(|m| m.query);
        if case == MatchCase::Stereo {
            stats.inconsistent =
                self.consistency
                    .retain(&mut self.tentative, &self.first, &self.second);
        }
        if case == MatchCase::FrameToFrame || self.config.stereo.flow_filter {
            // Predicted queries' matches sit out the filter unless it is asked for.
            self.set_aside.clear();
            if !self.config.predicted.flow_filter {
                self.set_aside
                    .extend(self.tentative.iter().filter(|m| is_predicted(m.query)));
                self.tentative.retain(|m| !is_predicted(m.query));
            }
            stats.outliers =
                self.filter
                    .retain(case, &mut self.tentative, &self.first, &self.second);
            if !self.set_aside.is_empty() {
                self.tentative.append(&mut self.set_aside);
                self.tentative.sort_unstable_by_key(|m| m.query);
            }
        }
        out.extend_from_slice(&self.tentative);
        stats.matches = out.len();
        stats
    }

    /// Whether the image content of stereo candidate `j` sits farther from its line,
    /// relative to query `i`'s, than the photometric check allows.
    fn misaligned(
        &self,
        profiles: Option<(&SegmentProfiles, &SegmentProfiles)>,
        query_rows: bool,
        i: usize,
        j: usize,
    ) -> bool {
        let limit = self.config.photometric.max_offset_px;
        match profiles {
            Some((a, b)) if query_rows && limit.is_finite() => a
                .offset_px(i, b, j)
                .is_some_and(|offset| !(offset.abs() <= limit)),
            _ => false,
        }
    }

    /// Solves the current query's lasso and applies the ratio test, in which a candidate
    /// on the best one's line (within `collinear_px`; 0: none is) is no rival.
    /// `Ok(None)`: no candidate or ambiguous.
    fn choose(&mut self, error_ratio: f64, collinear_px: f64) -> Result<Option<Match>, Choice> {
        if self.candidates.is_empty() {
            return Ok(None);
        }
        self.weights.clear();
        self.weights.resize(self.columns.len(), 0.0);
        let ideal = self.limits.weighted_ideal;
        if self
            .solver
            .solve(&self.columns, &ideal, self.config.lambda, &mut self.weights)
            .is_err()
        {
            return Err(SolverFailed);
        }
        let (mut best, mut runner_up) = (None::<usize>, None::<usize>);
        for (k, &w) in self.weights.iter().enumerate() {
            if w <= 0.0 {
                continue;
            }
            if best.is_none_or(|b| w > self.weights[b]) {
                runner_up = best;
                best = Some(k);
            } else if runner_up.is_none_or(|r| w > self.weights[r]) {
                runner_up = Some(k);
            }
        }
        let best = best.ok_or(Unsupported)?;
        let best_error = self.candidates[best].error;
        let rival = |k: usize| k != best && !self.on_line_of(best, k, collinear_px);
        let second_error = match self.config.second_best {
            SecondBest::LowestOtherError => self
                .candidates
                .iter()
                .enumerate()
                .filter(|(k, _)| rival(*k))
                .map(|(_, c)| c.error)
                .fold(f64::INFINITY, f64::min),
            SecondBest::SecondLassoWeight => runner_up
                .filter(|r| rival(*r))
                .map_or(f64::INFINITY, |r| self.candidates[r].error),
        };
        // Two candidates with zero error are ambiguous, not a pass.
        let distinct = second_error.is_infinite()
            || (second_error > 0.0 && best_error * error_ratio <= second_error);
        if !distinct {
            return Ok(None);
        }
        let l1: f64 = self.weights.iter().map(|w| w.abs()).sum();
        Ok(Some(Match {
            query: 0,
            train: self.candidates[best].index,
            error: best_error,
            weight: self.weights[best] / l1,
        }))
    }

    /// Whether candidate `k` lies on candidate `best`'s line: within `collinear_px` of it
    /// at both ends and within [`COLLINEAR_MAX_ANGLE_DEG`] of its direction (0 px: never).
    fn on_line_of(&self, best: usize, k: usize, collinear_px: f64) -> bool {
        if !(collinear_px > 0.0) {
            return false;
        }
        let feature = |c: usize| self.second.get(self.candidates[c].index).copied().flatten();
        let (Some(a), Some(b)) = (feature(best), feature(k)) else {
            return false;
        };
        let off = |p: linetrack_geometry::Point| {
            let r = p - a.start;
            (r.x * a.dir.y - r.y * a.dir.x).abs()
        };
        let cos = (a.dir.x * b.dir.x + a.dir.y * b.dir.y).abs();
        cos >= COLLINEAR_MAX_ANGLE_DEG.to_radians().cos()
            && off(b.start) <= collinear_px
            && off(b.end) <= collinear_px
    }
}

/// The largest angle between two candidates on one line, degrees.
const COLLINEAR_MAX_ANGLE_DEG: f64 = 2.0;

/// Why a query got no match from its lasso.
#[derive(Debug, Clone, Copy)]
enum Choice {
    Unsupported,
    SolverFailed,
}
use Choice::{SolverFailed, Unsupported};

/// Fills `features` with each segment's features (`None` if degenerate); returns how many
/// were degenerate.
fn prepare(segments: &[Segment], features: &mut Vec<Option<SegmentFeatures>>) -> usize {
    features.clear();
    features.extend(segments.iter().map(|s| SegmentFeatures::new(s).ok()));
    features.iter().filter(|f| f.is_none()).count()
}

#[cfg(test)]
mod tests;
