//! Intensity profiles across a segment, compared in a way that no affine change of the
//! intensities (`α·I + β`, α > 0) can alter: the photometric check of the stereo matcher.
//!
//! In a rectified pair, row `y` of the left image corresponds to row `y` of the right
//! image. For a segment that is not near-horizontal, the point of its line on row `y` is
//! `x(y)`; the [`PROFILE_LEN`] pixels of row `y` centred on `x(y)` (linearly interpolated
//! along the row) form the row's *profile*. Each profile is made zero-mean and unit-norm,
//! so a gain and a bias between the two images cancel exactly, and a slowly varying light
//! field (vignetting) nearly so. Profiles are taken on the rows that are multiples of
//! [`ROW_STEP`], for every segment, so that two segments' profiles on a shared row compare
//! the same image row.
//!
//! The similarity of a left and a right segment is the mean, over the rows both cover, of
//! the dot product of their profiles (a zero-normalised cross-correlation per row) in
//! [−1, 1]; it is 1 when the intensities across the two lines agree up to gain and bias,
//! and negative when the edge has the opposite polarity. Rows where either image is flat
//! (no contrast, or clipped to one level) carry no information and are skipped.
//!
//! Extraction reads the image in place (a borrowed [`GrayView`]) and reuses its buffers;
//! comparing two segments touches only their profiles.

use linetrack_geometry::Segment;

/// Pixels per profile, centred on the line: offsets −3.5 … +3.5 px along the row.
pub const PROFILE_LEN: usize = 16;

/// Profiles are taken on rows that are multiples of this…
pub const ROW_STEP: usize = 2;

/// …or of a power-of-two multiple of it, the smallest that gives a segment at most this
/// many rows. Two segments' grids then share every row of the coarser one.
pub const MAX_ROWS: usize = 12;

/// Samples of a near-horizontal segment's column profile: offsets −7.5 … +7.5 px down
/// the columns.
pub const COLUMN_PROFILE_LEN: usize = 16;

/// Columns averaged into one column profile: groups of adjacent columns (which share
/// cache lines) at evenly spread places along the segment.
const COLUMN_GROUPS: usize = 4;
/// Adjacent columns per group.
const GROUP_WIDTH: usize = 2;

/// Standard deviation (grey levels) below which a profile is flat and carries nothing.
const FLAT_STD: f32 = 0.75;

/// A borrowed 8-bit grey image: `height` rows of `width` pixels, `stride` bytes apart.
#[derive(Debug, Clone, Copy)]
pub struct GrayView<'a> {
    pixels: &'a [u8],
    width: usize,
    height: usize,
    stride: usize,
}

/// Pixels that do not make the image they are said to make.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{len} bytes cannot hold a {width}×{height} image with rows {stride} bytes apart")]
pub struct ViewError {
    /// Bytes given.
    pub len: usize,
    /// Stated width.
    pub width: usize,
    /// Stated height.
    pub height: usize,
    /// Stated stride.
    pub stride: usize,
}

