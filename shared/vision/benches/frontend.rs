//! Per-frame cost of every front-end step on the same real 752×480 EuRoC stereo pair
//! (frame 0, left and right; frame 1 for frame to frame), so the paper's Table III
//! (detector × matcher, monocular and stereo) can be rebuilt from one run:
//!
//! - `detect/{lsd,fld,edgelines}`: one image (every [`DetectorKind`], 100 longest kept);
//! - `detect/edgedrawing`: OpenCV's EdgeDrawing (EDLines, ximgproc) on the same image, a
//!   reference for our own `edgelines` (not a pipeline detector; its segments are not
//!   capped or sorted, which would only add to its time);
//! - `mono/{lsd+lbd,fld+l1,edgelines+l1}`: one whole monocular step, measured as one: detect
//!   the next image, describe its segments, match them to the previous image's;
//! - `lbd/describe`: LBD descriptors of one image's 100 segments;
//! - `match/{lbd,l1}/{stereo,frame-to-frame}`: matching two images' segments (ℓ1 stereo
//!   with its photometric check, the profiles already taken);
//! - `l1/describe`: the ℓ1 matcher's intensity profiles of one image's segments;
//! - `l1/stereo-whole`: the whole ℓ1 stereo call with its photometric check, image access
//!   included: profiles of both images + matching;
//! - `orb/extract`: 600 ORB points of one image (the stereo front end's), `orb/match/stereo`;
//! - `orb/extract/odometry`: 1500 ORB points of one image (the odometry's);
//! - `fast-brief/extract/odometry`: the same 1500 points, same levels and scale, from our
//!   own extractor (`[orb] extractor = "fast-brief"`), to compare with the case above;
//!   `{orb,fast-brief}/extract/odometry/4x1.44` and `/1x`: both with 4 levels of 1.44 (about
//!   the same span of scales) and with one level;
//! - `orb/match/frame-to-frame/odometry`: the odometry's frame-to-frame point search (1500
//!   points an image, a 30 px window);
//! - `orb/refine-track`: the sub-pixel refinement of frame 0's frame-to-frame point matches;
//! - `orb/refine-stereo`: the sub-pixel columns of frame 0's stereo point matches;
//! - `stereo-frontend/{orb-opencv,fast-brief}`: the whole stereo front end of one frame
//!   with each point extractor: both images' segments (edgelines), ℓ1 profiles and stereo
//!   match; both images' 1500 points (8 levels of 1.2), their stereo match and every
//!   partner's sub-pixel column (the 8 ms bar; the contrast stretch, `stretch`, apart);
//!   `…/row-search`: the same with `[orb] stereo = "row-search"`: the left image's points
//!   only, their partners searched along the right image's rows, then refined;
//! - `stereo-partners/{descriptors,row-search}`: the points' stereo step alone, given the
//!   left image's 1500 points: the right image's extracted and matched, or the row search;
//! - `stretch`: the contrast stretch of one image (the odometry's default gain limit, 4).
//!
//! Monocular tracking of a frame = detect + describe + frame-to-frame match; stereo =
//! 2 × (detect + describe) + stereo match + frame-to-frame match. The data is located as in
//! the tests (`LINETRACK_EUROC_DIR`, else ../shared/data beside the workspace).

#![allow(clippy::expect_used)] // a bench on fixed inputs: failing loudly is right

use criterion::{Criterion, criterion_group, criterion_main};
use linetrack_geometry::MatchCase;
use linetrack_vision::{
    AppearanceGates, DetectorKind, FrontendConfig, GrayImage, HammingMatcher, LineFeatures,
    MatcherKind, OrbExtractor, OrbOptions, PointExtractor, PointExtractorKind, PointFeatures,
    PointMatcher, PointStereo, RowSearch, RowSearchSettings, create_detector,
    create_segment_matcher, points_may_match, refine_stereo_column, refine_track,
};
use opencv::core::{Vec4f, Vector};
use opencv::ximgproc::{self, EdgeDrawingTrait};
use std::hint::black_box;

/// The odometry's `frame_to_frame_ratio` (configs/odometry.toml).
const FRAME_TO_FRAME_RATIO: f64 = 1.5;

fn load(index: usize) -> (GrayImage, GrayImage) {
    let (l, r) = linetrack_test_data::euroc_stereo_pair(index)
        .expect("EuRoC excerpt (set LINETRACK_EUROC_DIR)");
    (
        GrayImage::load(&l).expect("left image"),
        GrayImage::load(&r).expect("right image"),
    )
}

