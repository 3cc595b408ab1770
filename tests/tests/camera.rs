//! The live stereo camera source end to end, without a camera: `linetrack run` on a
//! GStreamer `videotestsrc` pipeline (a side-by-side stereo stream), on numbered copies of
//! the EuRoC excerpt's images read as two devices through OpenCV's `CAP_IMAGES`, on a
//! pipeline that ends (a camera that disappears, reopened), on a device that does not
//! exist, and on frames of the wrong size. Needs GStreamer's base and good plugins
//! (`cargo xtask test` installs them).

use linetrack_e2e::*;
use std::path::{Path, PathBuf};
use std::time::Duration;

const RUN_TIMEOUT: Duration = Duration::from_secs(120);
/// Quick supervision, and every frame processed however late (the drop policy has its own
/// tests): what a frame becomes then depends on the camera source alone.
const QUICK: &str = "[supervisor]\nrestart_backoff_ms = 100\nhang_timeout_ms = 2000\ndrain_timeout_ms = 30000\nstatus_every_ms = 0\n[budget]\ndrop_late = false\n";

/// A Kalibr camchain of an ideal 752×480 rig: focal 400 px, 10 cm baseline, no distortion.
fn camchain(dir: &Path, width: u32) -> PathBuf {
    let path = dir.join("camchain.yaml");
    let cam = |extra: &str| {
        format!(
            "{extra}  camera_model: pinhole\n  intrinsics: [400.0, 400.0, {}.0, 240.0]\n  distortion_model: radtan\n  distortion_coeffs: [0.0, 0.0, 0.0, 0.0]\n  resolution: [{width}, 480]\n",
            width / 2
        )
    };
    let text = format!(
        "cam0:\n{}cam1:\n{}",
        cam(""),
        cam(
            "  T_cn_cnm1:\n  - [1.0, 0.0, 0.0, -0.1]\n  - [0.0, 1.0, 0.0, 0.0]\n  - [0.0, 0.0, 1.0, 0.0]\n  - [0.0, 0.0, 0.0, 1.0]\n"
        )
    );
    std::fs::write(&path, text).unwrap_or_else(|e| panic!("{e}"));
    path
}

/// A side-by-side stereo stream of `frames` frames (0: endless) from GStreamer's test
/// source: the `spokes` pattern in both halves, the right one shifted 8 px (a plane 5 m
/// away for the rig of [`camchain`]), grey, 1504×480.
fn stereo_testsrc(frames: u32, live: bool) -> String {
    let src = |crop: &str| {
        format!(
            "videotestsrc num-buffers={} pattern=spokes is-live={live} ! video/x-raw,width=760,height=480,framerate=20/1 ! videocrop {crop}=8 ! c.",
            if frames == 0 { -1 } else { frames as i64 }
        )
    };
    format!(
        "compositor name=c sink_1::xpos=752 ! video/x-raw,width=1504,height=480 ! videoconvert ! video/x-raw,format=GRAY8 ! appsink {} {}",
        src("right"),
        src("left")
    )
}

/// The `[camera]` section.
fn camera_section(capture: &str, right: &str, calibration: &Path, rest: &str) -> String {
    format!(
        "[camera]\ncapture = {capture:?}\ncapture_right = {right:?}\ncalibration = {:?}\nretry_ms = 200\nretry_max_ms = 400\n{rest}",
        calibration.display().to_string()
    )
}

/// Frame ids 0..n once each, in order, capture markers allowed.
fn assert_ids_accounted(records: &Records, n: u64) {
    linetrack_e2e::assert_ids_accounted(records, n, &["capture-dropped", "capture-late"]);
}

fn outcomes(records: &Records, outcome: &str) -> usize {
    records
        .frames
        .iter()
        .filter(|f| f.outcome == outcome)
        .count()
}

/// Starts `linetrack run` with `extra` config; the sequence the harness writes into
/// `[source]` is not read in camera mode.
fn start_camera(dir: &Path, extra: &str, args: &[&str]) -> Run {
    start_with_args(dir, &dir.join("no-sequence"), extra, args)
}

#[test]
fn a_videotestsrc_stereo_stream_runs_the_pipeline_with_every_frame_accounted() {
    let dir = scratch("camera-testsrc");
    let calibration = camchain(&dir, 752);
    let extra = format!(
        "{QUICK}{}",
        camera_section(&stereo_testsrc(0, false), "", &calibration, "")
    );
    // 30 frame ids at the harness's 10 Hz, then the source stops.
    let run = start_camera(&dir, &extra, &["--frames", "30"]);
    let (status, out, records) = run.finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_ids_accounted(&records, 30);
    // A test source read at 10 Hz loses nothing; the static scene is tracked.
    assert_eq!(outcomes(&records, "capture-dropped"), 0, "{out}");
    assert!(outcomes(&records, "pose") > 0, "nothing tracked:\n{out}");
    assert!(
        records.events_of("camera-lost").is_empty(),
        "{:?}",
        records.events
    );
    assert_eq!(
        records.leftovers,
        Default::default(),
        "iceoryx2 resources left behind"
    );
}

