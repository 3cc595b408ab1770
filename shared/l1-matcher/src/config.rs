//! Every threshold of the matcher, with the paper's defaults where the paper gives one.
//! `configs/l1-matcher.toml` documents the same fields for users.

use serde::{Deserialize, Serialize};
use std::path::Path;

/// Configuration of [`crate::L1Matcher`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MatcherConfig {
    /// λ of the lasso `min λ‖ω‖₁ + ½‖Aω − b‖²` (paper: 0.1).
    pub lambda: f64,
    /// Accept the best candidate only if the second best's error is at least this many
    /// times larger (paper: 2).
    pub error_ratio: f64,
    /// Which candidate is "second best" in the ratio test.
    pub second_best: SecondBest,
    /// What differs for stereo pairs.
    pub stereo: StereoSettings,
    /// Row weights applied to both β and b, to make the four terms commensurate
    /// (default: epipolar row off, see [`TermWeights::default`]).
    pub term_weights: TermWeights,
    /// Cheap tests that discard candidates before the lasso.
    pub gates: Gates,
    /// Robust filter on the direction of the midpoint flow of accepted matches.
    pub outlier_filter: OutlierFilter,
    /// The illumination-invariant check of intensities across stereo segments (not in
    /// the paper).
    pub photometric: Photometric,
    /// Disparity consistency of stereo matches with their neighbours (not in the paper).
    pub consistency: Consistency,
    /// Frame to frame, for queries placed where the camera's predicted motion puts them
    /// ([`crate::L1Matcher::match_predicted`]; not in the paper).
    pub predicted: PredictedSettings,
}

impl Default for MatcherConfig {
    fn default() -> Self {
        Self {
            lambda: 0.1,
            error_ratio: 2.0,
            second_best: SecondBest::LowestOtherError,
            stereo: StereoSettings::default(),
            term_weights: TermWeights::default(),
            gates: Gates::default(),
            outlier_filter: OutlierFilter::default(),
            photometric: Photometric::default(),
            consistency: Consistency::default(),
            predicted: PredictedSettings::default(),
        }
    }
}

/// What differs frame to frame for a query segment that was moved to where the camera's
/// predicted motion puts it. Only the motion's error is left between such a query and its
/// true partner: a small displacement, of no common direction (the flow-direction filter
/// assumes a coherent flow, which a forward motion's radial flow is not, and a prediction's
/// residual is not either).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PredictedSettings {
    /// The displacement gate ([`Gates::max_displacement_px`]) for predicted queries,
    /// pixels.
    pub max_displacement_px: f64,
    /// Whether the flow-direction outlier filter also runs on predicted queries' matches.
    pub flow_filter: bool,
    /// The gate narrowed to the frame's own prediction error (0: off). After matching
    /// with [`PredictedSettings::max_displacement_px`], the median distance of the
    /// predicted queries' partners from their queries' lines measures how far off this
    /// frame's prediction is; the predicted queries are then matched again with their gate
    /// at this many times that median, within [`PredictedSettings::narrow_min_px`] and
    /// `max_displacement_px`. A good prediction leaves a parallel edge a few pixels away
    /// (the other side of a kerb, a window frame) outside the gate; a poor one keeps the
    /// wide gate.
    pub narrow_factor: f64,
    /// The narrowed gate's smallest width, pixels.
    pub narrow_min_px: f64,
    /// Fewest predicted matches whose median may narrow the gate.
    pub narrow_min_matches: usize,
    /// In a predicted query's ratio test, a candidate lying on the best one's line (both
    /// ends within this many pixels of it, nearly parallel) is another piece of the same
    /// edge, which the detector split differently in this frame, not a rival (0: off,
    /// every other candidate is a rival).
    pub collinear_px: f64,
}

impl Default for PredictedSettings {
    fn default() -> Self {
        Self {
            max_displacement_px: 15.0,
            flow_filter: false,
            narrow_factor: 3.0,
            narrow_min_px: 4.0,
            narrow_min_matches: 6,
            collinear_px: 0.0,
        }
    }
}

