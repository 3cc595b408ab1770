//! What goes on the link: one [`Message`] per zenoh sample, postcard-encoded (integers as
//! varints), under the key `<key_prefix>/<topic>`.

use crate::LinkError;
use linetrack_msgs::{FrameHeader, PoseRecord, SegmentRecord, StatusReport, TrackedLine};
use serde::{Deserialize, Serialize};

/// One forwarded message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Message {
    /// A frame's pose (or its drop: the header's status says).
    Pose {
        /// The frame's header.
        header: FrameHeader,
        /// The pose.
        pose: PoseRecord,
    },
    /// A stage's heartbeat or event.
    Status {
        /// The message's header.
        header: FrameHeader,
        /// The report.
        report: StatusReport,
    },
    /// A frame's segments, left image's then right image's (`header.left_count` splits them).
    Segments {
        /// The frame's header.
        header: FrameHeader,
        /// The segments.
        segments: Vec<SegmentRecord>,
    },
    /// A frame's matched segments.
    Tracks {
        /// The frame's header.
        header: FrameHeader,
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

    /// The header.
    pub fn header(&self) -> &FrameHeader {
        match self {
            Message::Pose { header, .. }
            | Message::Status { header, .. }
            | Message::Segments { header, .. }
            | Message::Tracks { header, .. }
            | Message::Image { header, .. } => header,
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

    fn header(frame_id: u64) -> FrameHeader {
        FrameHeader {
            frame_id,
            sequence_ns: 1_403_636_579_763_555_584,
            capture_ns: 17,
            left_count: 2,
            ..Default::default()
        }
    }

    #[test]
    fn every_message_comes_back_as_it_went() {
        let messages = [
            Message::Pose {
                header: header(3),
                pose: PoseRecord {
                    translation: [0.1, -2.0, 1e-9],
                    rotation_xyzw: [0.0, 0.0, 0.6, 0.8],
                    inliers: [3, 40],
                    rms_px: 0.25,
                    ..Default::default()
                },
            },
            Message::Status {
                header: header(0),
                report: StatusReport {
                    stage: 1,
                    pid: 4242,
                    kind: 3,
                    frame_id: 99,
                    value: 100,
                    ..Default::default()
                },
            },
            Message::Segments {
                header: header(4),
                segments: vec![
                    SegmentRecord {
                        endpoints: [1.0, 2.0, 3.5, 4.25],
                    };
                    3
                ],
            },
            Message::Tracks {
                header: header(5),
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
            assert_eq!(back.header().frame_id, m.header().frame_id);
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
            header: header(1),
            tracks: vec![TrackedLine::default(); 4],
        }
        .encode()
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(Message::decode("k", &bytes[..bytes.len() - 3]).is_err());
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
