//! MCAP recordings of pipeline runs, and reading their stereo frames back.
//!
//! [`Recording`] writes one `.mcap` file: the stereo images as Foxglove `RawImage`s
//! (`mono8`, exactly the bytes the frame source published), the rectified rig as two
//! Foxglove `CameraCalibration`s, the detected segments and the matches as Foxglove
//! `ImageAnnotations`, the poses as Foxglove `PoseInFrame`s (all protobuf), and each
//! frame's stage latencies and the stages' events as JSON with a JSON schema. The file is
//! indexed and has its summary once [`Recording::finish`] ran.
//!
//! [`Replay`] opens such a file, checks that it holds what a replay needs (both images'
//! channels with the Foxglove schema, the rig) and hands the stereo frames back in order
//! ([`Replay::for_each_frame`]).

use foxglove::messages::{
    CameraCalibration, Color, ImageAnnotations, Point2, PointsAnnotation, Pose, PoseInFrame,
    Quaternion, RawImage, Timestamp, Vector3, points_annotation,
};
use foxglove::{Decode, Encode};
use linetrack_msgs::{
    FrameHeader, PoseRecord, RigRecord, SegmentRecord, SegmentsHeader, StageKind, StatusReport,
    TrackedLine,
};
use mcap::records::MessageHeader;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// The left camera's images.
pub const LEFT_IMAGE: &str = "/cam0/image";
/// The right camera's images.
pub const RIGHT_IMAGE: &str = "/cam1/image";
/// The left camera's rectified calibration.
pub const LEFT_CALIBRATION: &str = "/cam0/calibration";
/// The right camera's rectified calibration (its projection holds the baseline).
pub const RIGHT_CALIBRATION: &str = "/cam1/calibration";
/// Segments detected in the left image.
pub const LEFT_SEGMENTS: &str = "/cam0/segments";
/// Segments detected in the right image.
pub const RIGHT_SEGMENTS: &str = "/cam1/segments";
/// The left image's segments coloured by what they were matched to.
pub const LEFT_MATCHES: &str = "/cam0/matches";
/// The right segments the left ones were stereo-matched to.
pub const RIGHT_MATCHES: &str = "/cam1/matches";
/// The left camera's pose in the first frame's world.
pub const POSE: &str = "/pose";
/// Each frame's per-stage and end-to-end latency (JSON).
pub const LATENCY: &str = "/latency";
/// The stages' events (JSON): ready, overflow, gaps, camera lost, exits.
pub const EVENTS: &str = "/events";

/// The coordinate frame of the left camera (Foxglove `frame_id`).
pub const LEFT_FRAME: &str = "cam0";
/// The coordinate frame of the right camera.
pub const RIGHT_FRAME: &str = "cam1";
/// The world frame of the poses: the first frame's left camera.
pub const WORLD_FRAME: &str = "world";

/// Name of the JSON schema of [`LATENCY`].
pub const LATENCY_SCHEMA: &str = "linetrack.FrameLatency";
/// Name of the JSON schema of [`EVENTS`].
pub const EVENT_SCHEMA: &str = "linetrack.StageEvent";

/// Recording and replay errors; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum McapError {
    /// The file could not be created, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The MCAP library refused the file or a record.
    #[error("{}: not a readable MCAP file: {source}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// The library's reason.
        source: mcap::McapError,
    },
    /// The file has no summary: it was not closed (a crashed recorder, a copy cut short).
    #[error(
        "{}: truncated or not closed: no MCAP footer/summary (the recorder did not finish it)",
        path.display()
    )]
    Truncated {
        /// The file.
        path: PathBuf,
    },
    /// A channel the replay needs is missing or carries another schema.
    #[error("{}: {message}", path.display())]
    Content {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A message could not be encoded.
    #[error("encoding a {schema} message: {message}")]
    Encode {
        /// The schema.
        schema: &'static str,
        /// Why.
        message: String,
    },
}

/// One frame's latencies, as the [`LATENCY`] channel holds them (milliseconds; a stage
/// that did not handle the frame has none).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct FrameLatency {
    /// The frame.
    pub frame_id: u64,
    /// `ok`, or the reason it was dropped (`dropped-late`, …).
    pub outcome: String,
    /// Frame source, line detector, matcher, pose estimator: publish − take, ms.
    pub stages_ms: BTreeMap<String, f64>,
    /// Capture to the pose estimator's publish, ms.
    pub end_to_end_ms: f64,
}

