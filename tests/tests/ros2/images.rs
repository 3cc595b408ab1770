//! Frames from ROS 2 image topics (`linetrack run --ros2-images LEFT RIGHT`, the
//! `linetrack-ros2-source` process) fed by an independent DDS peer: a Cyclone DDS stereo
//! camera (`tests/ros2/publish.py`) publishing the EuRoC excerpt's 95 rectified pairs as
//! `sensor_msgs/Image` + `sensor_msgs/CameraInfo` with their stamps, a few as rgb8, bgr8 and
//! mono16, and, midway, two unpaired images and three pairs with a malformed image. It waits
//! for each pair's `Odometry` before the next, so no frame's fate depends on scheduling.

use super::{Listener, Stamped, assert_matches, from_json, peer_python, tum};
use linetrack_e2e::*;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The excerpt's stereo pairs.
const PAIRS: usize = 95;
/// Frame ids of the ROS run: the pairs, two unpaired images, three malformed pairs.
const IDS: usize = PAIRS + 2 + 3;
/// The pair after which the peer injects what must not become a pose.
const INJECT_AFTER: usize = 40;
const RUN_TIMEOUT: Duration = Duration::from_secs(400);
/// The front end of both runs: the shipped defaults (a few tens of ms a frame; LSD and
/// LBD take up to 0.6 s on the loaded test machine).
const FRONT_END: [&str; 4] = ["--detector", "edgelines", "--matcher", "l1"];
/// The dataset run's pace: the stages hold 11 frames, so it loses none unless they fall
/// 5.5 s behind.
const DATASET_RATE_HZ: f64 = 2.0;
/// Nothing depends on time: every frame processed however late, the matcher switched on
/// match counts only, the detector never swapped (the test config's LSD, no fallback).
const DETERMINISTIC: &str =
    "[budget]\ndrop_late = false\n[matcher.fallback]\nover_budget = false\nend_to_end = false\n";

