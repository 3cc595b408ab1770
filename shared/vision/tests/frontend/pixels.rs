//! Borrowed pixels read in place, and a PGM scaled by its own maxval.

use super::*;
use linetrack_test_data::Scratch;

#[test]
fn borrowed_pixels_are_read_in_place_and_detect_like_owned_ones() {
    let (w, h) = (320, 240);
    let pixels = test_card(w, h);
    let card = GrayImage::from_pixels(w, h, &pixels, "owned card").unwrap();
    let view = GrayImage::borrow_pixels(w, h, &pixels, "borrowed card").unwrap();
    // The view's Mat reads the caller's buffer itself, no copy.
    assert_eq!(view.pixels().unwrap().as_ptr(), pixels.as_ptr());
    let mut detector = create_detector(DetectorKind::Lsd, &FrontendConfig::default()).unwrap();
    let (mut from_view, mut from_owned) = (Vec::new(), Vec::new());
    detector.detect(&view, &mut from_view).unwrap();
    detector.detect(&card, &mut from_owned).unwrap();
    assert!(!from_owned.is_empty());
    assert_eq!(from_view, from_owned);
    // A wrong length names the image.
    let err = GrayImage::borrow_pixels(w, h + 1, &pixels, "short buffer")
        .unwrap_err()
        .to_string();
    assert!(err.contains("short buffer"), "{err}");
}

#[test]
fn a_pgm_is_scaled_by_its_own_maxval() {
    // A 12-bit PGM (maxval 4095) and a 10-bit one hold their data at their own full
    // scale; PGM with a small 8-bit maxval too. Written by hand: the format is that simple.
    for (maxval, value, grey) in [
        (4095u32, 4095u32, 255u8),
        (4095, 2048, 128), // 2048 · 255 / 4095 = 127.55
        (1023, 1023, 255),
        (65535, 40000, 156),
        (100, 50, 128), // 50 · 255 / 100 = 127.5, rounded to even by OpenCV
        (255, 128, 128),
    ] {
        let mut bytes = format!("P5\n4 2\n{maxval}\n").into_bytes();
        for _ in 0..8 {
            if maxval > 255 {
                bytes.extend_from_slice(&u16::try_from(value).unwrap().to_be_bytes());
            } else {
                bytes.push(u8::try_from(value).unwrap());
            }
        }
        let dir = Scratch::new("vision", &format!("maxval-{maxval}-{value}"));
        let path = dir.join("image.pgm");
        std::fs::write(&path, &bytes).unwrap();
        let image = GrayImage::load(&path).unwrap();
        assert_eq!((image.width(), image.height()), (4, 2));
        assert!(
            image.pixels().unwrap().iter().all(|&p| p == grey),
            "maxval {maxval}, value {value}: {:?}",
            image.pixels()
        );
    }
}
