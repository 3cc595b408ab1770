//! The renderer: a z-buffered rasteriser of textured rectangles with 2×2 anti-aliasing,
//! optics blur, exposure, sensor noise and 8-bit quantisation; and exact depth maps.
//!
//! Pixel centres are at integer coordinates (the OpenCV convention): pixel (u, v) sees the
//! ray through `((u − cx)/f, (v − cy)/f, 1)`. The depth map holds, per pixel, the depth (z
//! in the camera frame, metres) of the surface that ray hits first; 0 where it hits none.

use crate::{FrameIllumination, Scene};
use linetrack_geometry::StereoRig;
use nalgebra::{Isometry3, Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// Closest depth rendered, metres.
const NEAR_M: f64 = 0.05;
/// Anti-aliasing sample offsets (pixels) around the pixel centre, then the centre itself
/// (used for the depth map only).
const SAMPLES: [(f64, f64); 5] = [
    (-0.25, -0.25),
    (0.25, -0.25),
    (-0.25, 0.25),
    (0.25, 0.25),
    (0.0, 0.0),
];
/// Direction towards the room's key light, for shading.
const KEY_LIGHT: [f64; 3] = [0.3, 0.5, 0.8];

/// Sensor and optics.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorOptions {
    /// Grey level of a white surface under full light at gain 1.
    pub white_level: f64,
    /// Weight of each direct neighbour in the separable 3-tap optics blur (0 = none).
    pub blur: f32,
    /// Standard deviation of the additive Gaussian read noise, grey levels.
    pub read_noise: f64,
    /// Shot noise: standard deviation `shot_noise · sqrt(level)`.
    pub shot_noise: f64,
}

impl Default for SensorOptions {
    fn default() -> Self {
        Self {
            white_level: 200.0,
            blur: 0.2,
            read_noise: 1.2,
            shot_noise: 0.15,
        }
    }
}

/// One rendered camera view.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// 8-bit grey levels, row-major.
    pub pixels: Vec<u8>,
    /// Depth in metres per pixel (0: nothing hit), row-major.
    pub depth_m: Vec<f32>,
}

impl View {
    /// Depth at pixel (u, v), `None` outside the image or where nothing was hit.
    pub fn depth_at(&self, u: usize, v: usize) -> Option<f32> {
        (u < self.width && v < self.height)
            .then(|| self.depth_m[v * self.width + u])
            .filter(|d| *d > 0.0)
    }
}

/// A quad in camera coordinates, with what the inner loop needs.
struct CameraQuad {
    origin: Vector3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
    normal: Vector3<f64>,
    u_norm2: f64,
    v_norm2: f64,
    /// Pixel bounding box (inclusive) of its part in front of the near plane.
    bbox: (usize, usize, usize, usize),
    shade: f32,
}

