//! The onboard side: what the `linetrack-link` process does with the run's messages.
//!
//! It subscribes to the allowed topics in the run's shared memory and wakes with the
//! supervisor (poses and status wake it: a frame's pose comes after its segments, tracks
//! and images, so each wake-up finds the frame's messages in place). Each message is
//! encoded and handed to the sender thread through a bounded queue; a full queue (the link
//! is stalled) drops the message and counts it. The sender thread owns the zenoh
//! publishers and blocks in zenoh while the link is congested; a message with nobody on the
//! far side to hear it is not sent, and counted as unheard. The counters go to `link.json`
//! in the run folder every second and at the end.

use crate::wire::{Message, key, shrink};
use crate::{LinkError, peer_config};
use crossbeam_channel::{Receiver, Sender, TrySendError};
use linetrack_ipc::{Bus, Inlet, Record};
use linetrack_msgs::{
    FrameHeader, PoseRecord, SegmentRecord, SegmentsHeader, StageKind, StatusReport, TopicOf,
    TrackedLine, TracksHeader, topics,
};
use linetrack_pipeline_config::LinkConfig;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;
use zenoh::qos::CongestionControl;

/// Messages waiting for the sender thread: a stalled link fills it within about a second
/// of frames, then messages are dropped.
const QUEUE: usize = 64;
/// The longest the link sleeps without a wake-up (it also checks for shutdown).
pub const WAKE_TIMEOUT: Duration = Duration::from_millis(100);
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
    topic: TopicOf<P, H>,
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

/// The onboard side of the link, open: the allowed topics' subscribers, the sender thread
/// and its zenoh session. [`Onboard::drain`] forwards what is waiting; [`Onboard::finish`]
/// closes it. The `linetrack-link` process runs it as a sink of the stage runtime, which
/// wakes it with the supervisor (poses and status).
pub struct Onboard {
    inlets: Inlets,
    /// Every frame's pose message, when poses are not forwarded: it counts frames.
    frame_counter: Option<Inlet<PoseRecord, TracksHeader>>,
    counts: Arc<Mutex<LinkCounts>>,
    counts_path: PathBuf,
    tx: Sender<(&'static str, Vec<u8>)>,
    sender: std::thread::JoinHandle<()>,
    session: zenoh::Session,
    scale: u32,
    every: u64,
    next_write: Instant,
    batch: Vec<Message>,
}

impl Onboard {
    /// Opens the link on `bus`: listens on `config.listen`, subscribes to the allowed
    /// topics; the counters go to `counts_path`. Fails when the endpoint cannot be listened
    /// on or the shared memory cannot be joined.
    pub fn open(config: &LinkConfig, bus: &Bus, counts_path: &Path) -> Result<Self, LinkError> {
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
        let inlets = Inlets {
            poses: inlet_if(config, bus, "poses", topics::POSES)?,
            status: inlet_if(config, bus, "status", topics::STATUS)?,
            segments: inlet_if(config, bus, "segments", topics::SEGMENTS)?,
            tracks: inlet_if(config, bus, "tracks", topics::TRACKS)?,
            frames: inlet_if(config, bus, "images", topics::FRAMES)?,
        };
        let frame_counter = match inlets.poses {
            Some(_) => None,
            None => Some(bus.inlet::<PoseRecord, TracksHeader>(topics::POSES)?),
        };
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
        Ok(Self {
            inlets,
            frame_counter,
            counts,
            counts_path: counts_path.to_path_buf(),
            tx,
            sender,
            session,
            scale: config.image_scale,
            every: u64::from(config.image_every),
            next_write: Instant::now(),
            batch: Vec::new(),
        })
    }

    /// The counters so far.
    pub fn counts(&self) -> LinkCounts {
        self.counts
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .clone()
    }

    /// Hands everything waiting to the sender thread (what its full queue cannot take is
    /// dropped and counted); rewrites the counters when they are due.
    pub fn drain(&mut self) -> Result<(), LinkError> {
        let (scale, every) = (self.scale, self.every);
        let (inlets, batch) = (&mut self.inlets, &mut self.batch);
        drain(&mut inlets.frames, batch, |header, pixels| {
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
        drain(&mut inlets.segments, batch, |header, s| {
            Some(Message::Segments {
                header: *header,
                segments: s.to_vec(),
            })
        })?;
        drain(&mut inlets.tracks, batch, |header, t| {
            Some(Message::Tracks {
                header: *header,
                tracks: t.to_vec(),
            })
        })?;
        let before_poses = batch.len();
        drain(&mut inlets.poses, batch, |header, p| {
            Some(Message::Pose {
                header: *header,
                pose: Box::new(*p.first()?),
            })
        })?;
        let mut frames = (batch.len() - before_poses) as u64;
        if let Some(inlet) = &mut self.frame_counter {
            frames += inlet.receive_all()?.len() as u64;
        }
        drain(&mut inlets.status, batch, |_, r| {
            Some(Message::Status {
                report: *r.first()?,
            })
        })?;
        let mut dropped = Vec::new();
        for message in batch.drain(..) {
            let topic = message.topic();
            match message.encode() {
                Ok(bytes) => match self.tx.try_send((topic, bytes)) {
                    Ok(()) => {}
                    Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                        dropped.push(topic)
                    }
                },
                Err(e) => tracing::warn!("link: {e}"),
            }
        }
        {
            let mut c = self.counts.lock().unwrap_or_else(|p| p.into_inner());
            c.frames += frames;
            for topic in dropped {
                c.topic(topic).dropped += 1;
            }
        }
        if Instant::now() >= self.next_write {
            if let Err(e) = self.counts().write(&self.counts_path) {
                tracing::warn!("link: {e}");
            }
            self.next_write = Instant::now() + COUNTS_EVERY;
        }
        Ok(())
    }

    /// Closes the link: the sender sends what is queued, the counters are written a last
    /// time; returns them.
    pub fn finish(self) -> Result<LinkCounts, LinkError> {
        drop(self.tx);
        // The sender ends with its queue: at most a blocked put's wait (zenoh closes a link
        // that stays congested).
        let _ = self.sender.join();
        let counts = self
            .counts
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .clone();
        counts.write(&self.counts_path)?;
        let _ = self.session.close().wait();
        Ok(counts)
    }
}

impl linetrack_stage_runtime::Sink for Onboard {
    const KIND: StageKind = StageKind::Link;
    const WAKES_WITH: StageKind = StageKind::Supervisor;

    fn drain(&mut self) -> anyhow::Result<()> {
        Ok(Onboard::drain(self)?)
    }

    fn count(&self) -> u64 {
        self.counts().frames
    }

    fn max_sleep(&self) -> Duration {
        WAKE_TIMEOUT
    }

    fn finish(self) -> anyhow::Result<()> {
        let counts = Onboard::finish(self)?;
        tracing::info!(
            "link: {} frames; per topic (sent, bytes, dropped, unheard): {}",
            counts.frames,
            counts
                .topics
                .iter()
                .map(|(t, c)| format!("{t} {} {} {} {}", c.sent, c.bytes, c.dropped, c.unheard))
                .collect::<Vec<_>>()
                .join(", ")
        );
        Ok(())
    }
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
