//! Middlebury stereo pairs with ground-truth disparity, in the benchmark's own layouts.
//!
//! | layout | left / right | ground truth (left view) | disparity |
//! |---|---|---|---|
//! | 2005/2006, third size | `view1.png` / `view5.png` | `disp1.png` | value / 3 |
//! | 2001 Tsukuba | `imL.png` / `imR.png` | `truedisp.pgm` | value / 16 |
//! | 2001 Venus | `imL.png` / `imR.png` | `disp2.pgm` | value / 8 |
//! | 2003 Cones, Teddy (quarter size) | `imL.png` / `imR.png` | `disp2.png` | value / 4 |
//!
//! The pairs are rectified: a left pixel (x, y) with disparity d is seen at (x − d, y) in
//! the right image. A map value of 0 means *unknown* (occluded, or no structured-light
//! data), never d = 0. Images are colour and are read as grey.

use crate::DatasetError;
use linetrack_vision::GrayImage;
use opencv::core::{Mat, MatTraitConst, MatTraitConstManual};
use opencv::imgcodecs;
use std::path::{Path, PathBuf};

/// One stereo pair and where its ground truth is.
#[derive(Debug, Clone, PartialEq)]
pub struct MiddleburyPair {
    /// The scene's folder name (`Baby1`, `Tsukuba`, …).
    pub name: String,
    /// Left image.
    pub left: PathBuf,
    /// Right image.
    pub right: PathBuf,
    /// Ground-truth disparity of the left view.
    pub disparity: PathBuf,
    /// Map value per pixel of disparity (the map stores d × scale).
    pub scale: f64,
}

/// Left and right images (grey) with the left view's ground-truth disparity.
#[derive(Debug, Clone)]
pub struct LoadedPair {
    /// Left image, grey.
    pub left: GrayImage,
    /// Right image, grey.
    pub right: GrayImage,
    /// Disparity of the left view.
    pub disparity: DisparityMap,
}

impl MiddleburyPair {
    /// Recognises the layout of one scene folder, or `None` when it holds no known pair.
    pub fn in_folder(folder: &Path) -> Option<Self> {
        let name = folder.file_name()?.to_string_lossy().into_owned();
        let has = |file: &str| folder.join(file).is_file();
        let pair = |left: &str, right: &str, disparity: &str, scale: f64| Self {
            name: name.clone(),
            left: folder.join(left),
            right: folder.join(right),
            disparity: folder.join(disparity),
            scale,
        };
        if has("view1.png") && has("view5.png") && has("disp1.png") {
            return Some(pair("view1.png", "view5.png", "disp1.png", 3.0));
        }
        if !(has("imL.png") && has("imR.png")) {
            return None;
        }
        [
            ("truedisp.pgm", 16.0),
            ("disp2.pgm", 8.0),
            ("disp2.png", 4.0),
        ]
        .into_iter()
        .find(|(file, _)| has(file))
        .map(|(file, scale)| pair("imL.png", "imR.png", file, scale))
    }

    /// Loads both images as grey and the disparity map; errors name the file. Refuses a
    /// map whose size differs from the images', and a 2005/2006 pair that is not third
    /// size (its disparity scale would differ).
    pub fn load(&self) -> Result<LoadedPair, DatasetError> {
        let left = GrayImage::load(&self.left)?;
        let right = GrayImage::load(&self.right)?;
        left.ensure_same_size(&right)?;
        if self.scale == 3.0 && !(THIRD_SIZE_WIDTH_PX.contains(&left.width())) {
            return Err(crate::parse_error(
                &self.left,
                0,
                format!(
                    "{} px wide: only the third-size 2005/2006 images ({}–{} px wide) have disparity = value / 3",
                    left.width(),
                    THIRD_SIZE_WIDTH_PX.start(),
                    THIRD_SIZE_WIDTH_PX.end()
                ),
            ));
        }
        let disparity = DisparityMap::load(&self.disparity, self.scale)?;
        if (disparity.width, disparity.height) != (left.width() as usize, left.height() as usize) {
            return Err(crate::parse_error(
                &self.disparity,
                0,
                format!(
                    "disparity map is {}×{} but the images are {}×{}",
                    disparity.width,
                    disparity.height,
                    left.width(),
                    left.height()
                ),
            ));
        }
        Ok(LoadedPair {
            left,
            right,
            disparity,
        })
    }
}

/// Widths of the third-size 2005/2006 images (413–465 px in the benchmark).
const THIRD_SIZE_WIDTH_PX: std::ops::RangeInclusive<i32> = 400..=480;

