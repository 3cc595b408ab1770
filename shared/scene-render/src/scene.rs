//! The scene: a room of textured rectangles (walls, floor, ceiling, doors, posters, a
//! window, boxes and shelves), drawn from a seed.

use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// How a surface's reflectance varies over it; coordinates are metres along the
/// rectangle's two edges.
#[derive(Debug, Clone, PartialEq)]
pub enum Texture {
    /// A flat level with faint low-frequency variation: a low-texture area.
    Plain {
        /// Reflectance in [0, 1].
        level: f32,
    },
    /// Square tiles with grout lines.
    Tiles {
        /// Tile reflectance.
        level: f32,
        /// Grout reflectance.
        grout: f32,
        /// Tile side, metres.
        size_m: f32,
    },
    /// Parallel bands: a repetitive structure (blinds, radiators, shelving).
    Stripes {
        /// First band's reflectance.
        a: f32,
        /// Second band's reflectance.
        b: f32,
        /// Band pair width, metres.
        period_m: f32,
        /// Bands along the rectangle's first edge (`true`) or second.
        along_u: bool,
    },
    /// A poster: a background with axis-aligned blocks, fractions of its size.
    Poster {
        /// Background reflectance.
        background: f32,
        /// Blocks `(u0, v0, u1, v1, level)` in fractions of the poster's sides.
        blocks: Vec<[f32; 5]>,
    },
    /// A checkerboard.
    Checker {
        /// First colour.
        a: f32,
        /// Second colour.
        b: f32,
        /// Square side, metres.
        size_m: f32,
    },
}

/// A textured rectangle `origin + s·u + t·v`, s, t ∈ [0, 1], with `u ⟂ v`.
#[derive(Debug, Clone, PartialEq)]
pub struct Quad {
    /// One corner, world frame (metres).
    pub origin: Point3<f64>,
    /// First edge.
    pub u: Vector3<f64>,
    /// Second edge, perpendicular to the first.
    pub v: Vector3<f64>,
    /// Surface pattern.
    pub texture: Texture,
    /// Emitted radiance added to the reflected light (windows, lamps), ≥ 0.
    pub emission: f32,
    /// Which switchable light illuminates it.
    pub light: usize,
}

impl Quad {
    /// The four corners, in order around the rectangle.
    pub fn corners(&self) -> [Point3<f64>; 4] {
        [
            self.origin,
            self.origin + self.u,
            self.origin + self.u + self.v,
            self.origin + self.v,
        ]
    }

    /// Unit normal `u × v`.
    pub fn normal(&self) -> Vector3<f64> {
        self.u.cross(&self.v).normalize()
    }

    /// Reflectance at `(s, t)` ∈ [0, 1]².
    pub fn reflectance(&self, s: f64, t: f64, noise_seed: u64) -> f32 {
        let (a, b) = ((s * self.u.norm()) as f32, (t * self.v.norm()) as f32);
        let value = match &self.texture {
            Texture::Plain { level } => {
                level + 0.04 * (value_noise(a * 1.5, b * 1.5, noise_seed) - 0.5)
            }
            Texture::Tiles {
                level,
                grout,
                size_m,
            } => {
                let grout_width = 0.012;
                let (fa, fb) = ((a / size_m).fract() * size_m, (b / size_m).fract() * size_m);
                if fa < grout_width || fb < grout_width {
                    *grout
                } else {
                    level + 0.06 * (value_noise(a * 4.0, b * 4.0, noise_seed) - 0.5)
                }
            }
            Texture::Stripes {
                a: first,
                b: second,
                period_m,
                along_u,
            } => {
                let x = if *along_u { b } else { a };
                if (x / period_m).fract() < 0.5 {
                    *first
                } else {
                    *second
                }
            }
            Texture::Poster { background, blocks } => {
                let (fs, ft) = (s as f32, t as f32);
                blocks
                    .iter()
                    .rev()
                    .find(|[u0, v0, u1, v1, _]| fs >= *u0 && fs < *u1 && ft >= *v0 && ft < *v1)
                    .map_or(*background, |block| block[4])
            }
            Texture::Checker {
                a: first,
                b: second,
                size_m,
            } => {
                let parity =
                    ((a / size_m).floor() as i64 + (b / size_m).floor() as i64).rem_euclid(2);
                if parity == 0 { *first } else { *second }
            }
        };
        value.clamp(0.0, 1.0)
    }
}

