use super::*;
use crate::canvas::{HEIGHT, LEGEND_WIDTH, ROW_HEIGHT, WIDTH, value_text};
use linetrack_test_data::Scratch;
use std::path::Path;

fn read(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

/// Pixels in the band of rows `y0..y1` that are dark (text, axes).
fn dark_pixels(img: &image::RgbImage, y0: u32, y1: u32) -> usize {
    (y0..y1.min(img.height()))
        .flat_map(|y| (0..img.width()).map(move |x| (x, y)))
        .filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|c| *c < 100))
        .count()
}

#[test]
fn a_chart_is_written_with_its_title_set_in_the_embedded_font() {
    let dir = Scratch::new("plot", "lines");
    let path = dir.join("lines.png");
    let series = vec![
        ("a".to_string(), vec![(0.0, 1.0), (1.0, 2.0), (2.0, 1.5)]),
        (
            "b".to_string(),
            vec![(0.0, 0.5), (1.0, f64::NAN), (2.0, 0.7)],
        ),
    ];
    lines(&path, "Title", "frame", "matches", &series, &[1.0], false)
        .unwrap_or_else(|e| panic!("{e}"));
    let img = read(&path);
    assert_eq!((img.width(), img.height()), (WIDTH, HEIGHT));
    assert!(
        dark_pixels(&img, 0, 30) > 20,
        "no title text: the font did not render"
    );
    // The legend panel holds the series names.
    let legend_text = (50..120)
        .flat_map(|y| (WIDTH - LEGEND_WIDTH + 40..WIDTH).map(move |x| (x, y)))
        .filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|c| *c < 100))
        .count();
    assert!(legend_text > 10, "no legend text");
}

#[test]
fn empty_nan_and_single_point_data_still_give_a_picture() {
    type NamedSeries = Vec<(String, Vec<(f64, f64)>)>;
    let cases: Vec<NamedSeries> = vec![
        vec![],
        vec![(
            "nan".to_string(),
            vec![(f64::NAN, f64::NAN), (1.0, f64::INFINITY)],
        )],
        vec![("one".to_string(), vec![(3.0, 4.0)])],
        vec![("flat".to_string(), vec![(0.0, 2.0), (1.0, 2.0)])],
    ];
    for (k, series) in cases.iter().enumerate() {
        let dir = Scratch::new("plot", &format!("degenerate-{k}"));
        let path = dir.join("degenerate.png");
        lines(&path, "degenerate", "x [m]", "z [m]", series, &[], true)
            .unwrap_or_else(|e| panic!("case {k}: {e}"));
        scatter(&path, "degenerate", "x", "y", series).unwrap_or_else(|e| panic!("case {k}: {e}"));
        assert_eq!(read(&path).width(), WIDTH);
    }
}

