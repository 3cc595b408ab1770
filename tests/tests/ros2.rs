//! The ROS 2 output on the real pipeline (cargo feature `ros2`; `cargo xtask test-ros2`):
//! `linetrack run` with `[ros2] enabled = true` starts `linetrack-ros2`, and an independent
//! DDS subscriber — Eclipse Cyclone DDS through its Python binding (`tests/ros2/listen.py`,
//! installed by `cargo xtask setup` into `target/dds-peer`), with the ROS 2 types under
//! their DDS names — receives `geometry_msgs/msg/PoseStamped` on `/linetrack/pose`,
//! `nav_msgs/msg/Path` on `/linetrack/path`, `nav_msgs/msg/Odometry` on `/linetrack/odom`
//! `tf2_msgs/msg/TFMessage` on `/tf` and `diagnostic_msgs/msg/DiagnosticArray` on
//! `/diagnostics`; and frames from ROS 2 image topics ([`images`]). Each test uses its own
//! domain id (from the
//! process id) and loopback-only discovery, so parallel runs do not cross.

#[path = "ros2/images.rs"]
mod images;

use linetrack_e2e::*;
use nalgebra::Matrix6;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const FRAMES: usize = 40;
const RUN_TIMEOUT: Duration = Duration::from_secs(120);
/// How long the subscriber may take to start, and to get the last path after the run.
const PEER_TIMEOUT: Duration = Duration::from_secs(30);
/// `poses.tum` has 6 decimals: a value read back is within half a unit of the 6th.
const TUM_PRECISION: f64 = 0.5e-6 + 1e-12;
/// Stamps of one frame agree within this (`poses.tum`'s seconds are printed from an f64).
const STAMP_TOLERANCE_NS: i128 = 1_000;

/// The Python with Cyclone DDS: `LINETRACK_DDS_PYTHON`, else `target/dds-peer/bin/python3`.
fn peer_python() -> PathBuf {
    linetrack_e2e::peer_python(
        "LINETRACK_DDS_PYTHON",
        "dds-peer",
        "the DDS peer (cyclonedds)",
    )
}

/// The subscriber process; killed when dropped.
struct Listener {
    child: Child,
    out: PathBuf,
}

