//! Ground-truth consistency of rendered sequences (depth maps, poses and scene agree to
//! sub-pixel accuracy across cameras and frames), determinism by seed, the illumination
//! model, and that a line detector finds the rendered edges.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_geometry::{Segment, SegmentFeatures, StereoRig, direction_angle};
use linetrack_scene_render::{
    IlluminationConfig, Preset, RenderedFrame, Scene, SequenceConfig, SequenceRenderer, View,
};
use linetrack_vision::{DetectorKind, FrontendConfig, GrayImage, create_detector};
use nalgebra::{Isometry3, Point3, Vector3};

/// Half the EuRoC-like rig, to keep the tests quick.
fn small_rig() -> StereoRig {
    StereoRig {
        focal_px: 229.0,
        cx_px: 188.0,
        cy_px: 120.0,
        baseline_m: 0.11,
        width_px: 376,
        height_px: 240,
    }
}

fn renderer(preset: Preset, seed: u64) -> SequenceRenderer {
    SequenceRenderer::new(SequenceConfig {
        rig: small_rig(),
        ..preset.config(seed, 40)
    })
}

fn backproject(rig: &StereoRig, u: usize, v: usize, depth: f64) -> Point3<f64> {
    Point3::new(
        (u as f64 - rig.cx_px) / rig.focal_px * depth,
        (v as f64 - rig.cy_px) / rig.focal_px * depth,
        depth,
    )
}

fn project(rig: &StereoRig, p: &Point3<f64>) -> Option<(f64, f64)> {
    (p.z > 0.05).then(|| {
        (
            rig.focal_px * p.x / p.z + rig.cx_px,
            rig.focal_px * p.y / p.z + rig.cy_px,
        )
    })
}

/// Distance from `p` to the nearest scene rectangle (plane distance, inside its bounds).
fn distance_to_scene(scene: &Scene, p: &Point3<f64>) -> f64 {
    scene
        .quads
        .iter()
        .filter_map(|q| {
            let rel = p - q.origin;
            let (s, t) = (
                rel.dot(&q.u) / q.u.norm_squared(),
                rel.dot(&q.v) / q.v.norm_squared(),
            );
            let inside = (-1e-6..=1.0 + 1e-6).contains(&s) && (-1e-6..=1.0 + 1e-6).contains(&t);
            inside.then(|| rel.dot(&q.normal()).abs())
        })
        .fold(f64::INFINITY, f64::min)
}

/// Checks pixels of `from` (every 7th) against `to`: the depth of `from` puts the point on
/// a scene surface; where `to` sees the same surface, `to`'s depth at the nearest pixel,
/// back-projected and projected into `from`, lands within 1 px of the start. Returns
/// (points checked, points visible in `to`).
fn check_pair(
    scene: &Scene,
    rig: &StereoRig,
    from: (&View, Isometry3<f64>),
    to: (&View, Isometry3<f64>),
) -> (usize, usize) {
    let (view_a, pose_a) = from;
    let (view_b, pose_b) = to;
    let (mut checked, mut visible) = (0, 0);
    for v in (3..view_a.height - 3).step_by(7) {
        for u in (3..view_a.width - 3).step_by(7) {
            let Some(depth) = view_a.depth_at(u, v) else {
                continue;
            };
            let world = pose_a * backproject(rig, u, v, f64::from(depth));
            // f32 depth: 1e-6 relative ≈ well under a millimetre.
            assert!(
                distance_to_scene(scene, &world) < 1e-3 + 1e-6 * f64::from(depth),
                "pixel ({u}, {v}) depth {depth} is off every surface"
            );
            checked += 1;
            let in_b = pose_b.inverse() * world;
            let Some((ub, vb)) = project(rig, &in_b) else {
                continue;
            };
            let (qu, qv) = (ub.round(), vb.round());
            if qu < 0.0 || qv < 0.0 || qu >= view_b.width as f64 || qv >= view_b.height as f64 {
                continue;
            }
            let Some(depth_b) = view_b.depth_at(qu as usize, qv as usize) else {
                continue;
            };
            // Occluded in `to` (something nearer by more than the pixel's depth spread).
            if f64::from(depth_b) < in_b.z * 0.97 {
                continue;
            }
            let back = pose_a.inverse()
                * (pose_b * backproject(rig, qu as usize, qv as usize, f64::from(depth_b)));
            let (ua, va) = project(rig, &back).unwrap();
            // Rounding to the nearest pixel in `to` moves at most √2/2 px there; the
            // warp between the views can stretch that a little.
            let error = ((ua - u as f64).powi(2) + (va - v as f64).powi(2)).sqrt();
            if error < 2.0 {
                visible += 1;
                assert!(
                    error < 1.0,
                    "pixel ({u}, {v}) comes back at ({ua:.2}, {va:.2}): {error:.2} px"
                );
            }
        }
    }
    (checked, visible)
}

