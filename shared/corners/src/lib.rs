//! Oriented corners with a binary descriptor in plain Rust, the point front end without
//! OpenCV: the 8-bit pixels read in place (a shared-memory frame is never copied), every
//! buffer kept in the extractor and reused, so a warm extractor allocates nothing per frame.
//!
//! The method is ORB's (Rublee et al. 2011: FAST corners, intensity-centroid orientation, a
//! steered BRIEF descriptor); the code, and the descriptor's sampling pattern, are ours:
//!
//! 1. **Pyramid** (`pyramid.rs`, `resample.rs`): `levels` images, each `scale_factor`
//!    smaller than the one before (bilinear, pixel centres aligned, exact 8-bit weights);
//!    level 0 is the caller's image itself. Each source row is blended horizontally once
//!    (with AVX2, 16 pixels an instruction by byte shuffles from tables made once a level),
//!    then two such rows vertically.
//! 2. **FAST-9** (`fast.rs`): a pixel is a corner when 9 contiguous pixels of the 16 on the
//!    circle of radius 3 around it are all brighter than it by more than `fast_threshold`,
//!    or all darker. Rows are worked 32 centres at a time (with AVX2 intrinsics where the
//!    CPU has them, else in loops the compiler vectorises): the 4 compass positions first
//!    (a block with no centre passing is done), then the 8 even ones (and, in the
//!    portable loops, the 8 odd ones, each way); a block with a centre left is scored
//!    whole, every centre on its whole circle in byte lanes. The score of a corner is the
//!    largest threshold at which it still is one.
//! 3. **Selection** (`select.rs`): 3×3 non-maximum suppression of the score, a counting
//!    sort on the 8-bit score (best first, raster order within a score); then each
//!    level's share of `max_corners` (shares proportional to the levels' widths, as OpenCV's
//!    ORB) is taken best first; optionally (`cell_px`) from a grid, at most an even share
//!    per cell on the first pass, then the best of the rest, so textured corners of the
//!    image do not take every point (off by default: measured, it cost the odometry).
//! 4. **Orientation and descriptor** (`describe.rs`, `patch.rs`): the angle from the
//!    patch's centre to its intensity centroid (radius 15), quantised to 128 steps; 256
//!    intensity comparisons of pixel pairs of the smoothed level image (read from the
//!    corner's 32 × 32 patch, copied out; the level is smoothed only over the bands of
//!    rows and columns the kept corners' patches cover), the pairs rotated by that angle.
//!    The pairs are a table (`learned_pattern.rs`) learned once by ORB's greedy search
//!    (`learn.rs`, [`learn_pattern`]) from the corners of the Middlebury stereo pairs: within
//!    15 px of the corner, the two points at least 5 px apart, each comparison splitting
//!    those corners about evenly and little correlated with the others. Bit `j` of byte `i`
//!    is pair `8i + j`: "first darker than second", the layout of OpenCV's 32-byte ORB
//!    descriptors, so the same Hamming matching serves both.
//!
//! On x86-64 CPUs with AVX2 all of it runs compiled for AVX2, the resampling with its byte
//! shuffles and FAST with intrinsics; where the CPU has AVX-512 VBMI too, the descriptor
//! looks its points up 64 at a time with byte permutes (all chosen at run time, so the
//! binaries stay portable; the same results, tested).
//!
//! Positions are in full-resolution pixels (pixel centres at integers); a corner found at
//! level `l` sits on that level's pixel grid, `scale_factor^l` pixels apart. Corners stay
//! `edge_px`, and at least [`BORDER_PX`], level pixels from the border so their patch is whole. Nothing panics on
//! any image: empty, tiny, blank, noise (tested). Images come as the tree's 8-bit view,
//! [`GrayView`] (from `linetrack-edge-lines`), whose constructor refuses a slice that cannot
//! hold the image it is said to hold.

#![warn(missing_docs)]

mod describe;
mod fast;
mod harris;
mod learn;
mod learned_pattern;
mod patch;
mod pyramid;
mod resample;
mod select;