impl<'a> GrayView<'a> {
    /// A view of `pixels`; refused when the rows do not fit.
    pub fn new(
        pixels: &'a [u8],
        width: usize,
        height: usize,
        stride: usize,
    ) -> Result<Self, ViewError> {
        let error = ViewError {
            len: pixels.len(),
            width,
            height,
            stride,
        };
        let needed = match height {
            0 => 0,
            h => stride
                .checked_mul(h - 1)
                .and_then(|n| n.checked_add(width))
                .ok_or(error.clone())?,
        };
        if stride < width || pixels.len() < needed {
            return Err(error);
        }
        Ok(Self {
            pixels,
            width,
            height,
            stride,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    fn row(&self, y: usize) -> &'a [u8] {
        &self.pixels[y * self.stride..y * self.stride + self.width]
    }
}

/// Where one segment's profiles are in [`SegmentProfiles`].
#[derive(Debug, Clone, Copy, Default)]
struct Span {
    /// Index of the first profile's row on the segment's grid: row / (ROW_STEP << shift).
    first_row: usize,
    /// The segment's grid: rows that are multiples of ROW_STEP << shift.
    shift: u32,
    /// Number of profiles (0: the segment has none).
    count: usize,
    /// Index of the first profile in the shared buffer.
    offset: usize,
}

/// One row's profile, in fixed point so that extraction and comparison stay in integer
/// arithmetic: the correlation of two rows is
/// `(n·Σab − Σa·Σb) / √(n·Σa² − (Σa)²) / √(n·Σb² − (Σb)²)`.
#[derive(Debug, Clone, Copy)]
struct RowProfile {
    /// Grey levels × 16 (the interpolation's four fractional bits): at most 4080.
    samples: [i16; PROFILE_LEN],
    /// Σ samples.
    sum: i32,
    /// Σ samples².
    squares: i32,
    /// 1 / √(n·Σs² − (Σs)²).
    inv_spread: f32,
}

impl RowProfile {
    /// The zero-normalised cross-correlation of two rows, in [−1, 1].
    fn correlation(&self, other: &RowProfile) -> f32 {
        let products = dot_i16(&self.samples, &other.samples);
        let covariance =
            PROFILE_LEN as f64 * f64::from(products) - f64::from(self.sum) * f64::from(other.sum);
        covariance as f32 * self.inv_spread * other.inv_spread
    }

    /// The correlation of this row's samples `k` with `other`'s samples `k + shift`
    /// (shift −1, 0 or +1), over the samples both have; `None` when either part is flat.
    fn shifted_correlation(&self, other: &RowProfile, shift: isize) -> Option<f64> {
        let last = PROFILE_LEN - 1;
        // The sample each side leaves out, if any.
        let (a, b, a_out, b_out) = match shift {
            -1 => (
                &self.samples[1..],
                &other.samples[..last],
                Some(0),
                Some(last),
            ),
            1 => (
                &self.samples[..last],
                &other.samples[1..],
                Some(last),
                Some(0),
            ),
            _ => (&self.samples[..], &other.samples[..], None, None),
        };
        let part = |p: &RowProfile, out: Option<usize>| {
            let v = out.map_or(0, |k| i64::from(p.samples[k]));
            (i64::from(p.sum) - v, i64::from(p.squares) - v * v)
        };
        let ((sa, saa), (sb, sbb)) = (part(self, a_out), part(other, b_out));
        let n = a.len() as i64;
        let (va, vb) = (n * saa - sa * sa, n * sbb - sb * sb);
        let covariance = n * i64::from(dot_i16(a, b)) - sa * sb;
        (va > 0 && vb > 0).then(|| covariance as f64 / ((va as f64) * (vb as f64)).sqrt())
    }
}

/// Σ a_k b_k of two sample rows (at most 16 samples of at most 4080: fits an i32).
fn dot_i16(a: &[i16], b: &[i16]) -> i32 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| i32::from(x) * i32::from(y))
        .sum()
}

/// One profile, or `None` where the row is flat or leaves the image.
type Profile = Option<RowProfile>;

/// The row profiles of every segment of one image; see the module documentation.
#[derive(Debug, Clone, Default)]
pub struct SegmentProfiles {
    spans: Vec<Span>,
    profiles: Vec<Profile>,
    /// Per segment: the mean column profile of a near-horizontal segment.
    columns: Vec<Option<[f32; COLUMN_PROFILE_LEN]>>,
}

/// How alike two segments' profiles are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Similarity {
    /// Mean per-row correlation, in [−1, 1].
    pub correlation: f64,
    /// Rows it was measured on.
    pub rows: usize,
}

impl SegmentProfiles {
    /// Replaces the contents with the profiles of `segments` in `image`. Segments closer
    /// than `min_angle_from_horizontal_deg` to horizontal, degenerate ones, and rows
    /// outside the image get no profile.
    pub fn extract(
        &mut self,
        image: GrayView<'_>,
        segments: &[Segment],
        min_angle_from_horizontal_deg: f64,
    ) {
        self.clear();
        let min_sin = min_angle_from_horizontal_deg.to_radians().sin();
        for segment in segments {
            let span = self.extract_one(image, segment, min_sin);
            self.spans.push(span);
            let column = if span.count == 0 {
                column_profile(image, segment)
            } else {
                None
            };
            self.columns.push(column);
        }
    }

