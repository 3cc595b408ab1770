//! ORB points (OpenCV features2d) and their stereo / frame-to-frame matching.

use crate::cpu::with_avx2;
use crate::worker::{SideWorker, copy_image_into};
use crate::{
    AppearanceGates, BinaryDescriptors, FeatureMatch, GrayImage, HammingMatcher, OpenCvContext,
    OrbOptions, VisionError,
};
use linetrack_geometry::{MatchCase, Point};
use opencv::core::{KeyPoint, KeyPointTraitConst, Mat, MatTraitConst, Ptr, Vector};
use opencv::features2d::{Feature2DTrait, ORB, ORB_ScoreType};

/// Points of one image with their descriptors (row k for `points[k]`).
#[derive(Debug, Clone, Default)]
pub struct PointFeatures {
    /// Keypoint positions, pixels.
    pub points: Vec<Point>,
    /// Pyramid level each point was detected at (0: full resolution); its position is
    /// quantised to that level's pixel, `scale_factor^level` full-resolution pixels.
    pub levels: Vec<u8>,
    /// ORB descriptors.
    pub descriptors: BinaryDescriptors,
}

impl PointFeatures {
    /// Makes this a copy of `other`, in the buffers it has (no allocation once they are
    /// large enough).
    pub fn copy_from(&mut self, other: &Self) {
        self.points.clone_from(&other.points);
        self.levels.clone_from(&other.levels);
        self.descriptors.copy_from(&other.descriptors);
    }
}

/// ORB detection and description; keeps its buffers.
pub struct OrbExtractor {
    orb: Ptr<ORB>,
    keypoints: Vector<KeyPoint>,
    raw: Mat,
}

impl OrbExtractor {
    /// An ORB extractor with `options`.
    pub fn new(options: &OrbOptions) -> Result<Self, VisionError> {
        let orb = ORB::create(
            options.features,
            options.scale_factor,
            options.levels,
            options.edge_threshold,
            0,
            2,
            ORB_ScoreType::HARRIS_SCORE,
            31,
            options.fast_threshold,
        )
        .context("creating the ORB extractor")?;
        Ok(Self {
            orb,
            keypoints: Vector::new(),
            raw: Mat::default(),
        })
    }

    /// Detects and describes points in `image` into `out`.
    pub fn extract(
        &mut self,
        image: &GrayImage,
        out: &mut PointFeatures,
    ) -> Result<(), VisionError> {
        self.keypoints.clear();
        let no_mask = Mat::default();
        self.orb
            .detect_and_compute(
                image.mat(),
                &no_mask,
                &mut self.keypoints,
                &mut self.raw,
                false,
            )
            .context("ORB detection")?;
        out.points.clear();
        out.points.extend(
            self.keypoints
                .iter()
                .map(|k| Point::new(f64::from(k.pt().x), f64::from(k.pt().y))),
        );
        out.levels.clear();
        out.levels.extend(
            self.keypoints
                .iter()
                .map(|k| u8::try_from(k.octave().max(0)).unwrap_or(u8::MAX)),
        );
        let row_bytes = usize::try_from(self.raw.cols()).unwrap_or(0);
        out.descriptors.reset(out.points.len(), row_bytes);
        out.descriptors.set_rows_from_mat(&self.raw)?;
        Ok(())
    }
}

/// An [`OrbExtractor`] on a thread of its own ([`SideWorker`]): one image's points are found
/// there while the caller works on another, and two images' points can be matched there
/// too. The inputs are copied into the worker's buffers (reused from frame to frame) and
/// the results come back in buffers that are swapped, not reallocated.
pub struct OrbWorker {
    worker: SideWorker<OrbJob>,
}

/// What travels to the worker and back.
struct OrbJob {
    task: OrbTask,
    extractor: OrbExtractor,
    image: Option<GrayImage>,
    points: PointFeatures,
    stereo: StereoJob,
    result: Result<(), VisionError>,
}

/// What the worker is to do with its job.
#[derive(Debug, Clone, Copy)]
enum OrbTask {
    /// Find the points of `image`.
    Extract,
    /// Match the stereo job's points.
    MatchStereo,
}

/// A stereo matching of points: copies of the two images' points, the matcher and its
/// settings, and the matches.
#[derive(Default)]
struct StereoJob {
    left: PointFeatures,
    right: PointFeatures,
    matcher: PointMatcher,
    gates: AppearanceGates,
    min_ratio: f64,
    matches: Vec<FeatureMatch>,
    /// How long the matching took, milliseconds.
    ms: f64,
}

