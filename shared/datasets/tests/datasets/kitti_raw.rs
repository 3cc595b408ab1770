//! KITTI raw: the real drive (`real_data_*`) with its OXTS ground truth, and a hand-made
//! drive, good and malformed.

use super::*;

fn kitti_raw() -> StereoSequence {
    let dir = linetrack_test_data::kitti_raw_dir().unwrap_or_else(|e| panic!("{e}"));
    StereoSequence::open(&dir).unwrap()
}

#[test]
fn real_data_kitti_raw_drive_loads_with_rig_times_and_oxts_ground_truth() {
    let seq = kitti_raw();
    assert_eq!(seq.name, "2011_09_26_drive_0001_sync");
    assert_eq!(seq.frames.len(), 108);
    assert!(!seq.is_rectified_on_load());
    let rig = seq.rig;
    assert_eq!((rig.width_px, rig.height_px), (1242, 375));
    assert_eq!(
        (rig.focal_px, rig.cx_px, rig.cy_px),
        (721.5377, 609.5593, 172.854)
    );
    assert!((rig.baseline_m - 0.537).abs() < 0.001, "{rig:?}");
    // 107 intervals of 0.100–0.106 s (README of the drive): 9.69 Hz measured.
    assert!((9.6..10.0).contains(&seq.rate_hz), "{} Hz", seq.rate_hz);
    assert_eq!(seq.frames[0].timestamp_ns, 1_317_042_145_967_790_592);
    assert!(seq.frames.windows(2).all(|w| {
        let dt = w[1].timestamp_ns - w[0].timestamp_ns;
        (95_000_000..110_000_000).contains(&dt)
    }));
    let poses: Vec<Isometry3<f64>> = seq
        .frames
        .iter()
        .map(|f| f.pose.expect("ground truth"))
        .collect();
    // Frame 0 is the world origin, up to rounding.
    assert!(poses[0].translation.vector.norm() < 1e-12 && poses[0].rotation.angle() < 1e-12);
    let path_m: f64 = poses
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum();
    eprintln!(
        "path {path_m:.2} m, last position {:?}",
        poses[107].translation.vector.as_slice()
    );
    assert!((105.0..109.0).contains(&path_m), "path {path_m} m");
    // The car drives forward: the camera's +z.
    assert!(poses[107].translation.z > 100.0, "{}", poses[107]);
    let frame = seq.load_frame(107).unwrap();
    assert_eq!((frame.left.width(), frame.right.height()), (1242, 375));
}

#[test]
fn real_data_kitti_raw_oxts_conversion_agrees_with_the_independent_one() {
    let seq = kitti_raw();
    let dir = linetrack_test_data::kitti_raw_dir().unwrap();
    let reference =
        linetrack_datasets::read_kitti_poses(&dir.join("poses_cam0_rect_from_oxts.txt")).unwrap();
    assert_eq!(reference.len(), seq.frames.len());
    // The reference is at the OXTS fixes' instants; the loader gives the poses at the
    // cameras'. Interpolated here on the reference (position linearly, rotation by slerp),
    // for the frames whose time lies between two fixes, and taken relative to frame 0.
    let clock = |path: &str| -> Vec<f64> {
        std::fs::read_to_string(dir.join(path))
            .unwrap()
            .lines()
            .map(|line| {
                let clock = line.split(' ').nth(1).unwrap();
                let [h, m, s]: [f64; 3] = clock
                    .split(':')
                    .map(|v| v.parse::<f64>().unwrap())
                    .collect::<Vec<_>>()
                    .try_into()
                    .unwrap();
                (h * 60.0 + m) * 60.0 + s
            })
            .collect()
    };
    let (fixes, cameras) = (
        clock("oxts/timestamps.txt"),
        clock("image_00/timestamps.txt"),
    );
    let at = |t: f64| {
        let k = fixes.iter().rposition(|f| *f <= t)?;
        let s = (t - fixes[k]) / (fixes.get(k + 1)? - fixes[k]);
        let (a, b) = (&reference[k], &reference[k + 1]);
        Some(nalgebra::Isometry3::from_parts(
            a.translation.vector.lerp(&b.translation.vector, s).into(),
            a.rotation.slerp(&b.rotation, s),
        ))
    };
    let origin = at(cameras[0]).unwrap_or(reference[0]).inverse();
    let (mut translation_m, mut rotation_deg, mut compared) = (0.0f64, 0.0f64, 0);
    for (frame, t) in seq.frames.iter().zip(&cameras).skip(1) {
        let Some(expected) = at(*t).map(|p| origin * p) else {
            continue;
        };
        let pose = frame.pose.unwrap();
        translation_m =
            translation_m.max((pose.translation.vector - expected.translation.vector).norm());
        rotation_deg = rotation_deg.max(pose.rotation.angle_to(&expected.rotation).to_degrees());
        compared += 1;
    }
    eprintln!(
        "OXTS conversion vs poses_cam0_rect_from_oxts.txt at the camera times, {compared} \
         frames: max {:.4} mm, {:.2e}°",
        translation_m * 1e3,
        rotation_deg
    );
    assert!(compared > 100, "{compared} frames between two fixes");
    // The reference is printed with 10 significant digits (1e-8 m at 107 m) and both are
    // computed in f64 from the same inputs; a millimetre and a thousandth of a degree are
    // far below the OXTS unit's own accuracy (2.7 cm) yet would catch any wrong recipe
    // step (a swapped axis, the latitude scale of each frame instead of the first, a pose
    // taken at the fix's instant instead of the camera's: up to 5 ms, 5 cm here).
    assert!(translation_m < 1e-3, "{translation_m} m");
    assert!(rotation_deg < 1e-3, "{rotation_deg}°");
}

