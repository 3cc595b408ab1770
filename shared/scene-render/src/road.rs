//! An outdoor road for far-field sequences: a path (straight, a curve, straight), the
//! car's camera driving along it at road speed, and the scene beside it — asphalt with lane
//! markings, a guard rail, lamp posts, signs, buildings from 12 to 70 m off the road and a
//! far tree line — under a bright, featureless sky.
//!
//! Most structure is seen from 30 to 150 m away, as from a car on a highway: with KITTI's
//! rig (0.54 m baseline, f ≈ 718 px) that is 2.6 to 13 px of disparity, where a depth from
//! a noisy disparity is least certain.

use crate::scene::{Quad, Scene, Texture};
use nalgebra::{Point3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Height of the camera above the road, metres (KITTI's: 1.65 m).
pub const CAMERA_HEIGHT_M: f64 = 1.65;
/// Width of the asphalt, metres (two lanes and shoulders).
const ROAD_WIDTH_M: f64 = 10.0;
/// Length of each flat piece the road and its rails are built of, metres.
const PIECE_M: f64 = 4.0;
/// How far ahead of the last frame the scene is built, metres.
const AHEAD_M: f64 = 170.0;

/// The road's centre line on the ground plane (z = 0): straight, then an arc of constant
/// curvature, then straight again; `s` is the distance along it from the start, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoadPath {
    /// Where the curve starts, metres.
    pub curve_start_m: f64,
    /// Length of the curve, metres.
    pub curve_length_m: f64,
    /// Curvature, 1/m (positive: turning left).
    pub curvature: f64,
}

impl RoadPath {
    /// A path drawn from `seed`: the curve starts after 10–30 m, lasts 60–100 m, with a
    /// radius of 150–300 m to either side (a highway on-ramp's sweep: 11–38° of turn).
    pub fn new(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x20AD);
        let radius = rng.random_range(150.0..300.0);
        let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        Self {
            curve_start_m: rng.random_range(10.0..30.0),
            curve_length_m: rng.random_range(60.0..100.0),
            curvature: side / radius,
        }
    }

    /// Heading at `s`: the angle of the direction of travel from the world's +x, radians.
    pub fn heading(&self, s: f64) -> f64 {
        self.curvature * (s - self.curve_start_m).clamp(0.0, self.curve_length_m)
    }

    /// The centre line's point at `s` (before the start: the first straight extended back).
    pub fn point(&self, s: f64) -> Vector2<f64> {
        let start = Vector2::new(self.curve_start_m, 0.0);
        if s <= self.curve_start_m {
            return Vector2::new(s, 0.0);
        }
        let in_curve = (s - self.curve_start_m).min(self.curve_length_m);
        let k = self.curvature;
        let turned = k * in_curve;
        let end_of_curve = start + Vector2::new(turned.sin() / k, (1.0 - turned.cos()) / k);
        let after = s - self.curve_start_m - in_curve;
        end_of_curve + Vector2::new(turned.cos(), turned.sin()) * after
    }

    /// Unit direction of travel at `s`.
    pub fn tangent(&self, s: f64) -> Vector2<f64> {
        let h = self.heading(s);
        Vector2::new(h.cos(), h.sin())
    }
}

/// A point `lateral` metres left of the centre line at `s`, `up` metres above the road.
fn beside(path: &RoadPath, s: f64, lateral: f64, up: f64) -> Point3<f64> {
    let p = path.point(s);
    let t = path.tangent(s);
    Point3::new(p.x - t.y * lateral, p.y + t.x * lateral, up)
}

/// A flat rectangle lying on the road between `s` and `s + length` (the chord of the
/// path there), from `left` to `right` metres off the centre (left > right), `up` above.
fn ground_piece(
    path: &RoadPath,
    s: f64,
    length: f64,
    (left, right): (f64, f64),
    up: f64,
    texture: Texture,
) -> Quad {
    let a = beside(path, s, 0.0, up);
    let b = beside(path, s + length, 0.0, up);
    let along = b - a;
    let across = Vector3::new(-along.y, along.x, 0.0).normalize();
    Quad {
        origin: a + across * right,
        u: along,
        v: across * (left - right),
        texture,
        emission: 0.0,
        light: 0,
    }
}

/// An upright rectangle along the road between `s` and `s + length` at `lateral`, from
/// `bottom` to `top` metres above the road.
fn upright_along(
    path: &RoadPath,
    s: f64,
    length: f64,
    lateral: f64,
    (bottom, top): (f64, f64),
    texture: Texture,
) -> Quad {
    let a = beside(path, s, lateral, bottom);
    let b = beside(path, s + length, lateral, bottom);
    Quad {
        origin: a,
        u: b - a,
        v: Vector3::z() * (top - bottom),
        texture,
        emission: 0.0,
        light: 0,
    }
}