impl OrbWorker {
    /// A worker with its own extractor made from `options`.
    pub fn new(options: &OrbOptions) -> Result<Self, VisionError> {
        let job = OrbJob {
            task: OrbTask::Extract,
            extractor: OrbExtractor::new(options)?,
            image: None,
            points: PointFeatures::default(),
            stereo: StereoJob::default(),
            result: Ok(()),
        };
        // (Named for its main work, the right image's corners; it matches the stereo pair's
        // points too.)
        let worker = SideWorker::new("orb-right", job, |job: &mut OrbJob| {
            job.result = match (job.task, &job.image) {
                (OrbTask::Extract, Some(image)) => job.extractor.extract(image, &mut job.points),
                (OrbTask::Extract, None) => Ok(()),
                (OrbTask::MatchStereo, _) => {
                    let started = std::time::Instant::now();
                    let stereo = &mut job.stereo;
                    stereo.matcher.match_points(
                        MatchCase::Stereo,
                        &stereo.left,
                        &stereo.right,
                        &stereo.gates,
                        stereo.min_ratio,
                        &mut stereo.matches,
                    );
                    stereo.ms = started.elapsed().as_secs_f64() * 1e3;
                    Ok(())
                }
            };
        })?;
        Ok(Self { worker })
    }

    /// Finds `image`'s points into `out` on the worker while `here` runs on the calling
    /// thread; returns both outcomes once both are done.
    pub fn extract_while<R>(
        &mut self,
        image: &GrayImage,
        out: &mut PointFeatures,
        here: impl FnOnce() -> R,
    ) -> (Result<(), VisionError>, R) {
        let handed = self.worker.job().and_then(|job| {
            job.task = OrbTask::Extract;
            copy_image_into(&mut job.image, image)
        });
        if let Err(error) = handed {
            return (Err(error), here());
        }
        let (job, beside) = self.worker.run_while(here);
        let result = job.and_then(|job| {
            std::mem::swap(out, &mut job.points);
            std::mem::replace(&mut job.result, Ok(()))
        });
        (result, beside)
    }

    /// Replaces `out` with the stereo matches of `left`'s points among `right`'s
    /// ([`PointMatcher::match_points`] with `gates` and `min_ratio`), found on the worker
    /// while `here` runs on the calling thread; returns both outcomes once both are done
    /// (the matching's: its milliseconds on the worker). `out` is left empty when the
    /// worker's thread is lost.
    pub fn match_stereo_while<R>(
        &mut self,
        [left, right]: [&PointFeatures; 2],
        gates: &AppearanceGates,
        min_ratio: f64,
        out: &mut Vec<FeatureMatch>,
        here: impl FnOnce() -> R,
    ) -> (Result<f64, VisionError>, R) {
        out.clear();
        match self.worker.job() {
            Ok(job) => {
                job.task = OrbTask::MatchStereo;
                job.stereo.left.copy_from(left);
                job.stereo.right.copy_from(right);
                job.stereo.gates = *gates;
                job.stereo.min_ratio = min_ratio;
            }
            Err(error) => return (Err(error), here()),
        }
        let (job, beside) = self.worker.run_while(here);
        let result = job.and_then(|job| {
            std::mem::swap(out, &mut job.stereo.matches);
            std::mem::replace(&mut job.result, Ok(())).map(|()| job.stereo.ms)
        });
        (result, beside)
    }
}

/// Matches points by descriptor among the pairs the geometry allows; keeps its buffers
/// (no allocation per frame once warm).
#[derive(Debug, Clone, Default)]
pub struct PointMatcher {
    hamming: HammingMatcher,
    grid: PointGrid,
}

impl PointMatcher {
    /// A matcher with empty buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// Replaces `out` with the mutual-best Hamming matches that pass the ratio test, among
    /// pairs on the same rows within the disparity range (stereo) or within the
    /// displacement (frame to frame). Only the second image's points in the cells that
    /// window covers are compared: on a 752 × 480 image with 1500 points a side that is a
    /// few dozen per point instead of all of them, with the same result.
    pub fn match_points(
        &mut self,
        case: MatchCase,
        first: &PointFeatures,
        second: &PointFeatures,
        gates: &AppearanceGates,
        min_ratio: f64,
        out: &mut Vec<FeatureMatch>,
    ) {
        let first = (first.points.as_slice(), &first.descriptors);
        self.match_points_of(case, first, |_| true, second, gates, min_ratio, out);
    }

    /// [`PointMatcher::match_points`] for the first image's points `wanted` says yes to
    /// (the others are neither matched nor compete for the second image's points), their
    /// positions and descriptors given apart (positions moved to where they are predicted,
    /// say).
    #[allow(clippy::too_many_arguments)]
    pub fn match_points_of(
        &mut self,
        case: MatchCase,
        first: (&[Point], &BinaryDescriptors),
        wanted: impl Fn(usize) -> bool,
        second: &PointFeatures,
        gates: &AppearanceGates,
        min_ratio: f64,
        out: &mut Vec<FeatureMatch>,
    ) {
        match PairGate::new(case, gates) {
            PairGate::Stereo(gate) => self.match_gated(first, wanted, second, min_ratio, out, gate),
            PairGate::Displacement(gate) => {
                self.match_gated(first, wanted, second, min_ratio, out, gate)
            }
        }
    }

