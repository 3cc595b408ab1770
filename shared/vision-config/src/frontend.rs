//! The front end's configuration: detector and matcher by name, each detector's and
//! descriptor's options with OpenCV's defaults, and the gates of appearance matching.
//! `configs/frontend.toml` documents the same fields for users.

use crate::{DetectorKind, FrontendConfigError, MatcherKind};
use linetrack_corners::{CornersError, Params};
use linetrack_frontend_core::{EdgeLinesOptions, LineOptions};
use linetrack_l1_matcher::MatcherConfig;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Configuration of the whole front end.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FrontendConfig {
    /// Line detector: `lsd`, `fld` or `edgelines`.
    pub detector: DetectorKind,
    /// Segment matcher: `lbd` (appearance) or `l1` (geometry).
    pub matcher: MatcherKind,
    /// Which detected segments are kept.
    pub lines: LineOptions,
    /// LSD parameters (OpenCV's defaults).
    pub lsd: LsdOptions,
    /// FLD parameters (OpenCV's defaults).
    pub fld: FldOptions,
    /// Parameters of our own detector (`edgelines`).
    pub edgelines: EdgeLinesOptions,
    /// LBD matching.
    pub lbd: LbdOptions,
    /// ORB points and their matching.
    pub orb: OrbOptions,
    /// Where appearance matchers (LBD, ORB) look for a counterpart.
    pub appearance_gates: AppearanceGates,
    /// The ℓ1 matcher (fields as in `configs/l1-matcher.toml`).
    pub l1: MatcherConfig,
}

impl Default for FrontendConfig {
    fn default() -> Self {
        Self {
            detector: DetectorKind::Lsd,
            matcher: MatcherKind::Lbd,
            lines: LineOptions::default(),
            lsd: LsdOptions::default(),
            fld: FldOptions::default(),
            edgelines: EdgeLinesOptions::default(),
            lbd: LbdOptions::default(),
            orb: OrbOptions::default(),
            appearance_gates: AppearanceGates::default(),
            l1: MatcherConfig::default(),
        }
    }
}

/// LSD's refinement mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LsdRefine {
    /// No refinement.
    None,
    /// Standard refinement (OpenCV's default).
    Standard,
    /// Advanced refinement.
    Advanced,
}

/// Parameters of OpenCV's `createLineSegmentDetector`, with its defaults.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LsdOptions {
    /// Refinement of the detected lines.
    pub refine: LsdRefine,
    /// Image scale used before detection.
    pub scale: f64,
    /// Gaussian sigma is sigma_scale / scale.
    pub sigma_scale: f64,
    /// Bound on the gradient quantisation error.
    pub quant: f64,
    /// Gradient angle tolerance, degrees.
    pub angle_tolerance_deg: f64,
    /// Detection threshold on −log10(NFA) (advanced refinement only).
    pub log_eps: f64,
    /// Minimal density of aligned points in the enclosing rectangle.
    pub density_threshold: f64,
    /// Bins in the pseudo-ordering of gradient modulus.
    pub bins: i32,
}

impl Default for LsdOptions {
    fn default() -> Self {
        Self {
            refine: LsdRefine::Standard,
            scale: 0.8,
            sigma_scale: 0.6,
            quant: 2.0,
            angle_tolerance_deg: 22.5,
            log_eps: 0.0,
            density_threshold: 0.7,
            bins: 1024,
        }
    }
}

/// Parameters of OpenCV's `ximgproc::createFastLineDetector`, with its defaults.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FldOptions {
    /// Segments shorter than this are discarded by FLD itself, pixels.
    pub length_threshold_px: i32,
    /// Points farther than this from the hypothesised line are outliers, pixels.
    pub distance_threshold_px: f32,
    /// Canny hysteresis, first threshold.
    pub canny_low: f64,
    /// Canny hysteresis, second threshold.
    pub canny_high: f64,
    /// Canny Sobel aperture.
    pub canny_aperture: i32,
    /// Merge collinear segments.
    pub merge: bool,
}

impl Default for FldOptions {
    fn default() -> Self {
        Self {
            length_threshold_px: 10,
            distance_threshold_px: std::f32::consts::SQRT_2,
            canny_low: 50.0,
            canny_high: 50.0,
            canny_aperture: 3,
            merge: false,
        }
    }
}

/// LBD descriptor matching.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LbdOptions {
    /// Accept a mutual best match only if the second-best Hamming distance is at least
    /// this many times the best.
    pub min_distance_ratio: f64,
}

impl Default for LbdOptions {
    fn default() -> Self {
        Self {
            min_distance_ratio: 1.0 / 0.75,
        }
    }
}