#[test]
fn a_camera_whose_stream_ends_is_reported_reopened_and_the_run_goes_on() {
    let dir = scratch("camera-ends");
    let calibration = camchain(&dir, 752);
    // Each connection delivers 12 frames, then the stream ends (as a camera unplugged).
    let extra = format!(
        "{QUICK}{}",
        camera_section(&stereo_testsrc(12, false), "", &calibration, "")
    );
    let run = start_camera(&dir, &extra, &["--frames", "30"]);
    let (status, out, records) = run.finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_ids_accounted(&records, 30);
    // 30 frames need three connections: lost twice (after 12 and 24), back twice.
    let lost = records.events_of("camera-lost");
    assert!(lost.len() >= 2, "{:?}", records.events);
    for e in &lost {
        assert!(
            e.detail.contains("videotestsrc") && e.detail.contains("read failed"),
            "{e:?}"
        );
    }
    assert_eq!(lost[0].frame_id, Some(12), "{:?}", records.events);
    assert!(
        records.events_of("camera-back").len() >= 2,
        "{:?}",
        records.events
    );
    // Every frame the camera delivered is in the records with its pixels: none dropped.
    assert_eq!(outcomes(&records, "capture-dropped"), 0, "{out}");
    assert!(out.contains("camera lost"), "{out}");
    assert_eq!(
        records.leftovers,
        Default::default(),
        "iceoryx2 resources left behind"
    );
}

#[test]
fn a_missing_device_is_retried_until_the_run_ends_and_the_records_say_so() {
    let dir = scratch("camera-missing");
    let calibration = camchain(&dir, 752);
    let device = "/dev/video-linetrack-e2e-missing";
    let extra = format!(
        "{QUICK}{}",
        camera_section(device, "", &calibration, "duration_s = 2.0\n")
    );
    let run = start_camera(&dir, &extra, &[]);
    let run_dir = run.run_dir.clone();
    let (status, out, records) = run.finish(RUN_TIMEOUT);
    // No frame, so nothing was tracked: the run says so and fails, with its records.
    assert!(!status.success(), "{out}");
    assert!(records.frames.is_empty());
    let lost = records.events_of("camera-lost");
    assert!(lost.len() >= 2, "{:?}", records.events);
    assert!(
        lost.iter()
            .all(|e| e.detail.contains(device) && e.detail.contains("cannot be opened")),
        "{lost:?}"
    );
    let summary = std::fs::read_to_string(run_dir.join("summary.json")).unwrap_or_default();
    assert!(summary.contains("nothing was tracked"), "{summary}");
    assert_eq!(
        records.leftovers,
        Default::default(),
        "iceoryx2 resources left behind"
    );
}

#[test]
fn frames_of_another_size_than_the_calibration_are_refused_before_the_run_starts() {
    let dir = scratch("camera-size");
    let calibration = camchain(&dir, 640);
    let config = dir.join("pipeline.toml");
    let run_dir = dir.join("run");
    std::fs::write(
        &config,
        format!("[output]\nrun_dir = {:?}\n", run_dir.display().to_string()),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let output = std::process::Command::new(bin_dir().join("linetrack"))
        .args(["run", "--quiet", "--config"])
        .arg(&config)
        .args(["--camera", &stereo_testsrc(5, false), "--calibration"])
        .arg(&calibration)
        .env(
            "LINETRACK_IPC_PREFIX",
            format!("lte2e{}_size_", std::process::id()),
        )
        .output()
        .unwrap_or_else(|e| panic!("{e}"));
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{err}");
    // Named: the device, its frames' size, and the size the calibration needs.
    assert!(
        err.contains("GStreamer pipeline") && err.contains("1504×480") && err.contains("1280×480"),
        "{err}"
    );
    // No stage was started.
    assert!(!run_dir.join("frames.csv").is_file());
}

/// Numbered links `dir/left|right/000000.png…` to the first `n` frames of the EuRoC
/// excerpt, for OpenCV's image-sequence reader.
fn numbered_euroc_frames(dir: &Path, n: usize) -> PathBuf {
    let euroc = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
    for (cam, side) in [(0, "left"), (1, "right")] {
        let target = dir.join(side);
        std::fs::create_dir_all(&target).unwrap_or_else(|e| panic!("{e}"));
        let files = images(&euroc, cam);
        assert!(files.len() >= n, "the excerpt has {} frames", files.len());
        for (i, file) in files.iter().take(n).enumerate() {
            std::os::unix::fs::symlink(file, target.join(format!("{i:06}.png")))
                .unwrap_or_else(|e| panic!("{e}"));
        }
    }
    euroc
}

#[test]
fn real_data_euroc_frames_read_as_two_devices_are_all_accounted_for_and_tracked() {
    const FRAMES: usize = 40;
    let dir = scratch("camera-euroc");
    let euroc = numbered_euroc_frames(&dir, FRAMES);
    let capture = |side: &str| dir.join(side).join("%06d.png").display().to_string();
    // The calibration: the data set's own sensor.yaml pair.
    let extra = format!(
        "{QUICK}{}",
        camera_section(&capture("left"), &capture("right"), &euroc, "")
    );
    let run = start_camera(&dir, &extra, &["--frames", &FRAMES.to_string()]);
    let run_dir = run.run_dir.clone();
    let (status, out, records) = run.finish(RUN_TIMEOUT);
    assert!(status.success(), "{status}\n{out}");
    assert_ids_accounted(&records, FRAMES as u64);
    assert_eq!(outcomes(&records, "capture-dropped"), 0, "{out}");
    // Poses come out, one line of poses.tum per frame with a pose. How many depends on the
    // CPU the run gets: a camera does not wait for the pipeline, so under load the line
    // detector's queue overwrites frames (each still accounted for above).
    let with_pose = records.frames.iter().filter(|f| f.has_pose()).count();
    assert!(outcomes(&records, "pose") > 0, "nothing tracked:\n{out}");
    let tum = std::fs::read_to_string(run_dir.join("poses.tum")).unwrap_or_default();
    let lines = tum
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .count();
    assert_eq!(lines, with_pose, "{tum}");
}
