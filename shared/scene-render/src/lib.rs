//! Deterministic renderer of stereo sequences with exact ground truth, for testing line
//! tracking under illumination changes where no real HDR dataset can be downloaded, and the
//! odometry's scale where most structure is far.
//!
//! A seeded [`Scene`] (a room of textured rectangles: tiled floor, walls, doors, posters, a
//! bright window, a checkerboard, striped radiators and shelves, plain low-texture areas)
//! is seen by a rectified stereo rig moving along a smooth [`Trajectory`] (hand-held or
//! drone-like); or a road ([`RoadPath`]: lane paint, a guard rail, posts, buildings, a far
//! tree line, sky) is driven along at 10 m/s with KITTI's rig ([`Preset::Highway`]). Each frame is rendered with 2×2 anti-aliasing, optics blur, exposure with
//! the frame's [`FrameIllumination`] (gain/bias jumps, flicker, local lights, saturation,
//! left/right mismatch), sensor noise and 8-bit quantisation. Every frame comes with the
//! exact pose and per-pixel depth maps of both cameras; the scene's 3-D segments are known.
//!
//! The same seed and configuration give the same bytes.
#![warn(missing_docs)]

mod motion;
mod render;
mod road;
mod scene;

pub use motion::{
    FrameIllumination, IlluminationConfig, ROAD_SPEED_M_S, Trajectory, TrajectoryKind,
};
pub use render::{SensorOptions, View, render_view};
pub use road::{CAMERA_HEIGHT_M, RoadPath};
pub use scene::{Quad, Scene, Texture};

use linetrack_geometry::StereoRig;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};

/// Everything that decides a sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SequenceConfig {
    /// Seed of the scene, trajectory phases and noise.
    pub seed: u64,
    /// Number of stereo frames.
    pub frames: usize,
    /// Frame rate, Hz.
    pub rate_hz: f64,
    /// The rectified stereo rig.
    pub rig: StereoRig,
    /// How the camera moves.
    pub trajectory: TrajectoryKind,
    /// Illumination effects.
    pub illumination: IlluminationConfig,
    /// Optics and sensor.
    pub sensor: SensorOptions,
}

impl Default for SequenceConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            frames: 60,
            rate_hz: 20.0,
            rig: StereoRig::default(),
            trajectory: TrajectoryKind::Handheld,
            illumination: IlluminationConfig::default(),
            sensor: SensorOptions::default(),
        }
    }
}

/// Named combinations of trajectory and illumination.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// Hand-held, steady light.
    Normal,
    /// Hand-held, gain/bias jumps every 2 s (the paper's protocol, compressed in time).
    HandheldGainJumps,
    /// Drone, gain/bias jumps every 2 s.
    DroneGainJumps,
    /// Hand-held, 7 Hz flicker of depth 0.5 over a 1.6× over-exposure (saturated window).
    HdrFlicker,
    /// Hand-held, over-exposed 2.2×: saturated areas.
    HdrSaturation,
    /// Hand-held, the two halves of the room's lights switching on and off.
    LightsSwitching,
    /// Hand-held, right camera at gain 0.5 and bias +15 (left/right mismatch).
    LeftRightMismatch,
    /// A car at 10 m/s (1 m per frame at 10 Hz) on a road with a curve, KITTI's rig, steady
    /// daylight: far-field structure (most of it 30–150 m away), sky, few near features.
    Highway,
}

impl Preset {
    /// Every preset.
    pub const ALL: [Preset; 8] = [
        Preset::Normal,
        Preset::HandheldGainJumps,
        Preset::DroneGainJumps,
        Preset::HdrFlicker,
        Preset::HdrSaturation,
        Preset::LightsSwitching,
        Preset::LeftRightMismatch,
        Preset::Highway,
    ];

    /// The preset's name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Normal => "normal",
            Preset::HandheldGainJumps => "handheld-gain-jumps",
            Preset::DroneGainJumps => "drone-gain-jumps",
            Preset::HdrFlicker => "hdr-flicker",
            Preset::HdrSaturation => "hdr-saturation",
            Preset::LightsSwitching => "lights-switching",
            Preset::LeftRightMismatch => "left-right-mismatch",
            Preset::Highway => "highway",
        }
    }

    /// The sequence configuration of this preset with `seed` and `frames`.
    pub fn config(self, seed: u64, frames: usize) -> SequenceConfig {
        let illumination = IlluminationConfig {
            seed,
            ..IlluminationConfig::default()
        };
        let (trajectory, illumination) = match self {
            Preset::Normal => (TrajectoryKind::Handheld, illumination),
            Preset::HandheldGainJumps => (
                TrajectoryKind::Handheld,
                IlluminationConfig {
                    gain_jump_period_s: Some(2.0),
                    ..illumination
                },
            ),
            Preset::DroneGainJumps => (
                TrajectoryKind::Drone,
                IlluminationConfig {
                    gain_jump_period_s: Some(2.0),
                    ..illumination
                },
            ),
            Preset::HdrFlicker => (
                TrajectoryKind::Handheld,
                IlluminationConfig {
                    base_gain: 1.6,
                    flicker: Some((7.0, 0.5)),
                    ..illumination
                },
            ),
            Preset::HdrSaturation => (
                TrajectoryKind::Handheld,
                IlluminationConfig {
                    base_gain: 2.2,
                    ..illumination
                },
            ),
            Preset::LightsSwitching => (
                TrajectoryKind::Handheld,
                IlluminationConfig {
                    light_switch_period_s: Some(1.5),
                    ..illumination
                },
            ),
            Preset::LeftRightMismatch => (
                TrajectoryKind::Handheld,
                IlluminationConfig {
                    right_mismatch: Some((0.5, 15.0)),
                    ..illumination
                },
            ),
            Preset::Highway => {
                return SequenceConfig {
                    seed,
                    frames,
                    rate_hz: 10.0,
                    rig: kitti_rig(),
                    trajectory: TrajectoryKind::Road,
                    illumination,
                    ..SequenceConfig::default()
                };
            }
        };
        SequenceConfig {
            seed,
            frames,
            trajectory,
            illumination,
            ..SequenceConfig::default()
        }
    }
}