/// Smooth lattice noise in [0, 1].
fn value_noise(x: f32, y: f32, seed: u64) -> f32 {
    let hash = |i: i64, j: i64| {
        let mut h = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
            ^ seed;
        h ^= h >> 29;
        h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h ^= h >> 32;
        (h & 0xFFFF) as f32 / 65535.0
    };
    let (i, j) = (x.floor() as i64, y.floor() as i64);
    let (fx, fy) = (x - x.floor(), y - y.floor());
    let smooth = |t: f32| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (smooth(fx), smooth(fy));
    let top = hash(i, j) * (1.0 - sx) + hash(i + 1, j) * sx;
    let bottom = hash(i, j + 1) * (1.0 - sx) + hash(i + 1, j + 1) * sx;
    top * (1.0 - sy) + bottom * sy
}

/// A scene: rectangles, the number of switchable lights, and a noise seed.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// All surfaces.
    pub quads: Vec<Quad>,
    /// Switchable light groups (`Quad::light` < this).
    pub lights: usize,
    /// Seed of the textures' noise.
    pub noise_seed: u64,
    /// Room extent `(x, y, z)` in metres; the room spans [0, x] × [0, y] × [0, z], z up.
    /// For a road: the extent of its path.
    pub room_m: Vector3<f64>,
    /// Radiance where a ray hits nothing (a room: none, 0; a road: the sky).
    pub background: f32,
}

impl Scene {
    /// The straight edges a line detector can find, world frame: every rectangle's
    /// outline and its texture's edges (poster blocks, tile grout, stripe and checker
    /// boundaries). Occlusion is not considered.
    pub fn segments(&self) -> Vec<[Point3<f64>; 2]> {
        let mut out = Vec::new();
        for q in &self.quads {
            let at = |s: f64, t: f64| q.origin + q.u * s + q.v * t;
            // A line across the rectangle at fraction `f` of the u edge (or of the v edge).
            let across_u = |f: f64| [at(f, 0.0), at(f, 1.0)];
            let across_v = |f: f64| [at(0.0, f), at(1.0, f)];
            let (len_u, len_v) = (q.u.norm(), q.v.norm());
            let steps = |length: f64, step: f64| {
                (1..)
                    .map(move |k| k as f64 * step)
                    .take_while(move |x| *x < length)
            };
            out.extend([across_v(0.0), across_u(1.0), across_v(1.0), across_u(0.0)]);
            match &q.texture {
                Texture::Plain { .. } => {}
                Texture::Tiles { size_m, .. } => {
                    let (size, grout) = (f64::from(*size_m), 0.012);
                    for edge in [0.0, grout] {
                        out.extend(steps(len_u, size).map(|x| across_u((x + edge) / len_u)));
                        out.extend(steps(len_v, size).map(|x| across_v((x + edge) / len_v)));
                    }
                }
                Texture::Stripes {
                    period_m, along_u, ..
                } => {
                    let half = f64::from(*period_m) / 2.0;
                    if *along_u {
                        out.extend(steps(len_v, half).map(|x| across_v(x / len_v)));
                    } else {
                        out.extend(steps(len_u, half).map(|x| across_u(x / len_u)));
                    }
                }
                Texture::Checker { size_m, .. } => {
                    let size = f64::from(*size_m);
                    out.extend(steps(len_u, size).map(|x| across_u(x / len_u)));
                    out.extend(steps(len_v, size).map(|x| across_v(x / len_v)));
                }
                Texture::Poster { blocks, .. } => {
                    for [u0, v0, u1, v1, _] in blocks {
                        let (u0, v0, u1, v1) = (
                            f64::from(*u0),
                            f64::from(*v0),
                            f64::from(*u1),
                            f64::from(*v1),
                        );
                        let corners = [at(u0, v0), at(u1, v0), at(u1, v1), at(u0, v1)];
                        for k in 0..4 {
                            out.push([corners[k], corners[(k + 1) % 4]]);
                        }
                    }
                }
            }
        }
        out
    }

