//! `linetrack-disparity-check` as a user runs it: on the three 2001–2003 Middlebury scenes
//! (`real_data_*`), on generated highway frames (exact truth), and on bad input.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_test_data::Scratch;
use std::process::{Command, Output};

fn check(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_linetrack-disparity-check"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn real_data_correct_point_disparities_are_unbiased_on_the_2001_2003_scenes() {
    let out = Scratch::new("disparity-check", "three-scenes");
    let result = check(&[
        "--pair",
        "Tsukuba",
        "--pair",
        "Venus",
        "--pair",
        "Cones",
        "--samples",
        "--quiet",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(stdout.contains("3 pairs"), "{stdout}");
    for needle in [
        "| points | (any) | < 10 |",
        "| segment endpoints | lbd | all |",
        "| segment endpoints | l1 | all |",
    ] {
        assert!(stdout.contains(needle), "{needle} missing:\n{stdout}");
    }
    let rows: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(out.join("disparity-check.json")).unwrap())
            .unwrap();
    // Points in every band, then segment endpoints per matcher: 5 rows each (4 bands, all).
    assert_eq!(rows.len(), 15);
    let all_points = &rows[4];
    assert_eq!(all_points["band"], "all");
    let count = all_points["count"].as_u64().unwrap();
    let mismatched = all_points["mismatched"].as_u64().unwrap();
    // Measured: 1278 points, 44 of them wrong matches, the others' mean −0.001 px.
    assert!(count > 500, "{all_points}");
    assert!(
        mismatched * 10 < count,
        "over 10 % wrong matches: {all_points}"
    );
    let bias = all_points["correct"]["mean_px"].as_f64().unwrap();
    assert!(bias.abs() <= 0.05, "a bias of {bias} px: {all_points}");
    // Every sighting is written, each with its error.
    let samples = std::fs::read_to_string(out.join("samples.jsonl")).unwrap();
    let first: serde_json::Value = serde_json::from_str(samples.lines().next().unwrap()).unwrap();
    let (measured, truth) = (
        first["sample"]["measured_px"].as_f64().unwrap(),
        first["sample"]["true_px"].as_f64().unwrap(),
    );
    assert!((first["error_px"].as_f64().unwrap() - (measured - truth)).abs() < 1e-9);
}

#[test]
fn an_unknown_scene_and_bad_limits_are_refused_by_name() {
    let data = Scratch::new("disparity-check", "empty");
    let result = check(&["--data", data.to_str().unwrap(), "--quiet"]);
    assert!(!result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains(data.to_str().unwrap()), "{stderr}");
    for (args, needle) in [
        (["--inlier-px", "0"], "--inlier-px 0"),
        (["--max-spread-px", "NaN"], "--max-spread-px NaN"),
        (["--matcher", "sift"], "sift"),
        (["--generated", "motorway"], "motorway"),
    ] {
        let result = check(&args);
        assert!(!result.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
    }
    let result = check(&["--generated", "highway", "--frames", "0", "--quiet"]);
    assert!(!result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains("--frames 0"), "{stderr}");
}

#[test]
fn generated_highway_point_disparities_are_unbiased_against_the_exact_depth() {
    let out = Scratch::new("disparity-check", "highway");
    let result = check(&[
        "--generated",
        "highway",
        "--frames",
        "2",
        "--matcher",
        "lbd",
        "--quiet",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(stdout.contains("2 pairs"), "{stdout}");
    let rows: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(out.join("disparity-check.json")).unwrap())
            .unwrap();
    // The highway's points are far: nearly all of them under 10 px of disparity.
    let (far, all) = (&rows[0], &rows[4]);
    assert_eq!(
        (far["band"].as_str(), all["band"].as_str()),
        (Some("< 10"), Some("all"))
    );
    let count = far["count"].as_u64().unwrap();
    // Measured on frames 0 and 50 of seed 1: 1077 points under 10 px, 9 of them wrong
    // matches, the others' mean error −0.002 px (10 frames: +0.006 ± 0.006 px).
    assert!(count > 500, "{far}");
    assert!(
        count * 10 > all["count"].as_u64().unwrap() * 9,
        "{far}\n{all}"
    );
    let bias = far["correct"]["mean_px"].as_f64().unwrap();
    assert!(bias.abs() <= 0.03, "a bias of {bias} px: {far}");
}

/// Rocks1 (2005–2006) is the scene whose points read furthest above its truth. The truth's
/// own shift, found from the images alone, says the same: two unrelated measures (sparse
/// matched corners, dense photometric fit of the map) agree on where the map stands.
#[test]
fn real_data_a_2005_truth_reads_as_far_below_its_own_images_as_our_points_read_above_it() {
    let out = Scratch::new("disparity-check", "truth-shift");
    let shifted = check(&[
        "--truth-shift",
        "--pair",
        "Rocks1",
        "--quiet",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(
        shifted.status.success(),
        "{}",
        String::from_utf8_lossy(&shifted.stderr)
    );
    let stdout = String::from_utf8_lossy(&shifted.stdout);
    assert!(stdout.contains("| Rocks1 |"), "{stdout}");
    let rows: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(out.join("truth-shift.json")).unwrap())
            .unwrap();
    assert_eq!(rows.len(), 1);
    assert!(rows[0]["pixels"].as_u64().unwrap() > 10_000, "{}", rows[0]);
    let shift = rows[0]["shift_px"].as_f64().unwrap();
    let matched = check(&[
        "--pair",
        "Rocks1",
        "--matcher",
        "l1",
        "--quiet",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(matched.status.success());
    let table: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(out.join("disparity-check.json")).unwrap())
            .unwrap();
    let points = table
        .iter()
        .find(|r| r["kind"] == "point" && r["band"] == "all")
        .unwrap_or_else(|| panic!("no points row: {table:?}"));
    let bias = points["correct"]["mean_px"].as_f64().unwrap();
    // Measured: truth shift +0.256 px, points +0.262 px.
    assert!(shift > 0.1 && bias > 0.1, "shift {shift}, points {bias}");
    assert!((shift - bias).abs() <= 0.05, "shift {shift}, points {bias}");
}
