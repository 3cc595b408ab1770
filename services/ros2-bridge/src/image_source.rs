//! The frame source fed by ROS 2 image topics (cargo feature `ros2`; the
//! `linetrack-ros2-source` process, which the supervisor starts as the frame source when
//! `[camera.ros2_images]` names two topics).
//!
//! It subscribes to a left and a right `sensor_msgs/Image` and their `sensor_msgs/CameraInfo`
//! on `[ros2]`'s domain and wakes on their data (a mio poll on the DDS readers). The rig comes
//! from the first two `CameraInfo` ([`crate::camera_info::stereo_rig`]) and is published
//! before the first frame; frames wait for it. The images are paired by header stamp
//! ([`crate::pairing`]); every pair and every unpaired image gets a frame id, in the order
//! the pairing settles them:
//!
//! - a pair: its pixels written into the shared-memory frame ([`crate::image_in`]), stamped
//!   with the left image's header stamp (the frame's timestamp: poses, `poses.tum` and the
//!   ROS output carry it);
//! - a pair with an image that cannot be read (encoding, size, step, length): a `corrupt`
//!   marker, and a warning naming the topic, the stamp and what is wrong;
//! - an unpaired image: a `capture-dropped` marker.
//!
//! It finishes after `source.max_frames` frame ids or `camera.duration_s` seconds from its
//! first frame (when set); else it runs until the run is stopped.

use crate::BridgeError;
use crate::camera_info::{InfoError, stereo_rig};
use crate::dds::{join, ros_topic, setup};
use crate::image_in::gray;
use crate::pairing::{Paired, Pairing, Side};
use crate::ros_msgs::Time;
use crate::sensor_msgs::{CAMERA_INFO_TYPE, CameraInfo, IMAGE_TYPE, Image};
use anyhow::Context as _;
use linetrack_geometry::StereoRig;
use linetrack_msgs::{FrameStatus, StageKind};
use linetrack_pipeline_config::Ros2ImagesConfig;
use linetrack_stage_runtime::{RigOutlet, Source, SourceOut, StageContext, Step, rig_record};
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{Message, Node, QosProfile, Subscription};
use std::collections::VecDeque;
use std::time::Duration;

/// Bytes a frame message holds before more are allocated: a 752×480 stereo pair.
const FRAME_BYTES: usize = 2 * 752 * 480;
/// A warning of a kind is logged for the first this many, then once per [`WARN_EVERY`].
const WARN_FIRST: u64 = 10;
/// See [`WARN_FIRST`].
const WARN_EVERY: u64 = 100;
/// How long a reliable reader's writer may wait for room (the DDS side of the publisher).
const READER_WAIT: Duration = Duration::from_millis(100);

/// The stamp of a header, ns (a stamp before 1970 counts as 0).
fn stamp_ns(time: &Time) -> u64 {
    u64::try_from(time.sec).unwrap_or(0) * 1_000_000_000 + u64::from(time.nanosec)
}

/// An error with its causes, `a: b: c`.
fn chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(cause) = source {
        text.push_str(&format!(": {cause}"));
        source = cause.source();
    }
    text
}

/// Whether the `n`th warning of a kind is logged.
fn logged(n: u64) -> bool {
    n <= WARN_FIRST || n.is_multiple_of(WARN_EVERY)
}

/// The subscriptions, woken through one poll.
struct Readers {
    images: [Subscription<Image>; 2],
    infos: [Subscription<CameraInfo>; 2],
    poll: Poll,
    events: Events,
}

impl Readers {
    fn subscribe<M: Message + 'static>(
        node: &mut Node,
        key: &'static str,
        topic: &str,
        type_name: (&str, &str),
        qos: &QosProfile,
    ) -> Result<Subscription<M>, BridgeError> {
        let made = ros_topic(node, key, topic, type_name, qos)?;
        node.create_subscription::<M>(&made, None)
            .map_err(|e| setup(key)(e.to_string()))
    }

    fn new(node: &mut Node, config: &Ros2ImagesConfig) -> anyhow::Result<Self> {
        let history = History::KeepLast {
            depth: config.queue,
        };
        let qos = if config.best_effort {
            QosProfile::subscription_default().reliability_best_effort()
        } else {
            QosProfile::subscription_default().reliability_reliable(WhenFull::Wait(READER_WAIT))
        }
        .durability(Durability::Volatile)
        .history(history);
        let (left_info, right_info) = (config.left_info_topic(), config.right_info_topic());
        let mut readers = Self {
            images: [
                Self::subscribe(node, "ros2_images.left", &config.left, IMAGE_TYPE, &qos)?,
                Self::subscribe(node, "ros2_images.right", &config.right, IMAGE_TYPE, &qos)?,
            ],
            infos: [
                Self::subscribe(
                    node,
                    "ros2_images.left_info",
                    &left_info,
                    CAMERA_INFO_TYPE,
                    &qos,
                )?,
                Self::subscribe(
                    node,
                    "ros2_images.right_info",
                    &right_info,
                    CAMERA_INFO_TYPE,
                    &qos,
                )?,
            ],
            poll: Poll::new().context("making the DDS readers' poll")?,
            events: Events::with_capacity(8),
        };
        let registry = readers.poll.registry();
        for (i, reader) in readers.images.iter_mut().enumerate() {
            registry
                .register(reader, Token(i), Interest::READABLE)
                .context("polling an image reader")?;
        }
        for (i, reader) in readers.infos.iter_mut().enumerate() {
            registry
                .register(reader, Token(2 + i), Interest::READABLE)
                .context("polling a CameraInfo reader")?;
        }
        Ok(readers)
    }
}

