//! KITTI raw layout: one synchronised, rectified drive.
//!
//! ```text
//! <date>/calib_cam_to_cam.txt      P_rect_00, P_rect_01 (row-major 3×4), R_rect_00 (3×3), …
//! <date>/calib_imu_to_velo.txt     R: (3×3) T: (3): IMU → Velodyne
//! <date>/calib_velo_to_cam.txt     R: T:          Velodyne → camera 0 (unrectified)
//! <date>/<drive>_sync/image_00/timestamps.txt     `2011-09-26 13:02:25.967790592`, one per frame
//! <date>/<drive>_sync/image_00/data/0000000000.png   left (grey, rectified), image_01/ right
//! <date>/<drive>_sync/oxts/data/0000000000.txt    lat lon alt roll pitch yaw … (30 values)
//! ```
//!
//! The images are already rectified: the rig comes straight from P_rect_00 and P_rect_01.
//! Timestamps are nanoseconds since the Unix epoch, the clock text read as UTC (KITTI
//! writes it without a zone; only differences matter).
//!
//! Ground truth, when `oxts/` is there, follows the KITTI devkit: each OXTS fix becomes an
//! IMU pose by a Mercator projection with the scale of the first latitude and the rotation
//! Rz(yaw)·Ry(pitch)·Rx(roll); taken relative to frame 0 and carried into the rectified
//! left camera with `T_rect_imu = R_rect_00 · T_cam0_velo · T_velo_imu`:
//! `pose_k = T_rect_imu · T_imu0⁻¹ · T_imuk · T_rect_imu⁻¹`.
//!
//! The fixes are not taken at the cameras' instants: on drive 0001 the OXTS clock ticks every
//! 0.100 s, the cameras every 0.103 s (median), the two up to 5 ms apart — at 10 m/s, 5 cm,
//! and most steps measured 3 % short. So when `oxts/timestamps.txt` is there, each frame's
//! pose is interpolated between the two fixes around its left image's timestamp (position
//! linearly, rotation by slerp; the first and last fix extend linearly), then taken
//! relative to frame 0's, which is the identity.

use crate::euroc::{isometry_from_rows, sequence_name};
use crate::kitti::{finite_numbers, key_values, rate_hz, read_increasing, rectified_rig};
use crate::{DatasetError, FrameEntry, StereoSequence, parse_error, read_text};
use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion};
use std::path::{Path, PathBuf};

/// Equatorial Earth radius of the devkit's Mercator projection, metres.
const EARTH_RADIUS_M: f64 = 6_378_137.0;
/// Values on an OXTS line (`oxts/dataformat.txt`).
const OXTS_FIELDS: usize = 30;
/// Nanoseconds per second.
const NS_PER_S: u64 = 1_000_000_000;

/// The folder holding the calibration files: the parent of the drive folder.
fn calibration_dir(drive: &Path) -> PathBuf {
    match (drive.parent(), drive.file_name()) {
        (Some(parent), Some(_)) if !parent.as_os_str().is_empty() => parent.to_path_buf(),
        _ => drive.join(".."),
    }
}

/// Whether `dir` looks like a KITTI raw drive folder (`image_00/` and
/// `../calib_cam_to_cam.txt`).
pub(crate) fn is_kitti_raw(dir: &Path) -> bool {
    dir.join("image_00").is_dir() && calibration_dir(dir).join("calib_cam_to_cam.txt").is_file()
}

/// The `R:` and `T:` of a KITTI raw rigid-transform file, as the transform they describe.
fn read_transform(path: &Path) -> Result<Isometry3<f64>, DatasetError> {
    let text = read_text(path)?;
    let r = key_values::<9>(&text, path, "R")?;
    let t = key_values::<3>(&text, path, "T")?;
    let rows = [
        r[0], r[1], r[2], t[0], r[3], r[4], r[5], t[1], r[6], r[7], r[8], t[2], 0.0, 0.0, 0.0, 1.0,
    ];
    isometry_from_rows(&rows).ok_or_else(|| parse_error(path, 0, "R is not a rotation"))
}

