//! Runs the real `linetrack-detector-bench` binary on a short generated sequence: one
//! table row per detector with figures in range; a folder that is not a generated
//! sequence fails clearly.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_scene_render::Preset;
use linetrack_test_data::Scratch;
use std::process::{Command, Output};

fn bench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_linetrack-detector-bench"))
        .args(args)
        .output()
        .expect("the binary starts")
}

#[test]
fn every_detector_is_scored_on_a_generated_sequence() {
    let out = Scratch::new("detector-bench", "normal");
    linetrack_synth::generate(Preset::Normal, 0, 2, &out, true).unwrap();
    let result = bench(&[out.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    for detector in ["lsd", "fld", "edgelines"] {
        let row = stdout
            .lines()
            .find(|l| l.contains(&format!("| {detector} |")))
            .unwrap_or_else(|| panic!("no {detector} row in\n{stdout}"));
        let cells: Vec<&str> = row.trim_matches('|').split('|').map(str::trim).collect();
        assert_eq!(cells[2], "2", "{row}");
        let repeatability: f64 = cells[4].parse().unwrap();
        let frame_to_frame: f64 = cells[5].parse().unwrap();
        assert!((0.4..=1.0).contains(&repeatability), "{row}");
        assert!((0.5..=1.0).contains(&frame_to_frame), "{row}");
    }
}

#[test]
fn a_folder_without_a_sequence_is_refused() {
    let out = Scratch::new("detector-bench", "empty");
    let result = bench(&[out.to_str().unwrap()]);
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains("Error"));
}