#[cfg(test)]
mod tests;

use describe::Pattern;
pub use learn::{LearnSettings, LearnedPattern, learn_pattern};
pub use linetrack_edge_lines::{EdgeLinesError, GrayView};
use pyramid::{Pyramid, Smoother};
use thiserror::Error;

/// A corner of one level before it is described, level pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Candidate {
    /// Column.
    pub(crate) x: u32,
    /// Row.
    pub(crate) y: u32,
    /// FAST score.
    pub(crate) score: u8,
}

/// Bytes of a descriptor (256 comparisons).
pub const DESCRIPTOR_BYTES: usize = 32;

/// A corner stays this many pixels (of its level) from every border: the descriptor's and
/// the orientation's patch, radius 15, lies wholly inside.
pub const BORDER_PX: usize = 16;

/// Most pyramid levels an extractor builds.
pub const MAX_LEVELS: usize = 16;

/// The extractor's errors: parameters out of range. (Describing an image goes through
/// [`GrayView::new`], whose errors are [`EdgeLinesError`]s.)
#[derive(Debug, Clone, Error, PartialEq)]
pub enum CornersError {
    /// A parameter out of its range.
    #[error("corner parameter {name} = {value}: {reason}")]
    Param {
        /// The parameter's field name in [`Params`].
        name: &'static str,
        /// Its value, as given.
        value: String,
        /// What it must be.
        reason: &'static str,
    },
}

/// The extractor's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// At most this many corners an image.
    pub max_corners: usize,
    /// Pyramid levels (1: the full-resolution image only), at most [`MAX_LEVELS`].
    pub levels: usize,
    /// Each level is this much smaller than the one before (> 1).
    pub scale_factor: f32,
    /// FAST: the 9 contiguous circle pixels differ from the centre by more than this.
    pub fast_threshold: u8,
    /// Side of the grid's cells, pixels of each level; 0: no grid, the best corners of each
    /// level wherever they are (the default: on the KITTI raw drive the grid's even coverage
    /// cost the odometry frame-to-frame matches, ATE 0.78 m with 32-pixel cells against
    /// 0.17 m without).
    pub cell_px: usize,
    /// Rank each level's best FAST corners (twice its share) by the Harris measure of the
    /// 7 × 7 block around them and keep the best of those, as OpenCV's ORB does by default;
    /// false (the default): by the FAST score alone (docs/speed.md, "Ranked by Harris").
    pub harris: bool,
    /// Corners are at least this many pixels of their level from the borders (at least
    /// [`BORDER_PX`] whatever this says); OpenCV's ORB calls it `edgeThreshold`. In forward
    /// motion, corners near the borders leave the view first.
    pub edge_px: usize,
}

impl Default for Params {
    /// OpenCV ORB's defaults (500 points, 8 levels of 1.2, FAST threshold 20, 31 px from
    /// the borders), but ranked by the FAST score; no grid.
    fn default() -> Self {
        Self {
            max_corners: 500,
            levels: 8,
            scale_factor: 1.2,
            fast_threshold: 20,
            cell_px: 0,
            edge_px: 31,
            harris: false,
        }
    }
}

impl Params {
    /// Errs on the first parameter out of its range.
    pub fn validate(&self) -> Result<(), CornersError> {
        let fail = |name, value: String, reason| {
            Err(CornersError::Param {
                name,
                value,
                reason,
            })
        };
        if !(1..=MAX_LEVELS).contains(&self.levels) {
            return fail("levels", self.levels.to_string(), "must be 1 to 16");
        }
        if !(self.scale_factor > 1.0 && self.scale_factor <= 4.0) {
            return fail(
                "scale_factor",
                self.scale_factor.to_string(),
                "must be above 1 and at most 4",
            );
        }
        if self.fast_threshold == 0 {
            return fail("fast_threshold", "0".into(), "must be at least 1");
        }
        Ok(())
    }
}

