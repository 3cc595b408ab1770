//! Random 3-D line scenes seen by a rectified stereo rig, giving 2-D segment sets with
//! known correspondences: the ground truth the matchers are tested, benchmarked and
//! demonstrated on before any image is involved.
//!
//! A scene is a set of 3-D segments in front of the left camera: mostly "Manhattan"
//! (vertical, or horizontal along the two floor axes, as in rooms and buildings), some in
//! random directions, and some groups of closely spaced parallel copies (blinds, shelves,
//! tiles) that make matching ambiguous. Each view projects them, clips them to the image
//! and then damages them the way a real detector does: endpoints truncated independently,
//! Gaussian endpoint noise, some segments missed, some split in two, and random clutter
//! segments that exist in one view only. Every 2-D segment carries the id of the 3-D
//! segment it came from ([`LabelledSegments::labels`]), so a match can be scored.
//!
//! Endpoint order follows the 3-D segment's order in both views, as a gradient-polarity
//! detector (LSD) would give; [`SceneConfig::random_endpoint_order`] scrambles it.
#![warn(missing_docs)]

pub use linetrack_geometry::StereoRig;
use linetrack_geometry::{Point, Segment};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// How a scene is drawn and how detection is damaged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SceneConfig {
    /// Seed of everything random: the same seed gives the same scene.
    pub seed: u64,
    /// Independent 3-D segments (before repetitive groups are added).
    pub segments: usize,
    /// Groups of closely spaced parallel segments.
    pub repetitive_groups: usize,
    /// Segments per repetitive group.
    pub group_size: usize,
    /// Spacing between neighbours of a repetitive group, metres.
    pub group_spacing_m: f64,
    /// Nearest and farthest depth of segment midpoints, metres.
    pub depth_range_m: (f64, f64),
    /// Shortest and longest 3-D segment, metres.
    pub length_range_m: (f64, f64),
    /// Standard deviation of the Gaussian noise on each endpoint coordinate, pixels.
    pub endpoint_noise_px: f64,
    /// Each endpoint is pulled inwards by up to this fraction of the length, per view.
    pub max_truncation: f64,
    /// Probability that a view misses a segment.
    pub miss_probability: f64,
    /// Probability that a view splits a segment into two pieces.
    pub split_probability: f64,
    /// Random segments per view that correspond to nothing in the other view.
    pub clutter: usize,
    /// Segments shorter than this in a view are not detected there, pixels.
    pub min_length_px: f64,
    /// Keep only the longest N segments per view (detectors cap their output the same way).
    pub max_segments: Option<usize>,
    /// Scramble endpoint order (a detector without gradient polarity).
    pub random_endpoint_order: bool,
    /// Camera translation between the two frames of a frame-to-frame pair, metres.
    pub motion_translation_m: f64,
    /// Camera rotation between the two frames of a frame-to-frame pair, degrees.
    pub motion_rotation_deg: f64,
}

impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            segments: 120,
            repetitive_groups: 3,
            group_size: 6,
            group_spacing_m: 0.06,
            depth_range_m: (1.5, 8.0),
            length_range_m: (0.2, 1.5),
            endpoint_noise_px: 0.5,
            max_truncation: 0.08,
            miss_probability: 0.08,
            split_probability: 0.05,
            clutter: 6,
            min_length_px: 15.0,
            max_segments: None,
            random_endpoint_order: false,
            motion_translation_m: 0.03,
            motion_rotation_deg: 1.0,
        }
    }
}

/// Segments of one view, each with the id of the 3-D segment it images (`None`: clutter).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LabelledSegments {
    /// The detected segments, in no particular order.
    pub segments: Vec<Segment>,
    /// `labels[k]` is the 3-D segment id behind `segments[k]`.
    pub labels: Vec<Option<usize>>,
}

/// Two views of one scene with the ground truth to score matches between them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentPair {
    /// Segments of the first image (left, or frame k).
    pub first: LabelledSegments,
    /// Segments of the second image (right, or frame k + 1).
    pub second: LabelledSegments,
    /// The rig both views were taken with.
    pub rig: StereoRig,
}

/// Precision and recall of a set of matches against the labels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Score {
    /// Matches given.
    pub accepted: usize,
    /// Matches whose two segments image the same 3-D segment.
    pub correct: usize,
    /// First-view segments that have at least one counterpart in the second view.
    pub matchable: usize,
}