#[test]
fn depth_maps_poses_and_scene_agree_across_cameras_and_frames() {
    let r = renderer(Preset::Normal, 5);
    let rig = small_rig();
    let (a, b): (RenderedFrame, RenderedFrame) = (r.render(10), r.render(14));
    let right_a = r.right_pose(&a.world_from_left);
    for (name, from, to) in [
        (
            "left → right",
            (&a.left, a.world_from_left),
            (&a.right, right_a),
        ),
        (
            "right → left",
            (&a.right, right_a),
            (&a.left, a.world_from_left),
        ),
        (
            "frame 10 → 14",
            (&a.left, a.world_from_left),
            (&b.left, b.world_from_left),
        ),
    ] {
        let (checked, visible) = check_pair(&r.scene, &rig, from, to);
        assert!(checked > 1000, "{name}: {checked}");
        assert!(
            visible as f64 > 0.7 * checked as f64,
            "{name}: only {visible} of {checked} found again"
        );
    }
}

#[test]
fn same_seed_same_bytes_other_seed_other_bytes() {
    let (a, b) = (
        renderer(Preset::DroneGainJumps, 3),
        renderer(Preset::DroneGainJumps, 3),
    );
    assert_eq!(a.render(45), b.render(45));
    assert_ne!(
        a.render(45).left.pixels,
        renderer(Preset::DroneGainJumps, 4).render(45).left.pixels
    );
}

#[test]
fn the_camera_moves_smoothly_and_stays_in_the_room() {
    for preset in [Preset::Normal, Preset::DroneGainJumps] {
        let r = renderer(preset, 9);
        let room = r.scene.room_m;
        let poses: Vec<Isometry3<f64>> = (0..200).map(|k| r.render_pose(k)).collect();
        for w in poses.windows(2) {
            let step = (w[1].translation.vector - w[0].translation.vector).norm();
            assert!(step < 0.1, "{step} m in one frame");
            assert!(w[0].rotation.angle_to(&w[1].rotation) < 0.1);
        }
        for p in &poses {
            let t = p.translation.vector;
            assert!(
                t.x > 1.0
                    && t.x < room.x - 1.0
                    && t.y > 1.0
                    && t.y < room.y - 1.0
                    && t.z > 1.0
                    && t.z < 2.0,
                "{t:?}"
            );
        }
    }
}