/// What became of the images so far.
#[derive(Debug, Clone, Copy, Default)]
struct Counts {
    pairs: u64,
    unpaired: u64,
    malformed: u64,
    info_refused: u64,
}

/// Frames from ROS 2 image topics.
pub struct RosImageSource {
    config: Ros2ImagesConfig,
    topics: [String; 2],
    rig_out: RigOutlet,
    rig: Option<StereoRig>,
    infos: [Option<CameraInfo>; 2],
    /// The last refusal of the two `CameraInfo`, logged once each time it changes.
    refused: Option<InfoError>,
    readers: Readers,
    pairing: Pairing<Image>,
    settled: VecDeque<Paired<Image>>,
    counts: Counts,
    max_frames: u64,
    duration: Option<Duration>,
    /// When the first frame was published, on the source's monotonic clock.
    began: Option<Duration>,
    // Dropped last: the readers belong to it.
    _node: Node,
}

impl RosImageSource {
    /// Joins `ctx`'s `[ros2]` domain and subscribes to `[camera.ros2_images]`'s topics.
    pub fn new(ctx: &StageContext, rig_out: RigOutlet) -> anyhow::Result<Self> {
        let config = ctx.config.camera.ros2_images.clone();
        let node_name = format!("{}_images", ctx.config.ros2.node_name);
        let (mut node, domain) = join(&ctx.config.ros2, &node_name)?;
        let readers = Readers::new(&mut node, &config)?;
        tracing::info!(
            "ROS 2 images on domain {domain}: {} + {} ({} + {}), stamps paired within {} ms",
            config.left,
            config.right,
            config.left_info_topic(),
            config.right_info_topic(),
            config.stamp_tolerance_ms
        );
        let duration_s = ctx.config.camera.duration_s;
        Ok(Self {
            topics: [config.left.clone(), config.right.clone()],
            pairing: Pairing::new(config.tolerance_ns(), config.queue),
            config,
            rig_out,
            rig: None,
            infos: [None, None],
            refused: None,
            readers,
            settled: VecDeque::new(),
            counts: Counts::default(),
            max_frames: ctx.config.source.max_frames as u64,
            duration: (duration_s > 0.0).then(|| Duration::from_secs_f64(duration_s)),
            began: None,
            _node: node,
        })
    }

    /// Takes what the readers hold: the newest `CameraInfo` of each side, the images into
    /// the pairing.
    fn take(&mut self) {
        for (i, reader) in self.readers.infos.iter().enumerate() {
            loop {
                match reader.take() {
                    Ok(Some((info, _))) => self.infos[i] = Some(info),
                    Ok(None) => break,
                    Err(e) => {
                        tracing::warn!("reading a CameraInfo: {e}");
                        break;
                    }
                }
            }
        }
        for side in [Side::Left, Side::Right] {
            loop {
                match self.readers.images[side as usize].take() {
                    Ok(Some((image, _))) => {
                        let stamp = stamp_ns(&image.header.stamp);
                        self.pairing.push(side, stamp, image, &mut self.settled);
                    }
                    Ok(None) => break,
                    Err(e) => {
                        // A message that does not deserialise: counted as malformed.
                        self.counts.malformed += 1;
                        if logged(self.counts.malformed) {
                            tracing::warn!(
                                "{}: an image that cannot be read: {e} ({} malformed so far)",
                                self.topics[side as usize],
                                self.counts.malformed
                            );
                        }
                        break;
                    }
                }
            }
        }
    }

    /// The rig, once both `CameraInfo` arrived and describe a rectified pair.
    fn rig(&mut self) -> anyhow::Result<Option<StereoRig>> {
        if self.rig.is_some() {
            return Ok(self.rig);
        }
        let [Some(left), Some(right)] = &self.infos else {
            return Ok(None);
        };
        match stereo_rig(left, right) {
            Ok(rig) => {
                // The pose estimator logs it when it arrives.
                self.rig_out.publish(rig_record(&rig))?;
                self.rig = Some(rig);
            }
            Err(e) => {
                self.counts.info_refused += 1;
                if self.refused.as_ref() != Some(&e) {
                    tracing::error!(
                        "camera.ros2_images: the CameraInfo of {} and {} are refused: {e}; frames wait for ones that describe a rectified pair",
                        self.config.left_info_topic(),
                        self.config.right_info_topic()
                    );
                    self.refused = Some(e);
                }
                self.infos = [None, None];
            }
        }
        Ok(self.rig)
    }

