//! The OpenCV front end on real and generated images: detection, appearance and geometric
//! matching, perturbation, and bad input. Tests named `real_data_*` need the EuRoC excerpt
//! (see `linetrack-test-data`) and fail, saying where they looked, when it is missing.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_geometry::{MatchCase, Segment, SegmentFeatures, direction_angle};
use linetrack_test_data::{euroc_stereo_pair, shift_left, test_card, test_card_edges};
use linetrack_vision::*;
use opencv::core::{Mat, Scalar, Vector};
use opencv::imgcodecs;

mod bad_input;
mod perturbation;
mod pixels;
mod points;
mod real_data;

const W: usize = 752;
const H: usize = 480;

fn detect_all(kind: DetectorKind, image: &GrayImage) -> Vec<Segment> {
    let mut detector = create_detector(kind, &FrontendConfig::default()).unwrap();
    let mut out = Vec::new();
    detector.detect(image, &mut out).unwrap();
    out
}

/// Detects, describes and matches two images with `detector` + `matcher`.
fn match_images(
    detector: DetectorKind,
    matcher: MatcherKind,
    case: MatchCase,
    a: &GrayImage,
    b: &GrayImage,
) -> (LineFeatures, LineFeatures, Vec<FeatureMatch>) {
    let result = LinePairMatcher::new(detector, matcher, &FrontendConfig::default())
        .unwrap()
        .run(case, a, b)
        .unwrap();
    (result.first, result.second, result.matches)
}

fn features(s: &Segment) -> SegmentFeatures {
    SegmentFeatures::new(s).unwrap()
}

/// EuRoC excerpt frame `index`, left and right, loaded.
fn euroc_images(index: usize) -> (GrayImage, GrayImage) {
    let (left, right) = euroc_stereo_pair(index).unwrap_or_else(|e| panic!("{e}"));
    (
        GrayImage::load(&left).unwrap(),
        GrayImage::load(&right).unwrap(),
    )
}

fn card(shift: usize) -> GrayImage {
    let pixels = test_card(W, H);
    let pixels = if shift == 0 {
        pixels
    } else {
        shift_left(&pixels, W, shift)
    };
    GrayImage::from_pixels(W, H, &pixels, &format!("test card shifted {shift} px")).unwrap()
}

// ---------------------------------------------------------------- generated images

#[test]
fn detectors_find_the_test_card_edges_and_nothing_else() {
    let image = card(0);
    let truth = test_card_edges(W, H);
    for kind in DetectorKind::ALL {
        let segments = detect_all(kind, &image);
        assert!(!segments.is_empty());
        // Every long detection lies on a true edge: parallel within 2°, within 2 px of its line.
        let on_an_edge = |s: &Segment| {
            truth.iter().any(|e| {
                let edge = features(&Segment::from_coords(e[0], e[1], e[2], e[3]));
                let f = features(s);
                let distance = |p: linetrack_geometry::Point| {
                    linetrack_geometry::cross(&edge.dir, &(p - edge.mid)).abs()
                };
                direction_angle(&edge, &f).to_degrees() < 2.0
                    && distance(s.start) < 2.0
                    && distance(s.end) < 2.0
            })
        };
        let long: Vec<&Segment> = segments.iter().filter(|s| s.length() > 40.0).collect();
        let stray: Vec<&&Segment> = long.iter().filter(|s| !on_an_edge(s)).collect();
        assert!(
            stray.is_empty(),
            "{}: {} of {} long segments off every edge: {stray:?}",
            kind.name(),
            stray.len(),
            long.len()
        );
        // And most true edges are found: a long detection runs along at least 17 of the 20.
        let found = truth
            .iter()
            .filter(|e| {
                let edge = features(&Segment::from_coords(e[0], e[1], e[2], e[3]));
                long.iter().any(|s| {
                    let f = features(s);
                    direction_angle(&edge, &f).to_degrees() < 2.0
                        && linetrack_geometry::cross(&edge.dir, &(f.mid - edge.mid)).abs() < 2.0
                        && linetrack_geometry::overlap(&edge, &f, MatchCase::FrameToFrame) > 0.3
                })
            })
            .count();
        assert!(
            found >= 17,
            "{}: found {found} of {} edges",
            kind.name(),
            truth.len()
        );
    }
}

