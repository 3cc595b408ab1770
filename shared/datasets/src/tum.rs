//! TUM trajectory files: one pose per line, `timestamp tx ty tz qx qy qz qw` (seconds,
//! metres, unit quaternion), `#` comments.

use crate::{DatasetError, parse_error, read_text};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use std::fmt::Write as _;
use std::path::Path;

/// A pose with its time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StampedPose {
    /// Seconds.
    pub timestamp_s: f64,
    /// The camera's pose in the world (`p_world = pose · p_camera`).
    pub pose: Isometry3<f64>,
}

/// Reads a TUM trajectory; errors name the file and line.
pub fn read(path: &Path) -> Result<Vec<StampedPose>, DatasetError> {
    let text = read_text(path)?;
    let mut poses = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let values: Vec<f64> = line
            .split_whitespace()
            .map(|v| {
                v.parse::<f64>()
                    .map_err(|_| parse_error(path, k + 1, format!("not a number: {v:?}")))
            })
            .collect::<Result<_, _>>()?;
        let [t, tx, ty, tz, qx, qy, qz, qw] = values[..] else {
            return Err(parse_error(
                path,
                k + 1,
                format!(
                    "expected 8 values (t tx ty tz qx qy qz qw), found {}",
                    values.len()
                ),
            ));
        };
        if values.iter().any(|v| !v.is_finite()) {
            return Err(parse_error(path, k + 1, "non-finite value"));
        }
        let q = Quaternion::new(qw, qx, qy, qz);
        if (q.norm() - 1.0).abs() > 1e-3 {
            return Err(parse_error(
                path,
                k + 1,
                format!("quaternion norm {} is not 1", q.norm()),
            ));
        }
        if poses
            .last()
            .is_some_and(|p: &StampedPose| p.timestamp_s >= t)
        {
            return Err(parse_error(
                path,
                k + 1,
                format!("timestamp {t} does not increase"),
            ));
        }
        poses.push(StampedPose {
            timestamp_s: t,
            pose: Isometry3::from_parts(
                Translation3::new(tx, ty, tz),
                UnitQuaternion::from_quaternion(q),
            ),
        });
    }
    Ok(poses)
}

/// The text of a TUM trajectory.
pub fn format(poses: &[StampedPose]) -> String {
    let mut text = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for p in poses {
        let t = p.pose.translation.vector;
        let q = p.pose.rotation.quaternion();
        let _ = writeln!(
            text,
            "{:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}",
            p.timestamp_s, t.x, t.y, t.z, q.i, q.j, q.k, q.w
        );
    }
    text
}

/// Writes a TUM trajectory.
pub fn write(path: &Path, poses: &[StampedPose]) -> Result<(), DatasetError> {
    std::fs::write(path, format(poses)).map_err(|reason| DatasetError::Io {
        path: path.to_path_buf(),
        reason,
    })
}