    /// [`PointMatcher::match_points_of`] with `gate`: the grid buckets the second image's
    /// points into the gate's cells, and each wanted first point is compared with the
    /// points in the cells its window meets that the gate admits, the gate applied while
    /// the cells are listed (over the grid's own copy of the positions, contiguous cell by
    /// cell), so the Hamming matcher sees only admitted pairs.
    fn match_gated(
        &mut self,
        (first_points, first_descriptors): (&[Point], &BinaryDescriptors),
        wanted: impl Fn(usize) -> bool,
        second: &PointFeatures,
        min_ratio: f64,
        out: &mut Vec<FeatureMatch>,
        gate: impl Gate,
    ) {
        self.grid.rebuild(&second.points, gate.cell_px());
        let grid = &self.grid;
        self.hamming.match_mutual_among(
            first_descriptors,
            &second.descriptors,
            min_ratio,
            |i, candidates| {
                if !wanted(i) {
                    return;
                }
                let a = first_points[i];
                let (x, y) = gate.window(a);
                grid.extend_within(x, y, |b| gate.admits(a, b), candidates);
            },
            |_, _| true,
            out,
        );
    }
}

/// Which pairs of points may match: [`points_may_match`] with what it derives from the
/// gates worked out once, and where to look.
trait Gate: Copy {
    /// Whether point `a` of the first image and `b` of the second may match.
    fn admits(&self, a: Point, b: Point) -> bool;

    /// The columns and rows that hold every second-image point `a` may match.
    fn window(&self, a: Point) -> ([f64; 2], [f64; 2]);

    /// Width and height of the grid's cells that suit the windows, pixels.
    fn cell_px(&self) -> [f64; 2];
}

/// [`points_may_match`]'s gate for one case.
#[derive(Debug, Clone, Copy)]
enum PairGate {
    Stereo(StereoGate),
    Displacement(DisplacementGate),
}

impl PairGate {
    fn new(case: MatchCase, gates: &AppearanceGates) -> Self {
        match case {
            MatchCase::Stereo => Self::Stereo(StereoGate {
                min_disparity_px: gates.min_disparity_px,
                max_disparity_px: gates.max_disparity_px,
                max_row_difference_px: gates.max_row_difference_px,
            }),
            MatchCase::FrameToFrame => {
                let limit_px = gates.max_displacement_px;
                let squared = limit_px * limit_px;
                // Limits whose square is not a normal number, or that are not a distance,
                // settle nothing on the square: every pair gets the exact test.
                let exact_only = !(1e-100..=1e100).contains(&limit_px);
                Self::Displacement(DisplacementGate {
                    limit_px,
                    surely_within: if exact_only {
                        f64::NEG_INFINITY
                    } else {
                        squared * (1.0 - 1e-9)
                    },
                    surely_beyond: if exact_only {
                        f64::INFINITY
                    } else {
                        squared * (1.0 + 1e-9)
                    },
                })
            }
        }
    }

    fn admits(&self, a: Point, b: Point) -> bool {
        match self {
            Self::Stereo(gate) => gate.admits(a, b),
            Self::Displacement(gate) => gate.admits(a, b),
        }
    }
}

/// Stereo: on the same rows, with a disparity in range.
#[derive(Debug, Clone, Copy)]
struct StereoGate {
    min_disparity_px: f64,
    max_disparity_px: f64,
    max_row_difference_px: f64,
}

impl Gate for StereoGate {
    #[inline(always)]
    fn admits(&self, a: Point, b: Point) -> bool {
        let disparity = a.x - b.x;
        (a.y - b.y).abs() <= self.max_row_difference_px
            && disparity >= self.min_disparity_px
            && disparity <= self.max_disparity_px
    }

    fn window(&self, a: Point) -> ([f64; 2], [f64; 2]) {
        (
            [a.x - self.max_disparity_px, a.x - self.min_disparity_px],
            [
                a.y - self.max_row_difference_px,
                a.y + self.max_row_difference_px,
            ],
        )
    }

    /// Stereo windows are a few rows high and wide along them: flat cells list fewer
    /// points outside the window than square ones.
    fn cell_px(&self) -> [f64; 2] {
        STEREO_CELL_PX
    }
}

/// Frame to frame: at most `limit_px` apart.
#[derive(Debug, Clone, Copy)]
struct DisplacementGate {
    limit_px: f64,
    /// Squared distances below this are within the limit, above `surely_beyond` (or NaN)
    /// beyond it; those between (within a rounding error of the limit) get the exact test.
    surely_within: f64,
    surely_beyond: f64,
}

