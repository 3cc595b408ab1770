use super::Summary;
use super::score::{Rule, score_frame};
use super::truth::{AllVisible, DepthVisibility, TrueSegment, project_segments};
use linetrack_geometry::{Point, Segment, StereoRig};
use linetrack_scene_render::{Preset, SequenceRenderer};
use std::sync::OnceLock;

/// A small rendered frame of the normal preset and its true segments (occlusion from the
/// rendered depth map).
fn rendered_truth() -> (&'static [TrueSegment], &'static [TrueSegment]) {
    static TRUTH: OnceLock<(Vec<TrueSegment>, Vec<TrueSegment>)> = OnceLock::new();
    let (visible, all) = TRUTH.get_or_init(render_truth);
    (visible, all)
}

fn render_truth() -> (Vec<TrueSegment>, Vec<TrueSegment>) {
    let mut config = Preset::Normal.config(0, 1);
    config.rig = StereoRig {
        focal_px: 229.0,
        cx_px: 188.0,
        cy_px: 120.0,
        baseline_m: 0.11,
        width_px: 376,
        height_px: 240,
    };
    let renderer = SequenceRenderer::new(config);
    let frame = renderer.render(0);
    let segments = renderer.scene.segments();
    let rig = renderer.config.rig;
    let visibility = DepthVisibility {
        width: frame.left.width,
        height: frame.left.height,
        metres: &frame.left.depth_m,
    };
    (
        project_segments(&segments, &frame.world_from_left, &rig, &visibility),
        project_segments(&segments, &frame.world_from_left, &rig, &AllVisible),
    )
}

fn map(truth: &[TrueSegment], f: impl Fn(&Segment) -> Segment) -> Vec<Segment> {
    truth.iter().map(|t| f(&t.segment)).collect()
}

/// `s` moved `by` pixels along its normal.
fn shifted(s: &Segment, by: f64) -> Segment {
    let d = (s.end - s.start).normalize();
    let n = nalgebra::Vector2::new(-d.y, d.x) * by;
    Segment::new(s.start + n, s.end + n)
}

/// `s` turned by `deg` degrees about its midpoint.
fn rotated(s: &Segment, deg: f64) -> Segment {
    let (c, r) = (s.midpoint(), deg.to_radians());
    let turn = |p: &Point| {
        let v = p - c;
        c + nalgebra::Vector2::new(v.x * r.cos() - v.y * r.sin(), v.x * r.sin() + v.y * r.cos())
    };
    Segment::new(turn(&s.start), turn(&s.end))
}

/// `s` between fractions `a` and `b` of its length.
fn part(s: &Segment, a: f64, b: f64) -> Segment {
    let d = s.end - s.start;
    Segment::new(s.start + d * a, s.start + d * b)
}

#[test]
fn the_true_segments_themselves_are_all_found_exactly() {
    let (truth, _) = rendered_truth();
    let rule = Rule::default();
    let score = score_frame(truth, &map(truth, |s| *s), &rule);
    assert!(
        score.asked.len() > 20,
        "{} true segments",
        score.asked.len()
    );
    assert_eq!(score.found.len(), score.asked.len());
    assert_eq!(score.unmatched, 0);
    assert!(score.endpoint_distances.iter().all(|d| *d < 1e-9));
}

#[test]
fn perturbed_segments_are_found_only_within_the_rule() {
    let (truth, _) = rendered_truth();
    let rule = Rule::default();
    let share = |detections: Vec<Segment>| {
        let score = score_frame(truth, &detections, &rule);
        score.found.len() as f64 / score.asked.len() as f64
    };
    // 1 px off the line: still found, localisation 1 px.
    let near = score_frame(truth, &map(truth, |s| shifted(s, 1.0)), &rule);
    assert_eq!(near.found.len(), near.asked.len());
    let median = {
        let mut d = near.endpoint_distances.clone();
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    };
    assert!((median - 1.0).abs() < 1e-6, "median {median}");
    // 3 px off, or turned 6°: lost (a few may still fit a parallel neighbour).
    assert!(share(map(truth, |s| shifted(s, 3.0))) < 0.3);
    assert!(share(map(truth, |s| rotated(s, 6.0))) < 0.3);
    // A third of each: not enough cover; two halves together: enough.
    assert!(share(map(truth, |s| part(s, 0.0, 0.33))) < 0.3);
    let halves: Vec<Segment> = truth
        .iter()
        .flat_map(|t| [part(&t.segment, 0.0, 0.3), part(&t.segment, 0.5, 0.8)])
        .collect();
    assert_eq!(share(halves), 1.0);
    // Nothing near any true segment: all unmatched.
    let far = score_frame(
        truth,
        &[Segment::from_coords(-50.0, -50.0, -10.0, -50.0)],
        &rule,
    );
    assert_eq!((far.found.len(), far.unmatched), (0, 1));
}

