//! Runs `linetrack-eval --quick` as CI does and checks the report: three tables with a row
//! for every sequence and case, the frame-to-frame line benchmark's counts, plots that
//! exist, and inlier ratios that say the front end works on easy generated data. The real sequences have a test of their own, without the
//! generated ones.
//!
//! Both tests run 3 frames of every sequence (generated and real): two frame-to-frame steps
//! per sequence, so the work (rendering, then six detector × matcher combinations and four
//! odometry configurations over each frame) stays small. The quick setting's illumination
//! jump every 0.15 s would come after the third frame at 20 Hz, so the starred rows would see
//! no change; a jump every 0.04 s perturbs every frame after the first, with a new gain and
//! bias each time.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_test_data::Scratch;
use std::path::Path;
use std::process::Command;

fn run_report(dir: &Path, extra: &[&str]) -> String {
    let (sequences, output) = (dir.join("sequences"), dir.join("report"));
    let mut args = vec![
        "--quick",
        "--frames",
        "3",
        "--real-frames",
        "3",
        "--jump-period-s",
        "0.04",
        "--sequences",
        sequences.to_str().unwrap(),
        "--output",
        output.to_str().unwrap(),
    ];
    args.extend(extra);
    let result = Command::new(env!("CARGO_BIN_EXE_linetrack-eval"))
        .args(&args)
        .output()
        .unwrap();
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    // stderr is a pipe: plain progress lines. The work was counted right: the count
    // reaches its total exactly once, at the end.
    let stderr = String::from_utf8_lossy(&result.stderr);
    let finished = stderr
        .lines()
        .filter(|l| l.starts_with("eval frames: ") && l.contains(" (100 %)"))
        .count();
    assert_eq!(finished, 1, "{stderr}");
    let report = std::fs::read_to_string(output.join("report.md")).unwrap();
    for line in report.lines().filter(|l| l.starts_with("![")) {
        let name = line.split('(').nth(1).unwrap().trim_end_matches(')');
        let picture = std::fs::read(output.join(name)).unwrap();
        assert!(picture.starts_with(b"\x89PNG"), "{name} is not a PNG");
    }
    report
}

/// The cells of the Table I row for `sequence` and `case`.
fn table1_row(report: &str, sequence: &str, case: &str) -> Vec<String> {
    let row = report
        .lines()
        .find(|l| l.starts_with(&format!("| {sequence} | {case} |")))
        .unwrap_or_else(|| panic!("no row {sequence} {case}"));
    row.split('|')
        .map(str::trim)
        .filter(|c| !c.is_empty())
        .skip(2)
        .map(String::from)
        .collect()
}

/// The cells of the Table II row for `sequence`: a configuration's cell, then its step ratio,
/// for each configuration.
fn table2_row(report: &str, sequence: &str) -> Vec<String> {
    let table = report
        .split("## Table II")
        .nth(1)
        .and_then(|rest| rest.split("## Table III").next())
        .unwrap_or_else(|| panic!("no Table II"));
    let row = table
        .lines()
        .find(|l| l.starts_with(&format!("| {sequence} |")))
        .unwrap_or_else(|| panic!("no Table II row {sequence}"));
    row.split(" | ")
        .skip(1)
        .map(|c| c.trim_end_matches(" |").to_string())
        .collect()
}

/// The counts of the frame-to-frame line benchmark's row for `sequence` with or without
/// gain jumps, the segments as seen or predicted: frame pairs, then matches, judged,
/// correct, disjoint for LBD and for ℓ1.
fn f2f_counts(report: &str, sequence: &str, jumps: bool, positions: &str) -> [usize; 9] {
    let section = report
        .split("## Frame-to-frame line tracking against ground truth")
        .nth(1)
        .unwrap_or_else(|| panic!("no frame-to-frame line section"));
    let prefix = format!(
        "| {sequence} | {} | {positions} |",
        if jumps { "yes" } else { "no" }
    );
    let row = section
        .lines()
        .find(|l| l.starts_with(&prefix))
        .unwrap_or_else(|| panic!("no row {prefix}"));
    let cells: Vec<&str> = row
        .split('|')
        .map(str::trim)
        .filter(|c| !c.is_empty())
        .collect();
    assert_eq!(cells.len(), 14, "{row}");
    let count = |k: usize| cells[k].parse::<usize>().unwrap();
    [3, 4, 5, 6, 7, 9, 10, 11, 12].map(count)
}

/// The frame-to-frame line rows of `sequence` were measured: with and without gain jumps,
/// as seen and predicted, each matcher with matches, judged ones and correct ones among
/// them, and one CSV row per matcher and variant.
fn assert_f2f_rows(report: &str, csv: &str, sequence: &str) {
    for (jumps, positions) in [false, true]
        .into_iter()
        .flat_map(|j| ["as seen", "predicted"].map(|p| (j, p)))
    {
        let [pairs, counts @ ..] = f2f_counts(report, sequence, jumps, positions);
        assert_eq!(pairs, 2, "3 frames: 2 pairs");
        for tally in counts.chunks(4) {
            let (matches, judged, correct, disjoint) = (tally[0], tally[1], tally[2], tally[3]);
            assert!(
                matches >= judged && judged >= correct + disjoint && correct > 0,
                "{sequence} jumps {jumps}: {counts:?}"
            );
        }
    }
    assert_eq!(
        csv.lines()
            .filter(|l| l.starts_with(&format!("{sequence},")))
            .count(),
        8,
        "{csv}"
    );
}

