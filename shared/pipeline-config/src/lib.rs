//! The pipeline's configuration (`configs/pipeline.toml`): what the frame source reads and
//! how fast, which detector and matcher run, the latency budgets and drop policy, when the
//! matcher falls back to ℓ1 and comes back, and how the supervisor watches and restarts
//! stages, each stage's CPUs and scheduling policy (`[stages.<name>]`, applied by
//! `linetrack-sched`), where the shared memory's bookkeeping lives (`[ipc]`), and the
//! optional ROS 2 output (`[ros2]`). Every
//! field has a default; [`PipelineConfig::validate`] names the first bad one.

mod ros2;
mod ros2_images;

pub mod file;
use linetrack_msgs::StageKind;
use linetrack_odometry::OdometryConfig;
pub use linetrack_sched::{Policy, SchedSettings};
use linetrack_vision::DetectorKind;
pub use ros2::{CameraMount, Convention, MAX_DOMAIN_ID, Ros2Config, StampSource};
pub use ros2_images::{MAX_STAMP_TOLERANCE_MS, Ros2ImagesConfig};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Errors reading a pipeline config.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read {}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The TOML is malformed or has unknown keys.
    #[error("{origin}: {message}")]
    Parse {
        /// The file (or `<string>`).
        origin: String,
        /// The parser's message.
        message: String,
    },
    /// A value is out of range.
    #[error("{origin}: {message}")]
    Invalid {
        /// The file (or `<string>`).
        origin: String,
        /// Which key and why.
        message: String,
    },
}

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
    /// the stages leave instead of taking it from a frame in flight.
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

fn is_empty_path(path: &Path) -> bool {
    path.as_os_str().is_empty()
}

impl SourceConfig {
    /// The recording to replay, when one is set.
    pub fn replay(&self) -> Option<&Path> {
        (!self.replay.as_os_str().is_empty()).then_some(self.replay.as_path())
    }
}

/// The run's MCAP recording (`[record]`), written by the `linetrack-recorder` process the
/// supervisor starts next to the stages.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecordConfig {
    /// Record the run into an MCAP file.
    pub mcap: bool,
    /// The file; empty: `recording.mcap` in the run folder.
    #[serde(skip_serializing_if = "is_empty_path")]
    pub path: PathBuf,
    /// Record the images of every n-th frame (frame id divisible by n); 0 = no images.
    /// Only a recording of every frame's images (1) replays the run.
    pub every_nth_image: u64,
    /// How long the supervisor waits for the recorder to open its file before starting
    /// the frame source (it starts it anyway then, without a recording).
    pub startup_timeout_ms: u64,
    /// How long the recorder may take to write what it still holds and close the file
    /// when the run ends, before it is killed.
    pub close_timeout_ms: u64,
}

impl Default for RecordConfig {
    fn default() -> Self {
        Self {
            mcap: false,
            path: PathBuf::new(),
            every_nth_image: 1,
            startup_timeout_ms: 10_000,
            close_timeout_ms: 10_000,
        }
    }
}

impl RecordConfig {
    /// The file a run into `run_dir` records into.
    pub fn file(&self, run_dir: &Path) -> PathBuf {
        if self.path.as_os_str().is_empty() {
            run_dir.join("recording.mcap")
        } else {
            self.path.clone()
        }
    }
}

impl Default for SourceConfig {
    fn default() -> Self {
        Self {
            sequence: PathBuf::from("out/sequences/pipeline"),
            pacing: Pacing::Realtime,
            rate_hz: 0.0,
            max_frames: 0,
            reader_nice: 10,
            replay: PathBuf::new(),
            gain_jumps_s: 0.0,
            gain_jumps_seed: 0,
        }
    }
}

/// A live stereo camera in place of the sequence (`[camera]`): off while `capture` is empty.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// The capture: a V4L2 device (`0`, `/dev/video0`), a GStreamer pipeline ending in
    /// `appsink`, or a numbered image pattern (`dir/%06d.png`). Side by side (left half,
    /// right half) unless `capture_right` is set, then the left camera. Empty: no camera.
    pub capture: String,
    /// The right camera's capture when the two are separate devices; empty: side by side.
    pub capture_right: String,
    /// Kalibr `camchain.yaml`, or a folder with EuRoC `cam0/sensor.yaml` and `cam1/sensor.yaml`.
    pub calibration: PathBuf,
    /// Frames per second the camera delivers, to count frames lost in gaps of the driver's
    /// timestamps; 0 = the rate the driver announces (no count when it announces none).
    pub fps: f64,
    /// A frame read more than this long after it could have been (it waited in a buffer)
    /// is late: with `budget.drop_late` it is dropped as `capture-late`.
    pub late_ms: f64,
    /// Stop after this many seconds; 0 = until stopped (Ctrl-C, `source.max_frames`).
    pub duration_s: f64,
    /// A camera that fails is reopened after this long, doubling per failure ...
    pub retry_ms: u64,
    /// ... up to this.
    pub retry_max_ms: u64,
    /// Frames from two ROS 2 image topics instead (`[camera.ros2_images]`, needs the
    /// `linetrack-ros2-source` binary: cargo feature `linetrack-ros2-bridge/ros2`); off
    /// while its `left` is empty. `duration_s` applies to it too.
    pub ros2_images: Ros2ImagesConfig,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            capture: String::new(),
            capture_right: String::new(),
            calibration: PathBuf::new(),
            fps: 0.0,
            late_ms: 100.0,
            duration_s: 0.0,
            retry_ms: 500,
            retry_max_ms: 5000,
            ros2_images: Ros2ImagesConfig::default(),
        }
    }
}

impl CameraConfig {
    /// Whether a camera replaces the sequence.
    pub fn enabled(&self) -> bool {
        !self.capture.trim().is_empty()
    }

    /// The right camera's capture, when separate.
    pub fn right(&self) -> Option<&str> {
        let right = self.capture_right.trim();
        (!right.is_empty()).then_some(right)
    }
}

/// Which segment matcher the matcher stage uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MatcherPolicy {
    /// LBD, falling back to ℓ1 when descriptor matching fails, with hysteresis.
    Auto,
    /// LBD only.
    Lbd,
    /// ℓ1 only.
    L1,
}

