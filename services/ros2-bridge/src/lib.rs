//! `linetrack-ros2`: the optional output process that publishes the pipeline's poses to
//! ROS 2.
//!
//! The supervisor starts it beside the stages when `[ros2] enabled = true` (binary built
//! with the cargo feature `ros2`). It subscribes to the `poses` topic over iceoryx2 like
//! the supervisor does, turns each tracked pose into a `geometry_msgs/msg/PoseStamped`
//! ([`convert::ros_pose`]: REP-103 or camera axes, stamp from the capture or the sequence)
//! and keeps the newest `path_max_poses` in a `nav_msgs/msg/Path`
//! ([`convert::PathWindow`]); [`dds`] publishes both over DDS with ros2-client (pure Rust,
//! no ROS install). Frames dropped by a stage publish nothing; frames where tracking was
//! lost publish their predicted pose only with `publish_lost = true`.
//!
//! Its second process, `linetrack-ros2-source` ([`image_source`]), is the frame source
//! when frames come from ROS 2 image topics (`[camera.ros2_images]`, `linetrack run
//! --ros2-images LEFT RIGHT`): the two `sensor_msgs/Image` paired by stamp
//! ([`pairing`]), read as grey ([`image_in`]), the rig from their `CameraInfo`
//! ([`camera_info`]). With it, the bridge stamps its messages with the images' header
//! stamps whatever `[ros2] stamp` says.
//!
//! It never holds up the pipeline: its poses subscription overwrites the oldest message
//! when it falls behind (the publisher never waits for it), and a DDS write that fails is
//! logged (the first, then every [`LOG_EVERY`]th) and the next pose is tried.

#![warn(missing_docs)]

pub mod camera_info;
pub mod convert;
#[cfg(feature = "ros2")]
pub mod dds;
pub mod health;
pub mod image_in;
#[cfg(feature = "ros2")]
pub mod image_source;
pub mod odometry;
pub mod pairing;
pub mod ros_msgs;
pub mod sensor_msgs;

use convert::PathWindow;
use health::Health;
use linetrack_ipc::{Bus, Shutdown};
use linetrack_msgs::{PoseRecord, StageKind, StatusKind, StatusReport, TracksHeader, topics};
use linetrack_pipeline_config::BudgetConfig;
use linetrack_pipeline_config::Ros2Config;
use nalgebra::Isometry3;
use ros_msgs::{DiagnosticArray, Header, Odometry, Path, PoseStamped, TfMessage, Time};
use std::time::Duration;
use std::time::Instant;

/// A failed write is logged the first time and then once per this many failures.
pub const LOG_EVERY: u64 = 100;

/// How long the loop sleeps at most between checks of the shutdown flag.
const WAKE_TIMEOUT: Duration = Duration::from_millis(100);

/// Errors of the ROS 2 output.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// The shared-memory side (poses subscription, status).
    #[error("shared memory")]
    Ipc(#[from] linetrack_ipc::IpcError),
    /// A ROS name in the config was refused by ros2-client.
    #[error("ros2.{key} = {value:?}: {message}")]
    Name {
        /// The config key.
        key: &'static str,
        /// Its value.
        value: String,
        /// Why.
        message: String,
    },
    /// The DDS participant, node, topic or writer could not be made.
    #[error("DDS setup: {what}: {message}")]
    Setup {
        /// What was being made.
        what: &'static str,
        /// The DDS library's message.
        message: String,
    },
    /// `ROS_DOMAIN_ID` is set but is no domain id.
    #[error("ROS_DOMAIN_ID = {0:?} is not a domain id 0..=232")]
    DomainEnv(String),
    /// A DDS write failed.
    #[error("DDS write on {topic}: {message}")]
    Write {
        /// The ROS topic.
        topic: String,
        /// The DDS library's message.
        message: String,
    },
}

/// Where the messages go (DDS in the binary, a list in tests).
pub trait PoseSink {
    /// Publishes one pose.
    fn pose(&mut self, message: PoseStamped) -> Result<(), BridgeError>;
    /// Publishes the path.
    fn path(&mut self, message: Path) -> Result<(), BridgeError>;
    /// Whether a path topic is configured.
    fn wants_path(&self) -> bool;
    /// Publishes one odometry message.
    fn odometry(&mut self, message: Odometry) -> Result<(), BridgeError>;
    /// Publishes one `/tf` message.
    fn transform(&mut self, message: TfMessage) -> Result<(), BridgeError>;
    /// Publishes one health report.
    fn diagnostics(&mut self, message: DiagnosticArray) -> Result<(), BridgeError>;
    /// Called once after the last message, before the sink is dropped.
    fn finish(&mut self) {}
}