#[test]
fn illumination_effects_follow_their_definitions() {
    let jumps = IlluminationConfig {
        seed: 2,
        gain_jump_period_s: Some(2.0),
        ..Default::default()
    };
    let first = jumps.at(1.9, 2);
    assert_eq!(
        (first.gain, first.bias),
        ([1.0, 1.0], [0.0, 0.0]),
        "the first period is unperturbed"
    );
    let mut distinct = std::collections::HashSet::new();
    for k in 1..50 {
        let il = jumps.at(2.0 * k as f64 + 0.5, 2);
        assert!(
            (0.5..2.5).contains(&il.gain[0])
                && (0.0..20.0).contains(&il.bias[0])
                && il.gain[0] == il.gain[1]
        );
        assert_eq!(
            il,
            jumps.at(2.0 * k as f64 + 1.5, 2),
            "constant within a period"
        );
        distinct.insert(il.gain[0].to_bits());
    }
    assert!(distinct.len() > 40);
    let mismatch = IlluminationConfig {
        right_mismatch: Some((0.5, 15.0)),
        ..Default::default()
    }
    .at(3.0, 2);
    assert_eq!((mismatch.gain, mismatch.bias), ([1.0, 0.5], [0.0, 15.0]));
    let flicker = IlluminationConfig {
        flicker: Some((5.0, 0.5)),
        ..Default::default()
    };
    assert!(
        (flicker.at(0.05, 2).gain[0] - 1.5).abs() < 1e-12,
        "peak of a 5 Hz sine at 50 ms"
    );
    let lights = IlluminationConfig {
        light_switch_period_s: Some(1.0),
        seed: 4,
        ..Default::default()
    };
    let levels: Vec<f32> = (0..40)
        .flat_map(|k| lights.at(k as f64 + 0.5, 2).lights)
        .collect();
    assert!(
        levels.iter().all(|l| *l == 1.0 || *l == 0.25)
            && levels.contains(&0.25)
            && levels.contains(&1.0)
    );
}

#[test]
fn over_exposure_saturates_and_a_right_mismatch_darkens_the_right_image() {
    let mean = |p: &[u8]| p.iter().map(|v| f64::from(*v)).sum::<f64>() / p.len() as f64;
    let saturated = |p: &[u8]| p.iter().filter(|v| **v == 255).count() as f64 / p.len() as f64;
    let normal = renderer(Preset::Normal, 6).render(5);
    let hdr = renderer(Preset::HdrSaturation, 6).render(5);
    // Measured on this frame: 11.0 % saturated in normal light (the window), 19.1 % at 2.2×.
    let (s_normal, s_hdr) = (saturated(&normal.left.pixels), saturated(&hdr.left.pixels));
    assert!(
        s_hdr > 1.5 * s_normal && s_hdr > 0.15,
        "normal {s_normal:.3}, hdr {s_hdr:.3}"
    );
    assert!(mean(&hdr.left.pixels) > 1.5 * mean(&normal.left.pixels));
    // Same seed: same scene, motion and noise draws, so the mismatched right image is the
    // normal one × 0.5 + 15 wherever the normal one is not saturated (up to the noise,
    // whose level-dependent part differs).
    let mismatch = renderer(Preset::LeftRightMismatch, 6).render(5);
    assert_eq!(mismatch.left, normal.left);
    let pairs: Vec<(f64, f64)> = normal
        .right
        .pixels
        .iter()
        .zip(&mismatch.right.pixels)
        .filter(|(n, _)| **n < 250)
        .map(|(n, m)| (f64::from(*n), f64::from(*m)))
        .collect();
    let close = pairs
        .iter()
        .filter(|(n, m)| (m - (0.5 * n + 15.0)).abs() <= 4.0)
        .count();
    assert!(
        close as f64 >= 0.95 * pairs.len() as f64,
        "{close} of {}",
        pairs.len()
    );
}

