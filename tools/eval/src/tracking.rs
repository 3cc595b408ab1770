//! Table I (tracking) and Table III (cost): every detector × matcher on every frame of a
//! sequence, stereo and frame to frame, with inliers judged against ground-truth depth.
//!
//! **Inlier.** A match (i in the first image, j in the second) is an inlier when segment i,
//! carried into the second image with the true geometry, lies on segment j's line: five
//! points along i (at 10 %, 30 %, 50 %, 70 %, 90 %) are back-projected with the first image's
//! depth map, moved with the true relative pose (stereo: the baseline; frame to frame: the
//! two ground-truth poses), projected, and their distances to j's infinite line taken; the
//! match's error is the median, an inlier when below 1 px (SPEC §6). A point on an
//! occluding edge sees two surfaces, so each sample uses the depth, among its pixel's 3×3
//! neighbours, that projects closest to the line. Samples without depth are skipped; a match
//! with fewer than three samples is not judged. Sequences without depth maps (the real
//! EuRoC excerpt) report counts only.

use linetrack_datasets::depth::{DepthMap, read_depth_png};
use linetrack_datasets::{StereoFrame, StereoSequence};
use linetrack_geometry::{MatchCase, Point, Segment, StereoRig};
use linetrack_vision::{
    DetectorKind, FeatureMatch, FrontendConfig, LinePairMatcher, MatcherKind, perturb,
};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use std::path::Path;

/// An optional illumination change: time in seconds → (gain, bias) for both images.
pub type Illumination<'a> = Option<&'a dyn Fn(f64) -> (f64, f64)>;

/// Detector × matcher combinations of the paper's tables.
pub const COMBINATIONS: [(DetectorKind, MatcherKind); 6] = [
    (DetectorKind::Lsd, MatcherKind::Lbd),
    (DetectorKind::Lsd, MatcherKind::L1),
    (DetectorKind::Fld, MatcherKind::Lbd),
    (DetectorKind::Fld, MatcherKind::L1),
    (DetectorKind::EdgeLines, MatcherKind::Lbd),
    (DetectorKind::EdgeLines, MatcherKind::L1),
];

/// Per frame counts of one combination and case.
#[derive(Debug, Clone, Copy, Default)]
pub struct FrameCount {
    /// Matches.
    pub matches: usize,
    /// Matches judged.
    pub judged: usize,
    /// Judged matches that are inliers.
    pub inliers: usize,
}

/// Results of one combination on one sequence.
#[derive(Debug, Clone, Default)]
pub struct TrackingResult {
    /// Per frame, stereo.
    pub stereo: Vec<FrameCount>,
    /// Per frame (k − 1 → k), frame to frame.
    pub frame_to_frame: Vec<FrameCount>,
    /// Per tracked frame (from the second on): monocular ms (detect + describe the left
    /// image + frame-to-frame match).
    pub mono_ms: Vec<f64>,
    /// Per tracked frame: stereo ms (both images + stereo match + frame-to-frame match).
    pub stereo_ms: Vec<f64>,
}

impl TrackingResult {
    /// Mean matches per frame and inlier ratio (None when nothing was judged).
    pub fn summary(counts: &[FrameCount]) -> (f64, Option<f64>) {
        let n = counts.len().max(1) as f64;
        let matches: usize = counts.iter().map(|c| c.matches).sum();
        let judged: usize = counts.iter().map(|c| c.judged).sum();
        let inliers: usize = counts.iter().map(|c| c.inliers).sum();
        (
            matches as f64 / n,
            (judged > 0).then(|| inliers as f64 / judged as f64),
        )
    }
}

