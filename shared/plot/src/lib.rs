//! Every chart the project draws, with [plotters] into PNG files, in one look: a title,
//! axes labelled with their units, a legend beside the plot, white background.
//!
//! - [`Chart`]: series over shared axes — lines (broken where a value is missing), points,
//!   or a rug of ticks along the top (things without a value, such as dropped frames) —
//!   with dashed vertical event lines and horizontal reference lines (budgets). The
//!   evaluation report's curves and trajectories and the pipeline's latency timeline.
//!   [`lines`] and [`scatter`] are the short forms.
//! - [`Distributions`]: one row per group of values (a pipeline stage) on a shared axis,
//!   logarithmic when the spread asks for it, each row a histogram with marked values
//!   (p50, p99) and a limit (the budget).
//! - [`Tracks`]: intervals on parallel tracks over time (spans of processes), coloured by
//!   group (frame), with each group's intervals joined across tracks (a frame's path).
//!
//! Text is set in DejaVu Sans, embedded (`fonts/`, with its licence): no system fonts are
//! needed. Non-finite values are left out; a chart without any data is still written, with
//! its axes and a "no data" note.

#![warn(missing_docs)]

mod axis;

pub use axis::{LOG_SPREAD, Scale};

use axis::Axis;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Plotting errors.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// plotters could not draw the chart.
    #[error("cannot draw {}", path.display())]
    Draw {
        /// The chart's file.
        path: PathBuf,
        /// What plotters reported.
        #[source]
        source: DrawingAreaErrorKind<BitMapBackendError>,
    },
    /// The PNG could not be encoded or written.
    #[error("cannot write {}", path.display())]
    Write {
        /// The chart's file.
        path: PathBuf,
        /// Why.
        #[source]
        source: image::ImageError,
    },
    /// The embedded font did not load (a broken build).
    #[error("the embedded font cannot be read")]
    Font,
}

/// What the bitmap backend reports.
type BitMapBackendError = <BitMapBackend<'static> as DrawingBackend>::ErrorType;
type DrawError = DrawingAreaErrorKind<BitMapBackendError>;
type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// The font family every text is set in.
const FONT: &str = "sans-serif";
static FONT_LOADED: OnceLock<bool> = OnceLock::new();

fn load_font() -> Result<(), PlotError> {
    let ok = FONT_LOADED.get_or_init(|| {
        plotters::style::register_font(
            FONT,
            FontStyle::Normal,
            include_bytes!("../fonts/DejaVuSans.ttf"),
        )
        .is_ok()
    });
    if *ok { Ok(()) } else { Err(PlotError::Font) }
}

fn text_style(size: u32) -> TextStyle<'static> {
    (FONT, size).into_font().color(&BLACK)
}

/// Series colours (Tableau 10), in order.
pub const PALETTE: [(u8, u8, u8); 10] = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
];

fn palette(k: usize) -> RGBColor {
    let (r, g, b) = PALETTE[k % PALETTE.len()];
    RGBColor(r, g, b)
}

/// Chart size, pixels.
const WIDTH: u32 = 1100;
const HEIGHT: u32 = 560;
/// Width of the legend panel right of the plot.
const LEGEND_WIDTH: u32 = 240;
const TITLE_SIZE: u32 = 20;
const LABEL_SIZE: u32 = 15;
const LEGEND_ROW: i32 = 22;

/// Draws into an RGB buffer of `width × height` and writes it to `path` as PNG.
fn render(
    path: &Path,
    (width, height): (u32, u32),
    draw: impl FnOnce(&Area<'_>) -> Result<(), DrawError>,
) -> Result<(), PlotError> {
    load_font()?;
    let mut buffer = vec![255u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        draw(&root)
            .and_then(|()| root.present())
            .map_err(|source| PlotError::Draw {
                path: path.to_path_buf(),
                source,
            })?;
    }
    image::save_buffer_with_format(
        path,
        &buffer,
        width,
        height,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .map_err(|source| {
        // A picture cut short (a full disk, the file size limit) is not left behind.
        let _ = std::fs::remove_file(path);
        PlotError::Write {
            path: path.to_path_buf(),
            source,
        }
    })
}

/// A point marker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Marker {
    /// Filled circle.
    Circle,
    /// Diagonal cross.
    Cross,
    /// Filled triangle, point up.
    Triangle,
}

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

/// Event line colours: apart from the reference lines' red.
fn event_colour(k: usize) -> RGBColor {
    const EVENTS: [(u8, u8, u8); 5] = [
        (148, 103, 189),
        (44, 160, 44),
        (23, 190, 207),
        (30, 30, 30),
        (140, 86, 75),
    ];
    let (r, g, b) = EVENTS[k % EVENTS.len()];
    RGBColor(r, g, b)
}

/// The margins and label areas of every chart with axes.
fn chart_builder<'a, 'b>(area: &'a Area<'b>) -> ChartBuilder<'a, 'b, BitMapBackend<'b>> {
    let mut builder = ChartBuilder::on(area);
    builder
        .margin(14)
        .x_label_area_size(48)
        .y_label_area_size(78);
    builder
}

