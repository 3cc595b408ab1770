//! [`Chart`]: series over shared axes (lines, points, rugs) with event and reference lines;
//! [`lines`] and [`scatter`], its short forms.

use crate::PlotError;
use crate::axis::{Axis, Scale};
use crate::canvas::*;
use plotters::prelude::*;
use std::path::Path;

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Style {
    /// Joined by a line `width` pixels wide, broken at non-finite values.
    Line {
        /// Pixels.
        width: u32,
    },
    /// A marker at each point.
    Points(Marker),
    /// A short vertical tick along the top edge at each point's x (its y is not used):
    /// things that happened at an x without a value to plot.
    Rug,
}

/// One named series.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// `(x, y)` in data units.
    pub points: Vec<(f64, f64)>,
    /// How it is drawn.
    pub style: Style,
    /// RGB; the palette's next colour when `None`.
    pub colour: Option<(u8, u8, u8)>,
}

impl Series {
    /// A series drawn as a 2-pixel line in the palette's next colour.
    pub fn line(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            style: Style::Line { width: 2 },
            colour: None,
        }
    }

    /// The same series drawn as `style`.
    pub fn styled(mut self, style: Style) -> Self {
        self.style = style;
        self
    }

    /// The same series in colour `rgb`.
    pub fn coloured(mut self, rgb: (u8, u8, u8)) -> Self {
        self.colour = Some(rgb);
        self
    }
}

/// Something that happened at an x: a dashed vertical line, one colour and legend entry per
/// `kind` (no entry when `kind` is empty).
#[derive(Debug, Clone, PartialEq)]
pub struct EventLine {
    /// Where, data units.
    pub x: f64,
    /// What (the legend text).
    pub kind: String,
}

/// A horizontal dashed line at `y` (a budget), labelled in the legend.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    /// Where, data units.
    pub y: f64,
    /// Legend text.
    pub label: String,
}

/// A chart of series over shared axes; [`Chart::write`] draws it.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// X axis label, with its unit.
    pub x_label: String,
    /// Y axis label, with its unit.
    pub y_label: String,
    /// The data.
    pub series: Vec<Series>,
    /// Dashed vertical lines.
    pub events: Vec<EventLine>,
    /// Dashed horizontal lines.
    pub references: Vec<Reference>,
    /// The y axis's scale (the x axis is linear).
    pub y_scale: Scale,
    /// Whether the y axis starts at zero (when no value is negative; linear axes only).
    pub y_from_zero: bool,
    /// One unit is as long on both axes (top views of trajectories); linear axes only.
    pub equal_axes: bool,
}

