//! The demo's picture: both views of the generated scene with the matches in colour.

use anyhow::Context;
use linetrack_draw::{Side, SideBySide, UNMATCHED, WRONG, palette};
use linetrack_l1_matcher::Match;
use linetrack_synthetic_segments::SegmentPair;
use std::path::Path;

/// Draws the first view left, the second right; correct matches share a colour, wrong
/// ones are red, unmatched segments grey.
pub(crate) fn matches_side_by_side(
    pair: &SegmentPair,
    matches: &[Match],
    path: &Path,
) -> anyhow::Result<()> {
    let mut picture = SideBySide::blank(pair.rig.width_px, pair.rig.height_px);
    for s in &pair.first.segments {
        picture.segment(Side::First, s, UNMATCHED, 1);
    }
    for s in &pair.second.segments {
        picture.segment(Side::Second, s, UNMATCHED, 1);
    }
    for (k, m) in matches.iter().enumerate() {
        let truth = pair.first.labels[m.query];
        let colour = if truth.is_some() && truth == pair.second.labels[m.train] {
            palette(k)
        } else {
            WRONG
        };
        picture.segment(Side::First, &pair.first.segments[m.query], colour, 2);
        picture.segment(Side::Second, &pair.second.segments[m.train], colour, 2);
    }
    picture
        .save(path)
        .with_context(|| format!("cannot write {}", path.display()))
}
