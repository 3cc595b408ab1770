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
                *o = binomial5(a, b, c, d, e) >> (8 - SMOOTH_SHIFT);
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
        // At most 16 × 255 = 4080.
        inner[i] = binomial5(
            u16::from(a[i]),
            u16::from(b[i]),
            u16::from(c[i]),
            u16::from(d[i]),
            u16::from(e[i]),
        );
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
        // Values are at most 4080: every sum below fits in i16 (|gx|, |gy| ≤ 16320), so the
        // wrapping operations never wrap.
        let v = |p: &[u16]| p[i] as i16;
        let gx = sobel3(v(a0), v(a2), v(b0), v(b2), v(c0), v(c2));
        let gy = sobel3(v(a0), v(c0), v(a1), v(c1), v(a2), v(c2));
        let (ax, ay) = (gx.unsigned_abs(), gy.unsigned_abs());
        magnitude[i] = ax.wrapping_add(ay);
        flags[i] = u8::from(ax >= ay);
    }
}

/// `a + 4b + 6c + 4d + e`, for sums the caller knows fit in `u16`.
///
/// Wrapping operations, which give the same result as checked ones when nothing
/// overflows: with overflow checks on (the `test-release` profile the tests and the
/// measured pipeline run) a checked `+` or `*` is a branch per operation that keeps these
/// row loops from vectorising, the detector then costing ~5× the release build.
#[inline(always)]
fn binomial5(a: u16, b: u16, c: u16, d: u16, e: u16) -> u16 {
    let four = |v: u16| v << 2;
    a.wrapping_add(four(b))
        .wrapping_add(c.wrapping_mul(6))
        .wrapping_add(four(d))
        .wrapping_add(e)
}

/// `(p1 − m1) + 2 (p2 − m2) + (p3 − m3)`, one Sobel component from its three minus/plus
/// pairs, for values the caller knows keep it within `i16` (wrapping as [`binomial5`]).
#[inline(always)]
fn sobel3(m1: i16, p1: i16, m2: i16, p2: i16, m3: i16, p3: i16) -> i16 {
    let diff = |m: i16, p: i16| p.wrapping_sub(m);
    diff(m1, p1)
        .wrapping_add(diff(m2, p2) << 1)
        .wrapping_add(diff(m3, p3))
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