/// Median, or NaN for an empty slice.
pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Frame `k` of `sequence`, both images perturbed by `illumination(t)` when given (`t`:
/// seconds since the first frame).
pub fn load_frame(
    sequence: &StereoSequence,
    k: usize,
    illumination: Illumination<'_>,
) -> anyhow::Result<StereoFrame> {
    let mut frame = sequence.load_frame(k).map_err(|e| anyhow::anyhow!("{e}"))?;
    if let Some(at) = illumination {
        let start_ns = sequence.frames.first().map_or(0, |f| f.timestamp_ns);
        let (gain, bias) = at(frame.timestamp_ns.saturating_sub(start_ns) as f64 * 1e-9);
        frame.left = perturb(&frame.left, gain, bias)?;
        frame.right = perturb(&frame.right, gain, bias)?;
    }
    Ok(frame)
}

/// The depth map of the left image of a frame, if the dataset has one.
pub fn left_depth(dataset: &Path, timestamp_ns: u64) -> Option<DepthMap> {
    let path = dataset.join(format!("mav0/depth0/data/{timestamp_ns}.png"));
    path.is_file().then(|| read_depth_png(&path).ok()).flatten()
}

/// The match's error in pixels (median over samples), or None if it cannot be judged.
fn match_error(
    rig: &StereoRig,
    depth: &DepthMap,
    second_from_first: &Isometry3<f64>,
    a: &Segment,
    b: &Segment,
) -> Option<f64> {
    let d = b.end - b.start;
    let length = d.norm();
    if !(length > 0.0) {
        return None;
    }
    let line_distance = |p: Point| ((p - b.start).x * d.y - (p - b.start).y * d.x).abs() / length;
    let mut errors = Vec::new();
    for t in [0.1, 0.3, 0.5, 0.7, 0.9] {
        let q = a.start + (a.end - a.start) * t;
        let (u, v) = (q.x.round() as i64, q.y.round() as i64);
        let mut best: Option<f64> = None;
        for (du, dv) in (-1..=1).flat_map(|du| (-1..=1).map(move |dv| (du, dv))) {
            let (x, y) = (u + du, v + dv);
            if x < 0 || y < 0 {
                continue;
            }
            let Some(z) = depth.at(x as usize, y as usize) else {
                continue;
            };
            let z = f64::from(z);
            let point = Point3::new(
                (q.x - rig.cx_px) * z / rig.focal_px,
                (q.y - rig.cy_px) * z / rig.focal_px,
                z,
            );
            let moved = second_from_first * point;
            if moved.z <= 0.05 {
                continue;
            }
            let pixel = Point::new(
                rig.focal_px * moved.x / moved.z + rig.cx_px,
                rig.focal_px * moved.y / moved.z + rig.cy_px,
            );
            let e = line_distance(pixel);
            best = Some(best.map_or(e, |b: f64| b.min(e)));
        }
        errors.extend(best);
    }
    (errors.len() >= 3).then(|| median(&errors))
}

fn judge(
    counts: &mut FrameCount,
    matches: &[FeatureMatch],
    judge_one: impl Fn(&FeatureMatch) -> Option<f64>,
) {
    counts.matches = matches.len();
    for m in matches {
        if let Some(e) = judge_one(m) {
            counts.judged += 1;
            counts.inliers += usize::from(e < 1.0);
        }
    }
}

/// Runs `combination` over the first `frames` frames of `dataset`, images perturbed by
/// `illumination(t)` when given.
pub fn evaluate(
    dataset: &Path,
    sequence: &StereoSequence,
    config: &FrontendConfig,
    combination: (DetectorKind, MatcherKind),
    frames: usize,
    illumination: Illumination<'_>,
) -> anyhow::Result<TrackingResult> {
    let mut pair = LinePairMatcher::new(combination.0, combination.1, config)?;
    let rig = sequence.rig;
    let baseline = Isometry3::from_parts(
        Translation3::new(-rig.baseline_m, 0.0, 0.0),
        UnitQuaternion::identity(),
    );
    let mut result = TrackingResult::default();
    let n = frames.min(sequence.frames.len());
    // Each frame is detected and described once, in its stereo run; the frame-to-frame
    // pass matches the left features of consecutive stereo runs.
    let mut previous: Option<(
        linetrack_vision::LineFeatures,
        Option<DepthMap>,
        Option<Isometry3<f64>>,
    )> = None;
    let mut f2f_matches = Vec::new();
    for k in 0..n {
        let entry = &sequence.frames[k];
        let StereoFrame { left, right, .. } = load_frame(sequence, k, illumination)?;
        let depth = left_depth(dataset, entry.timestamp_ns);
        let stereo = pair.run(MatchCase::Stereo, &left, &right)?;
        let mut counts = FrameCount::default();
        judge(&mut counts, &stereo.matches, |m| {
            let depth = depth.as_ref()?;
            match_error(
                &rig,
                depth,
                &baseline,
                &stereo.first.segments[m.query],
                &stereo.second.segments[m.train],
            )
        });
        result.stereo.push(counts);
        let t = stereo.timings;
        let stereo_ms =
            t.detect_ms[0] + t.detect_ms[1] + t.describe_ms[0] + t.describe_ms[1] + t.match_ms;
        let mono_ms = t.detect_ms[0] + t.describe_ms[0];
        if let Some((prev_left, prev_depth, prev_pose)) = previous.take() {
            let f2f_ms = pair.match_features(
                MatchCase::FrameToFrame,
                &prev_left,
                &stereo.first,
                &mut f2f_matches,
            );
            let relative = match (prev_pose, entry.pose) {
                (Some(a), Some(b)) => Some(b.inverse() * a),
                _ => None,
            };
            let mut counts = FrameCount::default();
            judge(&mut counts, &f2f_matches, |m| {
                match_error(
                    &rig,
                    prev_depth.as_ref()?,
                    relative.as_ref()?,
                    &prev_left.segments[m.query],
                    &stereo.first.segments[m.train],
                )
            });
            result.frame_to_frame.push(counts);
            // Tracking a frame = its own detection and description plus matching it to the
            // previous one (and, in stereo, the stereo match).
            result.mono_ms.push(mono_ms + f2f_ms);
            result.stereo_ms.push(stereo_ms + f2f_ms);
        }
        previous = Some((stereo.first, depth, entry.pose));
    }
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_inlier_judge_measures_pixels_on_a_known_plane() {
        // A fronto-parallel wall 2 m away; the second camera is 10 cm to the right, so the
        // true disparity is f·b/z = 400·0.1/2 = 20 px.
        let rig = StereoRig {
            focal_px: 400.0,
            cx_px: 100.0,
            cy_px: 80.0,
            baseline_m: 0.1,
            width_px: 200,
            height_px: 160,
        };
        let depth = DepthMap {
            width: 200,
            height: 160,
            metres: vec![2.0; 200 * 160],
        };
        let right_from_left = Isometry3::from_parts(
            Translation3::new(-0.1, 0.0, 0.0),
            UnitQuaternion::identity(),
        );
        let left = Segment::from_coords(120.0, 20.0, 130.0, 140.0);
        let exact = Segment::from_coords(100.0, 20.0, 110.0, 140.0);
        let error = match_error(&rig, &depth, &right_from_left, &left, &exact).unwrap();
        assert!(error < 1e-9, "{error}");
        // Three pixels off horizontally on a line of slope 12: 3·12/√145 px from it.
        let shifted = Segment::from_coords(103.0, 20.0, 113.0, 140.0);
        let error = match_error(&rig, &depth, &right_from_left, &left, &shifted).unwrap();
        assert!((error - 36.0 / 145f64.sqrt()).abs() < 1e-6, "{error}");
        // No depth: not judged.
        let empty = DepthMap {
            width: 200,
            height: 160,
            metres: vec![0.0; 200 * 160],
        };
        assert_eq!(
            match_error(&rig, &empty, &right_from_left, &left, &exact),
            None
        );
    }
}
