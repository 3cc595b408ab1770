//! The ground-station link end to end (feature `link`): an onboard `linetrack run` with
//! `[link] enabled` in one iceoryx2 domain, `linetrack watch` in another (its own prefix
//! and root), the two joined only by zenoh over TCP on loopback; the far side is frozen
//! (SIGSTOP) for 2 s mid-run.
#![cfg(feature = "link")]

use linetrack_e2e::*;
use linetrack_ipc::Scope;
use linetrack_run_record::read_frames;
use std::collections::BTreeSet;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The other end-to-end tests' sequence: 40 frames at 10 Hz, 4 s, so that the run goes on
/// after a 2 s cut that starts at the fifth pose.
const FRAMES: usize = 40;
const TIMEOUT: Duration = Duration::from_secs(120);

/// A loopback port nobody listens on now.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .unwrap_or_else(|e| panic!("no free port: {e}"))
}

/// The pose lines of a `poses.tum` (no comments); none when it does not exist yet.
fn pose_lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(str::to_string)
        .collect()
}

/// Messages of `topic` in a `link.json` (0 when it is not there yet).
fn link_count(path: &Path, topic: &str, field: &str) -> u64 {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v["topics"][topic][field].as_u64())
        .unwrap_or(0)
}

/// The far side's process, killed if the test ends early.
struct Far(Child);