/// All digits, at least one.
fn digits(text: &str) -> Option<u64> {
    if text.is_empty() || !text.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    text.parse().ok()
}

/// Days from 1970-01-01 to a proleptic Gregorian date (`month` 1..=12, `day` checked).
fn days_since_epoch(year: u64, month: u64, day: u64) -> Option<u64> {
    let leap = year.is_multiple_of(4) && (!year.is_multiple_of(100) || year.is_multiple_of(400));
    let month_days = [
        31,
        if leap { 29 } else { 28 },
        31,
        30,
        31,
        30,
        31,
        31,
        30,
        31,
        30,
        31,
    ];
    let days_in_month = *month_days.get(usize::try_from(month).ok()?.checked_sub(1)?)?;
    if !(1970..=9999).contains(&year) || !(1..=days_in_month).contains(&day) {
        return None;
    }
    // Count from 0000-03-01 so the leap day ends the year (civil-from-days, inverted).
    let (y, m) = if month <= 2 {
        (year - 1, month + 9)
    } else {
        (year, month - 3)
    };
    let day_of_year = (153 * m + 2) / 5 + day - 1;
    let days = y * 365 + y / 4 - y / 100 + y / 400 + day_of_year;
    // 1970-01-01 is day 719 468 counted that way.
    days.checked_sub(719_468)
}

/// `YYYY-MM-DD hh:mm:ss[.fraction]` (up to 9 fraction digits) as nanoseconds since the Unix
/// epoch, the clock read as UTC; `None` for anything else or a time out of range.
fn parse_clock_ns(text: &str) -> Option<u64> {
    let (date, clock) = text.split_once(' ')?;
    let date: Vec<&str> = date.split('-').collect();
    let clock: Vec<&str> = clock.trim_start().split(':').collect();
    let ([year, month, day], [hour, minute, second]) = (date.as_slice(), clock.as_slice()) else {
        return None;
    };
    let (whole, fraction) = second.split_once('.').unwrap_or((second, "0"));
    if fraction.len() > 9 {
        return None;
    }
    let fraction_ns = digits(fraction)? * 10u64.pow(9 - fraction.len() as u32);
    let (hour, minute, whole) = (digits(hour)?, digits(minute)?, digits(whole)?);
    if hour >= 24 || minute >= 60 || whole >= 60 {
        return None;
    }
    let days = days_since_epoch(digits(year)?, digits(month)?, digits(day)?)?;
    let seconds = ((days * 24 + hour) * 60 + minute) * 60 + whole;
    // u64 nanoseconds end in the year 2554.
    seconds.checked_mul(NS_PER_S)?.checked_add(fraction_ns)
}

/// Timestamps (ns) of one camera: `<camera>/timestamps.txt`.
fn read_timestamps(camera: &Path) -> Result<Vec<u64>, DatasetError> {
    read_increasing(
        &camera.join("timestamps.txt"),
        "a time `YYYY-MM-DD hh:mm:ss.fraction`",
        parse_clock_ns,
    )
}

/// Number of files named `*.<extension>` in `dir`.
fn count_files(dir: &Path, extension: &str) -> Result<usize, DatasetError> {
    let io = |reason| DatasetError::Io {
        path: dir.to_path_buf(),
        reason,
    };
    let mut count = 0;
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        if path.extension().is_some_and(|e| e == extension) {
            count += 1;
        }
    }
    Ok(count)
}

/// Fails, naming `dir`, unless it holds `expected` `*.<extension>` files.
fn check_count(
    dir: &Path,
    extension: &str,
    expected: usize,
    listed_in: &Path,
) -> Result<(), DatasetError> {
    let found = count_files(dir, extension)?;
    if found == expected {
        Ok(())
    } else {
        Err(parse_error(
            dir,
            0,
            format!(
                "{found} .{extension} files for {expected} frames in {}",
                listed_in.display()
            ),
        ))
    }
}

/// One OXTS fix: position (degrees, metres) and attitude (radians).
#[derive(Debug, Clone, Copy)]
struct OxtsFix {
    lat_deg: f64,
    lon_deg: f64,
    alt_m: f64,
    roll_rad: f64,
    pitch_rad: f64,
    yaw_rad: f64,
}