impl Score {
    /// correct / accepted (1 when nothing was accepted).
    pub fn precision(&self) -> f64 {
        if self.accepted == 0 {
            1.0
        } else {
            self.correct as f64 / self.accepted as f64
        }
    }

    /// correct / matchable (1 when nothing was matchable).
    pub fn recall(&self) -> f64 {
        if self.matchable == 0 {
            1.0
        } else {
            self.correct as f64 / self.matchable as f64
        }
    }
}

impl SegmentPair {
    /// Scores `(first index, second index)` matches. Indices out of range count as wrong.
    pub fn score(&self, matches: impl IntoIterator<Item = (usize, usize)>) -> Score {
        let mut accepted = 0;
        let mut correct = 0;
        for (i, j) in matches {
            accepted += 1;
            let a = self.first.labels.get(i).copied().flatten();
            let b = self.second.labels.get(j).copied().flatten();
            if a.is_some() && a == b {
                correct += 1;
            }
        }
        let matchable = self
            .first
            .labels
            .iter()
            .filter(|l| l.is_some() && self.second.labels.contains(l))
            .count();
        Score {
            accepted,
            correct,
            matchable,
        }
    }
}

/// A scene: 3-D segments in the first left camera's frame (x right, y down, z forward).
struct Scene {
    segments: Vec<(Point3<f64>, Point3<f64>)>,
}

/// The left and right views of a random scene.
pub fn stereo_pair(rig: &StereoRig, config: &SceneConfig) -> SegmentPair {
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let scene = random_scene(rig, config, &mut rng);
    let left = Isometry3::identity();
    let right = Isometry3::from_parts(
        Translation3::new(-rig.baseline_m, 0.0, 0.0),
        UnitQuaternion::identity(),
    );
    SegmentPair {
        first: observe(&scene, &left, rig, config, &mut rng),
        second: observe(&scene, &right, rig, config, &mut rng),
        rig: *rig,
    }
}

/// The left view of a random scene at frame k and after a small random camera motion.
pub fn frame_pair(rig: &StereoRig, config: &SceneConfig) -> SegmentPair {
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let scene = random_scene(rig, config, &mut rng);
    let axis = random_unit(&mut rng);
    let angle = config.motion_rotation_deg.to_radians() * rng.random_range(0.5..1.0);
    let shift = random_unit(&mut rng) * config.motion_translation_m * rng.random_range(0.5..1.0);
    // World → second camera: p₂ = R p + t.
    let moved = Isometry3::from_parts(shift.into(), UnitQuaternion::from_scaled_axis(axis * angle));
    SegmentPair {
        first: observe(&scene, &Isometry3::identity(), rig, config, &mut rng),
        second: observe(&scene, &moved, rig, config, &mut rng),
        rig: *rig,
    }
}

fn random_unit(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    loop {
        let v = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let n = v.norm();
        if n > 0.1 && n <= 1.0 {
            return v / n;
        }
    }
}

/// A direction that is vertical, horizontal along x or z, or random.
fn scene_direction(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    match rng.random_range(0..10) {
        0..=3 => Vector3::y(),
        4..=5 => Vector3::x(),
        6..=7 => Vector3::z(),
        _ => random_unit(rng),
    }
}

fn random_scene(rig: &StereoRig, config: &SceneConfig, rng: &mut ChaCha8Rng) -> Scene {
    let (near, far) = config.depth_range_m;
    let (short, long) = config.length_range_m;
    let random_midpoint = |rng: &mut ChaCha8Rng| {
        let z = rng.random_range(near..far);
        let u = rng.random_range(0.0..rig.width_px as f64);
        let v = rng.random_range(0.0..rig.height_px as f64);
        Point3::new(
            (u - rig.cx_px) * z / rig.focal_px,
            (v - rig.cy_px) * z / rig.focal_px,
            z,
        )
    };
    let mut segments = Vec::new();
    for _ in 0..config.segments {
        let mid = random_midpoint(rng);
        let half = scene_direction(rng) * rng.random_range(short..long) * 0.5;
        segments.push((mid - half, mid + half));
    }
    for _ in 0..config.repetitive_groups {
        let mid = random_midpoint(rng);
        let dir = scene_direction(rng);
        // Spread the copies across the direction, within the plane facing the camera.
        let across = dir
            .cross(&Vector3::z())
            .try_normalize(1e-9)
            .unwrap_or_else(Vector3::x);
        let half = dir * rng.random_range(short..long) * 0.5;
        for k in 0..config.group_size {
            let offset = across * (k as f64 * config.group_spacing_m);
            segments.push((mid + offset - half, mid + offset + half));
        }
    }
    Scene { segments }
}