    fn extract_one(&mut self, image: GrayView<'_>, segment: &Segment, min_sin: f64) -> Span {
        let offset = self.profiles.len();
        let none = Span {
            offset,
            ..Span::default()
        };
        let (s, e) = (segment.start, segment.end);
        let (dx, dy) = (e.x - s.x, e.y - s.y);
        let length = dx.hypot(dy);
        if !(length.is_finite() && length > 0.0 && dy.abs() >= min_sin * length) {
            return none;
        }
        let (y_low, y_high) = (s.y.min(e.y), s.y.max(e.y));
        let last_row = image.height.saturating_sub(1) as f64;
        let (y_low, y_high) = (y_low.max(0.0), y_high.min(last_row));
        if !(y_low <= y_high) {
            return none;
        }
        let mut shift = 0;
        let (first_row, last) = loop {
            let step = (ROW_STEP << shift) as f64;
            let (first, last) = (
                (y_low / step).ceil() as usize,
                (y_high / step).floor() as usize,
            );
            if last < first || last - first < MAX_ROWS {
                break (first, last);
            }
            shift += 1;
        };
        if last < first_row {
            return none;
        }
        let slope = dx / dy;
        for grid in first_row..=last {
            let y = grid * (ROW_STEP << shift);
            let x = s.x + (y as f64 - s.y) * slope;
            self.profiles.push(profile(image, x, y));
        }
        Span {
            first_row,
            shift,
            count: last - first_row + 1,
            offset,
        }
    }

    /// Removes every segment's profiles.
    pub fn clear(&mut self) {
        self.spans.clear();
        self.profiles.clear();
        self.columns.clear();
    }

    /// The correlation of the mean column profiles of near-horizontal segments `i` of
    /// `self` and `j` of `other`; `None` when either has none.
    pub fn column_similarity(&self, i: usize, other: &SegmentProfiles, j: usize) -> Option<f64> {
        let (a, b) = (
            self.columns.get(i)?.as_ref()?,
            other.columns.get(j)?.as_ref()?,
        );
        Some(f64::from(dot(a, b)).clamp(-1.0, 1.0))
    }

    /// Whether segment `i` has a mean column profile (near-horizontal segments).
    pub fn has_column_profile(&self, i: usize) -> bool {
        self.columns.get(i).is_some_and(Option::is_some)
    }

    /// Whether segment `i` has at least one usable row profile.
    pub fn has_profile(&self, i: usize) -> bool {
        self.spans.get(i).is_some_and(|s| {
            self.profiles[s.offset..s.offset + s.count]
                .iter()
                .any(Option::is_some)
        })
    }

    /// Number of segments.
    pub fn len(&self) -> usize {
        self.spans.len()
    }

    /// Whether there are no segments.
    pub fn is_empty(&self) -> bool {
        self.spans.is_empty()
    }

    /// Calls `visit` with the profiles of segment `i` of `self` and segment `j` of `other`
    /// on every row both have one on (the coarser of their two grids).
    fn for_common_rows(
        &self,
        i: usize,
        other: &SegmentProfiles,
        j: usize,
        mut visit: impl FnMut(&RowProfile, &RowProfile),
    ) {
        let (Some(a), Some(b)) = (self.spans.get(i), other.spans.get(j)) else {
            return;
        };
        if a.count == 0 || b.count == 0 {
            return;
        }
        // Rows of the coarser grid that both segments cover, in units of its step.
        let shift = a.shift.max(b.shift);
        let coarse = |s: &Span| {
            let up = shift - s.shift;
            let low = s.first_row.div_ceil(1 << up);
            let high = (s.first_row + s.count - 1) >> up;
            (low, high)
        };
        let ((a_low, a_high), (b_low, b_high)) = (coarse(a), coarse(b));
        for c in a_low.max(b_low)..=a_high.min(b_high) {
            let at = |s: &Span| s.offset + (c << (shift - s.shift)) - s.first_row;
            if let (Some(p), Some(q)) = (&self.profiles[at(a)], &other.profiles[at(b)]) {
                visit(p, q);
            }
        }
    }

