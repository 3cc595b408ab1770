//! The true 2-D segments of a frame: the scene's 3-D segments projected with the frame's
//! ground-truth pose, clipped to the image, and cut where the depth map shows another
//! surface in front (occlusion).

use linetrack_geometry::{Point, Segment, StereoRig};
use nalgebra::{Isometry3, Point3};

/// Points nearer than this to the camera plane are dropped before projecting, metres.
const NEAR_M: f64 = 0.05;

/// A visible piece of a projected 3-D segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrueSegment {
    /// Index of the 3-D segment (the row of `segments3d.csv`).
    pub id: usize,
    /// The visible piece in the left image, pixels.
    pub segment: Segment,
}

/// Visibility of a camera-frame point: whether the surface seen at its pixel (or at a
/// neighbouring pixel, since a segment often lies on a depth edge) is at its depth.
pub trait Visibility {
    /// Whether the point at depth `z_m` projecting to pixel `(u, v)` is seen.
    fn sees(&self, u: f64, v: f64, z_m: f64) -> bool;
}

/// Every point is seen (no occlusion test).
pub struct AllVisible;

impl Visibility for AllVisible {
    fn sees(&self, _: f64, _: f64, _: f64) -> bool {
        true
    }
}

/// Occlusion from a depth map (metres, row-major, 0 = none): a point is seen when some
/// pixel of the 3 × 3 block around it holds its depth within 2 % + 1 cm.
pub struct DepthVisibility<'a> {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Depth per pixel, metres.
    pub metres: &'a [f32],
}

impl Visibility for DepthVisibility<'_> {
    fn sees(&self, u: f64, v: f64, z_m: f64) -> bool {
        let (u, v) = (u.round() as i64, v.round() as i64);
        let tolerance = 0.02 * z_m + 0.01;
        (-1..=1).any(|dv| {
            (-1..=1).any(|du| {
                let (x, y) = (u + du, v + dv);
                (x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height) && {
                    let d = f64::from(self.metres[y as usize * self.width + x as usize]);
                    d > 0.0 && (d - z_m).abs() <= tolerance
                }
            })
        })
    }
}

/// Projects the world-frame `segments` into the left camera at `world_from_left`: each
/// is cut to the part in front of the camera, sampled every half pixel in the image, and
/// split into the runs of samples that are inside the image and seen; runs shorter than
/// 2 px are dropped. Exact duplicates (edges shared by two rectangles) are kept once.
pub fn project_segments(
    segments: &[[Point3<f64>; 2]],
    world_from_left: &Isometry3<f64>,
    rig: &StereoRig,
    visibility: &impl Visibility,
) -> Vec<TrueSegment> {
    let left_from_world = world_from_left.inverse();
    let (w, h) = (f64::from(rig.width_px), f64::from(rig.height_px));
    let inside = |p: &Point| p.x >= 0.0 && p.y >= 0.0 && p.x <= w - 1.0 && p.y <= h - 1.0;
    let mut out: Vec<TrueSegment> = Vec::new();
    for (id, [a, b]) in segments.iter().enumerate() {
        let (mut a, mut b) = (left_from_world * a, left_from_world * b);
        // Cut to z ≥ NEAR_M.
        if a.z < NEAR_M && b.z < NEAR_M {
            continue;
        }
        if a.z < NEAR_M || b.z < NEAR_M {
            let t = (NEAR_M - a.z) / (b.z - a.z);
            let cut = a + (b - a) * t;
            if a.z < NEAR_M {
                a = cut;
            } else {
                b = cut;
            }
        }
        let (Some(pa), Some(pb)) = (rig.project_left(&a), rig.project_left(&b)) else {
            continue;
        };
        // Samples: uniform in 3-D, dense enough for ≤ 0.5 px steps in the image even where
        // perspective stretches one end (bounded for segments far outside the image).
        let length = (pb - pa).norm();
        let ratio = (a.z.max(b.z) / a.z.min(b.z)).max(1.0);
        let n = ((2.0 * length * ratio).ceil() as usize).clamp(2, 20_000);
        let mut run: Option<(Point, Point)> = None;
        let finish = |run: &mut Option<(Point, Point)>, out: &mut Vec<TrueSegment>| {
            if let Some((s, e)) = run.take() {
                let segment = Segment::new(s, e);
                let duplicate = out.iter().any(|t| same(&t.segment, &segment));
                if segment.length() >= 2.0 && !duplicate {
                    out.push(TrueSegment { id, segment });
                }
            }
        };
        for k in 0..=n {
            let p3 = a + (b - a) * (k as f64 / n as f64);
            let Some(p) = rig.project_left(&p3) else {
                continue;
            };
            if inside(&p) && visibility.sees(p.x, p.y, p3.z) {
                run = Some(run.map_or((p, p), |(s, _)| (s, p)));
            } else {
                finish(&mut run, &mut out);
            }
        }
        finish(&mut run, &mut out);
    }
    out
}

/// Whether two segments have the same endpoints within 0.5 px, in either order.
fn same(a: &Segment, b: &Segment) -> bool {
    let close = |p: &Point, q: &Point| (p - q).norm() <= 0.5;
    (close(&a.start, &b.start) && close(&a.end, &b.end))
        || (close(&a.start, &b.end) && close(&a.end, &b.start))
}
