//! Runs the real `linetrack-synth` binary and reads its output back with the dataset
//! loader: same frames, exact rig, poses and depth as rendered, illumination as asked,
//! byte-identical on a second run with the same seed; bad options fail clearly.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_datasets::StereoSequence;
use linetrack_datasets::depth::read_depth_png;
use linetrack_scene_render::{Preset, SequenceRenderer};
use linetrack_test_data::Scratch;
use std::process::{Command, Output};

fn synth(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_linetrack-synth"))
        .args(args)
        .output()
        .expect("the binary starts")
}

#[test]
fn a_generated_sequence_loads_back_with_its_exact_ground_truth() {
    let out = Scratch::new("synth", "mismatch");
    let result = synth(&[
        "--preset",
        "left-right-mismatch",
        "--seed",
        "4",
        "--frames",
        "3",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    assert!(
        String::from_utf8_lossy(&result.stdout)
            .contains("wrote 3 stereo frames (left-right-mismatch, seed 4)")
    );
    // stderr is a pipe here: plain progress lines, the last one at the end.
    let progress = String::from_utf8_lossy(&result.stderr);
    assert!(
        progress.contains("rendering left-right-mismatch frames: 3/3 (100 %)"),
        "progress is reported: {progress}"
    );

    let renderer = SequenceRenderer::new(Preset::LeftRightMismatch.config(4, 3));
    let seq = StereoSequence::open(&out).unwrap();
    assert_eq!(seq.frames.len(), 3);
    assert!(!seq.is_rectified_on_load(), "an ideal rig is used as is");
    assert_eq!(seq.rig, renderer.config.rig);
    let frame = renderer.render(2);
    let loaded = seq.load_frame(2).unwrap();
    assert_eq!(loaded.left.pixels().unwrap(), frame.left.pixels.as_slice());
    assert_eq!(
        loaded.right.pixels().unwrap(),
        frame.right.pixels.as_slice()
    );
    let pose = loaded.pose.unwrap();
    assert!((pose.translation.vector - frame.world_from_left.translation.vector).norm() < 1e-6);
    assert!(pose.rotation.angle_to(&frame.world_from_left.rotation) < 1e-6);

    let depth =
        read_depth_png(&out.join(format!("mav0/depth0/data/{}.png", frame.timestamp_ns))).unwrap();
    let worst = depth
        .metres
        .iter()
        .zip(&frame.left.depth_m)
        .filter(|(_, d)| **d > 0.0 && **d < 13.0)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst <= 0.5 / 5000.0 + 1e-6, "depth PNG off by {worst} m");

    let illumination = std::fs::read_to_string(out.join("mav0/scene/illumination.csv")).unwrap();
    let row: Vec<f64> = illumination
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!((row[1], row[2], row[3], row[4]), (1.0, 0.0, 0.5, 15.0));
    let segments = std::fs::read_to_string(out.join("mav0/scene/segments3d.csv")).unwrap();
    assert_eq!(
        segments.lines().count() - 1,
        renderer.scene.segments().len()
    );
    let sheet = image::open(out.join("contact-sheet.png")).unwrap();
    assert_eq!(sheet.width(), 3 * 376 + 2 * 4);

    // The same seed again, quiet: the same bytes, and nothing on stderr.
    let again = Scratch::new("synth", "mismatch-again");
    let quiet = synth(&[
        "--preset",
        "left-right-mismatch",
        "--seed",
        "4",
        "--frames",
        "3",
        "--output",
        again.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(quiet.status.success());
    assert_eq!(
        String::from_utf8_lossy(&quiet.stderr),
        "",
        "--quiet says nothing"
    );
    let name = format!("mav0/cam1/data/{}.png", frame.timestamp_ns);
    assert_eq!(
        std::fs::read(out.join(&name)).unwrap(),
        std::fs::read(again.join(&name)).unwrap()
    );
}

#[test]
fn bad_options_fail_with_a_clear_message() {
    let unknown = synth(&["--preset", "disco"]);
    assert!(!unknown.status.success());
    assert!(String::from_utf8_lossy(&unknown.stderr).contains("expected one of normal"));
    let zero = Scratch::new("synth", "zero");
    let none = synth(&[
        "--frames",
        "0",
        "--output",
        zero.join("out").to_str().unwrap(),
    ]);
    assert!(!none.status.success() && String::from_utf8_lossy(&none.stderr).contains("--frames"));
    let dir = Scratch::new("synth", "blocked");
    let blocked = dir.join("output");
    std::fs::write(&blocked, b"a file where the folder should go").unwrap();
    let result = synth(&["--frames", "1", "--output", blocked.to_str().unwrap()]);
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains(blocked.to_str().unwrap()));
}
