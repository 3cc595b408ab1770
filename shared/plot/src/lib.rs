//! Line plots drawn with OpenCV into PNG files (its built-in Hershey font labels the axes):
//! evaluation curves, trajectories, latency histograms.

use anyhow::Context;
use opencv::core::{CV_8UC3, Mat, Point, Scalar, Vector};
use opencv::imgcodecs;
use opencv::imgproc;
use std::path::Path;

/// Line colours (BGR), one per series.
pub const COLOURS: [(f64, f64, f64); 6] = [
    (255.0, 255.0, 255.0),
    (60.0, 180.0, 255.0),
    (255.0, 160.0, 60.0),
    (90.0, 220.0, 90.0),
    (200.0, 90.0, 230.0),
    (80.0, 80.0, 255.0),
];

const W: i32 = 1000;
/// Right-hand space for the legend, outside the plot area.
const LEGEND: i32 = 190;
const H: i32 = 480;
const MARGIN: i32 = 60;

fn colour(k: usize) -> Scalar {
    let (b, g, r) = COLOURS[k % COLOURS.len()];
    Scalar::new(b, g, r, 0.0)
}

fn text(canvas: &mut Mat, label: &str, x: i32, y: i32, k: usize) -> opencv::Result<()> {
    imgproc::put_text(
        canvas,
        label,
        Point::new(x, y),
        imgproc::FONT_HERSHEY_SIMPLEX,
        0.5,
        colour(k),
        1,
        imgproc::LINE_AA,
        false,
    )
}

/// Series `(name, points)` in data coordinates, on shared axes; `markers` are x positions
/// drawn as dashed vertical lines (events). Equal axis scales when `equal_axes`.
pub fn lines(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(String, Vec<(f64, f64)>)],
    markers: &[f64],
    equal_axes: bool,
) -> anyhow::Result<()> {
    draw(
        path,
        (title, x_label, y_label),
        series,
        markers,
        equal_axes,
        false,
    )
}

/// Series `(name, points)` drawn as points (one filled circle each, no joining line).
pub fn scatter(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(String, Vec<(f64, f64)>)],
) -> anyhow::Result<()> {
    draw(path, (title, x_label, y_label), series, &[], false, true)
}

fn draw(
    path: &Path,
    (title, x_label, y_label): (&str, &str, &str),
    series: &[(String, Vec<(f64, f64)>)],
    markers: &[f64],
    equal_axes: bool,
    points_only: bool,
) -> anyhow::Result<()> {
    let mut canvas =
        Mat::new_rows_cols_with_default(H, W, CV_8UC3, Scalar::all(25.0)).context("canvas")?;
    let all = series
        .iter()
        .flat_map(|(_, p)| p.iter())
        .filter(|(x, y)| x.is_finite() && y.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = all.fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), (x, y)| (a.min(*x), b.max(*x), c.min(*y), d.max(*y)),
    );
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    let pad = |lo: f64, hi: f64| {
        if hi - lo < 1e-9 {
            (lo - 0.5, hi + 0.5)
        } else {
            (lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo))
        }
    };
    (x0, x1) = pad(x0, x1);
    (y0, y1) = pad(y0, y1);
    let (pw, ph) = (
        f64::from(W - 2 * MARGIN - LEGEND),
        f64::from(H - 2 * MARGIN),
    );
    let (mut sx, mut sy) = (pw / (x1 - x0), ph / (y1 - y0));
    if equal_axes {
        let s = sx.min(sy);
        (sx, sy) = (s, s);
    }
    let to_px = |x: f64, y: f64| {
        Point::new(
            MARGIN + ((x - x0) * sx) as i32,
            H - MARGIN - ((y - y0) * sy) as i32,
        )
    };
    let axis = Scalar::all(160.0);
    imgproc::rectangle_points(
        &mut canvas,
        Point::new(MARGIN, MARGIN),
        Point::new(W - MARGIN - LEGEND, H - MARGIN),
        axis,
        1,
        imgproc::LINE_8,
        0,
    )?;
    for m in markers {
        let p = to_px(*m, y0);
        let mut y = MARGIN;
        while y < H - MARGIN {
            imgproc::line(
                &mut canvas,
                Point::new(p.x, y),
                Point::new(p.x, (y + 6).min(H - MARGIN)),
                Scalar::new(90.0, 90.0, 220.0, 0.0),
                1,
                imgproc::LINE_8,
                0,
            )?;
            y += 12;
        }
    }
    for (k, (name, points)) in series.iter().enumerate() {
        let pts: Vector<Point> = points
            .iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(x, y)| to_px(*x, *y))
            .collect();
        if points_only {
            for p in pts.iter() {
                imgproc::circle(&mut canvas, p, 5, colour(k), -1, imgproc::LINE_AA, 0)?;
            }
        } else if pts.len() > 1 {
            let mut polylines = Vector::<Vector<Point>>::new();
            polylines.push(pts);
            imgproc::polylines(
                &mut canvas,
                &polylines,
                false,
                colour(k),
                2,
                imgproc::LINE_AA,
                0,
            )?;
        }
        text(
            &mut canvas,
            name,
            W - LEGEND - MARGIN / 2,
            MARGIN + 20 + 18 * k as i32,
            k,
        )?;
    }
    text(&mut canvas, title, MARGIN, 30, 0)?;
    text(&mut canvas, x_label, (W - LEGEND) / 2 - 40, H - 20, 0)?;
    text(&mut canvas, y_label, 5, MARGIN - 10, 0)?;
    text(&mut canvas, &format!("{x0:.2}"), MARGIN, H - MARGIN + 18, 0)?;
    text(
        &mut canvas,
        &format!("{x1:.2}"),
        W - MARGIN - LEGEND - 40,
        H - MARGIN + 18,
        0,
    )?;
    text(&mut canvas, &format!("{y0:.2}"), 5, H - MARGIN, 0)?;
    text(&mut canvas, &format!("{y1:.2}"), 5, MARGIN + 10, 0)?;
    imgcodecs::imwrite(path.display().to_string().as_str(), &canvas, &Vector::new())
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

/// Histogram outlines: for each series `(name, values)`, the count of values per bin of
/// width `bin` from 0, drawn as a step line; `markers` as dashed vertical lines (budgets).
pub fn histogram(
    path: &Path,
    title: &str,
    x_label: &str,
    series: &[(String, Vec<f64>)],
    bin: f64,
    markers: &[f64],
) -> anyhow::Result<()> {
    anyhow::ensure!(
        bin.is_finite() && bin > 0.0,
        "histogram bin width must be positive, got {bin}"
    );
    let top = series
        .iter()
        .flat_map(|(_, v)| v.iter().copied())
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .max(markers.iter().copied().fold(0.0, f64::max));
    let bins = ((top / bin).floor() as usize + 1).min(10_000);
    let outlines: Vec<(String, Vec<(f64, f64)>)> = series
        .iter()
        .map(|(name, values)| {
            let mut counts = vec![0usize; bins];
            for v in values.iter().filter(|v| v.is_finite() && **v >= 0.0) {
                counts[((v / bin) as usize).min(bins - 1)] += 1;
            }
            let mut points = vec![(0.0, 0.0)];
            for (k, c) in counts.iter().enumerate() {
                let (x0, x1, y) = (k as f64 * bin, (k + 1) as f64 * bin, *c as f64);
                points.push((x0, y));
                points.push((x1, y));
            }
            points.push((bins as f64 * bin, 0.0));
            (name.clone(), points)
        })
        .collect();
    lines(path, title, x_label, "frames", &outlines, markers, false)
}