impl FrameLatency {
    /// The latencies `header` (a pose message's) records.
    pub fn of(header: &FrameHeader) -> Self {
        let mut stages_ms = BTreeMap::new();
        for stage in StageKind::PROCESSING {
            if let Some(i) = stage.stamp_index() {
                let s = header.stamps[i];
                if s.end_ns >= s.start_ns && s.start_ns > 0 {
                    stages_ms.insert(
                        stage.name().to_string(),
                        (s.end_ns - s.start_ns) as f64 * 1e-6,
                    );
                }
            }
        }
        let last = header.stamps.iter().map(|s| s.end_ns).max().unwrap_or(0);
        Self {
            frame_id: header.frame_id,
            outcome: header
                .status
                .get()
                .map_or_else(|unknown| unknown.to_string(), |s| s.name().to_string()),
            stages_ms,
            end_to_end_ms: header.age_ms(last),
        }
    }
}

const LATENCY_JSON_SCHEMA: &str = r#"{"type":"object","properties":{"frame_id":{"type":"integer"},"outcome":{"type":"string"},"stages_ms":{"type":"object","additionalProperties":{"type":"number"}},"end_to_end_ms":{"type":"number"}},"required":["frame_id","outcome","stages_ms","end_to_end_ms"]}"#;
const EVENT_JSON_SCHEMA: &str = r#"{"type":"object","properties":{"stage":{"type":"string"},"pid":{"type":"integer"},"kind":{"type":"integer"},"detail":{"type":"integer"},"frame_id":{"type":"integer"},"value":{"type":"integer"}},"required":["stage","pid","kind","frame_id","value"]}"#;

/// A stage event as the [`EVENTS`] channel holds it.
#[derive(Debug, Clone, Serialize)]
struct StageEvent {
    stage: String,
    pid: u32,
    kind: u32,
    detail: u32,
    frame_id: u64,
    value: u64,
}

/// What the recording holds, counted as it is written.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Counts {
    /// Stereo frames whose two images were written.
    pub images: u64,
    /// Frames whose images were left out by `every_nth_image`.
    pub images_decimated: u64,
    /// Frames with segments written.
    pub segments: u64,
    /// Frames with matches written.
    pub matches: u64,
    /// Poses written (tracked or predicted).
    pub poses: u64,
    /// Latency records written (every frame that got an outcome).
    pub latencies: u64,
    /// Stage events written.
    pub events: u64,
}

/// An MCAP file being written.
pub struct Recording {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    channels: HashMap<&'static str, u16>,
    sequence: HashMap<&'static str, u32>,
    rig: Option<RigRecord>,
    counts: Counts,
}

fn timestamp(ns: u64) -> Timestamp {
    Timestamp::new(
        u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
        (ns % 1_000_000_000) as u32,
    )
}

fn encode<M: Encode>(message: &M, schema: &'static str) -> Result<Vec<u8>, McapError> {
    let mut buf = Vec::with_capacity(message.encoded_len().unwrap_or(256));
    message.encode(&mut buf).map_err(|e| McapError::Encode {
        schema,
        message: e.to_string(),
    })?;
    Ok(buf)
}

/// Segment end points as a Foxglove line list, one colour per segment.
fn line_list(
    segments: impl Iterator<Item = ([f32; 4], Color)>,
    thickness: f64,
) -> PointsAnnotation {
    let mut points = Vec::new();
    let mut colors = Vec::new();
    for (e, color) in segments {
        points.push(Point2 {
            x: f64::from(e[0]),
            y: f64::from(e[1]),
        });
        points.push(Point2 {
            x: f64::from(e[2]),
            y: f64::from(e[3]),
        });
        colors.push(color);
        colors.push(color);
    }
    PointsAnnotation {
        r#type: points_annotation::Type::LineList as i32,
        points,
        outline_colors: colors,
        thickness,
        ..Default::default()
    }
}