/// Settings that differ for stereo pairs (rectified, left ↔ right) from frame to frame,
/// chosen on the real Middlebury pairs (`linetrack-stereo-bench`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StereoSettings {
    /// The ratio test's factor for stereo pairs (replaces `error_ratio`): the error there
    /// includes the photometric row, which separates candidates on its own.
    pub error_ratio: f64,
    /// Whether the flow-direction outlier filter also runs on stereo matches. On real
    /// images detectors cut segments at different places in the two views, which tilts
    /// the midpoint flow: the filter dropped correct matches by the hundred.
    pub flow_filter: bool,
}

impl Default for StereoSettings {
    fn default() -> Self {
        Self {
            error_ratio: 1.3,
            flow_filter: false,
        }
    }
}

/// The reference error in the best-versus-second-best test.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SecondBest {
    /// The lowest error among all other gated candidates (stricter and more precise).
    LowestOtherError,
    /// The error of the candidate with the second-largest lasso weight.
    SecondLassoWeight,
}

/// Weights of the four rows [θ, θ^epip, ρ, μ] of A and b.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TermWeights {
    /// Weight of the direction angle θ (radians).
    pub angle: f64,
    /// Weight of the epipolar angle θ^epip (radians).
    pub epipolar: f64,
    /// Weight of the overlap ρ.
    pub overlap: f64,
    /// Weight of the length ratio μ.
    pub length_ratio: f64,
}

impl TermWeights {
    /// The weights as the diagonal of the row scaling.
    pub fn to_array(&self) -> [f64; 4] {
        [self.angle, self.epipolar, self.overlap, self.length_ratio]
    }
}

impl Default for TermWeights {
    /// The epipolar row off, the others as in the paper. The midpoint-flow angle is
    /// distorted by endpoint truncation, and frame to frame it assumes null motion; on
    /// generated scenes dropping it from the lasso raised precision and recall in both
    /// cases (see the crate tests). The epipolar constraint still acts through the stereo
    /// row overlap, the gates and the outlier filter.
    fn default() -> Self {
        Self {
            angle: 1.0,
            epipolar: 0.0,
            overlap: 1.0,
            length_ratio: 1.0,
        }
    }
}

impl TermWeights {
    /// All ones: the problem exactly as the paper writes it.
    pub fn paper() -> Self {
        Self {
            angle: 1.0,
            epipolar: 1.0,
            overlap: 1.0,
            length_ratio: 1.0,
        }
    }
}

/// Candidate gates. Each only removes candidates; [`Gates::wide_open`] removes none.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Gates {
    /// Master switch: `false` skips every gate below.
    pub enabled: bool,
    /// Largest direction angle θ between query and candidate, degrees (90 = off).
    pub max_angle_deg: f64,
    /// Frame to frame: smallest overlap ρ (0 = off).
    pub min_overlap: f64,
    /// Stereo: smallest overlap ρ of the row extents (0 = off; rows must still meet when
    /// it is above 0).
    pub stereo_min_overlap: f64,
    /// Largest length ratio μ (`inf` = off).
    pub max_length_ratio: f64,
    /// Stereo: smallest disparity (left x minus right x), pixels; a little below 0 allows
    /// for endpoint noise.
    pub min_disparity_px: f64,
    /// Stereo: largest disparity, pixels.
    pub max_disparity_px: f64,
    /// Stereo: segments closer than this to horizontal are not matched, degrees
    /// (0 = off). They carry almost no disparity information in a rectified pair.
    pub min_angle_from_horizontal_deg: f64,
    /// Frame to frame: largest distance of the candidate's midpoint from the query's
    /// line, and of the two midpoints beyond half the longer length, pixels.
    pub max_displacement_px: f64,
    /// Require the same gradient polarity (endpoint order) in both images. Not in the
    /// paper; needs a detector that orients segments by gradient, as LSD does.
    pub same_polarity: bool,
}

impl Default for Gates {
    fn default() -> Self {
        Self {
            enabled: true,
            max_angle_deg: 10.0,
            min_overlap: 0.1,
            stereo_min_overlap: 0.4,
            max_length_ratio: 4.0,
            min_disparity_px: -2.0,
            max_disparity_px: 150.0,
            min_angle_from_horizontal_deg: 0.0,
            max_displacement_px: 40.0,
            same_polarity: true,
        }
    }
}

