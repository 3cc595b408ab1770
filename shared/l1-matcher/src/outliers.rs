//! The flow-direction outlier filter (paper §III-C).
//!
//! Each accepted match has a midpoint flow `x = m_i − m_j`. Stereo flows of a rectified
//! pair are horizontal; flows between consecutive frames of a small motion point in a
//! consistent direction. The filter takes the axial angle of every flow against the
//! epipolar axis (X for stereo, Y frame to frame), estimates the centre and spread of
//! those angles robustly (median and 1.4826 × MAD), and drops matches further than
//! `sigmas` spreads from the centre.
//!
//! Angles are axial (a flow and its opposite are the same line), so they live on a circle
//! of period π. To take a median without a seam, they are first unwrapped around their
//! circular mean (the mean direction of the doubled angles).

use crate::{Match, MatchCase, OutlierFilter};
use linetrack_geometry::SegmentFeatures;
use std::f64::consts::{FRAC_PI_2, PI};

/// Scale from the median absolute deviation to σ for a normal distribution.
const MAD_TO_SIGMA: f64 = 1.4826;

#[derive(Debug, Clone)]
pub(crate) struct FlowFilter {
    config: OutlierFilter,
    /// Axial angle per tentative match (NaN where the flow is too short to have one).
    angles: Vec<f64>,
    scratch: Vec<f64>,
}

impl FlowFilter {
    pub(crate) fn new(config: OutlierFilter) -> Self {
        Self {
            config,
            angles: Vec::new(),
            scratch: Vec::new(),
        }
    }

    /// Removes the outliers from `matches`; returns how many were removed.
    pub(crate) fn retain(
        &mut self,
        case: MatchCase,
        matches: &mut Vec<Match>,
        first: &[Option<SegmentFeatures>],
        second: &[Option<SegmentFeatures>],
    ) -> usize {
        if !self.config.enabled {
            return 0;
        }
        self.angles.clear();
        for m in matches.iter() {
            // Matches only ever pair valid segments.
            let angle = match (&first[m.query], &second[m.train]) {
                (Some(a), Some(b)) => axial_angle(case, a, b, self.config.min_flow_px),
                _ => f64::NAN,
            };
            self.angles.push(angle);
        }
        self.scratch.clear();
        self.scratch
            .extend(self.angles.iter().copied().filter(|a| !a.is_nan()));
        if self.scratch.len() < self.config.min_matches.max(1) {
            return 0;
        }
        let (sum_sin, sum_cos) = self.scratch.iter().fold((0.0, 0.0), |(s, c), a| {
            (s + (2.0 * a).sin(), c + (2.0 * a).cos())
        });
        let mean = 0.5 * sum_sin.atan2(sum_cos);
        for a in self.scratch.iter_mut() {
            *a = fold(*a - mean);
        }
        let centre = median(&mut self.scratch);
        for a in self.scratch.iter_mut() {
            *a = (*a - centre).abs();
        }
        let sigma =
            (MAD_TO_SIGMA * median(&mut self.scratch)).max(self.config.min_sigma_deg.to_radians());
        let limit = self.config.sigmas * sigma;
        let before = matches.len();
        let mut k = 0;
        matches.retain(|_| {
            let a = self.angles[k];
            k += 1;
            a.is_nan() || (fold(a - mean) - centre).abs() <= limit
        });
        before - matches.len()
    }
}

/// Angle of the flow `m_a − m_b` against the epipolar axis, folded to [−π/2, π/2);
/// NaN when the flow is shorter than `min_flow_px`.
fn axial_angle(case: MatchCase, a: &SegmentFeatures, b: &SegmentFeatures, min_flow_px: f64) -> f64 {
    let flow = a.mid - b.mid;
    if !(flow.norm() >= min_flow_px.max(f64::MIN_POSITIVE)) {
        return f64::NAN;
    }
    let (off_axis, on_axis) = match case {
        MatchCase::Stereo => (flow.y, flow.x),
        MatchCase::FrameToFrame => (flow.x, flow.y),
    };
    fold(off_axis.atan2(on_axis))
}

