//! `linetrack` for Python: the `edgelines` line segment detector and the geometric ℓ1
//! segment matcher on numpy arrays, without OpenCV.
//!
//! Every function runs the code the Rust tools run (`linetrack-match-pair --detector
//! edgelines --matcher l1`): detection through `linetrack_frontend_core::EdgeLinesSegments`,
//! the matcher's image step through `L1Matcher::describe`, matching through
//! `L1Matcher::match_with_profiles`, settings through the same config types and checks.
//! The arguments are checked here ([`arrays`], [`image`], [`segments`], [`config`]); the work runs
//! with the GIL released.
#![warn(missing_docs)]

mod arrays;
mod config;
mod image;
mod segments;

use linetrack_frontend_core::{EdgeLinesSegments, GrayView as DetectorView};
use linetrack_geometry::{MatchCase, Segment};
use linetrack_l1_matcher::{GrayView as MatcherView, L1Matcher, Match, SegmentProfiles};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// How many detectors (each with its image-sized buffers) a thread keeps, one per recent
/// setting: a benchmark alternating two settings, or a caller with a few, reuses them.
const KEPT_DETECTORS: usize = 4;

thread_local! {
    /// The detectors this thread used last, oldest first: a call with the same settings
    /// reuses one and allocates no image-sized buffer again.
    static DETECTORS: std::cell::RefCell<Vec<EdgeLinesSegments>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// Line segments of a grey image by the edgelines detector.
///
/// image: 2-D numpy array (height, width) of uint8, or uint16 (scaled to 8 bits,
///     v * 255 / 65535). Read in place when its rows are strided views of one buffer.
/// max_segments: keep at most this many segments, the longest.
/// settings: min_length_px (15.0) and the [edgelines] keys of configs/frontend.toml:
///     gradient_threshold (16), anchor_threshold (8), scan_interval (2),
///     max_fit_error_px (1.0), max_outlier_run (3), min_aligned_fraction (0.7).
///
/// Returns a float32 array (N, 4) of x0, y0, x1, y1 rows, longest first, pixel centres at
/// integer coordinates; walking from (x0, y0) to (x1, y1) the darker side is on the right.
/// Images under 8 pixels wide or high have none. Raises TypeError or ValueError naming the
/// bad argument. Do not write the image from another thread during the call.
#[pyfunction]
#[pyo3(
    signature = (image, *, max_segments = None, **settings),
    text_signature = "(image, *, max_segments=100, **settings)"
)]
fn detect_lines<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    max_segments: Option<&Bound<'py, PyAny>>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let (options, keep) = config::detector_settings(max_segments, settings)?;
    let image = image::from_array("image", image)?;
    let (pixels, stride) = image.rows();
    let view = DetectorView::new(pixels, image.width, image.height, stride)
        .map_err(|e| PyValueError::new_err(format!("image: {e}")))?;
    let found = py.detach(|| {
        let mut found = Vec::new();
        DETECTORS.with_borrow_mut(|kept| {
            let params = options.params(keep);
            let mut detector = match kept.iter().position(|d| *d.params() == params) {
                Some(k) => kept.remove(k),
                None => EdgeLinesSegments::new(&options, keep),
            };
            detector.detect(view, &mut found);
            if kept.len() == KEPT_DETECTORS {
                kept.remove(0);
            }
            kept.push(detector);
        });
        found
    });
    Ok(segments::to_array(py, &found))
}

/// Matches the segments of a rectified stereo pair with the geometric l1 matcher.
///
/// left_image, right_image: the two images (as for detect_lines), the same shape; the
///     matcher reads intensity profiles across the segments from them.
/// left_segments, right_segments: float32 or float64 arrays (N, 4) of x0, y0, x1, y1 rows,
///     e.g. from detect_lines; every coordinate finite.
/// config: None (the defaults), a dict with the keys of configs/l1-matcher.toml (nested
///     tables as dicts, e.g. {"gates": {"max_disparity_px": 80.0}}), or the path of such
///     a TOML file.
///
/// Returns (pairs, costs): pairs an int64 array (M, 2) of (left index, right index) rows
/// in increasing left index, costs a float64 array (M,) of each match's weighted
/// geometric error (lower is better).
#[pyfunction]
#[pyo3(signature = (left_image, right_image, left_segments, right_segments, *, config = None))]
fn match_stereo<'py>(
    py: Python<'py>,
    left_image: &Bound<'py, PyAny>,
    right_image: &Bound<'py, PyAny>,
    left_segments: &Bound<'py, PyAny>,
    right_segments: &Bound<'py, PyAny>,
    config: Option<&Bound<'py, PyAny>>,
) -> PyResult<Matches<'py>> {
    let images = [("left_image", left_image), ("right_image", right_image)];
    let segments = [
        ("left_segments", left_segments),
        ("right_segments", right_segments),
    ];
    match_pair(py, MatchCase::Stereo, images, segments, config)
}

