//! [`Tracks`]: intervals on parallel tracks over time, coloured by group, each group's
//! intervals joined across tracks.

use crate::PlotError;
use crate::axis::{Axis, Scale};
use crate::canvas::*;
use plotters::prelude::*;
use std::path::Path;

/// An interval on a track of [`Tracks`].
#[derive(Debug, Clone, PartialEq)]
pub struct Bar {
    /// Index into [`Tracks::tracks`].
    pub track: usize,
    /// Start, data units.
    pub start: f64,
    /// End, data units.
    pub end: f64,
    /// The group it belongs to (its colour and label).
    pub group: u64,
    /// A part of an enclosing interval: drawn as a thin bar below it, unlabelled.
    pub nested: bool,
}

/// A group of [`Tracks`] and its intervals' `(track, start, end)`, in the order to join them.
pub type Link = (u64, Vec<(usize, f64, f64)>);

/// Intervals on parallel tracks over one time axis, each group's intervals joined in
/// order by a line from where one ends to where the next starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Tracks {
    /// Title above the plot.
    pub title: String,
    /// Time axis label, with its unit.
    pub x_label: String,
    /// Track names, top to bottom.
    pub tracks: Vec<String>,
    /// The intervals.
    pub bars: Vec<Bar>,
    /// Per group, its intervals in the order to join them.
    pub links: Vec<Link>,
}

impl Tracks {
    /// Draws the tracks into `path` (PNG).
    pub fn write(&self, path: &Path) -> Result<(), PlotError> {
        let height = 150 + ROW_HEIGHT * self.tracks.len().max(1) as u32;
        render(path, (WIDTH, height), |root| self.draw(root))
    }

    fn draw(&self, root: &Area<'_>) -> Result<(), DrawError> {
        root.fill(&WHITE)?;
        let main = root.titled(&self.title, text_style(TITLE_SIZE))?;
        let ends: Vec<f64> = self.bars.iter().flat_map(|b| [b.start, b.end]).collect();
        let axis = Axis::fit(&ends, Scale::Linear, false);
        let n = self.tracks.len().max(1);
        let row_of = |track: usize| (n - 1 - track.min(n - 1)) as f64;
        let mut chart = rows_chart(&main, &axis, &self.tracks, &self.x_label)?;
        // A bar at least `MIN_BAR_PX` wide (a span of microseconds is still seen), and a
        // label per linked group's bar, left out where it would cover another.
        let (lo, hi) = axis.ends();
        let per_px = (hi - lo) / f64::from(WIDTH - 150 - 28);
        let min_width = MIN_BAR_PX * per_px;
        let finite = |b: &&Bar| b.start.is_finite() && b.end.is_finite();
        chart.draw_series(self.bars.iter().filter(finite).map(|b| {
            let base = row_of(b.track);
            let (y0, y1) = if b.nested {
                (base + 0.2, base + 0.3)
            } else {
                (base + 0.32, base + 0.68)
            };
            let colour = palette(b.group as usize);
            let style = if b.nested {
                colour.mix(0.6).filled()
            } else {
                colour.filled()
            };
            let end = b.end.max(b.start + min_width);
            Rectangle::new([(b.start, y0), (end, y1)], style)
        }))?;
        let linked: std::collections::BTreeSet<u64> = self.links.iter().map(|l| l.0).collect();
        // Longest bars first, so a sliver does not take the label place of the bar it
        // touches.
        let mut placed: Vec<Vec<(f64, f64)>> = vec![Vec::new(); n];
        let mut labels = Vec::new();
        let mut bars: Vec<&Bar> = self
            .bars
            .iter()
            .filter(finite)
            .filter(|b| !b.nested && linked.contains(&b.group))
            .collect();
        bars.sort_by(|a, b| (b.end - b.start).total_cmp(&(a.end - a.start)));
        for b in bars {
            let row = n - 1 - b.track.min(n - 1);
            let text = b.group.to_string();
            let width = (text.len() as f64 * LABEL_CHAR_PX + 4.0) * per_px;
            let (x0, x1) = (b.start, b.start + width);
            if placed[row].iter().any(|&(p0, p1)| x0 < p1 && p0 < x1) {
                continue;
            }
            placed[row].push((x0, x1));
            labels.push(Text::new(
                text,
                (b.start, row_of(b.track) + 0.9),
                text_style(LABEL_SIZE - 3),
            ));
        }
        chart.draw_series(labels)?;
        for (group, path) in &self.links {
            let colour = palette(*group as usize);
            for pair in path.windows(2) {
                let (from, to) = (pair[0], pair[1]);
                let (a, b) = ((from.2, row_of(from.0) + 0.32), (to.1, row_of(to.0) + 0.68));
                if [a.0, b.0].iter().all(|x| x.is_finite()) {
                    chart.draw_series(std::iter::once(PathElement::new(
                        vec![a, b],
                        colour.stroke_width(2),
                    )))?;
                    chart.draw_series(std::iter::once(Circle::new(b, 3, colour.filled())))?;
                }
            }
        }
        Ok(())
    }
}