/// When the supervisor switches LBD → ℓ1 and back.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FallbackConfig {
    /// LBD is failing on a frame with fewer stereo segment matches than this.
    pub min_stereo_matches: u32,
    /// ... or when fewer than this fraction of the frame-to-frame line observations are
    /// inliers of the motion estimate (with at least `min_observations` observations).
    pub min_inlier_ratio: f64,
    /// Observations needed before the inlier ratio is judged.
    pub min_observations: u32,
    /// ... or when the matcher stage goes over its budget.
    pub over_budget: bool,
    /// ... or when the frame misses `budget.end_to_end_ms` (processed late, or dropped late
    /// by any stage): the pipeline's deadline, not only the matcher's own. With it, a probe
    /// passes only when its frame's end to end is within `recover_budget_fraction` of that
    /// budget too.
    pub end_to_end: bool,
    /// Consecutive failing frames before switching to ℓ1.
    pub bad_frames: u32,
    /// In ℓ1 mode, the matcher also runs LBD on every n-th frame to see if it works again.
    pub probe_every: u32,
    /// A probe passes with at least this many LBD stereo matches (above
    /// `min_stereo_matches`: the hysteresis band).
    pub recover_stereo_matches: u32,
    /// Consecutive passing probes before switching back to LBD.
    pub recover_probes: u32,
    /// With `over_budget`, a probe also passes only when the matcher stage (ℓ1 and the LBD
    /// probe together) took at most this fraction of its budget: below the failing bar
    /// (the budget itself), the latency's hysteresis band.
    pub recover_budget_fraction: f64,
}

impl Default for FallbackConfig {
    fn default() -> Self {
        Self {
            min_stereo_matches: 12,
            min_inlier_ratio: 0.25,
            min_observations: 10,
            over_budget: true,
            end_to_end: true,
            bad_frames: 3,
            probe_every: 5,
            recover_stereo_matches: 24,
            recover_probes: 2,
            recover_budget_fraction: 0.8,
        }
    }
}

/// When the supervisor hot-swaps the line detector from LSD to a faster one under budget
/// pressure, and back (`[detector_fallback]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DetectorFallbackConfig {
    /// The off switch: false leaves the detector to the config and `linetrack ctl`.
    pub enabled: bool,
    /// The faster detector LSD gives way to (not LSD).
    pub to: DetectorKind,
    /// Consecutive LSD frames over `budget.line_detector_ms` before the swap.
    pub bad_frames: u32,
    /// Consecutive frames of the faster detector within `recover_budget_fraction` of the
    /// budget before the swap back to LSD.
    pub recover_frames: u32,
    /// The fraction (< 1: the hysteresis band) of `budget.line_detector_ms` the faster
    /// detector must stay within for the swap back.
    pub recover_budget_fraction: f64,
    /// Frames between two swaps of this policy, at least.
    pub min_interval_frames: u64,
    /// An LSD frame that misses `budget.end_to_end_ms` (processed late, or dropped late by
    /// any stage) counts as over budget too: the pipeline's deadline, not only LSD's own.
    pub end_to_end: bool,
}

impl Default for DetectorFallbackConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            to: DetectorKind::Fld,
            bad_frames: 5,
            recover_frames: 40,
            recover_budget_fraction: 0.25,
            min_interval_frames: 200,
            end_to_end: true,
        }
    }
}

/// Matcher stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MatcherConfig {
    /// auto, lbd or l1.
    pub mode: MatcherPolicy,
    /// Fallback rules for `auto`.
    pub fallback: FallbackConfig,
}

impl MatcherPolicy {
    /// `auto`, `lbd` or `l1`, as in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            MatcherPolicy::Auto => "auto",
            MatcherPolicy::Lbd => "lbd",
            MatcherPolicy::L1 => "l1",
        }
    }
}

impl std::str::FromStr for MatcherPolicy {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        [MatcherPolicy::L1, MatcherPolicy::Lbd, MatcherPolicy::Auto]
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| format!("{s:?}: expected l1, lbd or auto"))
    }
}

impl MatcherConfig {
    /// `auto`, `lbd` or `l1`.
    pub fn mode_name(&self) -> &'static str {
        self.mode.name()
    }
}

impl Default for MatcherConfig {
    fn default() -> Self {
        Self {
            mode: MatcherPolicy::L1,
            fallback: FallbackConfig::default(),
        }
    }
}

/// Latency budgets, milliseconds, and what happens to late frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BudgetConfig {
    /// From the source starting to read a frame to its pose being published.
    pub end_to_end_ms: f64,
    /// Frame source: read, decode and publish.
    pub frame_source_ms: f64,
    /// Line detector: both images.
    pub line_detector_ms: f64,
    /// Matcher: description and stereo + frame-to-frame matching.
    pub matcher_ms: f64,
    /// Pose estimator.
    pub pose_estimator_ms: f64,
    /// Drop a frame that is already over the end-to-end budget when a stage takes it, and
    /// any frame with a newer one queued behind it; otherwise process every frame.
    pub drop_late: bool,
}

impl Default for BudgetConfig {
    fn default() -> Self {
        Self {
            end_to_end_ms: 100.0,
            frame_source_ms: 30.0,
            line_detector_ms: 50.0,
            matcher_ms: 50.0,
            pose_estimator_ms: 50.0,
            drop_late: true,
        }
    }
}

impl BudgetConfig {
    /// The budget of `stage` (`None` for a stage without one: supervisor, recorder, ...).
    pub fn stage_ms(&self, stage: StageKind) -> Option<f64> {
        match stage {
            StageKind::FrameSource => Some(self.frame_source_ms),
            StageKind::LineDetector => Some(self.line_detector_ms),
            StageKind::Matcher => Some(self.matcher_ms),
            StageKind::PoseEstimator => Some(self.pose_estimator_ms),
            StageKind::Supervisor
            | StageKind::Recorder
            | StageKind::Ros2Bridge
            | StageKind::Link => None,
        }
    }
}