/// ORB points (OpenCV's `ORB::create` defaults but the count) and their matching.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OrbOptions {
    /// Who finds and describes the points: `orb-opencv` (OpenCV's ORB, the default) or
    /// `fast-brief` (our own oriented FAST corners with a steered binary descriptor,
    /// `linetrack-corners`, no OpenCV). Both take the settings below (ours: FAST's threshold
    /// as a byte, no `edge_threshold`, a fixed 16-pixel border) and give 32-byte
    /// descriptors for the same Hamming matching.
    pub extractor: PointExtractorKind,
    /// Points per image (paper: 600).
    pub features: i32,
    /// Pyramid decimation ratio.
    pub scale_factor: f32,
    /// Pyramid levels.
    pub levels: i32,
    /// Border where no point is detected, pixels.
    pub edge_threshold: i32,
    /// FAST threshold.
    pub fast_threshold: i32,
    /// Accept a mutual best match only if the second-best distance is at least this many
    /// times the best (paper: 2).
    pub min_distance_ratio: f64,
    /// `fast-brief` only: spread each level's points over a grid of cells this many pixels
    /// wide (at most an even share per cell first); 0, the default, for none (measured on
    /// the KITTI raw drive, the grid cost the odometry's frame-to-frame matches).
    pub grid_cell_px: usize,
    /// `fast-brief` only: rank each level's best FAST corners (twice its share) by the
    /// Harris measure and keep the best of those, as OpenCV's ORB does; false (the
    /// default): by the FAST score alone (measured against each other in docs/speed.md).
    pub harris_ranking: bool,
    /// How each left point finds its stereo partner: `descriptors` (the default: the
    /// right image's points are extracted too and matched by descriptor) or `row-search`
    /// (the right image is not extracted: each left point's window is searched for along
    /// its row of the rectified right image, see `row_search_min_correlation`).
    pub stereo: PointStereo,
    /// `row-search` only: the smallest zero-mean normalised correlation (in (0, 1]) at
    /// which the best window along the row is believed.
    pub row_search_min_correlation: f64,
    /// `row-search` only: the best window's cost (1 − correlation) must be under this
    /// fraction (in (0, 1)) of the runner-up's, another dip of the cost along the row;
    /// a repeated pattern, whose dips are alike, is refused.
    pub row_search_uniqueness: f64,
}

/// How the odometry's left points find their stereo partners.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PointStereo {
    /// Both images' points extracted and matched by descriptor.
    Descriptors,
    /// Only the left image's points extracted; each one's window searched for along its
    /// row of the rectified right image.
    RowSearch,
}

impl PointStereo {
    /// The name used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            PointStereo::Descriptors => "descriptors",
            PointStereo::RowSearch => "row-search",
        }
    }
}

impl Default for OrbOptions {
    fn default() -> Self {
        Self {
            extractor: PointExtractorKind::OrbOpenCv,
            features: 600,
            scale_factor: 1.2,
            levels: 8,
            edge_threshold: 31,
            fast_threshold: 20,
            min_distance_ratio: 2.0,
            grid_cell_px: 0,
            harris_ranking: false,
            stereo: PointStereo::Descriptors,
            row_search_min_correlation: 0.8,
            row_search_uniqueness: 0.3,
        }
    }
}

impl OrbOptions {
    /// The `linetrack-corners` parameters of these options (the point count, levels, scale factor,
    /// FAST threshold, border and grid).
    pub fn fast_brief_params(&self) -> Result<Params, CornersError> {
        let out_of_range = |name, value: i32, reason| CornersError::Param {
            name,
            value: value.to_string(),
            reason,
        };
        let params = Params {
            max_corners: usize::try_from(self.features)
                .map_err(|_| out_of_range("features", self.features, "must be at least 1"))?,
            levels: usize::try_from(self.levels)
                .map_err(|_| out_of_range("levels", self.levels, "must be 1 to 16"))?,
            scale_factor: self.scale_factor,
            fast_threshold: u8::try_from(self.fast_threshold).map_err(|_| {
                out_of_range("fast_threshold", self.fast_threshold, "must be 1 to 255")
            })?,
            edge_px: usize::try_from(self.edge_threshold)
                .map_err(|_| out_of_range("edge_threshold", self.edge_threshold, "must be ≥ 0"))?,
            cell_px: self.grid_cell_px,
            harris: self.harris_ranking,
        };
        params.validate()?;
        Ok(params)
    }
}

/// The point extractors that can be chosen by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum PointExtractorKind {
    /// OpenCV's ORB (features2d).
    #[serde(rename = "orb-opencv")]
    OrbOpenCv,
    /// Our own oriented FAST-9 corners with a steered binary descriptor
    /// (`linetrack-corners`, no OpenCV).
    #[serde(rename = "fast-brief")]
    FastBrief,
}

impl PointExtractorKind {
    /// Every kind, in a fixed order.
    pub const ALL: [PointExtractorKind; 2] =
        [PointExtractorKind::OrbOpenCv, PointExtractorKind::FastBrief];

    /// The name used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            PointExtractorKind::OrbOpenCv => "orb-opencv",
            PointExtractorKind::FastBrief => "fast-brief",
        }
    }
}

impl std::str::FromStr for PointExtractorKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                format!("unknown point extractor {s:?}: expected orb-opencv or fast-brief")
            })
    }
}