/// An upright rectangle facing the road (across it) at `s`, centred `lateral` metres off
/// it, `width` wide, from `bottom` to `top`.
fn upright_facing(
    path: &RoadPath,
    s: f64,
    lateral: f64,
    width: f64,
    (bottom, top): (f64, f64),
    texture: Texture,
) -> Quad {
    let t = path.tangent(s);
    let across = Vector3::new(t.x, t.y, 0.0);
    Quad {
        origin: beside(path, s, lateral, bottom) - across * (width / 2.0),
        u: across * width,
        v: Vector3::z() * (top - bottom),
        texture,
        emission: 0.0,
        light: 0,
    }
}

/// A building's windows: a grid of blocks of one level on a façade of another.
fn facade(rng: &mut ChaCha8Rng, columns: usize, rows: usize) -> Texture {
    let glass = rng.random_range(0.08..0.3f32);
    let background = rng.random_range(0.45..0.85f32);
    let mut blocks = Vec::with_capacity(columns * rows);
    for c in 0..columns {
        for r in 0..rows {
            let (w, h) = (1.0 / columns as f32, 1.0 / rows as f32);
            let (u0, v0) = (c as f32 * w + 0.25 * w, r as f32 * h + 0.3 * h);
            // A few windows lit or shaded differently.
            let level = if rng.random_bool(0.15) {
                rng.random_range(0.3..0.7)
            } else {
                glass
            };
            blocks.push([u0, v0, u0 + 0.5 * w, v0 + 0.45 * h, level]);
        }
    }
    Texture::Poster { background, blocks }
}

/// A building standing beside the road at `s`: a box `width` along the road, `depth`
/// away from it, `height` tall, its near face `lateral` metres off the centre line (the
/// sign says the side), windows on the faces.
fn building(
    rng: &mut ChaCha8Rng,
    path: &RoadPath,
    s: f64,
    lateral: f64,
    (width, depth, height): (f64, f64, f64),
    quads: &mut Vec<Quad>,
) {
    let side = lateral.signum();
    let t = path.tangent(s);
    let along = Vector3::new(t.x, t.y, 0.0) * width;
    let away = Vector3::new(-t.y, t.x, 0.0) * (side * depth);
    let up = Vector3::z() * height;
    let corner = beside(path, s, lateral, 0.0) - along / 2.0;
    let (columns, rows) = (
        (width / 3.0).round().max(1.0) as usize,
        (height / 3.2).round().max(1.0) as usize,
    );
    let ends = (
        (depth / 3.0).round().max(1.0) as usize,
        (height / 3.2).round().max(1.0) as usize,
    );
    let faces = [
        (corner, along, facade(rng, columns, rows)),
        (corner, away, facade(rng, ends.0, ends.1)),
        (corner + along, away, facade(rng, ends.0, ends.1)),
    ];
    for (origin, u, texture) in faces {
        quads.push(Quad {
            origin,
            u,
            v: up,
            texture,
            emission: 0.0,
            light: 0,
        });
    }
    let roof = rng.random_range(0.2..0.5f32);
    quads.push(Quad {
        origin: corner + up,
        u: along,
        v: away,
        texture: Texture::Plain { level: roof },
        emission: 0.0,
        light: 0,
    });
}