/// The overall ratio a step-ratio cell starts with.
fn overall_step_ratio(cell: &str) -> f64 {
    cell.split(" / ")
        .next()
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no step ratio in {cell:?}"))
}

#[test]
fn quick_report_has_every_table_row_and_plot() {
    let dir = Scratch::new("eval", "quick");
    let report = run_report(&dir, &["--no-euroc", "--no-kitti-raw", "--seeds", "2"]);
    for heading in [
        "## Table I",
        "## Table II",
        "## Table III",
        "RPE over pose pairs",
    ] {
        assert!(report.contains(heading), "missing {heading}");
    }
    for sequence in ["normal", "hdr-flicker", "left-right-mismatch"] {
        for case in ["stereo", "frame to frame"] {
            let cells = table1_row(&report, sequence, case);
            assert_eq!(cells.len(), 6);
            // LSD+LBD on easy generated frames: most matches are geometric inliers.
            let ratio: f64 = cells[0].split(" / ").nth(1).unwrap().parse().unwrap();
            assert!(ratio > 0.8, "{sequence} {case}: {}", cells[0]);
        }
        // Each configuration and its step ratio; the camera moves 1–3 cm a frame, well
        // tracked (measured overall ratios 0.990 to 1.005).
        let cells = table2_row(&report, sequence);
        assert_eq!(cells.len(), 8, "{cells:?}");
        for ratio in cells.iter().skip(1).step_by(2) {
            assert!(
                (overall_step_ratio(ratio) - 1.0).abs() < 0.05 && ratio.contains("(worst "),
                "{sequence}: {cells:?}"
            );
        }
        // Two seeds: the median and the worst of them.
        assert!(
            report
                .lines()
                .any(|l| l.starts_with(&format!("| {sequence} |"))
                    && l.contains(" cm / ")
                    && l.contains("(worst ")),
            "Table II row for {sequence}"
        );
    }
    assert!(
        report.contains("| normal* |"),
        "the simulated illumination row"
    );
    let csv = std::fs::read_to_string(dir.join("report/f2f-lines.csv")).unwrap();
    for sequence in ["normal", "hdr-flicker", "left-right-mismatch"] {
        assert_f2f_rows(&report, &csv, sequence);
    }
    assert_eq!(
        report
            .lines()
            .filter(|l| {
                l.starts_with("| LSD+") || l.starts_with("| FLD+") || l.starts_with("| EDGELINES+")
            })
            .count(),
        6,
        "Table III rows"
    );
}

/// The real sequences only: the generated presets and the Middlebury section are
/// `quick_report_has_every_table_row_and_plot`'s, so they are left out here.
#[test]
fn real_data_quick_report_includes_the_euroc_excerpt() {
    let euroc = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
    let dir = Scratch::new("eval", "euroc");
    let report = run_report(
        &dir,
        &[
            "--euroc",
            euroc.to_str().unwrap(),
            "--no-generated",
            "--no-middlebury",
        ],
    );
    assert!(!dir.join("sequences").exists(), "nothing was rendered");
    let cells = table1_row(&report, "EuRoC V1_01_easy_micro", "frame to frame");
    assert!(
        cells.iter().all(|c| c.ends_with("/ –")),
        "no depth, so no inlier ratio: {cells:?}"
    );
    // Frame-to-frame matching ran: every combination matched something (measured: 66 to 84
    // matches per frame).
    for c in &cells {
        let matches: f64 = c.split(" / ").next().unwrap().parse().unwrap();
        assert!(matches > 0.0, "{cells:?}");
    }
    assert!(report.contains("| EuRoC V1_01_easy_micro* |"));
    // The KITTI raw drive, found beside the workspace: a real-motion row in Table II with a
    // single run's RPE / ATE / drift, and both real sequences' zero-motion baselines.
    assert!(
        report.lines().any(
            |l| l.starts_with("| KITTI raw 2011_09_26_drive_0001_sync |") && l.contains(" mm / ")
        ),
        "{report}"
    );
    // Step ratios: the car's two steps of about 1.4 m each (points and lines, measured: 0.976
    // with either matcher); the parked EuRoC vehicle's steps are all under 1 cm, so none.
    let kitti = table2_row(&report, "KITTI raw 2011_09_26_drive_0001_sync");
    for ratio in [&kitti[1], &kitti[3]] {
        assert!((overall_step_ratio(ratio) - 1.0).abs() < 0.1, "{kitti:?}");
    }
    // Frame-to-frame lines on the drive, judged against stereo triangulation and the poses.
    let csv = std::fs::read_to_string(dir.join("report/f2f-lines.csv")).unwrap();
    assert_f2f_rows(&report, &csv, "KITTI raw 2011_09_26_drive_0001_sync");
    let euroc = table2_row(&report, "EuRoC V1_01_easy_micro");
    assert!(
        euroc.iter().skip(1).step_by(2).all(|c| c == "–"),
        "{euroc:?}"
    );
    for name in [
        "EuRoC V1_01_easy_micro",
        "KITTI raw 2011_09_26_drive_0001_sync",
    ] {
        assert!(
            report.contains(&format!("- {name}: path ")) && report.contains("staying put"),
            "zero-motion baseline of {name}"
        );
    }
}