/// Side of a corner's patch ([`Patch`]), level pixels.
pub const PATCH_SIDE: usize = patch::PATCH;
/// The corner's row and column inside its patch.
pub const PATCH_CENTRE: usize = patch::CENTRE;

/// What the descriptor of one corner reads: the smoothed level pixels around it and its
/// orientation ([`CornerExtractor::patches`]). The sampling pattern is learned from these.
#[derive(Debug, Clone, PartialEq)]
pub struct Patch {
    /// Level pixels `c − 15 ..= c + 16` around the corner `c`, row by row.
    pub pixels: [u8; PATCH_SIDE * PATCH_SIDE],
    /// The corner's orientation, radians (as [`Corner::angle_rad`]).
    pub angle_rad: f32,
}

/// A corner: position, level, orientation and score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// Column, full-resolution pixels.
    pub x: f32,
    /// Row, full-resolution pixels.
    pub y: f32,
    /// Pyramid level it was found at (0: full resolution).
    pub level: u8,
    /// Direction from the corner to its patch's intensity centroid, radians in (−π, π],
    /// image axes (x right, y down).
    pub angle_rad: f32,
    /// FAST score: the largest threshold at which it is still a corner.
    pub score: u8,
}

/// The corners of one image with their descriptors (`descriptors[k]` for `corners[k]`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Corners {
    /// The corners, level by level, best first within a level.
    pub corners: Vec<Corner>,
    /// Their descriptors.
    pub descriptors: Vec<[u8; DESCRIPTOR_BYTES]>,
}

impl Corners {
    /// Empties both lists (keeping their buffers).
    pub fn clear(&mut self) {
        self.corners.clear();
        self.descriptors.clear();
    }

    /// Number of corners.
    pub fn len(&self) -> usize {
        self.corners.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.corners.is_empty()
    }
}

/// Finds and describes corners; keeps every buffer from image to image.
pub struct CornerExtractor {
    params: Params,
    pattern: Pattern,
    pyramid: Pyramid,
    smoother: Smoother,
    scores: Vec<u8>,
    candidates: Vec<Candidate>,
    /// The candidates' sorting buffer.
    sorted: Vec<Candidate>,
    /// The Harris measures of a level's best candidates, with their indices.
    ranked: Vec<(i64, u32)>,
    grid: select::Grid,
}

impl CornerExtractor {
    /// An extractor with `params` (checked).
    pub fn new(params: Params) -> Result<Self, CornersError> {
        params.validate()?;
        Ok(Self {
            params,
            pattern: Pattern::new(),
            pyramid: Pyramid::default(),
            smoother: Smoother::default(),
            scores: Vec::new(),
            candidates: Vec::new(),
            sorted: Vec::new(),
            ranked: Vec::new(),
            grid: select::Grid::default(),
        })
    }