impl Chart {
    /// An empty chart: linear axes, no data.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            events: Vec::new(),
            references: Vec::new(),
            y_scale: Scale::Linear,
            y_from_zero: false,
            equal_axes: false,
        }
    }

    /// Draws the chart into `path` (PNG).
    pub fn write(&self, path: &Path) -> Result<(), PlotError> {
        render(path, (WIDTH, HEIGHT), |root| self.draw(root))
    }

    /// The y axis this chart gets.
    fn y_axis(&self) -> Axis {
        let ys: Vec<f64> = self
            .series
            .iter()
            .filter(|s| s.style != Style::Rug)
            .flat_map(|s| s.points.iter().map(|p| p.1))
            .chain(self.references.iter().map(|r| r.y))
            .collect();
        Axis::fit(&ys, self.y_scale, self.y_from_zero)
    }

    fn draw(&self, root: &Area<'_>) -> Result<(), DrawError> {
        root.fill(&WHITE)?;
        let (main, legend) = root.split_horizontally(WIDTH - LEGEND_WIDTH);
        let main = main.titled(&self.title, text_style(TITLE_SIZE))?;
        let xs: Vec<f64> = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0))
            .chain(self.events.iter().map(|e| e.x))
            .collect();
        let mut x_axis = Axis::fit(&xs, Scale::Linear, false);
        let mut y_axis = self.y_axis();
        let has_data = self
            .series
            .iter()
            .flat_map(|s| &s.points)
            .any(|(x, y)| x.is_finite() && y.is_finite());
        if self.equal_axes && !y_axis.log {
            let probe = chart_builder(&main).build_cartesian_2d(x_axis.coord(), y_axis.coord())?;
            let (w, h) = probe.plotting_area().dim_in_pixel();
            let per_pixel = ((x_axis.hi - x_axis.lo) / f64::from(w.max(1)))
                .max((y_axis.hi - y_axis.lo) / f64::from(h.max(1)));
            x_axis.widen_to(per_pixel * f64::from(w));
            y_axis.widen_to(per_pixel * f64::from(h));
        }
        let mut chart = chart_builder(&main).build_cartesian_2d(x_axis.coord(), y_axis.coord())?;
        let y_label = if y_axis.log {
            format!("{} (log scale)", self.y_label)
        } else {
            self.y_label.clone()
        };
        chart
            .configure_mesh()
            .x_desc(self.x_label.as_str())
            .y_desc(y_label)
            .x_label_formatter(&|t| x_axis.label(*t))
            .y_label_formatter(&|t| y_axis.label(*t))
            .label_style(text_style(LABEL_SIZE - 2))
            .axis_desc_style(text_style(LABEL_SIZE))
            .bold_line_style(RGBColor(215, 215, 215))
            .light_line_style(RGBColor(240, 240, 240))
            .draw()?;
        let (y0, y1) = y_axis.ends();
        let (x0, x1) = x_axis.ends();
        if !has_data {
            chart.draw_series(std::iter::once(Text::new(
                "no data",
                (0.5 * (x0 + x1), 0.5 * (y0 + y1)),
                text_style(LABEL_SIZE),
            )))?;
        }

        let mut entries: Vec<(String, LegendSample)> = Vec::new();
        for (k, reference) in self.references.iter().enumerate() {
            let colour = RGBColor(200, 30, 30).mix(1.0 - 0.3 * k as f64);
            let y = y_axis.to(reference.y);
            if reference.y.is_finite() {
                chart.draw_series(DashedLineSeries::new(
                    [(x0, y), (x1, y)],
                    10,
                    6,
                    colour.stroke_width(2),
                ))?;
            }
            entries.push((
                reference.label.clone(),
                LegendSample::Dashed(colour.to_rgba()),
            ));
        }
        let mut kinds: Vec<&str> = Vec::new();
        for event in self.events.iter().filter(|e| e.x.is_finite()) {
            let k = match kinds.iter().position(|kind| *kind == event.kind) {
                Some(k) => k,
                None => {
                    kinds.push(&event.kind);
                    kinds.len() - 1
                }
            };
            let colour = event_colour(k);
            chart.draw_series(DashedLineSeries::new(
                [(event.x, y0), (event.x, y1)],
                6,
                5,
                colour.stroke_width(1),
            ))?;
        }
        for (k, kind) in kinds.iter().enumerate().filter(|(_, k)| !k.is_empty()) {
            entries.push((
                kind.to_string(),
                LegendSample::Dashed(event_colour(k).to_rgba()),
            ));
        }
        let mut rug_level = 0;
        let mut auto_colour = 0;
        for series in &self.series {
            let colour = match series.colour {
                Some((r, g, b)) => RGBColor(r, g, b),
                None => {
                    auto_colour += 1;
                    palette(auto_colour - 1)
                }
            };
            let finite = series
                .points
                .iter()
                .filter(|(x, y)| x.is_finite() && (series.style == Style::Rug || y.is_finite()));
            match series.style {
                Style::Line { width } => {
                    let mut run: Vec<(f64, f64)> = Vec::new();
                    for &(x, y) in &series.points {
                        if x.is_finite() && y.is_finite() {
                            run.push((x, y_axis.to(y)));
                        } else if !run.is_empty() {
                            draw_run(&mut chart, &run, colour, width)?;
                            run.clear();
                        }
                    }
                    draw_run(&mut chart, &run, colour, width)?;
                    entries.push((series.name.clone(), LegendSample::Line(colour, width)));
                }
                Style::Points(marker) => {
                    let at = finite.map(|&(x, y)| (x, y_axis.to(y)));
                    draw_markers(&mut chart, at, marker, colour)?;
                    entries.push((series.name.clone(), LegendSample::Marker(colour, marker)));
                }
                Style::Rug => {
                    let tick = 0.035 * (y1 - y0);
                    let top = y1 - tick * f64::from(rug_level);
                    rug_level += 1;
                    chart.draw_series(finite.map(|&(x, _)| {
                        PathElement::new(vec![(x, top), (x, top - tick)], colour.stroke_width(2))
                    }))?;
                    entries.push((series.name.clone(), LegendSample::Rug(colour)));
                }
            }
        }
        draw_legend(&legend, &entries)
    }
}

/// One unbroken stretch of a line series; a lone point as a dot.
pub(crate) fn draw_run(
    chart: &mut Plot<'_, '_>,
    run: &[(f64, f64)],
    colour: RGBColor,
    width: u32,
) -> Result<(), DrawError> {
    match run {
        [] => Ok(()),
        [point] => chart
            .draw_series(std::iter::once(Circle::new(
                *point,
                width + 1,
                colour.filled(),
            )))
            .map(|_| ()),
        _ => chart
            .draw_series(std::iter::once(PathElement::new(
                run.to_vec(),
                colour.stroke_width(width),
            )))
            .map(|_| ()),
    }
}

pub(crate) fn draw_markers(
    chart: &mut Plot<'_, '_>,
    at: impl Iterator<Item = (f64, f64)>,
    marker: Marker,
    colour: RGBColor,
) -> Result<(), DrawError> {
    match marker {
        Marker::Circle => chart
            .draw_series(at.map(|p| Circle::new(p, 4, colour.filled())))
            .map(|_| ()),
        Marker::Cross => chart
            .draw_series(at.map(|p| Cross::new(p, 5, colour.stroke_width(2))))
            .map(|_| ()),
        Marker::Triangle => chart
            .draw_series(at.map(|p| TriangleMarker::new(p, 6, colour.filled())))
            .map(|_| ()),
    }
}

/// Series `(name, points)` as lines on shared axes; `markers` are x positions drawn as
/// dashed vertical lines (events, explained in the title). One unit is as long on both
/// axes when `equal_axes`.
pub fn lines(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(String, Vec<(f64, f64)>)],
    markers: &[f64],
    equal_axes: bool,
) -> Result<(), PlotError> {
    let mut chart = Chart::new(title, x_label, y_label);
    chart.series = series
        .iter()
        .map(|(name, points)| Series::line(name.clone(), points.clone()))
        .collect();
    chart.events = markers
        .iter()
        .map(|&x| EventLine {
            x,
            kind: String::new(),
        })
        .collect();
    chart.equal_axes = equal_axes;
    chart.write(path)
}

/// Series `(name, points)` drawn as points (one filled circle each, no joining line).
pub fn scatter(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<(), PlotError> {
    let mut chart = Chart::new(title, x_label, y_label);
    chart.series = series
        .iter()
        .map(|(name, points)| {
            Series::line(name.clone(), points.clone()).styled(Style::Points(Marker::Circle))
        })
        .collect();
    chart.write(path)
}
