//! EuRoC MAV, ASL folder layout.
//!
//! ```text
//! <sequence>/mav0/cam0/sensor.yaml       intrinsics, distortion, T_BS, resolution, rate
//! <sequence>/mav0/cam0/data.csv          #timestamp [ns],filename
//! <sequence>/mav0/cam0/data/<ns>.png
//! <sequence>/mav0/cam1/…                 the right camera, the same way
//! <sequence>/mav0/state_groundtruth_estimate0/data.csv
//!     timestamp [ns], p_RS_R x y z [m], q_RS w x y z, (velocity, biases…)
//! ```
//!
//! sensor.yaml is OpenCV-flavoured YAML (`%YAML:1.0`); only the keys listed above are read,
//! with a small reader of `key: value` and `key: [a, b, …]` (lists may span lines).

use crate::{
    DatasetError, FrameEntry, PinholeCamera, Rectifier, StereoSequence, parse_error, read_text,
};
use linetrack_geometry::StereoRig;
use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};

/// Reads one camera's sensor.yaml.
pub fn read_euroc_camera(path: &Path) -> Result<PinholeCamera, DatasetError> {
    let text = read_text(path)?;
    let resolution = yaml_numbers(&text, path, "resolution", Some(2))?;
    let intrinsics = yaml_numbers(&text, path, "intrinsics", Some(4))?;
    let model = yaml_scalar(&text, "distortion_model").unwrap_or_else(|| "none".to_string());
    let distortion = match model.as_str() {
        "radial-tangential" | "radtan" => {
            yaml_numbers(&text, path, "distortion_coefficients", Some(4))?
        }
        "none" => vec![0.0; 4],
        other => {
            let line = line_of(&text, "distortion_model");
            return Err(parse_error(
                path,
                line,
                format!("distortion_model {other:?} is not supported (radial-tangential or none)"),
            ));
        }
    };
    let t_bs = yaml_numbers(&text, path, "data", Some(16))?;
    let [w, h] = [resolution[0], resolution[1]];
    if !(w >= 1.0 && h >= 1.0 && w.fract() == 0.0 && h.fract() == 0.0 && w <= 1e5 && h <= 1e5) {
        return Err(parse_error(
            path,
            line_of(&text, "resolution"),
            format!("resolution {w}×{h} is not a positive whole size"),
        ));
    }
    let body_from_camera = isometry_from_rows(&t_bs).ok_or_else(|| {
        parse_error(
            path,
            line_of(&text, "T_BS"),
            "T_BS is not a rigid transform (rotation not orthonormal, or last row not 0 0 0 1)",
        )
    })?;
    Ok(PinholeCamera {
        width: w as u32,
        height: h as u32,
        intrinsics: [intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]],
        distortion: [distortion[0], distortion[1], distortion[2], distortion[3]],
        body_from_camera,
    })
}

/// A 4×4 row-major rigid transform, checked.
pub(crate) fn isometry_from_rows(m: &[f64]) -> Option<Isometry3<f64>> {
    if m.len() != 16 || m.iter().any(|v| !v.is_finite()) || m[12..16] != [0.0, 0.0, 0.0, 1.0] {
        return None;
    }
    let r = Matrix3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]);
    if !((r.transpose() * r - Matrix3::identity()).amax() < 1e-4)
        || !((r.determinant() - 1.0).abs() < 1e-4)
    {
        return None;
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
    Some(Isometry3::from_parts(
        Translation3::new(m[3], m[7], m[11]),
        rotation,
    ))
}

/// 1-based line of the first occurrence of `key:`, 0 when absent.
fn line_of(text: &str, key: &str) -> usize {
    text.lines()
        .position(|l| {
            strip_comment(l)
                .trim_start()
                .starts_with(&format!("{key}:"))
        })
        .map_or(0, |k| k + 1)
}

fn strip_comment(line: &str) -> &str {
    line.split('#').next().unwrap_or("")
}

/// The scalar after `key:` on its line.
fn yaml_scalar(text: &str, key: &str) -> Option<String> {
    text.lines().map(strip_comment).find_map(|l| {
        let rest = l
            .trim_start()
            .strip_prefix(key)?
            .trim_start()
            .strip_prefix(':')?;
        Some(rest.trim().trim_matches('"').to_string())
    })
}

