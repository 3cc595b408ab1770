//! Runs the real `linetrack-match-pair` binary as a user would: on generated images with a
//! known disparity, on the real EuRoC pair (`real_data_*`), and on bad input.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_test_data::Scratch;
use std::path::Path;
use std::process::{Command, Output};

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_linetrack-match-pair"))
        .args(args)
        .output()
        .expect("the binary starts")
}

fn save_gray(path: &Path, width: usize, height: usize, pixels: Vec<u8>) {
    image::GrayImage::from_raw(width as u32, height as u32, pixels)
        .unwrap()
        .save(path)
        .unwrap();
}

/// A test card and its copy shifted by `disparity` px, as PNG files.
fn card_pair(dir: &Path, disparity: usize) -> (String, String) {
    let card = linetrack_test_data::test_card(752, 480);
    let shifted = linetrack_test_data::shift_left(&card, 752, disparity);
    let (a, b) = (dir.join("left.png"), dir.join("right.png"));
    save_gray(&a, 752, 480, card);
    save_gray(&b, 752, 480, shifted);
    (a.display().to_string(), b.display().to_string())
}

fn stdout(output: &Output) -> String {
    assert!(
        output.status.success(),
        "failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

fn stderr(output: &Output) -> String {
    assert!(!output.status.success(), "should have failed");
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// The number before `word` in the summary line.
fn count_before(summary: &str, word: &str) -> usize {
    let before = &summary[..summary.find(word).unwrap()];
    before
        .split_whitespace()
        .last()
        .unwrap()
        .rsplit('|')
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

#[test]
fn generated_pair_gives_picture_json_csv_and_summary_with_the_true_disparity() {
    let dir = Scratch::new("match-pair", "generated");
    let (left, right) = card_pair(&dir, 10);
    let out = dir.join("out");
    for (detector, matcher) in [("lsd", "lbd"), ("fld", "l1")] {
        let text = stdout(&run(&[
            &left,
            &right,
            "--detector",
            detector,
            "--matcher",
            matcher,
            "--points",
            "--output",
            out.to_str().unwrap(),
        ]));
        let summary = text.lines().last().unwrap();
        assert!(
            summary.starts_with(&format!("{detector}+{matcher} stereo:")),
            "{summary}"
        );
        assert!(
            summary.contains("detect") && summary.contains("ms") && summary.contains("orb"),
            "{summary}"
        );
        let matches = count_before(summary, "matches");
        assert!(matches >= 8, "{summary}");

        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("matches.json")).unwrap())
                .unwrap();
        let listed = json["matches"].as_array().unwrap();
        assert_eq!(listed.len(), matches);
        let first = json["first_segments"].as_array().unwrap();
        let second = json["second_segments"].as_array().unwrap();
        let mid_x = |s: &serde_json::Value| {
            (s["start"][0].as_f64().unwrap() + s["end"][0].as_f64().unwrap()) / 2.0
        };
        let at_disparity = listed
            .iter()
            .filter(|m| {
                let (q, t) = (
                    m["query"].as_u64().unwrap() as usize,
                    m["train"].as_u64().unwrap() as usize,
                );
                (mid_x(&first[q]) - mid_x(&second[t]) - 10.0).abs() <= 1.5
            })
            .count();
        assert!(
            at_disparity as f64 >= 0.9 * matches as f64,
            "{detector}+{matcher}: {at_disparity} of {matches}"
        );

        let csv = std::fs::read_to_string(out.join("matches.csv")).unwrap();
        assert_eq!(csv.lines().count(), matches + 1);
        let picture = image::open(out.join("matches.png")).unwrap();
        assert_eq!((picture.width(), picture.height()), (2 * 752 + 8, 480));
    }
}

#[test]
fn real_data_euroc_pairs_with_and_without_perturbation() {
    let (left, right) = linetrack_test_data::euroc_stereo_pair(0).unwrap_or_else(|e| panic!("{e}"));
    let (next, _) = linetrack_test_data::euroc_stereo_pair(1).unwrap_or_else(|e| panic!("{e}"));
    let dir = Scratch::new("match-pair", "euroc");
    let out = dir.to_str().unwrap();
    let stereo = stdout(&run(&[
        left.to_str().unwrap(),
        right.to_str().unwrap(),
        "--output",
        out,
    ]));
    assert!(
        count_before(&stereo, "segments") == 100 && count_before(&stereo, "matches") >= 15,
        "{stereo}"
    );
    let f2f = stdout(&run(&[
        left.to_str().unwrap(),
        next.to_str().unwrap(),
        "--mode",
        "frame-to-frame",
        "--matcher",
        "l1",
        "--gain",
        "2.2",
        "--bias",
        "15",
        "--output",
        out,
    ]));
    assert!(
        f2f.contains("lsd+l1 frame-to-frame") && f2f.contains("second image × 2.2 + 15"),
        "{f2f}"
    );
    assert!(count_before(&f2f, "matches") >= 10, "{f2f}");
}

#[test]
fn bad_inputs_fail_naming_the_culprit() {
    let dir = Scratch::new("match-pair", "bad");
    let (good, _) = card_pair(&dir, 4);
    let out = dir.join("out").display().to_string();

    let missing = dir.join("missing.png").display().to_string();
    assert!(stderr(&run(&[&good, &missing, "--output", &out])).contains(&missing));

    let corrupt = dir.join("corrupt.png");
    std::fs::write(&corrupt, b"definitely not an image").unwrap();
    let corrupt = corrupt.display().to_string();
    assert!(stderr(&run(&[&good, &corrupt, "--output", &out])).contains(&corrupt));

    let small = dir.join("small.png");
    save_gray(&small, 100, 50, vec![7; 5000]);
    let small = small.display().to_string();
    let text = stderr(&run(&[&good, &small, "--output", &out]));
    assert!(
        text.contains(&good) && text.contains(&small) && text.contains("same size"),
        "{text}"
    );

    // A colour image is converted to grey and matched like its grey original…
    let (_, shifted) = card_pair(&dir, 4);
    let grey = image::open(&shifted).unwrap().to_luma8();
    let colour = dir.join("colour.png");
    image::DynamicImage::ImageLuma8(grey)
        .to_rgb8()
        .save(&colour)
        .unwrap();
    let colour = colour.display().to_string();
    let text = stdout(&run(&[&good, &colour, "--output", &out]));
    assert!(count_before(&text, "matches") >= 10, "{text}");

    // …but a float image (a portable float map) is refused, naming the file and the format.
    let float = dir.join("float.pfm");
    let mut bytes = b"Pf\n752 480\n-1.0\n".to_vec();
    for _ in 0..752 * 480 {
        bytes.extend_from_slice(&0.5f32.to_le_bytes());
    }
    std::fs::write(&float, bytes).unwrap();
    let float = float.display().to_string();
    let text = stderr(&run(&[&good, &float, "--output", &out]));
    assert!(text.contains(&float) && text.contains("8-bit"), "{text}");

    assert!(stderr(&run(&[&good, &good, "--gain", "NaN", "--output", &out])).contains("gain"));
    assert!(stderr(&run(&[&good, &good, "--matcher", "sift"])).contains("expected one of lbd, l1"));

    let config = dir.join("bad.toml");
    std::fs::write(&config, "[lines]\nmax_segmnets = 3\n").unwrap();
    let text = stderr(&run(&[
        &good,
        &good,
        "--config",
        config.to_str().unwrap(),
        "--output",
        &out,
    ]));
    assert!(
        text.contains("bad.toml") && text.contains("max_segmnets"),
        "{text}"
    );
}

#[test]
fn help_shows_examples() {
    let text = stdout(&run(&["--help"]));
    assert!(
        text.contains("EXAMPLES") && text.contains("--gain") && text.contains("frame-to-frame")
    );
}