const fn rgb(r: f64, g: f64, b: f64) -> Color {
    Color { r, g, b, a: 1.0 }
}
/// Detected segments.
const DETECTED: Color = rgb(0.2, 0.6, 1.0);
/// Stereo-matched and tracked from the previous frame.
const TRACKED: Color = rgb(0.1, 0.9, 0.2);
/// Stereo-matched only.
const STEREO_ONLY: Color = rgb(1.0, 0.8, 0.0);
/// Not stereo-matched.
const UNMATCHED: Color = rgb(0.9, 0.1, 0.1);

impl Recording {
    /// Creates `path` (its folder must exist) with every channel declared.
    pub fn create(path: &Path) -> Result<Self, McapError> {
        let io = |source| McapError::Io {
            path: path.to_path_buf(),
            source,
        };
        let format = |source| McapError::Format {
            path: path.to_path_buf(),
            source,
        };
        let file = File::create(path).map_err(io)?;
        let mut writer = mcap::WriteOptions::new()
            .compression(None)
            .profile("")
            .library("linetrack-recorder")
            .create(BufWriter::new(file))
            .map_err(format)?;
        let mut channels = HashMap::new();
        let mut add = |topic: &'static str,
                       schema: Option<foxglove::Schema>,
                       json: Option<(&str, &str)>|
         -> Result<(), McapError> {
            let (schema_id, encoding) = match (schema, json) {
                (Some(s), _) => (
                    writer
                        .add_schema(&s.name, &s.encoding, &s.data)
                        .map_err(format)?,
                    "protobuf",
                ),
                (None, Some((name, text))) => (
                    writer
                        .add_schema(name, "jsonschema", text.as_bytes())
                        .map_err(format)?,
                    "json",
                ),
                (None, None) => (0, "json"),
            };
            let id = writer
                .add_channel(schema_id, topic, encoding, &BTreeMap::new())
                .map_err(format)?;
            channels.insert(topic, id);
            Ok(())
        };
        for topic in [LEFT_IMAGE, RIGHT_IMAGE] {
            add(topic, RawImage::get_schema(), None)?;
        }
        for topic in [LEFT_CALIBRATION, RIGHT_CALIBRATION] {
            add(topic, CameraCalibration::get_schema(), None)?;
        }
        for topic in [LEFT_SEGMENTS, RIGHT_SEGMENTS, LEFT_MATCHES, RIGHT_MATCHES] {
            add(topic, ImageAnnotations::get_schema(), None)?;
        }
        add(POSE, PoseInFrame::get_schema(), None)?;
        add(LATENCY, None, Some((LATENCY_SCHEMA, LATENCY_JSON_SCHEMA)))?;
        add(EVENTS, None, Some((EVENT_SCHEMA, EVENT_JSON_SCHEMA)))?;
        Ok(Self {
            path: path.to_path_buf(),
            writer,
            channels,
            sequence: HashMap::new(),
            rig: None,
            counts: Counts::default(),
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What was written so far.
    pub fn counts(&self) -> Counts {
        self.counts
    }

    fn write(
        &mut self,
        topic: &'static str,
        sequence: Option<u32>,
        log_ns: u64,
        publish_ns: u64,
        data: &[u8],
    ) -> Result<(), McapError> {
        let channel_id = self.channels.get(topic).copied().unwrap_or_default();
        let counter = self.sequence.entry(topic).or_default();
        let sequence = sequence.unwrap_or(*counter);
        *counter = counter.wrapping_add(1);
        self.writer
            .write_to_known_channel(
                &MessageHeader {
                    channel_id,
                    sequence,
                    log_time: log_ns,
                    publish_time: publish_ns,
                },
                data,
            )
            .map_err(|source| McapError::Format {
                path: self.path.clone(),
                source,
            })
    }

    /// Encodes and writes `message` about the frame of `header` on `topic`: its sequence
    /// number the frame id, its log time the sequence's timestamp, its publish time the
    /// capture time.
    fn write_of_frame<M: Encode>(
        &mut self,
        topic: &'static str,
        header: &FrameHeader,
        message: &M,
        schema: &'static str,
    ) -> Result<(), McapError> {
        let data = encode(message, schema)?;
        let sequence = u32::try_from(header.frame_id).ok();
        self.write(
            topic,
            sequence,
            header.sequence_ns,
            header.capture_ns,
            &data,
        )
    }

    /// Writes the rig as the two cameras' calibrations (rectified: no distortion, the
    /// right camera's projection `Tx = −f·B`), unless it is the rig already written.
    pub fn rig(&mut self, rig: &RigRecord, log_ns: u64) -> Result<(), McapError> {
        if self.rig == Some(*rig) {
            return Ok(());
        }
        self.rig = Some(*rig);
        let f = rig.focal_px;
        let k = vec![f, 0.0, rig.cx_px, 0.0, f, rig.cy_px, 0.0, 0.0, 1.0];
        let identity = vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        for (topic, frame, tx) in [
            (LEFT_CALIBRATION, LEFT_FRAME, 0.0),
            (RIGHT_CALIBRATION, RIGHT_FRAME, -f * rig.baseline_m),
        ] {
            let calibration = CameraCalibration {
                timestamp: Some(timestamp(log_ns)),
                frame_id: frame.to_string(),
                width: rig.width_px,
                height: rig.height_px,
                distortion_model: "plumb_bob".to_string(),
                d: vec![0.0; 5],
                k: k.clone(),
                r: identity.clone(),
                p: vec![
                    f, 0.0, rig.cx_px, tx, 0.0, f, rig.cy_px, 0.0, 0.0, 0.0, 1.0, 0.0,
                ],
            };
            let data = encode(&calibration, "foxglove.CameraCalibration")?;
            self.write(topic, None, log_ns, log_ns, &data)?;
        }
        Ok(())
    }

    /// Writes a frame's two images (`pixels`: the left image then the right one, row-major
    /// mono8, as the frames topic carries them). The message's sequence number is the
    /// frame id, its log time the sequence's timestamp.
    pub fn images(&mut self, header: &FrameHeader, pixels: &[u8]) -> Result<(), McapError> {
        let (w, h) = (header.width as usize, header.height as usize);
        let size = w * h;
        if size == 0 || pixels.len() != 2 * size {
            return Err(McapError::Content {
                path: self.path.clone(),
                message: format!(
                    "frame {}: {} bytes of pixels for two {w}×{h} images",
                    header.frame_id,
                    pixels.len()
                ),
            });
        }
        for (topic, frame, image) in [
            (LEFT_IMAGE, LEFT_FRAME, &pixels[..size]),
            (RIGHT_IMAGE, RIGHT_FRAME, &pixels[size..]),
        ] {
            let message = RawImage {
                timestamp: Some(timestamp(header.sequence_ns)),
                frame_id: frame.to_string(),
                width: header.width,
                height: header.height,
                encoding: "mono8".to_string(),
                step: header.width,
                data: foxglove::bytes::Bytes::copy_from_slice(image),
            };
            self.write_of_frame(topic, header, &message, "foxglove.RawImage")?;
        }
        self.counts.images += 1;
        Ok(())
    }

    /// Counts a frame whose images are left out (decimation).
    pub fn skip_images(&mut self) {
        self.counts.images_decimated += 1;
    }

    /// Writes a frame's detected segments (left then right, as the segments topic holds
    /// them: the detection's `left_count` left ones).
    pub fn segments(
        &mut self,
        message: &SegmentsHeader,
        segments: &[SegmentRecord],
    ) -> Result<(), McapError> {
        let header = &message.frame;
        let split = (message.detection.left_count as usize).min(segments.len());
        for (topic, side) in [
            (LEFT_SEGMENTS, &segments[..split]),
            (RIGHT_SEGMENTS, &segments[split..]),
        ] {
            let message = ImageAnnotations {
                timestamp: Some(timestamp(header.sequence_ns)),
                points: vec![line_list(side.iter().map(|s| (s.endpoints, DETECTED)), 2.0)],
                ..Default::default()
            };
            self.write_of_frame(topic, header, &message, "foxglove.ImageAnnotations")?;
        }
        self.counts.segments += 1;
        Ok(())
    }

    /// Writes a frame's matches: on the left image every segment, green when stereo-matched
    /// and tracked from the previous frame, yellow when stereo-matched only, red when not
    /// stereo-matched; on the right image the stereo partners.
    pub fn matches(
        &mut self,
        header: &FrameHeader,
        lines: &[TrackedLine],
    ) -> Result<(), McapError> {
        let left = lines.iter().map(|l| {
            let color = match (l.has_stereo == 1, l.previous >= 0) {
                (true, true) => TRACKED,
                (true, false) => STEREO_ONLY,
                (false, _) => UNMATCHED,
            };
            (l.left, color)
        });
        let right = lines.iter().filter(|l| l.has_stereo == 1).map(|l| {
            (
                l.right,
                if l.previous >= 0 {
                    TRACKED
                } else {
                    STEREO_ONLY
                },
            )
        });
        for (topic, annotation) in [
            (LEFT_MATCHES, line_list(left, 2.0)),
            (RIGHT_MATCHES, line_list(right, 2.0)),
        ] {
            let message = ImageAnnotations {
                timestamp: Some(timestamp(header.sequence_ns)),
                points: vec![annotation],
                ..Default::default()
            };
            self.write_of_frame(topic, header, &message, "foxglove.ImageAnnotations")?;
        }
        self.counts.matches += 1;
        Ok(())
    }

    /// Writes a frame's outcome: its latencies, and its pose when it got one.
    pub fn outcome(
        &mut self,
        header: &FrameHeader,
        pose: Option<&PoseRecord>,
    ) -> Result<(), McapError> {
        let sequence = u32::try_from(header.frame_id).ok();
        if let Some(p) = pose.filter(|_| header.is_ok()) {
            let message = PoseInFrame {
                timestamp: Some(timestamp(header.sequence_ns)),
                frame_id: WORLD_FRAME.to_string(),
                pose: Some(Pose {
                    position: Some(Vector3 {
                        x: p.translation[0],
                        y: p.translation[1],
                        z: p.translation[2],
                    }),
                    orientation: Some(Quaternion {
                        x: p.rotation_xyzw[0],
                        y: p.rotation_xyzw[1],
                        z: p.rotation_xyzw[2],
                        w: p.rotation_xyzw[3],
                    }),
                }),
            };
            self.write_of_frame(POSE, header, &message, "foxglove.PoseInFrame")?;
            self.counts.poses += 1;
        }
        let latency =
            serde_json::to_vec(&FrameLatency::of(header)).map_err(|e| McapError::Encode {
                schema: LATENCY_SCHEMA,
                message: e.to_string(),
            })?;
        self.write(
            LATENCY,
            sequence,
            header.sequence_ns,
            header.capture_ns,
            &latency,
        )?;
        self.counts.latencies += 1;
        Ok(())
    }

    /// Writes a stage's event (heartbeats are not events: the caller leaves them out).
    pub fn event(&mut self, report: &StatusReport, now_ns: u64) -> Result<(), McapError> {
        let event = StageEvent {
            stage: report.stage.get().map_or_else(
                |_| format!("stage {}", report.stage.raw()),
                |s| s.name().to_string(),
            ),
            pid: report.pid,
            kind: report.kind.raw(),
            detail: report.detail,
            frame_id: report.frame_id,
            value: report.value,
        };
        let data = serde_json::to_vec(&event).map_err(|e| McapError::Encode {
            schema: EVENT_SCHEMA,
            message: e.to_string(),
        })?;
        self.write(EVENTS, None, now_ns, now_ns, &data)?;
        self.counts.events += 1;
        Ok(())
    }

    /// Writes `name` → `values` as an MCAP metadata record (the recorder's counts).
    pub fn metadata(
        &mut self,
        name: &str,
        values: BTreeMap<String, String>,
    ) -> Result<(), McapError> {
        self.writer
            .write_metadata(&mcap::records::Metadata {
                name: name.to_string(),
                metadata: values,
            })
            .map_err(|source| McapError::Format {
                path: self.path.clone(),
                source,
            })
    }

    /// Closes the file: the last chunk, the index and the summary.
    pub fn finish(mut self) -> Result<Counts, McapError> {
        self.writer.finish().map_err(|source| McapError::Format {
            path: self.path.clone(),
            source,
        })?;
        Ok(self.counts)
    }
}

/// One stereo frame read back from a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayFrame {
    /// The frame id of the recorded run.
    pub frame_id: u64,
    /// The sequence's timestamp, ns.
    pub timestamp_ns: u64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Left image then right image, row-major mono8.
    pub pixels: Vec<u8>,
}

/// A recording opened for replay: checked, its rig read.
pub struct Replay {
    path: PathBuf,
    bytes: Vec<u8>,
    /// The rectified rig the frames were recorded with.
    pub rig: RigRecord,
    /// Stereo frames (both images present) in the file.
    pub frames: usize,
}

fn expect_schema(path: &Path, channel: &mcap::Channel<'_>, schema: &str) -> Result<(), McapError> {
    let found = channel.schema.as_ref().map(|s| s.name.as_str());
    if found != Some(schema) || channel.message_encoding != "protobuf" {
        return Err(McapError::Content {
            path: path.to_path_buf(),
            message: format!(
                "channel {} has schema {} ({}), not {schema} (protobuf)",
                channel.topic,
                found.unwrap_or("none"),
                channel.message_encoding
            ),
        });
    }
    Ok(())
}

impl Replay {
    /// Reads and checks `path`: a complete MCAP file (with its summary) whose image and
    /// calibration channels carry the Foxglove schemas, with a rig and at least one stereo
    /// frame. The whole file is read into memory.
    pub fn open(path: &Path) -> Result<Self, McapError> {
        let bytes = std::fs::read(path).map_err(|source| McapError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let format = |source| McapError::Format {
            path: path.to_path_buf(),
            source,
        };
        let content = |message: String| McapError::Content {
            path: path.to_path_buf(),
            message,
        };
        if !bytes.starts_with(mcap::MAGIC) {
            return Err(content(
                "not an MCAP file (no MCAP magic at its start)".to_string(),
            ));
        }
        let summary = match mcap::Summary::read(&bytes) {
            Ok(Some(summary)) => summary,
            Ok(None) | Err(_) => {
                return Err(McapError::Truncated {
                    path: path.to_path_buf(),
                });
            }
        };
        let by_topic: HashMap<&str, &mcap::Channel<'_>> = summary
            .channels
            .values()
            .map(|c| (c.topic.as_str(), c.as_ref()))
            .collect();
        for (topic, schema) in [
            (LEFT_IMAGE, "foxglove.RawImage"),
            (RIGHT_IMAGE, "foxglove.RawImage"),
            (LEFT_CALIBRATION, "foxglove.CameraCalibration"),
            (RIGHT_CALIBRATION, "foxglove.CameraCalibration"),
        ] {
            let channel = by_topic
                .get(topic)
                .ok_or_else(|| content(format!("no {topic} channel: not a linetrack recording")))?;
            expect_schema(path, channel, schema)?;
        }
        let count = |topic: &str| {
            let id = by_topic.get(topic).map(|c| c.id);
            summary
                .stats
                .as_ref()
                .and_then(|s| id.and_then(|id| s.channel_message_counts.get(&id)))
                .copied()
                .unwrap_or(0)
        };
        let frames = count(LEFT_IMAGE).min(count(RIGHT_IMAGE));
        if frames == 0 {
            return Err(content(
                "no stereo images: recorded with every_nth_image = 0?".to_string(),
            ));
        }
        let (mut left, mut right) = (None, None);
        for message in mcap::MessageStream::new(&bytes).map_err(format)? {
            let message = message.map_err(format)?;
            let topic = message.channel.topic.as_str();
            if topic == LEFT_CALIBRATION || topic == RIGHT_CALIBRATION {
                let c = CameraCalibration::decode(message.data.as_ref())
                    .map_err(|e| content(format!("{topic}: undecodable CameraCalibration: {e}")))?;
                if topic == LEFT_CALIBRATION {
                    left = Some(c);
                } else {
                    right = Some(c);
                }
            }
            if left.is_some() && right.is_some() {
                break;
            }
        }
        let (Some(left), Some(right)) = (left, right) else {
            return Err(content(
                "no calibration message: the rig is missing".to_string(),
            ));
        };
        let rig = rig_of(&left, &right).map_err(content)?;
        Ok(Self {
            path: path.to_path_buf(),
            bytes,
            rig,
            frames: usize::try_from(frames).unwrap_or(usize::MAX),
        })
    }

    /// Calls `each` with every stereo frame in frame-id order (a frame whose other image is
    /// missing is left out); stops early when `each` returns `false`. Returns how many
    /// frames were handed over.
    pub fn for_each_frame(
        &self,
        mut each: impl FnMut(ReplayFrame) -> bool,
    ) -> Result<usize, McapError> {
        let format = |source| McapError::Format {
            path: self.path.clone(),
            source,
        };
        let content = |message: String| McapError::Content {
            path: self.path.clone(),
            message,
        };
        // Images of frames whose other image has not been read yet.
        let mut pending: BTreeMap<u32, (Option<RawImage>, Option<RawImage>, u64)> = BTreeMap::new();
        let mut handed = 0;
        for message in mcap::MessageStream::new(&self.bytes).map_err(format)? {
            let message = message.map_err(format)?;
            let topic = message.channel.topic.as_str();
            let left = topic == LEFT_IMAGE;
            if !left && topic != RIGHT_IMAGE {
                continue;
            }
            let image = RawImage::decode(message.data.as_ref()).map_err(|e| {
                content(format!(
                    "{topic} message {}: undecodable RawImage: {e}",
                    message.sequence
                ))
            })?;
            if image.encoding != "mono8"
                || image.step != image.width
                || image.data.len() != image.width as usize * image.height as usize
            {
                return Err(content(format!(
                    "{topic} message {}: a {}×{} {} image with step {} and {} bytes: replay needs unpadded mono8",
                    message.sequence,
                    image.width,
                    image.height,
                    image.encoding,
                    image.step,
                    image.data.len()
                )));
            }
            let entry = pending
                .entry(message.sequence)
                .or_insert((None, None, message.log_time));
            if left {
                entry.0 = Some(image);
            } else {
                entry.1 = Some(image);
            }
            if let (Some(_), Some(_), _) = entry
                && let Some((Some(l), Some(r), log_time)) = pending.remove(&message.sequence)
            {
                if (l.width, l.height) != (r.width, r.height) {
                    return Err(content(format!(
                        "frame {}: left image {}×{}, right image {}×{}",
                        message.sequence, l.width, l.height, r.width, r.height
                    )));
                }
                let mut pixels = Vec::with_capacity(l.data.len() * 2);
                pixels.extend_from_slice(&l.data);
                pixels.extend_from_slice(&r.data);
                handed += 1;
                let go_on = each(ReplayFrame {
                    frame_id: u64::from(message.sequence),
                    timestamp_ns: log_time,
                    width: l.width,
                    height: l.height,
                    pixels,
                });
                if !go_on {
                    break;
                }
            }
        }
        Ok(handed)
    }
}

/// The rig of a left and a right rectified calibration.
fn rig_of(left: &CameraCalibration, right: &CameraCalibration) -> Result<RigRecord, String> {
    let (Some(&f), Some(&cx), Some(&cy), Some(&tx)) =
        (left.p.first(), left.p.get(2), left.p.get(6), right.p.get(3))
    else {
        return Err("a CameraCalibration without its 3×4 projection P".to_string());
    };
    let baseline_m = -tx / f;
    if !(f > 0.0) || !(baseline_m > 0.0) || !f.is_finite() || !baseline_m.is_finite() {
        return Err(format!(
            "calibration gives focal {f} px and baseline {baseline_m} m: not a rectified stereo rig"
        ));
    }
    Ok(RigRecord {
        focal_px: f,
        cx_px: cx,
        cy_px: cy,
        baseline_m,
        width_px: left.width,
        height_px: left.height,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("linetrack-mcap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_default();
        dir.join(name)
    }

    fn rig() -> RigRecord {
        RigRecord {
            focal_px: 435.2,
            cx_px: 367.4,
            cy_px: 252.2,
            baseline_m: 0.11,
            width_px: 4,
            height_px: 3,
        }
    }

    fn header(frame_id: u64) -> FrameHeader {
        let mut h = FrameHeader::new(frame_id, 1_000 + frame_id * 50_000_000, 7);
        h.width = 4;
        h.height = 3;
        h
    }

    fn record(path: &Path, frames: u64) -> Counts {
        let mut r = Recording::create(path).expect("create");
        r.rig(&rig(), 0).expect("rig");
        r.rig(&rig(), 1).expect("the same rig again");
        for id in 0..frames {
            let pixels: Vec<u8> = (0..24).map(|i| (i as u64 * 3 + id) as u8).collect();
            r.images(&header(id), &pixels).expect("images");
            let h = header(id);
            let mut detected = SegmentsHeader::from(h);
            detected.detection.left_count = 1;
            let segs = [
                SegmentRecord {
                    endpoints: [0.0, 0.0, 3.0, 2.0],
                },
                SegmentRecord {
                    endpoints: [1.0, 0.0, 3.0, 2.0],
                },
            ];
            r.segments(&detected, &segs).expect("segments");
            r.matches(&h, &[TrackedLine::default()]).expect("matches");
            r.outcome(&h, Some(&PoseRecord::default())).expect("pose");
        }
        r.finish().expect("finish")
    }

    #[test]
    fn a_recording_replays_its_frames_and_rig_exactly() {
        let path = temp("round-trip.mcap");
        let counts = record(&path, 3);
        assert_eq!(counts.images, 3);
        assert_eq!(counts.poses, 3);
        let replay = Replay::open(&path).expect("open");
        assert_eq!(replay.rig, rig());
        assert_eq!(replay.frames, 3);
        let mut frames = Vec::new();
        replay
            .for_each_frame(|f| {
                frames.push(f);
                true
            })
            .expect("frames");
        assert_eq!(frames.len(), 3);
        for (id, f) in frames.iter().enumerate() {
            assert_eq!(f.frame_id, id as u64);
            assert_eq!(f.timestamp_ns, header(id as u64).sequence_ns);
            let expected: Vec<u8> = (0..24).map(|i| (i * 3 + id) as u8).collect();
            assert_eq!(f.pixels, expected);
        }
    }

    #[test]
    fn a_truncated_recording_is_refused_as_such() {
        let path = temp("truncated.mcap");
        record(&path, 2);
        let bytes = std::fs::read(&path).expect("read");
        std::fs::write(&path, &bytes[..bytes.len() * 2 / 3]).expect("write");
        let error = Replay::open(&path).err().expect("refused");
        assert!(matches!(error, McapError::Truncated { .. }), "{error}");
        assert!(error.to_string().contains("truncated.mcap"), "{error}");
    }

    #[test]
    fn a_file_that_is_no_mcap_is_refused_naming_it() {
        let path = temp("garbage.mcap");
        std::fs::write(&path, b"P5\n4 3\n255\n").expect("write");
        let error = Replay::open(&path).err().expect("refused");
        assert!(error.to_string().contains("not an MCAP file"), "{error}");
    }

    #[test]
    fn images_under_another_schema_are_refused_naming_the_channel() {
        let path = temp("wrong-schema.mcap");
        {
            let file = File::create(&path).expect("create");
            let mut w = mcap::Writer::new(BufWriter::new(file)).expect("writer");
            let schema = w
                .add_schema("my.Image", "jsonschema", b"{}")
                .expect("schema");
            for topic in [LEFT_IMAGE, RIGHT_IMAGE] {
                let id = w
                    .add_channel(schema, topic, "json", &BTreeMap::new())
                    .expect("channel");
                w.write_to_known_channel(
                    &MessageHeader {
                        channel_id: id,
                        sequence: 0,
                        log_time: 0,
                        publish_time: 0,
                    },
                    b"{}",
                )
                .expect("message");
            }
            w.finish().expect("finish");
        }
        let error = Replay::open(&path).err().expect("refused");
        let text = error.to_string();
        assert!(
            text.contains("/cam0/image") && text.contains("my.Image"),
            "{text}"
        );
    }

    #[test]
    fn latencies_are_each_stage_s_publish_minus_take() {
        let mut h = header(4);
        h.capture_ns = 1_000_000;
        h.stamps[0] = linetrack_msgs::StageStamp {
            start_ns: 1_000_000,
            end_ns: 1_500_000,
        };
        h.stamps[3] = linetrack_msgs::StageStamp {
            start_ns: 2_000_000,
            end_ns: 5_000_000,
        };
        let l = FrameLatency::of(&h);
        assert_eq!(l.stages_ms.get("frame-source"), Some(&0.5));
        assert_eq!(l.stages_ms.get("pose-estimator"), Some(&3.0));
        assert!(!l.stages_ms.contains_key("matcher"));
        assert_eq!(l.end_to_end_ms, 4.0);
        assert_eq!(l.outcome, "ok");
    }
}