impl Gate for DisplacementGate {
    #[inline(always)]
    fn admits(&self, a: Point, b: Point) -> bool {
        let (dx, dy) = (a.x - b.x, a.y - b.y);
        let squared = dx * dx + dy * dy;
        if squared < self.surely_within {
            true
        } else if squared > self.surely_beyond || squared.is_nan() {
            false
        } else {
            (a - b).norm() <= self.limit_px
        }
    }

    fn window(&self, a: Point) -> ([f64; 2], [f64; 2]) {
        let r = self.limit_px;
        ([a.x - r, a.x + r], [a.y - r, a.y + r])
    }

    fn cell_px(&self) -> [f64; 2] {
        GRID_CELL_PX
    }
}

/// Whether point `a` of the first image and `b` of the second may match: on the same rows
/// (within `max_row_difference_px`) with a disparity in range (stereo), or at most
/// `max_displacement_px` apart (frame to frame).
pub fn points_may_match(case: MatchCase, gates: &AppearanceGates, a: Point, b: Point) -> bool {
    PairGate::new(case, gates).admits(a, b)
}

/// Side of a square [`PointGrid`] cell for frame-to-frame windows, pixels.
const GRID_CELL_PX: [f64; 2] = [8.0, 8.0];

/// Width and height of a [`PointGrid`] cell for stereo windows (±3 rows by default), pixels.
const STEREO_CELL_PX: [f64; 2] = [32.0, 4.0];

/// Most cells along one side of a [`PointGrid`]: points spread wider share cells.
const GRID_MAX_CELLS: usize = 1024;

/// Points bucketed into cells (a counting sort by cell), to list the points in a window
/// without visiting every point.
#[derive(Debug, Clone, Default)]
struct PointGrid {
    origin: Point,
    /// Cell width and height, pixels.
    cell: [f64; 2],
    cols: usize,
    rows: usize,
    /// Where each cell's points start in `order` (one more entry than cells).
    starts: Vec<usize>,
    /// Point indices, cell by cell, increasing within a cell.
    order: Vec<usize>,
    /// The positions of `order`'s points, in its order.
    ordered: Vec<Point>,
    cell_of: Vec<usize>,
}

impl PointGrid {
    /// Buckets `points` into cells of `cell` (width, height) pixels at least (non-finite
    /// positions are left out: no window holds them).
    fn rebuild(&mut self, points: &[Point], cell: [f64; 2]) {
        let finite = || points.iter().filter(|p| p.x.is_finite() && p.y.is_finite());
        let (mut lo, mut hi) = (
            Point::new(f64::MAX, f64::MAX),
            Point::new(f64::MIN, f64::MIN),
        );
        for p in finite() {
            lo = Point::new(lo.x.min(p.x), lo.y.min(p.y));
            hi = Point::new(hi.x.max(p.x), hi.y.max(p.y));
        }
        if lo.x > hi.x {
            (lo, hi) = (Point::origin(), Point::origin());
        }
        let spread = [hi.x - lo.x, hi.y - lo.y];
        for axis in 0..2 {
            self.cell[axis] = cell[axis]
                .max(spread[axis] / (GRID_MAX_CELLS - 1) as f64)
                .max(f64::MIN_POSITIVE);
        }
        self.origin = lo;
        self.cols = self.index(spread[0], 0, GRID_MAX_CELLS) + 1;
        self.rows = self.index(spread[1], 1, GRID_MAX_CELLS) + 1;
        self.starts.clear();
        self.starts.resize(self.cols * self.rows + 1, 0);
        self.cell_of.clear();
        for p in points {
            let k = if p.x.is_finite() && p.y.is_finite() {
                self.index(p.y - lo.y, 1, self.rows) * self.cols
                    + self.index(p.x - lo.x, 0, self.cols)
            } else {
                usize::MAX
            };
            self.cell_of.push(k);
            if k != usize::MAX {
                self.starts[k + 1] += 1;
            }
        }
        for k in 1..self.starts.len() {
            self.starts[k] += self.starts[k - 1];
        }
        self.order.clear();
        self.order.resize(self.starts[self.starts.len() - 1], 0);
        // Each point goes to its cell's next free place; that moves every start to the
        // following cell's, put back after.
        for (j, &k) in self.cell_of.iter().enumerate() {
            if k != usize::MAX {
                self.order[self.starts[k]] = j;
                self.starts[k] += 1;
            }
        }
        let cells = self.starts.len() - 1;
        self.starts.copy_within(..cells, 1);
        self.starts[0] = 0;
        self.ordered.clear();
        self.ordered.extend(self.order.iter().map(|&j| points[j]));
    }

