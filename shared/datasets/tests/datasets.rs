//! Loading the real EuRoC excerpt and KITTI raw drive (`real_data_*`), rectification, the
//! read-ahead stream, and small hand-made EuRoC, KITTI, KITTI raw and TUM fixtures, good
//! and malformed.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_datasets::{Next, StereoSequence};
use linetrack_geometry::MatchCase;
use linetrack_vision::{
    AppearanceGates, GrayImage, OrbExtractor, OrbOptions, PointFeatures, PointMatcher,
};
use nalgebra::{Isometry3, Vector3};
use std::path::{Path, PathBuf};
use std::time::Duration;

fn euroc() -> StereoSequence {
    let dir = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
    StereoSequence::open_euroc(&dir).unwrap()
}

// ---------------------------------------------------------------- the real excerpt

#[test]
fn real_data_euroc_excerpt_loads_with_rig_and_ground_truth() {
    let seq = euroc();
    assert_eq!(seq.frames.len(), 95);
    assert_eq!(seq.rate_hz, 20.0);
    assert!(seq.is_rectified_on_load());
    // The rectified EuRoC rig: one focal length near the raw ones, an 11 cm baseline.
    let rig = seq.rig;
    assert_eq!((rig.width_px, rig.height_px), (752, 480));
    assert!((400.0..470.0).contains(&rig.focal_px), "{rig:?}");
    assert!((rig.baseline_m - 0.110).abs() < 0.002, "{rig:?}");
    assert!(
        seq.frames
            .windows(2)
            .all(|w| w[1].timestamp_ns > w[0].timestamp_ns
                && w[1].timestamp_ns - w[0].timestamp_ns < 60_000_000)
    );
    // Ground truth for every frame; the vehicle is almost still (README of the excerpt).
    let poses: Vec<Isometry3<f64>> = seq
        .frames
        .iter()
        .map(|f| f.pose.expect("ground truth"))
        .collect();
    let path: f64 = poses
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum();
    assert!(path < 0.05, "path {path} m");
}

/// |row difference| of ORB stereo matches (rows gated loosely at 20 px so that it is
/// measured, not imposed), sorted.
fn row_differences(left: &GrayImage, right: &GrayImage) -> Vec<f64> {
    let mut orb = OrbExtractor::new(&OrbOptions::default()).unwrap();
    let (mut a, mut b) = (PointFeatures::default(), PointFeatures::default());
    orb.extract(left, &mut a).unwrap();
    orb.extract(right, &mut b).unwrap();
    let gates = AppearanceGates {
        max_row_difference_px: 20.0,
        ..Default::default()
    };
    let mut out = Vec::new();
    PointMatcher::new().match_points(MatchCase::Stereo, &a, &b, &gates, 2.0, &mut out);
    let mut dy: Vec<f64> = out
        .iter()
        .map(|m| (a.points[m.query].y - b.points[m.train].y).abs())
        .collect();
    dy.sort_by(f64::total_cmp);
    dy
}

#[test]
fn real_data_rectified_matches_lie_on_the_same_row() {
    // Measured on frame 0: raw images 85 ORB matches, median |Δrow| 11.9 px; rectified
    // 122 matches, median 0.00 px (the rest are mostly wrong matches the loose gate admits).
    let seq = euroc();
    let frame = seq.load_frame(0).unwrap();
    let rectified = row_differences(&frame.left, &frame.right);
    let raw = row_differences(
        &GrayImage::load(&seq.frames[0].left).unwrap(),
        &GrayImage::load(&seq.frames[0].right).unwrap(),
    );
    let median = |v: &[f64]| v[v.len() / 2];
    let within_1px =
        rectified.iter().filter(|d| **d <= 1.0).count() as f64 / rectified.len() as f64;
    eprintln!(
        "raw: {} matches, median {:.2}; rectified: {} matches, median {:.2}, {:.0}% within 1 px",
        raw.len(),
        median(&raw),
        rectified.len(),
        median(&rectified),
        100.0 * within_1px
    );
    assert!(median(&raw) > 5.0, "the raw pair should be visibly off-row");
    assert!(rectified.len() > raw.len());
    assert!(median(&rectified) <= 0.5);
    assert!(within_1px >= 0.7, "{within_1px}");
}

#[test]
fn real_data_stream_yields_every_frame_in_order_with_read_ahead() {
    let seq = euroc();
    let expected: Vec<u64> = seq.frames.iter().map(|f| f.timestamp_ns).collect();
    let mut stream = seq.into_stream(0, 4);
    assert_eq!(stream.len(), 95);
    let mut seen = Vec::new();
    for frame in stream.by_ref() {
        let frame = frame.unwrap();
        assert_eq!((frame.left.width(), frame.right.height()), (752, 480));
        seen.push(frame.timestamp_ns);
    }
    assert_eq!(seen, expected);
    assert_eq!(stream.skipped(), 0);
}

