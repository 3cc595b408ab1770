//! What every chart shares: the embedded font, the palette, the sizes, the PNG canvas, the
//! axes' builders, the point markers, the legend and the value labels.

use crate::PlotError;
use crate::axis::{self, Axis};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;
use std::sync::OnceLock;

/// What the bitmap backend reports.
pub(crate) type BitMapBackendError = <BitMapBackend<'static> as DrawingBackend>::ErrorType;
pub(crate) type DrawError = DrawingAreaErrorKind<BitMapBackendError>;
pub(crate) type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// The font family every text is set in.
pub(crate) const FONT: &str = "sans-serif";
pub(crate) static FONT_LOADED: OnceLock<bool> = OnceLock::new();

pub(crate) fn load_font() -> Result<(), PlotError> {
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

pub(crate) fn text_style(size: u32) -> TextStyle<'static> {
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

pub(crate) fn palette(k: usize) -> RGBColor {
    let (r, g, b) = PALETTE[k % PALETTE.len()];
    RGBColor(r, g, b)
}

/// Chart size, pixels.
pub(crate) const WIDTH: u32 = 1100;
pub(crate) const HEIGHT: u32 = 560;
/// Width of the legend panel right of the plot.
pub(crate) const LEGEND_WIDTH: u32 = 240;
pub(crate) const TITLE_SIZE: u32 = 20;
pub(crate) const LABEL_SIZE: u32 = 15;
/// Height of one row of a [`Distributions`](crate::Distributions) or [`Tracks`](crate::Tracks), pixels.
pub(crate) const ROW_HEIGHT: u32 = 96;
/// Narrowest bar of [`Tracks`](crate::Tracks), pixels.
pub(crate) const MIN_BAR_PX: f64 = 3.0;
/// Width of a digit of a [`Tracks`](crate::Tracks) label, pixels (about).
pub(crate) const LABEL_CHAR_PX: f64 = 8.0;
pub(crate) const LEGEND_ROW: i32 = 22;

/// Draws into an RGB buffer of `width × height` and writes it to `path` as PNG.
pub(crate) fn render(
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

/// A chart's drawing context over two ticked axes.
pub(crate) type Plot<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<axis::Ticked, axis::Ticked>>;

/// Event line colours: apart from the reference lines' red.
pub(crate) fn event_colour(k: usize) -> RGBColor {
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
pub(crate) fn chart_builder<'a, 'b>(area: &'a Area<'b>) -> ChartBuilder<'a, 'b, BitMapBackend<'b>> {
    let mut builder = ChartBuilder::on(area);
    builder
        .margin(14)
        .x_label_area_size(48)
        .y_label_area_size(78);
    builder
}

/// A chart with one horizontal row per name, the first at the top, over `axis`: the row
/// names as y labels, the mesh drawn.
pub(crate) fn rows_chart<'a, 'b>(
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

/// What a legend entry shows beside its text.
pub(crate) enum LegendSample {
    Line(RGBColor, u32),
    Dashed(RGBAColor),
    Marker(RGBColor, Marker),
    Rug(RGBColor),
}

pub(crate) fn draw_legend(
    area: &Area<'_>,
    entries: &[(String, LegendSample)],
) -> Result<(), DrawError> {
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

/// `value` with three significant digits (at least two decimals below 1) and `unit`.
pub(crate) fn value_text(value: f64, unit: &str) -> String {
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