/// A chart with one horizontal row per name, the first at the top, over `axis`: the row
/// names as y labels, the mesh drawn.
fn rows_chart<'a, 'b>(
    area: &'a Area<'b>,
    axis: &Axis,
    names: &[String],
    x_label: &str,
) -> Result<Plot<'a, 'b>, DrawError> {
    let n = names.len().max(1);
    let centres: Vec<f64> = (0..n).map(|i| i as f64 + 0.5).collect();
    let mut chart = chart_builder(area)
        .y_label_area_size(150)
        .build_cartesian_2d(
            axis.coord(),
            axis::Ticked::new(0.0..n as f64, centres, Vec::new()),
        )?;
    let name_of = |t: &f64| {
        let row = n - 1 - (t.floor().max(0.0) as usize).min(n - 1);
        names.get(row).cloned().unwrap_or_default()
    };
    chart
        .configure_mesh()
        .x_desc(x_label)
        .x_label_formatter(&|t| axis.label(*t))
        .y_label_formatter(&name_of)
        .disable_y_mesh()
        .label_style(text_style(LABEL_SIZE))
        .axis_desc_style(text_style(LABEL_SIZE))
        .bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(240, 240, 240))
        .draw()?;
    Ok(chart)
}

/// One unbroken stretch of a line series; a lone point as a dot.
fn draw_run(
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

type Plot<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<axis::Ticked, axis::Ticked>>;

fn draw_markers(
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

/// What a legend entry shows beside its text.
enum LegendSample {
    Line(RGBColor, u32),
    Dashed(RGBAColor),
    Marker(RGBColor, Marker),
    Rug(RGBColor),
}

fn draw_legend(area: &Area<'_>, entries: &[(String, LegendSample)]) -> Result<(), DrawError> {
    let (x, mut y) = (8, 60);
    for (name, sample) in entries {
        let mid = (x + 14, y);
        match sample {
            LegendSample::Line(c, w) => {
                area.draw(&PathElement::new(
                    vec![(x, y), (x + 28, y)],
                    c.stroke_width(*w),
                ))?;
            }
            LegendSample::Dashed(c) => {
                for k in 0..3 {
                    area.draw(&PathElement::new(
                        vec![(x + 11 * k, y), (x + 11 * k + 6, y)],
                        c.stroke_width(2),
                    ))?;
                }
            }
            LegendSample::Marker(c, Marker::Circle) => {
                area.draw(&Circle::new(mid, 4, c.filled()))?;
            }
            LegendSample::Marker(c, Marker::Cross) => {
                area.draw(&Cross::new(mid, 5, c.stroke_width(2)))?;
            }
            LegendSample::Marker(c, Marker::Triangle) => {
                area.draw(&TriangleMarker::new(mid, 6, c.filled()))?;
            }
            LegendSample::Rug(c) => {
                area.draw(&PathElement::new(
                    vec![(x + 14, y - 7), (x + 14, y + 7)],
                    c.stroke_width(2),
                ))?;
            }
        }
        area.draw(&Text::new(
            name.clone(),
            (x + 36, y - 8),
            text_style(LABEL_SIZE - 1),
        ))?;
        y += LEGEND_ROW;
    }
    Ok(())
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
/// Height of one row, pixels.
const ROW_HEIGHT: u32 = 96;
/// Narrowest bar of [`Tracks`], pixels.
const MIN_BAR_PX: f64 = 3.0;
/// Width of a digit of a [`Tracks`] label, pixels (about).
const LABEL_CHAR_PX: f64 = 8.0;

impl Distributions {
    /// Draws the rows into `path` (PNG).
    pub fn write(&self, path: &Path) -> Result<(), PlotError> {
        let height = 150 + ROW_HEIGHT * self.rows.len().max(1) as u32;
        render(path, (WIDTH, height), |root| self.draw(root))
    }

    /// The shared axis: every value, mark and limit.
    fn axis(&self) -> Axis {
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

/// `value` with three significant digits (at least two decimals below 1) and `unit`.
fn value_text(value: f64, unit: &str) -> String {
    let decimals = if value.abs() >= 100.0 {
        0
    } else if value.abs() >= 10.0 {
        1
    } else if value.abs() >= 1.0 || value == 0.0 {
        2
    } else {
        (2.0 - value.abs().log10().floor()).clamp(2.0, 6.0) as usize
    };
    format!("{value:.decimals$} {unit}").trim_end().to_string()
}

#[cfg(test)]
mod tests;