/// The numbers of the list after `key:` (`[a, b, …]`, possibly over several lines),
/// checking the count when given.
fn yaml_numbers(
    text: &str,
    path: &Path,
    key: &str,
    count: Option<usize>,
) -> Result<Vec<f64>, DatasetError> {
    let start = line_of(text, key);
    if start == 0 {
        return Err(parse_error(path, 0, format!("missing key `{key}`")));
    }
    let mut collected = String::new();
    for line in text.lines().skip(start - 1).map(strip_comment) {
        collected.push_str(line);
        collected.push(' ');
        if line.contains(']') {
            break;
        }
    }
    let open = collected.find('[');
    let close = collected.find(']');
    let (Some(open), Some(close)) = (open, close) else {
        return Err(parse_error(path, start, format!("`{key}` is not a [list]")));
    };
    let numbers = collected[open + 1..close]
        .split(',')
        .map(str::trim)
        .filter(|v| !v.is_empty())
        .map(|v| {
            v.parse::<f64>()
                .map_err(|_| parse_error(path, start, format!("`{key}`: not a number: {v:?}")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(n) = count
        && numbers.len() != n
    {
        return Err(parse_error(
            path,
            start,
            format!("`{key}` has {} values, expected {n}", numbers.len()),
        ));
    }
    if numbers.iter().any(|v| !v.is_finite()) {
        return Err(parse_error(
            path,
            start,
            format!("`{key}` has a non-finite value"),
        ));
    }
    Ok(numbers)
}

/// `(timestamp ns, file name, line)` rows of a camera's data.csv, timestamps increasing.
fn read_image_list(path: &Path) -> Result<Vec<(u64, String, usize)>, DatasetError> {
    let text = read_text(path)?;
    let mut rows: Vec<(u64, String, usize)> = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut columns = line.split(',').map(str::trim);
        let (Some(stamp), Some(name)) = (columns.next(), columns.next()) else {
            return Err(parse_error(
                path,
                k + 1,
                "expected 2 columns: timestamp [ns],filename",
            ));
        };
        if name.is_empty() {
            return Err(parse_error(path, k + 1, "empty file name"));
        }
        let stamp: u64 = stamp.parse().map_err(|_| {
            parse_error(
                path,
                k + 1,
                format!("timestamp {stamp:?} is not a whole number of ns"),
            )
        })?;
        if let Some((previous, _, _)) = rows.last()
            && *previous >= stamp
        {
            return Err(parse_error(
                path,
                k + 1,
                format!("timestamp {stamp} does not increase (previous {previous})"),
            ));
        }
        rows.push((stamp, name.to_string(), k + 1));
    }
    if rows.is_empty() {
        return Err(parse_error(path, 0, "lists no images"));
    }
    Ok(rows)
}

/// Ground-truth body poses `(timestamp ns, world_from_body)`.
fn read_ground_truth(path: &Path) -> Result<Vec<(u64, Isometry3<f64>)>, DatasetError> {
    let text = read_text(path)?;
    let mut poses: Vec<(u64, Isometry3<f64>)> = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let columns: Vec<&str> = line.split(',').map(str::trim).collect();
        if columns.len() < 8 {
            return Err(parse_error(
                path,
                k + 1,
                format!(
                    "expected at least 8 columns (timestamp, position, quaternion w x y z), found {}",
                    columns.len()
                ),
            ));
        }
        let stamp: u64 = columns[0].parse().map_err(|_| {
            parse_error(
                path,
                k + 1,
                format!("timestamp {:?} is not a whole number of ns", columns[0]),
            )
        })?;
        let v: Vec<f64> = columns[1..8]
            .iter()
            .map(|c| {
                c.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| parse_error(path, k + 1, format!("not a finite number: {c:?}")))
            })
            .collect::<Result<_, _>>()?;
        let q = Quaternion::new(v[3], v[4], v[5], v[6]);
        if (q.norm() - 1.0).abs() > 1e-3 {
            return Err(parse_error(
                path,
                k + 1,
                format!("quaternion norm {} is not 1", q.norm()),
            ));
        }
        if poses.last().is_some_and(|(previous, _)| *previous >= stamp) {
            return Err(parse_error(
                path,
                k + 1,
                format!("timestamp {stamp} does not increase"),
            ));
        }
        poses.push((
            stamp,
            Isometry3::from_parts(
                Translation3::new(v[0], v[1], v[2]),
                UnitQuaternion::from_quaternion(q),
            ),
        ));
    }
    Ok(poses)
}

/// Ground truth at `stamp`: linear in position, spherical in rotation, between the two
/// samples around it; `None` outside the sampled span or across a gap over 100 ms (the
/// excerpt is sampled every 50 ms, a few hundred ns off the camera stamps).
fn interpolate(poses: &[(u64, Isometry3<f64>)], stamp: u64) -> Option<Isometry3<f64>> {
    const MAX_GAP_NS: u64 = 100_000_000;
    let after = poses.partition_point(|(t, _)| *t < stamp);
    let (t1, p1) = poses.get(after)?;
    if *t1 == stamp {
        return Some(*p1);
    }
    let (t0, p0) = poses.get(after.checked_sub(1)?)?;
    if t1 - t0 > MAX_GAP_NS {
        return None;
    }
    let s = (stamp - t0) as f64 / (t1 - t0) as f64;
    let translation: Vector3<f64> = p0.translation.vector.lerp(&p1.translation.vector, s);
    Some(Isometry3::from_parts(
        translation.into(),
        p0.rotation.slerp(&p1.rotation, s),
    ))
}

impl StereoSequence {
    /// Opens an EuRoC sequence folder (the one holding `mav0/`).
    pub fn open_euroc(dir: &Path) -> Result<Self, DatasetError> {
        let mav0 = dir.join("mav0");
        if !mav0.is_dir() {
            return Err(DatasetError::Io {
                path: mav0,
                reason: std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    "no mav0/ folder: not an EuRoC (ASL) sequence",
                ),
            });
        }
        let left = read_euroc_camera(&mav0.join("cam0/sensor.yaml"))?;
        let right = read_euroc_camera(&mav0.join("cam1/sensor.yaml"))?;
        let rate_hz = yaml_scalar(&read_text(&mav0.join("cam0/sensor.yaml"))?, "rate_hz")
            .and_then(|v| v.parse().ok())
            .unwrap_or(20.0);
        let rectifier = Rectifier::new(&left, &right)?;
        // An ideal rig (generated data) needs no remapping: keep its exact geometry.
        let (rig, rectifier) = match ideal_rig(&left, &right) {
            Some(rig) => (rig, None),
            None => (rectifier.rig(), Some(rectifier)),
        };
        let left_list = read_image_list(&mav0.join("cam0/data.csv"))?;
        let right_list = read_image_list(&mav0.join("cam1/data.csv"))?;
        let gt_path = mav0.join("state_groundtruth_estimate0/data.csv");
        let ground_truth = if gt_path.is_file() {
            read_ground_truth(&gt_path)?
        } else {
            Vec::new()
        };

        let mut frames = Vec::new();
        let mut right_rows = right_list.iter().peekable();
        for (stamp, name, _) in &left_list {
            while right_rows.next_if(|(r, _, _)| r < stamp).is_some() {}
            let Some((_, right_name, _)) = right_rows.next_if(|(r, _, _)| r == stamp) else {
                continue;
            };
            let pose = interpolate(&ground_truth, *stamp).map(|world_from_body| {
                let raw_left = world_from_body * left.body_from_camera;
                rectifier
                    .as_ref()
                    .map_or(raw_left, |r| r.rectified_left_pose(&raw_left))
            });
            frames.push(FrameEntry {
                index: frames.len(),
                timestamp_ns: *stamp,
                left: mav0.join("cam0/data").join(name),
                right: mav0.join("cam1/data").join(right_name),
                pose,
            });
        }
        if frames.is_empty() {
            return Err(parse_error(
                &mav0.join("cam1/data.csv"),
                0,
                "no timestamp in common with cam0/data.csv",
            ));
        }
        Ok(StereoSequence::new(
            sequence_name(dir),
            frames,
            rig,
            rectifier,
            rate_hz,
        ))
    }
}