    /// The cell along `axis` (0: x, 1: y) of an offset from the origin, clamped to
    /// `count` cells.
    fn index(&self, offset: f64, axis: usize, count: usize) -> usize {
        let k = (offset / self.cell[axis]).floor();
        if k.is_nan() || k <= 0.0 {
            0
        } else {
            (k as usize).min(count.saturating_sub(1))
        }
    }

    /// Appends the points `keep` accepts among those of every cell meeting the window
    /// `x` × `y` (so every point inside the window that `keep` accepts).
    fn extend_within(
        &self,
        x: [f64; 2],
        y: [f64; 2],
        keep: impl Fn(Point) -> bool,
        out: &mut Vec<usize>,
    ) {
        let outside = |range: [f64; 2], low: f64, cell: f64, cells: usize| {
            !(range[1] >= low && range[0] <= low + cell * cells as f64)
        };
        if self.order.is_empty()
            || outside(x, self.origin.x, self.cell[0], self.cols)
            || outside(y, self.origin.y, self.cell[1], self.rows)
        {
            return;
        }
        let [c0, c1] = x.map(|v| self.index(v - self.origin.x, 0, self.cols));
        let [r0, r1] = y.map(|v| self.index(v - self.origin.y, 1, self.rows));
        for r in r0..=r1 {
            let row = r * self.cols;
            let span = self.starts[row + c0]..self.starts[row + c1 + 1];
            out.extend(
                self.order[span.clone()]
                    .iter()
                    .zip(&self.ordered[span])
                    .filter(|&(_, &p)| keep(p))
                    .map(|(&j, _)| j),
            );
        }
    }
}

/// Half the side of the windows the sub-pixel refinements compare (11 × 11).
const HALF: i64 = 5;
const SIDE: usize = (2 * HALF + 1) as usize;

/// The window of `pixels` (an image `width` wide) centred on pixel `(u, v)`, which the caller
/// has checked lies at least [`HALF`] pixels inside the image (on the stack: this runs for
/// every point match of every frame).
fn window<T: From<u8> + Copy + Default>(
    pixels: &[u8],
    width: i64,
    u: i64,
    v: i64,
) -> [T; SIDE * SIDE] {
    let mut values = [T::default(); SIDE * SIDE];
    for (row_values, y) in values.chunks_exact_mut(SIDE).zip(v - HALF..=v + HALF) {
        let start = (y * width + u - HALF) as usize;
        widen(&pixels[start..start + SIDE], row_values);
    }
    values
}

/// `pixels` into `values` as integers.
fn widen<T: From<u8>>(pixels: &[u8], values: &mut [T]) {
    for (value, &p) in values.iter_mut().zip(pixels) {
        *value = T::from(p);
    }
}

/// The sum of the products of `a`'s and `b`'s values, pair by pair. Exact for windows of
/// pixels: 121 products of at most 255² stay far below `i32::MAX`. (Wrapping operations,
/// which cannot wrap here, so that the sum is vectorised in builds with overflow checks
/// too, such as the tests'.)
#[inline(always)]
fn sum_of_products(a: &[i16], b: &[i16]) -> i32 {
    a.iter().zip(b).fold(0i32, |sum, (&a, &b)| {
        sum.wrapping_add(i32::from(a).wrapping_mul(i32::from(b)))
    })
}

/// The sum of `values` (exact for a window of pixels, see [`sum_of_products`]).
#[inline(always)]
fn sum_of(values: &[i16]) -> i32 {
    values
        .iter()
        .fold(0i32, |sum, &v| sum.wrapping_add(i32::from(v)))
}

/// Whether the windows centred on pixel `(u, v)` and shifted by up to `reach` (columns,
/// rows) either way all lie inside an image of `size` (width, height).
fn windows_inside(u: i64, v: i64, reach: (i64, i64), (width, height): (i64, i64)) -> bool {
    // (Compared so that no sum overflows: a point at infinity rounds to i64::MAX.)
    u >= HALF + reach.0
        && u < width - HALF - reach.0
        && v >= HALF + reach.1
        && v < height - HALF - reach.1
}