/// The set-up given to `into_stream_with` runs on the reading thread, before any frame.
#[test]
fn the_reading_threads_set_up_runs_on_it_first() {
    let (sender, receiver) = crossbeam_channel::unbounded();
    let mut stream = euroc().into_stream_with(90, 1, move || {
        let name = std::thread::current().name().map(str::to_string);
        sender.send(name).unwrap();
    });
    assert_eq!(receiver.recv().unwrap().as_deref(), Some("frame-reader"));
    assert_eq!(stream.by_ref().count(), 5);
    assert_eq!(stream.skipped(), 0);
}

/// A reading thread that is behind (held here before its first frame, as a loaded machine
/// starves it) leaves `next_within` free to return: the frame is not there yet, then it is.
#[test]
fn a_frame_the_reader_does_not_have_yet_is_not_waited_for_past_the_wait() {
    let (release, held) = crossbeam_channel::bounded::<()>(0);
    let sequence = StereoSequence::open(&euroc_fixture("next-within")).unwrap();
    let mut stream = sequence.into_stream_with(0, 1, move || {
        let _ = held.recv();
    });
    // The reader cannot have sent anything: it is held before its first read.
    assert!(matches!(
        stream.next_within(Duration::from_millis(1)),
        Next::NotYet
    ));
    release.send(()).unwrap();
    let mut indices = Vec::new();
    loop {
        // Long enough for a loaded machine: the test waits for frames, never for time.
        match stream.next_within(Duration::from_secs(60)) {
            Next::Frame(frame) => indices.push(frame.unwrap().index),
            Next::NotYet => panic!("the reader is not held any more: {indices:?}"),
            Next::End => break,
        }
    }
    assert_eq!(indices, [0, 1, 2]);
    assert!(matches!(stream.next_within(Duration::ZERO), Next::End));
}

// ---------------------------------------------------------------- hand-made EuRoC fixture

const W: usize = 64;
const H: usize = 48;

fn write(path: &Path, text: &str) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
}

fn png(path: &Path, seed: u8) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let pixels: Vec<u8> = (0..W * H)
        .map(|k| ((k % W) as u8).wrapping_mul(3).wrapping_add(seed))
        .collect();
    image::GrayImage::from_raw(W as u32, H as u32, pixels)
        .unwrap()
        .save(path)
        .unwrap();
}

fn sensor_yaml(x_m: f64) -> String {
    format!(
        "%YAML:1.0\nsensor_type: camera\nT_BS:\n  cols: 4\n  rows: 4\n  data: [1.0, 0.0, 0.0, {x_m},\n         0.0, 1.0, 0.0, 0.0,\n         0.0, 0.0, 1.0, 0.0,\n         0.0, 0.0, 0.0, 1.0]\nrate_hz: 20\nresolution: [{W}, {H}]\ncamera_model: pinhole\nintrinsics: [50.0, 50.0, 32.0, 24.0] #fu, fv, cu, cv\ndistortion_model: radial-tangential\ndistortion_coefficients: [0.0, 0.0, 0.0, 0.0]\n"
    )
}

/// A three-frame EuRoC sequence: 10 cm baseline, identity ground truth moving along x.
fn euroc_fixture(name: &str) -> PathBuf {
    let dir = linetrack_test_data::scratch_dir("datasets", name).unwrap();
    let mav0 = dir.join("mav0");
    let stamps = [1_000_000_000u64, 1_050_000_000, 1_100_000_000];
    for (cam, x) in [("cam0", 0.0), ("cam1", 0.1)] {
        write(&mav0.join(cam).join("sensor.yaml"), &sensor_yaml(x));
        let mut csv = String::from("#timestamp [ns],filename\n");
        for (k, t) in stamps.iter().enumerate() {
            csv.push_str(&format!("{t},{t}.png\n"));
            png(
                &mav0.join(cam).join("data").join(format!("{t}.png")),
                k as u8,
            );
        }
        write(&mav0.join(cam).join("data.csv"), &csv);
    }
    let mut gt = String::from("#timestamp,p_x,p_y,p_z,q_w,q_x,q_y,q_z\n");
    for (k, t) in stamps.iter().enumerate() {
        gt.push_str(&format!("{t},{},0,0,1,0,0,0\n", 0.01 * k as f64));
    }
    write(&mav0.join("state_groundtruth_estimate0/data.csv"), &gt);
    dir
}