#[test]
fn edgelines_orients_segments_as_lsd_and_fld_do() {
    // The ℓ1 matcher's polarity gate compares endpoint order; frame to frame across a
    // detector swap it compares segments of two detectors, so all must agree.
    let image = card(0);
    let ours = detect_all(DetectorKind::EdgeLines, &image);
    for kind in [DetectorKind::Lsd, DetectorKind::Fld] {
        let theirs = detect_all(kind, &image);
        let mut compared = 0;
        for s in ours.iter().filter(|s| s.length() > 40.0) {
            let f = features(s);
            let same_edge = theirs.iter().find(|t| {
                let g = features(t);
                direction_angle(&f, &g).to_degrees() < 2.0
                    && linetrack_geometry::cross(&f.dir, &(g.mid - f.mid)).abs() < 2.0
                    && linetrack_geometry::overlap(&f, &g, MatchCase::FrameToFrame) > 0.3
            });
            if let Some(t) = same_edge {
                compared += 1;
                assert!(
                    (s.end - s.start).dot(&(t.end - t.start)) > 0.0,
                    "{}: {t:?} runs against edgelines' {s:?}",
                    kind.name()
                );
            }
        }
        assert!(
            compared >= 10,
            "{}: {compared} segments compared",
            kind.name()
        );
    }
}

#[test]
fn detections_are_capped_longest_first_and_above_the_minimum_length() {
    let image = card(0);
    let config = FrontendConfig {
        lines: LineOptions {
            max_segments: 7,
            min_length_px: 30.0,
        },
        ..Default::default()
    };
    for kind in DetectorKind::ALL {
        let mut detector = create_detector(kind, &config).unwrap();
        let mut out = Vec::new();
        detector.detect(&image, &mut out).unwrap();
        assert_eq!(out.len(), 7, "{}", kind.name());
        assert!(out.windows(2).all(|w| w[0].length() >= w[1].length()));
        assert!(out.iter().all(|s| s.length() >= 30.0));
        // The kept ones are the longest of an uncapped run.
        let all = detect_all(kind, &image);
        assert!(
            (out[6].length()
                - all
                    .iter()
                    .map(Segment::length)
                    .filter(|l| *l >= 30.0)
                    .nth(6)
                    .unwrap())
            .abs()
                < 1e-9
        );
    }
}

#[test]
fn stereo_matches_on_a_shifted_test_card_have_the_true_disparity() {
    const DISPARITY: usize = 12;
    let (left, right) = (card(0), card(DISPARITY));
    for detector in DetectorKind::ALL {
        for matcher in MatcherKind::ALL {
            let (fa, fb, matches) =
                match_images(detector, matcher, MatchCase::Stereo, &left, &right);
            let right_shift = matches
                .iter()
                .filter(|m| {
                    let (a, b) = (
                        features(&fa.segments[m.query]),
                        features(&fb.segments[m.train]),
                    );
                    (a.mid.x - b.mid.x - DISPARITY as f64).abs() <= 1.5
                        && (a.mid.y - b.mid.y).abs() <= 1.5
                })
                .count();
            let label = format!("{}+{}", detector.name(), matcher.name());
            assert!(
                matches.len() >= 8,
                "{label}: only {} matches",
                matches.len()
            );
            assert!(
                right_shift as f64 >= 0.9 * matches.len() as f64,
                "{label}: {right_shift} of {} at the true disparity",
                matches.len()
            );
        }
    }
}

// ---------------------------------------------------------------- configuration

#[test]
fn shipped_frontend_config_matches_the_defaults_and_names_are_checked() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/frontend.toml");
    assert_eq!(
        FrontendConfig::from_file(&path).unwrap(),
        FrontendConfig::default()
    );
    let err = FrontendConfig::from_toml_str("detector = \"hough\"")
        .unwrap_err()
        .to_string();
    assert!(err.contains("hough"), "{err}");
    let err = FrontendConfig::from_toml_str("[fld]\ncanny_aperture = 4")
        .unwrap_err()
        .to_string();
    assert!(err.contains("fld.canny_aperture"), "{err}");
    let err = FrontendConfig::from_toml_str("[l1]\nlambda = -1.0")
        .unwrap_err()
        .to_string();
    assert!(err.contains("lambda"), "{err}");
    let config = FrontendConfig::from_toml_str("[orb]\nstereo = \"row-search\"").unwrap();
    assert_eq!(config.orb.stereo, PointStereo::RowSearch);
    let err = FrontendConfig::from_toml_str("[orb]\nstereo = \"rows\"")
        .unwrap_err()
        .to_string();
    assert!(err.contains("rows"), "{err}");
    for (key, value) in [
        ("row_search_min_correlation", "0.0"),
        ("row_search_min_correlation", "1.5"),
        ("row_search_uniqueness", "1.0"),
        ("row_search_uniqueness", "nan"),
    ] {
        let err = FrontendConfig::from_toml_str(&format!("[orb]\n{key} = {value}"))
            .unwrap_err()
            .to_string();
        assert!(err.contains(&format!("orb.{key}")), "{err}");
    }
    assert_eq!("FLD".parse::<DetectorKind>(), Ok(DetectorKind::Fld));
    assert!(
        "sift"
            .parse::<MatcherKind>()
            .unwrap_err()
            .contains("lbd, l1")
    );
}