/// The fraction of a pixel, within ±0.5, by which a parabola through three costs at
/// shifts −1, 0 and 1 puts its minimum (0 when they do not curve upwards).
fn parabola_minimum(before: f64, at: f64, after: f64) -> f64 {
    let curvature = before - 2.0 * at + after;
    if curvature > 0.0 {
        (0.5 * (before - after) / curvature).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

/// The two images' pixels and their common size, or `None` when they differ in size or are
/// not stored in one block.
fn pixels_of_pair<'a>(
    first: &'a GrayImage,
    second: &'a GrayImage,
) -> Option<(&'a [u8], &'a [u8], i64, i64)> {
    let size = |image: &GrayImage| (i64::from(image.width()), i64::from(image.height()));
    if size(first) != size(second) {
        return None;
    }
    let (width, height) = size(first);
    Some((first.pixels()?, second.pixels()?, width, height))
}

/// Refines the right image's column of a stereo point match to a fraction of a pixel.
///
/// Detected keypoints sit on whole pixels (of their pyramid level), so disparities come in
/// whole pixels too, and every point of a surface at one depth is rounded the same way:
/// a depth bias that averaging cannot remove. Here an 11 × 11 window around the pixel
/// nearest `left` is compared with windows of the right image on the same row, up to 3 px
/// either side of `right`, by the sum of absolute differences after removing each window's
/// mean (so a gain offset between the cameras does not matter), and a parabola through the
/// best shift and its two neighbours gives the fraction. The result is the column of `left`
/// itself: a keypoint of a coarser pyramid level lies between pixels, and its offset from
/// the window's centre is carried over. `None` when a window leaves an image or the best
/// shift is at the end of the search (the match is then left as it was).
pub fn refine_stereo_column(
    left_image: &GrayImage,
    right_image: &GrayImage,
    left: Point,
    right: Point,
) -> Option<f64> {
    with_avx2(
        #[inline(always)]
        || refine_stereo_column_portably(left_image, right_image, left, right),
    )
}

/// [`refine_stereo_column`] for any CPU; inlined where it is compiled for more
/// ([`with_avx2`]).
#[inline(always)]
fn refine_stereo_column_portably(
    left_image: &GrayImage,
    right_image: &GrayImage,
    left: Point,
    right: Point,
) -> Option<f64> {
    const SEARCH: i64 = 3;
    let (lp, rp, width, height) = pixels_of_pair(left_image, right_image)?;
    let (ul, v) = (left.x.round() as i64, left.y.round() as i64);
    let ur = right.x.round() as i64;
    let size = (width, height);
    if !(windows_inside(ul, v, (0, 0), size) && windows_inside(ur, v, (SEARCH, 0), size)) {
        return None;
    }
    let mean_removed = |pixels: &[u8], u: i64| {
        let mut values: [i32; SIDE * SIDE] = window(pixels, width, u, v);
        let mean = values.iter().sum::<i32>() / values.len() as i32;
        values.iter_mut().for_each(|p| *p -= mean);
        values
    };
    let reference = mean_removed(lp, ul);
    let mut costs = [0.0f64; (2 * SEARCH + 1) as usize];
    for (cost, shift) in costs.iter_mut().zip(-SEARCH..=SEARCH) {
        let candidate = mean_removed(rp, ur + shift);
        // Summed as integers, then converted: the same value as summing them as f64 (a sum
        // of small integers is exact in f64, in any order). At most 121 × 510: no wrap.
        let sum = reference
            .iter()
            .zip(&candidate)
            .fold(0i32, |sum, (a, b)| sum.wrapping_add((a - b).abs()));
        *cost = f64::from(sum);
    }
    let best = (0..costs.len()).min_by(|&a, &b| costs[a].total_cmp(&costs[b]))?;
    if best == 0 || best == costs.len() - 1 {
        return None;
    }
    let fraction = parabola_minimum(costs[best - 1], costs[best], costs[best + 1]);
    Some((ur + best as i64 - SEARCH) as f64 + fraction + (left.x - ul as f64))
}

/// Smallest normalised correlation at which [`refine_track`] believes its best shift.
pub const MIN_TRACK_CORRELATION: f64 = 0.8;

/// Where `from` (a point of the previous image) lies in the current image, to a fraction
/// of a pixel, given `to`, the keypoint it was matched to there.
///
/// A frame-to-frame point match pairs two detections, each on a whole pixel of its own
/// pyramid level: up to half a pixel (several full-resolution pixels at a coarse level)
/// from where the other one's point really is. Here the 11 × 11 window around the pixel
/// nearest `from` is looked for around `to`, up to 2 px either way in both directions, by
/// zero-mean normalised correlation (the exposure may change between frames: gain and
/// offset do not matter); a parabola through the best shift and its neighbours gives the
/// fraction along each axis, and `from`'s offset from its window's centre is carried over.
/// `None` when a window leaves an image, the best shift is at the edge of the search, or
/// its correlation is under [`MIN_TRACK_CORRELATION`] (the match is then left as it was).
pub fn refine_track(
    previous_image: &GrayImage,
    current_image: &GrayImage,
    from: Point,
    to: Point,
) -> Option<Point> {
    with_avx2(
        #[inline(always)]
        || refine_track_portably(previous_image, current_image, from, to),
    )
}

/// [`refine_track`] for any CPU; inlined where it is compiled for more ([`with_avx2`]).
#[inline(always)]
fn refine_track_portably(
    previous_image: &GrayImage,
    current_image: &GrayImage,
    from: Point,
    to: Point,
) -> Option<Point> {
    const SEARCH: i64 = 2;
    const SHIFTS: usize = (2 * SEARCH + 1) as usize;
    let (pp, cp, width, height) = pixels_of_pair(previous_image, current_image)?;
    let (uf, vf) = (from.x.round() as i64, from.y.round() as i64);
    let (ut, vt) = (to.x.round() as i64, to.y.round() as i64);
    let size = (width, height);
    if !(windows_inside(uf, vf, (0, 0), size) && windows_inside(ut, vt, (SEARCH, SEARCH), size)) {
        return None;
    }
    // Correlations from integer sums (11 × 11 × 255² fits an i32): Σa, Σa², then per
    // candidate Σb, Σb² and Σab.
    let n = (SIDE * SIDE) as f64;
    // (Pixels as i16: products of two fit an i32, and the sums of products of 16-bit
    // values are what the vector units multiply-add fastest.)
    let reference: [i16; SIDE * SIDE] = window(pp, width, uf, vf);
    let sum_a = sum_of(&reference);
    let sum_aa = sum_of_products(&reference, &reference);
    let var_a = f64::from(sum_aa) - f64::from(sum_a).powi(2) / n;
    if var_a < 1.0 {
        return None;
    }
    // Costs are 1 − correlation, row-major over the shifts (dy, dx). For each dx the
    // columns the windows of that dx cover are copied once, row after row, for all five
    // dy: the window at dy is then the 121 values from row dy on.
    let mut costs = [[0.0f64; SHIFTS]; SHIFTS];
    let mut columns = [[0i16; SIDE * (SIDE + SHIFTS - 1)]; SHIFTS];
    for (strip, dx) in columns.iter_mut().zip(-SEARCH..=SEARCH) {
        let left = (ut + dx - HALF) as usize;
        for (values, y) in strip.chunks_exact_mut(SIDE).zip(vt - HALF - SEARCH..) {
            let start = (y * width) as usize + left;
            widen(&cp[start..start + SIDE], values);
        }
    }
    for (row, dy) in costs.iter_mut().zip(0..) {
        for (cost, strip) in row.iter_mut().zip(&columns) {
            let candidate = &strip[dy * SIDE..dy * SIDE + SIDE * SIDE];
            let sum_b = sum_of(candidate);
            let sum_bb = sum_of_products(candidate, candidate);
            let sum_ab = sum_of_products(&reference, candidate);
            let var_b = f64::from(sum_bb) - f64::from(sum_b).powi(2) / n;
            let covariance = f64::from(sum_ab) - f64::from(sum_a) * f64::from(sum_b) / n;
            *cost = if var_b > 0.0 {
                1.0 - covariance / (var_a * var_b).sqrt()
            } else {
                2.0
            };
        }
    }
    let (by, bx) = (0..SHIFTS)
        .flat_map(|y| (0..SHIFTS).map(move |x| (y, x)))
        .min_by(|&(ay, ax), &(by, bx)| costs[ay][ax].total_cmp(&costs[by][bx]))?;
    let last = SHIFTS - 1;
    if bx == 0 || by == 0 || bx == last || by == last || 1.0 - costs[by][bx] < MIN_TRACK_CORRELATION
    {
        return None;
    }
    let fx = parabola_minimum(costs[by][bx - 1], costs[by][bx], costs[by][bx + 1]);
    let fy = parabola_minimum(costs[by - 1][bx], costs[by][bx], costs[by + 1][bx]);
    Some(Point::new(
        (ut + bx as i64 - SEARCH) as f64 + fx + (from.x - uf as f64),
        (vt + by as i64 - SEARCH) as f64 + fy + (from.y - vf as f64),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sub-pixel refinements give the same answers, bit for bit, built for AVX2 (where
    /// this CPU has it: what the public functions run) and for the baseline CPU, at every
    /// position of a grid over two textured images that differ by a shift, a gain and
    /// noise: both refined and refused matches. Points at infinity or NaN are refused.
    #[test]
    fn the_refinements_answer_the_same_for_every_cpu() {
        let textured = |shift: f64, gain: f64, seed: u32| {
            let (width, height) = (160, 120);
            let pixels: Vec<u8> = (0..width * height)
                .map(|i| {
                    let (x, y) = ((i % width) as f64 + shift, (i / width) as f64);
                    let smooth = 120.0 + 60.0 * (x / 5.0).sin() * (y / 7.0).cos();
                    let noise = (i as u32 ^ seed).wrapping_mul(2_654_435_761) >> 29;
                    (gain * smooth + f64::from(noise)).clamp(0.0, 255.0) as u8
                })
                .collect();
            GrayImage::from_pixels(width, height, &pixels, "texture").unwrap()
        };
        let (first, second) = (textured(0.0, 1.0, 1), textured(1.6, 1.1, 2));
        let (mut refined, mut refused) = (0, 0);
        for y in (0..120).step_by(3) {
            for x in (0..160).step_by(3) {
                let from = Point::new(f64::from(x) + 0.3, f64::from(y) - 0.2);
                let to = Point::new(f64::from(x) - 2.0, f64::from(y) + 1.0);
                let track = refine_track(&first, &second, from, to);
                assert_eq!(track, refine_track_portably(&first, &second, from, to));
                let column = refine_stereo_column(&first, &second, from, to);
                assert_eq!(
                    column.map(f64::to_bits),
                    refine_stereo_column_portably(&first, &second, from, to).map(f64::to_bits)
                );
                match track {
                    Some(_) => refined += 1,
                    None => refused += 1,
                }
            }
        }
        assert!(
            refined > 100 && refused > 100,
            "{refined} refined, {refused} refused"
        );
        // A point at infinity or NaN is refused, not an overflow or an index out of range.
        for odd in [f64::INFINITY, f64::NEG_INFINITY, f64::NAN, 1e300] {
            let (good, bad) = (Point::new(50.0, 50.0), Point::new(odd, odd));
            assert_eq!(refine_track(&first, &second, bad, good), None);
            assert_eq!(refine_track(&first, &second, good, bad), None);
            assert_eq!(refine_stereo_column(&first, &second, bad, good), None);
            assert_eq!(refine_stereo_column(&first, &second, good, bad), None);
        }
    }

    /// Points the caller does not want are neither matched nor compete: here the second
    /// image's only point is nearer to the first image's point 0, which wins it unless it
    /// is left out.
    #[test]
    fn unwanted_points_do_not_compete_for_a_match() {
        let features = |points: &[(f64, f64)], rows: &[[u8; 4]]| {
            let mut f = PointFeatures {
                points: points.iter().map(|&(x, y)| Point::new(x, y)).collect(),
                levels: vec![0; points.len()],
                ..PointFeatures::default()
            };
            f.descriptors.reset(rows.len(), 4);
            for (k, row) in rows.iter().enumerate() {
                f.descriptors.set_row(k, row);
            }
            f
        };
        let first = features(&[(10.0, 10.0), (12.0, 10.0)], &[[0, 0, 0, 1], [0, 0, 0, 7]]);
        let second = features(&[(11.0, 10.0)], &[[0, 0, 0, 0]]);
        let gates = AppearanceGates::default();
        let mut matcher = PointMatcher::new();
        let mut out = Vec::new();
        let pairs = |out: &[FeatureMatch]| -> Vec<(usize, usize)> {
            out.iter().map(|m| (m.query, m.train)).collect()
        };
        matcher.match_points(
            MatchCase::FrameToFrame,
            &first,
            &second,
            &gates,
            1.0,
            &mut out,
        );
        assert_eq!(pairs(&out), [(0, 0)]);
        matcher.match_points_of(
            MatchCase::FrameToFrame,
            (&first.points, &first.descriptors),
            |i| i == 1,
            &second,
            &gates,
            1.0,
            &mut out,
        );
        assert_eq!(pairs(&out), [(1, 0)]);
    }

    /// The frame-to-frame gate settles most pairs on the squared distance; at the limit and
    /// for limits that are not a distance it answers as `|a − b| ≤ limit` does.
    #[test]
    fn the_frame_to_frame_gate_is_the_distance_test() {
        let exact = |a: Point, b: Point, limit: f64| (a - b).norm() <= limit;
        let (a, b) = (Point::new(10.0, 20.0), Point::new(13.0, 24.0)); // 5 px apart
        for limit in [
            5.0,
            5.0 - 1e-12,
            5.0 + 1e-12,
            4.999_999_999,
            5.000_000_001,
            0.0,
            -5.0,
            f64::NAN,
            f64::INFINITY,
            1e-300,
            1e300,
        ] {
            let gates = AppearanceGates {
                max_displacement_px: limit,
                ..AppearanceGates::default()
            };
            for (p, q) in [
                (a, b),
                (a, a),
                (a, Point::new(f64::NAN, 0.0)),
                (a, Point::new(f64::INFINITY, 0.0)),
            ] {
                assert_eq!(
                    points_may_match(MatchCase::FrameToFrame, &gates, p, q),
                    exact(p, q, limit),
                    "{p:?} {q:?} within {limit}"
                );
            }
        }
        // Many distances near one limit.
        let gates = AppearanceGates {
            max_displacement_px: 40.0,
            ..AppearanceGates::default()
        };
        for k in 0..20_000 {
            let angle = f64::from(k) * 0.001;
            let r = 40.0 + (f64::from(k % 200) - 100.0) * 1e-14;
            let q = Point::new(a.x + r * angle.cos(), a.y + r * angle.sin());
            assert_eq!(
                points_may_match(MatchCase::FrameToFrame, &gates, a, q),
                exact(a, q, 40.0),
                "{q:?}"
            );
        }
    }
}
