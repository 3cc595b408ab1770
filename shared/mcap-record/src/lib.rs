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

use std::path::PathBuf;

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
mod messages;
mod record;
mod replay;

pub use messages::FrameLatency;
pub use record::{Counts, Recording};
pub use replay::{Replay, ReplayFrame};

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::StampSlot;
    use linetrack_msgs::{
        FrameHeader, PoseRecord, RigRecord, SegmentRecord, SegmentsHeader, TrackedLine,
    };
    use linetrack_test_data::Scratch;
    use mcap::records::MessageHeader;
    use std::collections::BTreeMap;
    use std::fs::File;
    use std::io::BufWriter;
    use std::path::Path;

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
        let dir = Scratch::new("mcap", "round-trip");
        let path = dir.join("round-trip.mcap");
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
        let dir = Scratch::new("mcap", "truncated");
        let path = dir.join("truncated.mcap");
        record(&path, 2);
        let bytes = std::fs::read(&path).expect("read");
        std::fs::write(&path, &bytes[..bytes.len() * 2 / 3]).expect("write");
        let error = Replay::open(&path).err().expect("refused");
        assert!(matches!(error, McapError::Truncated { .. }), "{error}");
        assert!(error.to_string().contains("truncated.mcap"), "{error}");
    }

    #[test]
    fn a_file_that_is_no_mcap_is_refused_naming_it() {
        let dir = Scratch::new("mcap", "garbage");
        let path = dir.join("garbage.mcap");
        std::fs::write(&path, b"P5\n4 3\n255\n").expect("write");
        let error = Replay::open(&path).err().expect("refused");
        assert!(error.to_string().contains("not an MCAP file"), "{error}");
    }

    #[test]
    fn images_under_another_schema_are_refused_naming_the_channel() {
        let dir = Scratch::new("mcap", "wrong-schema");
        let path = dir.join("wrong-schema.mcap");
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
        h.stamps[StampSlot::FrameSource] = linetrack_msgs::StageStamp {
            start_ns: 1_000_000,
            end_ns: 1_500_000,
        };
        h.stamps[StampSlot::PoseEstimator] = linetrack_msgs::StageStamp {
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