/// Every pair under `root` (the scene folders directly in it, or one level further down),
/// sorted by name. Errs when `root` cannot be read or holds no pair.
pub fn list_middlebury(root: &Path) -> Result<Vec<MiddleburyPair>, DatasetError> {
    let mut pairs = Vec::new();
    for folder in sub_folders(root)? {
        match MiddleburyPair::in_folder(&folder) {
            Some(pair) => pairs.push(pair),
            None => pairs.extend(
                sub_folders(&folder)?
                    .iter()
                    .filter_map(|f| MiddleburyPair::in_folder(f)),
            ),
        }
    }
    if pairs.is_empty() {
        return Err(crate::parse_error(
            root,
            0,
            "no Middlebury pair found (expected scene folders with view1/view5/disp1.png or imL/imR.png and a disparity map)",
        ));
    }
    pairs.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(pairs)
}

/// The pairs under `root` named in `names` (scene folder names), or every pair when
/// `names` is empty. Errs, naming it, on a name that is no scene there.
pub fn select_middlebury(
    root: &Path,
    names: &[String],
) -> Result<Vec<MiddleburyPair>, DatasetError> {
    let mut pairs = list_middlebury(root)?;
    if let Some(missing) = names.iter().find(|n| !pairs.iter().any(|p| &p.name == *n)) {
        return Err(crate::parse_error(
            root,
            0,
            format!("no scene {missing:?} here"),
        ));
    }
    if !names.is_empty() {
        pairs.retain(|p| names.contains(&p.name));
    }
    Ok(pairs)
}

fn sub_folders(dir: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    let io = |reason| DatasetError::Io {
        path: dir.to_path_buf(),
        reason,
    };
    let mut folders = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        if path.is_dir() {
            folders.push(path);
        }
    }
    folders.sort();
    Ok(folders)
}

/// A dense disparity map in pixels; unknown pixels hold NaN.
#[derive(Debug, Clone, PartialEq)]
pub struct DisparityMap {
    width: usize,
    height: usize,
    values: Vec<f32>,
}

impl DisparityMap {
    /// Reads an 8- or 16-bit single-channel map (PNG or PGM) storing d × `scale`; 0 is
    /// unknown.
    pub fn load(path: &Path, scale: f64) -> Result<Self, DatasetError> {
        if !(scale.is_finite() && scale > 0.0) {
            return Err(crate::parse_error(
                path,
                0,
                format!("disparity scale must be > 0, got {scale}"),
            ));
        }
        let bytes = std::fs::read(path).map_err(|reason| DatasetError::Io {
            path: path.to_path_buf(),
            reason,
        })?;
        let buffer = opencv::core::Vector::<u8>::from_slice(&bytes);
        let not_a_map = |what: &str| crate::parse_error(path, 0, what.to_string());
        let mat = imgcodecs::imdecode(&buffer, imgcodecs::IMREAD_UNCHANGED)
            .ok()
            .filter(|m| !m.empty())
            .ok_or_else(|| not_a_map("not a decodable image"))?;
        if mat.channels() != 1 {
            return Err(not_a_map("a disparity map must have one channel"));
        }
        let (width, height) = (mat.cols() as usize, mat.rows() as usize);
        let raw: Vec<f64> = match mat.depth() {
            opencv::core::CV_8U => continuous(&mat)?.iter().map(|&v| f64::from(v)).collect(),
            opencv::core::CV_16U => continuous(&mat)?
                .chunks_exact(2)
                .map(|b| f64::from(u16::from_ne_bytes([b[0], b[1]])))
                .collect(),
            _ => return Err(not_a_map("a disparity map must be 8- or 16-bit")),
        };
        let values = raw
            .into_iter()
            .map(|v| {
                if v == 0.0 {
                    f32::NAN
                } else {
                    (v / scale) as f32
                }
            })
            .collect();
        Ok(Self {
            width,
            height,
            values,
        })
    }

