//! Smoothing and the Sobel gradient, in 16-bit integers over whole rows.

use crate::GrayView;

/// Images narrower or lower than this have no interior pixel and no segments.
pub(crate) const MIN_SIDE_PX: usize = 3;

/// The smoothed image carries this many fractional bits (8-bit values × 16).
pub(crate) const SMOOTH_SHIFT: u32 = 4;

/// Flag: the pixel's edge runs vertically (`|gx| ≥ |gy|`), so it is refined along x.
pub(crate) const VERTICAL: u8 = 1;
/// Flag: the pixel belongs to a drawn edge.
pub(crate) const DRAWN: u8 = 2;

/// The planes computed from one image, each `width × height`, row-major.
#[derive(Debug, Default)]
pub(crate) struct Planes {
    pub(crate) width: usize,
    pub(crate) height: usize,
    /// Horizontal pass of the blur (8-bit values × 16).
    rows_blurred: Vec<u16>,
    /// The smoothed image, 8-bit values × 16 (at most 4080).
    pub(crate) smooth: Vec<u16>,
    /// `|gx| + |gy|` of the Sobel on `smooth` (at most 32640); 0 on the one-pixel border.
    pub(crate) magnitude: Vec<u16>,
    /// [`VERTICAL`] and [`DRAWN`] bits; 0 on the border.
    pub(crate) flags: Vec<u8>,
}

impl Planes {
    /// Fills every plane from `image` (at least [`MIN_SIDE_PX`] each way).
    pub(crate) fn compute(&mut self, image: GrayView<'_>) {
        let (w, h) = (image.width, image.height);
        if (w, h) != (self.width, self.height) {
            let n = w * h;
            self.width = w;
            self.height = h;
            for plane in [
                &mut self.rows_blurred,
                &mut self.smooth,
                &mut self.magnitude,
            ] {
                plane.clear();
                plane.resize(n, 0);
            }
            self.flags.clear();
            self.flags.resize(n, 0);
        }
        for y in 0..h {
            blur_row(image.row(y), &mut self.rows_blurred[y * w..(y + 1) * w]);
        }
        for y in 0..h {
            let row = |dy: isize| {
                let r = (y as isize + dy).clamp(0, h as isize - 1) as usize;
                &self.rows_blurred[r * w..(r + 1) * w]
            };
            let (a, b, c, d, e) = (row(-2), row(-1), row(0), row(1), row(2));
            let out = &mut self.smooth[y * w..(y + 1) * w];
            // Zipped, not indexed: no bounds check in the loop, so it vectorises.
            for (o, ((((&a, &b), &c), &d), &e)) in
                out.iter_mut().zip(a.iter().zip(b).zip(c).zip(d).zip(e))
            {
                // 1 4 6 4 1 over rows: at most 16 × 4080 = 65280, within u16.
                let sum = a + 4 * b + 6 * c + 4 * d + e;
                *o = sum >> (8 - SMOOTH_SHIFT);
            }
        }
        for y in 1..h - 1 {
            let rows = &self.smooth[(y - 1) * w..(y + 2) * w];
            let (a, rest) = rows.split_at(w);
            let (b, c) = rest.split_at(w);
            let magnitude = &mut self.magnitude[y * w + 1..(y + 1) * w - 1];
            let flags = &mut self.flags[y * w + 1..(y + 1) * w - 1];
            sobel_row(a, b, c, magnitude, flags);
        }
    }
}

/// The 1 4 6 4 1 blur of one row (borders repeated), values × 16.
fn blur_row(src: &[u8], out: &mut [u16]) {
    let w = src.len();
    let at = |x: isize| u16::from(src[x.clamp(0, w as isize - 1) as usize]);
    let edge = |x: usize| {
        let x = x as isize;
        at(x - 2) + 4 * at(x - 1) + 6 * at(x) + 4 * at(x + 1) + at(x + 2)
    };
    if w < 5 {
        for (x, o) in out.iter_mut().enumerate() {
            *o = edge(x);
        }
        return;
    }
    let n = w - 4;
    let (a, b, c, d, e) = (
        &src[..n],
        &src[1..n + 1],
        &src[2..n + 2],
        &src[3..n + 3],
        &src[4..n + 4],
    );
    let inner = &mut out[2..n + 2];
    for i in 0..n {
        inner[i] = u16::from(a[i])
            + 4 * u16::from(b[i])
            + 6 * u16::from(c[i])
            + 4 * u16::from(d[i])
            + u16::from(e[i]);
    }
    for x in [0, 1, w - 2, w - 1] {
        out[x] = edge(x);
    }
}

/// Sobel of the interior of one row from the rows above (`a`), at (`b`) and below (`c`):
/// `|gx| + |gy|` into `magnitude` and the [`VERTICAL`] flag into `flags` (both `w − 2`
/// long, for columns 1..w−1). Clears [`DRAWN`].
fn sobel_row(a: &[u16], b: &[u16], c: &[u16], magnitude: &mut [u16], flags: &mut [u8]) {
    let n = magnitude.len();
    let (a0, a1, a2) = (&a[..n], &a[1..n + 1], &a[2..n + 2]);
    let (b0, b2) = (&b[..n], &b[2..n + 2]);
    let (c0, c1, c2) = (&c[..n], &c[1..n + 1], &c[2..n + 2]);
    let flags = &mut flags[..n];
    for i in 0..n {
        // Values are at most 4080: every sum below fits in i16.
        let gx = (a2[i] as i16 - a0[i] as i16)
            + 2 * (b2[i] as i16 - b0[i] as i16)
            + (c2[i] as i16 - c0[i] as i16);
        let gy = (c0[i] as i16 + 2 * c1[i] as i16 + c2[i] as i16)
            - (a0[i] as i16 + 2 * a1[i] as i16 + a2[i] as i16);
        let (ax, ay) = (gx.unsigned_abs(), gy.unsigned_abs());
        magnitude[i] = ax + ay;
        flags[i] = u8::from(ax >= ay);
    }
}

/// The Sobel gradient `(gx, gy)` of `smooth` at interior pixel `index`.
pub(crate) fn sobel_at(smooth: &[u16], width: usize, index: usize) -> (i32, i32) {
    let p = |i: usize| i32::from(smooth[i]);
    let (up, down) = (index - width, index + width);
    let gx =
        (p(up + 1) - p(up - 1)) + 2 * (p(index + 1) - p(index - 1)) + (p(down + 1) - p(down - 1));
    let gy = (p(down - 1) + 2 * p(down) + p(down + 1)) - (p(up - 1) + 2 * p(up) + p(up + 1));
    (gx, gy)
}