/// What became of the poses the bridge read.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Tally {
    /// Poses published.
    pub published: u64,
    /// Frames dropped by a stage (no pose).
    pub dropped: u64,
    /// Lost-tracking predictions not published (`publish_lost = false`).
    pub lost: u64,
    /// Poses that were no finite rotation and position.
    pub invalid: u64,
    /// Failed DDS writes.
    pub failed_writes: u64,
}

/// Turns pose messages into ROS messages on a sink.
#[derive(Debug)]
pub struct Bridge {
    config: Ros2Config,
    path: PathWindow,
    tally: Tally,
    /// The camera's optical frame in the base frame, in the published axes.
    mount: Isometry3<f64>,
    /// The last pose read of a frame that was not dropped, and its stamp (ns): where the
    /// next one's twist starts.
    previous: Option<(PoseRecord, u64)>,
}

impl Bridge {
    /// A bridge publishing as `config` says.
    pub fn new(config: &Ros2Config) -> Self {
        Self {
            config: config.clone(),
            path: PathWindow::new(config.path_max_poses),
            tally: Tally::default(),
            mount: odometry::camera_in_base(config.convention, &config.camera_in_base),
            previous: None,
        }
    }

    /// What it did so far.
    pub fn tally(&self) -> Tally {
        self.tally
    }

    /// Takes one message of the `poses` topic: publishes the pose, the path, the odometry
    /// and `/tf` (those configured) when the frame was tracked (or lost, with
    /// `publish_lost`); nothing otherwise.
    pub fn on_pose(
        &mut self,
        message: &TracksHeader,
        record: &PoseRecord,
        sink: &mut dyn PoseSink,
    ) {
        let header = &message.frame;
        if !header.is_ok() {
            self.tally.dropped += 1;
            return;
        }
        let stamp_ns = convert::stamp_ns(header, self.config.stamp);
        let previous = self.previous.replace((*record, stamp_ns));
        if record.lost != 0 && !self.config.publish_lost {
            self.tally.lost += 1;
            return;
        }
        let Some(pose) = convert::ros_pose(record, self.config.convention) else {
            self.tally.invalid += 1;
            tracing::warn!(
                "frame {}: pose is no finite rotation and position: not published",
                header.frame_id
            );
            return;
        };
        let message = PoseStamped {
            header: Header {
                stamp: convert::stamp(header, self.config.stamp),
                frame_id: self.config.frame_id.clone(),
            },
            pose,
        };
        if sink.wants_path() {
            self.path.push(message.clone());
        }
        let odometry = (!self.config.odom_topic.is_empty() || self.config.tf)
            .then(|| {
                odometry::odometry(
                    record,
                    message.header.clone(),
                    stamp_ns,
                    previous.as_ref().map(|(p, ns)| (p, *ns)),
                    &self.config.child_frame_id,
                    &self.mount,
                )
            })
            .flatten();
        let written = sink.pose(message);
        self.note(written);
        if let Some(odometry) = odometry {
            if self.config.tf {
                let written = sink.transform(odometry::transform(&odometry));
                self.note(written);
            }
            if !self.config.odom_topic.is_empty() {
                let written = sink.odometry(odometry);
                self.note(written);
            }
        }
        if sink.wants_path() {
            let written = sink.path(self.path.message(&self.config.frame_id));
            self.note(written);
        }
    }

    fn note(&mut self, written: Result<(), BridgeError>) {
        match written {
            Ok(()) => self.tally.published += 1,
            Err(e) => {
                self.tally.failed_writes += 1;
                let n = self.tally.failed_writes;
                if n == 1 || n.is_multiple_of(LOG_EVERY) {
                    tracing::warn!("{e} ({n} failed writes so far); the run goes on");
                }
            }
        }
    }
}

