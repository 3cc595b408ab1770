//! Ranking a level's best FAST corners by the Harris measure, as OpenCV's ORB does by
//! default: the FAST score says how far the circle's arc stands from the centre, which
//! ranks straight edges' bright pixels high; the Harris measure of the 7 × 7 block around
//! the corner says how well it is localised in both directions.

use crate::{Candidate, GrayView};

/// Half the side of the block the gradients are summed over (7 × 7, as OpenCV's ORB).
const HALF_BLOCK: usize = 3;

/// 25 × the Harris measure det(M) − 0.04 · trace(M)² of the block around (`x`, `y`), M the
/// sums of the 3 × 3 Sobel gradients' products over it: exact in integers (the factor 25
/// keeps k = 1/25 whole, and changes no order). The block and the gradients' neighbours lie
/// in `image` (a candidate is at least [`crate::BORDER_PX`] from its borders).
pub(crate) fn measure(image: GrayView<'_>, x: usize, y: usize) -> i64 {
    let (mut xx, mut yy, mut xy) = (0i64, 0i64, 0i64);
    for row in y - HALF_BLOCK..=y + HALF_BLOCK {
        let (above, here, below) = (image.row(row - 1), image.row(row), image.row(row + 1));
        for column in x - HALF_BLOCK..=x + HALF_BLOCK {
            let at = |line: &[u8], dx: usize| i64::from(line[column + dx - 1]);
            let gx = at(above, 2) - at(above, 0) + 2 * (at(here, 2) - at(here, 0)) + at(below, 2)
                - at(below, 0);
            let gy = at(below, 0) - at(above, 0) + 2 * (at(below, 1) - at(above, 1)) + at(below, 2)
                - at(above, 2);
            xx += gx * gx;
            yy += gy * gy;
            xy += gx * gy;
        }
    }
    25 * (xx * yy - xy * xy) - (xx + yy) * (xx + yy)
}

