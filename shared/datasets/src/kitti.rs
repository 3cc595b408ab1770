//! KITTI odometry layout.
//!
//! ```text
//! <root>/sequences/NN/calib.txt     P0: … (12 values, row-major 3×4), P1: …
//! <root>/sequences/NN/times.txt     one time in seconds per frame
//! <root>/sequences/NN/image_0/000000.png   left (grayscale), image_1/ right
//! <root>/poses/NN.txt               one row-major 3×4 camera pose per frame (optional)
//! ```
//!
//! KITTI images are already rectified: the rig comes straight from P0 and P1.

use crate::euroc::sequence_name;
use crate::{DatasetError, FrameEntry, StereoSequence, parse_error, read_text};
use linetrack_geometry::StereoRig;
use linetrack_vision::GrayImage;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};
use std::path::{Path, PathBuf};

/// The 12 values after `key:` in calib.txt.
fn projection(text: &str, path: &Path, key: &str) -> Result<[f64; 12], DatasetError> {
    let (k, line) = text
        .lines()
        .enumerate()
        .find(|(_, l)| l.trim_start().starts_with(&format!("{key}:")))
        .ok_or_else(|| parse_error(path, 0, format!("missing {key}")))?;
    let values: Vec<f64> = line
        .split_once(':')
        .map_or("", |(_, rest)| rest)
        .split_whitespace()
        .map(|v| {
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    parse_error(path, k + 1, format!("{key}: not a finite number: {v:?}"))
                })
        })
        .collect::<Result<_, _>>()?;
    values.try_into().map_err(|v: Vec<f64>| {
        parse_error(
            path,
            k + 1,
            format!("{key} has {} values, expected 12", v.len()),
        )
    })
}

fn read_times(path: &Path) -> Result<Vec<f64>, DatasetError> {
    let text = read_text(path)?;
    let mut times: Vec<f64> = Vec::new();
    for (k, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let t: f64 = line
            .trim()
            .parse()
            .ok()
            .filter(|t: &f64| t.is_finite())
            .ok_or_else(|| {
                parse_error(
                    path,
                    k + 1,
                    format!("not a time in seconds: {:?}", line.trim()),
                )
            })?;
        if times.last().is_some_and(|previous| *previous >= t) {
            return Err(parse_error(
                path,
                k + 1,
                format!("time {t} does not increase"),
            ));
        }
        times.push(t);
    }
    if times.is_empty() {
        return Err(parse_error(path, 0, "lists no frames"));
    }
    Ok(times)
}

fn read_poses(path: &Path) -> Result<Vec<Isometry3<f64>>, DatasetError> {
    let text = read_text(path)?;
    let mut poses = Vec::new();
    for (k, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let v: Vec<f64> = line
            .split_whitespace()
            .map(|x| {
                x.parse::<f64>()
                    .ok()
                    .filter(|y| y.is_finite())
                    .ok_or_else(|| parse_error(path, k + 1, format!("not a finite number: {x:?}")))
            })
            .collect::<Result<_, _>>()?;
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
        let p0 = projection(&calib, &calib_path, "P0")?;
        let p1 = projection(&calib, &calib_path, "P1")?;
        if !(p0[0] > 0.0 && p1[0] > 0.0) {
            return Err(parse_error(
                &calib_path,
                0,
                "P0/P1 focal length must be positive",
            ));
        }
        let baseline_m = -p1[3] / p1[0];
        if !(baseline_m > 0.0) {
            return Err(parse_error(
                &calib_path,
                0,
                format!("P1 gives baseline {baseline_m} m: the right camera must be to the right"),
            ));
        }
        let times = read_times(&dir.join("times.txt"))?;
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
                let list = read_poses(p)?;
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
        let first = GrayImage::load(&image("image_0", 0))?;
        let rig = StereoRig {
            focal_px: p0[0],
            cx_px: p0[2],
            cy_px: p0[6],
            baseline_m,
            width_px: first.width() as u32,
            height_px: first.height() as u32,
        };
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
        let rate_hz = if times.len() > 1 {
            (times.len() - 1) as f64 / (times[times.len() - 1] - times[0])
        } else {
            10.0
        };
        Ok(StereoSequence::new(
            sequence_name(dir),
            frames,
            rig,
            None,
            rate_hz,
        ))
    }
}
