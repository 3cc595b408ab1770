//! Stereo partners without a second extraction (`[orb] stereo = "row-search"`): each left
//! point's window looked for along its row of the rectified right image, by zero-mean
//! normalised correlation, instead of detecting and describing the right image's points.

use super::refine::{HALF, SIDE, pixels_of_pair, sum_of, sum_of_products, window, windows_inside};
use crate::cpu::with_avx2;
use crate::{AppearanceGates, FeatureMatch, GrayImage, OrbOptions, PointFeatures};
use linetrack_geometry::Point;

/// Smallest standard deviation of a left window's pixels, grey levels, for it to be
/// searched for at all: flatter windows match anywhere along a row.
pub const MIN_TEXTURE_STD: f64 = 3.0;

/// What the row search takes from the configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowSearchSettings {
    /// Smallest disparity (left column − right column) looked at, pixels.
    pub min_disparity_px: f64,
    /// Largest disparity looked at, pixels.
    pub max_disparity_px: f64,
    /// Smallest correlation at which the best window is believed.
    pub min_correlation: f64,
    /// The best cost (1 − correlation) must be under this fraction of the runner-up's.
    pub uniqueness: f64,
}

impl RowSearchSettings {
    /// The settings in `orb` (`row_search_*`) and `gates` (the disparity range).
    pub fn of(orb: &OrbOptions, gates: &AppearanceGates) -> Self {
        Self {
            min_disparity_px: gates.min_disparity_px,
            max_disparity_px: gates.max_disparity_px,
            min_correlation: orb.row_search_min_correlation,
            uniqueness: orb.row_search_uniqueness,
        }
    }
}

/// The row search, with its buffers (no allocation once they are large enough).
#[derive(Debug, Clone, Default)]
pub struct RowSearch {
    /// The right image's pixels under the windows of every candidate, column by column.
    strip: Vec<i16>,
    /// Per candidate: 1 − correlation.
    costs: Vec<f64>,
}

impl RowSearch {
    /// A search with empty buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// Replaces `right` with the stereo partners of `left`'s points found along their rows
    /// of `right_image`, and `matches` with the pairs (`query` indexes `left`, `train`
    /// `right`; `distance` is 1 − correlation). A partner lies on its point's row, at the
    /// whole-pixel shift of the best window plus the point's own offset from the pixel
    /// its window is centred on; it keeps the point's pyramid level. A point gets none when
    /// its window leaves the image, is too flat ([`MIN_TEXTURE_STD`]), correlates under
    /// `settings.min_correlation` at best, is at the end of the searched range, or has a
    /// runner-up too close ([`RowSearchSettings::uniqueness`]). Images of different sizes
    /// give no partners.
    pub fn find_partners(
        &mut self,
        [left_image, right_image]: [&GrayImage; 2],
        left: &PointFeatures,
        settings: &RowSearchSettings,
        right: &mut PointFeatures,
        matches: &mut Vec<FeatureMatch>,
    ) {
        right.points.clear();
        right.levels.clear();
        right.descriptors.reset(0, 0);
        matches.clear();
        for (query, &point) in left.points.iter().enumerate() {
            let Some((column, cost)) = self.best_column(left_image, right_image, point, settings)
            else {
                continue;
            };
            matches.push(FeatureMatch {
                query,
                train: right.points.len(),
                distance: cost,
            });
            right.points.push(Point::new(column, point.y));
            right
                .levels
                .push(left.levels.get(query).copied().unwrap_or(0));
        }
    }

    /// The column of `left`'s partner in `right_image` and its cost, or `None`
    /// ([`RowSearch::find_partners`]).
    pub fn best_column(
        &mut self,
        left_image: &GrayImage,
        right_image: &GrayImage,
        left: Point,
        settings: &RowSearchSettings,
    ) -> Option<(f64, f64)> {
        with_avx2(
            #[inline(always)]
            || self.best_column_portably(left_image, right_image, left, settings),
        )
    }