/// Keeps the best `2 × wanted` of `candidates` (sorted best first by the FAST score, as
/// OpenCV's ORB keeps twice its count before measuring) and orders them by the Harris
/// measure, best first (ties in the order they came), through `ranked` and `scratch`.
pub(crate) fn rank(
    image: GrayView<'_>,
    wanted: usize,
    candidates: &mut Vec<Candidate>,
    ranked: &mut Vec<(i64, u32)>,
    scratch: &mut Vec<Candidate>,
) {
    candidates.truncate(wanted.saturating_mul(2));
    ranked.clear();
    ranked.extend(candidates.iter().enumerate().map(|(k, c)| {
        // (`k` fits: a level holds fewer candidates than pixels, far under 2^32.)
        (measure(image, c.x as usize, c.y as usize), k as u32)
    }));
    // Unique keys (the index breaks ties), so the unstable sort is deterministic and does
    // not allocate.
    ranked.sort_unstable_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    scratch.clear();
    scratch.extend(ranked.iter().map(|&(_, k)| candidates[k as usize]));
    std::mem::swap(candidates, scratch);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pseudo-random pixels (a fixed xorshift), so every gradient direction occurs.
    fn noise(width: usize, height: usize) -> Vec<u8> {
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        (0..width * height)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 56) as u8
            })
            .collect()
    }

    #[test]
    fn the_measure_is_harris_written_out_in_floating_point() {
        let (width, height) = (40, 30);
        let pixels = noise(width, height);
        let image = GrayView::packed(&pixels, width, height).unwrap();
        let at = |x: usize, y: usize| f64::from(pixels[y * width + x]);
        for (x, y) in [(10, 10), (20, 15), (29, 22), (4, 4)] {
            let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
            for v in y - 3..=y + 3 {
                for u in x - 3..=x + 3 {
                    // Sobel: [1 2 1] across, [-1 0 1] along.
                    let gx = (at(u + 1, v - 1) + 2.0 * at(u + 1, v) + at(u + 1, v + 1))
                        - (at(u - 1, v - 1) + 2.0 * at(u - 1, v) + at(u - 1, v + 1));
                    let gy = (at(u - 1, v + 1) + 2.0 * at(u, v + 1) + at(u + 1, v + 1))
                        - (at(u - 1, v - 1) + 2.0 * at(u, v - 1) + at(u + 1, v - 1));
                    a += gx * gx;
                    b += gy * gy;
                    c += gx * gy;
                }
            }
            let harris = a * b - c * c - 0.04 * (a + b) * (a + b);
            assert_eq!(measure(image, x, y) as f64, 25.0 * harris, "at ({x}, {y})");
        }
    }

    #[test]
    fn a_corner_ranks_above_points_on_a_straight_edge_and_on_flat_ground() {
        // A bright square on a dark ground: its corner at (20, 20), an edge through
        // (30, 20), flat ground at (50, 50).
        let (width, height) = (64, 64);
        let mut pixels = vec![30u8; width * height];
        for y in 20..44 {
            pixels[y * width + 20..y * width + 44].fill(200);
        }
        let image = GrayView::packed(&pixels, width, height).unwrap();
        // Listed best first by a (made-up) FAST score that puts the corner last.
        let at = |x: u32, y: u32, score: u8| Candidate { x, y, score };
        let mut candidates = vec![at(50, 50, 90), at(30, 20, 80), at(20, 20, 70)];
        let (mut ranked, mut scratch) = (Vec::new(), Vec::new());
        rank(image, 2, &mut candidates, &mut ranked, &mut scratch);
        let order: Vec<(u32, u32)> = candidates.iter().map(|c| (c.x, c.y)).collect();
        // The corner first; the edge's measure is negative (one strong direction), below
        // flat ground's zero.
        assert_eq!(order, [(20, 20), (50, 50), (30, 20)], "{ranked:?}");
        assert!(
            ranked[0].0 > 0 && ranked[1].0 == 0 && ranked[2].0 < 0,
            "{ranked:?}"
        );
        // Only twice the wanted count is measured: with 1 wanted, the two best by FAST.
        let mut candidates = vec![at(50, 50, 90), at(30, 20, 80), at(20, 20, 70)];
        rank(image, 1, &mut candidates, &mut ranked, &mut scratch);
        let order: Vec<(u32, u32)> = candidates.iter().map(|c| (c.x, c.y)).collect();
        assert_eq!(order, [(50, 50), (30, 20)]);
    }

    #[test]
    fn the_extractor_ranks_by_harris_when_asked_and_keeps_its_count() {
        let (width, height) = (160, 120);
        let pixels = noise(width, height);
        let image = GrayView::packed(&pixels, width, height).unwrap();
        let run = |harris: bool| {
            let params = crate::Params {
                levels: 1,
                max_corners: 50,
                harris,
                ..crate::Params::default()
            };
            let mut extractor = crate::CornerExtractor::new(params).unwrap();
            let mut out = crate::Corners::default();
            extractor.extract(image, &mut out);
            let mut at: Vec<(u32, u32)> = (out.corners.iter())
                .map(|c| (c.x as u32, c.y as u32))
                .collect();
            at.sort_unstable();
            at
        };
        let (by_fast, by_harris) = (run(false), run(true));
        assert_eq!((by_fast.len(), by_harris.len()), (50, 50));
        assert_ne!(by_fast, by_harris, "noise has more than 100 FAST corners");
        // Each corner kept by Harris measures at least as much as each one it left out.
        let measured = |list: &[(u32, u32)]| -> Vec<i64> {
            (list.iter())
                .map(|&(x, y)| measure(image, x as usize, y as usize))
                .collect()
        };
        let kept_min = measured(&by_harris).into_iter().min().unwrap();
        let dropped: Vec<(u32, u32)> = (by_fast.iter())
            .filter(|c| !by_harris.contains(c))
            .copied()
            .collect();
        assert!(measured(&dropped).into_iter().all(|m| m <= kept_min));
    }
}
