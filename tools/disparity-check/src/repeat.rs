//! Repeatability of point extractors on stereo pairs with true disparity: does a corner
//! found in the left image come back in the right one where the truth puts it?
//!
//! For each left point with a ground-truth disparity `d` (no depth edge under it) whose
//! shifted position `(x − d, y)` lies in the right image, the nearest right point is looked
//! for: the left point is *repeated* when it lies within the radius (1.5 px by default).
//! The distance of the repeated ones measures localisation. More points make a chance
//! neighbour likelier, so an extractor can be held to another's count image by image
//! (`counts`), and the fractions compare.

use linetrack_datasets::LoadedPair;
use linetrack_vision::{OrbOptions, PointExtractor, PointFeatures};
use serde::Serialize;

/// Counts of one extractor over some pairs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct RepeatCounts {
    /// Left points with a ground truth whose shifted position is inside the right image.
    pub checked: usize,
    /// Of them, those with a right point within the radius.
    pub repeated: usize,
    /// Sum of the repeated ones' distances to their right point, pixels.
    pub distance_sum_px: f64,
    /// Points found, left and right images.
    pub points: usize,
}

impl RepeatCounts {
    /// Repeated over checked (0 when none was checked).
    pub fn repeatability(&self) -> f64 {
        self.repeated as f64 / self.checked.max(1) as f64
    }

    /// Mean distance of the repeated points to their right partner, pixels.
    pub fn mean_distance_px(&self) -> f64 {
        self.distance_sum_px / self.repeated.max(1) as f64
    }

    /// Adds `other`'s counts.
    pub fn add(&mut self, other: &RepeatCounts) {
        self.checked += other.checked;
        self.repeated += other.repeated;
        self.distance_sum_px += other.distance_sum_px;
        self.points += other.points;
    }
}

/// Extracts points from both images of `pair` with the extractor `options` name (at most
/// `counts` points in the left and the right image when given, else `options.features`) and
/// counts how many left points come back within `radius_px` of their true right position;
/// truth whose four pixels spread over more than `max_spread_px` is a depth edge and left
/// out. Returns the counts and the number of points of each image.
pub fn repeatability(
    pair: &LoadedPair,
    options: &OrbOptions,
    counts: Option<[usize; 2]>,
    radius_px: f64,
    max_spread_px: f64,
) -> anyhow::Result<(RepeatCounts, [usize; 2])> {
    let (mut left, mut right) = (PointFeatures::default(), PointFeatures::default());
    for (k, (image, out)) in [(&pair.left, &mut left), (&pair.right, &mut right)]
        .into_iter()
        .enumerate()
    {
        let features = match counts {
            Some(counts) => i32::try_from(counts[k].max(1))?,
            None => options.features,
        };
        PointExtractor::new(&OrbOptions {
            features,
            ..*options
        })?
        .extract(image, out)?;
    }
    let width = f64::from(pair.right.width());
    let mut counts = RepeatCounts {
        points: left.points.len() + right.points.len(),
        ..RepeatCounts::default()
    };
    for p in &left.points {
        let Some(d) = pair.disparity.interpolated(p.x, p.y, max_spread_px) else {
            continue;
        };
        let x = p.x - d;
        if !(0.0..=width - 1.0).contains(&x) {
            continue;
        }
        counts.checked += 1;
        let nearest = right
            .points
            .iter()
            .map(|q| (q.x - x).hypot(q.y - p.y))
            .fold(f64::INFINITY, f64::min);
        if nearest <= radius_px {
            counts.repeated += 1;
            counts.distance_sum_px += nearest;
        }
    }
    Ok((counts, [left.points.len(), right.points.len()]))
}

/// One row of the repeatability report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RepeatRow {
    /// The extractor's name.
    pub extractor: String,
    /// Its pyramid levels.
    pub levels: i32,
    /// The counts over every pair.
    pub counts: RepeatCounts,
    /// Repeated over checked.
    pub repeatability: f64,
    /// Mean distance of the repeated points to their partner, pixels.
    pub mean_distance_px: f64,
}

/// The rows as a Markdown table.
pub fn repeat_markdown(rows: &[RepeatRow], radius_px: f64) -> String {
    let mut out = format!(
        "| extractor | levels | points (L+R) | left points checked | repeated within {radius_px} px | repeatability | mean distance, px |\n|---|---|---|---|---|---|---|\n"
    );
    for r in rows {
        out.push_str(&format!(
            "| {} | {} | {} | {} | {} | {:.3} | {:.3} |\n",
            r.extractor,
            r.levels,
            r.counts.points,
            r.counts.checked,
            r.counts.repeated,
            r.repeatability,
            r.mean_distance_px
        ));
    }
    out
}
