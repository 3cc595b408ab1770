//! Stereo calibration files → the two cameras ([`PinholeCamera`]) the rectifier needs.
//!
//! Two formats:
//!
//! - **Kalibr** `camchain.yaml` (a file): `cam0` and `cam1`, each with `intrinsics`
//!   `[fu, fv, pu, pv]`, `distortion_model` (`radtan` or `none`), `distortion_coeffs`
//!   `[k1, k2, r1, r2]` and `resolution` `[width, height]`; `cam1` has `T_cn_cnm1`, the 4×4
//!   transform taking points from cam0's frame into cam1's (`p_cam1 = T · p_cam0`). Other
//!   keys (`rostopic`, `cam_overlaps`, `T_cam_imu`, …) are ignored.
//! - **EuRoC** `sensor.yaml` pairs (a folder): `DIR/cam0/sensor.yaml` and
//!   `DIR/cam1/sensor.yaml`, or `DIR/mav0/cam0|cam1/sensor.yaml` (a EuRoC sequence folder),
//!   read by the data set reader (`linetrack_datasets::read_euroc_camera`).
//!
//! The YAML is read with serde-saphyr; every error names the file and the key at fault.
//! Only the pinhole model with radial-tangential (or no) distortion is supported: the
//! rectifier (OpenCV `stereoRectify`) takes those; an `equidistant` (fisheye) chain is
//! refused with a message saying so.

use crate::CameraError;
use linetrack_datasets::{PinholeCamera, read_euroc_camera};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The two cameras of a stereo rig, as the calibration file gives them (unrectified).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoCalibration {
    /// The left camera (cam0).
    pub left: PinholeCamera,
    /// The right camera (cam1).
    pub right: PinholeCamera,
}

/// One camera of a Kalibr camchain.
#[derive(Debug, Deserialize)]
struct KalibrCamera {
    /// `pinhole` (the default when absent).
    camera_model: Option<String>,
    /// fu, fv, pu, pv.
    intrinsics: Vec<f64>,
    /// `radtan`, `none`, or another model (refused).
    distortion_model: Option<String>,
    /// k1, k2, r1, r2.
    distortion_coeffs: Option<Vec<f64>>,
    /// Width, height.
    resolution: Vec<f64>,
    /// cam(n-1) → cam(n), 4×4 rows (cam1 only).
    #[serde(rename = "T_cn_cnm1")]
    t_cn_cnm1: Option<Vec<Vec<f64>>>,
}

/// The two cameras of a Kalibr camchain that are read.
#[derive(Debug, Deserialize)]
struct KalibrChain {
    cam0: KalibrCamera,
    cam1: KalibrCamera,
}