/// Supervision.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SupervisorConfig {
    /// Stages report alive this often.
    pub heartbeat_ms: u64,
    /// A stage silent this long is hung: it is killed and restarted.
    pub hang_timeout_ms: u64,
    /// Stages must report ready within this.
    pub startup_timeout_ms: u64,
    /// First restart delay; doubles on each restart of the same stage.
    pub restart_backoff_ms: u64,
    /// Longest restart delay.
    pub restart_backoff_max_ms: u64,
    /// Restarts per stage before the run is abandoned.
    pub max_restarts: u32,
    /// After the source finishes, wait this long for the last poses.
    pub drain_timeout_ms: u64,
    /// On shutdown, wait this long for a stage to exit before killing it.
    pub shutdown_grace_ms: u64,
    /// Print a live status line this often (0 = never).
    pub status_every_ms: u64,
}

impl Default for SupervisorConfig {
    fn default() -> Self {
        Self {
            heartbeat_ms: 200,
            hang_timeout_ms: 3000,
            startup_timeout_ms: 30_000,
            restart_backoff_ms: 200,
            restart_backoff_max_ms: 5000,
            max_restarts: 5,
            drain_timeout_ms: 5000,
            shutdown_grace_ms: 3000,
            status_every_ms: 1000,
        }
    }
}

/// Where the run's records go.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// Each run gets a new folder here named by its UTC start time
    /// (`2026-11-23T12-00-00`), and `latest` here is a symlink to the newest. Unset: the
    /// user's state folder, [`OutputConfig::runs_dir`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub runs_dir: Option<PathBuf>,
    /// A fixed run folder instead (`linetrack run --run-dir`): frames.csv, events.csv,
    /// poses (TUM), summary.json, trace files. Locked while a run writes into it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub run_dir: Option<PathBuf>,
    /// Write per-process span files and the merged Chrome/Perfetto trace.
    pub trace: bool,
    /// What a record that cannot be written (a full disk, a quota, an I/O error) does to the
    /// run: either way the records end at their last whole row, the error names the file
    /// and the OS error, and the run ends `records-failed` (non-zero exit).
    pub on_record_error: OnRecordError,
}

impl OutputConfig {
    /// The folder of dated run folders: `runs_dir` when set, else
    /// `$XDG_STATE_HOME/linetrack/runs` (an absolute `XDG_STATE_HOME`), else
    /// `$HOME/.local/state/linetrack/runs`: the user's own, never a relative path that may
    /// sit in a shared folder.
    pub fn runs_dir(&self) -> Result<PathBuf, String> {
        if let Some(dir) = &self.runs_dir {
            return Ok(dir.clone());
        }
        default_runs_dir()
    }
}

/// `$XDG_STATE_HOME/linetrack/runs`, else `$HOME/.local/state/linetrack/runs` (the XDG base
/// directory rules: a relative `XDG_STATE_HOME` is ignored).
pub fn default_runs_dir() -> Result<PathBuf, String> {
    let absolute = |var: &str| {
        std::env::var_os(var)
            .map(PathBuf::from)
            .filter(|p| p.is_absolute())
    };
    absolute("XDG_STATE_HOME")
        .or_else(|| absolute("HOME").map(|home| home.join(".local/state")))
        .map(|state| state.join("linetrack/runs"))
        .ok_or_else(|| {
            "output.runs_dir is unset and neither XDG_STATE_HOME nor HOME is an absolute path: set output.runs_dir or --run-dir".to_string()
        })
}

/// What a record that cannot be written does to the run (`output.on_record_error`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OnRecordError {
    /// The pipeline stops at once (cleanly, like Ctrl-C): a run is for its records.
    #[default]
    Stop,
    /// The pipeline runs on without records (its poses still go to the ROS 2 output and
    /// the link): a robot that needs its odometry more than its log.
    Continue,
}

impl OnRecordError {
    /// The value as the config spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Stop => "stop",
            Self::Continue => "continue",
        }
    }
}

impl Default for OutputConfig {
    fn default() -> Self {
        Self {
            runs_dir: None,
            run_dir: None,
            trace: true,
            on_record_error: OnRecordError::Stop,
        }
    }
}

/// Each stage's CPUs and scheduling policy (`[stages.line-detector]` ...); a stage left out
/// keeps what it inherits from the supervisor. Unknown stage names are refused.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default, rename_all = "kebab-case")]
pub struct StagesConfig {
    /// `[stages.frame-source]`.
    #[serde(skip_serializing_if = "SchedSettings::is_empty")]
    pub frame_source: SchedSettings,
    /// `[stages.line-detector]` (a standby detector of a hot swap too).
    #[serde(skip_serializing_if = "SchedSettings::is_empty")]
    pub line_detector: SchedSettings,
    /// `[stages.matcher]`.
    #[serde(skip_serializing_if = "SchedSettings::is_empty")]
    pub matcher: SchedSettings,
    /// `[stages.pose-estimator]`.
    #[serde(skip_serializing_if = "SchedSettings::is_empty")]
    pub pose_estimator: SchedSettings,
}

impl StagesConfig {
    /// The processing stages, in pipeline order, with their settings.
    pub fn all(&self) -> [(StageKind, &SchedSettings); 4] {
        [
            (StageKind::FrameSource, &self.frame_source),
            (StageKind::LineDetector, &self.line_detector),
            (StageKind::Matcher, &self.matcher),
            (StageKind::PoseEstimator, &self.pose_estimator),
        ]
    }

    /// The settings of `stage` (`None` for a stage without any: supervisor, recorder, ...).
    pub fn of(&self, stage: StageKind) -> Option<&SchedSettings> {
        self.all()
            .into_iter()
            .find(|(kind, _)| *kind == stage)
            .map(|(_, settings)| settings)
    }
}

/// Shared memory.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IpcConfig {
    /// The folder of iceoryx2's node and service descriptions (created owner-only). Unset:
    /// `$XDG_RUNTIME_DIR/linetrack-iceoryx2`, else `/tmp/linetrack-<uid>/iceoryx2`. The
    /// environment variable `LINETRACK_IPC_ROOT` overrides it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub root: Option<PathBuf>,
}

