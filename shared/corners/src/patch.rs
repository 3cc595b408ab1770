//! The smoothed neighbourhood of one corner, the pixels its descriptor compares, copied
//! out of the smoothed level into a fixed 32 × 32 array: the descriptor's 512 reads then
//! index an array of known size (no bounds checks) with offsets that do not depend on the
//! level's stride (one table for every level).

use crate::GrayView;

/// Side of the patch: level pixels `c − 15 ..= c + 16` around the corner `c`.
pub(crate) const PATCH: usize = 32;
/// The corner's row and column inside the patch.
pub(crate) const CENTRE: usize = 15;

/// The rows of the patch around `(x, y)` of `smooth`, top to bottom, each its `PATCH`
/// pixels in place (what [`patch`] copies out); `None` where the patch leaves `smooth`.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))] // read in place by AVX-512 only
#[inline(always)]
pub(crate) fn rows(smooth: GrayView<'_>, x: usize, y: usize) -> Option<[&[u8; PATCH]; PATCH]> {
    let (left, top) = (x.checked_sub(CENTRE)?, y.checked_sub(CENTRE)?);
    if top + PATCH > smooth.height() {
        return None;
    }
    let mut rows: [&[u8; PATCH]; PATCH] = [&[0; PATCH]; PATCH];
    for (r, row) in rows.iter_mut().enumerate() {
        *row = smooth.row(top + r).get(left..)?.first_chunk()?;
    }
    Some(rows)
}

/// The patch around `(x, y)` of `smooth`, row by row (`PATCH` × `PATCH`); `(x, y)` is at
/// least [`crate::BORDER_PX`] from the borders, so the patch lies inside (`None` if not).
#[inline(always)]
pub(crate) fn patch(smooth: GrayView<'_>, x: usize, y: usize) -> Option<[u8; PATCH * PATCH]> {
    let (left, top) = (x.checked_sub(CENTRE)?, y.checked_sub(CENTRE)?);
    if left + PATCH > smooth.width() || top + PATCH > smooth.height() {
        return None;
    }
    let mut out = [0u8; PATCH * PATCH];
    for (r, out_row) in out.chunks_exact_mut(PATCH).enumerate() {
        out_row.copy_from_slice(&smooth.row(top + r)[left..left + PATCH]);
    }
    Some(out)
}
