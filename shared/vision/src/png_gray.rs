//! 8-bit grey PNGs (the EuRoC and KITTI frames) decoded by the `png` crate straight into
//! an OpenCV Mat. OpenCV's `imdecode` (libpng and zlib) spent a quarter of the frame
//! source's CPU in its CRC-32 and Adler-32 checks; the `png` crate keeps both checks
//! (SIMD Adler-32, CRC-32 by carry-less multiply) and writes the rows into the Mat once.
//! The pixels are the same (tested on every frame of the EuRoC excerpt and the KITTI
//! drive); any other PNG (16-bit, colour, palette, transparency, under 8 bits, animated)
//! or format is left to OpenCV.

use crate::{OpenCvContext, VisionError};
use opencv::core::{self, Mat, MatTraitManual, Scalar};

/// The first bytes of every PNG file.
const SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";

/// The pixels of `bytes` when they are an 8-bit greyscale PNG without transparency, in a
/// new Mat; `Ok(None)` for anything else (OpenCV decodes it). A PNG of that kind that is
/// corrupt (a checksum, truncated data) is an error naming `origin`.
pub(crate) fn decode_gray8_png(bytes: &[u8], origin: &str) -> Result<Option<Mat>, VisionError> {
    if !bytes.starts_with(SIGNATURE) {
        return Ok(None);
    }
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::IDENTITY);
    // A header this decoder cannot read is OpenCV's to judge (and refuse).
    let Ok(mut reader) = decoder.read_info() else {
        return Ok(None);
    };
    let info = reader.info();
    if info.color_type != png::ColorType::Grayscale
        || info.bit_depth != png::BitDepth::Eight
        || info.trns.is_some()
        || info.is_animated()
    {
        return Ok(None);
    }
    let (Ok(rows), Ok(cols)) = (i32::try_from(info.height), i32::try_from(info.width)) else {
        return Ok(None);
    };
    let corrupt = || VisionError::Decode {
        origin: origin.to_string(),
    };
    let mut mat = Mat::new_rows_cols_with_default(rows, cols, core::CV_8UC1, Scalar::all(0.0))
        .context("allocating a decoded image")?;
    let pixels = mat.data_bytes_mut().context("writing a decoded image")?;
    // Grey, 8 bits, no transformation: rows come packed, `cols` bytes each, as the Mat's.
    if reader.output_buffer_size() != Some(pixels.len()) {
        return Ok(None);
    }
    reader.next_frame(pixels).map_err(|_| corrupt())?;
    Ok(Some(mat))
}

#[cfg(test)]
mod tests {
    use super::*;
    use opencv::core::{MatTraitConst, MatTraitConstManual, Vector};
    use opencv::imgcodecs;
    use std::path::PathBuf;

    fn png_files(dir: PathBuf) -> Vec<PathBuf> {
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .map(|entry| entry.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "png"))
            .collect();
        files.sort();
        files
    }

    fn opencv_pixels(bytes: &[u8]) -> Vec<u8> {
        let mat =
            imgcodecs::imdecode(&Vector::from_slice(bytes), imgcodecs::IMREAD_UNCHANGED).unwrap();
        assert_eq!((mat.channels(), mat.depth()), (1, core::CV_8U));
        mat.data_bytes().unwrap().to_vec()
    }

    #[test]
    fn every_euroc_and_kitti_frame_decodes_to_opencvs_pixels() {
        let euroc = linetrack_test_data::euroc_dir().unwrap().join("mav0");
        let kitti = linetrack_test_data::kitti_raw_dir().unwrap();
        let files: Vec<PathBuf> = [
            euroc.join("cam0/data"),
            euroc.join("cam1/data"),
            kitti.join("image_00/data"),
            kitti.join("image_01/data"),
        ]
        .into_iter()
        .flat_map(png_files)
        .collect();
        assert!(files.len() >= 2 * 95 + 2 * 108, "{} files", files.len());
        for file in &files {
            let bytes = std::fs::read(file).unwrap();
            let mat = decode_gray8_png(&bytes, "frame")
                .unwrap()
                .unwrap_or_else(|| panic!("{}: not taken as 8-bit grey", file.display()));
            assert!(
                mat.data_bytes().unwrap() == opencv_pixels(&bytes).as_slice(),
                "{}: pixels differ from OpenCV's",
                file.display()
            );
        }
    }

    #[test]
    fn other_pngs_are_left_to_opencv_and_a_corrupt_one_is_refused() {
        let (w, h) = (40u32, 30u32);
        let encode = |color: png::ColorType, depth: png::BitDepth, data: &[u8]| {
            let mut out = Vec::new();
            let mut encoder = png::Encoder::new(&mut out, w, h);
            encoder.set_color(color);
            encoder.set_depth(depth);
            encoder
                .write_header()
                .unwrap()
                .write_image_data(data)
                .unwrap();
            out
        };
        let grey: Vec<u8> = (0..w * h).map(|i| (i * 7 % 256) as u8).collect();
        let gray8 = encode(png::ColorType::Grayscale, png::BitDepth::Eight, &grey);
        let decoded = decode_gray8_png(&gray8, "card").unwrap().unwrap();
        assert_eq!(decoded.data_bytes().unwrap(), grey.as_slice());
        assert_eq!((decoded.cols(), decoded.rows()), (w as i32, h as i32));

        let wide: Vec<u8> = grey.iter().flat_map(|&v| [v, 0]).collect();
        let gray16 = encode(png::ColorType::Grayscale, png::BitDepth::Sixteen, &wide);
        assert!(decode_gray8_png(&gray16, "16-bit").unwrap().is_none());
        let rgb: Vec<u8> = grey.iter().flat_map(|&v| [v, v, v]).collect();
        let colour = encode(png::ColorType::Rgb, png::BitDepth::Eight, &rgb);
        assert!(decode_gray8_png(&colour, "colour").unwrap().is_none());
        assert!(
            decode_gray8_png(b"P5\n1 1\n255\n\0", "pgm")
                .unwrap()
                .is_none()
        );

        // A flipped byte in the compressed pixels fails a checksum.
        let mut corrupt = gray8.clone();
        let idat = corrupt.windows(4).position(|w| w == b"IDAT").unwrap();
        corrupt[idat + 10] ^= 0x55;
        let error = decode_gray8_png(&corrupt, "bad.png").unwrap_err();
        assert!(error.to_string().contains("bad.png"), "{error}");
        // Cut short.
        let cut = &gray8[..gray8.len() / 2];
        assert!(decode_gray8_png(cut, "cut.png").is_err());
    }
}