/// The ground-station link (`linetrack-link`, built with the `link` feature): an optional
/// process the supervisor starts that forwards the allowed topics to zenoh. It never slows
/// the pipeline: when the link is down or slow, messages are dropped and counted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LinkConfig {
    /// Start the link process with the run.
    pub enabled: bool,
    /// The zenoh endpoint the onboard side listens on (`tcp/HOST:PORT`); `linetrack watch
    /// --connect` names the same.
    pub listen: String,
    /// The topics forwarded: any of `poses`, `status`, `segments`, `tracks`, `images`.
    pub topics: Vec<String>,
    /// The zenoh key prefix the topics are published under (`<key_prefix>/poses`, ...).
    pub key_prefix: String,
    /// `images`: the left image shrunk by this factor in each direction (box average).
    pub image_scale: u32,
    /// `images`: one image every this many frames.
    pub image_every: u32,
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            listen: "tcp/127.0.0.1:7447".to_string(),
            topics: ["poses", "status"].map(String::from).to_vec(),
            key_prefix: "linetrack".to_string(),
            image_scale: 4,
            image_every: 10,
        }
    }
}

impl LinkConfig {
    /// The topics `topics` may name.
    pub const TOPICS: [&'static str; 5] = ["poses", "status", "segments", "tracks", "images"];

    /// Whether `topic` is on the allow-list.
    pub fn allows(&self, topic: &str) -> bool {
        self.topics.iter().any(|t| t == topic)
    }

    fn validate(&self) -> Result<(), String> {
        if let Some(unknown) = self
            .topics
            .iter()
            .find(|t| !Self::TOPICS.contains(&t.as_str()))
        {
            return Err(format!(
                "link.topics: unknown topic {unknown:?}: allowed {:?}",
                Self::TOPICS
            ));
        }
        in_range("link.image_scale", self.image_scale, 1..=64)?;
        in_range("link.image_every", self.image_every, 1..=MAX_STREAK_FRAMES)?;
        if self.listen.is_empty() || !self.listen.contains('/') {
            return Err(format!(
                "link.listen = {:?}: expected a zenoh endpoint such as tcp/0.0.0.0:7447",
                self.listen
            ));
        }
        if self.key_prefix.is_empty()
            || self.key_prefix.starts_with('/')
            || self.key_prefix.ends_with('/')
            || self.key_prefix.contains(['*', '$', '?', '#'])
        {
            return Err(format!(
                "link.key_prefix = {:?}: expected words separated by '/', no wildcards",
                self.key_prefix
            ));
        }
        Ok(())
    }
}

/// Allowed latency budgets, milliseconds: above zero, at most a minute.
const BUDGET_MS: std::ops::RangeInclusive<f64> = 0.001..=60_000.0;
/// Allowed realtime rates, frames per second (0 = the sequence's own rate).
const RATE_HZ: std::ops::RangeInclusive<f64> = 0.01..=1000.0;
/// The most frames a run may be limited to.
const MAX_FRAMES: usize = 1_000_000_000;
/// The largest match and observation counts the fallback rules may name.
const MAX_MATCHES: u32 = 100_000;
/// Allowed streak lengths and probe periods of the fallback rules, frames.
const STREAK: std::ops::RangeInclusive<u32> = 1..=1000;
/// Allowed fractions of the matcher budget a recovering probe may take (below 1: hysteresis).
const RECOVER_BUDGET_FRACTION: std::ops::RangeInclusive<f64> = 0.05..=0.95;
/// Allowed heartbeat periods, milliseconds.
const HEARTBEAT_MS: std::ops::RangeInclusive<u64> = 10..=10_000;
/// The shortest startup timeout, milliseconds (a stage loads its detector first).
const MIN_STARTUP_MS: u64 = 100;
/// The longest timeout, backoff, drain or grace period, milliseconds (10 minutes).
const MAX_WAIT_MS: u64 = 600_000;
/// The longest image period of the link, frames.
const MAX_STREAK_FRAMES: u32 = 10_000;
/// The most restarts per stage.
const MAX_RESTARTS: u32 = 1000;
/// The longest camera run, seconds (a year).
const MAX_DURATION_S: f64 = 31_536_000.0;
/// The longest live-status period, milliseconds (an hour).
const MAX_STATUS_EVERY_MS: u64 = 3_600_000;

/// `key = value` inside `range`, or an error naming both (NaN is never inside).
fn in_range<T: PartialOrd + std::fmt::Debug>(
    key: &str,
    value: T,
    range: std::ops::RangeInclusive<T>,
) -> Result<(), String> {
    if range.contains(&value) {
        Ok(())
    } else {
        Err(format!(
            "{key} = {value:?} is out of range: allowed {:?} ..= {:?}",
            range.start(),
            range.end()
        ))
    }
}

/// The keys of a policy that switches with hysteresis (the matcher's fallback, the
/// detector's): its streaks of frames and its recovery fraction of a budget.
fn check_hysteresis(
    table: &str,
    streaks: &[(&str, u32)],
    recover_budget_fraction: f64,
) -> Result<(), String> {
    for &(key, frames) in streaks {
        in_range(&format!("{table}.{key}"), frames, STREAK)?;
    }
    in_range(
        &format!("{table}.recover_budget_fraction"),
        recover_budget_fraction,
        RECOVER_BUDGET_FRACTION,
    )
}

/// The whole pipeline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PipelineConfig {
    /// Frame source.
    pub source: SourceConfig,
    /// A live camera in place of the sequence.
    pub camera: CameraConfig,
    /// Line detector at start (swappable at run time).
    pub detector: DetectorKind,
    /// Work on the left and the right image at the same time, on two threads: the
    /// detector's segments and the matcher's LBD descriptors (the right side on a thread
    /// each stage starts once). The pose estimator's ORB corners always are.
    pub detect_sides_in_parallel: bool,
    /// The automatic LSD → faster detector swap under budget pressure.
    pub detector_fallback: DetectorFallbackConfig,
    /// Matcher policy.
    pub matcher: MatcherConfig,
    /// Budgets and drop policy.
    pub budget: BudgetConfig,
    /// Supervision.
    pub supervisor: SupervisorConfig,
    /// Records.
    pub output: OutputConfig,
    /// The MCAP recording.
    pub record: RecordConfig,
    /// Each stage's CPUs and scheduling policy.
    pub stages: StagesConfig,
    /// Shared memory.
    pub ipc: IpcConfig,
    /// The ground-station link.
    pub link: LinkConfig,
    /// Front end and motion estimation (its `detector` and `matcher` keys are ignored:
    /// the ones above rule).
    pub odometry: OdometryConfig,
    /// The ROS 2 output process.
    pub ros2: Ros2Config,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            source: SourceConfig::default(),
            camera: CameraConfig::default(),
            detector: DetectorKind::EdgeLines,
            detect_sides_in_parallel: false,
            detector_fallback: DetectorFallbackConfig::default(),
            matcher: MatcherConfig::default(),
            budget: BudgetConfig::default(),
            supervisor: SupervisorConfig::default(),
            output: OutputConfig::default(),
            record: RecordConfig::default(),
            stages: StagesConfig::default(),
            ipc: IpcConfig::default(),
            link: LinkConfig::default(),
            odometry: OdometryConfig::default(),
            ros2: Ros2Config::default(),
        }
    }
}