    /// How far (pixels, along the rows) the image content of segment `j` of `other` sits
    /// from where its line says, relative to segment `i` of `self`: the peak of the mean
    /// row correlation over shifts of −1, 0 and +1 sample, refined by a parabola. Near 0
    /// when both lines sit on the same image edge; `None` without common rows, and
    /// infinite when the correlation has no peak there.
    pub fn offset_px(&self, i: usize, other: &SegmentProfiles, j: usize) -> Option<f64> {
        let mut sums = [0.0f64; 3];
        let mut rows = 0usize;
        self.for_common_rows(i, other, j, |p, q| {
            let values: [Option<f64>; 3] =
                std::array::from_fn(|k| p.shifted_correlation(q, k as isize - 1));
            if let [Some(a), Some(b), Some(c)] = values {
                sums[0] += a;
                sums[1] += b;
                sums[2] += c;
                rows += 1;
            }
        });
        if rows == 0 {
            return None;
        }
        let [before, at, after] = sums;
        let curvature = before - 2.0 * at + after;
        if !(curvature < 0.0) {
            return Some(f64::INFINITY);
        }
        Some(0.5 * (before - after) / curvature)
    }

    /// The similarity of segment `i` of `self` and segment `j` of `other` over the rows
    /// both have a profile on; `None` when fewer than `min_rows` such rows exist (or an
    /// index is out of range).
    pub fn similarity(
        &self,
        i: usize,
        other: &SegmentProfiles,
        j: usize,
        min_rows: usize,
    ) -> Option<Similarity> {
        let (mut sum, mut rows) = (0.0f32, 0usize);
        self.for_common_rows(i, other, j, |p, q| {
            sum += p.correlation(q);
            rows += 1;
        });
        (rows >= min_rows.max(1)).then(|| Similarity {
            correlation: f64::from(sum / rows as f32).clamp(-1.0, 1.0),
            rows,
        })
    }
}

/// The normalised profile of row `y` centred on `x`, or `None` when it leaves the image
/// or is flat.
fn profile(image: GrayView<'_>, x: f64, y: usize) -> Profile {
    let first = x - (PROFILE_LEN as f64 - 1.0) / 2.0;
    if !(first >= 0.0 && first + PROFILE_LEN as f64 <= image.width as f64 - 1.0) {
        return None;
    }
    // `first` is >= 0: truncation is the floor.
    let start = first as usize;
    let t = (first - start as f64) as f32;
    let row = image.row(y);
    let window: &[u8; PROFILE_LEN + 1] = row[start..start + PROFILE_LEN + 1].try_into().ok()?;
    // Linear interpolation with a weight in sixteenths: samples = 16 × grey level.
    let weight = (t * 16.0 + 0.5) as i16;
    let samples: [i16; PROFILE_LEN] = std::array::from_fn(|k| {
        i16::from(window[k]) * (16 - weight) + i16::from(window[k + 1]) * weight
    });
    let sum: i32 = samples.iter().map(|&v| i32::from(v)).sum();
    let squares = dot_i16(&samples, &samples);
    let spread = PROFILE_LEN as i64 * i64::from(squares) - i64::from(sum) * i64::from(sum);
    // n²·var of 16 × grey: flat below FLAT_STD grey levels.
    let flat = (PROFILE_LEN as f32 * 16.0 * FLAT_STD).powi(2);
    if (spread as f32) < flat {
        return None;
    }
    Some(RowProfile {
        samples,
        sum,
        squares,
        inv_spread: (spread as f64).sqrt().recip() as f32,
    })
}