/// Matches the segments of two consecutive frames of one camera with the geometric l1
/// matcher; arguments and result as for match_stereo (pairs are (first index, second
/// index)).
#[pyfunction]
#[pyo3(signature = (first_image, second_image, first_segments, second_segments, *, config = None))]
fn match_frames<'py>(
    py: Python<'py>,
    first_image: &Bound<'py, PyAny>,
    second_image: &Bound<'py, PyAny>,
    first_segments: &Bound<'py, PyAny>,
    second_segments: &Bound<'py, PyAny>,
    config: Option<&Bound<'py, PyAny>>,
) -> PyResult<Matches<'py>> {
    let images = [("first_image", first_image), ("second_image", second_image)];
    let segments = [
        ("first_segments", first_segments),
        ("second_segments", second_segments),
    ];
    match_pair(py, MatchCase::FrameToFrame, images, segments, config)
}

/// What the matching functions return: index pairs and costs.
type Matches<'py> = (Bound<'py, PyArray2<i64>>, Bound<'py, PyArray1<f64>>);

/// An argument's name and value.
type Named<'a, 'py> = (&'a str, &'a Bound<'py, PyAny>);

fn match_pair<'py>(
    py: Python<'py>,
    case: MatchCase,
    images: [Named<'_, 'py>; 2],
    segment_arrays: [Named<'_, 'py>; 2],
    config: Option<&Bound<'py, PyAny>>,
) -> PyResult<Matches<'py>> {
    let matcher = L1Matcher::new(config::matcher_config(config)?)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let [first, second] = images.map(|(name, image)| image::from_array(name, image));
    let (first, second) = (first?, second?);
    if first.shape() != second.shape() {
        return Err(PyValueError::new_err(format!(
            "{} has shape {:?} but {} has shape {:?}: the two images must have the same shape",
            images[0].0,
            first.shape(),
            images[1].0,
            second.shape()
        )));
    }
    let [a, b] = segment_arrays.map(|(name, array)| segments::from_array(name, array));
    let (a, b) = (a?, b?);
    let views = [&first, &second].map(|image| {
        let (pixels, stride) = image.rows();
        MatcherView::new(pixels, image.width, image.height, stride)
    });
    let [first_view, second_view] = views;
    let views = (
        first_view.map_err(|e| PyValueError::new_err(format!("{}: {e}", images[0].0)))?,
        second_view.map_err(|e| PyValueError::new_err(format!("{}: {e}", images[1].0)))?,
    );
    let found = py.detach(move || run_matcher(matcher, case, views, [&a, &b]));
    let mut pairs = Array2::<i64>::zeros((found.len(), 2));
    for (mut row, m) in pairs.rows_mut().into_iter().zip(&found) {
        // Indices of Python-held arrays fit in an i64.
        row[0] = m.query as i64;
        row[1] = m.train as i64;
    }
    let costs: Vec<f64> = found.iter().map(|m| m.error).collect();
    Ok((pairs.into_pyarray(py), costs.into_pyarray(py)))
}

/// What `L1SegmentMatcher` of `linetrack-vision` does for one pair: both images described,
/// then matched with the profiles.
fn run_matcher(
    mut matcher: L1Matcher,
    case: MatchCase,
    (first, second): (MatcherView<'_>, MatcherView<'_>),
    [a, b]: [&[Segment]; 2],
) -> Vec<Match> {
    let (mut profiles_a, mut profiles_b) = (SegmentProfiles::default(), SegmentProfiles::default());
    matcher.describe(Some(first), a, &mut profiles_a);
    matcher.describe(Some(second), b, &mut profiles_b);
    let mut found = Vec::new();
    matcher.match_with_profiles(case, a, b, Some((&profiles_a, &profiles_b)), &mut found);
    found
}

/// The module: `detect_lines`, `match_stereo`, `match_frames`, `__version__`.
#[pymodule]
fn linetrack(module: &Bound<'_, PyModule>) -> PyResult<()> {
    module.add("__version__", env!("CARGO_PKG_VERSION"))?;
    module.add_function(wrap_pyfunction!(detect_lines, module)?)?;
    module.add_function(wrap_pyfunction!(match_stereo, module)?)?;
    module.add_function(wrap_pyfunction!(match_frames, module)?)?;
    Ok(())
}
