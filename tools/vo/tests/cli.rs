//! Runs the real `linetrack-vo` binary on a generated sequence, on the EuRoC excerpt
//! (`real_data_*`), and on bad input.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_datasets::tum;
use std::process::{Command, Output};

fn vo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_linetrack-vo"))
        .args(args)
        .output()
        .expect("the binary starts")
}

#[test]
fn a_generated_sequence_gives_trajectory_ground_truth_stats_and_metrics() {
    let dir = linetrack_test_data::scratch_path("vo", "generated");
    let sequence = dir.join("sequence");
    linetrack_synth::generate(
        linetrack_scene_render::Preset::HandheldGainJumps,
        3,
        8,
        &sequence,
    )
    .unwrap();
    let out = dir.join("out");
    let result = vo(&[
        sequence.to_str().unwrap(),
        "--gain-jumps",
        "0.1",
        "--output",
        out.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    assert!(
        stdout.contains("sequence: 8 frames (0 skipped)")
            && stdout.contains("RPE")
            && stdout.contains("ATE"),
        "{stdout}"
    );
    let trajectory = tum::read(&out.join("trajectory.txt")).unwrap();
    let truth = tum::read(&out.join("groundtruth.txt")).unwrap();
    assert_eq!((trajectory.len(), truth.len()), (8, 8));
    assert_eq!(
        trajectory[0].pose,
        nalgebra::Isometry3::identity(),
        "world = first camera"
    );
    // The estimate ends within 1 cm of the truth.
    let last = (trajectory[7].pose.translation.vector - truth[7].pose.translation.vector).norm();
    assert!(last < 0.01, "final position off by {last} m");
    let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    assert_eq!(csv.lines().count(), 9);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn real_data_euroc_excerpt_is_tracked_without_losing_a_frame() {
    let euroc = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
    let out = linetrack_test_data::scratch_path("vo", "euroc");
    let result = vo(&[euroc.to_str().unwrap(), "--output", out.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    // Measured: 95 frames, 0 lost, ATE 2.2 mm (the vehicle is almost still).
    assert!(stdout.contains("95 frames (0 skipped), 0 lost"), "{stdout}");
    let ate: f64 = stdout
        .split("ATE ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(ate < 0.01, "{stdout}");
    let _ = std::fs::remove_dir_all(out);
}

#[test]
fn a_folder_that_is_not_a_dataset_fails_naming_it() {
    let dir = linetrack_test_data::scratch_path("vo", "nothing");
    std::fs::create_dir_all(&dir).unwrap();
    let result = vo(&[
        dir.to_str().unwrap(),
        "--output",
        dir.join("out").to_str().unwrap(),
    ]);
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains(dir.to_str().unwrap()));
    let _ = std::fs::remove_dir_all(dir);
}
