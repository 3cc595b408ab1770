//! KITTI odometry layout.
//!
//! ```text
//! <root>/sequences/NN/calib.txt     P0: … (12 values, row-major 3×4), P1: …
//! <root>/sequences/NN/times.txt     one time in seconds per frame
//! <root>/sequences/NN/image_0/000000.png   left (grayscale), image_1/ right
//! <root>/poses/NN.txt               one row-major 3×4 camera pose per frame (optional)
//! ```
//!
//! KITTI images are already rectified: the rig comes straight from P0 and P1. The helpers
//! here (keyed calibration lines, increasing time lists, the rig from two projection
//! matrices) are shared with the KITTI raw layout.

use crate::euroc::sequence_name;
use crate::{DatasetError, FrameEntry, StereoSequence, parse_error, read_text};
use linetrack_geometry::StereoRig;
use linetrack_vision::GrayImage;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};
use std::path::{Path, PathBuf};

/// The whitespace-separated numbers of `fields` (on line `line` of `path`), each finite.
pub(crate) fn finite_numbers(
    fields: &str,
    path: &Path,
    line: usize,
) -> Result<Vec<f64>, DatasetError> {
    fields
        .split_whitespace()
        .map(|v| {
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| parse_error(path, line, format!("not a finite number: {v:?}")))
        })
        .collect()
}

/// The `N` values after `key:` in a KITTI calibration file (`text`, read from `path`).
pub(crate) fn key_values<const N: usize>(
    text: &str,
    path: &Path,
    key: &str,
) -> Result<[f64; N], DatasetError> {
    let (k, line) = text
        .lines()
        .enumerate()
        .find(|(_, l)| l.trim_start().starts_with(&format!("{key}:")))
        .ok_or_else(|| parse_error(path, 0, format!("missing {key}")))?;
    let values = finite_numbers(
        line.split_once(':').map_or("", |(_, rest)| rest),
        path,
        k + 1,
    )?;
    values.try_into().map_err(|v: Vec<f64>| {
        parse_error(
            path,
            k + 1,
            format!("{key} has {} values, expected {N}", v.len()),
        )
    })
}

/// The non-empty lines of `path`, each parsed by `parse` (`what` names the expected form),
/// strictly increasing; at least one.
pub(crate) fn read_increasing<T: PartialOrd>(
    path: &Path,
    what: &str,
    parse: impl Fn(&str) -> Option<T>,
) -> Result<Vec<T>, DatasetError> {
    let text = read_text(path)?;
    let mut times: Vec<T> = Vec::new();
    for (k, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let line = line.trim();
        let t =
            parse(line).ok_or_else(|| parse_error(path, k + 1, format!("not {what}: {line:?}")))?;
        if times.last().is_some_and(|previous| *previous >= t) {
            return Err(parse_error(
                path,
                k + 1,
                format!("time {line} does not increase"),
            ));
        }
        times.push(t);
    }
    if times.is_empty() {
        return Err(parse_error(path, 0, "lists no frames"));
    }
    Ok(times)
}

/// The rig of an already rectified KITTI pair: focal length and principal point from the
/// left projection matrix, baseline from the right one (keys `keys` in `calib_path`), image
/// size from `first_left`.
pub(crate) fn rectified_rig(
    left: &[f64; 12],
    right: &[f64; 12],
    keys: (&str, &str),
    calib_path: &Path,
    first_left: &Path,
) -> Result<StereoRig, DatasetError> {
    let (left_key, right_key) = keys;
    if !(left[0] > 0.0 && right[0] > 0.0) {
        return Err(parse_error(
            calib_path,
            0,
            format!("{left_key}/{right_key} focal length must be positive"),
        ));
    }
    let baseline_m = -right[3] / right[0];
    if !(baseline_m > 0.0) {
        return Err(parse_error(
            calib_path,
            0,
            format!(
                "{right_key} gives baseline {baseline_m} m: the right camera must be to the right"
            ),
        ));
    }
    let first = GrayImage::load(first_left)?;
    Ok(StereoRig {
        focal_px: left[0],
        cx_px: left[2],
        cy_px: left[6],
        baseline_m,
        width_px: first.width() as u32,
        height_px: first.height() as u32,
    })
}

/// Frames per second over a list of increasing timestamps (KITTI's 10 Hz for one frame).
pub(crate) fn rate_hz(first_s: f64, last_s: f64, frames: usize) -> f64 {
    if frames > 1 {
        (frames - 1) as f64 / (last_s - first_s)
    } else {
        10.0
    }
}

/// Reads camera poses in the KITTI odometry format: one line per frame, 12 values, the
/// row-major 3×4 pose `[R | t]` of the camera in the world.
pub fn read_kitti_poses(path: &Path) -> Result<Vec<Isometry3<f64>>, DatasetError> {
    let text = read_text(path)?;
    let mut poses = Vec::new();
    for (k, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let v = finite_numbers(line, path, k + 1)?;
        if v.len() != 12 {
            return Err(parse_error(
                path,
                k + 1,
                format!("{} values, expected 12 (row-major 3×4)", v.len()),
            ));
        }
        let r = Matrix3::new(v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]);
        if !((r.transpose() * r - Matrix3::identity()).amax() < 1e-3) {
            return Err(parse_error(path, k + 1, "rotation is not orthonormal"));
        }
        let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
        poses.push(Isometry3::from_parts(
            Translation3::new(v[3], v[7], v[11]),
            rotation,
        ));
    }
    Ok(poses)
}

impl StereoSequence {
    /// Opens a KITTI odometry sequence folder (`…/sequences/NN`). Ground truth is read from
    /// `poses`, or else from `…/poses/NN.txt` beside `sequences/` when it exists.
    pub fn open_kitti(dir: &Path, poses: Option<&Path>) -> Result<Self, DatasetError> {
        let calib_path = dir.join("calib.txt");
        let calib = read_text(&calib_path)?;
        let p0 = key_values::<12>(&calib, &calib_path, "P0")?;
        let p1 = key_values::<12>(&calib, &calib_path, "P1")?;
        let times = read_increasing(&dir.join("times.txt"), "a time in seconds", |t| {
            t.parse::<f64>().ok().filter(|t| t.is_finite())
        })?;
        let default_poses: Option<PathBuf> = dir
            .file_name()
            .map(|name| {
                dir.join("../../poses")
                    .join(format!("{}.txt", name.to_string_lossy()))
            })
            .filter(|p| p.is_file());
        let pose_path = poses.map(Path::to_path_buf).or(default_poses);
        let ground_truth = match &pose_path {
            Some(p) => {
                let list = read_kitti_poses(p)?;
                if list.len() != times.len() {
                    return Err(parse_error(
                        p,
                        0,
                        format!(
                            "{} poses for {} frames in times.txt",
                            list.len(),
                            times.len()
                        ),
                    ));
                }
                Some(list)
            }
            None => None,
        };
        let image = |side: &str, k: usize| dir.join(side).join(format!("{k:06}.png"));
        let rig = rectified_rig(&p0, &p1, ("P0", "P1"), &calib_path, &image("image_0", 0))?;
        let frames = times
            .iter()
            .enumerate()
            .map(|(k, t)| FrameEntry {
                index: k,
                timestamp_ns: (t * 1e9).round() as u64,
                left: image("image_0", k),
                right: image("image_1", k),
                pose: ground_truth.as_ref().map(|g| g[k]),
            })
            .collect();
        let rate_hz = rate_hz(times[0], times[times.len() - 1], times.len());
        Ok(StereoSequence::new(
            sequence_name(dir),
            frames,
            rig,
            None,
            rate_hz,
        ))
    }
}