impl Gates {
    /// Every gate at the value that discards nothing.
    pub fn wide_open() -> Self {
        Self {
            enabled: true,
            max_angle_deg: 90.0,
            min_overlap: 0.0,
            stereo_min_overlap: 0.0,
            max_length_ratio: f64::INFINITY,
            min_disparity_px: f64::NEG_INFINITY,
            max_disparity_px: f64::INFINITY,
            min_angle_from_horizontal_deg: 0.0,
            max_displacement_px: f64::INFINITY,
            same_polarity: false,
        }
    }
}

/// Drops accepted matches whose midpoint flow points away from the bulk of the others
/// (paper §III-C): stereo flows should be horizontal, small-motion flows consistent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutlierFilter {
    /// Switch.
    pub enabled: bool,
    /// Drop matches further than this many robust standard deviations from the median
    /// flow angle (paper: 2).
    pub sigmas: f64,
    /// Floor on the robust standard deviation, degrees, so that near-perfect data does
    /// not turn noise into outliers.
    pub min_sigma_deg: f64,
    /// Flows shorter than this have no reliable direction: kept, and not used in the
    /// estimate, pixels.
    pub min_flow_px: f64,
    /// Fewer usable flows than this: the distribution is not estimated, nothing dropped.
    pub min_matches: usize,
}

impl Default for OutlierFilter {
    fn default() -> Self {
        Self {
            enabled: true,
            sigmas: 2.0,
            min_sigma_deg: 0.5,
            min_flow_px: 1.0,
            min_matches: 5,
        }
    }
}

/// The photometric check of stereo candidates (see `profiles`): intensities across the two
/// segments, row by row, compared by zero-normalised cross-correlation, which no gain or
/// bias between the images can change. Used only when the matcher is given the images.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Photometric {
    /// Switch.
    pub enabled: bool,
    /// Weight of the fifth row of A, the dissimilarity (1 − correlation) / 2 in [0, 1]
    /// (ideal 0). A candidate that cannot be compared (flat or clipped rows) counts 1/2.
    pub weight: f64,
    /// Candidates whose correlation is below this are discarded (−1 = never).
    pub min_correlation: f64,
    /// Rows both segments must have a usable profile on for a correlation.
    pub min_rows: usize,
    /// A match is dropped when the image content along the candidate sits farther than
    /// this from where its line says, relative to the query (the peak of the row
    /// correlation over one-pixel shifts), pixels (`inf` = off).
    pub max_offset_px: f64,
    /// Segments closer than this to horizontal get no profile, degrees: their point on a
    /// row is ill-defined.
    pub min_angle_from_horizontal_deg: f64,
}

impl Default for Photometric {
    fn default() -> Self {
        Self {
            enabled: true,
            weight: 16.0,
            min_correlation: 0.7,
            min_rows: 3,
            max_offset_px: 1.0,
            min_angle_from_horizontal_deg: 20.0,
        }
    }
}

/// Disparity consistency of stereo matches: a match of segments that are not
/// near-horizontal is dropped when at least `min_neighbours` of its `neighbours` nearest
/// such matches (by left midpoint, within `max_distance_px`) exist and none has a
/// disparity within the tolerance of its own.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Consistency {
    /// Switch.
    pub enabled: bool,
    /// Neighbours looked at: the nearest ones within `max_distance_px`.
    pub neighbours: usize,
    /// Farther matches are not neighbours, pixels (between left midpoints).
    pub max_distance_px: f64,
    /// Fewer neighbours with a disparity than this: the match is kept.
    pub min_neighbours: usize,
    /// Disparities within this many pixels agree...
    pub max_difference_px: f64,
    /// ...or within this fraction of the match's disparity, whichever is larger.
    pub max_relative_difference: f64,
    /// Segments closer than this to horizontal have no disparity here, degrees.
    pub min_angle_from_horizontal_deg: f64,
}

impl Default for Consistency {
    fn default() -> Self {
        Self {
            enabled: true,
            neighbours: 5,
            max_distance_px: 80.0,
            min_neighbours: 2,
            max_difference_px: 3.0,
            max_relative_difference: 0.05,
            min_angle_from_horizontal_deg: 20.0,
        }
    }
}

