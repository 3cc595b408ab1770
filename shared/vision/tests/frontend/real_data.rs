//! The EuRoC excerpt: detectors filling their cap, still-camera and stereo matches, the ORB
//! worker frame after frame and its stereo matching.

use super::*;

#[test]
fn real_data_both_detectors_fill_their_cap_on_a_euroc_frame() {
    let (image, _) = euroc_images(0);
    assert_eq!((image.width(), image.height()), (752, 480));
    for kind in DetectorKind::ALL {
        let segments = detect_all(kind, &image);
        assert_eq!(segments.len(), 100, "{}", kind.name());
        let inside = |s: &Segment| {
            [s.start, s.end]
                .iter()
                .all(|p| (0.0..=751.0).contains(&p.x) && (0.0..=479.0).contains(&p.y))
        };
        assert!(segments.iter().all(|s| s.length() >= 15.0 && inside(s)));
    }
}

#[test]
fn real_data_frame_to_frame_matches_of_a_still_camera_do_not_move() {
    // In these frames the vehicle is almost still: a right match barely moves. Measured
    // (matches / static ones): LSD+LBD 83/83, LSD+L1 69/69, FLD+LBD 87/86, FLD+L1 76/75.
    let ((a, _), (b, _)) = (euroc_images(0), euroc_images(1));
    for detector in DetectorKind::ALL {
        for matcher in MatcherKind::ALL {
            let (fa, fb, matches) =
                match_images(detector, matcher, MatchCase::FrameToFrame, &a, &b);
            let still = matches
                .iter()
                .filter(|m| {
                    let (p, q) = (
                        features(&fa.segments[m.query]),
                        features(&fb.segments[m.train]),
                    );
                    linetrack_geometry::cross(&p.dir, &(q.mid - p.mid)).abs() < 2.0
                        && direction_angle(&p, &q).to_degrees() < 3.0
                })
                .count();
            let label = format!("{}+{}", detector.name(), matcher.name());
            eprintln!(
                "{label} frame to frame: {} matches, {still} still",
                matches.len()
            );
            assert!(matches.len() >= 55, "{label}: {} matches", matches.len());
            assert!(
                still as f64 >= 0.95 * matches.len() as f64,
                "{label}: {still} of {} still",
                matches.len()
            );
        }
    }
}

#[test]
fn real_data_stereo_matches_point_the_right_way() {
    // Not rectified yet (the datasets crate does that), so only coarse checks: parallel
    // within 5° and the right segment to the left of the left one. The ℓ1 matcher assumes
    // rectified rows and suffers most: measured LBD 47 matches, 40 sane; ℓ1 22, 14 sane.
    let (left, right) = euroc_images(0);
    for matcher in MatcherKind::ALL {
        let (fa, fb, matches) =
            match_images(DetectorKind::Lsd, matcher, MatchCase::Stereo, &left, &right);
        let sane = matches
            .iter()
            .filter(|m| {
                let (p, q) = (
                    features(&fa.segments[m.query]),
                    features(&fb.segments[m.train]),
                );
                direction_angle(&p, &q).to_degrees() < 5.0 && p.mid.x - q.mid.x > -2.0
            })
            .count();
        assert!(
            matches.len() >= 15,
            "{}: {} matches",
            matcher.name(),
            matches.len()
        );
        eprintln!(
            "lsd+{} stereo: {} matches, {sane} sane",
            matcher.name(),
            matches.len()
        );
        let share = if matcher == MatcherKind::Lbd {
            0.8
        } else {
            0.6
        };
        assert!(
            sane as f64 >= share * matches.len() as f64,
            "{}: {sane} of {}",
            matcher.name(),
            matches.len()
        );
    }
}

