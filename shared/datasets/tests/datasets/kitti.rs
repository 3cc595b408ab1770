//! The hand-made KITTI odometry fixture, good and malformed.

use super::*;

fn kitti_fixture(name: &str) -> Scratch {
    let root = Scratch::new("datasets", name);
    let dir = root.join("sequences/07");
    let p0 = "P0: 700 0 600 0 0 700 180 0 0 0 1 0\n";
    let p1 = "P1: 700 0 600 -378 0 700 180 0 0 0 1 0\n";
    write(&dir.join("calib.txt"), &format!("{p0}{p1}"));
    write(&dir.join("times.txt"), "0.0\n0.1\n0.2\n");
    for k in 0..3 {
        png(&dir.join(format!("image_0/{k:06}.png")), k as u8);
        png(&dir.join(format!("image_1/{k:06}.png")), k as u8);
    }
    write(
        &root.join("poses/07.txt"),
        "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0.5\n1 0 0 0 0 1 0 0 0 0 1 1.0\n",
    );
    root
}

#[test]
fn kitti_fixture_opens_with_rig_times_and_poses() {
    let root = kitti_fixture("kitti");
    let seq = StereoSequence::open(&root.join("sequences/07")).unwrap();
    assert_eq!(seq.name, "07");
    assert!(!seq.is_rectified_on_load());
    assert_eq!(seq.frames.len(), 3);
    assert!(
        (seq.rig.baseline_m - 0.54).abs() < 1e-12
            && seq.rig.focal_px == 700.0
            && seq.rig.cy_px == 180.0
    );
    assert_eq!(seq.frames[1].timestamp_ns, 100_000_000);
    assert!((seq.frames[2].pose.unwrap().translation.z - 1.0).abs() < 1e-12);
    assert!((seq.rate_hz - 10.0).abs() < 1e-9);
}

#[test]
fn malformed_kitti_files_are_refused_naming_them() {
    let cases = [
        (
            "sequences/07/calib.txt",
            "P0: 700 0 600 0 0 700 180 0 0 0 1 0\n",
            "missing P1",
        ),
        (
            "sequences/07/calib.txt",
            "P0: 700 0 600 0 0 700 180 0 0 0 1\nP1: 1 2\n",
            "calib.txt:1: P0 has 11 values",
        ),
        (
            "sequences/07/times.txt",
            "0.0\n0.2\n0.1\n",
            "times.txt:3: time 0.1 does not increase",
        ),
        (
            "poses/07.txt",
            "1 0 0 0 0 1 0 0 0 0 1 0\n",
            "1 poses for 3 frames",
        ),
    ];
    for (k, (file, text, what)) in cases.into_iter().enumerate() {
        let root = kitti_fixture(&format!("kitti-bad-{k}"));
        write(&root.join(file), text);
        let message = open_error(&root.join("sequences/07"));
        assert!(message.contains(what), "{file}: {message}");
    }
}