/// Where appearance matching looks for a counterpart.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AppearanceGates {
    /// Stereo: smallest disparity, pixels.
    pub min_disparity_px: f64,
    /// Stereo: largest disparity, pixels.
    pub max_disparity_px: f64,
    /// Stereo points: largest row difference, pixels.
    pub max_row_difference_px: f64,
    /// Stereo segments: smallest overlap of the two row extents over their union (the
    /// row gate); segments must share rows in any case.
    pub min_row_overlap: f64,
    /// Frame to frame: largest motion of a point or segment midpoint (beyond half the
    /// longer segment), pixels.
    pub max_displacement_px: f64,
}

impl Default for AppearanceGates {
    fn default() -> Self {
        Self {
            min_disparity_px: -2.0,
            max_disparity_px: 150.0,
            max_row_difference_px: 3.0,
            min_row_overlap: 0.0,
            max_displacement_px: 40.0,
        }
    }
}

impl FrontendConfig {
    /// Parses and validates TOML text.
    pub fn from_toml_str(text: &str) -> Result<Self, FrontendConfigError> {
        Self::parse(text, "<string>")
    }

    /// Reads, parses and validates a TOML file.
    pub fn from_file(path: &Path) -> Result<Self, FrontendConfigError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| FrontendConfigError {
            origin: origin.clone(),
            message: format!("cannot read: {e}"),
        })?;
        Self::parse(&text, &origin)
    }

    fn parse(text: &str, origin: &str) -> Result<Self, FrontendConfigError> {
        let config: Self = toml::from_str(text).map_err(|e| FrontendConfigError {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        config.validate().map_err(|message| FrontendConfigError {
            origin: origin.to_string(),
            message,
        })?;
        Ok(config)
    }

    /// Checks the ranges; the message names the first bad field.
    pub fn validate(&self) -> Result<(), String> {
        let bad = |field: &str, value: String, expected: &str| {
            Err(format!("field `{field}` = {value}: {expected}"))
        };
        self.lines.validate().map_err(|e| e.to_string())?;
        if !(self.lsd.scale > 0.0 && self.lsd.scale <= 1.0) {
            return bad("lsd.scale", self.lsd.scale.to_string(), "in (0, 1]");
        }
        if !(self.lsd.angle_tolerance_deg > 0.0 && self.lsd.angle_tolerance_deg < 180.0) {
            return bad(
                "lsd.angle_tolerance_deg",
                self.lsd.angle_tolerance_deg.to_string(),
                "in (0, 180)",
            );
        }
        if self.lsd.bins < 1 {
            return bad("lsd.bins", self.lsd.bins.to_string(), ">= 1");
        }
        if ![3, 5, 7].contains(&self.fld.canny_aperture) {
            return bad(
                "fld.canny_aperture",
                self.fld.canny_aperture.to_string(),
                "3, 5 or 7",
            );
        }
        if self.fld.length_threshold_px < 0 {
            return bad(
                "fld.length_threshold_px",
                self.fld.length_threshold_px.to_string(),
                ">= 0",
            );
        }
        self.edgelines.validate().map_err(|e| e.to_string())?;
        for (field, ratio) in [
            ("lbd.min_distance_ratio", self.lbd.min_distance_ratio),
            ("orb.min_distance_ratio", self.orb.min_distance_ratio),
        ] {
            if !(ratio >= 1.0 && ratio.is_finite()) {
                return bad(field, ratio.to_string(), "a finite number >= 1");
            }
        }
        if self.orb.extractor == PointExtractorKind::FastBrief {
            self.orb.fast_brief_params().map_err(|e| e.to_string())?;
        }
        if self.orb.features < 1 || self.orb.levels < 1 || !(self.orb.scale_factor > 1.0) {
            return bad(
                "orb",
                format!("{:?}", self.orb),
                "features >= 1, levels >= 1, scale_factor > 1",
            );
        }
        let correlation = self.orb.row_search_min_correlation;
        if !(correlation > 0.0 && correlation <= 1.0) {
            return bad(
                "orb.row_search_min_correlation",
                correlation.to_string(),
                "in (0, 1]",
            );
        }
        let uniqueness = self.orb.row_search_uniqueness;
        if !(uniqueness > 0.0 && uniqueness < 1.0) {
            return bad(
                "orb.row_search_uniqueness",
                uniqueness.to_string(),
                "in (0, 1)",
            );
        }
        let g = &self.appearance_gates;
        if g.min_disparity_px.is_nan()
            || g.max_disparity_px.is_nan()
            || g.min_disparity_px > g.max_disparity_px
        {
            return bad(
                "appearance_gates.min_disparity_px",
                g.min_disparity_px.to_string(),
                "<= max_disparity_px",
            );
        }
        if !(g.max_row_difference_px >= 0.0) || !(g.max_displacement_px >= 0.0) {
            return bad(
                "appearance_gates",
                format!("{g:?}"),
                "row difference and displacement >= 0",
            );
        }
        if !(0.0..=1.0).contains(&g.min_row_overlap) {
            return bad(
                "appearance_gates.min_row_overlap",
                g.min_row_overlap.to_string(),
                "a fraction in [0, 1]",
            );
        }
        self.l1.validate().map_err(|e| format!("[l1] {e}"))
    }
}
