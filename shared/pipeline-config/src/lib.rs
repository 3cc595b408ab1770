//! The pipeline's configuration (`configs/pipeline.toml`): what the frame source reads and
//! how fast, which detector and matcher run, the latency budgets and drop policy, when the
//! matcher falls back to ℓ1 and comes back, and how the supervisor watches and restarts
//! stages, each stage's CPUs and scheduling policy (`[stages.<name>]`, applied by
//! `linetrack-sched`), where the shared memory's bookkeeping lives (`[ipc]`), and the
//! optional ROS 2 output (`[ros2]`). Every
//! field has a default; [`PipelineConfig::validate`] names the first bad one.

mod budget;
mod camera;
mod detector_fallback;
pub mod file;
mod ipc;
mod limits;
mod link;
mod matcher;
mod output;
mod record;
mod ros2;
mod ros2_images;
mod source;
mod stages;
mod supervisor;

pub use budget::{BehindRule, BudgetConfig};
pub use camera::CameraConfig;
pub use detector_fallback::DetectorFallbackConfig;
pub use ipc::IpcConfig;
pub use linetrack_sched::{Policy, SchedSettings};
pub use link::LinkConfig;
pub use matcher::{FallbackConfig, MatcherConfig, MatcherPolicy};
pub use output::{OnRecordError, OutputConfig, default_runs_dir};
pub use record::RecordConfig;
pub use ros2::{CameraMount, Convention, MAX_DOMAIN_ID, Ros2Config, StampSource};
pub use ros2_images::{MAX_STAMP_TOLERANCE_MS, Ros2ImagesConfig};
pub use source::{Pacing, SourceConfig};
pub use stages::StagesConfig;
pub use supervisor::SupervisorConfig;

use linetrack_odometry_config::OdometryConfig;
use linetrack_vision_config::DetectorKind;
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
            linetrack_odometry_config::Features::LinesOnly => "none (lines only)".to_string(),
            linetrack_odometry_config::Features::PointsAndLines => {
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
        self.budget.validate()?;
        self.output.validate()?;
        self.ipc.validate()?;
        self.source.validate()?;
        self.record.validate()?;
        if self.source.replay().is_some() && self.camera.enabled() {
            return Err(
                "source.replay and camera.capture are both set: frames come from one of them"
                    .to_string(),
            );
        }
        self.camera.validate()?;
        if self.camera.ros2_images.enabled() && self.source.replay().is_some() {
            return Err(
                "camera.ros2_images is set with source.replay: frames come from one of them"
                    .to_string(),
            );
        }
        self.matcher.validate()?;
        self.detector_fallback.validate()?;
        self.supervisor.validate()?;
        self.stages.validate()?;
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
    use linetrack_msgs::StageKind;

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
        config.odometry.features = linetrack_odometry_config::Features::LinesOnly;
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
        let of = |stage| config.stages.of(stage).cloned().unwrap_or_default();
        assert_eq!(of(StageKind::PoseEstimator).nice, Some(5));
        assert!(of(StageKind::Matcher).is_empty());
        // Every node the declaration schedules has a section, in its order.
        let sections: Vec<StageKind> = config.stages.all().iter().map(|(s, _)| *s).collect();
        assert_eq!(sections, StageKind::PROCESSING);
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
        assert!(
            err.contains("expected one of frame-source, line-detector, matcher, pose-estimator"),
            "{err}"
        );
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
