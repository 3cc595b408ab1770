//! What goes on the link: one [`Message`] per zenoh sample, postcard-encoded (integers as
//! varints), under the key `<key_prefix>/<topic>`. Each message carries the header its topic
//! has in shared memory; a code (a stage, a status, a mode) arrives as it was sent and is
//! checked where it is read, as in shared memory.

use crate::LinkError;
use linetrack_msgs::{
    FrameHeader, PoseRecord, SegmentRecord, SegmentsHeader, StatusReport, TrackedLine, TracksHeader,
};
use serde::{Deserialize, Serialize};

/// One forwarded message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Message {
    /// A frame's pose (or its drop: the header's status says).
    Pose {
        /// The frame's header, with the detector's and the matcher's results.
        header: TracksHeader,
        /// The pose (boxed: it carries two covariances, the largest variant by far; the
        /// encoding is the record's).
        pose: Box<PoseRecord>,
    },
    /// A stage's heartbeat or event.
    Status {
        /// The report.
        report: StatusReport,
    },
    /// A frame's segments, left image's then right image's (the detection's `left_count`
    /// splits them).
    Segments {
        /// The frame's header, with the detector's results.
        header: SegmentsHeader,
        /// The segments.
        segments: Vec<SegmentRecord>,
    },
    /// A frame's matched segments.
    Tracks {
        /// The frame's header, with the detector's and the matcher's results.
        header: TracksHeader,
        /// The tracks.
        tracks: Vec<TrackedLine>,
    },
    /// A frame's left image, shrunk.
    Image {
        /// The frame's header (its `width` and `height` are the full image's).
        header: FrameHeader,
        /// The shrink factor in each direction.
        scale: u32,
        /// The shrunk image's width, pixels.
        width: u32,
        /// The shrunk image's height, pixels.
        height: u32,
        /// 8-bit gray, row-major.
        pixels: Vec<u8>,
    },
}

impl Message {
    /// The topic name, as in `[link] topics` and the zenoh key.
    pub fn topic(&self) -> &'static str {
        match self {
            Message::Pose { .. } => "poses",
            Message::Status { .. } => "status",
            Message::Segments { .. } => "segments",
            Message::Tracks { .. } => "tracks",
            Message::Image { .. } => "images",
        }
    }

    /// The frame the message is about (none for a status report).
    pub fn frame(&self) -> Option<&FrameHeader> {
        match self {
            Message::Pose { header, .. } | Message::Tracks { header, .. } => Some(&header.frame),
            Message::Segments { header, .. } => Some(&header.frame),
            Message::Image { header, .. } => Some(header),
            Message::Status { .. } => None,
        }
    }

    /// The bytes sent.
    pub fn encode(&self) -> Result<Vec<u8>, LinkError> {
        postcard::to_stdvec(self).map_err(|e| LinkError::Encode {
            topic: self.topic(),
            message: e.to_string(),
        })
    }

    /// The message in `bytes` received on `key`.
    pub fn decode(key: &str, bytes: &[u8]) -> Result<Self, LinkError> {
        postcard::from_bytes(bytes).map_err(|e| LinkError::Decode {
            key: key.to_string(),
            message: e.to_string(),
        })
    }
}

/// The zenoh key of `topic` under `prefix`.
pub fn key(prefix: &str, topic: &str) -> String {
    format!("{prefix}/{topic}")
}

