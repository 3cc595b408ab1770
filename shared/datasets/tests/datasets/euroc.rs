//! The hand-made EuRoC fixture: calibration and ground truth, rectification, and malformed
//! lists, calibrations and frames.

use super::*;

#[test]
fn euroc_fixture_opens_with_its_calibration_and_ground_truth() {
    let dir = euroc_fixture("good");
    let seq = StereoSequence::open(&dir).unwrap();
    assert_eq!(seq.frames.len(), 3);
    // An ideal rig (no distortion, equal intrinsics, pure x baseline) is used as is.
    assert!(!seq.is_rectified_on_load());
    assert_eq!(
        (seq.rig.focal_px, seq.rig.cx_px, seq.rig.cy_px),
        (50.0, 32.0, 24.0)
    );
    assert!((seq.rig.baseline_m - 0.1).abs() < 1e-12, "{:?}", seq.rig);
    let p = seq.frames[2].pose.unwrap();
    assert!((p.translation.vector - Vector3::new(0.02, 0.0, 0.0)).norm() < 1e-9);
    let frame = seq.load_frame(1).unwrap();
    assert_eq!(
        (frame.left.width(), frame.left.height()),
        (W as i32, H as i32)
    );
}

#[test]
fn a_distorted_fixture_is_rectified_on_load() {
    let dir = euroc_fixture("distorted");
    write(
        &dir.join("mav0/cam1/sensor.yaml"),
        &sensor_yaml(0.1).replace("[0.0, 0.0, 0.0, 0.0]", "[-0.05, 0.01, 0.0, 0.0]"),
    );
    let seq = StereoSequence::open(&dir).unwrap();
    assert!(seq.is_rectified_on_load());
    assert!(
        (seq.rig.baseline_m - 0.1).abs() < 1e-6 && (seq.rig.focal_px - 50.0).abs() < 5.0,
        "{:?}",
        seq.rig
    );
    let frame = seq.load_frame(0).unwrap();
    assert!(
        frame.left.origin().contains("rectified") && frame.right.origin().contains("rectified")
    );
}

#[test]
fn malformed_image_lists_name_file_and_line() {
    let cases = [
        (
            "columns",
            "#timestamp [ns],filename\n1000000000\n",
            "data.csv:2",
            "2 columns",
        ),
        (
            "number",
            "#timestamp [ns],filename\n1000000000,a.png\n10x0,b.png\n",
            "data.csv:3",
            "not a whole number",
        ),
        (
            "order",
            "#timestamp [ns],filename\n1100000000,a.png\n1000000000,b.png\n",
            "data.csv:3",
            "does not increase",
        ),
        (
            "empty",
            "#timestamp [ns],filename\n",
            "data.csv",
            "lists no images",
        ),
    ];
    for (name, csv, place, what) in cases {
        let dir = euroc_fixture(name);
        write(&dir.join("mav0/cam0/data.csv"), csv);
        let text = open_error(&dir);
        assert!(
            text.contains(place) && text.contains(what),
            "{name}: {text}"
        );
    }
}

#[test]
fn malformed_calibration_and_ground_truth_are_refused() {
    let cases: [(&str, &str, String, &str); 5] = [
        (
            "no-intrinsics",
            "mav0/cam1/sensor.yaml",
            sensor_yaml(0.1).replace("intrinsics", "intrinsix"),
            "sensor.yaml:15: missing field `intrinsics`",
        ),
        (
            "bad-number",
            "mav0/cam1/sensor.yaml",
            sensor_yaml(0.1).replace("50.0, 50.0", "50.0, fifty"),
            "sensor.yaml:13",
        ),
        (
            "not-rigid",
            "mav0/cam0/sensor.yaml",
            sensor_yaml(0.0).replace("data: [1.0", "data: [2.0"),
            "T_BS is not a rigid transform",
        ),
        (
            "same-place",
            "mav0/cam1/sensor.yaml",
            sensor_yaml(0.0),
            "no baseline",
        ),
        (
            "gt-quaternion",
            "mav0/state_groundtruth_estimate0/data.csv",
            "1000000000,0,0,0,2,0,0,0\n".to_string(),
            "data.csv:1: quaternion norm",
        ),
    ];
    for (name, file, text, what) in cases {
        let dir = euroc_fixture(name);
        write(&dir.join(file), &text);
        let message = open_error(&dir);
        assert!(message.contains(what), "{name}: {message}");
    }
    let missing = Scratch::new("datasets", "not-a-dataset");
    assert!(open_error(&missing).contains("expected mav0/"));
}

#[test]
fn missing_and_corrupt_frames_are_skipped_counted_and_named() {
    let dir = euroc_fixture("bad-frames");
    std::fs::remove_file(dir.join("mav0/cam1/data/1000000000.png")).unwrap();
    std::fs::write(dir.join("mav0/cam0/data/1100000000.png"), b"not a png").unwrap();
    let seq = StereoSequence::open(&dir).unwrap();
    let mut stream = seq.into_stream(0, 2);
    let results: Vec<_> = stream.by_ref().collect();
    assert_eq!(results.len(), 3);
    let first = results[0].as_ref().unwrap_err().to_string();
    assert!(
        first.contains("frame 0") && first.contains("cam1/data/1000000000.png"),
        "{first}"
    );
    assert_eq!(results[1].as_ref().unwrap().index, 1);
    let third = results[2].as_ref().unwrap_err().to_string();
    assert!(
        third.contains("cam0/data/1100000000.png") && third.contains("not a decodable image"),
        "{third}"
    );
    assert_eq!(stream.skipped(), 2);
}

#[test]
fn a_wrongly_sized_frame_is_skipped_naming_it() {
    let dir = euroc_fixture("wrong-size");
    let path = dir.join("mav0/cam0/data/1050000000.png");
    image::GrayImage::new(32, 24).save(&path).unwrap();
    let seq = StereoSequence::open(&dir).unwrap();
    let error = seq.load_frame(1).unwrap_err().to_string();
    assert!(
        error.contains("1050000000.png") && error.contains("same size"),
        "{error}"
    );
    assert!(seq.load_frame(0).is_ok() && seq.load_frame(2).is_ok());
}
