//! Bad input: image files refused naming the file, colour and 16-bit images converted,
//! blank and tiny images survived, segments outside the image skipped.

use super::*;
use linetrack_test_data::Scratch;

fn error_text(result: Result<GrayImage, VisionError>) -> String {
    result.expect_err("bad input must be refused").to_string()
}

#[test]
fn bad_image_files_are_refused_naming_the_file() {
    let dir = Scratch::new("vision", "bad-files");
    let missing = dir.join("missing.png");
    let text = error_text(GrayImage::load(&missing));
    assert!(
        text.contains(missing.to_str().unwrap()) && text.contains("cannot read"),
        "{text}"
    );

    let empty = dir.join("empty.png");
    std::fs::write(&empty, b"").unwrap();
    let text = error_text(GrayImage::load(&empty));
    assert!(
        text.contains(empty.to_str().unwrap()) && text.contains("empty"),
        "{text}"
    );

    let corrupt = dir.join("corrupt.png");
    std::fs::write(&corrupt, b"\x89PNG\r\n\x1a\nthis is not really a png").unwrap();
    let text = error_text(GrayImage::load(&corrupt));
    assert!(
        text.contains(corrupt.to_str().unwrap()) && text.contains("not a decodable image"),
        "{text}"
    );

    // A truncated real PNG.
    let whole = std::fs::read(euroc_stereo_pair(0).map(|p| p.0).unwrap_or_default())
        .unwrap_or_else(|_| {
            let mut buffer = Vector::<u8>::new();
            imgcodecs::imencode(".png", card(0).mat(), &mut buffer, &Vector::new()).unwrap();
            buffer.as_slice().to_vec()
        });
    let truncated = dir.join("truncated.png");
    std::fs::write(&truncated, &whole[..whole.len() / 3]).unwrap();
    let text = error_text(GrayImage::load(&truncated));
    assert!(text.contains(truncated.to_str().unwrap()), "{text}");
}

#[test]
fn only_regular_files_of_a_sane_size_are_read() {
    // A folder and a FIFO (which would block a plain read forever) are refused unread.
    let folder = Scratch::new("vision", "not-a-file");
    let text = error_text(GrayImage::load(&folder));
    assert!(
        text.contains(folder.to_str().unwrap()) && text.contains("not a regular file"),
        "{text}"
    );
    let fifo = folder.join("fifo.png");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    let text = error_text(GrayImage::load(&fifo));
    assert!(
        text.contains("fifo.png") && text.contains("not a regular file"),
        "{text}"
    );

    // An image over the pixel limit is refused from its header, before it is decoded.
    let side = 10_001;
    let big = Mat::new_rows_cols_with_default(side, side, opencv::core::CV_8UC1, Scalar::all(0.0))
        .unwrap();
    let mut buffer = Vector::<u8>::new();
    imgcodecs::imencode(".png", &big, &mut buffer, &Vector::new()).unwrap();
    drop(big);
    let text = error_text(GrayImage::decode(buffer.as_slice(), "big.png"));
    assert!(
        text.contains("big.png")
            && text.contains("10001×10001 pixels")
            && text.contains("too large"),
        "{text}"
    );
}

#[test]
fn colour_and_sixteen_bit_images_are_converted_to_grey_once() {
    // BGR (30, 100, 200): grey = 0.114·30 + 0.587·100 + 0.299·200 = 121.9 → 122.
    // 16-bit 40000: 40000 · 255 / 65535 = 155.6 → 156.
    for (name, mat_type, value, grey) in [
        (
            "colour.png",
            opencv::core::CV_8UC3,
            Scalar::new(30.0, 100.0, 200.0, 0.0),
            122u8,
        ),
        (
            "colour-alpha.png",
            opencv::core::CV_8UC4,
            Scalar::new(30.0, 100.0, 200.0, 255.0),
            122,
        ),
        (
            "deep.png",
            opencv::core::CV_16UC1,
            Scalar::all(40000.0),
            156,
        ),
        (
            "deep-colour.png",
            opencv::core::CV_16UC3,
            Scalar::all(40000.0),
            156,
        ),
    ] {
        let mat = Mat::new_rows_cols_with_default(20, 30, mat_type, value).unwrap();
        let mut bytes = Vector::<u8>::new();
        imgcodecs::imencode(".png", &mat, &mut bytes, &Vector::new()).unwrap();
        let dir = Scratch::new("vision", "grey-once");
        let path = dir.join(name);
        std::fs::write(&path, bytes.as_slice()).unwrap();
        let image = GrayImage::load(&path).unwrap();
        assert_eq!((image.width(), image.height()), (30, 20), "{name}");
        let pixels = image.pixels().unwrap();
        assert!(
            pixels.iter().all(|&p| p == grey),
            "{name}: {:?}",
            &pixels[..4]
        );
    }
}

#[test]
fn float_images_are_refused_with_what_was_found() {
    let mat =
        Mat::new_rows_cols_with_default(20, 30, opencv::core::CV_32FC1, Scalar::all(0.5)).unwrap();
    let mut bytes = Vector::<u8>::new();
    imgcodecs::imencode(".tiff", &mat, &mut bytes, &Vector::new()).unwrap();
    let dir = Scratch::new("vision", "float");
    let path = dir.join("float.tiff");
    std::fs::write(&path, bytes.as_slice()).unwrap();
    let text = error_text(GrayImage::load(&path));
    assert!(
        text.contains(path.to_str().unwrap()) && text.contains("CV_32F"),
        "{text}"
    );
}

#[test]
fn mismatched_sizes_and_bad_raw_pixels_are_refused() {
    let a = GrayImage::from_pixels(10, 10, &[0; 100], "a.png").unwrap();
    let b = GrayImage::from_pixels(10, 8, &[0; 80], "b.png").unwrap();
    let text = a.ensure_same_size(&b).unwrap_err().to_string();
    assert!(text.contains("a.png") && text.contains("b.png"), "{text}");
    assert!(a.ensure_same_size(&a.clone()).is_ok());
    assert!(GrayImage::from_pixels(10, 10, &[0; 99], "short").is_err());
    assert!(GrayImage::from_pixels(0, 10, &[], "zero").is_err());
}

#[test]
fn detectors_and_matchers_survive_blank_and_tiny_images() {
    let blank = GrayImage::from_pixels(64, 48, &[128; 64 * 48], "blank").unwrap();
    let tiny = GrayImage::from_pixels(2, 2, &[0, 255, 255, 0], "tiny").unwrap();
    for image in [&blank, &tiny] {
        for detector in DetectorKind::ALL {
            for matcher in MatcherKind::ALL {
                let (fa, _, matches) =
                    match_images(detector, matcher, MatchCase::Stereo, image, image);
                assert!(fa.segments.len() <= 100 && matches.len() <= fa.segments.len());
            }
        }
    }
}

#[test]
fn lbd_skips_segments_outside_the_image_and_degenerate_ones() {
    let image = card(0);
    let mut extractor = LbdExtractor::new().unwrap();
    let segments = [
        Segment::from_coords(100.0, 50.0, 100.0, 300.0),
        Segment::from_coords(f64::NAN, 0.0, 5.0, 5.0),
        Segment::from_coords(5000.0, 5000.0, 6000.0, 6000.0),
        Segment::from_coords(10.0, 10.0, 10.0, 10.0),
    ];
    let mut out = BinaryDescriptors::default();
    extractor.compute(&image, &segments, &mut out).unwrap();
    assert_eq!(out.len(), 4);
    assert!(out.row(0).is_some());
    assert!(out.row(1).is_none() && out.row(2).is_none() && out.row(3).is_none());
}