/// A configuration that cannot be used, with the field that is wrong.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// A field holds a value outside its range.
    #[error("matcher config field `{field}` = {value}: {expected}")]
    OutOfRange {
        /// Dotted path of the field.
        field: &'static str,
        /// The value found.
        value: f64,
        /// What the field accepts.
        expected: &'static str,
    },
    /// The TOML text does not parse or has unknown/mistyped fields.
    #[error("matcher config {origin}: {reason}")]
    Toml {
        /// The file (or "<string>").
        origin: String,
        /// The parser's message, with line and column.
        reason: toml::de::Error,
    },
    /// The file cannot be read.
    #[error("matcher config {path}: {reason}")]
    Io {
        /// The file.
        path: String,
        /// Why it cannot be read.
        reason: std::io::Error,
    },
}

impl MatcherConfig {
    /// The method exactly as published: unit term weights, no gates, no polarity, the
    /// 2σ outlier filter, λ = 0.1, ratio 2.
    pub fn paper() -> Self {
        Self {
            stereo: StereoSettings {
                error_ratio: 2.0,
                flow_filter: true,
            },
            term_weights: TermWeights::paper(),
            gates: Gates::wide_open(),
            photometric: Photometric {
                enabled: false,
                ..Photometric::default()
            },
            consistency: Consistency {
                enabled: false,
                ..Consistency::default()
            },
            ..Self::default()
        }
    }

    /// Parses and validates TOML text (missing fields take their defaults).
    pub fn from_toml_str(text: &str) -> Result<Self, ConfigError> {
        Self::parse(text, "<string>")
    }