#[test]
fn real_data_orb_worker_finds_the_extractors_points_frame_after_frame() {
    let (left, right) = euroc_images(0);
    // A smaller image between two full ones: the worker's buffer changes size and back.
    let checkerboard: Vec<u8> = (0..200 * 120)
        .map(|i| {
            if (i % 200 / 20 + i / 200 / 20) % 2 == 0 {
                40
            } else {
                210
            }
        })
        .collect();
    let small = GrayImage::from_pixels(200, 120, &checkerboard, "checkerboard").unwrap();
    let options = OrbOptions::default();
    let mut extractor = OrbExtractor::new(&options).unwrap();
    let mut worker = OrbWorker::new(&options).unwrap();
    let mut on_worker = PointFeatures::default();
    for image in [&left, &right, &small, &right] {
        let mut here = PointFeatures::default();
        let (from_worker, from_here) = worker.extract_while(image, &mut on_worker, || {
            extractor.extract(image, &mut here)
        });
        from_worker.unwrap();
        from_here.unwrap();
        assert!(!here.points.is_empty(), "{}", image.origin());
        assert_eq!(on_worker.points, here.points, "{}", image.origin());
        assert_eq!(on_worker.levels, here.levels);
        assert_eq!(on_worker.descriptors, here.descriptors);
    }
}

/// The worker's stereo matching gives the matches the calling thread's matcher gives (the
/// same matching code: what is tested is the hand-over, the points copied in and the
/// matches swapped out) on real EuRoC pairs (as recorded: unrectified, so a few dozen
/// matches), between extractions on the same worker (its task changes back and forth) and
/// with the caller's own work beside it.
#[test]
fn real_data_the_worker_matches_stereo_points_as_the_caller_does() {
    let options = OrbOptions::default();
    let gates = AppearanceGates::default();
    let mut extractor = OrbExtractor::new(&options).unwrap();
    let mut worker = OrbWorker::new(&options).unwrap();
    let mut matcher = PointMatcher::new();
    let (mut from_worker, mut from_here) = (Vec::new(), Vec::new());
    for frame in [0, 1, 0] {
        let (left, right) = euroc_images(frame);
        let (mut points_l, mut points_r) = (PointFeatures::default(), PointFeatures::default());
        let (right_side, left_side) = worker.extract_while(&right, &mut points_r, || {
            extractor.extract(&left, &mut points_l)
        });
        right_side.unwrap();
        left_side.unwrap();
        let (on_worker, ()) = worker.match_stereo_while(
            [&points_l, &points_r],
            &gates,
            options.min_distance_ratio,
            &mut from_worker,
            || {
                matcher.match_points(
                    MatchCase::Stereo,
                    &points_l,
                    &points_r,
                    &gates,
                    options.min_distance_ratio,
                    &mut from_here,
                )
            },
        );
        on_worker.unwrap();
        assert!(from_here.len() > 10, "frame {frame}: {}", from_here.len());
        assert_eq!(from_worker, from_here, "frame {frame}");
    }
}

#[test]
fn real_data_lbd_describing_only_right_segments_with_a_partner_gives_the_same_stereo_matches() {
    // The matcher stage describes only the right segments that pass the stereo gates with
    // some left one; the others' descriptors are never compared. Same matches, same
    // descriptors for the segments described, fewer described.
    let config = FrontendConfig::default();
    let (mut all_right, mut described_right) = (0, 0);
    for frame in 0..6 {
        let (left_image, right_image) = euroc_images(frame);
        for detector in [DetectorKind::EdgeLines, DetectorKind::Fld] {
            let mut lbd = create_segment_matcher(MatcherKind::Lbd, &config).unwrap();
            let features = |image: &GrayImage| LineFeatures {
                segments: detect_all(detector, image),
                ..LineFeatures::default()
            };
            let (mut left, mut right) = (features(&left_image), features(&right_image));
            let mut right_some = right.clone();
            lbd.describe(&left_image, &mut left).unwrap();
            lbd.describe(&right_image, &mut right).unwrap();
            lbd.describe_stereo_right(&right_image, &left.segments, &mut right_some)
                .unwrap();
            let (mut every, mut some) = (Vec::new(), Vec::new());
            lbd.match_lines(MatchCase::Stereo, &left, &right, &mut every);
            lbd.match_lines(MatchCase::Stereo, &left, &right_some, &mut some);
            let label = format!("frame {frame}, {}", detector.name());
            assert!(every.len() >= 20, "{label}: {} matches", every.len());
            assert_eq!(some, every, "{label}");
            for k in 0..right.segments.len() {
                if let Some(row) = right_some.descriptors.row(k) {
                    assert_eq!(Some(row), right.descriptors.row(k), "{label}: segment {k}");
                }
            }
            all_right += right.descriptors.count_present();
            described_right += right_some.descriptors.count_present();
        }
    }
    eprintln!("right segments described: {described_right} of {all_right}");
    assert!(described_right < all_right);
}
