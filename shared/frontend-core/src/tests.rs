use super::*;

/// A `width`×`height` image, dark with a bright axis-aligned rectangle and a bright
/// triangle (slanted edges), each pixel `stride` bytes after the row start.
fn scene(width: usize, height: usize, stride: usize) -> Vec<u8> {
    let mut pixels = vec![7u8; stride * height];
    for y in 0..height {
        for x in 0..width {
            let in_box =
                (width / 5..width / 2).contains(&x) && (height / 4..height * 3 / 4).contains(&y);
            let in_triangle =
                x > width * 3 / 5 && y > height / 5 && (x - width * 3 / 5) < (y - height / 5);
            if in_box || in_triangle {
                pixels[y * stride + x] = 200;
            }
        }
    }
    pixels
}

fn detect(pixels: &[u8], width: usize, height: usize, stride: usize) -> Vec<Segment> {
    let mut detector = EdgeLinesSegments::new(&EdgeLinesOptions::default(), LineOptions::default());
    let mut out = vec![Segment::from_coords(1.0, 2.0, 3.0, 4.0)];
    let view = GrayView::new(pixels, width, height, stride).expect("the scene fits its view");
    detector.detect(view, &mut out);
    out
}

#[test]
fn segments_lie_in_the_image_longest_first() {
    let (width, height) = (160, 120);
    let segments = detect(&scene(width, height, width), width, height, width);
    assert!(
        segments.len() >= 4,
        "the box's four sides at least: {segments:?}"
    );
    for s in &segments {
        for p in [s.start, s.end] {
            assert!((0.0..=(width - 1) as f64).contains(&p.x), "{s:?}");
            assert!((0.0..=(height - 1) as f64).contains(&p.y), "{s:?}");
        }
        assert!(s.length() >= LineOptions::default().min_length_px, "{s:?}");
    }
    assert!(
        segments.windows(2).all(|w| w[0].length() >= w[1].length()),
        "longest first: {segments:?}"
    );
}

#[test]
fn a_strided_view_gives_what_the_packed_image_gives() {
    let (width, height) = (160, 120);
    let packed = detect(&scene(width, height, width), width, height, width);
    let strided = detect(&scene(width, height, width + 37), width, height, width + 37);
    assert!(!packed.is_empty());
    assert_eq!(packed, strided);
}

#[test]
fn images_under_the_minimum_side_have_no_segments() {
    for (width, height) in [
        (MIN_IMAGE_SIDE_PX - 1, 60),
        (60, MIN_IMAGE_SIDE_PX - 1),
        (0, 0),
    ] {
        let segments = detect(&scene(width, height, width), width, height, width);
        assert!(segments.is_empty(), "{width}×{height}: {segments:?}");
    }
}

#[test]
fn max_segments_and_min_length_bound_what_is_kept() {
    let (width, height) = (160, 120);
    let pixels = scene(width, height, width);
    let keep = LineOptions {
        max_segments: 2,
        min_length_px: 30.0,
    };
    let mut detector = EdgeLinesSegments::new(&EdgeLinesOptions::default(), keep);
    let mut out = Vec::new();
    detector.detect(
        GrayView::packed(&pixels, width, height).expect("fits"),
        &mut out,
    );
    assert_eq!(out.len(), 2, "{out:?}");
    assert!(out.iter().all(|s| s.length() >= 30.0), "{out:?}");
    assert_eq!(detector.params().max_segments, 2);
}

#[test]
fn each_bad_field_is_named() {
    let base = EdgeLinesOptions::default();
    let cases = [
        (
            EdgeLinesOptions {
                gradient_threshold: 0,
                ..base
            },
            "edgelines.gradient_threshold",
        ),
        (
            EdgeLinesOptions {
                scan_interval: 0,
                ..base
            },
            "edgelines.scan_interval",
        ),
        (
            EdgeLinesOptions {
                max_fit_error_px: f32::NAN,
                ..base
            },
            "edgelines.max_fit_error_px",
        ),
        (
            EdgeLinesOptions {
                min_aligned_fraction: 1.5,
                ..base
            },
            "edgelines.min_aligned_fraction",
        ),
    ];
    assert_eq!(base.validate(), Ok(()));
    for (options, field) in cases {
        let error = options.validate().expect_err(field);
        assert_eq!(error.field, field);
        assert!(
            error
                .to_string()
                .starts_with(&format!("field `{field}` = ")),
            "{error}"
        );
    }
    let lines = LineOptions {
        min_length_px: f64::INFINITY,
        ..LineOptions::default()
    };
    assert_eq!(
        lines.validate().expect_err("inf").field,
        "lines.min_length_px"
    );
    assert_eq!(LineOptions::default().validate(), Ok(()));
}

#[test]
fn tables_take_defaults_and_refuse_unknown_keys() {
    let options: EdgeLinesOptions = toml::from_str("scan_interval = 3").expect("parses");
    assert_eq!(
        options,
        EdgeLinesOptions {
            scan_interval: 3,
            ..EdgeLinesOptions::default()
        }
    );
    let error = toml::from_str::<EdgeLinesOptions>("scan_intervall = 3").expect_err("unknown key");
    assert!(error.to_string().contains("scan_intervall"), "{error}");
}