/// The mean, over [`COLUMNS`] columns spread along a near-horizontal segment, of the
/// vertical profile centred on the line (linearly interpolated down the column),
/// normalised; `None` when a column leaves the image or the mean is flat.
fn column_profile(image: GrayView<'_>, segment: &Segment) -> Option<[f32; COLUMN_PROFILE_LEN]> {
    let (s, e) = (segment.start, segment.end);
    let (dx, dy) = (e.x - s.x, e.y - s.y);
    if !(dx.is_finite() && dy.is_finite()) || dx.abs() < 2.0 {
        return None;
    }
    let (x_low, x_high) = (s.x.min(e.x), s.x.max(e.x));
    let last_column = image.width.checked_sub(1)? as f64;
    let (x_low, x_high) = (x_low.max(0.0), x_high.min(last_column));
    if !(x_high - x_low >= (COLUMN_GROUPS * GROUP_WIDTH) as f64) {
        return None;
    }
    let mut sum = [0f32; COLUMN_PROFILE_LEN];
    let slope = dy / dx;
    for group in 0..COLUMN_GROUPS {
        // Group g is centred (g + ½) / COLUMN_GROUPS of the way along; non-negative, so
        // adding ½ and truncating rounds.
        let centre = x_low + (group as f64 + 0.5) * (x_high - x_low) / COLUMN_GROUPS as f64;
        let x0 = (centre - GROUP_WIDTH as f64 / 2.0 + 0.5).max(0.0) as usize;
        if x0 + GROUP_WIDTH > image.width {
            return None;
        }
        // Where each column's profile starts (row, fraction), and the rows they span.
        let mut starts = [(0usize, 0f32); GROUP_WIDTH];
        for (c, start) in starts.iter_mut().enumerate() {
            let first =
                s.y + ((x0 + c) as f64 - s.x) * slope - (COLUMN_PROFILE_LEN as f64 - 1.0) / 2.0;
            if !(first >= 0.0 && first + COLUMN_PROFILE_LEN as f64 <= image.height as f64 - 1.0) {
                return None;
            }
            let base = first as usize;
            *start = (base, (first - base as f64) as f32);
        }
        for (c, &(base, t)) in starts.iter().enumerate() {
            // The column's COLUMN_PROFILE_LEN + 1 pixels from row `base` down (in the
            // image: checked above).
            let mut read = [0f32; COLUMN_PROFILE_LEN + 1];
            let column = image.pixels[base * image.stride + x0 + c..]
                .iter()
                .step_by(image.stride);
            for (slot, &value) in read.iter_mut().zip(column) {
                *slot = f32::from(value);
            }
            for (k, total) in sum.iter_mut().enumerate() {
                *total += read[k] + (read[k + 1] - read[k]) * t;
            }
        }
    }
    normalise(&mut sum).then_some(sum)
}

/// Lanes of the sums below: independent partial sums the compiler can keep in one vector
/// register (a sequential float sum cannot be vectorised without reordering it).
const LANES: usize = 4;

/// Σ a_k b_k over arrays whose length is a multiple of [`LANES`].
fn dot<const N: usize>(a: &[f32; N], b: &[f32; N]) -> f32 {
    let mut lanes = [0f32; LANES];
    for (x, y) in a.chunks_exact(LANES).zip(b.chunks_exact(LANES)) {
        for k in 0..LANES {
            lanes[k] += x[k] * y[k];
        }
    }
    lanes.iter().sum()
}