impl Scene {
    /// A road along `path` from 20 m behind the start to [`AHEAD_M`] past `length_m`, with
    /// everything beside it drawn from `seed`.
    pub fn random_road(seed: u64, path: &RoadPath, length_m: f64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x51DE);
        let mut quads = Vec::new();
        let (first, last) = (-20.0, length_m + AHEAD_M);
        let pieces = ((last - first) / PIECE_M).ceil() as usize;
        let marking = Texture::Plain { level: 0.85 };
        // Pieces overlap a little, so that on the curve no wedge of sky shows between them.
        let overlap = 0.3;
        for k in 0..pieces {
            let s = first + k as f64 * PIECE_M;
            let half = ROAD_WIDTH_M / 2.0;
            quads.push(ground_piece(
                path,
                s,
                PIECE_M + overlap,
                (half, -half),
                0.0,
                Texture::Plain { level: 0.3 },
            ));
            // Solid edge lines, 15 cm wide, 3.6 m either side.
            for lateral in [3.6, -3.6] {
                quads.push(ground_piece(
                    path,
                    s,
                    PIECE_M + overlap,
                    (lateral + 0.075, lateral - 0.075),
                    0.01,
                    marking.clone(),
                ));
            }
            // The dashed centre line: 4 m of paint every 12 m.
            if k % 3 == 0 {
                quads.push(ground_piece(
                    path,
                    s,
                    PIECE_M,
                    (0.075, -0.075),
                    0.01,
                    marking.clone(),
                ));
            }
            // Flat fields on either side, a little below the asphalt, out to 170 m.
            if k % 5 == 0 {
                for (left, right) in [(170.0, half - 0.5), (0.5 - half, -170.0)] {
                    quads.push(ground_piece(
                        path,
                        s,
                        5.0 * PIECE_M + 2.0,
                        (left, right),
                        -0.02,
                        Texture::Plain { level: 0.42 },
                    ));
                }
            }
            // A guard rail on the right and its posts.
            quads.push(upright_along(
                path,
                s,
                PIECE_M,
                -6.0,
                (0.5, 0.8),
                Texture::Plain { level: 0.7 },
            ));
            quads.push(upright_facing(
                path,
                s,
                -6.05,
                0.12,
                (0.0, 0.75),
                Texture::Plain { level: 0.35 },
            ));
        }
        // Lamp posts every 40–60 m on the left, signs now and then on the right.
        let mut s = first + rng.random_range(0.0..20.0);
        while s < last {
            quads.push(upright_facing(
                path,
                s,
                7.0,
                0.25,
                (0.0, 9.0),
                Texture::Plain { level: 0.55 },
            ));
            if rng.random_bool(0.4) {
                let blocks = (0..rng.random_range(2..5))
                    .map(|_| {
                        let (u0, v0) =
                            (rng.random_range(0.1..0.6f32), rng.random_range(0.1..0.6f32));
                        [u0, v0, u0 + 0.3, v0 + 0.25, rng.random_range(0.05..0.95f32)]
                    })
                    .collect();
                let sign_at = s + rng.random_range(10.0..20.0);
                let lateral = -rng.random_range(8.0..12.0);
                quads.push(upright_facing(
                    path,
                    sign_at,
                    lateral,
                    rng.random_range(2.5..4.0),
                    (2.5, 4.5),
                    Texture::Poster {
                        background: 0.9,
                        blocks,
                    },
                ));
                quads.push(upright_facing(
                    path,
                    sign_at,
                    lateral,
                    0.15,
                    (0.0, 2.5),
                    Texture::Plain { level: 0.4 },
                ));
            }
            s += rng.random_range(40.0..60.0);
        }
        // Buildings on both sides, 12 to 70 m off the road, with gaps.
        for side in [1.0, -1.0] {
            let mut s = first + rng.random_range(0.0..15.0);
            while s < last {
                let width = rng.random_range(10.0..30.0);
                let lateral = side * rng.random_range(12.0..70.0);
                let size = (
                    width,
                    rng.random_range(8.0..20.0),
                    rng.random_range(6.0..25.0),
                );
                building(&mut rng, path, s + width / 2.0, lateral, size, &mut quads);
                s += width + rng.random_range(5.0..40.0);
            }
        }
        // A far tree line, 110–150 m out: trunks and crowns as vertical bands.
        for side in [1.0, -1.0] {
            let mut s = first;
            while s < last {
                let length = rng.random_range(30.0..60.0);
                quads.push(upright_along(
                    path,
                    s,
                    length,
                    side * rng.random_range(110.0..150.0),
                    (0.0, rng.random_range(8.0..15.0)),
                    Texture::Stripes {
                        a: rng.random_range(0.15..0.3),
                        b: rng.random_range(0.35..0.5),
                        period_m: rng.random_range(2.0..5.0),
                        along_u: false,
                    },
                ));
                s += length;
            }
        }
        let ends = [path.point(first), path.point(last)];
        Scene {
            quads,
            lights: 1,
            noise_seed: seed ^ 0x5EED,
            room_m: Vector3::new(
                (ends[1].x - ends[0].x).abs(),
                (ends[1].y - ends[0].y).abs(),
                25.0,
            ),
            background: 0.95,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_path_is_continuous_and_unit_speed_through_the_curve() {
        let path = RoadPath {
            curve_start_m: 20.0,
            curve_length_m: 50.0,
            curvature: 1.0 / 100.0,
        };
        let mut s = -5.0;
        while s < 120.0 {
            let (a, b) = (path.point(s), path.point(s + 0.01));
            // Chord over a 1 cm step: the speed along the path is 1 m per metre of s.
            assert!(((b - a).norm() - 0.01).abs() < 1e-9, "at {s}");
            let direction = (b - a).normalize();
            assert!(
                (direction - path.tangent(s + 0.005)).norm() < 1e-6,
                "at {s}"
            );
            s += 0.37;
        }
        // A quarter of a radian of turn by the curve's end.
        assert!((path.heading(200.0) - 0.5).abs() < 1e-12);
        let end = path.point(70.0);
        assert!(
            (end - Vector2::new(20.0 + 0.5f64.sin() * 100.0, (1.0 - 0.5f64.cos()) * 100.0)).norm()
                < 1e-9
        );
    }

    #[test]
    fn the_scene_stands_beside_the_road_not_on_it() {
        let path = RoadPath::new(3);
        let scene = Scene::random_road(3, &path, 100.0);
        // Nothing but the road and its paint comes within 5.5 m of the centre line above
        // the ground: the car's lane is free.
        for q in &scene.quads {
            let corners = q.corners();
            if corners.iter().all(|c| c.z <= 0.02) {
                continue;
            }
            for c in corners {
                let nearest = (0..2000)
                    .map(|k| {
                        let p = path.point(-20.0 + k as f64 * 0.2);
                        (Vector2::new(c.x, c.y) - p).norm()
                    })
                    .fold(f64::INFINITY, f64::min);
                assert!(nearest > 5.5, "{q:?} reaches {nearest} m from the road");
            }
        }
    }
}
