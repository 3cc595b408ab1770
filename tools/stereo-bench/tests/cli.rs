//! `linetrack-stereo-bench` as a user runs it: on two real Middlebury pairs (`real_data_*`),
//! and on bad input.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_test_data::Scratch;
use std::process::{Command, Output};

fn bench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_linetrack-stereo-bench"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn real_data_two_pairs_give_tables_csv_plot_and_goals() {
    let out = Scratch::new("stereo-bench", "two-pairs");
    let result = bench(&[
        "--pair",
        "Cones",
        "--pair",
        "Venus",
        "--condition",
        "as-is",
        "--condition",
        "over-exposed",
        "--matches",
        "--quiet",
        "--output",
        out.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    assert!(stdout.contains("2 pairs"), "{stdout}");
    let table = std::fs::read_to_string(out.join("stereo-bench.md")).unwrap();
    for needle in [
        "| as-is |",
        "| over-exposed |",
        "LSD+lbd",
        "FLD+l1",
        "EDGELINES+l1",
        "Stereo repeatability",
        "Goals",
    ] {
        assert!(table.contains(needle), "{needle} missing:\n{table}");
    }
    // One row per pair × condition × detector (LSD, FLD, edgelines) × matcher, with counts
    // that add up.
    let mut reader = csv::Reader::from_path(out.join("stereo-bench.csv")).unwrap();
    let rows: Vec<csv::StringRecord> = reader.records().map(Result::unwrap).collect();
    assert_eq!(rows.len(), 2 * 2 * 3 * 2);
    let headers = reader.headers().unwrap().clone();
    let field = |row: &csv::StringRecord, name: &str| -> usize {
        row[headers.iter().position(|h| h == name).unwrap()]
            .parse()
            .unwrap()
    };
    let mut correct = 0;
    for row in &rows {
        assert_eq!(
            field(row, "matches"),
            field(row, "correct") + field(row, "wrong") + field(row, "unjudged")
        );
        assert!(field(row, "correct") <= field(row, "matchable"));
        assert!(field(row, "matchable") <= field(row, "left_segments"));
        correct += field(row, "correct");
    }
    assert!(correct > 100, "real pairs give real matches: {correct}");
    let lines = std::fs::read_to_string(out.join("matches.jsonl")).unwrap();
    let total: usize = rows.iter().map(|r| field(r, "matches")).sum();
    assert_eq!(lines.lines().count(), total);
    assert!(
        std::fs::read(out.join("stereo-bench.png"))
            .unwrap()
            .starts_with(b"\x89PNG")
    );
}

#[test]
fn bad_arguments_are_refused_naming_the_culprit() {
    let result = bench(&["--data", "/nonexistent/middlebury", "--quiet"]);
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains("/nonexistent/middlebury"));

    let result = bench(&["--condition", "sunset"]);
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains("sunset"));

    let result = bench(&["--compare", "no-equals-sign"]);
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains("LABEL=MATCHER:CONFIG"));
}

#[test]
fn real_data_an_unknown_scene_is_named() {
    let result = bench(&["--pair", "Atlantis", "--quiet"]);
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains("Atlantis"));
}