/// Makes `samples` zero-mean and unit-norm; `false` when they are flat.
fn normalise<const N: usize>(samples: &mut [f32; N]) -> bool {
    const { assert!(N.is_multiple_of(LANES)) };
    let n = N as f32;
    let mut lanes = [0f32; LANES];
    for chunk in samples.chunks_exact(LANES) {
        for k in 0..LANES {
            lanes[k] += chunk[k];
        }
    }
    let mean = lanes.iter().sum::<f32>() / n;
    for s in samples.iter_mut() {
        *s -= mean;
    }
    let energy = dot(samples, samples);
    if energy < FLAT_STD * FLAT_STD * n {
        return false;
    }
    let scale = energy.sqrt().recip();
    for s in samples.iter_mut() {
        *s *= scale;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 64 × 40 image: a vertical step at x = 20 (dark left), a ramp texture that varies
    /// along the rows, and a thin bright line at x = 45.
    fn image(gain: f32, bias: f32) -> Vec<u8> {
        let (w, h) = (64, 40);
        let mut pixels = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                let base = if x < 20 { 40.0 } else { 120.0 } + (y % 7) as f32 * 3.0;
                let line = if x == 45 { 60.0 } else { 0.0 };
                let v = gain * (base + line + ((x * 5 + y * 3) % 11) as f32) + bias;
                pixels[y * w + x] = v.round().clamp(0.0, 255.0) as u8;
            }
        }
        pixels
    }

    fn profiles_of(pixels: &[u8], segments: &[Segment]) -> SegmentProfiles {
        let view = GrayView::new(pixels, 64, 40, 64).unwrap();
        let mut p = SegmentProfiles::default();
        p.extract(view, segments, 20.0);
        p
    }

    #[test]
    fn the_same_edge_under_gain_and_bias_correlates_fully_and_a_different_edge_does_not() {
        let step = Segment::from_coords(19.5, 2.0, 19.5, 37.0);
        let line = Segment::from_coords(45.0, 2.0, 45.0, 37.0);
        let left = profiles_of(&image(1.0, 0.0), &[step, line]);
        let right = profiles_of(&image(0.6, 30.0), &[step, line]);
        let same = left.similarity(0, &right, 0, 3).unwrap();
        assert!(same.correlation > 0.98, "{same:?}");
        // Rows 2, 4, …, 36 are 18, more than MAX_ROWS: the grid doubles to 4, 8, …, 36.
        assert_eq!(same.rows, 9);
        let other = left.similarity(0, &right, 1, 3).unwrap();
        assert!(other.correlation < 0.5, "{other:?}");
        assert!(left.similarity(1, &right, 1, 3).unwrap().correlation > 0.98);
    }

    #[test]
    fn opposite_polarity_correlates_negatively() {
        let pixels = image(1.0, 0.0);
        let inverted: Vec<u8> = pixels.iter().map(|p| 255 - p).collect();
        let step = Segment::from_coords(19.5, 2.0, 19.5, 37.0);
        let a = profiles_of(&pixels, &[step]);
        let b = profiles_of(&inverted, &[step]);
        assert!(a.similarity(0, &b, 0, 3).unwrap().correlation < -0.98);
    }

    #[test]
    fn horizontal_flat_outside_and_degenerate_segments_have_no_profile() {
        let pixels = image(1.0, 0.0);
        let flat = vec![100u8; 64 * 40];
        let segments = [
            Segment::from_coords(5.0, 10.0, 60.0, 12.0), // 2° from horizontal
            Segment::from_coords(1.0, 2.0, 1.0, 37.0),   // profile leaves the image
            Segment::from_coords(30.0, 5.0, 30.0, 5.0),  // no length
            Segment::from_coords(19.5, 50.0, 19.5, 80.0), // below the image
            Segment::from_coords(f64::NAN, 1.0, 3.0, 4.0), // not finite
        ];
        let p = profiles_of(&pixels, &segments);
        assert_eq!(p.len(), segments.len());
        for k in 0..segments.len() {
            assert_eq!(p.similarity(k, &p, k, 1), None, "segment {k}");
        }
        let step = [Segment::from_coords(19.5, 2.0, 19.5, 37.0)];
        let flat_profiles = profiles_of(&flat, &step);
        assert_eq!(flat_profiles.similarity(0, &flat_profiles, 0, 1), None);
    }

    #[test]
    fn rows_outside_the_common_extent_and_too_few_rows_give_no_similarity() {
        let pixels = image(1.0, 0.0);
        let top = Segment::from_coords(19.5, 2.0, 19.5, 12.0);
        let bottom = Segment::from_coords(19.5, 20.0, 19.5, 37.0);
        let p = profiles_of(&pixels, &[top, bottom]);
        assert_eq!(p.similarity(0, &p, 1, 1), None);
        let short = Segment::from_coords(19.5, 10.0, 19.5, 13.0); // rows 10, 12
        let q = profiles_of(&pixels, &[short]);
        assert_eq!(p.similarity(0, &q, 0, 3), None);
        assert_eq!(p.similarity(0, &q, 0, 2).unwrap().rows, 2);
    }

    #[test]
    fn views_that_do_not_fit_their_pixels_are_refused() {
        assert!(GrayView::new(&[0; 10], 5, 2, 5).is_ok());
        assert!(
            GrayView::new(&[0; 12], 5, 2, 7).is_ok(),
            "last row needs no padding"
        );
        assert!(GrayView::new(&[0; 9], 5, 2, 5).is_err());
        assert!(
            GrayView::new(&[0; 20], 5, 2, 4).is_err(),
            "stride below width"
        );
        assert!(GrayView::new(&[], 5, usize::MAX, usize::MAX).is_err());
    }
}