#[test]
fn lsd_finds_the_rendered_edges() {
    let r = SequenceRenderer::new(Preset::Normal.config(8, 40));
    let rig = r.config.rig;
    let frame = r.render(12);
    let image = GrayImage::from_pixels(
        frame.left.width,
        frame.left.height,
        &frame.left.pixels,
        "rendered frame",
    )
    .unwrap();
    let mut detector = create_detector(DetectorKind::Lsd, &FrontendConfig::default()).unwrap();
    let mut detected = Vec::new();
    detector.detect(&image, &mut detected).unwrap();
    // The scene's 3-D segments projected into the left camera (clipped at the near plane).
    let camera_from_world = frame.world_from_left.inverse();
    let truth: Vec<SegmentFeatures> = r
        .scene
        .segments()
        .iter()
        .filter_map(|[a, b]| {
            let (mut a, mut b) = (camera_from_world * a, camera_from_world * b);
            if a.z < 0.1 && b.z < 0.1 {
                return None;
            }
            let cut = |p: Point3<f64>, q: Point3<f64>| p + (q - p) * ((0.1 - p.z) / (q.z - p.z));
            if a.z < 0.1 {
                a = cut(a, b);
            } else if b.z < 0.1 {
                b = cut(b, a);
            }
            let (pa, pb) = (project(&rig, &a)?, project(&rig, &b)?);
            SegmentFeatures::new(&Segment::from_coords(pa.0, pa.1, pb.0, pb.1)).ok()
        })
        .collect();
    let on_truth = |s: &Segment| {
        let f = SegmentFeatures::new(s).unwrap();
        truth.iter().any(|t| {
            let distance = |p: Vector3<f64>| {
                linetrack_geometry::cross(
                    &t.dir,
                    &(nalgebra::Vector2::new(p.x, p.y) - t.mid.coords),
                )
                .abs()
            };
            direction_angle(t, &f).to_degrees() < 3.0
                && distance(Vector3::new(s.start.x, s.start.y, 0.0)) < 2.5
                && distance(Vector3::new(s.end.x, s.end.y, 0.0)) < 2.5
        })
    };
    let long: Vec<&Segment> = detected.iter().filter(|s| s.length() > 30.0).collect();
    let explained = long.iter().filter(|s| on_truth(s)).count();
    eprintln!(
        "{explained} of {} long LSD segments lie on a projected 3-D segment",
        long.len()
    );
    // Measured on this frame: 37 long segments, all 37 on a projected 3-D segment.
    assert!(long.len() >= 25, "{} long segments", long.len());
    assert!(
        explained as f64 >= 0.9 * long.len() as f64,
        "{explained} of {}",
        long.len()
    );
}

#[test]
fn the_highway_car_drives_a_metre_a_frame_through_a_curve_with_far_structure() {
    for seed in 1..=3 {
        let r = SequenceRenderer::new(Preset::Highway.config(seed, 200));
        assert_eq!((r.config.rig.width_px, r.config.rig.height_px), (1241, 376));
        let poses: Vec<Isometry3<f64>> = (0..200).map(|k| r.render_pose(k)).collect();
        for w in poses.windows(2) {
            let step = (w[1].translation.vector - w[0].translation.vector).norm();
            assert!(
                (0.98..1.02).contains(&step),
                "seed {seed}: {step} m in one frame"
            );
        }
        for p in &poses {
            let height = p.translation.z;
            assert!(
                (1.6..1.7).contains(&height),
                "seed {seed}: camera {height} m up"
            );
        }
        // The curve turns the car by 11–38° (a 150–300 m radius over 60–100 m).
        let turned = poses[0]
            .rotation
            .angle_to(&poses[199].rotation)
            .to_degrees();
        assert!(
            (10.0..40.0).contains(&turned),
            "seed {seed}: turned {turned}°"
        );
        // Above the horizon: sky (no depth) and structure, most of it beyond 30 m.
        let frame = r.render(100);
        let (width, horizon) = (frame.left.width, r.config.rig.cy_px as usize);
        let above: Vec<f32> = frame.left.depth_m[..width * horizon].to_vec();
        let sky = above.iter().filter(|z| **z == 0.0).count();
        let far = above.iter().filter(|z| **z > 30.0).count();
        let seen = above.len() - sky;
        assert!(
            sky > above.len() / 4,
            "seed {seed}: {sky} sky pixels of {}",
            above.len()
        );
        assert!(far * 2 > seen, "seed {seed}: {far} of {seen} beyond 30 m");
    }
}