fn open_error(dir: &Path) -> String {
    StereoSequence::open(dir)
        .expect_err("malformed dataset must be refused")
        .to_string()
}

#[test]
fn euroc_fixture_opens_with_its_calibration_and_ground_truth() {
    let dir = euroc_fixture("good");
    let seq = StereoSequence::open(&dir).unwrap();
    assert_eq!(seq.frames.len(), 3);
    // An ideal rig (no distortion, equal intrinsics, pure x baseline) is used as is.
    assert!(!seq.is_rectified_on_load());
    assert_eq!(
        (seq.rig.focal_px, seq.rig.cx_px, seq.rig.cy_px),
        (50.0, 32.0, 24.0)
    );
    assert!((seq.rig.baseline_m - 0.1).abs() < 1e-12, "{:?}", seq.rig);
    let p = seq.frames[2].pose.unwrap();
    assert!((p.translation.vector - Vector3::new(0.02, 0.0, 0.0)).norm() < 1e-9);
    let frame = seq.load_frame(1).unwrap();
    assert_eq!(
        (frame.left.width(), frame.left.height()),
        (W as i32, H as i32)
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_distorted_fixture_is_rectified_on_load() {
    let dir = euroc_fixture("distorted");
    write(
        &dir.join("mav0/cam1/sensor.yaml"),
        &sensor_yaml(0.1).replace("[0.0, 0.0, 0.0, 0.0]", "[-0.05, 0.01, 0.0, 0.0]"),
    );
    let seq = StereoSequence::open(&dir).unwrap();
    assert!(seq.is_rectified_on_load());
    assert!(
        (seq.rig.baseline_m - 0.1).abs() < 1e-6 && (seq.rig.focal_px - 50.0).abs() < 5.0,
        "{:?}",
        seq.rig
    );
    let frame = seq.load_frame(0).unwrap();
    assert!(
        frame.left.origin().contains("rectified") && frame.right.origin().contains("rectified")
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn malformed_image_lists_name_file_and_line() {
    let cases = [
        (
            "columns",
            "#timestamp [ns],filename\n1000000000\n",
            "data.csv:2",
            "2 columns",
        ),
        (
            "number",
            "#timestamp [ns],filename\n1000000000,a.png\n10x0,b.png\n",
            "data.csv:3",
            "not a whole number",
        ),
        (
            "order",
            "#timestamp [ns],filename\n1100000000,a.png\n1000000000,b.png\n",
            "data.csv:3",
            "does not increase",
        ),
        (
            "empty",
            "#timestamp [ns],filename\n",
            "data.csv",
            "lists no images",
        ),
    ];
    for (name, csv, place, what) in cases {
        let dir = euroc_fixture(name);
        write(&dir.join("mav0/cam0/data.csv"), csv);
        let text = open_error(&dir);
        assert!(
            text.contains(place) && text.contains(what),
            "{name}: {text}"
        );
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn malformed_calibration_and_ground_truth_are_refused() {
    let cases: [(&str, &str, String, &str); 5] = [
        (
            "no-intrinsics",
            "mav0/cam1/sensor.yaml",
            sensor_yaml(0.1).replace("intrinsics", "intrinsix"),
            "sensor.yaml:15: missing field `intrinsics`",
        ),
        (
            "bad-number",
            "mav0/cam1/sensor.yaml",
            sensor_yaml(0.1).replace("50.0, 50.0", "50.0, fifty"),
            "sensor.yaml:13",
        ),
        (
            "not-rigid",
            "mav0/cam0/sensor.yaml",
            sensor_yaml(0.0).replace("data: [1.0", "data: [2.0"),
            "T_BS is not a rigid transform",
        ),
        (
            "same-place",
            "mav0/cam1/sensor.yaml",
            sensor_yaml(0.0),
            "no baseline",
        ),
        (
            "gt-quaternion",
            "mav0/state_groundtruth_estimate0/data.csv",
            "1000000000,0,0,0,2,0,0,0\n".to_string(),
            "data.csv:1: quaternion norm",
        ),
    ];
    for (name, file, text, what) in cases {
        let dir = euroc_fixture(name);
        write(&dir.join(file), &text);
        let message = open_error(&dir);
        assert!(message.contains(what), "{name}: {message}");
        let _ = std::fs::remove_dir_all(dir);
    }
    let missing = linetrack_test_data::scratch_dir("datasets", "not-a-dataset").unwrap();
    assert!(open_error(&missing).contains("expected mav0/"));
}

#[test]
fn missing_and_corrupt_frames_are_skipped_counted_and_named() {
    let dir = euroc_fixture("bad-frames");
    std::fs::remove_file(dir.join("mav0/cam1/data/1000000000.png")).unwrap();
    std::fs::write(dir.join("mav0/cam0/data/1100000000.png"), b"not a png").unwrap();
    let seq = StereoSequence::open(&dir).unwrap();
    let mut stream = seq.into_stream(0, 2);
    let results: Vec<_> = stream.by_ref().collect();
    assert_eq!(results.len(), 3);
    let first = results[0].as_ref().unwrap_err().to_string();
    assert!(
        first.contains("frame 0") && first.contains("cam1/data/1000000000.png"),
        "{first}"
    );
    assert_eq!(results[1].as_ref().unwrap().index, 1);
    let third = results[2].as_ref().unwrap_err().to_string();
    assert!(
        third.contains("cam0/data/1100000000.png") && third.contains("not a decodable image"),
        "{third}"
    );
    assert_eq!(stream.skipped(), 2);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_wrongly_sized_frame_is_skipped_naming_it() {
    let dir = euroc_fixture("wrong-size");
    let path = dir.join("mav0/cam0/data/1050000000.png");
    image::GrayImage::new(32, 24).save(&path).unwrap();
    let seq = StereoSequence::open(&dir).unwrap();
    let error = seq.load_frame(1).unwrap_err().to_string();
    assert!(
        error.contains("1050000000.png") && error.contains("same size"),
        "{error}"
    );
    assert!(seq.load_frame(0).is_ok() && seq.load_frame(2).is_ok());
    let _ = std::fs::remove_dir_all(dir);
}

// ---------------------------------------------------------------- KITTI fixture

fn kitti_fixture(name: &str) -> PathBuf {
    let root = linetrack_test_data::scratch_dir("datasets", name).unwrap();
    let dir = root.join("sequences/07");
    let p0 = "P0: 700 0 600 0 0 700 180 0 0 0 1 0\n";
    let p1 = "P1: 700 0 600 -378 0 700 180 0 0 0 1 0\n";
    write(&dir.join("calib.txt"), &format!("{p0}{p1}"));
    write(&dir.join("times.txt"), "0.0\n0.1\n0.2\n");
    for k in 0..3 {
        png(&dir.join(format!("image_0/{k:06}.png")), k as u8);
        png(&dir.join(format!("image_1/{k:06}.png")), k as u8);
    }
    write(
        &root.join("poses/07.txt"),
        "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0.5\n1 0 0 0 0 1 0 0 0 0 1 1.0\n",
    );
    root
}

#[test]
fn kitti_fixture_opens_with_rig_times_and_poses() {
    let root = kitti_fixture("kitti");
    let seq = StereoSequence::open(&root.join("sequences/07")).unwrap();
    assert_eq!(seq.name, "07");
    assert!(!seq.is_rectified_on_load());
    assert_eq!(seq.frames.len(), 3);
    assert!(
        (seq.rig.baseline_m - 0.54).abs() < 1e-12
            && seq.rig.focal_px == 700.0
            && seq.rig.cy_px == 180.0
    );
    assert_eq!(seq.frames[1].timestamp_ns, 100_000_000);
    assert!((seq.frames[2].pose.unwrap().translation.z - 1.0).abs() < 1e-12);
    assert!((seq.rate_hz - 10.0).abs() < 1e-9);
    let _ = std::fs::remove_dir_all(root);
}

#[test]
fn malformed_kitti_files_are_refused_naming_them() {
    let cases = [
        (
            "sequences/07/calib.txt",
            "P0: 700 0 600 0 0 700 180 0 0 0 1 0\n",
            "missing P1",
        ),
        (
            "sequences/07/calib.txt",
            "P0: 700 0 600 0 0 700 180 0 0 0 1\nP1: 1 2\n",
            "calib.txt:1: P0 has 11 values",
        ),
        (
            "sequences/07/times.txt",
            "0.0\n0.2\n0.1\n",
            "times.txt:3: time 0.1 does not increase",
        ),
        (
            "poses/07.txt",
            "1 0 0 0 0 1 0 0 0 0 1 0\n",
            "1 poses for 3 frames",
        ),
    ];
    for (k, (file, text, what)) in cases.into_iter().enumerate() {
        let root = kitti_fixture(&format!("kitti-bad-{k}"));
        write(&root.join(file), text);
        let message = open_error(&root.join("sequences/07"));
        assert!(message.contains(what), "{file}: {message}");
        let _ = std::fs::remove_dir_all(root);
    }
}

// ---------------------------------------------------------------- KITTI raw

fn kitti_raw() -> StereoSequence {
    let dir = linetrack_test_data::kitti_raw_dir().unwrap_or_else(|e| panic!("{e}"));
    StereoSequence::open(&dir).unwrap()
}

#[test]
fn real_data_kitti_raw_drive_loads_with_rig_times_and_oxts_ground_truth() {
    let seq = kitti_raw();
    assert_eq!(seq.name, "2011_09_26_drive_0001_sync");
    assert_eq!(seq.frames.len(), 108);
    assert!(!seq.is_rectified_on_load());
    let rig = seq.rig;
    assert_eq!((rig.width_px, rig.height_px), (1242, 375));
    assert_eq!(
        (rig.focal_px, rig.cx_px, rig.cy_px),
        (721.5377, 609.5593, 172.854)
    );
    assert!((rig.baseline_m - 0.537).abs() < 0.001, "{rig:?}");
    // 107 intervals of 0.100–0.106 s (README of the drive): 9.69 Hz measured.
    assert!((9.6..10.0).contains(&seq.rate_hz), "{} Hz", seq.rate_hz);
    assert_eq!(seq.frames[0].timestamp_ns, 1_317_042_145_967_790_592);
    assert!(seq.frames.windows(2).all(|w| {
        let dt = w[1].timestamp_ns - w[0].timestamp_ns;
        (95_000_000..110_000_000).contains(&dt)
    }));
    let poses: Vec<Isometry3<f64>> = seq
        .frames
        .iter()
        .map(|f| f.pose.expect("ground truth"))
        .collect();
    // Frame 0 is the world origin, up to rounding.
    assert!(poses[0].translation.vector.norm() < 1e-12 && poses[0].rotation.angle() < 1e-12);
    let path_m: f64 = poses
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum();
    eprintln!(
        "path {path_m:.2} m, last position {:?}",
        poses[107].translation.vector.as_slice()
    );
    assert!((105.0..109.0).contains(&path_m), "path {path_m} m");
    // The car drives forward: the camera's +z.
    assert!(poses[107].translation.z > 100.0, "{}", poses[107]);
    let frame = seq.load_frame(107).unwrap();
    assert_eq!((frame.left.width(), frame.right.height()), (1242, 375));
}

#[test]
fn real_data_kitti_raw_oxts_conversion_agrees_with_the_independent_one() {
    let seq = kitti_raw();
    let dir = linetrack_test_data::kitti_raw_dir().unwrap();
    let reference =
        linetrack_datasets::read_kitti_poses(&dir.join("poses_cam0_rect_from_oxts.txt")).unwrap();
    assert_eq!(reference.len(), seq.frames.len());
    // The reference is at the OXTS fixes' instants; the loader gives the poses at the
    // cameras'. Interpolated here on the reference (position linearly, rotation by slerp),
    // for the frames whose time lies between two fixes, and taken relative to frame 0.
    let clock = |path: &str| -> Vec<f64> {
        std::fs::read_to_string(dir.join(path))
            .unwrap()
            .lines()
            .map(|line| {
                let clock = line.split(' ').nth(1).unwrap();
                let [h, m, s]: [f64; 3] = clock
                    .split(':')
                    .map(|v| v.parse::<f64>().unwrap())
                    .collect::<Vec<_>>()
                    .try_into()
                    .unwrap();
                (h * 60.0 + m) * 60.0 + s
            })
            .collect()
    };
    let (fixes, cameras) = (
        clock("oxts/timestamps.txt"),
        clock("image_00/timestamps.txt"),
    );
    let at = |t: f64| {
        let k = fixes.iter().rposition(|f| *f <= t)?;
        let s = (t - fixes[k]) / (fixes.get(k + 1)? - fixes[k]);
        let (a, b) = (&reference[k], &reference[k + 1]);
        Some(nalgebra::Isometry3::from_parts(
            a.translation.vector.lerp(&b.translation.vector, s).into(),
            a.rotation.slerp(&b.rotation, s),
        ))
    };
    let origin = at(cameras[0]).unwrap_or(reference[0]).inverse();
    let (mut translation_m, mut rotation_deg, mut compared) = (0.0f64, 0.0f64, 0);
    for (frame, t) in seq.frames.iter().zip(&cameras).skip(1) {
        let Some(expected) = at(*t).map(|p| origin * p) else {
            continue;
        };
        let pose = frame.pose.unwrap();
        translation_m =
            translation_m.max((pose.translation.vector - expected.translation.vector).norm());
        rotation_deg = rotation_deg.max(pose.rotation.angle_to(&expected.rotation).to_degrees());
        compared += 1;
    }
    eprintln!(
        "OXTS conversion vs poses_cam0_rect_from_oxts.txt at the camera times, {compared} \
         frames: max {:.4} mm, {:.2e}°",
        translation_m * 1e3,
        rotation_deg
    );
    assert!(compared > 100, "{compared} frames between two fixes");
    // The reference is printed with 10 significant digits (1e-8 m at 107 m) and both are
    // computed in f64 from the same inputs; a millimetre and a thousandth of a degree are
    // far below the OXTS unit's own accuracy (2.7 cm) yet would catch any wrong recipe
    // step (a swapped axis, the latitude scale of each frame instead of the first, a pose
    // taken at the fix's instant instead of the camera's: up to 5 ms, 5 cm here).
    assert!(translation_m < 1e-3, "{translation_m} m");
    assert!(rotation_deg < 1e-3, "{rotation_deg}°");
}

const RAW_DRIVE: &str = "2011_09_26_drive_0001_sync";

fn oxts_line(lon_deg: f64) -> String {
    let mut values = vec![49.0, lon_deg, 100.0, 0.0, 0.0, 0.0];
    values.resize(30, 0.0);
    let text: Vec<String> = values.iter().map(f64::to_string).collect();
    text.join(" ") + "\n"
}

/// A three-frame KITTI raw drive under `<scratch>/2011_09_26/`: identity rotations, the
/// IMU at the camera, the car moving east (its x) by 1e-5° of longitude a frame.
fn kitti_raw_fixture(name: &str) -> PathBuf {
    let date = linetrack_test_data::scratch_dir("datasets", name)
        .unwrap()
        .join("2011_09_26");
    let identity = "1 0 0 0 1 0 0 0 1";
    write(
        &date.join("calib_cam_to_cam.txt"),
        &format!(
            "calib_time: 09-Jan-2012 13:57:47\nR_rect_00: {identity}\nP_rect_00: 700 0 600 0 0 700 180 0 0 0 1 0\nP_rect_01: 700 0 600 -378 0 700 180 0 0 0 1 0\n"
        ),
    );
    for file in ["calib_imu_to_velo.txt", "calib_velo_to_cam.txt"] {
        write(
            &date.join(file),
            &format!("calib_time: 25-May-2012 16:47:16\nR: {identity}\nT: 0 0 0\n"),
        );
    }
    let drive = date.join(RAW_DRIVE);
    let stamps = "2011-09-26 13:02:25.9\n2011-09-26 13:02:26.000000001\n2011-09-26 13:02:26.1\n";
    for camera in ["image_00", "image_01"] {
        write(&drive.join(camera).join("timestamps.txt"), stamps);
        for k in 0..3 {
            png(
                &drive.join(camera).join(format!("data/{k:010}.png")),
                k as u8,
            );
        }
    }
    for k in 0..3 {
        write(
            &drive.join(format!("oxts/data/{k:010}.txt")),
            &oxts_line(8.0 + 1e-5 * k as f64),
        );
    }
    drive
}

#[test]
fn kitti_raw_fixture_opens_with_rig_times_and_oxts_poses() {
    let drive = kitti_raw_fixture("kitti-raw");
    let seq = StereoSequence::open(&drive).unwrap();
    assert_eq!(seq.name, RAW_DRIVE);
    assert_eq!(seq.frames.len(), 3);
    assert!((seq.rig.baseline_m - 0.54).abs() < 1e-12 && seq.rig.focal_px == 700.0);
    assert_eq!((seq.rig.width_px, seq.rig.height_px), (W as u32, H as u32));
    assert_eq!(
        seq.frames[1].timestamp_ns - seq.frames[0].timestamp_ns,
        100_000_001
    );
    assert!((seq.rate_hz - 10.0).abs() < 1e-9);
    assert!(seq.frames[2].left.ends_with("image_00/data/0000000002.png"));
    // Mercator x at the first latitude's scale: cos 49° · 1e-5° · π/180 · 6378137 m.
    let step_m = 49f64.to_radians().cos() * 1e-5f64.to_radians() * 6_378_137.0;
    let pose = seq.frames[2].pose.unwrap();
    assert!(
        (pose.translation.vector - Vector3::new(2.0 * step_m, 0.0, 0.0)).norm() < 1e-6,
        "{pose}"
    );
    assert!(pose.rotation.angle() < 1e-12);

    // Without oxts/ there is no ground truth.
    std::fs::remove_dir_all(drive.join("oxts")).unwrap();
    let seq = StereoSequence::open_kitti_raw(&drive).unwrap();
    assert!(seq.frames.iter().all(|f| f.pose.is_none()));
    let _ = std::fs::remove_dir_all(drive.parent().unwrap().parent().unwrap());
}

#[test]
fn malformed_kitti_raw_files_are_refused_naming_them() {
    let oxts_1 = format!("{RAW_DRIVE}/oxts/data/0000000001.txt");
    let cases = [
        (
            "calib_cam_to_cam.txt".to_string(),
            "R_rect_00: 1 0 0 0 1 0 0 0 1\nP_rect_00: 700 0 600 0 0 700 180 0 0 0 1\n".to_string(),
            "calib_cam_to_cam.txt:2: P_rect_00 has 11 values, expected 12",
        ),
        (
            "calib_cam_to_cam.txt".to_string(),
            "R_rect_00: 1 0 0 0 1 0 0 0 1\nP_rect_00: 700 0 600 0 0 700 180 0 0 0 1 0\n"
                .to_string(),
            "calib_cam_to_cam.txt:0: missing P_rect_01",
        ),
        (
            "calib_velo_to_cam.txt".to_string(),
            "R: 1 0 0 0 1 0 0 0 1\nT: 0 NaN 0\n".to_string(),
            "calib_velo_to_cam.txt:2: not a finite number: \"NaN\"",
        ),
        (
            "calib_imu_to_velo.txt".to_string(),
            "R: 1 0 0 0 2 0 0 0 1\nT: 0 0 0\n".to_string(),
            "calib_imu_to_velo.txt:0: R is not a rotation",
        ),
        (
            format!("{RAW_DRIVE}/image_00/timestamps.txt"),
            "2011-09-26 13:02:25.9\n2011-09-26 13:02:2x.0\n2011-09-26 13:02:26.1\n".to_string(),
            "image_00/timestamps.txt:2: not a time",
        ),
        (
            format!("{RAW_DRIVE}/image_00/timestamps.txt"),
            "2011-09-26 13:02:25.9\n2011-09-26 13:02:25.8\n2011-09-26 13:02:26.1\n".to_string(),
            "image_00/timestamps.txt:2: time 2011-09-26 13:02:25.8 does not increase",
        ),
        (
            format!("{RAW_DRIVE}/image_01/timestamps.txt"),
            "2011-09-26 13:02:25.9\n2011-09-26 13:02:26.0\n".to_string(),
            "image_01/timestamps.txt:0: 2 timestamps for 3",
        ),
        (
            oxts_1.clone(),
            "49 8 100\n".to_string(),
            "0000000001.txt:1: 3 values, expected 30",
        ),
        (
            oxts_1,
            oxts_line(8.0).replacen("49", "95", 1),
            "0000000001.txt:1: latitude 95° out of range",
        ),
    ];
    for (k, (file, text, what)) in cases.into_iter().enumerate() {
        let drive = kitti_raw_fixture(&format!("kitti-raw-bad-{k}"));
        write(&drive.parent().unwrap().join(&file), &text);
        let message = open_error(&drive);
        assert!(message.contains(what), "{file}: {message}");
        let _ = std::fs::remove_dir_all(drive.parent().unwrap().parent().unwrap());
    }

    // A frame's image or OXTS file gone: the counts disagree, naming the folder.
    for (k, (file, what)) in [
        (
            "image_01/data/0000000001.png",
            "image_01/data:0: 2 .png files for 3 frames",
        ),
        (
            "oxts/data/0000000002.txt",
            "oxts/data:0: 2 .txt files for 3 frames",
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let drive = kitti_raw_fixture(&format!("kitti-raw-missing-{k}"));
        std::fs::remove_file(drive.join(file)).unwrap();
        let message = open_error(&drive);
        assert!(message.contains(what), "{file}: {message}");
        let _ = std::fs::remove_dir_all(drive.parent().unwrap().parent().unwrap());
    }
}

// ---------------------------------------------------------------- Middlebury

#[test]
fn real_data_middlebury_scenes_are_selected_by_name_and_an_unknown_one_is_named() {
    let dir = linetrack_test_data::middlebury_dir().unwrap();
    let names = ["Venus".to_string(), "Cones".to_string()];
    let pairs = linetrack_datasets::select_middlebury(&dir, &names).unwrap();
    let found: Vec<&str> = pairs.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(found, ["Cones", "Venus"]);
    assert_eq!(
        linetrack_datasets::select_middlebury(&dir, &[])
            .unwrap()
            .len(),
        28
    );
    let error = linetrack_datasets::select_middlebury(&dir, &["Atlantis".to_string()])
        .unwrap_err()
        .to_string();
    assert!(error.contains("\"Atlantis\""), "{error}");
    assert!(error.contains(dir.to_str().unwrap()), "{error}");
}

#[test]
fn real_data_middlebury_lists_every_pair_with_its_disparity_scale() {
    let dir = linetrack_test_data::middlebury_dir().unwrap();
    let pairs = linetrack_datasets::list_middlebury(&dir).unwrap();
    assert_eq!(pairs.len(), 28);
    let scale = |name: &str| pairs.iter().find(|p| p.name == name).unwrap().scale;
    assert_eq!(
        (
            scale("Tsukuba"),
            scale("Venus"),
            scale("Cones"),
            scale("Baby1")
        ),
        (16.0, 8.0, 4.0, 3.0)
    );
    let tsukuba = pairs
        .iter()
        .find(|p| p.name == "Tsukuba")
        .unwrap()
        .load()
        .unwrap();
    assert_eq!((tsukuba.left.width(), tsukuba.left.height()), (384, 288));
    assert_eq!(
        (tsukuba.disparity.width(), tsukuba.disparity.height()),
        (384, 288)
    );
    // Tsukuba's disparities are 5–14 px; the centre of the lamp is in the front.
    let known: Vec<f64> = (0..288)
        .flat_map(|y| (0..384).map(move |x| (x, y)))
        .filter_map(|(x, y)| tsukuba.disparity.at(f64::from(x), f64::from(y)))
        .collect();
    let (low, high) = known
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &d| (a.min(d), b.max(d)));
    assert!(
        (4.0..=6.0).contains(&low) && (13.0..=15.0).contains(&high),
        "{low} {high}"
    );
    assert!(tsukuba.disparity.coverage() > 0.75);
}

/// A third-size 2005/2006 scene folder with a disparity map `disp1.png` of `map_size`.
fn middlebury_fixture(name: &str, map_size: (u32, u32)) -> PathBuf {
    let dir = linetrack_test_data::scratch_dir("datasets", name).unwrap();
    let scene = dir.join("Scene");
    let colour = image::RgbImage::from_fn(420, 30, |x, y| image::Rgb([x as u8, y as u8, 9]));
    std::fs::create_dir_all(&scene).unwrap();
    colour.save(scene.join("view1.png")).unwrap();
    colour.save(scene.join("view5.png")).unwrap();
    let map = image::GrayImage::from_fn(map_size.0, map_size.1, |x, _| {
        image::Luma([(x % 4) as u8 * 30])
    });
    map.save(scene.join("disp1.png")).unwrap();
    dir
}

#[test]
fn a_middlebury_fixture_loads_grey_with_unknown_disparities() {
    let dir = middlebury_fixture("middlebury-good", (420, 30));
    let pairs = linetrack_datasets::list_middlebury(&dir).unwrap();
    assert_eq!(pairs.len(), 1);
    let pair = pairs[0].load().unwrap();
    assert_eq!((pair.left.width(), pair.left.height()), (420, 30));
    // Value 0 (x % 4 == 0) is unknown, not d = 0; 30 / 3 = 10 px.
    assert_eq!(pair.disparity.at(0.0, 0.0), None);
    assert_eq!(pair.disparity.at(1.0, 0.0), Some(10.0));
    assert_eq!(pair.disparity.at(2.0, 5.0), Some(20.0));
}

#[test]
fn malformed_middlebury_folders_are_refused_naming_the_file() {
    let wrong_size = middlebury_fixture("middlebury-size", (400, 30));
    let error = linetrack_datasets::list_middlebury(&wrong_size).unwrap()[0]
        .load()
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("disp1.png") && error.contains("400×30"),
        "{error}"
    );

    let corrupt = middlebury_fixture("middlebury-corrupt", (420, 30));
    std::fs::write(corrupt.join("Scene/disp1.png"), b"\x89PNG not really").unwrap();
    let error = linetrack_datasets::list_middlebury(&corrupt).unwrap()[0]
        .load()
        .unwrap_err()
        .to_string();
    assert!(error.contains("disp1.png"), "{error}");

    let empty = linetrack_test_data::scratch_dir("datasets", "middlebury-empty").unwrap();
    let error = linetrack_datasets::list_middlebury(&empty)
        .unwrap_err()
        .to_string();
    assert!(error.contains("no Middlebury pair"), "{error}");
    let missing = linetrack_datasets::list_middlebury(Path::new("/nonexistent/middlebury"))
        .unwrap_err()
        .to_string();
    assert!(missing.contains("/nonexistent/middlebury"), "{missing}");
}
