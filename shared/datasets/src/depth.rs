//! Depth maps as 16-bit PNG: value = depth in metres × [`DEPTH_SCALE`] (the TUM RGB-D
//! convention, 0.2 mm steps, up to 13.1 m), 0 where there is no depth.

use crate::DatasetError;
use std::path::Path;

/// Grey levels per metre in depth PNGs.
pub const DEPTH_SCALE: f32 = 5000.0;

/// A depth map in metres (0: unknown), row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthMap {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Depth per pixel, metres; 0 where unknown.
    pub metres: Vec<f32>,
}

impl DepthMap {
    /// Depth at pixel (u, v); `None` outside or unknown.
    pub fn at(&self, u: usize, v: usize) -> Option<f32> {
        (u < self.width && v < self.height)
            .then(|| self.metres[v * self.width + u])
            .filter(|d| *d > 0.0)
    }
}

fn image_error(path: &Path, error: image::ImageError) -> DatasetError {
    DatasetError::Io {
        path: path.to_path_buf(),
        reason: std::io::Error::other(error.to_string()),
    }
}

/// Writes a depth map (depths beyond 13.1 m are written as unknown).
pub fn write_depth_png(path: &Path, depth: &DepthMap) -> Result<(), DatasetError> {
    let levels: Vec<u16> = depth
        .metres
        .iter()
        .map(|d| {
            let level = (d * DEPTH_SCALE).round();
            if *d > 0.0 && level <= f32::from(u16::MAX) {
                level as u16
            } else {
                0
            }
        })
        .collect();
    let buffer = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(
        depth.width as u32,
        depth.height as u32,
        levels,
    )
    .ok_or_else(|| {
        DatasetError::Calibration(format!(
            "{}: depth map size does not match its data",
            path.display()
        ))
    })?;
    buffer.save(path).map_err(|e| image_error(path, e))
}

/// Reads a 16-bit depth PNG.
pub fn read_depth_png(path: &Path) -> Result<DepthMap, DatasetError> {
    let image = image::open(path).map_err(|e| image_error(path, e))?;
    let image::DynamicImage::ImageLuma16(buffer) = image else {
        return Err(crate::parse_error(
            path,
            0,
            "a depth map must be a 16-bit single-channel PNG",
        ));
    };
    let (width, height) = (buffer.width() as usize, buffer.height() as usize);
    let metres = buffer
        .into_raw()
        .into_iter()
        .map(|v| f32::from(v) / DEPTH_SCALE)
        .collect();
    Ok(DepthMap {
        width,
        height,
        metres,
    })
}