    /// A map from row-major values in pixels (NaN or ≤ 0 for unknown); `None` when the
    /// count does not match the size.
    pub fn from_values(width: usize, height: usize, values: Vec<f32>) -> Option<Self> {
        (values.len() == width.checked_mul(height)?).then(|| Self {
            width,
            height,
            values: values
                .into_iter()
                .map(|v| if v > 0.0 { v } else { f32::NAN })
                .collect(),
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The disparity of the pixel holding (x, y) (pixel centres at integer coordinates),
    /// or `None` outside the map or where it is unknown.
    pub fn at(&self, x: f64, y: f64) -> Option<f64> {
        let (col, row) = (x.round(), y.round());
        if !(col >= 0.0 && row >= 0.0 && col < self.width as f64 && row < self.height as f64) {
            return None;
        }
        let v = self.values[row as usize * self.width + col as usize];
        v.is_finite().then_some(f64::from(v))
    }

    /// The disparity at (x, y) between pixel centres: bilinear over the four pixels around
    /// it. `None` outside the map, where one of them is unknown, or where they differ by
    /// more than `max_spread_px` (a depth edge: no single surface to interpolate).
    pub fn interpolated(&self, x: f64, y: f64, max_spread_px: f64) -> Option<f64> {
        let (col, row) = (x.floor(), y.floor());
        let inside = |c: f64, r: f64| {
            c >= 0.0 && r >= 0.0 && c < self.width as f64 && r < self.height as f64
        };
        if !(inside(col, row) && inside(col + 1.0, row + 1.0)) {
            return None;
        }
        let (c, r) = (col as usize, row as usize);
        let at = |dc: usize, dr: usize| f64::from(self.values[(r + dr) * self.width + c + dc]);
        let corners = [at(0, 0), at(1, 0), at(0, 1), at(1, 1)];
        if corners.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let (low, high) = corners
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        if !(high - low <= max_spread_px) {
            return None;
        }
        let (fx, fy) = (x - col, y - row);
        let top = corners[0] + (corners[1] - corners[0]) * fx;
        let bottom = corners[2] + (corners[3] - corners[2]) * fx;
        Some(top + (bottom - top) * fy)
    }

    /// Fraction of pixels with a known disparity.
    pub fn coverage(&self) -> f64 {
        let known = self.values.iter().filter(|v| v.is_finite()).count();
        known as f64 / self.values.len().max(1) as f64
    }
}

fn continuous(mat: &Mat) -> Result<&[u8], DatasetError> {
    mat.data_bytes().map_err(|reason| DatasetError::OpenCv {
        context: "reading a disparity map",
        reason,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookups_round_to_the_pixel_and_refuse_unknown_and_outside() {
        let map = DisparityMap::from_values(3, 2, vec![1.0, 0.0, 2.5, f32::NAN, 4.0, 5.0]).unwrap();
        assert_eq!(map.at(0.4, 0.0), Some(1.0));
        assert_eq!(map.at(1.0, 0.0), None, "0 is unknown, not d = 0");
        assert_eq!(map.at(0.0, 1.0), None);
        assert_eq!(map.at(1.6, 0.6), Some(5.0));
        assert_eq!(map.at(-0.6, 0.0), None);
        assert_eq!(map.at(0.0, 1.6), None);
        assert_eq!(map.at(f64::NAN, 0.0), None);
        assert!((map.coverage() - 4.0 / 6.0).abs() < 1e-12);
        assert!(DisparityMap::from_values(3, 2, vec![1.0; 5]).is_none());
    }

    #[test]
    fn interpolation_is_bilinear_and_refuses_unknown_edges_and_outside() {
        // A plane d = 10 + 0.5·x + 0.25·y on 4 × 3 pixels: bilinear reproduces it exactly.
        let plane = |x: f64, y: f64| 10.0 + 0.5 * x + 0.25 * y;
        let values = (0..3)
            .flat_map(|r| (0..4).map(move |c| plane(f64::from(c), f64::from(r)) as f32))
            .collect();
        let map = DisparityMap::from_values(4, 3, values).unwrap();
        for (x, y) in [(0.0, 0.0), (1.3, 0.6), (2.9, 1.99), (3.0, 2.0)] {
            let d = map.interpolated(x, y, 1.0);
            // The last column and row have no neighbour beyond them: outside.
            if x >= 3.0 || y >= 2.0 {
                assert_eq!(d, None, "({x}, {y})");
            } else {
                assert!((d.unwrap() - plane(x, y)).abs() < 1e-5, "({x}, {y}): {d:?}");
            }
        }
        assert_eq!(map.interpolated(-0.1, 0.0, 1.0), None);
        // The four pixels around (1.5, 0.5) span 0.75 px: refused under a tighter limit.
        assert_eq!(map.interpolated(1.5, 0.5, 0.7), None);
        let mut holed = map.clone();
        holed.values[5] = f32::NAN;
        assert_eq!(holed.interpolated(1.5, 0.5, 1.0), None);
        assert!(holed.interpolated(2.5, 1.5, 1.0).is_some());
    }
}
