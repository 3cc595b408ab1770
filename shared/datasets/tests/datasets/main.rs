//! Loading the real EuRoC excerpt and KITTI raw drive (`real_data_*`), rectification, the
//! read-ahead stream, and small hand-made EuRoC, KITTI, KITTI raw and TUM fixtures, good
//! and malformed.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_datasets::{Next, StereoSequence};
use linetrack_geometry::MatchCase;
use linetrack_test_data::Scratch;
use linetrack_vision::{
    AppearanceGates, GrayImage, OrbExtractor, OrbOptions, PointFeatures, PointMatcher,
};
use nalgebra::{Isometry3, Vector3};
use std::path::{Path, PathBuf};
use std::time::Duration;

mod euroc;
mod kitti;
mod kitti_raw;
mod middlebury;

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
    // Bound here, not a temporary: the reading thread reads from it after `open`.
    let fixture = euroc_fixture("next-within");
    let sequence = StereoSequence::open(&fixture).unwrap();
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

/// `wait_primed` says yes only once the frames read ahead fill the queue, or the reading is
/// over: a frame is then there without waiting.
#[test]
fn the_stream_is_primed_once_its_queue_is_full_or_the_reading_is_over() {
    let fixture = euroc_fixture("primed");
    // Three frames, one read ahead: primed when the second is read and the queue is full.
    let (release, held) = crossbeam_channel::bounded::<()>(0);
    let mut stream = StereoSequence::open(&fixture)
        .unwrap()
        .into_stream_with(0, 1, move || {
            let _ = held.recv();
        });
    assert!(
        !stream.wait_primed(Duration::from_millis(1)),
        "held before its first read"
    );
    release.send(()).unwrap();
    // Long enough for a loaded machine: the test waits for the reader, never for time.
    assert!(stream.wait_primed(Duration::from_secs(60)));
    assert!(stream.wait_primed(Duration::ZERO), "primed stays primed");
    assert!(matches!(stream.next_within(Duration::ZERO), Next::Frame(Ok(f)) if f.index == 0));

    // Three frames, four read ahead: the queue never fills, the end of the reading primes it.
    let mut stream = StereoSequence::open(&fixture).unwrap().into_stream(0, 4);
    assert!(stream.wait_primed(Duration::from_secs(60)));
    for index in 0..3 {
        assert!(
            matches!(stream.next_within(Duration::ZERO), Next::Frame(Ok(f)) if f.index == index)
        );
    }
    assert!(matches!(stream.next_within(Duration::ZERO), Next::End));
}

/// A paced stream's reader, once primed, reads a frame more only when let.
#[test]
fn a_paced_stream_reads_past_its_full_queue_only_when_let() {
    let fixture = euroc_fixture("paced");
    let mut stream = StereoSequence::open(&fixture)
        .unwrap()
        .into_paced_stream(0, 1, || {});
    // Long enough for a loaded machine: the test waits for the reader, never for time.
    let patience = Duration::from_secs(60);
    assert!(stream.wait_primed(patience));
    // Frame 0 queued, frame 1 read and held: both come without leave.
    for index in 0..2 {
        assert!(matches!(stream.next_within(patience), Next::Frame(Ok(f)) if f.index == index));
    }
    // Frame 2 is not read until let (however long this waits, it cannot come).
    assert!(matches!(
        stream.next_within(Duration::from_millis(20)),
        Next::NotYet
    ));
    stream.let_read();
    assert!(matches!(stream.next_within(patience), Next::Frame(Ok(f)) if f.index == 2));
    assert!(matches!(stream.next_within(patience), Next::End));
}

/// A paced stream dropped while its reader waits for leave ends that reader: the drop,
/// which joins it, returns.
#[test]
fn a_paced_stream_dropped_while_its_reader_waits_ends_it() {
    let fixture = euroc_fixture("paced-drop");
    let mut stream = StereoSequence::open(&fixture)
        .unwrap()
        .into_paced_stream(0, 1, || {});
    // Long enough for a loaded machine: the test waits for the reader, never for time.
    let patience = Duration::from_secs(60);
    assert!(stream.wait_primed(patience));
    // Two frames taken: the reader now waits for leave to read the third.
    for _ in 0..2 {
        assert!(matches!(stream.next_within(patience), Next::Frame(Ok(_))));
    }
    let (done, dropped) = crossbeam_channel::bounded(1);
    std::thread::spawn(move || {
        drop(stream);
        let _ = done.send(());
    });
    assert!(
        dropped.recv_timeout(patience).is_ok(),
        "the drop did not return"
    );
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
fn euroc_fixture(name: &str) -> Scratch {
    let dir = Scratch::new("datasets", name);
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