/// The excerpt rectified as a dataset run reads it, written for the peer into `dir`:
/// `frames.json` (size, rig, stamps) and the frames' pixels in `left.raw` and `right.raw`.
/// Returns the stamps.
fn rectified_frames(euroc: &Path, dir: &Path) -> Vec<u64> {
    let sequence = linetrack_datasets::StereoSequence::open(euroc)
        .unwrap_or_else(|e| panic!("{}: {e}", euroc.display()));
    assert_eq!(sequence.frames.len(), PAIRS, "{}", euroc.display());
    let (mut left, mut right, mut stamps) = (Vec::new(), Vec::new(), Vec::new());
    for index in 0..PAIRS {
        let frame = sequence
            .load_frame(index)
            .unwrap_or_else(|e| panic!("frame {index}: {e:?}"));
        let (Some(l), Some(r)) = (frame.left.pixels(), frame.right.pixels()) else {
            panic!("frame {index}: rectified images not continuous in memory");
        };
        left.extend_from_slice(l);
        right.extend_from_slice(r);
        stamps.push(frame.timestamp_ns);
    }
    let rig = sequence.rig;
    assert_eq!(
        left.len(),
        PAIRS * (rig.width_px * rig.height_px) as usize,
        "continuous rectified frames"
    );
    let write = |name: &str, bytes: &[u8]| {
        std::fs::write(dir.join(name), bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
    };
    write("left.raw", &left);
    write("right.raw", &right);
    let meta = serde_json::json!({
        "width": rig.width_px, "height": rig.height_px,
        "fx": rig.focal_px, "cx": rig.cx_px, "cy": rig.cy_px, "baseline_m": rig.baseline_m,
        "stamps_ns": stamps, "left": "left.raw", "right": "right.raw",
    });
    write("frames.json", meta.to_string().as_bytes());
    stamps
}

/// The excerpt's dataset run in `dir` with [`DETERMINISTIC`], paced at [`DATASET_RATE_HZ`]
/// (a source at full speed overruns the stages' queues): its `poses.tum` and records.
fn dataset_run(dir: &Path, euroc: &Path) -> (Vec<Stamped>, Records) {
    std::fs::create_dir_all(dir).unwrap_or_else(|e| panic!("{e}"));
    let run_dir = dir.join("run");
    let config = write_config_for(dir, euroc, DETERMINISTIC, &run_dir);
    let text = std::fs::read_to_string(&config).unwrap_or_else(|e| panic!("{e}"));
    let paced = text.replace("rate_hz = 10.0", &format!("rate_hz = {DATASET_RATE_HZ:?}"));
    assert_ne!(paced, text, "the test config's rate_hz");
    std::fs::write(&config, paced).unwrap_or_else(|e| panic!("{e}"));
    let prefix = format!("lte2e{}_rosdataset_", std::process::id());
    let out = Command::new(bin_dir().join("linetrack"))
        .args(["run", "--quiet", "--pacing", "realtime"])
        .args(FRONT_END)
        .arg("--config")
        .arg(&config)
        .env(linetrack_ipc::Scope::PREFIX_VAR, &prefix)
        .stdin(Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("starting linetrack: {e}"));
    assert!(
        out.status.success(),
        "the dataset run failed: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    (tum(&run_dir), Records::read(&run_dir, &prefix))
}

/// `poses.tum` by stamp.
fn by_stamp(poses: &[Stamped]) -> BTreeMap<i128, Stamped> {
    poses.iter().map(|p| (p.ns, *p)).collect()
}

#[test]
fn real_data_euroc_pairs_from_a_cyclone_dds_camera_give_the_dataset_runs_poses() {
    let euroc = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
    let dir = scratch("ros2-images");
    let frames_dir = dir.join("frames");
    std::fs::create_dir_all(&frames_dir).unwrap_or_else(|e| panic!("{e}"));
    let stamps = rectified_frames(&euroc, &frames_dir);

    // The dataset run: the excerpt read and rectified from its files.
    let (expected, dataset_records) = dataset_run(&dir.join("dataset"), &euroc);
    assert_ids_accounted(&dataset_records, PAIRS as u64, &[]);
    assert_eq!(
        expected.len(),
        PAIRS,
        "a pose for every pair of the dataset run"
    );

    // The ROS run: the same configuration, frames from the peer's topics.
    let ros_dir = dir.join("ros");
    std::fs::create_dir_all(&ros_dir).unwrap_or_else(|e| panic!("{e}"));
    let domain = 1 + ((std::process::id() + 117) % 232) as u16;
    let listener = Listener::start(&ros_dir, domain);
    let extra = format!(
        "{DETERMINISTIC}[supervisor]\nstatus_every_ms = 0\n\
         [ros2]\nenabled = true\ndomain_id = {domain}\nlocalhost_only = true\nframe_id = \"map\"\n\
         convention = \"camera\"\npublish_lost = true\ntf = true\n"
    );
    let ids = IDS.to_string();
    let run = start_logging(
        &ros_dir,
        &euroc,
        &extra,
        &[
            &FRONT_END[..],
            &[
                "--ros2-images",
                "/stereo/left/image_rect",
                "/stereo/right/image_rect",
                "--frames",
                &ids,
            ],
        ]
        .concat(),
    );
    let ros_run_dir = run.run_dir.clone();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("ros2/publish.py");
    let published = ros_dir.join("published.jsonl");
    let mut camera = Command::new(peer_python())
        .arg(&script)
        .args(["--domain", &domain.to_string()])
        .args(["--inject-after", &INJECT_AFTER.to_string()])
        .arg("--frames")
        .arg(&frames_dir)
        .arg("--out")
        .arg(&published)
        .stdin(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("starting {}: {e}", script.display()));
    // The camera ends after the last pair's Odometry; when it fails, the run has no more
    // frames to wait for.
    let mut run = run;
    let deadline = Instant::now() + RUN_TIMEOUT;
    let camera_status = loop {
        if let Some(status) = camera.try_wait().unwrap_or_else(|e| panic!("{e}")) {
            break status;
        }
        if Instant::now() > deadline {
            let _ = camera.kill();
            let _ = run.child.kill();
            panic!("the DDS camera did not finish within {RUN_TIMEOUT:?}");
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    if !camera_status.success() {
        let _ = run.child.kill();
    }
    let (status, out, records) = run.finish(RUN_TIMEOUT);
    let stderr = std::fs::read_to_string(ros_dir.join("stderr.log")).unwrap_or_default();
    assert!(
        camera_status.success(),
        "the DDS camera: {camera_status} (see {}); the run's stderr:\n{stderr}",
        published.display()
    );
    assert!(
        status.success(),
        "the ROS run failed: {status}\n{out}\n{stderr}"
    );

    // Every id has its outcome: the two unpaired images capture-dropped, the three
    // malformed pairs corrupt, every pair a pose.
    assert_ids_accounted(&records, IDS as u64, &["capture-dropped"]);
    let outcomes = |outcome: &str| -> Vec<u64> {
        records
            .frames
            .iter()
            .filter(|f| f.outcome == outcome)
            .map(|f| f.frame_id)
            .collect()
    };
    let first_injected = INJECT_AFTER as u64 + 1;
    assert_eq!(
        outcomes("capture-dropped"),
        [first_injected, first_injected + 1]
    );
    assert_eq!(
        outcomes("corrupt"),
        [first_injected + 2, first_injected + 3, first_injected + 4]
    );
    // ... named in warnings: the topic, the stamp, what is wrong.
    let injected_ns = stamps[INJECT_AFTER];
    let ms = 1_000_000;
    for (topic, ns, says) in [
        ("left", injected_ns + ms, "has no partner"),
        ("right", injected_ns + 2 * ms, "has no partner"),
        (
            "left",
            injected_ns + 3 * ms,
            "encoding \"yuv422\" is not read",
        ),
        (
            "left",
            injected_ns + 4 * ms,
            "640×480 pixels where the CameraInfo says 752×480",
        ),
        (
            "left",
            injected_ns + 5 * ms,
            "step 751 bytes is shorter than a row of 752 mono8 pixels",
        ),
    ] {
        let line = format!("/stereo/{topic}/image_rect image at {ns} ns");
        assert!(
            stderr
                .lines()
                .any(|l| l.contains(&line) && l.contains(says)),
            "no warning {line:?} … {says:?} in:\n{stderr}"
        );
    }

    // The poses: the dataset run's, stamp for stamp (the images' stamps end to end).
    let got = tum(&ros_run_dir);
    let (got, expected_by_stamp) = (by_stamp(&got), by_stamp(&expected));
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        expected_by_stamp.keys().collect::<Vec<_>>(),
        "the same frames got poses, with the images' stamps"
    );
    let mut largest = 0.0f64;
    for (ns, a) in &got {
        let b = &expected_by_stamp[ns];
        for (x, y) in a
            .position
            .iter()
            .zip(b.position)
            .chain(a.orientation.iter().zip(b.orientation))
        {
            largest = largest.max((x - y).abs());
        }
    }
    eprintln!(
        "ROS images: {} poses, largest difference of a poses.tum value from the dataset run {largest:e}",
        got.len()
    );
    assert!(largest <= 1e-6, "poses differ by {largest}");

    // Odometry and /tf of every pair at the pair's stamp, the dataset run's pose.
    let deadline = Instant::now() + Duration::from_secs(30);
    let received = loop {
        let received = listener.received();
        let count = |topic: &str| received.iter().filter(|m| m["topic"] == topic).count();
        if (count("odom") >= PAIRS && count("tf") >= PAIRS) || Instant::now() > deadline {
            break received;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let odometry: Vec<Stamped> = received
        .iter()
        .filter(|m| m["topic"] == "odom")
        .map(from_json)
        .collect();
    let transforms: Vec<Stamped> = received
        .iter()
        .filter(|m| m["topic"] == "tf")
        .flat_map(|t| t["transforms"].as_array().cloned().unwrap_or_default())
        .map(|t| from_json(&t))
        .collect();
    for (what, messages) in [("Odometry", &odometry), ("/tf", &transforms)] {
        for ns in &stamps {
            let m = messages
                .iter()
                .find(|m| m.ns == i128::from(*ns))
                .unwrap_or_else(|| panic!("no {what} stamped {ns} ({} received)", messages.len()));
            assert_matches(what, m, &expected);
        }
        assert_eq!(
            messages.len(),
            PAIRS,
            "{what}: one per pair, none for the rest"
        );
    }
    assert_eq!(
        records.leftovers,
        Default::default(),
        "iceoryx2 nodes or services left behind"
    );
}

#[test]
fn frames_from_ros2_topics_in_single_process_mode_are_refused_before_any_stage_starts() {
    let dir = scratch("ros2-images-threads");
    let euroc = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
    let run = start_logging(
        &dir,
        &euroc,
        "",
        &["--single-process", "--ros2-images", "/l/image", "/r/image"],
    );
    let run_dir = run.run_dir.clone();
    let mut child = run.child;
    let status = child.wait().unwrap_or_else(|e| panic!("{e}"));
    let stderr = std::fs::read_to_string(dir.join("stderr.log")).unwrap_or_default();
    assert!(!status.success(), "{stderr}");
    assert!(
        stderr.contains("camera.ros2_images")
            && stderr.contains("linetrack-ros2-source")
            && stderr.contains("without --single-process"),
        "{stderr}"
    );
    assert!(
        !run_dir.join("frames.csv").is_file()
            || std::fs::read_to_string(run_dir.join("frames.csv"))
                .unwrap_or_default()
                .lines()
                .count()
                <= 1,
        "no frame was processed"
    );
}

#[test]
fn a_ros2_image_source_without_images_waits_and_stops_cleanly_with_the_run() {
    let dir = scratch("ros2-images-idle");
    let euroc = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
    // A domain nobody publishes on: the source is ready and waits for the CameraInfo.
    let domain = 1 + ((std::process::id() + 61) % 232) as u16;
    let extra = format!(
        "[supervisor]\nstatus_every_ms = 0\n[ros2]\ndomain_id = {domain}\nlocalhost_only = true\n"
    );
    let mut run = start_logging(
        &dir,
        &euroc,
        &extra,
        &["--ros2-images", "/idle/left/image", "/idle/right/image"],
    );
    let status = run.wait_for("the ROS 2 image source ready", RUN_TIMEOUT, |s| {
        s.stages
            .iter()
            .any(|st| st.stage == "frame-source" && st.ready)
    });
    // It stays, beating: the supervisor neither restarts it (silent past its 3 s
    // hang_timeout_ms it would) nor ends the run.
    std::thread::sleep(Duration::from_secs(5));
    let source = |s: &linetrack_supervisor::LiveStatus| {
        s.stages
            .iter()
            .find(|st| st.stage == "frame-source")
            .map(|st| st.pid)
    };
    let later = run.status().unwrap_or_else(|| panic!("no status"));
    assert_eq!(source(&later), source(&status), "the source was restarted");
    assert_eq!(later.frames, 0);
    signal(status.supervisor_pid, "TERM");
    let (exit, out, records) = run.finish(RUN_TIMEOUT);
    let stderr = std::fs::read_to_string(dir.join("stderr.log")).unwrap_or_default();
    assert!(exit.success(), "{exit}\n{out}\n{stderr}");
    assert!(out.contains("(interrupted)"), "{out}");
    assert!(records.frames.is_empty());
    assert!(
        ["crash", "hang", "restart"]
            .iter()
            .all(|kind| records.events_of(kind).is_empty()),
        "{:?}",
        records.events
    );
    assert_eq!(
        records.leftovers,
        Default::default(),
        "iceoryx2 nodes or services left behind"
    );
}