impl PipelineConfig {
    /// What finds the pose estimator's points, for reports: the corner extractor's name
    /// (`[odometry.frontend.orb] extractor`, e.g. "orb-opencv" or "fast-brief") with its
    /// point count and pyramid, or "none (lines only)".
    pub fn points_text(&self) -> String {
        match self.odometry.features {
            linetrack_odometry::Features::LinesOnly => "none (lines only)".to_string(),
            linetrack_odometry::Features::PointsAndLines => {
                let orb = &self.odometry.frontend.orb;
                format!(
                    "{} ({} points, {} levels of {})",
                    orb.extractor.name(),
                    orb.features,
                    orb.levels,
                    orb.scale_factor
                )
            }
        }
    }

    /// Parses and validates TOML text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let config: Self = toml::from_str(text).map_err(|e| ConfigError::Parse {
            origin: origin.to_string(),
            message: file::parse_message(&e, text),
        })?;
        config.validate().map_err(|message| ConfigError::Invalid {
            origin: origin.to_string(),
            message: file::cut_quotes(&message),
        })?;
        Ok(config)
    }

    /// Reads and validates a config file: a regular file of at most
    /// [`file::MAX_CONFIG_BYTES`] ([`file::read_bounded`]).
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let text = file::read_bounded(path)?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// The first out-of-range value, named by its key with its allowed range. Every key of
    /// this crate is checked (the ranges are in `configs/pipeline.toml`), so no stage can
    /// be handed a value that overflows a clock or a duration; `[odometry]` is checked by
    /// its own crate.
    pub fn validate(&self) -> Result<(), String> {
        let b = &self.budget;
        for (key, ms) in [
            ("budget.end_to_end_ms", b.end_to_end_ms),
            ("budget.frame_source_ms", b.frame_source_ms),
            ("budget.line_detector_ms", b.line_detector_ms),
            ("budget.matcher_ms", b.matcher_ms),
            ("budget.pose_estimator_ms", b.pose_estimator_ms),
        ] {
            in_range(key, ms, BUDGET_MS)?;
        }
        for (key, path) in [
            ("output.run_dir", &self.output.run_dir),
            ("output.runs_dir", &self.output.runs_dir),
            ("ipc.root", &self.ipc.root),
        ] {
            if path.as_ref().is_some_and(|p| p.as_os_str().is_empty()) {
                return Err(format!(
                    "{key} = \"\": an empty path would be the current folder; leave the key out for the default"
                ));
            }
        }
        let src = &self.source;
        if src.rate_hz != 0.0 {
            in_range("source.rate_hz", src.rate_hz, RATE_HZ)
                .map_err(|e| format!("{e} (or 0 = the sequence's rate)"))?;
        }
        in_range("source.max_frames", src.max_frames, 0..=MAX_FRAMES)?;
        in_range("source.reader_nice", src.reader_nice, linetrack_sched::NICE)?;
        if src.gain_jumps_s != 0.0 {
            in_range("source.gain_jumps_s", src.gain_jumps_s, 0.001..=3600.0)
                .map_err(|e| format!("{e} (or 0 = off)"))?;
        }
        let rec = &self.record;
        in_range(
            "record.every_nth_image",
            rec.every_nth_image,
            0..=MAX_FRAMES as u64,
        )?;
        in_range(
            "record.startup_timeout_ms",
            rec.startup_timeout_ms,
            1..=MAX_WAIT_MS,
        )?;
        in_range(
            "record.close_timeout_ms",
            rec.close_timeout_ms,
            1..=MAX_WAIT_MS,
        )?;
        if src.replay().is_some() && self.camera.enabled() {
            return Err(
                "source.replay and camera.capture are both set: frames come from one of them"
                    .to_string(),
            );
        }
        let cam = &self.camera;
        if cam.fps != 0.0 {
            in_range("camera.fps", cam.fps, RATE_HZ)
                .map_err(|e| format!("{e} (or 0 = the driver's rate)"))?;
        }
        in_range("camera.late_ms", cam.late_ms, BUDGET_MS)?;
        in_range("camera.duration_s", cam.duration_s, 0.0..=MAX_DURATION_S)?;
        in_range("camera.retry_ms", cam.retry_ms, 1..=MAX_WAIT_MS)?;
        in_range(
            "camera.retry_max_ms",
            cam.retry_max_ms,
            cam.retry_ms..=MAX_WAIT_MS,
        )
        .map_err(|e| format!("{e}: at least retry_ms"))?;
        if cam.enabled() && cam.calibration.as_os_str().is_empty() {
            return Err(
                "camera.capture is set but camera.calibration is empty: the rig comes from a calibration file (Kalibr camchain.yaml or a folder of EuRoC sensor.yaml)"
                    .to_string(),
            );
        }
        if !cam.enabled() && cam.right().is_some() {
            return Err("camera.capture_right is set but camera.capture is empty".to_string());
        }
        cam.ros2_images.validate()?;
        if cam.ros2_images.enabled() && (cam.enabled() || src.replay().is_some()) {
            return Err(
                "camera.ros2_images is set with camera.capture or source.replay: frames come from one of them"
                    .to_string(),
            );
        }
        let f = &self.matcher.fallback;
        in_range(
            "matcher.fallback.min_stereo_matches",
            f.min_stereo_matches,
            1..=MAX_MATCHES,
        )?;
        in_range(
            "matcher.fallback.min_inlier_ratio",
            f.min_inlier_ratio,
            0.0..=1.0,
        )?;
        in_range(
            "matcher.fallback.min_observations",
            f.min_observations,
            0..=MAX_MATCHES,
        )?;
        check_hysteresis(
            "matcher.fallback",
            &[
                ("bad_frames", f.bad_frames),
                ("probe_every", f.probe_every),
                ("recover_probes", f.recover_probes),
            ],
            f.recover_budget_fraction,
        )?;
        in_range(
            "matcher.fallback.recover_stereo_matches",
            f.recover_stereo_matches,
            f.min_stereo_matches.saturating_add(1)..=MAX_MATCHES,
        )
        .map_err(|e| format!("{e}: above min_stereo_matches, that gap is the hysteresis"))?;
        let d = &self.detector_fallback;
        if d.to == DetectorKind::Lsd {
            return Err(
                "detector_fallback.to = \"lsd\": the detector LSD gives way to must be a faster one (fld or edgelines)"
                    .to_string(),
            );
        }
        check_hysteresis(
            "detector_fallback",
            &[
                ("bad_frames", d.bad_frames),
                ("recover_frames", d.recover_frames),
            ],
            d.recover_budget_fraction,
        )?;
        in_range(
            "detector_fallback.min_interval_frames",
            d.min_interval_frames,
            0..=MAX_FRAMES as u64,
        )?;
        let s = &self.supervisor;
        in_range("supervisor.heartbeat_ms", s.heartbeat_ms, HEARTBEAT_MS)?;
        in_range(
            "supervisor.hang_timeout_ms",
            s.hang_timeout_ms,
            2 * s.heartbeat_ms + 1..=MAX_WAIT_MS,
        )
        .map_err(|e| format!("{e}: more than twice heartbeat_ms"))?;
        in_range(
            "supervisor.startup_timeout_ms",
            s.startup_timeout_ms,
            MIN_STARTUP_MS..=MAX_WAIT_MS,
        )?;
        in_range(
            "supervisor.restart_backoff_ms",
            s.restart_backoff_ms,
            1..=MAX_WAIT_MS,
        )?;
        in_range(
            "supervisor.restart_backoff_max_ms",
            s.restart_backoff_max_ms,
            s.restart_backoff_ms..=MAX_WAIT_MS,
        )
        .map_err(|e| format!("{e}: at least restart_backoff_ms"))?;
        in_range("supervisor.max_restarts", s.max_restarts, 0..=MAX_RESTARTS)?;
        in_range(
            "supervisor.drain_timeout_ms",
            s.drain_timeout_ms,
            0..=MAX_WAIT_MS,
        )?;
        in_range(
            "supervisor.shutdown_grace_ms",
            s.shutdown_grace_ms,
            0..=MAX_WAIT_MS,
        )?;
        in_range(
            "supervisor.status_every_ms",
            s.status_every_ms,
            0..=MAX_STATUS_EVERY_MS,
        )?;
        for (stage, settings) in self.stages.all() {
            settings.validate(&format!("stages.{}", stage.name()))?;
        }
        if let Some(root) = &self.ipc.root
            && !root.is_absolute()
        {
            return Err(format!(
                "ipc.root = {:?}: an absolute folder (every stage must find the same one)",
                root.display().to_string()
            ));
        }
        self.link.validate()?;
        self.odometry
            .validate()
            .map_err(|e| format!("odometry.{e}"))?;
        self.ros2.validate()?;
        Ok(())
    }

    /// The odometry settings with the pipeline's detector applied.
    pub fn odometry_config(&self) -> OdometryConfig {
        OdometryConfig {
            detector: self.detector,
            ..self.odometry.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_points_line_names_the_corner_extractor_that_runs() {
        let mut config = PipelineConfig::default();
        assert_eq!(
            config.points_text(),
            "orb-opencv (1500 points, 8 levels of 1.2)"
        );
        let text = "[odometry.frontend.orb]\nextractor = \"fast-brief\"\nfeatures = 1200\nlevels = 4\nscale_factor = 1.44\n";
        let chosen = PipelineConfig::from_toml_str(text, "test").unwrap();
        assert_eq!(
            chosen.points_text(),
            "fast-brief (1200 points, 4 levels of 1.44)"
        );
        config.odometry.features = linetrack_odometry::Features::LinesOnly;
        assert_eq!(config.points_text(), "none (lines only)");
    }

    #[test]
    fn the_shipped_config_is_the_default() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/pipeline.toml");
        let shipped = PipelineConfig::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(shipped, PipelineConfig::default());
    }

    #[test]
    fn the_detector_fallback_is_range_checked_and_never_falls_back_to_lsd() {
        let refused = |text: &str| {
            PipelineConfig::from_toml_str(text, "x.toml")
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default()
        };
        for (text, key) in [
            ("[detector_fallback]\nbad_frames = 0\n", "bad_frames = 0"),
            (
                "[detector_fallback]\nrecover_frames = 1001\n",
                "recover_frames = 1001",
            ),
            (
                "[detector_fallback]\nrecover_budget_fraction = 1.0\n",
                "recover_budget_fraction = 1.0",
            ),
            (
                "[detector_fallback]\nrecover_budget_fraction = nan\n",
                "recover_budget_fraction = NaN",
            ),
            (
                "[detector_fallback]\nmin_interval_frames = 1000000001\n",
                "min_interval_frames = 1000000001",
            ),
        ] {
            let err = refused(text);
            assert!(
                err.contains(&format!("detector_fallback.{key}")) && err.contains("out of range"),
                "{text}: {err}"
            );
        }
        let err = refused("[detector_fallback]\nto = \"lsd\"\n");
        assert!(err.contains("detector_fallback.to"), "{err}");
        assert!(refused("[detector_fallback]\nfrom = \"lsd\"\n").contains("unknown field"));
        let config = PipelineConfig::from_toml_str(
            "[detector_fallback]\nenabled = false\nto = \"edgelines\"\n",
            "x.toml",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(!config.detector_fallback.enabled);
        assert_eq!(config.detector_fallback.to, DetectorKind::EdgeLines);
    }

    #[test]
    fn a_recording_goes_into_the_run_folder_unless_named_and_replay_excludes_a_camera() {
        let config = PipelineConfig::from_toml_str("[record]\nmcap = true\n", "x.toml")
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(config.record.mcap);
        assert_eq!(
            config.record.file(Path::new("out/runs/r1")),
            Path::new("out/runs/r1/recording.mcap")
        );
        let named = PipelineConfig::from_toml_str("[record]\npath = \"/data/a.mcap\"\n", "x.toml")
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(named.record.file(Path::new("x")), Path::new("/data/a.mcap"));
        assert_eq!(PipelineConfig::default().source.replay(), None);
        let err = refusal(
            "[source]\nreplay = \"r.mcap\"\n[camera]\ncapture = \"0\"\ncalibration = \"c.yaml\"\n",
        );
        assert!(err.contains("source.replay"), "{err}");
        let err = refusal("[record]\nclose_timeout_ms = 0\n");
        assert!(err.contains("record.close_timeout_ms"), "{err}");
        let err = refusal("[record]\nmcap = true\nevery_nth = 2\n");
        assert!(err.contains("every_nth"), "{err}");
    }

    #[test]
    fn a_link_topic_scale_endpoint_or_key_out_of_bounds_is_refused_naming_its_key() {
        let err = refusal("[link]\ntopics = [\"poses\", \"video\"]\n");
        assert!(
            err.contains("link.topics") && err.contains("video"),
            "{err}"
        );
        let err = refusal("[link]\nimage_scale = 0\n");
        assert!(err.contains("link.image_scale"), "{err}");
        let err = refusal("[link]\nimage_every = 0\n");
        assert!(err.contains("link.image_every"), "{err}");
        let err = refusal("[link]\nlisten = \"7447\"\n");
        assert!(err.contains("link.listen"), "{err}");
        let err = refusal("[link]\nkey_prefix = \"robot/**\"\n");
        assert!(err.contains("link.key_prefix"), "{err}");
        let err = refusal("[link]\nenable = true\n");
        assert!(err.contains("enable"), "{err}");
        let ok = PipelineConfig::from_toml_str(
            "[link]\nenabled = true\ntopics = [\"images\"]\nkey_prefix = \"robot/one\"\n",
            "x.toml",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(ok.link.allows("images") && !ok.link.allows("poses"));
    }

    #[test]
    fn a_camera_needs_a_calibration_and_a_right_camera_a_left_one() {
        let err = refusal("[camera]\ncapture = \"0\"\n");
        assert!(err.contains("camera.calibration"), "{err}");
        let err = refusal("[camera]\ncapture_right = \"1\"\n");
        assert!(err.contains("camera.capture "), "{err}");
        let ok = PipelineConfig::from_toml_str(
            "[camera]\ncapture = \"0\"\ncapture_right = \"/dev/video1\"\ncalibration = \"camchain.yaml\"\n",
            "x.toml",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(ok.camera.enabled());
        assert_eq!(ok.camera.right(), Some("/dev/video1"));
        assert!(!PipelineConfig::default().camera.enabled());
    }

    #[test]
    fn the_packaged_config_is_the_default_with_the_installed_layout() {
        // /etc/linetrack/pipeline.toml of the Debian package (packaging/etc).
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../packaging/etc/pipeline.toml");
        let packaged = PipelineConfig::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
        let mut expected = PipelineConfig::default();
        expected.output.runs_dir = Some(PathBuf::from("/var/lib/linetrack/runs"));
        expected.ipc.root = Some(PathBuf::from("/run/linetrack/iceoryx2"));
        assert_eq!(packaged, expected);
    }

    #[test]
    fn unknown_keys_and_bad_values_are_named() {
        let err = PipelineConfig::from_toml_str("[budget]\nend_to_end_mz = 3\n", "x.toml")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains("x.toml") && err.contains("end_to_end_mz"),
            "{err}"
        );
        let err = PipelineConfig::from_toml_str("[budget]\nmatcher_ms = nan\n", "x.toml")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("budget.matcher_ms"), "{err}");
        let err = PipelineConfig::from_toml_str(
            "[matcher.fallback]\nrecover_stereo_matches = 5\n",
            "x.toml",
        )
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
        assert!(err.contains("hysteresis"), "{err}");
        let err = PipelineConfig::from_toml_str("detector = \"sift\"\n", "x.toml")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("sift"), "{err}");
    }

    fn refusal(toml: &str) -> String {
        match PipelineConfig::from_toml_str(toml, "x.toml") {
            Ok(_) => panic!("accepted: {toml}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn every_key_is_range_checked_at_load_naming_key_and_range() {
        for (toml, key) in [
            ("[budget]\nend_to_end_ms = 1e308\n", "budget.end_to_end_ms"),
            (
                "[budget]\nframe_source_ms = 0.0\n",
                "budget.frame_source_ms",
            ),
            (
                "[budget]\nline_detector_ms = -1.0\n",
                "budget.line_detector_ms",
            ),
            (
                "[budget]\npose_estimator_ms = inf\n",
                "budget.pose_estimator_ms",
            ),
            ("[source]\nrate_hz = 1e-300\n", "source.rate_hz"),
            ("[source]\nrate_hz = nan\n", "source.rate_hz"),
            ("[source]\nreader_nice = 20\n", "source.reader_nice"),
            ("[source]\ngain_jumps_s = -0.5\n", "source.gain_jumps_s"),
            ("[source]\ngain_jumps_s = nan\n", "source.gain_jumps_s"),
            ("[camera]\nfps = 5000.0\n", "camera.fps"),
            ("[camera]\nlate_ms = nan\n", "camera.late_ms"),
            ("[camera]\nduration_s = -1.0\n", "camera.duration_s"),
            ("[camera]\nretry_ms = 0\n", "camera.retry_ms"),
            (
                "[camera]\nretry_ms = 900\nretry_max_ms = 800\n",
                "camera.retry_max_ms",
            ),
            (
                "[source]\nmax_frames = 9223372036854775807\n",
                "source.max_frames",
            ),
            (
                "[matcher.fallback]\nmin_stereo_matches = 0\n",
                "matcher.fallback.min_stereo_matches",
            ),
            (
                "[matcher.fallback]\nmin_inlier_ratio = 1.5\n",
                "matcher.fallback.min_inlier_ratio",
            ),
            (
                "[matcher.fallback]\nmin_observations = 4000000000\n",
                "matcher.fallback.min_observations",
            ),
            (
                "[matcher.fallback]\nbad_frames = 0\n",
                "matcher.fallback.bad_frames",
            ),
            (
                "[matcher.fallback]\nprobe_every = 5000\n",
                "matcher.fallback.probe_every",
            ),
            (
                "[matcher.fallback]\nrecover_probes = 0\n",
                "matcher.fallback.recover_probes",
            ),
            (
                "[matcher.fallback]\nrecover_budget_fraction = 1.0\n",
                "matcher.fallback.recover_budget_fraction",
            ),
            (
                "[matcher.fallback]\nrecover_stereo_matches = 4000000000\n",
                "matcher.fallback.recover_stereo_matches",
            ),
            (
                "[supervisor]\nheartbeat_ms = 9223372036854775807\n",
                "supervisor.heartbeat_ms",
            ),
            (
                "[supervisor]\nheartbeat_ms = 0\n",
                "supervisor.heartbeat_ms",
            ),
            (
                "[supervisor]\nhang_timeout_ms = 400\n",
                "supervisor.hang_timeout_ms",
            ),
            (
                "[supervisor]\nstartup_timeout_ms = 0\n",
                "supervisor.startup_timeout_ms",
            ),
            (
                "[supervisor]\nrestart_backoff_ms = 0\n",
                "supervisor.restart_backoff_ms",
            ),
            (
                "[supervisor]\nrestart_backoff_max_ms = 100\n",
                "supervisor.restart_backoff_max_ms",
            ),
            (
                "[supervisor]\nmax_restarts = 4000000000\n",
                "supervisor.max_restarts",
            ),
            (
                "[supervisor]\ndrain_timeout_ms = 9223372036854775807\n",
                "supervisor.drain_timeout_ms",
            ),
            (
                "[supervisor]\nshutdown_grace_ms = 9223372036854775807\n",
                "supervisor.shutdown_grace_ms",
            ),
            (
                "[supervisor]\nstatus_every_ms = 9223372036854775807\n",
                "supervisor.status_every_ms",
            ),
        ] {
            let err = refusal(toml);
            assert!(
                err.contains("x.toml")
                    && err.contains(&format!("{key} = "))
                    && err.contains("allowed"),
                "{toml}: {err}"
            );
        }
    }

    #[test]
    fn the_ends_of_every_range_are_accepted() {
        let edges = "[budget]\nend_to_end_ms = 60000.0\nframe_source_ms = 0.001\n\
            [source]\nrate_hz = 1000.0\nmax_frames = 1000000000\n\
            [matcher.fallback]\nmin_stereo_matches = 1\nmin_inlier_ratio = 1.0\n\
            min_observations = 0\nbad_frames = 1000\nprobe_every = 1\n\
            recover_stereo_matches = 100000\nrecover_probes = 1\n\
            [supervisor]\nheartbeat_ms = 10\nhang_timeout_ms = 21\n\
            startup_timeout_ms = 600000\nrestart_backoff_ms = 1\n\
            restart_backoff_max_ms = 600000\nmax_restarts = 0\ndrain_timeout_ms = 0\n\
            shutdown_grace_ms = 600000\nstatus_every_ms = 3600000\n";
        if let Err(e) = PipelineConfig::from_toml_str(edges, "edges.toml") {
            panic!("{e}");
        }
        let slow = "[source]\nrate_hz = 0.01\n[supervisor]\nheartbeat_ms = 10000\n\
            hang_timeout_ms = 600000\nstartup_timeout_ms = 100\n";
        if let Err(e) = PipelineConfig::from_toml_str(slow, "slow.toml") {
            panic!("{e}");
        }
    }

    #[test]
    fn stage_settings_are_read_checked_and_survive_the_run_folder_copy() {
        let text = "[stages.line-detector]\ncpus = [1]\npolicy = \"fifo\"\npriority = 20\n\
            [stages.pose-estimator]\nnice = 5\n[ipc]\nroot = \"/run/linetrack/iceoryx2\"\n";
        let config = PipelineConfig::from_toml_str(text, "x").unwrap_or_else(|e| panic!("{e}"));
        let detector = config
            .stages
            .of(StageKind::LineDetector)
            .cloned()
            .unwrap_or_default();
        assert_eq!(detector.cpus, Some(vec![1]));
        assert_eq!(detector.policy, Some(Policy::Fifo));
        assert_eq!(detector.priority, Some(20));
        assert_eq!(config.stages.pose_estimator.nice, Some(5));
        assert!(config.stages.matcher.is_empty());
        assert_eq!(config.stages.of(StageKind::Supervisor), None);
        assert_eq!(
            config.ipc.root.as_deref(),
            Some(Path::new("/run/linetrack/iceoryx2"))
        );
        // The supervisor hands the stages the config through a copy it writes.
        let copy = toml::to_string(&config).unwrap_or_else(|e| panic!("{e}"));
        let back = PipelineConfig::from_toml_str(&copy, "copy").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back, config);
    }

    #[test]
    fn unknown_stages_and_bad_stage_settings_are_refused_by_name() {
        let err = refusal("[stages.line-dectector]\ncpus = [1]\n");
        assert!(err.contains("line-dectector"), "{err}");
        let err = refusal("[stages.supervisor]\ncpus = [1]\n");
        assert!(err.contains("supervisor"), "{err}");
        let err = refusal("[stages.matcher]\npolicy = \"fifo\"\npriority = 120\n");
        assert!(
            err.contains("x.toml") && err.contains("stages.matcher.priority = 120"),
            "{err}"
        );
        let err = refusal("[stages.frame-source]\ncpus = []\n");
        assert!(err.contains("stages.frame-source.cpus"), "{err}");
        let err = refusal("[ipc]\nroot = \"relative/iceoryx2\"\n");
        assert!(err.contains("ipc.root"), "{err}");
    }

    #[test]
    fn odometry_follows_the_pipeline_detector() {
        let config = PipelineConfig::from_toml_str("detector = \"fld\"\n", "x")
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(config.odometry_config().detector, DetectorKind::Fld);
    }
}