fn bench_frontend(c: &mut Criterion) {
    let config = FrontendConfig::default();
    let (left, right) = load(0);
    let (next, _) = load(1);

    let mut group = c.benchmark_group("frontend");
    for kind in DetectorKind::ALL {
        let mut detector = create_detector(kind, &config).expect("detector");
        let mut out = Vec::new();
        group.bench_function(format!("detect/{}", kind.name()), |b| {
            b.iter(|| detector.detect(black_box(&left), &mut out))
        });
    }

    let mut edge_drawing = ximgproc::create_edge_drawing().expect("EdgeDrawing");
    let mut lines = Vector::<Vec4f>::new();
    group.bench_function("detect/edgedrawing", |b| {
        b.iter(|| {
            edge_drawing.detect_edges(black_box(left.mat()))?;
            edge_drawing.detect_lines(&mut lines)?;
            Ok::<_, opencv::Error>(lines.len())
        })
    });

    // A whole monocular step: detect, describe, match to the previous frame.
    for (detector_kind, matcher_kind) in [
        (DetectorKind::Lsd, MatcherKind::Lbd),
        (DetectorKind::Fld, MatcherKind::L1),
        (DetectorKind::EdgeLines, MatcherKind::L1),
    ] {
        let mut detector = create_detector(detector_kind, &config).expect("detector");
        let mut matcher = create_segment_matcher(matcher_kind, &config).expect("matcher");
        let mut previous = LineFeatures::default();
        detector
            .detect(&left, &mut previous.segments)
            .expect("detection");
        matcher.describe(&left, &mut previous).expect("describe");
        let mut current = LineFeatures::default();
        let mut matches = Vec::new();
        let name = format!("mono/{}+{}", detector_kind.name(), matcher_kind.name());
        group.bench_function(name, |b| {
            b.iter(|| {
                detector.detect(black_box(&next), &mut current.segments)?;
                matcher.describe(&next, &mut current)?;
                matcher.match_lines(MatchCase::FrameToFrame, &previous, &current, &mut matches);
                Ok::<_, linetrack_vision::VisionError>(matches.len())
            })
        });
    }

    // Segments of the three images, detected once with LSD (the matchers' input).
    let mut detector = create_detector(DetectorKind::Lsd, &config).expect("detector");
    let mut features = |image: &GrayImage| {
        let mut f = LineFeatures::default();
        detector.detect(image, &mut f.segments).expect("detection");
        f
    };
    let (mut l0, mut r0, mut l1) = (features(&left), features(&right), features(&next));

    let mut lbd = create_segment_matcher(MatcherKind::Lbd, &config).expect("lbd");
    group.bench_function("lbd/describe", |b| {
        b.iter(|| lbd.describe(black_box(&left), &mut l0))
    });
    lbd.describe(&left, &mut l0).expect("lbd");
    lbd.describe(&right, &mut r0).expect("lbd");
    lbd.describe(&next, &mut l1).expect("lbd");
    let mut out = Vec::new();
    for (case, name, second) in [
        (MatchCase::Stereo, "stereo", &r0),
        (MatchCase::FrameToFrame, "frame-to-frame", &l1),
    ] {
        group.bench_function(format!("match/lbd/{name}"), |b| {
            b.iter(|| lbd.match_lines(case, black_box(&l0), black_box(second), &mut out))
        });
    }
    let mut l1_matcher = create_segment_matcher(MatcherKind::L1, &config).expect("l1");
    let segments_only = |f: &LineFeatures| LineFeatures {
        segments: f.segments.clone(),
        ..LineFeatures::default()
    };
    let (mut g0, mut h0, g1) = (segments_only(&l0), segments_only(&r0), segments_only(&l1));
    group.bench_function("l1/describe", |b| {
        b.iter(|| l1_matcher.describe(black_box(&left), &mut g0))
    });
    group.bench_function("l1/stereo-whole", |b| {
        b.iter(|| {
            l1_matcher.describe(black_box(&left), &mut g0)?;
            l1_matcher.describe(black_box(&right), &mut h0)?;
            l1_matcher.match_lines(MatchCase::Stereo, &g0, &h0, &mut out);
            Ok::<_, linetrack_vision::VisionError>(out.len())
        })
    });
    for (case, name, second) in [
        (MatchCase::Stereo, "stereo", &h0),
        (MatchCase::FrameToFrame, "frame-to-frame", &g1),
    ] {
        group.bench_function(format!("match/l1/{name}"), |b| {
            b.iter(|| l1_matcher.match_lines(case, black_box(&g0), black_box(second), &mut out))
        });
    }

    let mut orb = OrbExtractor::new(&config.orb).expect("orb");
    let (mut p_left, mut p_right) = (PointFeatures::default(), PointFeatures::default());
    group.bench_function("orb/extract", |b| {
        b.iter(|| orb.extract(black_box(&left), &mut p_left))
    });
    orb.extract(&left, &mut p_left).expect("orb");
    orb.extract(&right, &mut p_right).expect("orb");
    // The odometry's default gain limit (`max_contrast_gain`), as both stages stretch.
    group.bench_function("stretch", |b| {
        b.iter(|| linetrack_vision::stretch_contrast(black_box(&left), 4.0))
    });
    // Every pair compared (the matcher before the grid) against the grid's candidates:
    // the same matches.
    let mut hamming = HammingMatcher::new();
    let mut point_matcher = PointMatcher::new();
    for (case, name, second) in [
        (MatchCase::Stereo, "stereo", &p_right),
        (MatchCase::FrameToFrame, "frame-to-frame", &p_left),
    ] {
        let gates = &config.appearance_gates;
        let admit =
            |i: usize, j: usize| points_may_match(case, gates, p_left.points[i], second.points[j]);
        group.bench_function(format!("orb/match/{name}/every-pair"), |b| {
            b.iter(|| {
                hamming.match_mutual(
                    &p_left.descriptors,
                    &second.descriptors,
                    config.orb.min_distance_ratio,
                    admit,
                    &mut out,
                )
            })
        });
        group.bench_function(format!("orb/match/{name}/grid"), |b| {
            b.iter(|| {
                point_matcher.match_points(
                    case,
                    black_box(&p_left),
                    black_box(second),
                    gates,
                    config.orb.min_distance_ratio,
                    &mut out,
                )
            })
        });
    }
    // The odometry's frame-to-frame search with its defaults (configs/odometry.toml):
    // 1500 points an image, frame 0's left points looked for among frame 1's within the
    // window it uses once a motion is known (`predicted_window_px`, 30 px; here around
    // where they were, every point wanted), its ratio test (`frame_to_frame_ratio`).
    let odometry_orb = OrbOptions {
        features: 1500,
        ..config.orb
    };
    let mut odometry_extractor = OrbExtractor::new(&odometry_orb).expect("ORB");
    let (mut o_first, mut o_second) = (PointFeatures::default(), PointFeatures::default());
    group.bench_function("orb/extract/odometry", |b| {
        b.iter(|| odometry_extractor.extract(black_box(&left), &mut o_first))
    });
    // Both extractors at the odometry's settings (8 levels of 1.2), then at a shallower
    // pyramid spanning about the same scales (4 levels of 1.44) and at one level.
    for (levels, scale_factor, suffix) in [(8, 1.2, ""), (4, 1.44, "/4x1.44"), (1, 1.2, "/1x")] {
        for extractor in PointExtractorKind::ALL {
            let options = OrbOptions {
                extractor,
                levels,
                scale_factor,
                ..odometry_orb
            };
            if extractor == PointExtractorKind::OrbOpenCv && suffix.is_empty() {
                continue; // `orb/extract/odometry` above
            }
            let mut points_extractor = PointExtractor::new(&options).expect("extractor");
            let mut points = PointFeatures::default();
            let name = match extractor {
                PointExtractorKind::OrbOpenCv => format!("orb/extract/odometry{suffix}"),
                PointExtractorKind::FastBrief => format!("fast-brief/extract/odometry{suffix}"),
            };
            group.bench_function(name, |b| {
                b.iter(|| points_extractor.extract(black_box(&left), &mut points))
            });
        }
    }
    // The whole stereo front end of one EuRoC frame, as the odometry runs it: both images'
    // segments with the pipeline's default detector (edgelines), their ℓ1 profiles and
    // stereo match; both images' points (the odometry's 1500, 8 levels of 1.2) with each
    // extractor, their stereo match and the sub-pixel column of every partner.
    let mut line_detector = create_detector(DetectorKind::EdgeLines, &config).expect("detector");
    let mut line_matcher = create_segment_matcher(MatcherKind::L1, &config).expect("l1");
    let (mut lines_l, mut lines_r) = (LineFeatures::default(), LineFeatures::default());
    let mut line_matches = Vec::new();
    let mut row_search = RowSearch::new();
    let row_settings = RowSearchSettings::of(&odometry_orb, &config.appearance_gates);
    // The points' stereo step alone, given the left image's 1500 points (OpenCV's ORB):
    // the right image's points extracted and matched by descriptor, against the left
    // points searched for along the right image's rows.
    let mut right_extractor = PointExtractor::new(&odometry_orb).expect("extractor");
    let (mut left_points, mut right_points) = (PointFeatures::default(), PointFeatures::default());
    right_extractor
        .extract(&left, &mut left_points)
        .expect("left points");
    group.bench_function("stereo-partners/descriptors", |b| {
        b.iter(|| {
            right_extractor.extract(black_box(&right), &mut right_points)?;
            point_matcher.match_points(
                MatchCase::Stereo,
                &left_points,
                &right_points,
                &config.appearance_gates,
                odometry_orb.min_distance_ratio,
                &mut out,
            );
            Ok::<_, linetrack_vision::VisionError>(out.len())
        })
    });
    group.bench_function("stereo-partners/row-search", |b| {
        b.iter(|| {
            row_search.find_partners(
                [&left, black_box(&right)],
                &left_points,
                &row_settings,
                &mut right_points,
                &mut out,
            );
            out.len()
        })
    });
    for (extractor, stereo) in PointExtractorKind::ALL
        .into_iter()
        .flat_map(|e| [(e, PointStereo::Descriptors), (e, PointStereo::RowSearch)])
    {
        let options = OrbOptions {
            extractor,
            ..odometry_orb
        };
        let mut points_extractor = PointExtractor::new(&options).expect("extractor");
        let (mut points_l, mut points_r) = (PointFeatures::default(), PointFeatures::default());
        let name = match stereo {
            PointStereo::Descriptors => format!("stereo-frontend/{}", extractor.name()),
            PointStereo::RowSearch => format!("stereo-frontend/{}/row-search", extractor.name()),
        };
        group.bench_function(name, |b| {
            b.iter(|| {
                line_detector.detect(black_box(&left), &mut lines_l.segments)?;
                line_detector.detect(black_box(&right), &mut lines_r.segments)?;
                line_matcher.describe(&left, &mut lines_l)?;
                line_matcher.describe(&right, &mut lines_r)?;
                line_matcher.match_lines(MatchCase::Stereo, &lines_l, &lines_r, &mut line_matches);
                points_extractor.extract(black_box(&left), &mut points_l)?;
                match stereo {
                    PointStereo::Descriptors => {
                        points_extractor.extract(black_box(&right), &mut points_r)?;
                        point_matcher.match_points(
                            MatchCase::Stereo,
                            &points_l,
                            &points_r,
                            &config.appearance_gates,
                            odometry_orb.min_distance_ratio,
                            &mut out,
                        );
                    }
                    PointStereo::RowSearch => row_search.find_partners(
                        [&left, black_box(&right)],
                        &points_l,
                        &row_settings,
                        &mut points_r,
                        &mut out,
                    ),
                }
                let refined = out
                    .iter()
                    .filter_map(|m| {
                        refine_stereo_column(
                            &left,
                            &right,
                            points_l.points[m.query],
                            points_r.points[m.train],
                        )
                    })
                    .count();
                Ok::<_, linetrack_vision::VisionError>((line_matches.len(), refined))
            })
        });
    }
    odometry_extractor
        .extract(&left, &mut o_first)
        .expect("orb");
    odometry_extractor
        .extract(&next, &mut o_second)
        .expect("orb");
    let window = AppearanceGates {
        max_displacement_px: 30.0,
        ..config.appearance_gates
    };
    group.bench_function("orb/match/frame-to-frame/odometry", |b| {
        b.iter(|| {
            point_matcher.match_points(
                MatchCase::FrameToFrame,
                black_box(&o_first),
                black_box(&o_second),
                &window,
                FRAME_TO_FRAME_RATIO,
                &mut out,
            )
        })
    });
    // The positions of frame 0's left points' matches among `second`'s points.
    let mut matched_pairs = |case, second: &PointFeatures| {
        point_matcher.match_points(
            case,
            &p_left,
            second,
            &config.appearance_gates,
            config.orb.min_distance_ratio,
            &mut out,
        );
        out.iter()
            .map(|m| (p_left.points[m.query], second.points[m.train]))
            .collect::<Vec<_>>()
    };
    // Sub-pixel tracking of every frame-to-frame point match of frame 0's left image in
    // frame 1's (the odometry runs it on each tracked landmark), and the sub-pixel columns
    // of every stereo point match of frame 0 (the odometry refines each stereo partner it
    // triangulates).
    let mut p_next = PointFeatures::default();
    orb.extract(&next, &mut p_next).expect("orb");
    let tracks = matched_pairs(MatchCase::FrameToFrame, &p_next);
    let partners = matched_pairs(MatchCase::Stereo, &p_right);
    group.bench_function("orb/refine-track", |b| {
        b.iter(|| {
            tracks
                .iter()
                .filter_map(|&(from, to)| refine_track(black_box(&left), &next, from, to))
                .count()
        })
    });
    group.bench_function("orb/refine-stereo", |b| {
        b.iter(|| {
            partners
                .iter()
                .filter_map(|&(l, r)| refine_stereo_column(black_box(&left), &right, l, r))
                .count()
        })
    });
    group.finish();
}

criterion_group!(benches, bench_frontend);
criterion_main!(benches);
