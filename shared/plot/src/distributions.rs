//! [`Distributions`]: a histogram row per group of values on a shared axis, with marked
//! values and a limit.

use crate::PlotError;
use crate::axis::{Axis, Scale};
use crate::canvas::*;
use plotters::prelude::*;
use std::path::Path;

/// One row of [`Distributions`]: a group of values.
#[derive(Debug, Clone, PartialEq)]
pub struct Distribution {
    /// Row label.
    pub name: String,
    /// The values (non-finite ones are left out).
    pub values: Vec<f64>,
    /// Values marked by a vertical line across the row and written beside the row:
    /// the first solid, the others dashed (`("p50", 34.5), ("p99", 46.5)`).
    pub marks: Vec<(String, f64)>,
    /// A limit drawn in red across the row (a budget), labelled.
    pub limit: Option<(String, f64)>,
}

/// Distributions of values in rows on one shared axis: per row a histogram (bar heights
/// relative to the row's own tallest bin, so no row dwarfs another), its marks and limit.
#[derive(Debug, Clone, PartialEq)]
pub struct Distributions {
    /// Title above the plot.
    pub title: String,
    /// Axis label, with its unit.
    pub x_label: String,
    /// Unit written after the marks' values (`ms`).
    pub unit: String,
    /// The rows, top to bottom.
    pub rows: Vec<Distribution>,
    /// The shared axis's scale.
    pub scale: Scale,
}

/// Histogram bins across the shared axis.
const BINS: usize = 60;

impl Distributions {
    /// Draws the rows into `path` (PNG).
    pub fn write(&self, path: &Path) -> Result<(), PlotError> {
        let height = 150 + ROW_HEIGHT * self.rows.len().max(1) as u32;
        render(path, (WIDTH, height), |root| self.draw(root))
    }

    /// The shared axis: every value, mark and limit.
    pub(crate) fn axis(&self) -> Axis {
        let all: Vec<f64> = self
            .rows
            .iter()
            .flat_map(|r| {
                r.values
                    .iter()
                    .copied()
                    .chain(r.marks.iter().map(|m| m.1))
                    .chain(r.limit.iter().map(|l| l.1))
            })
            .collect();
        Axis::fit(&all, self.scale, true)
    }

    fn draw(&self, root: &Area<'_>) -> Result<(), DrawError> {
        root.fill(&WHITE)?;
        let main = root.titled(&self.title, text_style(TITLE_SIZE))?;
        let axis = self.axis();
        let n = self.rows.len().max(1);
        let names: Vec<String> = self.rows.iter().map(|r| r.name.clone()).collect();
        let x_label = if axis.log {
            format!("{} (log scale)", self.x_label)
        } else {
            self.x_label.clone()
        };
        let mut chart = rows_chart(&main, &axis, &names, &x_label)?;
        let (t0, t1) = axis.ends();
        let bin = (t1 - t0) / BINS as f64;
        for (i, row) in self.rows.iter().enumerate() {
            let base = (n - 1 - i) as f64;
            if i > 0 {
                chart.draw_series(std::iter::once(PathElement::new(
                    vec![(t0, base + 1.0), (t1, base + 1.0)],
                    RGBColor(200, 200, 200).stroke_width(1),
                )))?;
            }
            let colour = palette(i);
            let mut counts = [0usize; BINS];
            let mut count = 0;
            for v in row.values.iter().filter(|v| v.is_finite()) {
                let k = ((axis.to(*v) - t0) / bin)
                    .floor()
                    .clamp(0.0, (BINS - 1) as f64);
                counts[k as usize] += 1;
                count += 1;
            }
            let tallest = counts.iter().copied().max().unwrap_or(0).max(1) as f64;
            chart.draw_series(counts.iter().enumerate().filter(|(_, c)| **c > 0).map(
                |(k, c)| {
                    let x = t0 + k as f64 * bin;
                    let top = base + 0.08 + 0.55 * (*c as f64 / tallest);
                    Rectangle::new(
                        [(x, base + 0.08), (x + bin, top)],
                        colour.mix(0.75).filled(),
                    )
                },
            ))?;
            let mut caption = vec![format!("n {count}")];
            for (k, (label, value)) in row.marks.iter().enumerate() {
                if !value.is_finite() {
                    continue;
                }
                let t = axis.to(*value);
                let segment = [(t, base + 0.04), (t, base + 0.7)];
                if k == 0 {
                    chart.draw_series(std::iter::once(PathElement::new(
                        segment.to_vec(),
                        BLACK.stroke_width(3),
                    )))?;
                } else {
                    chart.draw_series(DashedLineSeries::new(
                        segment,
                        5,
                        3,
                        BLACK.stroke_width(2),
                    ))?;
                }
                caption.push(format!("{label} {}", value_text(*value, &self.unit)));
            }
            if let Some((label, limit)) = &row.limit
                && limit.is_finite()
            {
                let t = axis.to(*limit);
                chart.draw_series(std::iter::once(PathElement::new(
                    vec![(t, base + 0.02), (t, base + 0.98)],
                    RGBColor(200, 30, 30).stroke_width(3),
                )))?;
                caption.push(format!("{label} {}", value_text(*limit, &self.unit)));
            }
            if count == 0 {
                caption[0] = "no data".to_string();
            }
            chart.draw_series(std::iter::once(Text::new(
                caption.join("    "),
                (t0 + 0.01 * (t1 - t0), base + 0.95),
                text_style(LABEL_SIZE - 1),
            )))?;
        }
        Ok(())
    }
}
