//! Camera trajectories and illumination over time.

use crate::road::{CAMERA_HEIGHT_M, RoadPath};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// How the camera moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TrajectoryKind {
    /// Walking pace, gentle turns, a little hand shake.
    Handheld,
    /// Faster, wider loops, steady yaw rotation.
    Drone,
    /// A car on a road at 10 m/s (see [`RoadPath`]), the camera 1.65 m above it, with a
    /// little suspension bounce.
    Road,
}

/// Speed of the [`TrajectoryKind::Road`] car, m/s.
pub const ROAD_SPEED_M_S: f64 = 10.0;

/// A smooth trajectory through the middle of a room.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trajectory {
    kind: TrajectoryKind,
    road: RoadPath,
    centre: Vector3<f64>,
    amplitude: Vector3<f64>,
    phase: [f64; 4],
}

impl Trajectory {
    /// A trajectory of `kind` in a room of size `room_m` (z up), phases drawn from `seed`.
    pub fn new(kind: TrajectoryKind, room_m: Vector3<f64>, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7A11);
        let phase = std::array::from_fn(|_| rng.random_range(0.0..TAU));
        // Keep at least 1.5 m from the walls, where boxes and shelves stand.
        let free = Vector3::new(
            (room_m.x / 2.0 - 1.5).max(0.1),
            (room_m.y / 2.0 - 1.5).max(0.1),
            0.3,
        );
        let amplitude = match kind {
            TrajectoryKind::Handheld => Vector3::new(0.6, 0.5, 0.06).inf(&free),
            TrajectoryKind::Drone => Vector3::new(1.4, 1.2, 0.25).inf(&free),
            TrajectoryKind::Road => Vector3::zeros(),
        };
        Self {
            kind,
            road: RoadPath::new(seed),
            centre: Vector3::new(room_m.x / 2.0, room_m.y / 2.0, 1.4),
            amplitude,
            phase,
        }
    }

    /// Pose of the left camera (x right, y down, z forward) in the world at `t` seconds.
    pub fn pose_at(&self, t: f64) -> Isometry3<f64> {
        if self.kind == TrajectoryKind::Road {
            return self.on_road(t);
        }
        let p = &self.phase;
        let (freq, yaw, pitch, roll, shake) = match self.kind {
            TrajectoryKind::Handheld => (
                [0.11, 0.17, 0.6],
                1.1 * (TAU * 0.05 * t + p[3]).sin(),
                0.06,
                0.03,
                0.004,
            ),
            TrajectoryKind::Drone => ([0.12, 0.17, 0.2], TAU * 0.07 * t + p[3], 0.04, 0.02, 0.0),
            TrajectoryKind::Road => unreachable!("handled by on_road"),
        };
        let position = self.centre
            + Vector3::new(
                self.amplitude.x * (TAU * freq[0] * t + p[0]).sin(),
                self.amplitude.y * (TAU * freq[1] * t + p[1]).sin(),
                self.amplitude.z * (TAU * freq[2] * t + p[2]).sin(),
            );
        let pitch = pitch * (TAU * 0.09 * t + p[1]).sin() + shake * (TAU * 2.3 * t).sin();
        let roll = roll * (TAU * 0.13 * t + p[2]).sin() + shake * (TAU * 1.7 * t + 1.0).sin();
        let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), -pitch)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), roll);
        Isometry3::from_parts(
            Translation3::from(position),
            UnitQuaternion::from_rotation_matrix(&(turn * looking_along_x())),
        )
    }

    /// The road's path, for a [`TrajectoryKind::Road`] trajectory.
    pub fn road(&self) -> &RoadPath {
        &self.road
    }

    /// On the road: along the path at [`ROAD_SPEED_M_S`], facing the direction of travel,
    /// with a 1–2 Hz suspension bounce of a centimetre and a tenth of a degree of pitch.
    fn on_road(&self, t: f64) -> Isometry3<f64> {
        let p = &self.phase;
        let s = ROAD_SPEED_M_S * t;
        let ground = self.road.point(s);
        let bounce = 0.01 * (TAU * 1.3 * t + p[0]).sin();
        let pitch = 0.1f64.to_radians() * (TAU * 1.7 * t + p[1]).sin();
        let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), self.road.heading(s))
            * Rotation3::from_axis_angle(&Vector3::y_axis(), -pitch);
        Isometry3::from_parts(
            Translation3::new(ground.x, ground.y, CAMERA_HEIGHT_M + bounce),
            UnitQuaternion::from_rotation_matrix(&(turn * looking_along_x())),
        )
    }
}

