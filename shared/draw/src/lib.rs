//! Pictures for people: two images (or two blank canvases) side by side, with segments,
//! points and the matches between them drawn in colour. Used by the tools that show what
//! the matchers did; pure Rust, so it works without OpenCV.
#![warn(missing_docs)]

use image::{Rgb, RgbImage};
use linetrack_geometry::{Point, Segment};
use std::path::Path;

/// Background of blank canvases.
pub const BACKGROUND: Rgb<u8> = Rgb([24, 24, 28]);
/// Segments and points without a match.
pub const UNMATCHED: Rgb<u8> = Rgb([110, 110, 118]);
/// Matches known to be wrong.
pub const WRONG: Rgb<u8> = Rgb([255, 40, 40]);
/// Pixels between the two halves.
pub const GAP_PX: u32 = 8;

/// Which half of the picture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The first image (left half).
    First,
    /// The second image (right half).
    Second,
}

/// Two equally sized images side by side.
#[derive(Debug, Clone)]
pub struct SideBySide {
    canvas: RgbImage,
    half_width: u32,
}

impl SideBySide {
    /// Two blank `width × height` canvases.
    pub fn blank(width: u32, height: u32) -> Self {
        Self {
            canvas: RgbImage::from_pixel(2 * width + GAP_PX, height, BACKGROUND),
            half_width: width,
        }
    }

    /// Two grayscale images (row-major, `width × height` each), dimmed so that colour
    /// stands out. Pixels missing from a short buffer stay background.
    pub fn from_gray(width: u32, height: u32, first: &[u8], second: &[u8]) -> Self {
        let mut picture = Self::blank(width, height);
        for (pixels, dx) in [(first, 0), (second, width + GAP_PX)] {
            for (k, &v) in pixels.iter().enumerate().take((width * height) as usize) {
                let (x, y) = (k as u32 % width, k as u32 / width);
                let dim = (u16::from(v) * 3 / 5) as u8;
                picture.canvas.put_pixel(x + dx, y, Rgb([dim, dim, dim]));
            }
        }
        picture
    }

    fn offset(&self, side: Side) -> f64 {
        match side {
            Side::First => 0.0,
            Side::Second => f64::from(self.half_width + GAP_PX),
        }
    }

    /// Draws a segment, `thickness` pixels wide.
    pub fn segment(&mut self, side: Side, s: &Segment, colour: Rgb<u8>, thickness: u32) {
        if !s.is_finite() {
            return;
        }
        let dx = self.offset(side);
        // Stamp a square every half pixel along the segment (bounded for absurd lengths).
        let steps = (2.0 * s.length()).ceil().min(1e5) as usize + 1;
        for k in 0..=steps {
            let p = s.start + (s.end - s.start) * (k as f64 / steps as f64);
            self.stamp(p.x + dx, p.y, colour, thickness);
        }
    }

    /// Draws a point as a filled square of side `size` pixels.
    pub fn point(&mut self, side: Side, p: Point, colour: Rgb<u8>, size: u32) {
        let half = f64::from(size) / 2.0;
        self.stamp(p.x + self.offset(side) - half, p.y - half, colour, size);
    }

    fn stamp(&mut self, x: f64, y: f64, colour: Rgb<u8>, size: u32) {
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        for oy in 0..size {
            for ox in 0..size {
                let (px, py) = (x.floor() + f64::from(ox), y.floor() + f64::from(oy));
                if px >= 0.0
                    && py >= 0.0
                    && px < f64::from(self.canvas.width())
                    && py < f64::from(self.canvas.height())
                {
                    self.canvas.put_pixel(px as u32, py as u32, colour);
                }
            }
        }
    }

    /// The picture so far.
    pub fn image(&self) -> &RgbImage {
        &self.canvas
    }

    /// Writes the picture as PNG.
    pub fn save(&self, path: &Path) -> Result<(), image::ImageError> {
        self.canvas.save(path)
    }
}

/// Two grayscale images with their segments (grey) and the matched pairs `(first index,
/// second index)` in one colour per match.
pub fn segment_matches(
    (width, height): (u32, u32),
    pixels: [Option<&[u8]>; 2],
    segments: [&[Segment]; 2],
    matches: impl IntoIterator<Item = (usize, usize)>,
) -> SideBySide {
    let mut picture = match pixels {
        [Some(a), Some(b)] => SideBySide::from_gray(width, height, a, b),
        _ => SideBySide::blank(width, height),
    };
    for (side, set) in [(Side::First, segments[0]), (Side::Second, segments[1])] {
        for s in set {
            picture.segment(side, s, UNMATCHED, 1);
        }
    }
    for (k, (i, j)) in matches.into_iter().enumerate() {
        if let (Some(a), Some(b)) = (segments[0].get(i), segments[1].get(j)) {
            picture.segment(Side::First, a, palette(k), 2);
            picture.segment(Side::Second, b, palette(k), 2);
        }
    }
    picture
}

/// A bright colour per index, spread by the golden angle over the hues from orange to
/// magenta (red is kept for [`WRONG`]).
pub fn palette(k: usize) -> Rgb<u8> {
    let hue = 40.0 + (k as f64 * 137.508) % 280.0;
    let x = 1.0 - ((hue / 60.0) % 2.0 - 1.0).abs();
    let (r, g, b) = match (hue / 60.0) as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    let channel = |v: f64| (90.0 + 165.0 * v) as u8;
    Rgb([channel(r), channel(g), channel(b)])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_land_in_their_half() {
        let mut picture = SideBySide::blank(20, 10);
        picture.segment(
            Side::Second,
            &Segment::from_coords(0.0, 5.0, 19.0, 5.0),
            WRONG,
            1,
        );
        let image = picture.image();
        assert_eq!(image.dimensions(), (48, 10));
        assert_eq!(*image.get_pixel(28, 5), WRONG);
        assert_eq!(*image.get_pixel(5, 5), BACKGROUND);
        // Off-canvas and non-finite input is ignored, not a panic.
        picture.segment(
            Side::First,
            &Segment::from_coords(-50.0, -50.0, 500.0, 500.0),
            WRONG,
            3,
        );
        picture.segment(
            Side::First,
            &Segment::from_coords(f64::NAN, 0.0, 1.0, 1.0),
            WRONG,
            1,
        );
        picture.point(Side::First, Point::new(f64::INFINITY, 0.0), WRONG, 2);
    }

    #[test]
    fn gray_images_are_copied_dimmed_and_palette_avoids_red() {
        let picture = SideBySide::from_gray(2, 1, &[100, 200], &[0, 255]);
        assert_eq!(*picture.image().get_pixel(1, 0), Rgb([120, 120, 120]));
        assert_eq!(
            *picture.image().get_pixel(2 + GAP_PX + 1, 0),
            Rgb([153, 153, 153])
        );
        for k in 0..50 {
            let Rgb([r, g, b]) = palette(k);
            assert!(
                !(r > 200 && g < 120 && b < 120),
                "colour {k} looks like WRONG: {:?}",
                palette(k)
            );
        }
    }
}