    /// Publishes one settled pair or unpaired image.
    fn publish(
        &mut self,
        out: &mut SourceOut,
        rig: StereoRig,
        settled: Paired<Image>,
    ) -> anyhow::Result<()> {
        let id = out.next_id();
        let now = out.now_ns();
        match settled {
            Paired::Unpaired { side, stamp_ns, .. } => {
                self.counts.unpaired += 1;
                if logged(self.counts.unpaired) {
                    tracing::warn!(
                        "{} image at {stamp_ns} ns has no partner within {} ms: frame {id} capture-dropped ({} unpaired so far)",
                        self.topics[side as usize],
                        self.config.stamp_tolerance_ms,
                        self.counts.unpaired
                    );
                }
                out.marker(id, stamp_ns, now, FrameStatus::CaptureDropped)
            }
            Paired::Pair {
                stamp_ns,
                left,
                right,
            } => {
                let size = (rig.width_px, rig.height_px);
                let (left_gray, right_gray) = (gray(&left, size), gray(&right, size));
                let mut parts = Vec::with_capacity(2);
                let mut bad = None;
                for (side, image) in [(Side::Left, &left_gray), (Side::Right, &right_gray)] {
                    let read = match image {
                        Ok(image) => image.push_parts(&mut parts).map_err(|e| chain(&e)),
                        Err(e) => Err(chain(e)),
                    };
                    if let Err(why) = read {
                        bad.get_or_insert((side, why));
                    }
                }
                if let Some((side, why)) = bad {
                    self.counts.malformed += 1;
                    if logged(self.counts.malformed) {
                        tracing::warn!(
                            "{} image at {stamp_ns} ns: {why}: frame {id} counted corrupt ({} malformed so far)",
                            self.topics[side as usize],
                            self.counts.malformed
                        );
                    }
                    return out.marker(id, stamp_ns, now, FrameStatus::Corrupt);
                }
                self.counts.pairs += 1;
                out.frame(id, stamp_ns, now, size, &parts)
            }
        }
    }

    fn finished(&self, out: &SourceOut) -> bool {
        let frames = self.max_frames > 0 && out.published() >= self.max_frames;
        let time = match (self.duration, self.began) {
            (Some(duration), Some(began)) => out.clock().monotonic() >= began + duration,
            _ => false,
        };
        frames || time
    }
}

impl Source for RosImageSource {
    const KIND: StageKind = StageKind::FrameSource;
    const FRAME_BYTES: usize = FRAME_BYTES;

    fn start(&mut self, _out: &mut SourceOut) -> anyhow::Result<()> {
        // The rig comes with the CameraInfo: published before the first frame.
        Ok(())
    }

    fn step(&mut self, out: &mut SourceOut, wait: Duration) -> anyhow::Result<Step> {
        if self.finished(out) {
            tracing::info!("ROS 2 images: {:?}", self.counts);
            return Ok(Step::Finished);
        }
        let due = self.rig.is_some() && !self.settled.is_empty();
        let timeout = if due { Duration::ZERO } else { wait };
        match self
            .readers
            .poll
            .poll(&mut self.readers.events, Some(timeout))
        {
            // A signal (Ctrl-C, the supervisor's stop): the runtime looks at it next turn.
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => return Ok(Step::Again),
            polled => polled.context("waiting for the DDS readers")?,
        }
        self.take();
        let Some(rig) = self.rig()? else {
            // Waiting for the CameraInfo: the oldest beyond the queue are dropped.
            while self.settled.len() > self.config.queue {
                if let Some(settled) = self.settled.pop_front() {
                    let stamp = match &settled {
                        Paired::Pair { stamp_ns, .. } | Paired::Unpaired { stamp_ns, .. } => {
                            *stamp_ns
                        }
                    };
                    self.counts.unpaired += 1;
                    tracing::warn!(
                        "images at {stamp} ns came before the CameraInfo of {} and {}: capture-dropped",
                        self.config.left_info_topic(),
                        self.config.right_info_topic()
                    );
                    let (id, now) = (out.next_id(), out.now_ns());
                    out.marker(id, stamp, now, FrameStatus::CaptureDropped)?;
                }
            }
            return Ok(Step::Again);
        };
        if let Some(settled) = self.settled.pop_front() {
            self.publish(out, rig, settled)?;
            self.began.get_or_insert(out.clock().monotonic());
        }
        Ok(Step::Again)
    }

    fn poll(&mut self) -> anyhow::Result<()> {
        self.rig_out.poll()
    }
}