impl Drop for Far {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn wait_until(what: &str, watch: &mut Child, ready: impl Fn() -> bool) {
    let deadline = Instant::now() + TIMEOUT;
    while !ready() {
        if let Ok(Some(status)) = watch.try_wait() {
            panic!("linetrack watch exited ({status}) before {what}");
        }
        assert!(Instant::now() < deadline, "no {what} within {TIMEOUT:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// `linetrack watch` on `endpoint`, recording into `out`, in its own iceoryx2 domain (it
/// joins none: the only way in is zenoh).
fn watch_on(dir: &Path, endpoint: &str, out: &Path) -> Far {
    Far(Command::new(bin_dir().join("linetrack"))
        .args(["watch", "--connect", endpoint, "--status-every-ms", "0"])
        .args(["--idle-exit", "3", "--out"])
        .arg(out)
        .env(Scope::PREFIX_VAR, format!("ltfar{}_", std::process::id()))
        .env(Scope::ROOT_VAR, dir.join("far-iceoryx2"))
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap_or_else(|e| panic!("starting linetrack watch: {e}")))
}

/// The onboard config: the link on `endpoint` with every topic, an image every 5th frame.
fn link_config(endpoint: &str) -> String {
    format!(
        "[supervisor]\nrestart_backoff_ms = 100\nstatus_every_ms = 0\n[budget]\ndrop_late = false\n[link]\nenabled = true\nlisten = \"{endpoint}\"\ntopics = [\"poses\", \"status\", \"segments\", \"tracks\", \"images\"]\nimage_every = 5\n"
    )
}

/// Waits for the far side to end on its own (after the onboard source's end); its stdout.
fn far_ends(watch: &mut Child) -> String {
    let deadline = Instant::now() + TIMEOUT;
    let status = loop {
        if let Ok(Some(status)) = watch.try_wait() {
            break status;
        }
        assert!(
            Instant::now() < deadline,
            "linetrack watch did not end after the run"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut out = String::new();
    if let Some(mut stdout) = watch.stdout.take() {
        use std::io::Read;
        let _ = stdout.read_to_string(&mut out);
    }
    assert!(status.success(), "{status}\n{out}");
    out
}

/// Every frame once onboard, each with a pose: the link cost the run nothing.
fn assert_onboard_lost_nothing(records: &Records) {
    assert_ids_accounted(records, FRAMES as u64, &[]);
    let outcomes: BTreeSet<&str> = records.frames.iter().map(|f| f.outcome.as_str()).collect();
    assert!(
        outcomes.iter().all(|o| *o == "pose" || *o == "lost"),
        "onboard outcomes {outcomes:?}"
    );
    assert!(
        records.events_of("link-exit").is_empty(),
        "{:?}",
        records.events
    );
}

#[test]
fn poses_and_status_cross_the_link_and_a_2_s_cut_costs_the_onboard_run_no_frame() {
    let dir = scratch("link");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let far = dir.join("far");
    // The far side: another iceoryx2 domain (it joins none; the only way in is zenoh).
    let mut far_side = watch_on(&dir, &endpoint, &far);
    let watch = &mut far_side.0;
    let extra = link_config(&endpoint);
    let run = start(&dir, &base_sequence(FRAMES), &extra);
    let run_dir = run.run_dir.clone();
    let far_poses = far.join("poses.tum");
    let far_counts = far.join("link.json");

    // Before the cut: poses and status reports on the far side.
    wait_until("5 poses on the far side", watch, || {
        pose_lines(&far_poses).len() >= 5
    });
    wait_until("status reports on the far side", watch, || {
        link_count(&far_counts, "status", "sent") > 0
    });
    let before_cut = pose_lines(&far_poses).len();
    signal(watch.id(), "STOP");
    std::thread::sleep(Duration::from_secs(2));
    // Every frame with an outcome onboard by now was produced before the far side came back.
    let onboard_at_resume = run.status().map_or(0, |s| s.frames) as u64;
    signal(watch.id(), "CONT");

    let (exit, out, records) = run.finish(TIMEOUT);
    assert!(exit.success(), "{exit}\n{out}");
    assert_onboard_lost_nothing(&records);
    assert!(
        onboard_at_resume < FRAMES as u64,
        "the run was over before the far side came back ({onboard_at_resume} frames)"
    );
    let onboard_counts = run_dir.join("link.json");
    assert_eq!(
        link_count(&onboard_counts, "poses", "sent")
            + link_count(&onboard_counts, "poses", "dropped")
            + link_count(&onboard_counts, "poses", "unheard"),
        FRAMES as u64,
        "every pose message forwarded, dropped or unheard, counted"
    );
    for topic in ["segments", "tracks", "images"] {
        assert!(
            link_count(&onboard_counts, topic, "sent") > 0,
            "no {topic} sent: {:?}",
            std::fs::read_to_string(&onboard_counts)
        );
    }

    // The far side ends on its own once the source's end has arrived (a status report
    // sent after the cut) and nothing more comes.
    far_ends(watch);

    // Poses on the far side equal the onboard ones, before and after the cut.
    let onboard_lines: BTreeSet<String> =
        pose_lines(&run_dir.join("poses.tum")).into_iter().collect();
    let far_lines = pose_lines(&far_poses);
    assert!(far_lines.len() > before_cut, "no pose after the cut");
    for line in &far_lines {
        assert!(
            onboard_lines.contains(line),
            "far pose {line:?} is not onboard"
        );
    }
    let far_frames = read_frames(&far.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
    let far_posed: Vec<u64> = far_frames
        .iter()
        .filter(|f| f.has_pose())
        .map(|f| f.frame_id)
        .collect();
    assert!(
        far_posed.iter().any(|&f| f > onboard_at_resume),
        "no pose of a frame after the far side came back (frame {onboard_at_resume}): {far_posed:?}"
    );
    assert_eq!(
        far_posed.len(),
        far_lines.len(),
        "one poses.tum line per far frame with a pose"
    );
    // Every far frame row agrees with the onboard one.
    for f in &far_frames {
        if f.outcome == "missing" {
            continue;
        }
        let onboard = records
            .frames
            .iter()
            .find(|o| o.frame_id == f.frame_id)
            .unwrap_or_else(|| panic!("far frame {} not onboard", f.frame_id));
        assert_eq!(
            (&f.outcome, f.stereo_matches, f.tracked_matches),
            (
                &onboard.outcome,
                onboard.stereo_matches,
                onboard.tracked_matches
            ),
            "frame {}",
            f.frame_id
        );
    }
    let far_events = std::fs::read_to_string(far.join("events.csv")).unwrap_or_default();
    assert!(far_events.contains("link-up"), "{far_events}");
}

#[test]
fn a_far_side_restarted_after_2_s_gets_the_rest_and_the_gap_is_counted_unheard() {
    let dir = scratch("link-restart");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let (first, second) = (dir.join("far-1"), dir.join("far-2"));
    let mut far_side = watch_on(&dir, &endpoint, &first);
    let run = start(&dir, &base_sequence(FRAMES), &link_config(&endpoint));
    let run_dir = run.run_dir.clone();
    wait_until("5 poses on the far side", &mut far_side.0, || {
        pose_lines(&first.join("poses.tum")).len() >= 5
    });
    // The far side goes away (its records closed), and another comes 2 s later.
    signal(far_side.0.id(), "TERM");
    far_ends(&mut far_side.0);
    std::thread::sleep(Duration::from_secs(2));
    let mut far_side = watch_on(&dir, &endpoint, &second);

    let (exit, out, records) = run.finish(TIMEOUT);
    assert!(exit.success(), "{exit}\n{out}");
    assert_onboard_lost_nothing(&records);
    let counts = run_dir.join("link.json");
    let unheard = link_count(&counts, "poses", "unheard");
    assert_eq!(
        link_count(&counts, "poses", "sent") + link_count(&counts, "poses", "dropped") + unheard,
        FRAMES as u64,
        "every pose message counted"
    );
    assert!(unheard > 0, "no pose counted unheard while nobody listened");

    far_ends(&mut far_side.0);
    let onboard: BTreeSet<String> = pose_lines(&run_dir.join("poses.tum")).into_iter().collect();
    let (before, after) = (
        pose_lines(&first.join("poses.tum")),
        pose_lines(&second.join("poses.tum")),
    );
    assert!(!after.is_empty(), "the second far side got no pose");
    for line in before.iter().chain(&after) {
        assert!(onboard.contains(line), "far pose {line:?} is not onboard");
    }
    let first_frames = read_frames(&first.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
    let second_frames = read_frames(&second.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
    let last_before = first_frames.iter().map(|f| f.frame_id).max().unwrap_or(0);
    let first_after = second_frames
        .iter()
        .map(|f| f.frame_id)
        .min()
        .unwrap_or(u64::MAX);
    assert!(
        first_after > last_before,
        "the second far side starts at frame {first_after}, the first ended at {last_before}"
    );
    let events = std::fs::read_to_string(second.join("events.csv")).unwrap_or_default();
    assert!(events.contains("link-up"), "{events}");
}
