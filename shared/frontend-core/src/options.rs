//! The `[lines]` and `[edgelines]` tables of `configs/frontend.toml`: which segments are
//! kept, and the `edgelines` detector's parameters, each with its range check.

use serde::{Deserialize, Serialize};

/// A field outside its range: its dotted name (as in the TOML file), its value and what
/// was expected.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InvalidField {
    /// The field, e.g. `edgelines.scan_interval`.
    pub field: &'static str,
    /// Its value, as given.
    pub value: String,
    /// The range it must be in.
    pub expected: &'static str,
}

impl std::fmt::Display for InvalidField {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "field `{}` = {}: {}",
            self.field, self.value, self.expected
        )
    }
}

impl std::error::Error for InvalidField {}

fn invalid(field: &'static str, value: impl ToString, expected: &'static str) -> InvalidField {
    InvalidField {
        field,
        value: value.to_string(),
        expected,
    }
}

/// Selection of detected segments.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LineOptions {
    /// Keep at most this many segments per image, longest first (paper: 100).
    pub max_segments: usize,
    /// Drop segments shorter than this, pixels.
    pub min_length_px: f64,
}

impl Default for LineOptions {
    fn default() -> Self {
        Self {
            max_segments: 100,
            min_length_px: 15.0,
        }
    }
}

impl LineOptions {
    /// Checks the ranges; the error names the field.
    pub fn validate(&self) -> Result<(), InvalidField> {
        if !(self.min_length_px >= 0.0 && self.min_length_px.is_finite()) {
            return Err(invalid(
                "lines.min_length_px",
                self.min_length_px,
                "a finite number >= 0",
            ));
        }
        Ok(())
    }
}

/// Parameters of the `edgelines` detector (`linetrack-edge-lines`). Gradient thresholds
/// are in units of a 3×3 Sobel `|gx| + |gy|` on the smoothed 8-bit image (at most 2040).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EdgeLinesOptions {
    /// Pixels whose gradient is below this are not edges.
    pub gradient_threshold: u16,
    /// An anchor's gradient exceeds both neighbours across the edge by at least this.
    pub anchor_threshold: u16,
    /// Anchors are looked for on every this-th row and column (>= 1).
    pub scan_interval: usize,
    /// A pixel further than this from the fitted line is an outlier, pixels.
    pub max_fit_error_px: f32,
    /// A segment ends after more than this many outlier pixels in a row.
    pub max_outlier_run: usize,
    /// A segment is kept when at least this fraction of its pixels have a gradient across
    /// it (within 22.5°) of one sign.
    pub min_aligned_fraction: f32,
}

impl Default for EdgeLinesOptions {
    fn default() -> Self {
        let p = linetrack_edge_lines::Params::default();
        Self {
            gradient_threshold: p.gradient_threshold,
            anchor_threshold: p.anchor_threshold,
            scan_interval: p.scan_interval,
            max_fit_error_px: p.max_fit_error_px,
            max_outlier_run: p.max_outlier_run,
            min_aligned_fraction: p.min_aligned_fraction,
        }
    }
}

impl EdgeLinesOptions {
    /// The detector's parameters, keeping segments by `keep`.
    pub fn params(&self, keep: LineOptions) -> linetrack_edge_lines::Params {
        linetrack_edge_lines::Params {
            gradient_threshold: self.gradient_threshold,
            anchor_threshold: self.anchor_threshold,
            scan_interval: self.scan_interval,
            max_fit_error_px: self.max_fit_error_px,
            max_outlier_run: self.max_outlier_run,
            min_length_px: keep.min_length_px as f32,
            max_segments: keep.max_segments,
            min_aligned_fraction: self.min_aligned_fraction,
        }
    }

    /// Checks the ranges; the error names the first bad field.
    pub fn validate(&self) -> Result<(), InvalidField> {
        if self.gradient_threshold < 1 {
            return Err(invalid(
                "edgelines.gradient_threshold",
                self.gradient_threshold,
                ">= 1",
            ));
        }
        if self.scan_interval < 1 {
            return Err(invalid(
                "edgelines.scan_interval",
                self.scan_interval,
                ">= 1",
            ));
        }
        if !(self.max_fit_error_px > 0.0 && self.max_fit_error_px.is_finite()) {
            return Err(invalid(
                "edgelines.max_fit_error_px",
                self.max_fit_error_px,
                "a finite number > 0",
            ));
        }
        if !(0.0..=1.0).contains(&self.min_aligned_fraction) {
            return Err(invalid(
                "edgelines.min_aligned_fraction",
                self.min_aligned_fraction,
                "in [0, 1]",
            ));
        }
        Ok(())
    }
}