    /// A random room: walls, tiled floor, ceiling, a window, doors, posters, a striped
    /// radiator, and boxes and shelves on the floor, kept out of the central free area
    /// the camera moves in.
    pub fn random_room(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (w, d, h) = (rng.random_range(5.5..7.0), rng.random_range(6.0..8.0), 2.7);
        let mut quads = Vec::new();
        let level = |rng: &mut ChaCha8Rng, lo: f32, hi: f32| rng.random_range(lo..hi);
        let plain = |level: f32| Texture::Plain { level };
        let x = Vector3::x();
        let y = Vector3::y();
        let z = Vector3::z();
        let light_of = |px: f64| usize::from(px > w / 2.0);
        // Floor (tiles) and ceiling, normals pointing into the room.
        quads.push(Quad {
            origin: Point3::new(0.0, 0.0, 0.0),
            u: x * w,
            v: y * d,
            texture: Texture::Tiles {
                level: 0.45,
                grout: 0.2,
                size_m: 0.6,
            },
            emission: 0.0,
            light: 0,
        });
        quads.push(Quad {
            origin: Point3::new(0.0, d, h),
            u: x * w,
            v: -y * d,
            texture: plain(0.8),
            emission: 0.0,
            light: 1,
        });
        // Walls: (origin, along-wall edge, inward normal direction).
        let walls = [
            (Point3::new(0.0, 0.0, 0.0), x * w, y), // y = 0, faces +y
            (Point3::new(w, d, 0.0), -x * w, -y),   // y = d, faces −y
            (Point3::new(0.0, d, 0.0), -y * d, x),  // x = 0, faces +x
            (Point3::new(w, 0.0, 0.0), y * d, -x),  // x = w, faces −x
        ];
        for (k, (origin, along, inward)) in walls.iter().enumerate() {
            // Surfaces are two-sided, so the wall's edge order does not matter.
            let (origin, u, v) = (*origin, *along, z * h);
            quads.push(Quad {
                origin,
                u,
                v,
                texture: plain(level(&mut rng, 0.5, 0.7)),
                emission: 0.0,
                light: k % 2,
            });
            let length = along.norm();
            let dir = along.normalize();
            // A dark baseboard along the wall's foot: a long horizontal edge.
            quads.push(Quad {
                origin: origin + inward * 0.005,
                u: dir * length,
                v: z * 0.1,
                texture: plain(0.12),
                emission: 0.0,
                light: k % 2,
            });
            // Things hung on the wall stand in front of it, each 4 mm further out than the
            // one before, so overlapping ones never share a depth.
            let mut hung = 0u32;
            let mut place = |rng: &mut ChaCha8Rng,
                             width: f64,
                             height: f64,
                             bottom: f64,
                             texture: Texture,
                             emission: f32,
                             quads: &mut Vec<Quad>| {
                hung += 1;
                let start = rng.random_range(0.3..(length - width - 0.3).max(0.31));
                let corner =
                    origin + dir * start + z * bottom + inward * (0.01 + 0.004 * f64::from(hung));
                quads.push(Quad {
                    origin: corner,
                    u: dir * width,
                    v: z * height,
                    texture,
                    emission,
                    light: light_of(corner.x),
                });
            };
            match k {
                0 => {
                    // A bright window: high radiance that saturates under gain (HDR).
                    place(&mut rng, 1.4, 1.2, 0.9, plain(0.95), 2.5, &mut quads);
                    place(
                        &mut rng,
                        1.2,
                        0.6,
                        0.3,
                        Texture::Stripes {
                            a: 0.85,
                            b: 0.35,
                            period_m: 0.06,
                            along_u: false,
                        },
                        0.0,
                        &mut quads,
                    );
                }
                1 => {
                    let door = plain(level(&mut rng, 0.2, 0.35));
                    place(&mut rng, 0.9, 2.05, 0.0, door, 0.0, &mut quads);
                    place(
                        &mut rng,
                        0.8,
                        0.8,
                        1.1,
                        Texture::Checker {
                            a: 0.1,
                            b: 0.9,
                            size_m: 0.1,
                        },
                        0.0,
                        &mut quads,
                    );
                }
                _ => {
                    let door = plain(level(&mut rng, 0.15, 0.35));
                    place(&mut rng, 0.9, 2.05, 0.0, door, 0.0, &mut quads);
                }
            }
            for _ in 0..rng.random_range(2..5) {
                let blocks = (0..rng.random_range(3..7))
                    .map(|_| {
                        let (u0, v0) = (
                            rng.random_range(0.05..0.7f32),
                            rng.random_range(0.05..0.7f32),
                        );
                        [
                            u0,
                            v0,
                            (u0 + rng.random_range(0.1..0.3f32)).min(0.95),
                            (v0 + rng.random_range(0.1..0.3f32)).min(0.95),
                            rng.random_range(0.05..0.95f32),
                        ]
                    })
                    .collect();
                let size = rng.random_range(0.5..1.0);
                let texture = Texture::Poster {
                    background: level(&mut rng, 0.6, 0.9),
                    blocks,
                };
                let (height, bottom) = (
                    size * rng.random_range(0.7..1.3),
                    rng.random_range(1.0..1.4),
                );
                place(&mut rng, size, height, bottom, texture, 0.0, &mut quads);
            }
        }
        // Boxes and shelves along the walls, outside the central free area.
        for _ in 0..rng.random_range(4..7) {
            let (bw, bd, bh) = (
                rng.random_range(0.4..1.2),
                rng.random_range(0.3..0.6),
                rng.random_range(0.4..1.8),
            );
            let near_x = rng.random_bool(0.5);
            let (cx, cy) = if near_x {
                (
                    if rng.random_bool(0.5) {
                        0.2 + bd / 2.0
                    } else {
                        w - 0.2 - bd / 2.0
                    },
                    rng.random_range(1.0..d - 1.0),
                )
            } else {
                (
                    rng.random_range(1.0..w - 1.0),
                    if rng.random_bool(0.5) {
                        0.2 + bd / 2.0
                    } else {
                        d - 0.2 - bd / 2.0
                    },
                )
            };
            let texture = if bh > 1.2 {
                Texture::Stripes {
                    a: 0.7,
                    b: 0.25,
                    period_m: 0.35,
                    along_u: false,
                }
            } else {
                plain(level(&mut rng, 0.25, 0.75))
            };
            push_box(
                &mut quads,
                Point3::new(cx - bw / 2.0, cy - bd / 2.0, 0.0),
                Vector3::new(bw, bd, bh),
                texture,
                light_of(cx),
            );
        }
        Scene {
            quads,
            lights: 2,
            noise_seed: seed ^ 0x5EED,
            room_m: Vector3::new(w, d, h),
            background: 0.0,
        }
    }
}

/// An axis-aligned box standing on the floor: its four sides and top, normals outward.
fn push_box(
    quads: &mut Vec<Quad>,
    min: Point3<f64>,
    size: Vector3<f64>,
    texture: Texture,
    light: usize,
) {
    let (x, y, z) = (
        Vector3::x() * size.x,
        Vector3::y() * size.y,
        Vector3::z() * size.z,
    );
    let faces = [
        (min, x, z),          // front (y = min), normal −y
        (min + y + x, -x, z), // back, normal +y
        (min + y, -y, z),     // left (x = min), normal −x
        (min + x, y, z),      // right, normal +x
        (min + z, x, y),      // top, normal +z
    ];
    for (origin, u, v) in faces {
        quads.push(Quad {
            origin,
            u,
            v,
            texture: texture.clone(),
            emission: 0.0,
            light,
        });
    }
}
