//! Side-by-side pictures of two segment sets and the matches between them.

use anyhow::Context;
use image::{Rgb, RgbImage};
use linetrack_geometry::Segment;
use linetrack_l1_matcher::Match;
use linetrack_synthetic_segments::SegmentPair;
use std::path::Path;

const BACKGROUND: Rgb<u8> = Rgb([24, 24, 28]);
const UNMATCHED: Rgb<u8> = Rgb([90, 90, 96]);
const WRONG: Rgb<u8> = Rgb([255, 40, 40]);
/// Pixels between the two images.
const GAP_PX: u32 = 8;

/// Draws the first view left, the second right; correct matches share a colour, wrong
/// ones are red, unmatched segments grey.
pub(crate) fn matches_side_by_side(pair: &SegmentPair, matches: &[Match], path: &Path) -> anyhow::Result<()> {
    let (w, h) = (pair.rig.width_px, pair.rig.height_px);
    let mut canvas = RgbImage::from_pixel(2 * w + GAP_PX, h, BACKGROUND);
    let offset = f64::from(w + GAP_PX);
    for s in &pair.first.segments {
        line(&mut canvas, s, 0.0, UNMATCHED, 1);
    }
    for s in &pair.second.segments {
        line(&mut canvas, s, offset, UNMATCHED, 1);
    }
    for (k, m) in matches.iter().enumerate() {
        let truth = pair.first.labels[m.query];
        let colour = if truth.is_some() && truth == pair.second.labels[m.train] { palette(k) } else { WRONG };
        line(&mut canvas, &pair.first.segments[m.query], 0.0, colour, 2);
        line(&mut canvas, &pair.second.segments[m.train], offset, colour, 2);
    }
    canvas.save(path).with_context(|| format!("cannot write {}", path.display()))
}

/// A bright colour per index, spread by the golden angle over the hues from orange to
/// magenta (red is kept for wrong matches).
fn palette(k: usize) -> Rgb<u8> {
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

/// Stamps `thickness`² squares every half pixel along the segment, shifted by `dx`.
fn line(canvas: &mut RgbImage, s: &Segment, dx: f64, colour: Rgb<u8>, thickness: u32) {
    let steps = (2.0 * s.length()).ceil().min(1e5) as usize + 1;
    for k in 0..=steps {
        let t = k as f64 / steps as f64;
        let p = s.start + (s.end - s.start) * t;
        for oy in 0..thickness {
            for ox in 0..thickness {
                let (x, y) = ((p.x + dx).floor() + f64::from(ox), p.y.floor() + f64::from(oy));
                if x >= 0.0 && y >= 0.0 && x < f64::from(canvas.width()) && y < f64::from(canvas.height()) {
                    canvas.put_pixel(x as u32, y as u32, colour);
                }
            }
        }
    }
}
