//! The onboard side: the `linetrack-link` process's loop.
//!
//! The loop subscribes to the allowed topics in the run's shared memory and wakes with the
//! supervisor (poses and status wake it: a frame's pose comes after its segments, tracks
//! and images, so each wake-up finds the frame's messages in place). Each message is
//! encoded and handed to the sender thread through a bounded queue; a full queue (the link
//! is stalled) drops the message and counts it. The sender thread owns the zenoh
//! publishers and blocks in zenoh while the link is congested; a message with nobody on the
//! far side to hear it is not sent, and counted as unheard. The counters go to `link.json`
//! in the run folder every second and at the end.

use crate::wire::{Message, key, shrink};
use crate::{LinkError, peer_config};
use crossbeam_channel::{Receiver, TrySendError};
use linetrack_ipc::{Bus, Inlet, Record, Shutdown};
use linetrack_msgs::{
    FrameHeader, PoseRecord, SegmentRecord, SegmentsHeader, StageKind, StatusReport, Topic,
    TrackedLine, TracksHeader,
};
use linetrack_pipeline_config::LinkConfig;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;
use zenoh::qos::CongestionControl;

/// Messages waiting for the sender thread: a stalled link fills it within about a second
/// of frames, then messages are dropped.
const QUEUE: usize = 64;
/// The longest the loop sleeps without a wake-up (it also checks for shutdown).
const WAKE_TIMEOUT: Duration = Duration::from_millis(100);
/// How often `link.json` is rewritten.
const COUNTS_EVERY: Duration = Duration::from_secs(1);

/// What happened to one topic's messages.
#[derive(Debug, Clone, Default, PartialEq, Serialize, serde::Deserialize)]
pub struct TopicCounts {
    /// Sent to zenoh.
    pub sent: u64,
    /// Bytes of the sent messages (the encoded messages: zenoh's and TCP's framing not
    /// included).
    pub bytes: u64,
    /// Dropped because the link was stalled (the sender's queue was full).
    pub dropped: u64,
    /// Not sent because nobody on the far side subscribed (the link was down).
    pub unheard: u64,
}

/// The link's counters (`link.json`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, serde::Deserialize)]
pub struct LinkCounts {
    /// Frames seen (pose messages: every frame's outcome, tracked or dropped).
    pub frames: u64,
    /// Per topic.
    pub topics: BTreeMap<String, TopicCounts>,
}

impl LinkCounts {
    fn topic(&mut self, topic: &str) -> &mut TopicCounts {
        self.topics.entry(topic.to_string()).or_default()
    }

    /// Writes the counters to `path` (through a temporary file renamed over it).
    pub fn write(&self, path: &Path) -> Result<(), LinkError> {
        let fail = |source| LinkError::Write {
            path: path.to_path_buf(),
            source,
        };
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| fail(std::io::Error::other(e.to_string())))?;
        let tmp = path.with_extension("json.tmp");
        std::fs::write(&tmp, text).map_err(fail)?;
        std::fs::rename(&tmp, path).map_err(fail)
    }
}

/// The allowed topics' subscribers.
struct Inlets {
    poses: Option<Inlet<PoseRecord, TracksHeader>>,
    status: Option<Inlet<StatusReport, ()>>,
    segments: Option<Inlet<SegmentRecord, SegmentsHeader>>,
    tracks: Option<Inlet<TrackedLine, TracksHeader>>,
    frames: Option<Inlet<u8, FrameHeader>>,
}

fn inlet_if<P: Record, H: Record>(
    config: &LinkConfig,
    bus: &Bus,
    name: &str,
    topic: Topic,
) -> Result<Option<Inlet<P, H>>, LinkError> {
    Ok(if config.allows(name) {
        Some(bus.inlet(topic)?)
    } else {
        None
    })
}

/// Every message waiting on `inlet`, as link messages.
fn drain<P: Record, H: Record>(
    inlet: &mut Option<Inlet<P, H>>,
    out: &mut Vec<Message>,
    make: impl Fn(&H, &[P]) -> Option<Message>,
) -> Result<(), LinkError> {
    if let Some(inlet) = inlet {
        for m in inlet.receive_all()? {
            out.extend(make(m.header(), m.payload()));
        }
    }
    Ok(())
}