/// Standard normal sample (Box–Muller).
fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.random_range(0.0..1.0);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Smallest depth kept when clipping against the image plane, metres.
const NEAR_PLANE_M: f64 = 0.1;

fn observe(
    scene: &Scene,
    world_to_camera: &Isometry3<f64>,
    rig: &StereoRig,
    config: &SceneConfig,
    rng: &mut ChaCha8Rng,
) -> LabelledSegments {
    let mut out = LabelledSegments::default();
    for (id, (a, b)) in scene.segments.iter().enumerate() {
        let Some(seg) = project_clipped(&(world_to_camera * a), &(world_to_camera * b), rig) else {
            continue;
        };
        if seg.length() < config.min_length_px || rng.random_bool(config.miss_probability) {
            continue;
        }
        let seg = truncate(&seg, config.max_truncation, rng);
        if rng.random_bool(config.split_probability) {
            let cut = rng.random_range(0.3..0.7);
            let gap = rng.random_range(2.0..6.0) / seg.length();
            let at = |t: f64| seg.start + (seg.end - seg.start) * t;
            for piece in [
                Segment::new(seg.start, at(cut - gap / 2.0)),
                Segment::new(at(cut + gap / 2.0), seg.end),
            ] {
                push_noisy(&mut out, piece, Some(id), config, rng);
            }
        } else {
            push_noisy(&mut out, seg, Some(id), config, rng);
        }
    }
    for _ in 0..config.clutter {
        let (w, h) = (rig.width_px as f64, rig.height_px as f64);
        let start = Point::new(rng.random_range(0.0..w), rng.random_range(0.0..h));
        let angle = rng.random_range(0.0..std::f64::consts::PI);
        let length = rng.random_range(config.min_length_px..config.min_length_px * 6.0);
        let end = start + nalgebra::Vector2::new(angle.cos(), angle.sin()) * length;
        push_noisy(&mut out, Segment::new(start, end), None, config, rng);
    }
    shuffle_and_cap(out, config.max_segments, rng)
}

fn push_noisy(
    out: &mut LabelledSegments,
    seg: Segment,
    label: Option<usize>,
    config: &SceneConfig,
    rng: &mut ChaCha8Rng,
) {
    let sigma = config.endpoint_noise_px;
    let mut jitter =
        |p: Point| Point::new(p.x + sigma * gaussian(rng), p.y + sigma * gaussian(rng));
    let noisy = Segment::new(jitter(seg.start), jitter(seg.end));
    let noisy = if config.random_endpoint_order && rng.random_bool(0.5) {
        noisy.reversed()
    } else {
        noisy
    };
    out.segments.push(noisy);
    out.labels.push(label);
}

fn truncate(seg: &Segment, max_fraction: f64, rng: &mut ChaCha8Rng) -> Segment {
    let delta = seg.end - seg.start;
    let head = rng.random_range(0.0..=max_fraction);
    let tail = rng.random_range(0.0..=max_fraction);
    Segment::new(seg.start + delta * head, seg.end - delta * tail)
}

/// Random order (Fisher–Yates), then the longest `cap` segments if capped.
fn shuffle_and_cap(
    mut set: LabelledSegments,
    cap: Option<usize>,
    rng: &mut ChaCha8Rng,
) -> LabelledSegments {
    let n = set.segments.len();
    for k in (1..n).rev() {
        let other = rng.random_range(0..=k);
        set.segments.swap(k, other);
        set.labels.swap(k, other);
    }
    if let Some(cap) = cap.filter(|&c| c < n) {
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| {
            set.segments[b]
                .length()
                .total_cmp(&set.segments[a].length())
        });
        order.truncate(cap);
        order.sort_unstable();
        set = LabelledSegments {
            segments: order.iter().map(|&k| set.segments[k]).collect(),
            labels: order.iter().map(|&k| set.labels[k]).collect(),
        };
    }
    set
}