impl Drop for Listener {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Listener {
    fn start(dir: &Path, domain: u16) -> Self {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("ros2/listen.py");
        let (out, ready) = (dir.join("received.jsonl"), dir.join("listener.ready"));
        let child = Command::new(peer_python())
            .arg(&script)
            .args(["--domain", &domain.to_string(), "--timeout", "300"])
            .arg("--out")
            .arg(&out)
            .arg("--ready")
            .arg(&ready)
            .stdin(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("starting {}: {e}", script.display()));
        let mut listener = Self { child, out };
        let deadline = Instant::now() + PEER_TIMEOUT;
        while !ready.is_file() {
            if let Ok(Some(status)) = listener.child.try_wait() {
                panic!("the DDS subscriber exited ({status}) before it was ready");
            }
            assert!(
                Instant::now() < deadline,
                "the DDS subscriber not ready within {PEER_TIMEOUT:?}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        listener
    }

    /// The messages received so far.
    fn received(&self) -> Vec<serde_json::Value> {
        std::fs::read_to_string(&self.out)
            .unwrap_or_default()
            .lines()
            .filter_map(|l| serde_json::from_str(l).ok())
            .collect()
    }
}

/// One pose: stamp in ns, position, orientation x y z w.
#[derive(Debug, Clone, Copy)]
struct Stamped {
    ns: i128,
    position: [f64; 3],
    orientation: [f64; 4],
}

fn from_json(v: &serde_json::Value) -> Stamped {
    let num = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let list = |key: &str| -> Vec<f64> {
        v[key]
            .as_array()
            .map(|a| a.iter().map(num).collect())
            .unwrap_or_default()
    };
    let (p, q) = (list("position"), list("orientation"));
    assert_eq!((p.len(), q.len()), (3, 4), "{v}");
    Stamped {
        ns: i128::from(v["sec"].as_i64().unwrap_or(-1)) * 1_000_000_000
            + i128::from(v["nanosec"].as_i64().unwrap_or(-1)),
        position: [p[0], p[1], p[2]],
        orientation: [q[0], q[1], q[2], q[3]],
    }
}

/// `poses.tum` as the run wrote it (the seconds parsed as text: no float rounding).
fn tum(run_dir: &Path) -> Vec<Stamped> {
    let text = std::fs::read_to_string(run_dir.join("poses.tum"))
        .unwrap_or_else(|e| panic!("poses.tum: {e}"));
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let v: Vec<&str> = l.split_whitespace().collect();
            assert_eq!(v.len(), 8, "{l}");
            let (sec, frac) = v[0].split_once('.').unwrap_or((v[0], "0"));
            let frac = format!("{frac:0<9}");
            let ns = sec.parse::<i128>().unwrap_or(-1) * 1_000_000_000
                + frac[..9].parse::<i128>().unwrap_or(-1);
            let f = |i: usize| v[i].parse::<f64>().unwrap_or(f64::NAN);
            Stamped {
                ns,
                position: [f(1), f(2), f(3)],
                orientation: [f(4), f(5), f(6), f(7)],
            }
        })
        .collect()
}

fn assert_matches(what: &str, got: &Stamped, expected: &[Stamped]) {
    let line = expected
        .iter()
        .find(|e| (e.ns - got.ns).abs() <= STAMP_TOLERANCE_NS)
        .unwrap_or_else(|| panic!("{what}: stamp {} ns is no frame of poses.tum", got.ns));
    for (a, b) in got
        .position
        .iter()
        .zip(line.position)
        .chain(got.orientation.iter().zip(line.orientation))
    {
        assert!(
            (a - b).abs() <= TUM_PRECISION,
            "{what} at {} ns: {got:?} vs poses.tum {line:?}",
            got.ns
        );
    }
}

#[test]
fn a_cyclone_dds_subscriber_receives_the_poses_and_the_path_of_poses_tum() {
    received_poses_match_poses_tum("ros2", false);
}

#[test]
fn in_single_process_mode_the_subscriber_receives_the_poses_too() {
    received_poses_match_poses_tum("ros2-threads", true);
}

/// A run with the bridge (stages as processes, or as threads with `single_process`) and
/// the subscriber: what it received is what `poses.tum` holds.
fn received_poses_match_poses_tum(name: &str, single_process: bool) {
    let dir = scratch(name);
    // Own domain per test process: 1..=232 from the pid.
    let domain = 1 + (std::process::id() % 232) as u16;
    let listener = Listener::start(&dir, domain);
    // Camera axes and sequence stamps: what poses.tum holds, so the two compare directly;
    // lost predictions too (poses.tum has them).
    let extra = format!(
        "[supervisor]\nstatus_every_ms = 0\n[budget]\ndrop_late = false\n\
         [ros2]\nenabled = true\ndomain_id = {domain}\nlocalhost_only = true\nframe_id = \"map\"\n\
         convention = \"camera\"\nstamp = \"sequence\"\npublish_lost = true\ntf = true\n\
         wait_for_subscribers_ms = 20000\n"
    );
    let run = if single_process {
        start_single_process(&dir, &base_sequence(FRAMES), &extra)
    } else {
        start(&dir, &base_sequence(FRAMES), &extra)
    };
    let run_dir = run.run_dir.clone();
    let (status, _, records) = run.finish(RUN_TIMEOUT);
    assert!(status.success(), "the run failed: {status}");
    assert!(
        records.events_of("output-exit").is_empty()
            && records.events_of("output-not-ready").is_empty(),
        "{:?}",
        records.events
    );
    let expected = tum(&run_dir);
    assert!(
        expected.len() >= FRAMES / 2,
        "only {} poses in poses.tum",
        expected.len()
    );
    let last_tum = expected
        .iter()
        .max_by_key(|p| p.ns)
        .copied()
        .unwrap_or_else(|| panic!("no pose"));

    // The path is transient-local and re-sent with every pose: wait for the one that holds
    // every pose of the run.
    let deadline = Instant::now() + PEER_TIMEOUT;
    let (poses, path, received) = loop {
        let received = listener.received();
        let path = received
            .iter()
            .filter(|m| m["topic"] == "path")
            .max_by_key(|m| m["poses"].as_array().map_or(0, Vec::len))
            .cloned();
        let full = path
            .as_ref()
            .is_some_and(|p| p["poses"].as_array().map_or(0, Vec::len) >= expected.len());
        let count = |topic: &str| received.iter().filter(|m| m["topic"] == topic).count();
        let all = count("odom") >= expected.len()
            && count("tf") >= expected.len()
            && count("diagnostics") >= 1;
        if (full && all) || Instant::now() > deadline {
            let poses: Vec<serde_json::Value> = received
                .iter()
                .filter(|m| m["topic"] == "pose")
                .cloned()
                .collect();
            break (
                poses,
                path.unwrap_or_else(|| panic!("no Path message received on domain {domain}")),
                received,
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    };

    // Poses: every one received is a line of poses.tum, in frame "map".
    assert!(
        !poses.is_empty(),
        "no PoseStamped received on domain {domain}"
    );
    for p in &poses {
        assert_eq!(p["frame_id"], "map");
        assert_matches("PoseStamped", &from_json(p), &expected);
    }
    eprintln!(
        "received {} of {} poses, path of {}",
        poses.len(),
        expected.len(),
        path["poses"].as_array().map_or(0, Vec::len)
    );

    // The path: all of poses.tum, in order, ending at its last pose.
    assert_eq!(path["frame_id"], "map");
    let path_poses: Vec<Stamped> = path["poses"]
        .as_array()
        .map(|a| a.iter().map(from_json).collect())
        .unwrap_or_default();
    assert_eq!(
        path_poses.len(),
        expected.len(),
        "the path holds every pose of the run"
    );
    for p in &path_poses {
        assert_matches("Path pose", p, &expected);
    }
    assert!(
        path_poses.windows(2).all(|w| w[0].ns < w[1].ns),
        "the path is in time order"
    );
    let last = path_poses
        .last()
        .copied()
        .unwrap_or_else(|| panic!("empty path"));
    assert_matches("the path's last pose", &last, &[last_tum]);
    assert_odometry_and_tf(&received, &poses, &expected);
    assert_diagnostics(&received, expected.len());
    assert_eq!(
        records.leftovers,
        Default::default(),
        "iceoryx2 nodes or services left behind"
    );
}

/// A 6×6 covariance from its 36 row-major values, checked symmetric and positive
/// semi-definite.
fn covariance(what: &str, m: &serde_json::Value) -> Matrix6<f64> {
    let values: Vec<f64> = m
        .as_array()
        .map(|a| a.iter().map(|v| v.as_f64().unwrap_or(f64::NAN)).collect())
        .unwrap_or_default();
    assert_eq!(values.len(), 36, "{what}: {m}");
    let c = Matrix6::from_row_slice(&values);
    assert_eq!(c, c.transpose(), "{what}: not symmetric");
    let eigen = c.symmetric_eigenvalues();
    assert!(
        eigen.min() >= -1e-9 * eigen.max().abs().max(1e-300),
        "{what}: not positive semi-definite: {eigen}"
    );
    c
}

/// Odometry and /tf: one of each for every frame of poses.tum, with its stamp; the pose
/// is the PoseStamped's of the same stamp (the camera is the base: no mount configured);
/// the covariances symmetric and positive semi-definite, the pose's growing from zero.
fn assert_odometry_and_tf(
    received: &[serde_json::Value],
    poses: &[serde_json::Value],
    expected: &[Stamped],
) {
    let of = |topic: &str| -> Vec<&serde_json::Value> {
        received.iter().filter(|m| m["topic"] == topic).collect()
    };
    let (odometry, transforms) = (of("odom"), of("tf"));
    let stamped_poses: Vec<Stamped> = poses.iter().map(from_json).collect();
    let mut traces = Vec::new();
    for o in &odometry {
        assert_eq!(
            (&o["frame_id"], &o["child_frame_id"]),
            (&"map".into(), &"base_link".into())
        );
        let got = from_json(o);
        assert_matches("Odometry", &got, expected);
        if let Some(p) = stamped_poses.iter().find(|p| p.ns == got.ns) {
            for (a, b) in got
                .position
                .iter()
                .zip(p.position)
                .chain(got.orientation.iter().zip(p.orientation))
            {
                assert!(
                    (a - b).abs() <= 1e-12,
                    "Odometry {got:?} vs PoseStamped {p:?}"
                );
            }
        }
        let c = covariance("pose covariance", &o["covariance"]);
        covariance("twist covariance", &o["twist_covariance"]);
        traces.push((got.ns, c.trace()));
    }
    for e in expected {
        assert!(
            odometry.iter().any(|o| from_json(o).ns == e.ns),
            "no Odometry for the frame at {} ns ({} received)",
            e.ns,
            odometry.len()
        );
    }
    traces.sort_by_key(|(ns, _)| *ns);
    assert!(
        traces.last().is_some_and(|(_, t)| *t > 0.0),
        "the pose covariance never grew: {traces:?}"
    );
    let tf: Vec<serde_json::Value> = transforms
        .iter()
        .flat_map(|t| t["transforms"].as_array().cloned().unwrap_or_default())
        .collect();
    for e in expected {
        let t = tf
            .iter()
            .find(|t| from_json(t).ns == e.ns)
            .unwrap_or_else(|| {
                panic!(
                    "no /tf for the frame at {} ns ({} received)",
                    e.ns,
                    tf.len()
                )
            });
        assert_eq!(
            (&t["frame_id"], &t["child_frame_id"]),
            (&"map".into(), &"base_link".into())
        );
        assert_matches("/tf", &from_json(t), expected);
    }
    eprintln!(
        "received {} Odometry and {} /tf messages",
        odometry.len(),
        tf.len()
    );
}

/// Diagnostics: at least the one at the end, reports a second or more apart (the bridge's
/// period; how many depends on the run's length), each with a status per stage (latency
/// p50/p99, budget misses), the pipeline's (frames, drops), the matcher's mode and the
/// tracking's figures; the last one counts every frame of the run.
fn assert_diagnostics(received: &[serde_json::Value], frames: usize) {
    let reports: Vec<&serde_json::Value> = received
        .iter()
        .filter(|m| m["topic"] == "diagnostics")
        .collect();
    assert!(!reports.is_empty(), "no DiagnosticArray received");
    // Periodic reports a period apart (the wall clock may step by a little against the
    // bridge's monotonic one); the one at the end comes whenever the run ends.
    let stamps: Vec<i128> = reports.iter().map(|r| from_stamp(r)).collect();
    let periodic = &stamps[..stamps.len() - 1];
    assert!(
        periodic.windows(2).all(|w| w[1] - w[0] >= 990_000_000),
        "{stamps:?}"
    );
    assert!(stamps.windows(2).all(|w| w[1] >= w[0]), "{stamps:?}");
    let named = |report: &serde_json::Value, name: &str| -> serde_json::Value {
        report["status"]
            .as_array()
            .and_then(|s| s.iter().find(|s| s["name"] == name).cloned())
            .unwrap_or_else(|| panic!("no {name} in {report}"))
    };
    for report in &reports {
        for stage in ["frame-source", "line-detector", "matcher", "pose-estimator"] {
            let s = named(report, &format!("linetrack: {stage}"));
            for key in [
                "latency_p50_ms",
                "latency_p99_ms",
                "budget_ms",
                "budget_misses",
            ] {
                assert!(s["values"][key].is_string(), "{stage}: no {key}: {s}");
            }
        }
        // "unknown" until a frame arrived (the first report may come before the first pose).
        let m = named(report, "linetrack: matcher mode");
        let mode = m["values"]["mode"].as_str().unwrap_or("");
        assert!(["lbd", "l1", "unknown"].contains(&mode), "{m}");
        let t = named(report, "linetrack: tracking");
        for key in [
            "state",
            "inlier_points",
            "inlier_lines",
            "conditioning",
            "lost_frames",
        ] {
            assert!(t["values"][key].is_string(), "tracking: no {key}: {t}");
        }
    }
    let last = reports.last().copied().unwrap_or(&serde_json::Value::Null);
    let mode = named(last, "linetrack: matcher mode");
    let mode_name = mode["values"]["mode"].as_str().unwrap_or("");
    assert!(["lbd", "l1"].contains(&mode_name), "{mode}");
    let pipeline = named(last, "linetrack: pipeline");
    let counted: usize = pipeline["values"]["frames"]
        .as_str()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    assert!(
        counted >= frames,
        "the last report counts {counted} frames of {frames}: {pipeline}"
    );
    // A report's p50 is a latency: a number of milliseconds, not above its p99.
    let detector = named(last, "linetrack: line-detector");
    let number = |key: &str| {
        detector["values"][key]
            .as_str()
            .and_then(|v| v.parse::<f64>().ok())
    };
    if let (Some(p50), Some(p99)) = (number("latency_p50_ms"), number("latency_p99_ms")) {
        assert!(p50 >= 0.0 && p50 <= p99, "{detector}");
    }
    eprintln!("received {} DiagnosticArray messages", reports.len());
}

/// A message's header stamp, ns.
fn from_stamp(v: &serde_json::Value) -> i128 {
    i128::from(v["sec"].as_i64().unwrap_or(-1)) * 1_000_000_000
        + i128::from(v["nanosec"].as_i64().unwrap_or(-1))
}

#[test]
fn a_bridge_that_cannot_join_dds_is_recorded_and_the_run_goes_on() {
    let dir = scratch("ros2-failing");
    // No domain in the config and one the bridge must refuse in the environment: it exits
    // before it is ready, as it would on any DDS setup failure.
    let extra = "[supervisor]\nstatus_every_ms = 0\n[budget]\ndrop_late = false\n\
                 [ros2]\nenabled = true\nlocalhost_only = true\n";
    let run = start_with_env(
        &dir,
        &base_sequence(FRAMES),
        extra,
        &[("ROS_DOMAIN_ID", "not-a-domain")],
    );
    let (status, _, records) = run.finish(RUN_TIMEOUT);
    assert!(status.success(), "the run failed: {status}");
    let exits = records.events_of("output-exit");
    assert_eq!(exits.len(), 1, "{:?}", records.events);
    assert_eq!(exits[0].stage, "ros2");
    assert!(
        exits[0].detail.contains("exit status: 1"),
        "{}",
        exits[0].detail
    );
    assert_ids_accounted(&records, FRAMES as u64, &[]);
    // The pipeline went on: poses after the bridge was gone (how many depends on the load).
    assert!(records.frames.iter().any(|f| f.outcome == "pose"));
    assert_eq!(
        records.leftovers,
        Default::default(),
        "iceoryx2 nodes or services left behind"
    );
}