fn read_oxts_fix(path: &Path) -> Result<OxtsFix, DatasetError> {
    let text = read_text(path)?;
    let (k, line) = text
        .lines()
        .enumerate()
        .find(|(_, l)| !l.trim().is_empty())
        .ok_or_else(|| parse_error(path, 0, "empty OXTS file"))?;
    let v = finite_numbers(line, path, k + 1)?;
    if v.len() != OXTS_FIELDS {
        return Err(parse_error(
            path,
            k + 1,
            format!(
                "{} values, expected {OXTS_FIELDS} (oxts/dataformat.txt)",
                v.len()
            ),
        ));
    }
    if !(v[0].abs() < 90.0) {
        return Err(parse_error(
            path,
            k + 1,
            format!("latitude {}° out of range", v[0]),
        ));
    }
    Ok(OxtsFix {
        lat_deg: v[0],
        lon_deg: v[1],
        alt_m: v[2],
        roll_rad: v[3],
        pitch_rad: v[4],
        yaw_rad: v[5],
    })
}

/// The IMU pose of `fix` in the devkit's Mercator world, `scale` = cos(first latitude).
fn imu_pose(fix: &OxtsFix, scale: f64) -> Isometry3<f64> {
    let x = scale * fix.lon_deg.to_radians() * EARTH_RADIUS_M;
    let y = scale * EARTH_RADIUS_M * ((90.0 + fix.lat_deg).to_radians() / 2.0).tan().ln();
    // from_euler_angles(roll, pitch, yaw) = Rz(yaw)·Ry(pitch)·Rx(roll).
    let rotation = Rotation3::from_euler_angles(fix.roll_rad, fix.pitch_rad, fix.yaw_rad);
    Isometry3::from_parts(
        Translation3::new(x, y, fix.alt_m),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
}

/// Ground-truth poses of the rectified left camera, frame 0 = identity, from
/// `<drive>/oxts/data/*.txt` and the calibration in `calib_dir`.
fn read_ground_truth(
    drive: &Path,
    calib_dir: &Path,
    rect_00: &[f64; 9],
    frames: usize,
    listed_in: &Path,
) -> Result<Vec<Isometry3<f64>>, DatasetError> {
    let data = drive.join("oxts/data");
    check_count(&data, "txt", frames, listed_in)?;
    let velo_from_imu = read_transform(&calib_dir.join("calib_imu_to_velo.txt"))?;
    let cam0_from_velo = read_transform(&calib_dir.join("calib_velo_to_cam.txt"))?;
    let r = rect_00;
    let rect_rows = [
        r[0], r[1], r[2], 0.0, r[3], r[4], r[5], 0.0, r[6], r[7], r[8], 0.0, 0.0, 0.0, 0.0, 1.0,
    ];
    let rect_from_cam0 = isometry_from_rows(&rect_rows).ok_or_else(|| {
        parse_error(
            &calib_dir.join("calib_cam_to_cam.txt"),
            0,
            "R_rect_00 is not a rotation",
        )
    })?;
    let rect_from_imu = rect_from_cam0 * cam0_from_velo * velo_from_imu;
    let imu_from_rect = rect_from_imu.inverse();
    let mut poses = Vec::with_capacity(frames);
    let mut first: Option<(f64, Isometry3<f64>)> = None;
    // Poses relative to the first fix; `at_camera_times` re-anchors on frame 0.
    for k in 0..frames {
        let path = data.join(format!("{k:010}.txt"));
        let fix = read_oxts_fix(&path)?;
        let (scale, world_from_imu0) = *first.get_or_insert_with(|| {
            let scale = fix.lat_deg.to_radians().cos();
            (scale, imu_pose(&fix, scale))
        });
        let imu0_from_imu = world_from_imu0.inverse() * imu_pose(&fix, scale);
        let pose = rect_from_imu * imu0_from_imu * imu_from_rect;
        if !(pose.translation.vector.iter().all(|v| v.is_finite())
            && pose.rotation.coords.iter().all(|v| v.is_finite()))
        {
            return Err(parse_error(&path, 0, "gives a non-finite pose"));
        }
        poses.push(pose);
    }
    Ok(poses)
}

/// Poses at `times` (ns) from poses `at` fix times `fix_times` (increasing, as many as
/// poses, at least two): linear in position and slerp in rotation between the two fixes
/// around each time, extended linearly from the end pairs; then relative to the first.
fn at_camera_times(fix_times: &[u64], at: &[Isometry3<f64>], times: &[u64]) -> Vec<Isometry3<f64>> {
    let interpolated: Vec<Isometry3<f64>> = times
        .iter()
        .map(|&t| {
            let after = fix_times
                .partition_point(|&f| f <= t)
                .clamp(1, fix_times.len() - 1);
            let (t0, t1) = (fix_times[after - 1] as f64, fix_times[after] as f64);
            let s = (t as f64 - t0) / (t1 - t0);
            let (a, b) = (&at[after - 1], &at[after]);
            // Slerp does not extend past [0, 1]: beyond the last pair, the relative
            // rotation is scaled instead (the same curve).
            let rotation = a.rotation
                * UnitQuaternion::from_scaled_axis(
                    (a.rotation.inverse() * b.rotation).scaled_axis() * s,
                );
            let translation = a.translation.vector.lerp(&b.translation.vector, s);
            Isometry3::from_parts(Translation3::from(translation), rotation)
        })
        .collect();
    let origin_inverse = interpolated[0].inverse();
    interpolated.iter().map(|p| origin_inverse * p).collect()
}

impl StereoSequence {
    /// Opens a KITTI raw drive folder (`…/<date>/<date>_drive_NNNN_sync`, holding
    /// `image_00/`, `image_01/` and optionally `oxts/`); the calibration files are read
    /// from its parent. Ground truth comes from `oxts/` when it exists, else poses are
    /// `None`.
    pub fn open_kitti_raw(dir: &Path) -> Result<Self, DatasetError> {
        let calib_dir = calibration_dir(dir);
        let calib_path = calib_dir.join("calib_cam_to_cam.txt");
        let calib = read_text(&calib_path)?;
        let p0 = key_values::<12>(&calib, &calib_path, "P_rect_00")?;
        let p1 = key_values::<12>(&calib, &calib_path, "P_rect_01")?;
        let rect_00 = key_values::<9>(&calib, &calib_path, "R_rect_00")?;
        let (left_dir, right_dir) = (dir.join("image_00"), dir.join("image_01"));
        let times = read_timestamps(&left_dir)?;
        let right_times = read_timestamps(&right_dir)?;
        let left_list = left_dir.join("timestamps.txt");
        if right_times.len() != times.len() {
            return Err(parse_error(
                &right_dir.join("timestamps.txt"),
                0,
                format!(
                    "{} timestamps for {} in {}",
                    right_times.len(),
                    times.len(),
                    left_list.display()
                ),
            ));
        }
        check_count(&left_dir.join("data"), "png", times.len(), &left_list)?;
        check_count(&right_dir.join("data"), "png", times.len(), &left_list)?;
        let image = |side: &Path, k: usize| side.join("data").join(format!("{k:010}.png"));
        let rig = rectified_rig(
            &p0,
            &p1,
            ("P_rect_00", "P_rect_01"),
            &calib_path,
            &image(&left_dir, 0),
        )?;
        let ground_truth = if dir.join("oxts").is_dir() {
            let at_fixes = read_ground_truth(dir, &calib_dir, &rect_00, times.len(), &left_list)?;
            let fix_list = dir.join("oxts/timestamps.txt");
            Some(if fix_list.is_file() && times.len() >= 2 {
                let fix_times = read_timestamps(&dir.join("oxts"))?;
                if fix_times.len() != times.len() {
                    return Err(parse_error(
                        &fix_list,
                        0,
                        format!(
                            "{} timestamps for {} in {}",
                            fix_times.len(),
                            times.len(),
                            left_list.display()
                        ),
                    ));
                }
                at_camera_times(&fix_times, &at_fixes, &times)
            } else {
                at_fixes
            })
        } else {
            None
        };
        let frames = times
            .iter()
            .enumerate()
            .map(|(k, t)| FrameEntry {
                index: k,
                timestamp_ns: *t,
                left: image(&left_dir, k),
                right: image(&right_dir, k),
                pose: ground_truth.as_ref().map(|g| g[k]),
            })
            .collect();
        let seconds = |t: u64| (t - times[0]) as f64 / NS_PER_S as f64;
        let rate_hz = rate_hz(0.0, seconds(times[times.len() - 1]), times.len());
        Ok(StereoSequence::new(
            sequence_name(dir),
            frames,
            rig,
            None,
            rate_hz,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_text_reads_as_utc_nanoseconds() {
        assert_eq!(parse_clock_ns("1970-01-01 00:00:00"), Some(0));
        assert_eq!(
            parse_clock_ns("1970-01-02 00:00:01.5"),
            Some(86_401_500_000_000)
        );
        // 2011-09-26 13:02:25 UTC is 1317042145 s after the epoch.
        assert_eq!(
            parse_clock_ns("2011-09-26 13:02:25.967790592"),
            Some(1_317_042_145_967_790_592)
        );
        assert_eq!(
            parse_clock_ns("2000-02-29 00:00:00"),
            Some(951_782_400 * NS_PER_S)
        );
        for bad in [
            "2011-09-26",
            "2011-09-26 13:02",
            "2011-02-29 00:00:00",
            "2011-13-01 00:00:00",
            "2011-09-26 24:00:00",
            "2011-09-26 13:02:25.1234567890",
            "2011-09-26 13:02:+5",
            "1969-12-31 23:59:59",
            "2011-09-26T13:02:25",
            "9999-12-31 23:59:59",
        ] {
            assert_eq!(parse_clock_ns(bad), None, "{bad}");
        }
    }

    #[test]
    fn poses_are_interpolated_at_the_camera_times_and_start_at_the_identity() {
        // Constant velocity (1 m/s along x) and yaw rate (0.1 rad/s): fixes at 0, 0.1, 0.2 s.
        let truth = |t_s: f64| {
            Isometry3::from_parts(
                Translation3::new(t_s, 0.0, 0.0),
                UnitQuaternion::from_scaled_axis(nalgebra::Vector3::z() * 0.1 * t_s),
            )
        };
        let ns = |t_s: f64| (t_s * 1e9).round() as u64;
        let fixes = [0.0, 0.1, 0.2];
        let poses: Vec<_> = fixes.iter().map(|t| truth(*t)).collect();
        let fix_times: Vec<u64> = fixes.iter().map(|t| ns(*t)).collect();
        // Between fixes, and past the last one (extended).
        let cameras = [0.03, 0.08, 0.16, 0.25];
        let got = at_camera_times(&fix_times, &poses, &cameras.map(ns));
        let origin = truth(cameras[0]).inverse();
        for (pose, t) in got.iter().zip(cameras) {
            let expected = origin * truth(t);
            assert!(
                (pose.translation.vector - expected.translation.vector).norm() < 1e-9,
                "{t}: {pose} vs {expected}"
            );
            assert!(pose.rotation.angle_to(&expected.rotation) < 1e-9, "{t}");
        }
        assert!(got[0].translation.vector.norm() < 1e-12 && got[0].rotation.angle() < 1e-12);
    }

    #[test]
    fn the_first_fix_is_the_mercator_origin_scaled_by_its_latitude() {
        let fix = OxtsFix {
            lat_deg: 0.0,
            lon_deg: 1.0,
            alt_m: 5.0,
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: std::f64::consts::FRAC_PI_2,
        };
        let pose = imu_pose(&fix, 1.0);
        let metres_per_degree = EARTH_RADIUS_M * std::f64::consts::PI / 180.0;
        assert!((pose.translation.x - metres_per_degree).abs() < 1e-6);
        assert!(pose.translation.y.abs() < 1e-6 && pose.translation.z == 5.0);
        // Yaw turns the IMU's x (forward) to the world's y (north).
        let forward = pose.rotation * nalgebra::Vector3::x();
        assert!((forward - nalgebra::Vector3::y()).norm() < 1e-12);
    }
}