/// Renders the scene seen by a camera at `world_from_camera` with intrinsics of `rig`
/// (left camera: the rig's intrinsics hold for both), lit by `illumination`
/// (`camera` 0 = left, 1 = right), noise drawn from `noise_seed`.
pub fn render_view(
    scene: &Scene,
    world_from_camera: &Isometry3<f64>,
    rig: &StereoRig,
    illumination: &FrameIllumination,
    camera: usize,
    sensor: &SensorOptions,
    noise_seed: u64,
) -> View {
    let (width, height) = (rig.width_px as usize, rig.height_px as usize);
    let camera_from_world = world_from_camera.inverse();
    let key = Vector3::from(KEY_LIGHT).normalize();
    let quads: Vec<CameraQuad> = scene
        .quads
        .iter()
        .map(|q| {
            let corners: Vec<Point3<f64>> =
                q.corners().iter().map(|c| camera_from_world * c).collect();
            // Only the part in front of the near plane can be hit: its projection bounds
            // the pixels to visit (a quad reaching behind the camera no longer costs the
            // whole image).
            let visible = clip_to_near(&corners);
            let bbox = if visible.is_empty() {
                (1, 0, 1, 0) // empty
            } else {
                let us = visible.iter().map(|c| rig.focal_px * c.x / c.z + rig.cx_px);
                let vs = visible.iter().map(|c| rig.focal_px * c.y / c.z + rig.cy_px);
                let (u0, u1) = us.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), u| {
                    (a.min(u), b.max(u))
                });
                let (v0, v1) = vs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                    (a.min(v), b.max(v))
                });
                let clamp_u = |x: f64| x.clamp(0.0, (width - 1) as f64) as usize;
                let clamp_v = |y: f64| y.clamp(0.0, (height - 1) as f64) as usize;
                if u1 < 0.0 || v1 < 0.0 || u0 > (width - 1) as f64 || v0 > (height - 1) as f64 {
                    (1, 0, 1, 0) // empty
                } else {
                    (
                        clamp_u(u0.floor() - 1.0),
                        clamp_u(u1.ceil() + 1.0),
                        clamp_v(v0.floor() - 1.0),
                        clamp_v(v1.ceil() + 1.0),
                    )
                }
            };
            let u = camera_from_world.rotation * q.u;
            let v = camera_from_world.rotation * q.v;
            CameraQuad {
                origin: corners[0].coords,
                normal: u.cross(&v).normalize(),
                u_norm2: u.norm_squared(),
                v_norm2: v.norm_squared(),
                u,
                v,
                bbox,
                shade: (0.55 + 0.45 * q.normal().dot(&key).abs()) as f32,
            }
        })
        .collect();

    // Per sample: nearest depth and the radiance found there.
    let samples = width * height;
    let mut depth = vec![f64::INFINITY; samples * SAMPLES.len()];
    let mut radiance = vec![scene.background; samples * SAMPLES.len()];
    for (qi, cq) in quads.iter().enumerate() {
        let quad = &scene.quads[qi];
        let light = illumination.lights.get(quad.light).copied().unwrap_or(1.0);
        let plane = cq.normal.dot(&cq.origin);
        let (u0, u1, v0, v1) = cq.bbox;
        for py in v0..=v1.min(height - 1) {
            for px in u0..=u1.min(width - 1) {
                for (k, (ox, oy)) in SAMPLES.iter().enumerate() {
                    let dir = Vector3::new(
                        (px as f64 + ox - rig.cx_px) / rig.focal_px,
                        (py as f64 + oy - rig.cy_px) / rig.focal_px,
                        1.0,
                    );
                    let denominator = cq.normal.dot(&dir);
                    if denominator.abs() < 1e-12 {
                        continue;
                    }
                    let z = plane / denominator;
                    let slot = (py * width + px) * SAMPLES.len() + k;
                    if z <= NEAR_M || z >= depth[slot] {
                        continue;
                    }
                    let relative = dir * z - cq.origin;
                    let (s, t) = (
                        relative.dot(&cq.u) / cq.u_norm2,
                        relative.dot(&cq.v) / cq.v_norm2,
                    );
                    if !(0.0..=1.0).contains(&s) || !(0.0..=1.0).contains(&t) {
                        continue;
                    }
                    depth[slot] = z;
                    if k < 4 {
                        radiance[slot] =
                            quad.reflectance(s, t, scene.noise_seed) * light * cq.shade
                                + quad.emission;
                    }
                }
            }
        }
    }

    // Anti-aliased radiance, optics blur, exposure, noise, quantisation.
    let mut image: Vec<f32> = (0..samples)
        .map(|p| {
            radiance[p * SAMPLES.len()..p * SAMPLES.len() + 4]
                .iter()
                .sum::<f32>()
                / 4.0
        })
        .collect();
    blur_3tap(&mut image, width, height, sensor.blur);
    let mut rng = ChaCha8Rng::seed_from_u64(noise_seed);
    let (gain, bias) = (illumination.gain[camera], illumination.bias[camera]);
    let pixels = image
        .iter()
        .map(|r| {
            let level = gain * sensor.white_level * f64::from(*r) + bias;
            let sigma =
                (sensor.read_noise.powi(2) + sensor.shot_noise.powi(2) * level.max(0.0)).sqrt();
            (level + sigma * rng.sample::<f64, _>(StandardNormal))
                .round()
                .clamp(0.0, 255.0) as u8
        })
        .collect();
    let depth_m = (0..samples)
        .map(|p| {
            let z = depth[p * SAMPLES.len() + 4];
            if z.is_finite() { z as f32 } else { 0.0 }
        })
        .collect();
    View {
        width,
        height,
        pixels,
        depth_m,
    }
}