/// The bridge's loop: subscribes to the poses, makes the sink (`make_sink`: DDS), tells the
/// supervisor it is ready, then publishes every pose until `shutdown`, and the ones still
/// queued after it; with a diagnostics topic, the run's health (against `budget`) once a
/// second and once at the end. A sink that cannot be made ends it with that error (the run
/// goes on without ROS 2 output).
pub fn run(
    config: &Ros2Config,
    budget: &BudgetConfig,
    bus: &Bus,
    shutdown: &Shutdown,
    make_sink: impl FnOnce() -> Result<Box<dyn PoseSink>, BridgeError>,
) -> Result<Tally, BridgeError> {
    // Subscribed before ready is said: no pose published after that is missed.
    let mut poses = bus.inlet::<PoseRecord, TracksHeader>(topics::POSES)?;
    let wake = bus.wake(StageKind::Supervisor)?;
    let mut sink = make_sink()?;
    let mut status = bus.outlet::<StatusReport, ()>(topics::STATUS, 1)?;
    let ready = StatusReport {
        stage: StageKind::Ros2Bridge.into(),
        pid: std::process::id(),
        kind: StatusKind::Ready.into(),
        ..StatusReport::default()
    };
    status.publish(&(), &[&[ready]])?;
    let mut bridge = Bridge::new(config);
    let mut health = (!config.diagnostics_topic.is_empty()).then(|| Health::new(budget));
    let wall_clock = || Time::from_ns(linetrack_msgs::now_ns());
    loop {
        let stopping = shutdown.requested();
        for message in poses.receive_all()? {
            if let Some(pose) = message.payload().first() {
                bridge.on_pose(message.header(), pose, sink.as_mut());
                if let Some(health) = &mut health {
                    health.observe(message.header(), pose);
                }
            }
        }
        if let Some(report) = health
            .as_mut()
            .and_then(|h| h.report_if_due(Instant::now(), wall_clock()))
        {
            let written = sink.diagnostics(report);
            bridge.note(written);
        }
        if stopping {
            break;
        }
        wake.wait(WAKE_TIMEOUT)?;
    }
    if let Some(health) = &mut health {
        let written = sink.diagnostics(health.report(wall_clock()));
        bridge.note(written);
    }
    sink.finish();
    Ok(bridge.tally())
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::{FrameHeader, FrameStatus};
    use linetrack_pipeline_config::Convention;

    #[derive(Default)]
    struct Recorded {
        poses: Vec<PoseStamped>,
        paths: Vec<Path>,
        odometry: Vec<Odometry>,
        transforms: Vec<TfMessage>,
        fail: bool,
    }

    impl PoseSink for Recorded {
        fn pose(&mut self, message: PoseStamped) -> Result<(), BridgeError> {
            if self.fail {
                return Err(BridgeError::Write {
                    topic: "/p".into(),
                    message: "no".into(),
                });
            }
            self.poses.push(message);
            Ok(())
        }
        fn path(&mut self, message: Path) -> Result<(), BridgeError> {
            self.paths.push(message);
            Ok(())
        }
        fn wants_path(&self) -> bool {
            true
        }
        fn odometry(&mut self, message: Odometry) -> Result<(), BridgeError> {
            self.odometry.push(message);
            Ok(())
        }
        fn transform(&mut self, message: TfMessage) -> Result<(), BridgeError> {
            self.transforms.push(message);
            Ok(())
        }
        fn diagnostics(&mut self, _: DiagnosticArray) -> Result<(), BridgeError> {
            Ok(())
        }
    }

    fn pose(x: f64, lost: u32) -> PoseRecord {
        PoseRecord {
            translation: [x, 0.0, 0.0],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            lost,
            ..PoseRecord::default()
        }
    }

    #[test]
    fn tracked_poses_go_out_drops_and_lost_predictions_do_not() {
        let config = Ros2Config {
            convention: Convention::Camera,
            path_max_poses: 2,
            ..Default::default()
        };
        let mut bridge = Bridge::new(&config);
        let mut sink = Recorded::default();
        bridge.on_pose(
            &TracksHeader::from(FrameHeader::new(0, 0, 0)),
            &pose(1.0, 0),
            &mut sink,
        );
        let mut dropped = FrameHeader::new(1, 1, 1);
        dropped.mark(FrameStatus::DroppedLate, StageKind::Matcher);
        bridge.on_pose(&TracksHeader::from(dropped), &pose(2.0, 0), &mut sink);
        bridge.on_pose(
            &TracksHeader::from(FrameHeader::new(2, 2, 2)),
            &pose(3.0, 1),
            &mut sink,
        );
        bridge.on_pose(
            &TracksHeader::from(FrameHeader::new(3, 3, 3)),
            &pose(4.0, 0),
            &mut sink,
        );
        bridge.on_pose(
            &TracksHeader::from(FrameHeader::new(4, 4, 4)),
            &pose(5.0, 0),
            &mut sink,
        );
        let xs: Vec<f64> = sink.poses.iter().map(|p| p.pose.position.x).collect();
        assert_eq!(xs, [1.0, 4.0, 5.0]);
        let last: Vec<f64> = sink
            .paths
            .last()
            .map(|p| p.poses.iter().map(|p| p.pose.position.x).collect())
            .unwrap_or_default();
        assert_eq!(last, [4.0, 5.0]);
        assert_eq!((bridge.tally().dropped, bridge.tally().lost), (1, 1));
        let mut publish_lost = Bridge::new(&Ros2Config {
            publish_lost: true,
            ..config
        });
        publish_lost.on_pose(
            &TracksHeader::from(FrameHeader::new(2, 2, 2)),
            &pose(3.0, 1),
            &mut sink,
        );
        assert_eq!(sink.poses.len(), 4);
    }

    /// Every published pose has its odometry (same stamp, same pose) and, with `tf`, its
    /// transform; the twist runs from the last pose read, lost or not.
    #[test]
    fn odometry_and_tf_go_with_every_published_pose() {
        let config = Ros2Config {
            convention: Convention::Camera,
            tf: true,
            ..Default::default()
        };
        let mut bridge = Bridge::new(&config);
        let mut sink = Recorded::default();
        let frame = |id: u64| TracksHeader::from(FrameHeader::new(id, 0, id * 100_000_000));
        bridge.on_pose(&frame(0), &pose(0.0, 0), &mut sink);
        bridge.on_pose(&frame(1), &pose(0.1, 1), &mut sink);
        bridge.on_pose(&frame(2), &pose(0.2, 0), &mut sink);
        assert_eq!((sink.poses.len(), sink.odometry.len()), (2, 2));
        assert_eq!(sink.transforms.len(), 2);
        for ((p, o), t) in sink.poses.iter().zip(&sink.odometry).zip(&sink.transforms) {
            assert_eq!(o.header, p.header);
            assert_eq!(o.pose.pose, p.pose);
            assert_eq!(o.child_frame_id, "base_link");
            assert_eq!(t.transforms[0].header, p.header);
        }
        // Frame 2's twist: 0.1 m along x over 0.1 s from the lost frame 1's pose.
        let twist = sink.odometry[1].twist.twist;
        assert!((twist.linear.x - 1.0).abs() < 1e-9, "{twist:?}");
        assert_eq!(sink.odometry[0].twist.twist.linear.x, 0.0);
        // Without an odometry topic and tf nothing but the pose and the path goes out.
        let mut quiet = Bridge::new(&Ros2Config {
            odom_topic: String::new(),
            ..Default::default()
        });
        let mut sink = Recorded::default();
        quiet.on_pose(&frame(0), &pose(0.0, 0), &mut sink);
        assert_eq!(
            (sink.poses.len(), sink.odometry.len(), sink.transforms.len()),
            (1, 0, 0)
        );
    }

    #[test]
    fn failed_writes_are_counted_and_the_next_pose_is_tried() {
        let mut bridge = Bridge::new(&Ros2Config::default());
        let mut sink = Recorded {
            fail: true,
            ..Default::default()
        };
        bridge.on_pose(
            &TracksHeader::from(FrameHeader::new(0, 0, 0)),
            &pose(1.0, 0),
            &mut sink,
        );
        sink.fail = false;
        bridge.on_pose(
            &TracksHeader::from(FrameHeader::new(1, 0, 0)),
            &pose(2.0, 0),
            &mut sink,
        );
        assert_eq!(bridge.tally().failed_writes, 1);
        assert_eq!(sink.poses.len(), 1);
        // The path still has both: a failed pose write does not lose it from the path.
        assert_eq!(sink.paths.last().map(|p| p.poses.len()), Some(2));
    }
}
