//! `[source]`: the sequence or recording the frame source reads, and how fast.

use crate::limits::{MAX_FRAMES, RATE_HZ, in_range};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// How fast the frame source publishes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Pacing {
    /// At the sequence's own frame rate (its timestamps), as a camera would.
    Realtime,
    /// As fast as the source can read; late frames are then dropped by policy downstream.
    Fastest,
}

/// The frame source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SourceConfig {
    /// A EuRoC (`mav0/cam0`, `mav0/cam1`) or KITTI (`image_0`, `image_1`) sequence folder.
    pub sequence: PathBuf,
    /// Realtime or fastest.
    pub pacing: Pacing,
    /// Frames per second for realtime pacing; 0 = from the sequence's timestamps.
    pub rate_hz: f64,
    /// Publish at most this many frames (0 = all).
    pub max_frames: usize,
    /// The nice value of the thread that decodes (and rectifies) the next frames ahead of
    /// their time, under the `other` policy whatever the stage's: it works in the CPU time
    /// the stages leave instead of taking it from a frame in flight. 0 by default: a
    /// realtime source whose reader starves falls behind its schedule, and its frames then
    /// leave late (`capture-late`); beside two CPU hogs nice 10 starved it to 9.7 frames a
    /// second and every frame of 1,200 left late (docs/pipeline.md). Paced in real time,
    /// the reader reads each next frame half a period after a frame is due, between the
    /// frames' processing, whatever its nice value.
    pub reader_nice: i32,
    /// An MCAP recording (`[record]`, `linetrack replay FILE`) whose stereo frames and rig
    /// are published instead of `sequence`'s; empty: the sequence.
    #[serde(skip_serializing_if = "is_empty_path")]
    pub replay: PathBuf,
    /// The paper's illumination protocol on a data set's images: a new gain α ~ U(0.5, 2.5)
    /// and bias β ~ U(0, 20) on both images every this many seconds of the sequence's
    /// time, as `linetrack-vo --gain-jumps` applies them (0 = off).
    pub gain_jumps_s: f64,
    /// The seed of those draws (`linetrack-vo --seed`).
    pub gain_jumps_seed: u64,
}

/// Serde's test for leaving an unset path out of a written config.
pub(crate) fn is_empty_path(path: &Path) -> bool {
    path.as_os_str().is_empty()
}

impl SourceConfig {
    /// The recording to replay, when one is set.
    pub fn replay(&self) -> Option<&Path> {
        (!self.replay.as_os_str().is_empty()).then_some(self.replay.as_path())
    }
}

impl Default for SourceConfig {
    fn default() -> Self {
        Self {
            sequence: PathBuf::from("out/sequences/pipeline"),
            pacing: Pacing::Realtime,
            rate_hz: 0.0,
            max_frames: 0,
            reader_nice: 0,
            replay: PathBuf::new(),
            gain_jumps_s: 0.0,
            gain_jumps_seed: 0,
        }
    }
}

impl SourceConfig {
    /// The first out-of-range key of `[source]`.
    pub fn validate(&self) -> Result<(), String> {
        if self.rate_hz != 0.0 {
            in_range("source.rate_hz", self.rate_hz, RATE_HZ)
                .map_err(|e| format!("{e} (or 0 = the sequence's rate)"))?;
        }
        in_range("source.max_frames", self.max_frames, 0..=MAX_FRAMES)?;
        in_range(
            "source.reader_nice",
            self.reader_nice,
            linetrack_sched::NICE,
        )?;
        if self.gain_jumps_s != 0.0 {
            in_range("source.gain_jumps_s", self.gain_jumps_s, 0.001..=3600.0)
                .map_err(|e| format!("{e} (or 0 = off)"))?;
        }
        Ok(())
    }
}
