//! Runs the real `linetrack-match-demo` binary as a user would and checks what it prints
//! and writes, and how it fails on bad input.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure
use linetrack_test_data::Scratch;
use std::process::{Command, Output};

fn demo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_linetrack-match-demo"))
        .args(args)
        .output()
        .expect("the demo binary starts")
}

fn workspace_file(relative: &str) -> String {
    concat!(env!("CARGO_MANIFEST_DIR"), "/../../").to_string() + relative
}

#[test]
fn default_run_prints_both_cases_and_writes_pictures_and_json() {
    let out = Scratch::new("match-demo", "default");
    let result = demo(&["--no-images", "--output", out.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(
        result.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&result.stderr)
    );
    for name in ["stereo", "frame-to-frame"] {
        let line = stdout
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{name}:")))
            .expect("a summary line per case");
        let printed_matches: usize = line
            .split(':')
            .nth(1)
            .unwrap()
            .split_whitespace()
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!(printed_matches > 20, "{line}");
        let picture = image::open(out.join(format!("{name}.png"))).expect("a readable PNG");
        assert_eq!((picture.width(), picture.height()), (2 * 752 + 8, 480));
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("matches.json")).unwrap()).unwrap();
    let cases = json.as_array().unwrap();
    assert_eq!(cases.len(), 2);
    for case in cases {
        let matches = case["matches"].as_array().unwrap();
        assert_eq!(
            case["score"]["accepted"].as_u64().unwrap() as usize,
            matches.len()
        );
        assert_eq!(
            case["stats"]["matches"].as_u64().unwrap() as usize,
            matches.len()
        );
    }
}

#[test]
fn list_prints_one_line_per_match_and_the_paper_config_loads() {
    let out = Scratch::new("match-demo", "list");
    let config = workspace_file("configs/l1-matcher-paper.toml");
    let result = demo(&[
        "--no-images",
        "--case",
        "stereo",
        "--list",
        "--config",
        &config,
        "--seed",
        "3",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(result.status.success());
    let stdout = String::from_utf8_lossy(&result.stdout);
    let listed = stdout.lines().filter(|l| l.contains("→")).count();
    let summary = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("stereo:"))
        .unwrap();
    let printed: usize = summary
        .split(':')
        .nth(1)
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(listed, printed);
    assert!(stdout.contains("l1-matcher-paper.toml"));
    assert!(!out.join("frame-to-frame.png").exists());
}

#[test]
fn missing_and_malformed_configs_fail_naming_the_culprit() {
    let missing_out = Scratch::new("match-demo", "missing");
    let missing = demo(&[
        "--config",
        "/nonexistent/matcher.toml",
        "--output",
        missing_out.join("out").to_str().unwrap(),
    ]);
    assert!(!missing.status.success());
    assert!(String::from_utf8_lossy(&missing.stderr).contains("/nonexistent/matcher.toml"));

    let dir = Scratch::new("match-demo", "malformed");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "lambda = 0.1\n[gates]\nmax_angle_deg = 120\n").unwrap();
    let result = demo(&[
        "--config",
        bad.to_str().unwrap(),
        "--output",
        dir.to_str().unwrap(),
    ]);
    assert!(!result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains("gates.max_angle_deg"), "{stderr}");
}

/// The count of matches on the image-part line of `case` and `pair` (e.g. "lsd+l1").
fn image_matches(stdout: &str, case: &str, pair: &str) -> usize {
    let line = stdout
        .lines()
        .find(|l| {
            l.trim_start().starts_with(&format!("{case}:"))
                && l.contains(pair)
                && l.contains("segments;")
        })
        .unwrap_or_else(|| panic!("no {case} {pair} line in:\n{stdout}"));
    line.split(pair)
        .nth(1)
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

#[test]
fn image_part_runs_lbd_and_l1_on_a_generated_sequence() {
    let dir = Scratch::new("match-demo", "images");
    let sequence = dir.join("sequence");
    linetrack_synth::generate(
        linetrack_scene_render::Preset::Normal,
        2,
        3,
        &sequence,
        true,
    )
    .unwrap();
    let out = dir.join("out");
    let result = demo(&[
        "--dataset",
        sequence.to_str().unwrap(),
        "--frame",
        "1",
        "--output",
        out.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(
        result.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&result.stderr)
    );
    assert!(
        stdout.contains("images: sequence") && stdout.contains("frame 1, 752×480"),
        "{stdout}"
    );
    for case in ["stereo", "frame-to-frame"] {
        for pair in ["lsd+lbd", "lsd+l1"] {
            assert!(
                image_matches(&stdout, case, pair) >= 10,
                "{case} {pair}: {stdout}"
            );
            let picture =
                image::open(out.join(format!("images-{case}-{}.png", pair.replace('+', "-"))))
                    .unwrap();
            assert_eq!(picture.width(), 2 * 752 + 8);
        }
    }
    // The last frame has no next one.
    let last = demo(&[
        "--dataset",
        sequence.to_str().unwrap(),
        "--frame",
        "2",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(
        !last.status.success()
            && String::from_utf8_lossy(&last.stderr).contains("the sequence has 3 frames")
    );
}

#[test]
fn real_data_image_part_on_the_euroc_excerpt() {
    let euroc = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
    let out = Scratch::new("match-demo", "euroc");
    let result = demo(&[
        "--dataset",
        euroc.to_str().unwrap(),
        "--detector",
        "fld",
        "--output",
        out.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(
        result.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&result.stderr)
    );
    assert!(stdout.contains("rectified on load"), "{stdout}");
    // Measured: fld+lbd 70 stereo / 86 frame to frame, fld+l1 48 / 77.
    assert!(
        image_matches(&stdout, "stereo", "fld+l1") >= 30
            && image_matches(&stdout, "frame-to-frame", "fld+l1") >= 50,
        "{stdout}"
    );
}

#[test]
fn a_folder_that_is_not_a_dataset_is_named() {
    let dir = Scratch::new("match-demo", "not-a-dataset");
    let result = demo(&[
        "--dataset",
        dir.to_str().unwrap(),
        "--output",
        dir.join("out").to_str().unwrap(),
    ]);
    assert!(!result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        stderr.contains(dir.to_str().unwrap()) && stderr.contains("not a dataset folder"),
        "{stderr}"
    );
}

#[test]
fn help_shows_examples() {
    let result = demo(&["--help"]);
    assert!(result.status.success());
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(stdout.contains("EXAMPLES") && stdout.contains("--config"));
}