#[test]
fn equal_axes_give_one_unit_the_same_length_both_ways() {
    // A square path must be drawn square: its red extent is as wide as it is tall.
    let dir = Scratch::new("plot", "square");
    let path = dir.join("square.png");
    let square = vec![(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (0.0, 0.0)];
    let mut chart = Chart::new("square", "x [m]", "z [m]");
    chart.series = vec![Series::line("square", square).coloured((255, 0, 0))];
    chart.equal_axes = true;
    chart.write(&path).unwrap_or_else(|e| panic!("{e}"));
    let img = read(&path);
    let red: Vec<(u32, u32)> = img
        .enumerate_pixels()
        .filter(|(x, _, p)| *x < WIDTH - LEGEND_WIDTH && p.0 == [255, 0, 0])
        .map(|(x, y, _)| (x, y))
        .collect();
    let extent = |f: fn(&(u32, u32)) -> u32| {
        let v: Vec<u32> = red.iter().map(f).collect();
        v.iter().max().copied().unwrap_or(0) - v.iter().min().copied().unwrap_or(0)
    };
    let (w, h) = (extent(|p| p.0), extent(|p| p.1));
    assert!(w > 50 && w.abs_diff(h) <= 3, "drawn {w} × {h} px");
}

#[test]
fn a_rug_and_a_reference_line_are_drawn_where_asked() {
    let dir = Scratch::new("plot", "timeline");
    let path = dir.join("timeline.png");
    let mut chart = Chart::new("timeline", "frame", "latency [ms]");
    chart.series = vec![
        Series::line("e2e", (0..50).map(|k| (k as f64, 70.0)).collect()),
        Series::line("dropped", vec![(10.0, f64::NAN)])
            .styled(Style::Rug)
            .coloured((0, 0, 255)),
    ];
    chart.references = vec![Reference {
        y: 250.0,
        label: "budget".to_string(),
    }];
    chart.y_from_zero = true;
    chart.write(&path).unwrap_or_else(|e| panic!("{e}"));
    let img = read(&path);
    let blue = img
        .enumerate_pixels()
        .filter(|(x, _, p)| *x < WIDTH - LEGEND_WIDTH && p.0 == [0, 0, 255])
        .count();
    assert!(blue > 5, "the dropped frame's tick is missing");
}

#[test]
fn distributions_handle_zero_values_on_a_log_axis_and_empty_rows() {
    let dir = Scratch::new("plot", "distributions");
    let path = dir.join("distributions.png");
    let rows = vec![
        Distribution {
            name: "frame-source".to_string(),
            values: vec![0.0, 0.004, 0.01, 0.008],
            marks: vec![("p50".to_string(), 0.004), ("p99".to_string(), 0.01)],
            limit: Some(("budget".to_string(), 30.0)),
        },
        Distribution {
            name: "line-detector".to_string(),
            values: (0..100).map(|k| 30.0 + f64::from(k) * 0.2).collect(),
            marks: vec![("p50".to_string(), 40.0), ("p99".to_string(), 49.8)],
            limit: Some(("budget".to_string(), 80.0)),
        },
        Distribution {
            name: "empty".to_string(),
            values: vec![f64::NAN],
            marks: vec![("p50".to_string(), f64::NAN)],
            limit: None,
        },
    ];
    let plot = Distributions {
        title: "latency".to_string(),
        x_label: "latency [ms]".to_string(),
        unit: "ms".to_string(),
        rows,
        scale: Scale::Auto,
    };
    assert!(plot.axis().log, "four decades of spread ask for a log axis");
    plot.write(&path).unwrap_or_else(|e| panic!("{e}"));
    let img = read(&path);
    assert_eq!(img.height(), 150 + 3 * ROW_HEIGHT);
    let budget_red = img.pixels().filter(|p| p.0 == [200, 30, 30]).count();
    assert!(budget_red > 50, "budget lines missing");
}

#[test]
fn values_are_written_with_three_significant_digits() {
    assert_eq!(value_text(34.54, "ms"), "34.5 ms");
    assert_eq!(value_text(250.0, "ms"), "250 ms");
    assert_eq!(value_text(0.0042, "ms"), "0.00420 ms");
    assert_eq!(value_text(2.0, ""), "2.00");
}

#[test]
fn an_unwritable_path_is_a_clear_error() {
    let dir = Scratch::new("plot", "unwritable");
    let path = dir.join("no-such-dir/x.png");
    let err = lines(&path, "t", "x", "y", &[], &[], false)
        .err()
        .unwrap_or_else(|| panic!("wrote into a missing folder"));
    assert!(err.to_string().contains("x.png"), "{err}");
}

#[test]
fn tracks_join_a_group_across_tracks() {
    let dir = Scratch::new("plot", "tracks");
    let path = dir.join("tracks.png");
    let bar = |track, start, end, group, nested| Bar {
        track,
        start,
        end,
        group,
        nested,
    };
    let plot = Tracks {
        title: "spans".to_string(),
        x_label: "ms".to_string(),
        tracks: vec!["source".to_string(), "detector".to_string()],
        bars: vec![
            bar(0, 0.0, 0.1, 3, false),
            bar(1, 2.0, 30.0, 3, false),
            bar(1, 3.0, 20.0, 3, true),
            bar(0, f64::NAN, 1.0, 4, false),
            // A microsecond: still drawn, a few pixels wide.
            bar(0, 10.0, 10.001, 5, false),
        ],
        links: vec![(3, vec![(0, 0.0, 0.1), (1, 2.0, 30.0)])],
    };
    plot.write(&path).unwrap_or_else(|e| panic!("{e}"));
    let img = read(&path);
    assert_eq!(img.height(), 150 + 2 * ROW_HEIGHT);
    let (r, g, b) = PALETTE[3];
    let group_pixels = img.pixels().filter(|p| p.0 == [r, g, b]).count();
    assert!(
        group_pixels > 500,
        "bars of group 3 missing: {group_pixels}"
    );
    let (r, g, b) = PALETTE[5];
    let short = img.pixels().filter(|p| p.0 == [r, g, b]).count();
    assert!(short >= 60, "a microsecond bar is not seen: {short} pixels");
}
