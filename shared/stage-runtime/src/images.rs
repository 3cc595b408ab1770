//! A frame message's two images (feature `images`, OpenCV through `linetrack-vision`): read
//! in place by a stage, or built from images by a test or a tool.

use crate::Images;
use linetrack_ipc::Received;
use linetrack_msgs::FrameHeader;
use linetrack_vision::{BorrowedGray, GrayImage, VisionError};

/// Frame `frame_id` carrying `left` and `right` as the frame source would publish them,
/// built in place (tests and tools that run a stage on images of their own).
pub fn stereo_frame(frame_id: u64, left: &GrayImage, right: &GrayImage) -> anyhow::Result<Images> {
    left.ensure_same_size(right)?;
    let (Some(l), Some(r)) = (left.pixels(), right.pixels()) else {
        anyhow::bail!("{}: the pixels are not one block", left.origin());
    };
    let mut header = FrameHeader::new(frame_id, 0, 1);
    header.width = u32::try_from(left.width())?;
    header.height = u32::try_from(left.height())?;
    Ok(Received::local(header, [l, r].concat()))
}

/// The two images of a frame message, read in place.
pub fn stereo_views<'a>(
    frame: &'a Images,
) -> Result<(BorrowedGray<'a>, BorrowedGray<'a>), VisionError> {
    let header = frame.header();
    let (w, h) = (header.width as usize, header.height as usize);
    let pixels = frame.payload();
    let origin = |side: &str| format!("frame {} {side} image", header.frame_id);
    let half = w.saturating_mul(h);
    if pixels.len() != 2 * half {
        return Err(VisionError::RawSize {
            origin: origin("stereo"),
            len: pixels.len(),
            width: w,
            height: 2 * h,
        });
    }
    let (left, right) = pixels.split_at(half);
    Ok((
        GrayImage::borrow_pixels(w, h, left, &origin("left"))?,
        GrayImage::borrow_pixels(w, h, right, &origin("right"))?,
    ))
}