const RAW_DRIVE: &str = "2011_09_26_drive_0001_sync";

fn oxts_line(lon_deg: f64) -> String {
    let mut values = vec![49.0, lon_deg, 100.0, 0.0, 0.0, 0.0];
    values.resize(30, 0.0);
    let text: Vec<String> = values.iter().map(f64::to_string).collect();
    text.join(" ") + "\n"
}

/// A three-frame KITTI raw drive under `<scratch>/2011_09_26/`: identity rotations, the
/// IMU at the camera, the car moving east (its x) by 1e-5° of longitude a frame.
/// Returns the fixture's folder (removed when dropped) and the drive folder in it.
fn kitti_raw_fixture(name: &str) -> (Scratch, PathBuf) {
    let root = Scratch::new("datasets", name);
    let date = root.join("2011_09_26");
    let identity = "1 0 0 0 1 0 0 0 1";
    write(
        &date.join("calib_cam_to_cam.txt"),
        &format!(
            "calib_time: 09-Jan-2012 13:57:47\nR_rect_00: {identity}\nP_rect_00: 700 0 600 0 0 700 180 0 0 0 1 0\nP_rect_01: 700 0 600 -378 0 700 180 0 0 0 1 0\n"
        ),
    );
    for file in ["calib_imu_to_velo.txt", "calib_velo_to_cam.txt"] {
        write(
            &date.join(file),
            &format!("calib_time: 25-May-2012 16:47:16\nR: {identity}\nT: 0 0 0\n"),
        );
    }
    let drive = date.join(RAW_DRIVE);
    let stamps = "2011-09-26 13:02:25.9\n2011-09-26 13:02:26.000000001\n2011-09-26 13:02:26.1\n";
    for camera in ["image_00", "image_01"] {
        write(&drive.join(camera).join("timestamps.txt"), stamps);
        for k in 0..3 {
            png(
                &drive.join(camera).join(format!("data/{k:010}.png")),
                k as u8,
            );
        }
    }
    for k in 0..3 {
        write(
            &drive.join(format!("oxts/data/{k:010}.txt")),
            &oxts_line(8.0 + 1e-5 * k as f64),
        );
    }
    (root, drive)
}