    /// Its parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Replaces `out` with the corners of `image` and their descriptors.
    ///
    /// On a CPU with AVX2 the work runs compiled for it (chosen at run time, so the
    /// binaries stay portable): the row loops then work on vectors twice as wide.
    pub fn extract(&mut self, image: GrayView<'_>, out: &mut Corners) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let vbmi = std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512bw")
                && std::arch::is_x86_feature_detected!("avx512vbmi");
            // SAFETY: the CPU has the instructions the function is compiled for, as just
            // checked, and AVX-512 F, BW and VBMI when `vbmi` says so.
            #[allow(unsafe_code)]
            unsafe {
                self.extract_with_avx2(image, out, vbmi);
            }
            return;
        }
        self.extract_on_any_cpu(image, out);
    }

    /// Appends to `out` the smoothed patch and the orientation of every corner
    /// [`CornerExtractor::extract`] finds in `image` (plain code on any CPU; the corners are
    /// the same): what the sampling pattern is learned from ([`learn_pattern`]).
    pub fn patches(&mut self, image: GrayView<'_>, out: &mut Vec<Patch>) {
        let mut corners = Corners::default();
        self.extract_for(image, &mut corners, false, false, Some(out));
    }

    /// [`CornerExtractor::extract_on_any_cpu`] compiled for AVX2 (everything it calls is
    /// `#[inline(always)]`, so inlined and compiled for it too).
    /// `vbmi`: the CPU has AVX-512 F, BW and VBMI too (checked by the caller), and the
    /// descriptor uses their byte permutes.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn extract_with_avx2(&mut self, image: GrayView<'_>, out: &mut Corners, vbmi: bool) {
        self.extract_for(image, out, true, vbmi, None);
    }

    /// [`CornerExtractor::extract`] for any CPU.
    fn extract_on_any_cpu(&mut self, image: GrayView<'_>, out: &mut Corners) {
        self.extract_for(image, out, false, false, None);
    }

    /// [`CornerExtractor::extract`], with AVX2's byte shuffles when `avx2` says the CPU has them,
    /// and AVX-512 VBMI's byte permutes when `vbmi` does (the caller has checked); each
    /// corner's patch appended to `patches` when given.
    #[inline(always)]
    fn extract_for(
        &mut self,
        image: GrayView<'_>,
        out: &mut Corners,
        avx2: bool,
        vbmi: bool,
        mut patches: Option<&mut Vec<Patch>>,
    ) {
        #[cfg(not(target_arch = "x86_64"))]
        let _ = vbmi;
        out.clear();
        let params = self.params;
        let count = self.pyramid.build(image, &params, avx2);
        let shares = select::level_shares(&self.pyramid, count, params.max_corners);
        let mut wanted = 0;
        for (level, share) in shares.into_iter().enumerate().take(count) {
            // A level's shortfall passes to the next one.
            wanted += share;
            let Some(plane) = self.pyramid.plane(level, image) else {
                break;
            };
            fast::detect(
                plane,
                params.fast_threshold,
                params.edge_px,
                &mut self.scores,
                &mut self.candidates,
                avx2,
            );

            select::suppress_and_sort(plane, &self.scores, &mut self.candidates, &mut self.sorted);
            if params.harris {
                harris::rank(
                    plane,
                    wanted,
                    &mut self.candidates,
                    &mut self.ranked,
                    &mut self.sorted,
                );
            }
            let kept = self
                .grid
                .select(plane, params.cell_px, wanted, &mut self.candidates);
            wanted -= kept;
            if kept == 0 {
                continue;
            }
            let Some(smooth) = self.smoother.smooth(plane, &self.candidates[..kept]) else {
                continue;
            };
            let scale = self.pyramid.scale(level);
            for candidate in &self.candidates[..kept] {
                let (x, y) = (candidate.x as usize, candidate.y as usize);
                let angle_rad = self.pattern.orientation(plane, x, y);
                if let Some(patches) = patches.as_deref_mut()
                    && let Some(pixels) = patch::patch(smooth, x, y)
                {
                    patches.push(Patch { pixels, angle_rad });
                }
                #[cfg(target_arch = "x86_64")]
                let descriptor = if vbmi {
                    let Some(rows) = patch::rows(smooth, x, y) else {
                        continue;
                    };
                    // SAFETY: the CPU has AVX-512 F, BW and VBMI (the caller's word).
                    #[allow(unsafe_code)]
                    unsafe {
                        self.pattern.describe_vbmi(&rows, angle_rad)
                    }
                } else {
                    let Some(patch) = patch::patch(smooth, x, y) else {
                        continue;
                    };
                    self.pattern.describe(&patch, angle_rad)
                };
                #[cfg(not(target_arch = "x86_64"))]
                let descriptor = {
                    let Some(patch) = patch::patch(smooth, x, y) else {
                        continue;
                    };
                    self.pattern.describe(&patch, angle_rad)
                };
                out.descriptors.push(descriptor);
                out.corners.push(Corner {
                    x: candidate.x as f32 * scale,
                    y: candidate.y as f32 * scale,
                    level: level as u8,
                    angle_rad,
                    score: candidate.score,
                });
            }
        }
    }
}