/// `pixels` (`width` × `height`, 8-bit gray, row-major) shrunk by `scale` in each direction,
/// each output pixel the mean of its `scale` × `scale` block (a partial block at the right
/// or bottom edge is left out); returns the image and its width and height. `None` when
/// `pixels` is shorter than `width` × `height` or `scale` is 0.
pub fn shrink(pixels: &[u8], width: u32, height: u32, scale: u32) -> Option<(Vec<u8>, u32, u32)> {
    let (w, h, s) = (width as usize, height as usize, scale as usize);
    if s == 0 || pixels.len() < w.checked_mul(h)? {
        return None;
    }
    let (ow, oh) = (w / s, h / s);
    let area = (s * s) as u32;
    let mut out = Vec::with_capacity(ow * oh);
    for by in 0..oh {
        for bx in 0..ow {
            let mut sum = 0u32;
            for row in pixels[by * s * w..].chunks(w).take(s) {
                sum += row[bx * s..(bx + 1) * s]
                    .iter()
                    .map(|&p| u32::from(p))
                    .sum::<u32>();
            }
            out.push(((sum + area / 2) / area) as u8);
        }
    }
    Some((out, ow as u32, oh as u32))
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::{MatcherMode, StageKind, StatusKind};

    fn header(frame_id: u64) -> FrameHeader {
        FrameHeader::new(frame_id, 1_403_636_579_763_555_584, 17)
    }

    fn segments_header(frame_id: u64) -> SegmentsHeader {
        let mut h = SegmentsHeader::from(header(frame_id));
        h.detection.left_count = 2;
        h
    }

    fn tracks_header(frame_id: u64) -> TracksHeader {
        let mut h = TracksHeader::from(segments_header(frame_id));
        h.matching.mode = MatcherMode::L1.into();
        h.matching.stereo_matches = 40;
        h
    }

    #[test]
    fn every_message_comes_back_as_it_went() {
        let messages = [
            Message::Pose {
                header: tracks_header(3),
                pose: Box::new(PoseRecord {
                    translation: [0.1, -2.0, 1e-9],
                    rotation_xyzw: [0.0, 0.0, 0.6, 0.8],
                    inliers: [3, 40],
                    rms_px: 0.25,
                    covariance: [1e-4; 21],
                    ..Default::default()
                }),
            },
            Message::Status {
                report: StatusReport {
                    stage: StageKind::LineDetector.into(),
                    pid: 4242,
                    kind: StatusKind::SourceFinished.into(),
                    frame_id: 99,
                    value: 100,
                    ..Default::default()
                },
            },
            Message::Segments {
                header: segments_header(4),
                segments: vec![
                    SegmentRecord {
                        endpoints: [1.0, 2.0, 3.5, 4.25],
                    };
                    3
                ],
            },
            Message::Tracks {
                header: tracks_header(5),
                tracks: vec![TrackedLine {
                    previous: -1,
                    has_stereo: 1,
                    ..Default::default()
                }],
            },
            Message::Image {
                header: header(6),
                scale: 4,
                width: 2,
                height: 1,
                pixels: vec![7, 250],
            },
        ];
        for m in messages {
            let bytes = m.encode().unwrap_or_else(|e| panic!("{e}"));
            let back = Message::decode("k", &bytes).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(back, m);
            assert_eq!(
                back.frame().map(|f| f.frame_id),
                m.frame().map(|f| f.frame_id)
            );
        }
    }

    #[test]
    fn bytes_that_are_not_a_message_are_refused_naming_the_key() {
        let err = Message::decode("linetrack/poses", &[200, 1])
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("linetrack/poses"), "{err}");
        // A message cut short is refused too.
        let bytes = Message::Tracks {
            header: tracks_header(1),
            tracks: vec![TrackedLine::default(); 4],
        }
        .encode()
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(Message::decode("k", &bytes[..bytes.len() - 3]).is_err());
    }

    #[test]
    fn a_code_that_names_nothing_arrives_and_reads_as_an_error_naming_it() {
        // A status message as a newer build might send it: variant 1 (status), then the
        // report's stage, pid, kind, detail, frame id and value; kind 99 is no status kind
        // of this build.
        let fields: (u32, u32, u32, u32, u32, u64, u64) = (1, 1, 4242, 99, 0, 7, 0);
        let bytes = postcard::to_stdvec(&fields).unwrap_or_else(|e| panic!("{e}"));
        let back = Message::decode("k", &bytes).unwrap_or_else(|e| panic!("{e}"));
        let Message::Status { report } = back else {
            panic!("not a status message: {back:?}");
        };
        assert_eq!((report.pid, report.frame_id), (4242, 7));
        assert_eq!(report.stage.get(), Ok(StageKind::LineDetector));
        let err = report.kind.get().err().map(|e| e.to_string());
        assert_eq!(err.as_deref(), Some("unknown status kind code 99"));
    }

    #[test]
    fn a_shrunk_image_averages_its_blocks_and_leaves_out_partial_ones() {
        // 5 × 4, scale 2: two by two blocks, the last column left out.
        #[rustfmt::skip]
        let pixels = [
            0, 2, 10, 10, 99,
            4, 6, 10, 10, 99,
            255, 255, 1, 0, 99,
            255, 255, 0, 0, 99,
        ];
        let (out, w, h) = shrink(&pixels, 5, 4, 2).unwrap_or_else(|| panic!("refused"));
        assert_eq!((w, h), (2, 2));
        assert_eq!(out, vec![3, 10, 255, 0]);
        assert_eq!(
            shrink(&pixels, 5, 4, 1).map(|(p, ..)| p),
            Some(pixels.to_vec())
        );
        assert!(shrink(&pixels[..10], 5, 4, 2).is_none(), "short input");
        assert!(shrink(&pixels, 5, 4, 0).is_none());
    }
}
