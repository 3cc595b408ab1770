//! The cheap candidate gates, evaluated for one query against every candidate in one
//! branch-free pass over a structure-of-arrays copy of the candidate set, so the compiler
//! can vectorise it. Only the survivors get their geometric terms computed.

use crate::Gates;
use linetrack_geometry::{MatchCase, ROW_FOOTPRINT_PX, SegmentFeatures};

/// The candidate set, one array per quantity the gates read. Single precision: the gates
/// are coarse tests, and `f32` lanes are twice as many per vector instruction.
#[derive(Debug, Clone, Default)]
pub(crate) struct CandidateTable {
    mid_x: Vec<f32>,
    mid_y: Vec<f32>,
    dir_x: Vec<f32>,
    dir_y: Vec<f32>,
    length: Vec<f32>,
    x_min: Vec<f32>,
    x_max: Vec<f32>,
    y_min: Vec<f32>,
    y_max: Vec<f32>,
    /// Valid and not excluded by a per-segment gate.
    usable: Vec<bool>,
    /// Scratch: which candidates pass, for the current query.
    mask: Vec<bool>,
}

/// Gate thresholds in the form the pass compares directly.
#[derive(Debug, Clone, Copy)]
pub(crate) struct GateLimits {
    enabled: bool,
    angle_gate: bool,
    sin_max_angle: f32,
    cos_max_angle: f32,
    /// Segments with |dir.y| below this are skipped in stereo (0: no gate).
    pub(crate) sin_min_from_horizontal: f64,
    /// Stereo rows must intersect (implied by a positive minimum overlap).
    rows_must_meet: bool,
    min_disparity_px: f32,
    max_disparity_px: f32,
    max_displacement_px: f32,
    max_length_ratio: f32,
    same_polarity: bool,
}

impl GateLimits {
    pub(crate) fn new(gates: &Gates) -> Self {
        let on = gates.enabled;
        Self {
            enabled: on,
            angle_gate: on && gates.max_angle_deg < 90.0,
            sin_max_angle: as_f32(gates.max_angle_deg.to_radians().sin()),
            cos_max_angle: as_f32(gates.max_angle_deg.to_radians().cos()),
            sin_min_from_horizontal: if on {
                gates.min_angle_from_horizontal_deg.to_radians().sin()
            } else {
                0.0
            },
            rows_must_meet: on && gates.stereo_min_overlap > 0.0,
            min_disparity_px: as_f32(gates.min_disparity_px),
            max_disparity_px: as_f32(gates.max_disparity_px),
            max_displacement_px: as_f32(gates.max_displacement_px),
            max_length_ratio: as_f32(gates.max_length_ratio),
            same_polarity: on && gates.same_polarity,
        }
    }

    /// Whether a segment takes part at all in `case` (the near-horizontal stereo gate).
    pub(crate) fn usable(&self, case: MatchCase, f: &SegmentFeatures) -> bool {
        case != MatchCase::Stereo || f.dir.y.abs() >= self.sin_min_from_horizontal
    }
}

impl CandidateTable {
    /// Refills the table from the candidate features.
    pub(crate) fn fill(
        &mut self,
        case: MatchCase,
        limits: &GateLimits,
        features: &[Option<SegmentFeatures>],
    ) {
        let columns = [
            &mut self.mid_x,
            &mut self.mid_y,
            &mut self.dir_x,
            &mut self.dir_y,
            &mut self.length,
            &mut self.x_min,
            &mut self.x_max,
            &mut self.y_min,
            &mut self.y_max,
        ];
        for column in columns {
            column.clear();
        }
        self.usable.clear();
        for f in features {
            // Degenerate segments get harmless values and are masked out by `usable`.
            let f_or_zero = f.unwrap_or(ZERO_FEATURES);
            self.mid_x.push(as_f32(f_or_zero.mid.x));
            self.mid_y.push(as_f32(f_or_zero.mid.y));
            self.dir_x.push(as_f32(f_or_zero.dir.x));
            self.dir_y.push(as_f32(f_or_zero.dir.y));
            self.length.push(as_f32(f_or_zero.length));
            self.x_min.push(as_f32(f_or_zero.x_min));
            self.x_max.push(as_f32(f_or_zero.x_max));
            self.y_min.push(as_f32(f_or_zero.y_min));
            self.y_max.push(as_f32(f_or_zero.y_max));
            self.usable
                .push(f.as_ref().is_some_and(|f| limits.usable(case, f)));
        }
    }