/// Folds an angle into [−π/2, π/2) (period π).
fn fold(angle: f64) -> f64 {
    (angle + FRAC_PI_2).rem_euclid(PI) - FRAC_PI_2
}

/// Median of a non-empty slice (reorders it).
fn median(values: &mut [f64]) -> f64 {
    let mid = values.len() / 2;
    let (_, upper, _) = values.select_nth_unstable_by(mid, f64::total_cmp);
    let upper = *upper;
    if values.len() % 2 == 1 {
        upper
    } else {
        let lower = values[..mid]
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lower + upper)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_geometry::Segment;

    fn features(x0: f64, y0: f64, x1: f64, y1: f64) -> Option<SegmentFeatures> {
        SegmentFeatures::new(&Segment::from_coords(x0, y0, x1, y1)).ok()
    }

    fn m(query: usize, train: usize) -> Match {
        Match {
            query,
            train,
            error: 0.0,
            weight: 1.0,
        }
    }

    #[test]
    fn fold_has_period_pi() {
        for a in [-3.0, -1.0, 0.0, 0.5, 1.5, 3.0] {
            assert!((fold(a) - fold(a + PI)).abs() < 1e-12);
            assert!((-FRAC_PI_2..FRAC_PI_2).contains(&fold(a)));
        }
    }

    #[test]
    fn median_of_odd_and_even() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
    }

    #[test]
    fn stereo_filter_drops_the_slanted_flow_and_keeps_short_ones() {
        // Ten horizontal flows with a little spread, one flow at 45°, one null flow.
        let mut first = Vec::new();
        let mut second = Vec::new();
        for k in 0..10 {
            let y = 10.0 * k as f64;
            first.push(features(100.0, y, 100.0, y + 30.0));
            second.push(features(80.0, y + 0.1 * (k % 3) as f64, 80.0, y + 30.0));
        }
        first.push(features(300.0, 0.0, 300.0, 30.0));
        second.push(features(280.0, 20.0, 280.0, 50.0));
        first.push(features(400.0, 0.0, 400.0, 30.0));
        second.push(features(400.0, 0.0, 400.0, 30.0));
        let mut matches: Vec<Match> = (0..12).map(|k| m(k, k)).collect();
        let mut filter = FlowFilter::new(OutlierFilter::default());
        assert_eq!(
            filter.retain(MatchCase::Stereo, &mut matches, &first, &second),
            1
        );
        assert!(matches.iter().all(|x| x.query != 10));
        assert_eq!(matches.len(), 11);
    }

    #[test]
    fn frame_to_frame_filter_handles_flows_across_the_seam() {
        // Consistent horizontal motion: angles against Y sit at ±π/2, across the seam.
        let mut first = Vec::new();
        let mut second = Vec::new();
        for k in 0..8 {
            let y = 20.0 * k as f64;
            let dy = if k % 2 == 0 { 0.2 } else { -0.2 };
            first.push(features(100.0, y, 120.0, y + 15.0));
            second.push(features(110.0, y + dy, 130.0, y + 15.0 + dy));
        }
        // One vertical flow: an outlier.
        first.push(features(500.0, 0.0, 520.0, 15.0));
        second.push(features(500.0, 10.0, 520.0, 25.0));
        let mut matches: Vec<Match> = (0..9).map(|k| m(k, k)).collect();
        let mut filter = FlowFilter::new(OutlierFilter::default());
        assert_eq!(
            filter.retain(MatchCase::FrameToFrame, &mut matches, &first, &second),
            1
        );
        assert_eq!(matches.last().map(|x| x.query), Some(7));
    }

    #[test]
    fn too_few_flows_are_left_alone() {
        let first = vec![
            features(0.0, 0.0, 0.0, 10.0),
            features(50.0, 0.0, 50.0, 10.0),
        ];
        let second = vec![
            features(-10.0, 0.0, -10.0, 10.0),
            features(40.0, 30.0, 40.0, 40.0),
        ];
        let mut matches = vec![m(0, 0), m(1, 1)];
        let mut filter = FlowFilter::new(OutlierFilter::default());
        assert_eq!(
            filter.retain(MatchCase::Stereo, &mut matches, &first, &second),
            0
        );
        assert_eq!(matches.len(), 2);
    }
}
