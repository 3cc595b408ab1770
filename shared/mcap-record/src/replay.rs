//! [`Replay`]: a recording's stereo frames and rig read back, in order.

use crate::{LEFT_CALIBRATION, LEFT_IMAGE, McapError, RIGHT_CALIBRATION, RIGHT_IMAGE};
use foxglove::Decode;
use foxglove::messages::{CameraCalibration, RawImage};
use linetrack_msgs::RigRecord;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

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

pub(crate) fn expect_schema(
    path: &Path,
    channel: &mcap::Channel<'_>,
    schema: &str,
) -> Result<(), McapError> {
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
pub(crate) fn rig_of(
    left: &CameraCalibration,
    right: &CameraCalibration,
) -> Result<RigRecord, String> {
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