/// The rectified grey rig of the KITTI odometry benchmark (sequences 00–02: P0 and P1).
fn kitti_rig() -> StereoRig {
    StereoRig {
        focal_px: 718.856,
        cx_px: 607.1928,
        cy_px: 185.2157,
        baseline_m: 0.537,
        width_px: 1241,
        height_px: 376,
    }
}

impl std::str::FromStr for Preset {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|p| p.name()).collect();
                format!("unknown preset {s:?}: expected one of {}", names.join(", "))
            })
    }
}

/// One rendered stereo frame with its ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedFrame {
    /// Position in the sequence.
    pub index: usize,
    /// Capture time, nanoseconds from the start.
    pub timestamp_ns: u64,
    /// Pose of the left camera in the world (`p_world = pose · p_camera`).
    pub world_from_left: Isometry3<f64>,
    /// Left view.
    pub left: View,
    /// Right view.
    pub right: View,
    /// Illumination of this frame.
    pub illumination: FrameIllumination,
}

/// A scene and its trajectory, ready to render frames of a sequence.
#[derive(Debug, Clone)]
pub struct SequenceRenderer {
    /// The configuration.
    pub config: SequenceConfig,
    /// The scene.
    pub scene: Scene,
    trajectory: Trajectory,
}

impl SequenceRenderer {
    /// Builds the scene and trajectory of `config`.
    pub fn new(config: SequenceConfig) -> Self {
        let (scene, trajectory) = if config.trajectory == TrajectoryKind::Road {
            let trajectory =
                Trajectory::new(config.trajectory, nalgebra::Vector3::zeros(), config.seed);
            let length_m = config.frames as f64 / config.rate_hz * ROAD_SPEED_M_S;
            let scene = Scene::random_road(config.seed, trajectory.road(), length_m);
            (scene, trajectory)
        } else {
            let scene = Scene::random_room(config.seed);
            let trajectory = Trajectory::new(config.trajectory, scene.room_m, config.seed);
            (scene, trajectory)
        };
        Self {
            config,
            scene,
            trajectory,
        }
    }

    /// Time of frame `index`, seconds.
    pub fn time_s(&self, index: usize) -> f64 {
        index as f64 / self.config.rate_hz
    }

    /// Pose of the right camera given the left camera's.
    pub fn right_pose(&self, world_from_left: &Isometry3<f64>) -> Isometry3<f64> {
        world_from_left
            * Isometry3::from_parts(
                Translation3::new(self.config.rig.baseline_m, 0.0, 0.0),
                UnitQuaternion::identity(),
            )
    }

    /// Pose of the left camera at frame `index`, without rendering.
    pub fn render_pose(&self, index: usize) -> Isometry3<f64> {
        self.trajectory.pose_at(self.time_s(index))
    }

    /// Renders frame `index`.
    pub fn render(&self, index: usize) -> RenderedFrame {
        let t = self.time_s(index);
        let world_from_left = self.trajectory.pose_at(t);
        let illumination = self.config.illumination.at(t, self.scene.lights);
        let rig = &self.config.rig;
        let noise = |camera: u64| {
            self.config.seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ ((index as u64) << 1 | camera)
        };
        let (left, right) = std::thread::scope(|scope| {
            let right = scope.spawn(|| {
                render_view(
                    &self.scene,
                    &self.right_pose(&world_from_left),
                    rig,
                    &illumination,
                    1,
                    &self.config.sensor,
                    noise(1),
                )
            });
            let left = render_view(
                &self.scene,
                &world_from_left,
                rig,
                &illumination,
                0,
                &self.config.sensor,
                noise(0),
            );
            (
                left,
                right
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic)),
            )
        });
        RenderedFrame {
            index,
            timestamp_ns: (t * 1e9).round() as u64,
            world_from_left,
            left,
            right,
            illumination,
        }
    }
}