/// Projects a camera-frame 3-D segment, clipped to the near plane and the image.
fn project_clipped(a: &Point3<f64>, b: &Point3<f64>, rig: &StereoRig) -> Option<Segment> {
    // Clip against z ≥ NEAR_PLANE_M in 3-D.
    let (mut a, mut b) = (*a, *b);
    if a.z < NEAR_PLANE_M && b.z < NEAR_PLANE_M {
        return None;
    }
    if a.z < NEAR_PLANE_M || b.z < NEAR_PLANE_M {
        let t = (NEAR_PLANE_M - a.z) / (b.z - a.z);
        let cut = a + (b - a) * t;
        if a.z < NEAR_PLANE_M { a = cut } else { b = cut }
    }
    let project = |p: &Point3<f64>| {
        Point::new(
            rig.focal_px * p.x / p.z + rig.cx_px,
            rig.focal_px * p.y / p.z + rig.cy_px,
        )
    };
    Segment::new(project(&a), project(&b)).clipped_to(rig.width_px as f64, rig.height_px as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_scene_other_seed_other_scene() {
        let rig = StereoRig::default();
        let config = SceneConfig {
            seed: 3,
            ..Default::default()
        };
        assert_eq!(stereo_pair(&rig, &config), stereo_pair(&rig, &config));
        assert_ne!(
            stereo_pair(&rig, &config),
            stereo_pair(&rig, &SceneConfig { seed: 4, ..config })
        );
    }

    #[test]
    fn noiseless_stereo_views_are_row_aligned_with_positive_disparity() {
        let rig = StereoRig::default();
        let config = SceneConfig {
            endpoint_noise_px: 0.0,
            max_truncation: 0.0,
            split_probability: 0.0,
            miss_probability: 0.0,
            clutter: 0,
            ..Default::default()
        };
        let pair = stereo_pair(&rig, &config);
        let mut checked = 0;
        for (i, label) in pair.first.labels.iter().enumerate() {
            let Some(j) = pair.second.labels.iter().position(|l| l == label) else {
                continue;
            };
            let (l, r) = (pair.first.segments[i], pair.second.segments[j]);
            // Unclipped segments: the same rows, shifted left in the right image.
            let inside = |s: &Segment| {
                [s.start, s.end]
                    .iter()
                    .all(|p| p.x > 1.0 && p.x < 751.0 && p.y > 1.0 && p.y < 479.0)
            };
            if inside(&l) && inside(&r) {
                assert!((l.start.y - r.start.y).abs() < 1e-9 && (l.end.y - r.end.y).abs() < 1e-9);
                assert!(l.start.x > r.start.x && l.end.x > r.end.x);
                checked += 1;
            }
        }
        assert!(checked > 50, "only {checked} pairs checked");
    }

    #[test]
    fn score_counts_correct_wrong_and_matchable() {
        let seg = Segment::from_coords(0.0, 0.0, 1.0, 1.0);
        let pair = SegmentPair {
            first: LabelledSegments {
                segments: vec![seg; 3],
                labels: vec![Some(1), Some(2), None],
            },
            second: LabelledSegments {
                segments: vec![seg; 2],
                labels: vec![Some(2), Some(1)],
            },
            rig: StereoRig::default(),
        };
        let score = pair.score([(0, 1), (1, 1), (2, 0), (7, 0)]);
        assert_eq!(
            score,
            Score {
                accepted: 4,
                correct: 1,
                matchable: 2
            }
        );
        assert_eq!(score.precision(), 0.25);
        assert_eq!(score.recall(), 0.5);
    }

    #[test]
    fn cap_keeps_the_longest() {
        let rig = StereoRig::default();
        let all = stereo_pair(&rig, &SceneConfig::default());
        let capped = stereo_pair(
            &rig,
            &SceneConfig {
                max_segments: Some(40),
                ..Default::default()
            },
        );
        assert_eq!(capped.first.segments.len(), 40);
        let shortest_kept = capped
            .first
            .segments
            .iter()
            .map(Segment::length)
            .fold(f64::INFINITY, f64::min);
        let longer_in_all = all
            .first
            .segments
            .iter()
            .filter(|s| s.length() > shortest_kept)
            .count();
        assert!(longer_in_all <= 40);
    }
}
