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
//! sensor.yaml is read with a YAML parser (serde-saphyr) into the keys listed above; other
//! keys (`sensor_type`, `comment`, `camera_model`, …) are ignored. OpenCV writes a
//! `%YAML:1.0` first line, which is not YAML (the directive is `%YAML 1.0`): that one line
//! is read as a comment. A key given twice is an error, as is a value of the wrong type or
//! count; every error names the file, the line where the parser knows it, and the key.

use crate::{
    DatasetError, FrameEntry, PinholeCamera, Rectifier, StereoSequence, parse_error, read_text,
};
use linetrack_geometry::StereoRig;
use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The keys of sensor.yaml that are read.
#[derive(Debug, Deserialize)]
struct SensorYaml {
    /// The camera's pose in the body frame.
    #[serde(rename = "T_BS")]
    t_bs: MatrixYaml,
    /// Frames per second (20 when absent).
    rate_hz: Option<f64>,
    /// Width and height, pixels.
    resolution: Vec<f64>,
    /// fu, fv, cu, cv.
    intrinsics: Vec<f64>,
    /// `radial-tangential` (or `radtan`), or `none`; `none` when absent.
    distortion_model: Option<String>,
    /// k1, k2, p1, p2 (for radial-tangential).
    distortion_coefficients: Option<Vec<f64>>,
}

/// An OpenCV-style matrix: `rows`, `cols` and row-major `data`.
#[derive(Debug, Deserialize)]
struct MatrixYaml {
    rows: usize,
    cols: usize,
    data: Vec<f64>,
}

/// OpenCV's `%YAML:1.0` first line (not a YAML directive) read as a comment, keeping the
/// line numbers.
fn without_opencv_directive(text: &str) -> std::borrow::Cow<'_, str> {
    if text.starts_with("%YAML:") {
        std::borrow::Cow::Owned(format!("#{text}"))
    } else {
        std::borrow::Cow::Borrowed(text)
    }
}

/// Parses sensor.yaml; errors name the file and, where the parser knows it, the line and
/// the top-level key it belongs to.
fn parse_sensor_yaml(text: &str, path: &Path) -> Result<SensorYaml, DatasetError> {
    serde_saphyr::from_str(&without_opencv_directive(text)).map_err(|e| {
        let line = e
            .location()
            .and_then(|l| usize::try_from(l.line()).ok())
            .unwrap_or(0);
        // The parser's advice to its caller is no help to whoever wrote the file.
        let message = e
            .without_snippet()
            .to_string()
            .replace(", set DuplicateKeyPolicy in Options if acceptable", "");
        match top_level_key_at(text, line) {
            // A missing field is found at the end of the mapping: no key to blame there.
            Some(key) if !message.contains(key) && !message.contains("missing field") => {
                parse_error(path, line, format!("`{key}`: {message}"))
            }
            _ => parse_error(path, line, message),
        }
    })
}

/// The top-level key whose value spans 1-based `line` (the last unindented `key:` at or
/// before it), to name the key in a parser error that gives only a position.
fn top_level_key_at(text: &str, line: usize) -> Option<&str> {
    text.lines()
        .take(line)
        .filter(|l| !l.starts_with([' ', '\t', '#', '%', '-']))
        .filter_map(|l| l.split_once(':').map(|(key, _)| key.trim()))
        .filter(|key| !key.is_empty())
        .last()
}

/// `values` when there are `count` of them, all finite; otherwise an error naming `key`.
fn exactly<const N: usize>(
    values: &[f64],
    path: &Path,
    key: &str,
) -> Result<[f64; N], DatasetError> {
    let array: [f64; N] = values.try_into().map_err(|_| {
        parse_error(
            path,
            0,
            format!("`{key}` has {} values, expected {N}", values.len()),
        )
    })?;
    if array.iter().any(|v| !v.is_finite()) {
        return Err(parse_error(
            path,
            0,
            format!("`{key}` has a non-finite value"),
        ));
    }
    Ok(array)
}

/// Reads one camera's sensor.yaml.
pub fn read_euroc_camera(path: &Path) -> Result<PinholeCamera, DatasetError> {
    read_sensor(path).map(|(camera, _)| camera)
}

/// One camera's sensor.yaml: the camera and its frame rate, if given.
fn read_sensor(path: &Path) -> Result<(PinholeCamera, Option<f64>), DatasetError> {
    let yaml = parse_sensor_yaml(&read_text(path)?, path)?;
    let [w, h] = exactly::<2>(&yaml.resolution, path, "resolution")?;
    let intrinsics = exactly::<4>(&yaml.intrinsics, path, "intrinsics")?;
    let distortion = match yaml.distortion_model.as_deref().unwrap_or("none") {
        "radial-tangential" | "radtan" => exactly::<4>(
            yaml.distortion_coefficients
                .as_deref()
                .ok_or_else(|| parse_error(path, 0, "missing field `distortion_coefficients`"))?,
            path,
            "distortion_coefficients",
        )?,
        "none" => [0.0; 4],
        other => {
            return Err(parse_error(
                path,
                0,
                format!("distortion_model {other:?} is not supported (radial-tangential or none)"),
            ));
        }
    };
    let t_bs = &yaml.t_bs;
    if (t_bs.rows, t_bs.cols) != (4, 4) {
        return Err(parse_error(
            path,
            0,
            format!("T_BS is {}×{}, expected 4×4", t_bs.rows, t_bs.cols),
        ));
    }
    let t_bs = exactly::<16>(&t_bs.data, path, "T_BS.data")?;
    if !(w >= 1.0 && h >= 1.0 && w.fract() == 0.0 && h.fract() == 0.0 && w <= 1e5 && h <= 1e5) {
        return Err(parse_error(
            path,
            0,
            format!("resolution {w}×{h} is not a positive whole size"),
        ));
    }
    let body_from_camera = isometry_from_rows(&t_bs).ok_or_else(|| {
        parse_error(
            path,
            0,
            "T_BS is not a rigid transform (rotation not orthonormal, or last row not 0 0 0 1)",
        )
    })?;
    if let Some(rate) = yaml.rate_hz
        && !(rate > 0.0 && rate.is_finite())
    {
        return Err(parse_error(
            path,
            0,
            format!("rate_hz {rate} is not a positive number"),
        ));
    }
    Ok((
        PinholeCamera {
            width: w as u32,
            height: h as u32,
            intrinsics,
            distortion,
            body_from_camera,
        },
        yaml.rate_hz,
    ))
}