#[test]
fn kitti_raw_fixture_opens_with_rig_times_and_oxts_poses() {
    let (_fixture, drive) = kitti_raw_fixture("kitti-raw");
    let seq = StereoSequence::open(&drive).unwrap();
    assert_eq!(seq.name, RAW_DRIVE);
    assert_eq!(seq.frames.len(), 3);
    assert!((seq.rig.baseline_m - 0.54).abs() < 1e-12 && seq.rig.focal_px == 700.0);
    assert_eq!((seq.rig.width_px, seq.rig.height_px), (W as u32, H as u32));
    assert_eq!(
        seq.frames[1].timestamp_ns - seq.frames[0].timestamp_ns,
        100_000_001
    );
    assert!((seq.rate_hz - 10.0).abs() < 1e-9);
    assert!(seq.frames[2].left.ends_with("image_00/data/0000000002.png"));
    // Mercator x at the first latitude's scale: cos 49° · 1e-5° · π/180 · 6378137 m.
    let step_m = 49f64.to_radians().cos() * 1e-5f64.to_radians() * 6_378_137.0;
    let pose = seq.frames[2].pose.unwrap();
    assert!(
        (pose.translation.vector - Vector3::new(2.0 * step_m, 0.0, 0.0)).norm() < 1e-6,
        "{pose}"
    );
    assert!(pose.rotation.angle() < 1e-12);

    // Without oxts/ there is no ground truth.
    std::fs::remove_dir_all(drive.join("oxts")).unwrap();
    let seq = StereoSequence::open_kitti_raw(&drive).unwrap();
    assert!(seq.frames.iter().all(|f| f.pose.is_none()));
}

#[test]
fn malformed_kitti_raw_files_are_refused_naming_them() {
    let oxts_1 = format!("{RAW_DRIVE}/oxts/data/0000000001.txt");
    let cases = [
        (
            "calib_cam_to_cam.txt".to_string(),
            "R_rect_00: 1 0 0 0 1 0 0 0 1\nP_rect_00: 700 0 600 0 0 700 180 0 0 0 1\n".to_string(),
            "calib_cam_to_cam.txt:2: P_rect_00 has 11 values, expected 12",
        ),
        (
            "calib_cam_to_cam.txt".to_string(),
            "R_rect_00: 1 0 0 0 1 0 0 0 1\nP_rect_00: 700 0 600 0 0 700 180 0 0 0 1 0\n"
                .to_string(),
            "calib_cam_to_cam.txt:0: missing P_rect_01",
        ),
        (
            "calib_velo_to_cam.txt".to_string(),
            "R: 1 0 0 0 1 0 0 0 1\nT: 0 NaN 0\n".to_string(),
            "calib_velo_to_cam.txt:2: not a finite number: \"NaN\"",
        ),
        (
            "calib_imu_to_velo.txt".to_string(),
            "R: 1 0 0 0 2 0 0 0 1\nT: 0 0 0\n".to_string(),
            "calib_imu_to_velo.txt:0: R is not a rotation",
        ),
        (
            format!("{RAW_DRIVE}/image_00/timestamps.txt"),
            "2011-09-26 13:02:25.9\n2011-09-26 13:02:2x.0\n2011-09-26 13:02:26.1\n".to_string(),
            "image_00/timestamps.txt:2: not a time",
        ),
        (
            format!("{RAW_DRIVE}/image_00/timestamps.txt"),
            "2011-09-26 13:02:25.9\n2011-09-26 13:02:25.8\n2011-09-26 13:02:26.1\n".to_string(),
            "image_00/timestamps.txt:2: time 2011-09-26 13:02:25.8 does not increase",
        ),
        (
            format!("{RAW_DRIVE}/image_01/timestamps.txt"),
            "2011-09-26 13:02:25.9\n2011-09-26 13:02:26.0\n".to_string(),
            "image_01/timestamps.txt:0: 2 timestamps for 3",
        ),
        (
            oxts_1.clone(),
            "49 8 100\n".to_string(),
            "0000000001.txt:1: 3 values, expected 30",
        ),
        (
            oxts_1,
            oxts_line(8.0).replacen("49", "95", 1),
            "0000000001.txt:1: latitude 95° out of range",
        ),
    ];
    for (k, (file, text, what)) in cases.into_iter().enumerate() {
        let (_fixture, drive) = kitti_raw_fixture(&format!("kitti-raw-bad-{k}"));
        write(&drive.parent().unwrap().join(&file), &text);
        let message = open_error(&drive);
        assert!(message.contains(what), "{file}: {message}");
    }

    // A frame's image or OXTS file gone: the counts disagree, naming the folder.
    for (k, (file, what)) in [
        (
            "image_01/data/0000000001.png",
            "image_01/data:0: 2 .png files for 3 frames",
        ),
        (
            "oxts/data/0000000002.txt",
            "oxts/data:0: 2 .txt files for 3 frames",
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let (_fixture, drive) = kitti_raw_fixture(&format!("kitti-raw-missing-{k}"));
        std::fs::remove_file(drive.join(file)).unwrap();
        let message = open_error(&drive);
        assert!(message.contains(what), "{file}: {message}");
    }
}