/// Forwards the allowed topics of the run on `bus` until `shutdown`; writes the counters
/// to `counts_path`. Fails only when the link cannot be set up (the endpoint cannot be
/// listened on, the shared memory cannot be joined).
pub fn run(
    config: &LinkConfig,
    bus: &Bus,
    shutdown: &Shutdown,
    counts_path: &Path,
) -> Result<LinkCounts, LinkError> {
    let zenoh_error = |what, endpoint: &str| {
        let endpoint = endpoint.to_string();
        move |e: zenoh::Error| LinkError::Zenoh {
            what,
            endpoint,
            message: e.to_string(),
        }
    };
    let session = zenoh::open(peer_config("listen", &config.listen)?)
        .wait()
        .map_err(zenoh_error("session", &config.listen))?;
    let mut publishers = BTreeMap::new();
    for topic in &config.topics {
        let key = key(&config.key_prefix, topic);
        let publisher = session
            .declare_publisher(key.clone())
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(zenoh_error("publisher", &key))?;
        publishers.insert(topic.clone(), publisher);
    }
    let mut inlets = Inlets {
        poses: inlet_if(config, bus, "poses", Topic::Poses)?,
        status: inlet_if(config, bus, "status", Topic::Status)?,
        segments: inlet_if(config, bus, "segments", Topic::Segments)?,
        tracks: inlet_if(config, bus, "tracks", Topic::Tracks)?,
        frames: inlet_if(config, bus, "images", Topic::Frames)?,
    };
    // Every frame's pose message is seen even when poses are not forwarded: it counts frames.
    let mut frame_counter = match inlets.poses {
        Some(_) => None,
        None => Some(bus.inlet::<PoseRecord, TracksHeader>(Topic::Poses)?),
    };
    let wake = bus.wake(StageKind::Supervisor)?;
    tracing::info!(
        "link: listening on {}, forwarding {:?} under {}/",
        config.listen,
        config.topics,
        config.key_prefix
    );

    let counts = Arc::new(Mutex::new(LinkCounts::default()));
    let (tx, rx) = crossbeam_channel::bounded::<(&'static str, Vec<u8>)>(QUEUE);
    let sender = {
        let counts = Arc::clone(&counts);
        std::thread::Builder::new()
            .name("link-sender".to_string())
            .spawn(move || send_all(&rx, &publishers, &counts))
            .map_err(LinkError::Thread)?
    };
    let lock = |counts: &Mutex<LinkCounts>| {
        counts
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .clone()
    };
    let (scale, every) = (config.image_scale, u64::from(config.image_every));
    let mut next_write = Instant::now();
    let mut batch = Vec::new();
    while !shutdown.requested() {
        wake.wait(WAKE_TIMEOUT)?;
        drain(&mut inlets.frames, &mut batch, |header, pixels| {
            if header.frame_id % every != 0 {
                return None;
            }
            let (pixels, width, height) = shrink(pixels, header.width, header.height, scale)?;
            Some(Message::Image {
                header: *header,
                scale,
                width,
                height,
                pixels,
            })
        })?;
        drain(&mut inlets.segments, &mut batch, |header, s| {
            Some(Message::Segments {
                header: *header,
                segments: s.to_vec(),
            })
        })?;
        drain(&mut inlets.tracks, &mut batch, |header, t| {
            Some(Message::Tracks {
                header: *header,
                tracks: t.to_vec(),
            })
        })?;
        let before_poses = batch.len();
        drain(&mut inlets.poses, &mut batch, |header, p| {
            Some(Message::Pose {
                header: *header,
                pose: Box::new(*p.first()?),
            })
        })?;
        let mut frames = (batch.len() - before_poses) as u64;
        if let Some(inlet) = &mut frame_counter {
            frames += inlet.receive_all()?.len() as u64;
        }
        drain(&mut inlets.status, &mut batch, |_, r| {
            Some(Message::Status {
                report: *r.first()?,
            })
        })?;
        let mut dropped = Vec::new();
        for message in batch.drain(..) {
            let topic = message.topic();
            match message.encode() {
                Ok(bytes) => match tx.try_send((topic, bytes)) {
                    Ok(()) => {}
                    Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                        dropped.push(topic)
                    }
                },
                Err(e) => tracing::warn!("link: {e}"),
            }
        }
        {
            let mut c = counts.lock().unwrap_or_else(|p| p.into_inner());
            c.frames += frames;
            for topic in dropped {
                c.topic(topic).dropped += 1;
            }
        }
        if Instant::now() >= next_write {
            if let Err(e) = lock(&counts).write(counts_path) {
                tracing::warn!("link: {e}");
            }
            next_write = Instant::now() + COUNTS_EVERY;
        }
    }
    drop(tx);
    // The sender ends with its queue: at most a blocked put's wait (zenoh closes a link
    // that stays congested).
    let _ = sender.join();
    let counts = lock(&counts);
    counts.write(counts_path)?;
    let _ = session.close().wait();
    Ok(counts)
}

/// The sender thread: puts each queued message on its topic's publisher until the queue
/// closes.
fn send_all(
    rx: &Receiver<(&'static str, Vec<u8>)>,
    publishers: &BTreeMap<String, zenoh::pubsub::Publisher<'static>>,
    counts: &Mutex<LinkCounts>,
) {
    for (topic, bytes) in rx {
        let Some(publisher) = publishers.get(topic) else {
            continue;
        };
        let heard = publisher
            .matching_status()
            .wait()
            .is_ok_and(|s| s.matching());
        let len = bytes.len() as u64;
        let sent = heard && publisher.put(bytes).wait().is_ok();
        let mut c = counts.lock().unwrap_or_else(|p| p.into_inner());
        let t = c.topic(topic);
        if sent {
            t.sent += 1;
            t.bytes += len;
        } else {
            t.unheard += 1;
        }
    }
}