/// Frames per second when sensor.yaml gives none.
const DEFAULT_RATE_HZ: f64 = 20.0;

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
        let (left, rate_hz) = read_sensor(&mav0.join("cam0/sensor.yaml"))?;
        let rate_hz = rate_hz.unwrap_or(DEFAULT_RATE_HZ);
        let right = read_euroc_camera(&mav0.join("cam1/sensor.yaml"))?;
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

    /// sensor.yaml as OpenCV writes it, with `extra` lines added at the end.
    fn sensor(extra: &str) -> String {
        format!(
            "%YAML:1.0\nsensor_type: camera\ncomment: a camera # with a comment\nT_BS:\n  cols: 4\n  rows: 4\n  data: [1, 0, 0, 0.1, # first row\n         0, 1, 0, 0,\n         0, 0, 1, 0,\n         0, 0, 0, 1]\nrate_hz: 30\nresolution: [640, 480]\nintrinsics: [400.0, 401.0, 320.0, 240.0] #fu, fv, cu, cv\ndistortion_model: radial-tangential\ndistortion_coefficients: [-0.1, 0.01, 0, 0]\n{extra}"
        )
    }

    fn parse_text(text: &str) -> Result<(PinholeCamera, Option<f64>), String> {
        let dir = linetrack_test_data::Scratch::new("datasets", "sensor-yaml");
        let path = dir.join("sensor.yaml");
        std::fs::write(&path, text).map_err(|e| e.to_string())?;
        read_sensor(&path).map_err(|e| e.to_string())
    }

    #[test]
    fn sensor_yaml_reads_the_nested_t_bs_data_and_ignores_other_keys() {
        // Other `data:` keys, nested elsewhere before and after T_BS: T_BS's is the one read.
        let text = sensor("after:\n  data: [8, 8]\n").replacen(
            "T_BS:",
            "before:\n  rows: 1\n  data: [9, 9]\nT_BS:",
            1,
        );
        let (camera, rate) = parse_text(&text).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(rate, Some(30.0));
        assert_eq!((camera.width, camera.height), (640, 480));
        assert_eq!(camera.intrinsics, [400.0, 401.0, 320.0, 240.0]);
        assert_eq!(camera.distortion, [-0.1, 0.01, 0.0, 0.0]);
        assert!((camera.body_from_camera.translation.vector.x - 0.1).abs() < 1e-12);
        // A standard YAML directive and document start are read too.
        let standard = sensor("").replacen("%YAML:1.0", "%YAML 1.1\n---", 1);
        assert!(parse_text(&standard).is_ok());
    }

    #[test]
    fn bad_sensor_yaml_names_the_file_and_the_key() {
        for (text, wants) in [
            (
                sensor("intrinsics: [1, 2, 3, 4]\n"),
                &["sensor-", ":16", "duplicate mapping key: intrinsics"][..],
            ),
            (
                sensor("").replace("data: [1, 0, 0, 0.1,", "data: [1, 0, 0, 0.1, 7,"),
                &["sensor-", "T_BS.data", "17 values, expected 16"][..],
            ),
            (
                sensor("").replace("400.0, 401.0", "400.0, fifty"),
                &["sensor-", ":13", "`intrinsics`"][..],
            ),
            (
                sensor("").replace("intrinsics:", "intrinsix:"),
                &["sensor-", "missing field `intrinsics`"][..],
            ),
            (
                sensor("").replacen(
                    "intrinsics: [",
                    "intrinsics: [1, 2, 3, 4]\nintrinsics: [",
                    1,
                ),
                &["sensor-", ":14", "duplicate mapping key: intrinsics"][..],
            ),
            (
                sensor("").replace("resolution: [640, 480]", "resolution: [640]"),
                &["sensor-", "`resolution` has 1 values, expected 2"][..],
            ),
            (
                sensor("").replace("  rows: 4", "  rows: 3"),
                &["sensor-", "T_BS is 3×4"][..],
            ),
            (
                sensor("").replace("data: [1, 0, 0, 0.1", "data: [2, 0, 0, 0.1"),
                &["sensor-", "T_BS is not a rigid transform"][..],
            ),
            (
                "resolution: [1, 2\nintrinsics: ]\n".to_string(),
                &["sensor-"][..],
            ),
        ] {
            let err = parse_text(&text)
                .err()
                .unwrap_or_else(|| panic!("accepted:\n{text}"));
            assert!(wants.iter().all(|w| err.contains(w)), "{wants:?}: {err}");
        }
    }
}