fn calibration_error(path: &Path, message: impl Into<String>) -> CameraError {
    CameraError::Calibration {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Reads a calibration: a Kalibr camchain file, or a folder of EuRoC sensor.yaml files.
pub fn read_calibration(path: &Path) -> Result<StereoCalibration, CameraError> {
    if path.is_dir() {
        return read_euroc_pair(path);
    }
    let text = std::fs::read_to_string(path).map_err(|source| CameraError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    read_kalibr(&text, path)
}

/// `DIR/cam0|cam1/sensor.yaml` or `DIR/mav0/cam0|cam1/sensor.yaml`.
fn read_euroc_pair(dir: &Path) -> Result<StereoCalibration, CameraError> {
    let candidates = [dir.to_path_buf(), dir.join("mav0")];
    let Some(base): Option<PathBuf> = candidates
        .into_iter()
        .find(|d| d.join("cam0/sensor.yaml").is_file())
    else {
        return Err(calibration_error(
            dir,
            "a calibration folder must hold cam0/sensor.yaml and cam1/sensor.yaml (EuRoC), directly or under mav0/",
        ));
    };
    let read = |cam: &str| {
        read_euroc_camera(&base.join(cam).join("sensor.yaml")).map_err(CameraError::Dataset)
    };
    Ok(StereoCalibration {
        left: read("cam0")?,
        right: read("cam1")?,
    })
}

/// Parses a Kalibr camchain; `path` names the file in errors.
pub fn read_kalibr(text: &str, path: &Path) -> Result<StereoCalibration, CameraError> {
    let chain: KalibrChain = serde_saphyr::from_str(text).map_err(|e| {
        let line = e
            .location()
            .map_or_else(String::new, |l| format!(" (line {})", l.line()));
        calibration_error(
            path,
            format!(
                "not a Kalibr camchain with cam0 and cam1{line}: {}",
                e.without_snippet()
            ),
        )
    })?;
    let left = kalibr_camera(&chain.cam0, "cam0", path, Isometry3::identity())?;
    let Some(rows) = &chain.cam1.t_cn_cnm1 else {
        return Err(calibration_error(
            path,
            "`cam1.T_cn_cnm1` is missing: the pose of cam1 relative to cam0",
        ));
    };
    let cam1_from_cam0 = isometry(rows, path, "cam1.T_cn_cnm1")?;
    // Body = cam0: p_body = p_cam0 = T⁻¹ · p_cam1.
    let right = kalibr_camera(&chain.cam1, "cam1", path, cam1_from_cam0.inverse())?;
    Ok(StereoCalibration { left, right })
}

fn kalibr_camera(
    cam: &KalibrCamera,
    name: &str,
    path: &Path,
    body_from_camera: Isometry3<f64>,
) -> Result<PinholeCamera, CameraError> {
    match cam.camera_model.as_deref().unwrap_or("pinhole") {
        "pinhole" => {}
        other => {
            return Err(calibration_error(
                path,
                format!("`{name}.camera_model` = {other:?}: only \"pinhole\" is supported"),
            ));
        }
    }
    let [fu, fv, pu, pv] = finite::<4>(&cam.intrinsics, path, &format!("{name}.intrinsics"))?;
    if fu <= 0.0 || fv <= 0.0 {
        return Err(calibration_error(
            path,
            format!("`{name}.intrinsics`: focal lengths {fu}, {fv} must be positive"),
        ));
    }
    let distortion = match cam.distortion_model.as_deref().unwrap_or("none") {
        "radtan" | "radial-tangential" => {
            let coeffs = cam.distortion_coeffs.as_deref().unwrap_or_default();
            finite::<4>(coeffs, path, &format!("{name}.distortion_coeffs"))?
        }
        "none" => [0.0; 4],
        other => {
            return Err(calibration_error(
                path,
                format!(
                    "`{name}.distortion_model` = {other:?}: only \"radtan\" or \"none\" can be rectified here"
                ),
            ));
        }
    };
    let [w, h] = finite::<2>(&cam.resolution, path, &format!("{name}.resolution"))?;
    let pixels = |v: f64| (v.fract() == 0.0 && (1.0..=65_535.0).contains(&v)).then_some(v as u32);
    let (Some(width), Some(height)) = (pixels(w), pixels(h)) else {
        return Err(calibration_error(
            path,
            format!("`{name}.resolution` = [{w}, {h}]: two whole numbers of pixels in 1..=65535"),
        ));
    };
    Ok(PinholeCamera {
        width,
        height,
        intrinsics: [fu, fv, pu, pv],
        distortion,
        body_from_camera,
    })
}

/// `values` when there are `N` of them, all finite; otherwise an error naming `key`.
fn finite<const N: usize>(values: &[f64], path: &Path, key: &str) -> Result<[f64; N], CameraError> {
    let array: [f64; N] = values.try_into().map_err(|_| {
        calibration_error(
            path,
            format!("`{key}` has {} values, expected {N}", values.len()),
        )
    })?;
    if array.iter().any(|v| !v.is_finite()) {
        return Err(calibration_error(
            path,
            format!("`{key}` has a non-finite value: {array:?}"),
        ));
    }
    Ok(array)
}

/// A rigid transform from 4×4 rows: the last row `0 0 0 1`, the rotation orthonormal with
/// determinant +1 (within 1e-3, what calibration tools print).
fn isometry(rows: &[Vec<f64>], path: &Path, key: &str) -> Result<Isometry3<f64>, CameraError> {
    if rows.len() != 4 || rows.iter().any(|r| r.len() != 4) {
        return Err(calibration_error(
            path,
            format!("`{key}` must be 4 rows of 4 values"),
        ));
    }
    let flat: Vec<f64> = rows.iter().flatten().copied().collect();
    let m = finite::<16>(&flat, path, key)?;
    let last_row_ok = (m[12].abs() + m[13].abs() + m[14].abs() + (m[15] - 1.0).abs()) < 1e-9;
    let r = Matrix3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]);
    let orthonormal = (r.transpose() * r - Matrix3::identity()).abs().max() < 1e-3;
    if !last_row_ok || !orthonormal || r.determinant() < 0.0 {
        return Err(calibration_error(
            path,
            format!(
                "`{key}` is not a rigid transform (rotation and translation, last row 0 0 0 1)"
            ),
        ));
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
    Ok(Isometry3::from_parts(
        Translation3::from(Vector3::new(m[3], m[7], m[11])),
        rotation,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Kalibr camchain of a 752×480 rig, 11 cm baseline, with `edit` applied to its text.
    fn chain(edit: impl Fn(String) -> String) -> String {
        edit(
            "cam0:\n  camera_model: pinhole\n  intrinsics: [458.6, 457.3, 367.2, 248.4]\n  \
             distortion_model: radtan\n  distortion_coeffs: [-0.28, 0.07, 0.0002, 0.00002]\n  \
             resolution: [752, 480]\n  rostopic: /cam0/image_raw\n\
             cam1:\n  T_cn_cnm1:\n  - [1.0, 0.0, 0.0, -0.11]\n  - [0.0, 1.0, 0.0, 0.0]\n  \
             - [0.0, 0.0, 1.0, 0.0]\n  - [0.0, 0.0, 0.0, 1.0]\n  camera_model: pinhole\n  \
             intrinsics: [457.6, 456.1, 379.9, 255.2]\n  distortion_model: radtan\n  \
             distortion_coeffs: [-0.28, 0.07, -0.0001, -0.00003]\n  resolution: [752, 480]\n  \
             cam_overlaps: [0]\n"
                .to_string(),
        )
    }

    fn refusal(text: &str) -> String {
        match read_kalibr(text, Path::new("camchain.yaml")) {
            Ok(c) => panic!("accepted {c:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn kalibr_camchain_gives_both_cameras_with_cam1_to_the_right() {
        let calib = read_kalibr(&chain(|t| t), Path::new("camchain.yaml"))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((calib.left.width, calib.left.height), (752, 480));
        assert_eq!(calib.left.intrinsics, [458.6, 457.3, 367.2, 248.4]);
        assert_eq!(calib.right.distortion, [-0.28, 0.07, -0.0001, -0.00003]);
        // cam1 sits 11 cm along cam0's +x: its origin in the body (cam0) frame.
        let origin = calib.right.body_from_camera.translation.vector;
        assert!(
            (origin - Vector3::new(0.11, 0.0, 0.0)).norm() < 1e-12,
            "{origin}"
        );
        // The rectifier accepts it and finds the baseline.
        let rectifier = linetrack_datasets::Rectifier::new(&calib.left, &calib.right)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!((rectifier.rig().baseline_m - 0.11).abs() < 1e-6);
    }

    #[test]
    fn malformed_camchains_are_refused_naming_the_key() {
        let cases: [(&dyn Fn(String) -> String, &str); 8] = [
            (
                &|t| t.replace("intrinsics: [458.6, ", "intrinsics: [.nan, "),
                "cam0.intrinsics",
            ),
            (
                &|t| t.replace("[-0.28, 0.07, 0.0002, 0.00002]", "[-0.28, 0.07]"),
                "cam0.distortion_coeffs",
            ),
            (
                &|t| {
                    t.replace(
                        "resolution: [752, 480]\n  rostopic",
                        "resolution: [752.5, 480]\n  rostopic",
                    )
                },
                "cam0.resolution",
            ),
            (
                &|t| t.replace("- [0.0, 0.0, 0.0, 1.0]", "- [0.0, 0.0, 0.5, 1.0]"),
                "cam1.T_cn_cnm1",
            ),
            (
                &|t| t.replace("- [1.0, 0.0, 0.0, -0.11]", "- [2.0, 0.0, 0.0, -0.11]"),
                "cam1.T_cn_cnm1",
            ),
            (
                &|t| {
                    t.replacen(
                        "distortion_model: radtan",
                        "distortion_model: equidistant",
                        1,
                    )
                },
                "equidistant",
            ),
            (
                &|t| t.replacen("camera_model: pinhole", "camera_model: omni", 1),
                "omni",
            ),
            (
                &|t| {
                    t.replace(
                        "intrinsics: [457.6, 456.1, 379.9, 255.2]",
                        "intrinsics: [-457.6, 456.1, 379.9, 255.2]",
                    )
                },
                "cam1.intrinsics",
            ),
        ];
        for (edit, key) in cases {
            let err = refusal(&chain(edit));
            assert!(
                err.contains("camchain.yaml") && err.contains(key),
                "{key}: {err}"
            );
        }
        let no_pose = chain(|t| {
            let start = t.find("  T_cn_cnm1").unwrap_or(0);
            let end = t
                .find("  camera_model: pinhole\n  intrinsics: [457")
                .unwrap_or(0);
            format!("{}{}", &t[..start], &t[end..])
        });
        assert!(refusal(&no_pose).contains("T_cn_cnm1"));
        assert!(refusal("cam0: [1, 2]\n").contains("camchain.yaml"));
        assert!(refusal("not: yaml: at: all").contains("camchain.yaml"));
        assert!(refusal("").contains("camchain.yaml"));
    }

    #[test]
    fn a_missing_file_or_an_empty_folder_is_named() {
        let err = read_calibration(Path::new("/nonexistent/camchain.yaml"))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("/nonexistent/camchain.yaml"), "{err}");
        let empty = linetrack_test_data::Scratch::new("camera", "empty");
        let err = read_calibration(empty.path())
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("cam0/sensor.yaml"), "{err}");
    }

    #[test]
    fn real_data_euroc_sensor_yaml_pairs_are_read_from_the_sequence_folder() {
        let dir = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
        let calib = read_calibration(&dir).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((calib.left.width, calib.left.height), (752, 480));
        let rectifier = linetrack_datasets::Rectifier::new(&calib.left, &calib.right)
            .unwrap_or_else(|e| panic!("{e}"));
        // EuRoC's stereo baseline is about 11 cm.
        assert!((rectifier.rig().baseline_m - 0.11).abs() < 0.01);
    }
}