    /// Appends to `out` the index of every candidate that passes the gates for `query`.
    pub(crate) fn admit(
        &mut self,
        case: MatchCase,
        limits: &GateLimits,
        query: &SegmentFeatures,
        out: &mut Vec<usize>,
    ) {
        let n = self.usable.len();
        if !limits.enabled {
            out.extend((0..n).filter(|&j| self.usable[j]));
            return;
        }
        self.mask.clear();
        self.mask.resize(n, false);
        let q = QueryF32::new(query);
        let mask = &mut self.mask[..n];
        let (dir_x, dir_y, length) = (&self.dir_x[..n], &self.dir_y[..n], &self.length[..n]);
        // Direction, polarity and length-ratio gates, common to both cases.
        for j in 0..n {
            let dot = q.dir_x * dir_x[j] + q.dir_y * dir_y[j];
            let cross = q.dir_x * dir_y[j] - q.dir_y * dir_x[j];
            let longer = q.length.max(length[j]);
            let shorter = q.length.min(length[j]);
            mask[j] = self.usable[j]
                & (longer <= limits.max_length_ratio * shorter)
                & (!limits.same_polarity | (dot > 0.0))
                & (!limits.angle_gate
                    | (cross.abs() * limits.cos_max_angle <= dot.abs() * limits.sin_max_angle));
        }
        match case {
            MatchCase::Stereo => {
                // Some point of the candidate lies within the disparity range of some point
                // of the query, and (with a positive minimum overlap) the padded row
                // extents intersect.
                let pad = as_f32(2.0 * ROW_FOOTPRINT_PX);
                let (lo, hi) = (
                    q.x_min - limits.max_disparity_px,
                    q.x_max - limits.min_disparity_px,
                );
                let (x_min, x_max) = (&self.x_min[..n], &self.x_max[..n]);
                let (y_min, y_max) = (&self.y_min[..n], &self.y_max[..n]);
                for j in 0..n {
                    mask[j] &= (x_max[j] >= lo)
                        & (x_min[j] <= hi)
                        & (!limits.rows_must_meet
                            | ((y_min[j] < q.y_max + pad) & (y_max[j] > q.y_min - pad)));
                }
            }
            MatchCase::FrameToFrame => {
                // The candidate's midpoint lies near the query's line, and not beyond the
                // displacement plus half the longer length from its midpoint.
                let reach = limits.max_displacement_px;
                let (mid_x, mid_y) = (&self.mid_x[..n], &self.mid_y[..n]);
                for j in 0..n {
                    let (fx, fy) = (mid_x[j] - q.mid_x, mid_y[j] - q.mid_y);
                    let off_line = (q.dir_x * fy - q.dir_y * fx).abs();
                    let along = reach + 0.5 * q.length.max(length[j]);
                    mask[j] &= (off_line <= reach) & (fx * fx + fy * fy <= along * along);
                }
            }
        }
        out.extend(
            mask.iter()
                .enumerate()
                .filter(|(_, pass)| **pass)
                .map(|(j, _)| j),
        );
    }
}

/// The query's quantities in the table's precision.
struct QueryF32 {
    mid_x: f32,
    mid_y: f32,
    dir_x: f32,
    dir_y: f32,
    length: f32,
    x_min: f32,
    x_max: f32,
    y_min: f32,
    y_max: f32,
}

impl QueryF32 {
    fn new(f: &SegmentFeatures) -> Self {
        Self {
            mid_x: as_f32(f.mid.x),
            mid_y: as_f32(f.mid.y),
            dir_x: as_f32(f.dir.x),
            dir_y: as_f32(f.dir.y),
            length: as_f32(f.length),
            x_min: as_f32(f.x_min),
            x_max: as_f32(f.x_max),
            y_min: as_f32(f.y_min),
            y_max: as_f32(f.y_max),
        }
    }
}

/// Rounds to single precision (values beyond its range become ±inf, which the gates
/// treat as "very far", never as NaN).
#[allow(clippy::cast_possible_truncation)]
fn as_f32(v: f64) -> f32 {
    v as f32
}

const ZERO_FEATURES: SegmentFeatures = SegmentFeatures {
    start: linetrack_geometry::Point::new(0.0, 0.0),
    end: linetrack_geometry::Point::new(0.0, 0.0),
    mid: linetrack_geometry::Point::new(0.0, 0.0),
    dir: linetrack_geometry::Vector::new(0.0, 0.0),
    length: 0.0,
    y_min: 0.0,
    y_max: 0.0,
    x_min: 0.0,
    x_max: 0.0,
};