    /// [`RowSearch::best_column`] for any CPU; inlined where it is compiled for more
    /// ([`with_avx2`]).
    #[inline(always)]
    fn best_column_portably(
        &mut self,
        left_image: &GrayImage,
        right_image: &GrayImage,
        left: Point,
        settings: &RowSearchSettings,
    ) -> Option<(f64, f64)> {
        let (lp, rp, width, height) = pixels_of_pair(left_image, right_image)?;
        let (ul, v) = (left.x.round() as i64, left.y.round() as i64);
        if !windows_inside(ul, v, (0, 0), (width, height)) {
            return None;
        }
        // Candidate right columns, the disparity range clipped to the image.
        let (min_d, max_d) = (settings.min_disparity_px, settings.max_disparity_px);
        if !(min_d.is_finite() && max_d.is_finite()) {
            return None;
        }
        let first = (ul - max_d.floor() as i64).max(HALF);
        let last = (ul - min_d.ceil() as i64).min(width - 1 - HALF);
        if last - first < 2 {
            return None;
        }
        let candidates = (last - first + 1) as usize;
        let n = (SIDE * SIDE) as f64;
        // (Column by column, as the strip below.)
        let rows: [i16; SIDE * SIDE] = window(lp, width, ul, v);
        let mut reference = [0i16; SIDE * SIDE];
        for (i, &p) in rows.iter().enumerate() {
            reference[(i % SIDE) * SIDE + i / SIDE] = p;
        }
        let sum_a = sum_of(&reference);
        let var_a =
            f64::from(sum_of_products(&reference, &reference)) - f64::from(sum_a).powi(2) / n;
        if var_a < n * MIN_TEXTURE_STD.powi(2) {
            return None;
        }
        let (strip, costs) = (&mut self.strip, &mut self.costs);
        // The strip under every candidate's window, column by column (a column's 11 pixels
        // one after the other): candidate k's window is then the 121 values from column k
        // on, contiguous, and its sums are the same vectorised loops as `refine_track`'s.
        let image_columns = candidates + SIDE - 1;
        let left_column = first - HALF;
        strip.clear();
        strip.resize(SIDE * image_columns, 0);
        for (r, y) in (v - HALF..=v + HALF).enumerate() {
            let start = (y * width + left_column) as usize;
            for (c, &p) in rp[start..start + image_columns].iter().enumerate() {
                strip[c * SIDE + r] = i16::from(p);
            }
        }
        costs.clear();
        costs.extend(strip.windows(SIDE * SIDE).step_by(SIDE).map(|candidate| {
            let sum_b = sum_of(candidate);
            let sum_bb = sum_of_products(candidate, candidate);
            let sum_ab = sum_of_products(&reference, candidate);
            let var_b = f64::from(sum_bb) - f64::from(sum_b).powi(2) / n;
            let covariance = f64::from(sum_ab) - f64::from(sum_a) * f64::from(sum_b) / n;
            if var_b > 0.0 {
                1.0 - covariance / (var_a * var_b).sqrt()
            } else {
                2.0
            }
        }));
        let costs = &self.costs;
        let best = (0..candidates).min_by(|&a, &b| costs[a].total_cmp(&costs[b]))?;
        if best == 0 || best == candidates - 1 || 1.0 - costs[best] < settings.min_correlation {
            return None;
        }
        // The runner-up: the lowest other dip of the cost along the row (the best one's
        // neighbours are its own slope, not another match).
        let is_dip = |k: usize| {
            (k == 0 || costs[k - 1] >= costs[k])
                && (k + 1 == candidates || costs[k + 1] >= costs[k])
        };
        let runner_up = (0..candidates)
            .filter(|&k| k.abs_diff(best) > 1 && is_dip(k))
            .map(|k| costs[k])
            .min_by(f64::total_cmp);
        if runner_up.is_some_and(|r| costs[best] >= settings.uniqueness * r) {
            return None;
        }
        let column = (first + best as i64) as f64 + (left.x - ul as f64);
        Some((column, costs[best]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::refine_stereo_column;

    const W: usize = 200;
    const H: usize = 80;

    fn settings() -> RowSearchSettings {
        RowSearchSettings::of(&OrbOptions::default(), &AppearanceGates::default())
    }

    /// A textured image (smooth waves and a little deterministic noise) moved `shift`
    /// pixels to the left (a right image of a scene at disparity `shift`), times `gain`
    /// plus `offset`.
    fn textured(shift: f64, gain: f64, offset: f64) -> GrayImage {
        let pixels: Vec<u8> = (0..W * H)
            .map(|i| {
                let (x, y) = ((i % W) as f64 + shift, (i / W) as f64);
                let smooth = 110.0
                    + 45.0 * (x / 4.3).sin() * (y / 5.1).cos()
                    + 30.0 * (x / 9.7 + y / 6.2).sin()
                    + 20.0 * (x * y / 97.0).cos();
                let noise = ((i as u32).wrapping_mul(2_654_435_761) >> 30) as f64;
                (gain * smooth + offset + noise).clamp(0.0, 255.0) as u8
            })
            .collect();
        GrayImage::from_pixels(W, H, &pixels, "texture").unwrap()
    }

    fn image(pixels: impl Fn(usize, usize) -> u8) -> GrayImage {
        let pixels: Vec<u8> = (0..W * H).map(|i| pixels(i % W, i / W)).collect();
        GrayImage::from_pixels(W, H, &pixels, "pattern").unwrap()
    }

    #[test]
    fn the_search_finds_a_gain_changed_shift_to_a_fraction_of_a_pixel() {
        let disparity = 23.4;
        let left = textured(0.0, 1.0, 0.0);
        let right = textured(disparity, 1.25, -20.0);
        let mut search = RowSearch::new();
        let (mut found, mut errors) = (0, Vec::new());
        for y in (10..70).step_by(7) {
            for x in (60..190).step_by(9) {
                let point = Point::new(x as f64, y as f64);
                let Some((column, cost)) = search.best_column(&left, &right, point, &settings())
                else {
                    continue;
                };
                found += 1;
                assert!(cost < 0.2, "cost {cost} at {point:?}");
                // The search's whole pixel is within one of the truth…
                assert!(
                    (point.x - column - disparity).abs() <= 1.0,
                    "{column} at {point:?}"
                );
                // …and the refinement after it takes it to a fraction of a pixel.
                let refined =
                    refine_stereo_column(&left, &right, point, Point::new(column, point.y))
                        .unwrap();
                errors.push((point.x - refined - disparity).abs());
            }
        }
        assert!(found > 100, "{found} found");
        errors.sort_by(f64::total_cmp);
        let median = errors[errors.len() / 2];
        assert!(median < 0.2, "median error {median} px");
        // Through `find_partners`: every partner on its point's row, with its level.
        let points = PointFeatures {
            points: vec![Point::new(100.2, 40.0), Point::new(2.0, 40.0)],
            levels: vec![3, 0],
            ..PointFeatures::default()
        };
        let (mut partners, mut matches) = (PointFeatures::default(), Vec::new());
        search.find_partners(
            [&left, &right],
            &points,
            &settings(),
            &mut partners,
            &mut matches,
        );
        assert_eq!(matches.len(), 1, "{matches:?}");
        assert_eq!((matches[0].query, matches[0].train), (0, 0));
        assert_eq!(partners.points[0].y, 40.0);
        assert_eq!(partners.levels, [3]);
        assert!((100.2 - partners.points[0].x - disparity).abs() <= 1.0);
    }

    #[test]
    fn a_flat_window_and_a_repeated_pattern_are_refused() {
        let settings = settings();
        let mut search = RowSearch::new();
        // Flat on the left half (a gentle ramp under the texture threshold), textured on
        // the right half.
        let texture = textured(0.0, 1.0, 0.0);
        let texture_pixels = texture.pixels().unwrap().to_vec();
        let half_flat = image(|x, y| {
            if x < 120 {
                100 + (x / 40) as u8
            } else {
                texture_pixels[y * W + x]
            }
        });
        let shifted = image(|x, y| {
            let source = x + 10;
            if source < W {
                half_flat.pixels().unwrap()[y * W + source]
            } else {
                0
            }
        });
        let flat_point = Point::new(100.0, 40.0);
        assert_eq!(
            search.best_column(&half_flat, &shifted, flat_point, &settings),
            None
        );
        let textured_point = Point::new(170.0, 40.0);
        let (column, _) = search
            .best_column(&half_flat, &shifted, textured_point, &settings)
            .unwrap();
        assert_eq!(column, 160.0);
        // Vertical stripes every 8 px: every 8th shift fits as well as the true one.
        let stripes = |shift: usize| image(move |x, _| if (x + shift) % 8 < 4 { 60 } else { 190 });
        let (left, right) = (stripes(0), stripes(3));
        assert_eq!(
            search.best_column(&left, &right, Point::new(120.0, 40.0), &settings),
            None
        );
        // The same stripes with one tall mark that only the true shift lines up.
        let marked = |shift: usize| {
            image(move |x, y| {
                if (x + shift) == 120 && (35..46).contains(&y) {
                    255
                } else if (x + shift) % 8 < 4 {
                    60
                } else {
                    190
                }
            })
        };
        let (left, right) = (marked(0), marked(5));
        assert_eq!(
            search
                .best_column(&left, &right, Point::new(120.0, 40.0), &settings)
                .map(|(column, _)| column),
            Some(115.0)
        );
        // Bad input is refused, not a panic: images of different sizes, odd points.
        let small = GrayImage::from_pixels(10, 10, &[0; 100], "small").unwrap();
        assert_eq!(
            search.best_column(&texture, &small, flat_point, &settings),
            None
        );
        for odd in [f64::NAN, f64::INFINITY, -1e300, 1e300] {
            assert_eq!(
                search.best_column(&texture, &texture, Point::new(odd, odd), &settings),
                None
            );
        }
        let no_range = RowSearchSettings {
            max_disparity_px: f64::NAN,
            ..settings
        };
        assert_eq!(
            search.best_column(&texture, &texture, textured_point, &no_range),
            None
        );
    }

    /// Built for AVX2 and for the baseline CPU, the search answers the same, bit for bit.
    #[test]
    fn the_search_answers_the_same_for_every_cpu() {
        let (left, right) = (textured(0.0, 1.0, 0.0), textured(7.6, 0.9, 12.0));
        let mut search = RowSearch::new();
        let (mut found, mut refused) = (0, 0);
        for y in (0..H).step_by(4) {
            for x in (0..W).step_by(5) {
                let point = Point::new(x as f64 + 0.3, y as f64);
                let a = search.best_column(&left, &right, point, &settings());
                let b = search.best_column_portably(&left, &right, point, &settings());
                match a {
                    Some(_) => found += 1,
                    None => refused += 1,
                }
                assert_eq!(
                    a.map(|(c, d)| (c.to_bits(), d.to_bits())),
                    b.map(|(c, d)| (c.to_bits(), d.to_bits()))
                );
            }
        }
        assert!(
            found > 100 && refused > 100,
            "{found} found, {refused} refused"
        );
    }
}