    /// Reads, parses and validates a TOML file.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let shown = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|reason| ConfigError::Io {
            path: shown.clone(),
            reason,
        })?;
        Self::parse(&text, &shown)
    }

    fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let config: Self = toml::from_str(text).map_err(|reason| ConfigError::Toml {
            origin: origin.to_string(),
            reason,
        })?;
        config.validate()?;
        Ok(config)
    }

    /// Checks every field's range; the error names the first bad field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let g = &self.gates;
        let w = &self.term_weights;
        let f = &self.outlier_filter;
        let p = &self.photometric;
        let c = &self.consistency;
        let checks: [(&'static str, f64, bool, &'static str); 32] = [
            (
                "lambda",
                self.lambda,
                finite_nonneg(self.lambda),
                "a finite number >= 0",
            ),
            (
                "error_ratio",
                self.error_ratio,
                self.error_ratio.is_finite() && self.error_ratio >= 1.0,
                "a finite number >= 1",
            ),
            (
                "stereo.error_ratio",
                self.stereo.error_ratio,
                self.stereo.error_ratio.is_finite() && self.stereo.error_ratio >= 1.0,
                "a finite number >= 1",
            ),
            (
                "gates.stereo_min_overlap",
                g.stereo_min_overlap,
                (0.0..=1.0).contains(&g.stereo_min_overlap),
                "a fraction in [0, 1]",
            ),
            (
                "term_weights.angle",
                w.angle,
                finite_nonneg(w.angle),
                "a finite number >= 0",
            ),
            (
                "term_weights.epipolar",
                w.epipolar,
                finite_nonneg(w.epipolar),
                "a finite number >= 0",
            ),
            (
                "term_weights.overlap",
                w.overlap,
                finite_nonneg(w.overlap),
                "a finite number >= 0",
            ),
            (
                "term_weights.length_ratio",
                w.length_ratio,
                finite_nonneg(w.length_ratio),
                "a finite number >= 0",
            ),
            (
                "gates.max_angle_deg",
                g.max_angle_deg,
                (0.0..=90.0).contains(&g.max_angle_deg),
                "degrees in [0, 90]",
            ),
            (
                "gates.min_overlap",
                g.min_overlap,
                (0.0..=1.0).contains(&g.min_overlap),
                "a fraction in [0, 1]",
            ),
            (
                "gates.max_length_ratio",
                g.max_length_ratio,
                g.max_length_ratio >= 1.0,
                "a number >= 1 (inf for no gate)",
            ),
            (
                "gates.min_disparity_px",
                g.min_disparity_px,
                !g.min_disparity_px.is_nan() && g.min_disparity_px <= g.max_disparity_px,
                "a number <= gates.max_disparity_px",
            ),
            (
                "gates.max_disparity_px",
                g.max_disparity_px,
                !g.max_disparity_px.is_nan(),
                "a number (inf for no gate)",
            ),
            (
                "gates.min_angle_from_horizontal_deg",
                g.min_angle_from_horizontal_deg,
                (0.0..=90.0).contains(&g.min_angle_from_horizontal_deg),
                "degrees in [0, 90]",
            ),
            (
                "gates.max_displacement_px",
                g.max_displacement_px,
                g.max_displacement_px >= 0.0,
                "a number >= 0 (inf for no gate)",
            ),
            (
                "predicted.max_displacement_px",
                self.predicted.max_displacement_px,
                self.predicted.max_displacement_px >= 0.0,
                "a number >= 0 (inf for no gate)",
            ),
            (
                "predicted.narrow_factor",
                self.predicted.narrow_factor,
                finite_nonneg(self.predicted.narrow_factor),
                "a finite number >= 0 (0: off)",
            ),
            (
                "predicted.narrow_min_px",
                self.predicted.narrow_min_px,
                finite_nonneg(self.predicted.narrow_min_px),
                "a finite number >= 0",
            ),
            (
                "predicted.collinear_px",
                self.predicted.collinear_px,
                finite_nonneg(self.predicted.collinear_px),
                "a finite number >= 0 (0: off)",
            ),
            (
                "outlier_filter.sigmas",
                f.sigmas,
                f.sigmas.is_finite() && f.sigmas > 0.0,
                "a finite number > 0",
            ),
            (
                "outlier_filter.min_sigma_deg",
                f.min_sigma_deg,
                finite_nonneg(f.min_sigma_deg),
                "a finite number >= 0",
            ),
            (
                "outlier_filter.min_flow_px",
                f.min_flow_px,
                finite_nonneg(f.min_flow_px),
                "a finite number >= 0",
            ),
            (
                "photometric.weight",
                p.weight,
                finite_nonneg(p.weight),
                "a finite number >= 0",
            ),
            (
                "photometric.min_correlation",
                p.min_correlation,
                (-1.0..=1.0).contains(&p.min_correlation),
                "a correlation in [-1, 1]",
            ),
            (
                "photometric.max_offset_px",
                p.max_offset_px,
                p.max_offset_px > 0.0,
                "a number > 0 (inf = off)",
            ),
            (
                "photometric.min_rows",
                p.min_rows as f64,
                p.min_rows >= 1,
                "a count >= 1",
            ),
            (
                "consistency.max_difference_px",
                c.max_difference_px,
                finite_nonneg(c.max_difference_px),
                "a finite number >= 0",
            ),
            (
                "consistency.max_distance_px",
                c.max_distance_px,
                c.max_distance_px >= 0.0,
                "a number >= 0 (inf for no limit)",
            ),
            (
                "consistency.max_relative_difference",
                c.max_relative_difference,
                finite_nonneg(c.max_relative_difference),
                "a finite number >= 0",
            ),
            (
                "consistency.min_angle_from_horizontal_deg",
                c.min_angle_from_horizontal_deg,
                (0.0..=90.0).contains(&c.min_angle_from_horizontal_deg),
                "degrees in [0, 90]",
            ),
            (
                "consistency.min_neighbours",
                c.min_neighbours as f64,
                c.min_neighbours >= 1 && c.min_neighbours <= c.neighbours,
                "a count in [1, consistency.neighbours]",
            ),
            (
                "photometric.min_angle_from_horizontal_deg",
                p.min_angle_from_horizontal_deg,
                (0.0..=90.0).contains(&p.min_angle_from_horizontal_deg),
                "degrees in [0, 90]",
            ),
        ];
        match checks.into_iter().find(|(_, _, ok, _)| !ok) {
            Some((field, value, _, expected)) => Err(ConfigError::OutOfRange {
                field,
                value,
                expected,
            }),
            None => Ok(()),
        }
    }
}

fn finite_nonneg(v: f64) -> bool {
    v.is_finite() && v >= 0.0
}