#[test]
fn occluded_parts_are_cut_from_the_truth() {
    // A horizontal segment 2 m ahead across the image; a nearer surface covers columns
    // 150..200.
    let rig = StereoRig {
        focal_px: 100.0,
        cx_px: 160.0,
        cy_px: 120.0,
        baseline_m: 0.1,
        width_px: 320,
        height_px: 240,
    };
    let (width, height) = (320, 240);
    let metres: Vec<f32> = (0..width * height)
        .map(|i| {
            if (150..200).contains(&(i % width)) {
                1.0
            } else {
                2.0
            }
        })
        .collect();
    let visibility = DepthVisibility {
        width,
        height,
        metres: &metres,
    };
    let segment = [
        nalgebra::Point3::new(-2.0, 0.0, 2.0),
        nalgebra::Point3::new(2.0, 0.0, 2.0),
    ];
    let pieces = project_segments(
        &[segment],
        &nalgebra::Isometry3::identity(),
        &rig,
        &visibility,
    );
    assert_eq!(pieces.len(), 2, "{pieces:?}");
    let (a, b) = (pieces[0].segment, pieces[1].segment);
    assert!(
        (a.start.x - 60.0).abs() < 0.5 && (b.end.x - 260.0).abs() < 0.5,
        "{pieces:?}"
    );
    // Cut within a pixel of the occluder (the 3 × 3 test lets edges touch it).
    assert!(
        (149.0..=151.0).contains(&a.end.x) && (198.0..=200.0).contains(&b.start.x),
        "{pieces:?}"
    );
    assert!(
        pieces
            .iter()
            .all(|p| p.id == 0 && (p.segment.start.y - 120.0).abs() < 1e-9)
    );
    let all = project_segments(
        &[segment],
        &nalgebra::Isometry3::identity(),
        &rig,
        &AllVisible,
    );
    assert_eq!(all.len(), 1);

    // In a rendered room, what is visible is at most what is projected, all in the image.
    let (visible, all) = rendered_truth();
    let length = |t: &[TrueSegment]| t.iter().map(|t| t.segment.length()).sum::<f64>();
    assert!(length(visible) < length(all));
    assert!(visible.iter().all(|t| {
        [t.segment.start, t.segment.end]
            .iter()
            .all(|p| p.x >= 0.0 && p.y >= 0.0 && p.x <= 375.0 && p.y <= 239.0)
    }));
}

#[test]
fn frame_to_frame_counts_segments_found_again() {
    use super::score::FrameScore;
    let frame = |asked: &[usize], found: &[usize]| FrameScore {
        asked: asked.to_vec(),
        found: found.to_vec(),
        detections: 4,
        unmatched: 1,
        endpoint_distances: vec![0.5, 1.5],
    };
    let (a, b) = (frame(&[1, 2, 3], &[1, 2, 3]), frame(&[1, 2, 4], &[1, 4]));
    let mut summary = Summary::default();
    summary.add(&a, None);
    summary.add(&b, Some(&a));
    // Found in a and asked in b: 1 and 2; found again: 1.
    assert_eq!((summary.carried, summary.carried_found), (2, 1));
    assert_eq!(summary.frame_to_frame(), 0.5);
    assert_eq!(summary.repeatability(), 5.0 / 6.0);
    assert_eq!(summary.unmatched_share(), 0.25);
    assert_eq!(summary.distance_quantile(0.5), 0.5);
    assert_eq!(summary.distance_quantile(0.9), 1.5);
}
