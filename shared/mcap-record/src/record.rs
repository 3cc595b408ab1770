//! [`Recording`]: writing a run into an MCAP file as it happens.

use crate::messages::*;
use crate::{
    EVENT_SCHEMA, EVENTS, LATENCY, LATENCY_SCHEMA, LEFT_CALIBRATION, LEFT_FRAME, LEFT_IMAGE,
    LEFT_MATCHES, LEFT_SEGMENTS, McapError, POSE, RIGHT_CALIBRATION, RIGHT_FRAME, RIGHT_IMAGE,
    RIGHT_MATCHES, RIGHT_SEGMENTS, WORLD_FRAME,
};
use foxglove::Encode;
use foxglove::messages::{
    CameraCalibration, Color, ImageAnnotations, Point2, PointsAnnotation, Pose, PoseInFrame,
    Quaternion, RawImage, Timestamp, Vector3, points_annotation,
};
use linetrack_msgs::{
    FrameHeader, PoseRecord, RigRecord, SegmentRecord, SegmentsHeader, StatusReport, TrackedLine,
};
use mcap::records::MessageHeader;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

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

pub(crate) fn timestamp(ns: u64) -> Timestamp {
    Timestamp::new(
        u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
        (ns % 1_000_000_000) as u32,
    )
}

pub(crate) fn encode<M: Encode>(message: &M, schema: &'static str) -> Result<Vec<u8>, McapError> {
    let mut buf = Vec::with_capacity(message.encoded_len().unwrap_or(256));
    message.encode(&mut buf).map_err(|e| McapError::Encode {
        schema,
        message: e.to_string(),
    })?;
    Ok(buf)
}

/// Segment end points as a Foxglove line list, one colour per segment.
pub(crate) fn line_list(
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

pub(crate) const fn rgb(r: f64, g: f64, b: f64) -> Color {
    Color { r, g, b, a: 1.0 }
}
/// Detected segments.
pub(crate) const DETECTED: Color = rgb(0.2, 0.6, 1.0);
/// Stereo-matched and tracked from the previous frame.
pub(crate) const TRACKED: Color = rgb(0.1, 0.9, 0.2);
/// Stereo-matched only.
pub(crate) const STEREO_ONLY: Color = rgb(1.0, 0.8, 0.0);
/// Not stereo-matched.
pub(crate) const UNMATCHED: Color = rgb(0.9, 0.1, 0.1);

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
