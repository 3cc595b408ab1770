//! Does a ground-truth map agree with its own images? The constant that, added to every
//! disparity of the truth, best maps the right image onto the left, found photometrically
//! over every textured pixel: no features, no matching, nothing of ours but the sampling.
//! A truth in the images' own convention gives about 0; a truth off by a constant (a
//! convention, a rounding) gives that constant. This is what separates a bias of the
//! odometry's disparities from one of the map they are scored against.

use linetrack_datasets::{DisparityMap, LoadedPair};
use serde::Serialize;

/// Shifts tried, pixels: from −`SEARCH_PX` to +`SEARCH_PX` in steps of `STEP_PX`.
const SEARCH_PX: f64 = 1.0;
const STEP_PX: f64 = 0.01;
/// A pixel's horizontal gradient (central difference, grey levels per pixel) below this
/// says nothing about a horizontal shift: left out.
const MIN_GRADIENT: f64 = 4.0;
/// Residuals are truncated here (grey levels), so occlusions the map does not mark and
/// specular spots weigh no more than a poor fit.
const TRUNCATE: f64 = 16.0;

/// The best shift of one pair's truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TruthShift {
    /// Added to every disparity of the truth, the right image fits the left best, pixels.
    pub shift_px: f64,
    /// Pixels compared (textured, with truth, away from depth edges and the borders).
    pub pixels: usize,
    /// Root of the mean truncated squared residual at that shift, grey levels.
    pub rms_grey: f64,
}

/// A row of an 8-bit grey image, sampled between pixels with a Catmull–Rom cubic (less
/// pulled towards whole pixels than linear interpolation).
fn sample(row: &[u8], x: f64) -> Option<f64> {
    let i = x.floor();
    if !(i >= 1.0 && i + 2.0 < row.len() as f64) {
        return None;
    }
    let (i, t) = (i as usize, x - i);
    let p = |k: usize| f64::from(row[k]);
    let (p0, p1, p2, p3) = (p(i - 1), p(i), p(i + 1), p(i + 2));
    Some(
        p1 + 0.5
            * t
            * (p2 - p0
                + t * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + t * (3.0 * (p1 - p2) + p3 - p0))),
    )
}

/// The shift of `truth` that best maps `pair`'s right image onto its left one; truth whose
/// horizontal neighbours differ from it by more than `max_spread_px` is a depth edge and
/// left out. `None` when no pixel can be compared.
pub fn truth_shift(
    pair: &LoadedPair,
    truth: &DisparityMap,
    max_spread_px: f64,
) -> anyhow::Result<Option<TruthShift>> {
    pair.left.ensure_same_size(&pair.right)?;
    let (mut left_copy, mut right_copy) = (Vec::new(), Vec::new());
    let left = pair.left.packed_pixels(&mut left_copy)?;
    let right = pair.right.packed_pixels(&mut right_copy)?;
    let width = usize::try_from(pair.left.width()).unwrap_or(0);
    let height = usize::try_from(pair.left.height()).unwrap_or(0);
    // Every pixel worth comparing: its grey level, its row and its truth.
    let mut compared = Vec::new();
    for y in 0..height.min(truth.height()) {
        let row = &left[y * width..(y + 1) * width];
        for x in 1..width.min(truth.width()).saturating_sub(1) {
            let (fx, fy) = (x as f64, y as f64);
            let Some(d) = truth.at(fx, fy) else { continue };
            let flat = [fx - 1.0, fx + 1.0].iter().all(|&n| {
                truth
                    .at(n, fy)
                    .is_some_and(|dn| (dn - d).abs() <= max_spread_px)
            });
            let gradient = 0.5 * (f64::from(row[x + 1]) - f64::from(row[x - 1]));
            if flat && gradient.abs() >= MIN_GRADIENT {
                compared.push((f64::from(row[x]), y, fx - d));
            }
        }
    }
    let cost = |shift: f64| {
        let (mut sum, mut n) = (0.0, 0usize);
        for &(grey, y, at) in &compared {
            if let Some(seen) = sample(&right[y * width..(y + 1) * width], at - shift) {
                sum += (grey - seen).powi(2).min(TRUNCATE * TRUNCATE);
                n += 1;
            }
        }
        (n > 0).then(|| (sum / n as f64, n))
    };
    let steps = (SEARCH_PX / STEP_PX).round() as i64;
    let costs: Vec<(f64, Option<(f64, usize)>)> = (-steps..=steps)
        .map(|k| {
            let shift = k as f64 * STEP_PX;
            (shift, cost(shift))
        })
        .collect();
    let Some((best, shift, mean, pixels)) = costs
        .iter()
        .enumerate()
        .filter_map(|(k, &(shift, c))| c.map(|(mean, n)| (k, shift, mean, n)))
        .min_by(|a, b| a.2.total_cmp(&b.2))
    else {
        return Ok(None);
    };
    // A parabola through the best step and its neighbours places the minimum between steps.
    let around = |k: usize| costs.get(k).and_then(|(_, c)| c.map(|c| c.0));
    let refined = match (best.checked_sub(1).and_then(around), around(best + 1)) {
        (Some(before), Some(after)) if before + after - 2.0 * mean > 0.0 => {
            shift + 0.5 * STEP_PX * (before - after) / (before + after - 2.0 * mean)
        }
        _ => shift,
    };
    Ok(Some(TruthShift {
        shift_px: refined,
        pixels,
        rms_grey: mean.sqrt(),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rendered_pair;
    use linetrack_scene_render::Preset;

    /// The truth moved by a constant.
    fn moved(truth: &DisparityMap, by_px: f64) -> DisparityMap {
        let (w, h) = (truth.width(), truth.height());
        let values = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                truth
                    .at(x as f64, y as f64)
                    .map_or(0.0, |d| (d + by_px) as f32)
            })
            .collect();
        DisparityMap::from_values(w, h, values).unwrap()
    }

    #[test]
    fn an_exact_truth_needs_no_shift_and_a_moved_one_is_moved_back() {
        // A rendered room (the renderer's exact depth at every pixel centre).
        let pair = rendered_pair(Preset::Normal, 1, 100, 0).unwrap();
        let exact = truth_shift(&pair, &pair.disparity, 1.0).unwrap().unwrap();
        assert!(exact.pixels > 1000, "{exact:?}");
        assert!(exact.shift_px.abs() <= 0.03, "{exact:?}");
        for by_px in [-0.3, 0.25] {
            let found = truth_shift(&pair, &moved(&pair.disparity, by_px), 1.0)
                .unwrap()
                .unwrap();
            assert!(
                (found.shift_px - (exact.shift_px - by_px)).abs() <= 0.02,
                "truth moved by {by_px}: {found:?}, exact {exact:?}"
            );
        }
    }

    #[test]
    fn the_cubic_passes_through_the_pixels_and_refuses_the_border() {
        let row = [10u8, 20, 40, 80, 160, 200];
        for (i, &grey) in row.iter().enumerate().take(4).skip(1) {
            assert_eq!(sample(&row, i as f64), Some(f64::from(grey)));
        }
        let between = sample(&row, 2.5).unwrap();
        assert!((40.0..80.0).contains(&between), "{between}");
        assert_eq!(sample(&row, 0.5), None);
        assert_eq!(sample(&row, 4.0), None);
    }
}
