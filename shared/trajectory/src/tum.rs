//! TUM trajectory files: one pose per line, `timestamp tx ty tz qx qy qz qw` (seconds,
//! metres, unit quaternion), `#` comments.

use crate::TrajectoryError;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use std::fmt::Write as _;
use std::path::Path;

fn parse_error(path: &Path, line: usize, message: impl Into<String>) -> TrajectoryError {
    TrajectoryError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// A pose with its time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StampedPose {
    /// Seconds.
    pub timestamp_s: f64,
    /// The camera's pose in the world (`p_world = pose · p_camera`).
    pub pose: Isometry3<f64>,
}

/// Reads a TUM trajectory; errors name the file and line.
pub fn read(path: &Path) -> Result<Vec<StampedPose>, TrajectoryError> {
    let text = std::fs::read_to_string(path).map_err(|source| TrajectoryError::Io {
        path: path.to_path_buf(),
        source,
    })?;
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
pub fn write(path: &Path, poses: &[StampedPose]) -> Result<(), TrajectoryError> {
    std::fs::write(path, format(poses)).map_err(|source| TrajectoryError::Io {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn tum_round_trip_and_malformed_lines() {
        let dir = linetrack_test_data::Scratch::new("trajectory", "tum");
        let path = dir.join("trajectory.txt");
        let poses = [
            StampedPose {
                timestamp_s: 0.5,
                pose: Isometry3::identity(),
            },
            StampedPose {
                timestamp_s: 0.55,
                pose: Isometry3::from_parts(
                    Translation3::new(1.0, -2.0, 0.25),
                    UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3),
                ),
            },
        ];
        write(&path, &poses).unwrap();
        let back = read(&path).unwrap();
        assert_eq!(back.len(), 2);
        for (a, b) in poses.iter().zip(&back) {
            assert!((a.timestamp_s - b.timestamp_s).abs() < 1e-9);
            assert!((a.pose.translation.vector - b.pose.translation.vector).norm() < 1e-8);
            assert!(a.pose.rotation.angle_to(&b.pose.rotation) < 1e-8);
        }
        for (text, what) in [
            ("0 1 2 3 0 0 0\n", "trajectory.txt:1: expected 8 values"),
            ("# c\n0 1 2 3 0 0 0 x\n", "trajectory.txt:2: not a number"),
            ("0 0 0 0 0 0 0 3\n", "quaternion norm"),
            (
                "1 0 0 0 0 0 0 1\n0.5 0 0 0 0 0 0 1\n",
                "trajectory.txt:2: timestamp 0.5 does not increase",
            ),
        ] {
            std::fs::write(&path, text).unwrap();
            let message = read(&path).unwrap_err().to_string();
            assert!(message.contains(what), "{message}");
        }
        assert!(matches!(
            read(&dir.join("absent.txt")),
            Err(TrajectoryError::Io { .. })
        ));
    }
}
