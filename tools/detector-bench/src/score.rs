//! Detected segments scored against the true ones of a frame.
//!
//! A detection **fits** a true segment when its direction is within [`Rule::angle_deg`]
//! of the true one, both its endpoints lie within [`Rule::distance_px`] of the true
//! segment's line, and at least half of it, projected on that line, falls within the
//! true segment. A true segment is **found** when the detections that fit it cover at
//! least [`Rule::coverage`] of its length together (detectors may break one edge in
//! pieces). A detection that fits no true segment (of any length) is **unmatched**.

use crate::truth::TrueSegment;
use linetrack_geometry::{Point, Segment};

/// The matching rule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rule {
    /// Largest angle between a detection and a true segment, degrees.
    pub angle_deg: f64,
    /// Largest perpendicular distance of a detection's endpoints to the true line, pixels.
    pub distance_px: f64,
    /// Share of a true segment's length the fitting detections must cover.
    pub coverage: f64,
    /// True segments shorter than this are not asked for (they can still be fitted).
    pub min_length_px: f64,
}

impl Default for Rule {
    fn default() -> Self {
        Self {
            angle_deg: 3.0,
            distance_px: 2.0,
            coverage: 0.5,
            min_length_px: 15.0,
        }
    }
}

/// One frame's outcome.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameScore {
    /// Ids of the true segments asked for (at least `min_length_px` long; an id counted
    /// once even when occlusion splits it).
    pub asked: Vec<usize>,
    /// Ids of the asked true segments that were found.
    pub found: Vec<usize>,
    /// Number of detections.
    pub detections: usize,
    /// Detections that fit no true segment.
    pub unmatched: usize,
    /// Perpendicular distance to the true line of both endpoints of every fitting
    /// detection (to its closest fitting true segment), pixels.
    pub endpoint_distances: Vec<f64>,
}

/// Unit direction, length and the perpendicular distance of `p` to `t`'s line, and the
/// position of `p` along it.
fn frame_of(t: &Segment) -> (Point, nalgebra::Vector2<f64>, f64) {
    let d = t.end - t.start;
    let length = d.norm();
    (t.start, d / length, length)
}

/// If `d` fits `t`: the detection's extent along `t` (clipped to `t`) and the mean
/// endpoint distance.
fn fit(t: &Segment, d: &Segment, rule: &Rule) -> Option<((f64, f64), [f64; 2])> {
    let (origin, u, length) = frame_of(t);
    let dd = d.end - d.start;
    let d_length = dd.norm();
    if length <= 0.0 || d_length <= 0.0 {
        return None;
    }
    let cos = (u.dot(&dd) / d_length).abs().min(1.0);
    if cos.acos().to_degrees() > rule.angle_deg {
        return None;
    }
    let perp = |p: &Point| {
        let r = p - origin;
        (u.x * r.y - u.y * r.x).abs()
    };
    let distances = [perp(&d.start), perp(&d.end)];
    if distances.iter().any(|x| *x > rule.distance_px) {
        return None;
    }
    let (s0, s1) = (u.dot(&(d.start - origin)), u.dot(&(d.end - origin)));
    let (lo, hi) = (s0.min(s1), s0.max(s1));
    let (clo, chi) = (lo.max(0.0), hi.min(length));
    (chi - clo >= 0.5 * (hi - lo)).then_some(((clo, chi), distances))
}

/// Length of the union of intervals.
fn union_length(mut intervals: Vec<(f64, f64)>) -> f64 {
    intervals.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut total = 0.0;
    let mut current: Option<(f64, f64)> = None;
    for (lo, hi) in intervals {
        match current {
            Some((clo, chi)) if lo <= chi => current = Some((clo, chi.max(hi))),
            _ => {
                if let Some((clo, chi)) = current {
                    total += chi - clo;
                }
                current = Some((lo, hi));
            }
        }
    }
    total + current.map_or(0.0, |(lo, hi)| hi - lo)
}

/// Scores `detections` against the `truth` of one frame.
pub fn score_frame(truth: &[TrueSegment], detections: &[Segment], rule: &Rule) -> FrameScore {
    let mut score = FrameScore {
        detections: detections.len(),
        ..FrameScore::default()
    };
    // Per true segment, the extents of the detections fitting it.
    let mut covered: Vec<Vec<(f64, f64)>> = vec![Vec::new(); truth.len()];
    for d in detections {
        let mut best: Option<[f64; 2]> = None;
        for (k, t) in truth.iter().enumerate() {
            if let Some((extent, distances)) = fit(&t.segment, d, rule) {
                covered[k].push(extent);
                if best.is_none_or(|b| distances[0] + distances[1] < b[0] + b[1]) {
                    best = Some(distances);
                }
            }
        }
        match best {
            Some(distances) => score.endpoint_distances.extend(distances),
            None => score.unmatched += 1,
        }
    }
    for (t, extents) in truth.iter().zip(covered) {
        let length = t.segment.length();
        if length < rule.min_length_px {
            continue;
        }
        if !score.asked.contains(&t.id) {
            score.asked.push(t.id);
        }
        if union_length(extents) >= rule.coverage * length && !score.found.contains(&t.id) {
            score.found.push(t.id);
        }
    }
    score
}