/// The rig itself when the pair is already rectified: no distortion, equal intrinsics with
/// square pixels, no relative rotation, and the right camera straight along +x.
fn ideal_rig(left: &PinholeCamera, right: &PinholeCamera) -> Option<StereoRig> {
    let right_from_left = right.body_from_camera.inverse() * left.body_from_camera;
    let t = right_from_left.translation.vector;
    let ideal = left.distortion == [0.0; 4]
        && right.distortion == [0.0; 4]
        && left.intrinsics == right.intrinsics
        && left.intrinsics[0] == left.intrinsics[1]
        && right_from_left.rotation.angle() < 1e-9
        && t.y.abs() < 1e-9
        && t.z.abs() < 1e-9
        && t.x < 0.0;
    ideal.then(|| StereoRig {
        focal_px: left.intrinsics[0],
        cx_px: left.intrinsics[2],
        cy_px: left.intrinsics[3],
        baseline_m: -t.x,
        width_px: left.width,
        height_px: left.height,
    })
}

pub(crate) fn sequence_name(dir: &Path) -> String {
    let absolute: PathBuf = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
    absolute.file_name().map_or_else(
        || dir.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_is_exact_at_samples_and_linear_between() {
        let a = Isometry3::translation(0.0, 0.0, 0.0);
        let b = Isometry3::translation(1.0, 2.0, 0.0);
        let poses = [(100, a), (200, b)];
        assert_eq!(interpolate(&poses, 100), Some(a));
        let mid = interpolate(&poses, 150).unwrap();
        assert!((mid.translation.vector - Vector3::new(0.5, 1.0, 0.0)).norm() < 1e-12);
        assert_eq!(interpolate(&poses, 50), None);
        assert_eq!(interpolate(&poses, 250), None);
        assert_eq!(
            interpolate(&[(0, a), (150_000_000, b)], 50_000_000),
            None,
            "gap over 100 ms"
        );
    }

    #[test]
    fn yaml_lists_may_span_lines_and_carry_comments() {
        let text = "T_BS:\n  cols: 4\n  data: [1, 2, # c\n   3]\nintrinsics: [4.5, 5] #fu\n";
        let p = Path::new("x.yaml");
        assert_eq!(
            yaml_numbers(text, p, "data", Some(3)).unwrap(),
            vec![1.0, 2.0, 3.0]
        );
        assert_eq!(
            yaml_numbers(text, p, "intrinsics", None).unwrap(),
            vec![4.5, 5.0]
        );
        let err = yaml_numbers(text, p, "intrinsics", Some(4))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("x.yaml:5") && err.contains("2 values"),
            "{err}"
        );
        assert!(
            yaml_numbers(text, p, "missing", None)
                .unwrap_err()
                .to_string()
                .contains("missing key `missing`")
        );
    }
}
