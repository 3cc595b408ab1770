//! Gain and bias with clamping, and the contrast stretch.

use super::*;

#[test]
fn perturbation_applies_gain_and_bias_with_clamping() {
    let image = GrayImage::from_pixels(4, 1, &[0, 10, 100, 200], "ramp").unwrap();
    let bright = perturb(&image, 2.0, 20.0).unwrap();
    assert_eq!(bright.pixels().unwrap(), &[20, 40, 220, 255]);
    let dark = perturb(&image, 0.5, 0.0).unwrap();
    assert_eq!(dark.pixels().unwrap(), &[0, 5, 50, 100]);
    assert!(perturb(&image, f64::NAN, 0.0).is_err());
    assert!(perturb(&image, -1.0, 0.0).is_err());
    assert!(perturb(&image, 1.0, f64::INFINITY).is_err());
}

#[test]
fn a_dark_image_is_stretched_to_the_full_range_and_a_bright_one_is_left_alone() {
    // 1000 pixels from 10 to 40: the 0.5 % tails are 5 pixels at each end.
    let dark: Vec<u8> = (0..1000).map(|k| 10 + (k * 31 / 1000) as u8).collect();
    let image = GrayImage::from_pixels(100, 10, &dark, "dark").unwrap();
    let (stretched, gain) = stretch_contrast(&image, 16.0).unwrap().expect("stretched");
    // The tails end at 10 and 40 (0.5th and 99.5th percentiles): 255 / 30.
    assert!((gain - 8.5).abs() < 1e-9, "{gain}");
    let pixels = stretched.pixels().unwrap();
    assert_eq!(pixels[0], 0);
    assert!(pixels[999] >= 250, "{}", pixels[999]);
    // The gain is capped.
    let (capped, gain) = stretch_contrast(&image, 2.0).unwrap().expect("stretched");
    assert_eq!(gain, 2.0);
    assert_eq!(capped.pixels().unwrap()[999], 60);
    assert!(stretch_contrast(&image, 1.0).unwrap().is_none());
    let full: Vec<u8> = (0..1000).map(|k| (k * 256 / 1000) as u8).collect();
    let bright = GrayImage::from_pixels(100, 10, &full, "full").unwrap();
    assert!(stretch_contrast(&bright, 16.0).unwrap().is_none());
}

#[test]
fn the_kept_stretch_gives_the_same_pixels_in_one_buffer() {
    // Odd widths: rows that do not split into fours (the histogram's remainder).
    let mut stretch = ContrastStretch::new();
    for (width, height) in [(101, 10), (7, 143), (1, 1), (3, 5)] {
        let n = width * height;
        let dark: Vec<u8> = (0..n).map(|k| 10 + (k * 31 / n) as u8).collect();
        let image = GrayImage::from_pixels(width, height, &dark, "dark").unwrap();
        let once = stretch_contrast(&image, 16.0).unwrap();
        let first = stretch
            .apply(&image, 16.0)
            .unwrap()
            .pixels()
            .map(<[u8]>::as_ptr);
        let kept = stretch.apply(&image, 16.0).unwrap();
        match once {
            Some((once, _)) => {
                assert_eq!(
                    kept.pixels().unwrap(),
                    once.pixels().unwrap(),
                    "{width}×{height}"
                );
                assert!(!std::ptr::eq(kept, &image));
                // The next frame of the same size goes where the last one went.
                assert_eq!(kept.pixels().map(<[u8]>::as_ptr), first);
            }
            None => assert!(std::ptr::eq(kept, &image), "{width}×{height}"),
        }
    }
    // Not stretched: the image itself.
    let full: Vec<u8> = (0..1000).map(|k| (k * 256 / 1000) as u8).collect();
    let bright = GrayImage::from_pixels(100, 10, &full, "full").unwrap();
    assert!(std::ptr::eq(stretch.apply(&bright, 16.0).unwrap(), &bright));
}