/// Camera axes in the world when looking along +x: right = −y, down = −z, forward = +x.
fn looking_along_x() -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0))
}

/// Illumination effects, each switchable; all seeded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IlluminationConfig {
    /// Seed of the random draws.
    pub seed: u64,
    /// Exposure gain of both cameras before any effect (> 1 over-exposes: saturation).
    pub base_gain: f64,
    /// Global gain/bias jumps every this many seconds: α ~ U(0.5, 2.5), β ~ U(0, 20)
    /// (the paper's EuRoC protocol). The first period is unperturbed.
    pub gain_jump_period_s: Option<f64>,
    /// Flicker: gain × (1 + depth · sin(2π f t)), `(f_hz, depth)`.
    pub flicker: Option<(f64, f64)>,
    /// Local lights (two groups, each lighting half the room) switch between full and
    /// 25 % about every this many seconds.
    pub light_switch_period_s: Option<f64>,
    /// Right camera only: extra `(gain, bias)`, a left/right mismatch.
    pub right_mismatch: Option<(f64, f64)>,
}

impl Default for IlluminationConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            base_gain: 1.0,
            gain_jump_period_s: None,
            flicker: None,
            light_switch_period_s: None,
            right_mismatch: None,
        }
    }
}

/// The illumination of one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameIllumination {
    /// Gain of the left and right camera.
    pub gain: [f64; 2],
    /// Bias (grey levels) of the left and right camera.
    pub bias: [f64; 2],
    /// Level of each light group.
    pub lights: Vec<f32>,
}

impl IlluminationConfig {
    /// A uniform draw in [lo, hi) that depends only on (seed, stream, index).
    fn draw(&self, stream: u64, index: i64, lo: f64, hi: f64) -> f64 {
        let mut rng = ChaCha8Rng::seed_from_u64(
            self.seed ^ stream.wrapping_mul(0x9E37_79B9) ^ (index as u64).wrapping_mul(0x85EB_CA6B),
        );
        rng.random_range(lo..hi)
    }

    /// The illumination at `t` seconds, for a scene with `lights` light groups.
    pub fn at(&self, t: f64, lights: usize) -> FrameIllumination {
        let (mut gain, mut bias) = (self.base_gain, 0.0);
        if let Some(period) = self.gain_jump_period_s.filter(|p| *p > 0.0) {
            let index = (t / period).floor() as i64;
            if index > 0 {
                gain *= self.draw(1, index, 0.5, 2.5);
                bias += self.draw(2, index, 0.0, 20.0);
            }
        }
        if let Some((f_hz, depth)) = self.flicker {
            gain *= 1.0 + depth * (std::f64::consts::TAU * f_hz * t).sin();
        }
        let levels = (0..lights)
            .map(|g| match self.light_switch_period_s.filter(|p| *p > 0.0) {
                Some(period) => {
                    let index = (t / period).floor() as i64;
                    if index > 0 && self.draw(3 + g as u64, index, 0.0, 1.0) < 0.5 {
                        0.25
                    } else {
                        1.0
                    }
                }
                None => 1.0,
            })
            .collect();
        let (right_gain, right_bias) = self.right_mismatch.unwrap_or((1.0, 0.0));
        FrameIllumination {
            gain: [gain, gain * right_gain],
            bias: [bias, bias + right_bias],
            lights: levels,
        }
    }
}