/// The part of the convex polygon `corners` (camera frame) in front of the near plane
/// (z ≥ [`NEAR_M`]), as its corners; empty when none of it is. A sample only counts a hit
/// beyond the near plane, so this part's projection holds every pixel the polygon can cover.
fn clip_to_near(corners: &[Point3<f64>]) -> Vec<Point3<f64>> {
    let mut visible = Vec::with_capacity(corners.len() + 1);
    for (i, a) in corners.iter().enumerate() {
        let b = &corners[(i + 1) % corners.len()];
        if a.z > NEAR_M {
            visible.push(*a);
        }
        if (a.z > NEAR_M) != (b.z > NEAR_M) {
            let along = (NEAR_M - a.z) / (b.z - a.z);
            let mut crossing = a + (b - a) * along;
            crossing.z = NEAR_M;
            visible.push(crossing);
        }
    }
    visible
}

/// Separable blur with kernel [w, 1 − 2w, w], clamped at the borders.
fn blur_3tap(image: &mut [f32], width: usize, height: usize, w: f32) {
    if w <= 0.0 {
        return;
    }
    let centre = 1.0 - 2.0 * w;
    let mut tmp = image.to_vec();
    for y in 0..height {
        for x in 0..width {
            let at = |xx: usize| image[y * width + xx];
            tmp[y * width + x] =
                w * at(x.saturating_sub(1)) + centre * at(x) + w * at((x + 1).min(width - 1));
        }
    }
    for y in 0..height {
        for x in 0..width {
            let at = |yy: usize| tmp[yy * width + x];
            image[y * width + x] =
                w * at(y.saturating_sub(1)) + centre * at(y) + w * at((y + 1).min(height - 1));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_near_clip_keeps_the_part_of_a_quad_in_front_of_the_camera() {
        let quad = |z: [f64; 4]| {
            [
                Point3::new(-1.0, -1.0, z[0]),
                Point3::new(1.0, -1.0, z[1]),
                Point3::new(1.0, 1.0, z[2]),
                Point3::new(-1.0, 1.0, z[3]),
            ]
        };
        // In front: unchanged.
        let front = quad([2.0; 4]);
        assert_eq!(clip_to_near(&front), front);
        // Behind: nothing.
        assert!(clip_to_near(&quad([-1.0, -1.0, NEAR_M, NEAR_M])).is_empty());
        // Across (a floor from behind the camera to 3 m ahead): the part from the near
        // plane on, x spanning the whole quad.
        let across = clip_to_near(&quad([-1.0, -1.0, 3.0, 3.0]));
        assert_eq!(across.len(), 4, "{across:?}");
        assert!(across.iter().all(|c| c.z >= NEAR_M), "{across:?}");
        assert!(across.iter().any(|c| c.x == -1.0) && across.iter().any(|c| c.x == 1.0));
        let near: Vec<&Point3<f64>> = across.iter().filter(|c| c.z == NEAR_M).collect();
        assert_eq!(near.len(), 2, "{across:?}");
        let y_at_near = -1.0 + 2.0 * (NEAR_M + 1.0) / 4.0;
        assert!(
            near.iter().all(|c| (c.y - y_at_near).abs() < 1e-12),
            "{near:?}"
        );
    }
}
