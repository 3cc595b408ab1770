//! A `sensor_msgs/Image` as the pipeline's 8-bit grey image, checked against the rig's size.
//!
//! `mono8` is taken as it is: its rows go straight from the message into the shared-memory
//! frame (one copy). `mono16`, `rgb8` and `bgr8` are converted with the arithmetic of the
//! conversion every other input goes through (`linetrack_vision::to_gray8_ordered`, OpenCV's
//! `convertTo` and `cvtColor`): 16 bits scaled by 255 / 65535 and rounded to the nearest
//! level, colour by OpenCV's fixed-point luminance. Written here without OpenCV so that the
//! bridge does not link it; a test checks it against that conversion pixel for pixel. An image
//! that cannot be read is [`Malformed`], saying why.

use crate::sensor_msgs::Image;

/// The encodings read.
pub const ENCODINGS: &str = "mono8, mono16, rgb8, bgr8";

/// A pixel encoding the source reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// 8-bit grey.
    Mono8,
    /// 16-bit grey.
    Mono16,
    /// 8-bit red, green, blue.
    Rgb8,
    /// 8-bit blue, green, red.
    Bgr8,
}

impl Encoding {
    /// The encoding named `name` (ROS's `sensor_msgs/image_encodings` names).
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "mono8" | "8UC1" => Some(Self::Mono8),
            "mono16" | "16UC1" => Some(Self::Mono16),
            "rgb8" => Some(Self::Rgb8),
            "bgr8" | "8UC3" => Some(Self::Bgr8),
            _ => None,
        }
    }

    /// Bytes of one pixel.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            Self::Mono8 => 1,
            Self::Mono16 => 2,
            Self::Rgb8 | Self::Bgr8 => 3,
        }
    }
}

/// Why an image cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum Malformed {
    /// An encoding the source does not read.
    #[error("encoding {0:?} is not read (only {ENCODINGS})")]
    Encoding(String),
    /// Not the size the `CameraInfo` gives.
    #[error("{width}×{height} pixels where the CameraInfo says {expected_width}×{expected_height}")]
    Size {
        /// The image's width.
        width: u32,
        /// Its height.
        height: u32,
        /// The rig's width.
        expected_width: u32,
        /// The rig's height.
        expected_height: u32,
    },
    /// A row step shorter than a row.
    #[error("step {step} bytes is shorter than a row of {width} {encoding} pixels ({row} bytes)")]
    Step {
        /// The message's step.
        step: u32,
        /// Its width.
        width: u32,
        /// Its encoding.
        encoding: String,
        /// Bytes a row needs.
        row: usize,
    },
    /// Data not `step × height` bytes long.
    #[error("{len} bytes of data where step × height is {expected} ({})", if len < expected { "truncated" } else { "too long" })]
    Length {
        /// Bytes in the message.
        len: usize,
        /// `step × height`.
        expected: usize,
    },
}

/// An image as 8-bit grey of the rig's size.
#[derive(Debug)]
pub enum Gray<'a> {
    /// `mono8` pixels in the message: `height` rows of `width` bytes, `step` apart.
    Message {
        /// The message's data.
        data: &'a [u8],
        /// Bytes from one row to the next.
        step: usize,
        /// Bytes of a row.
        width: usize,
        /// Rows.
        height: usize,
    },
    /// Converted (continuous, one byte a pixel).
    Converted(Vec<u8>),
}

impl<'a> Gray<'a> {
    /// Appends the image's pixels, row by row in order, to `parts`: one slice when they lie
    /// together, else one per row.
    pub fn push_parts<'s>(&'s self, parts: &mut Vec<&'s [u8]>) -> Result<(), Malformed> {
        match self {
            Gray::Message {
                data,
                step,
                width,
                height,
            } => {
                if step == width {
                    parts.push(&data[..width * height]);
                } else {
                    parts.extend(data.chunks(*step).take(*height).map(|row| &row[..*width]));
                }
            }
            Gray::Converted(pixels) => parts.push(pixels.as_slice()),
        }
        Ok(())
    }
}

/// `image` as 8-bit grey, checked to be `size` (width, height) pixels.
pub fn gray(image: &Image, size: (u32, u32)) -> Result<Gray<'_>, Malformed> {
    let encoding = Encoding::parse(&image.encoding)
        .ok_or_else(|| Malformed::Encoding(image.encoding.clone()))?;
    if (image.width, image.height) != size {
        return Err(Malformed::Size {
            width: image.width,
            height: image.height,
            expected_width: size.0,
            expected_height: size.1,
        });
    }
    let (width, height) = (image.width as usize, image.height as usize);
    let row = width * encoding.bytes_per_pixel();
    let step = image.step as usize;
    if step < row {
        return Err(Malformed::Step {
            step: image.step,
            width: image.width,
            encoding: image.encoding.clone(),
            row,
        });
    }
    let expected = step * height;
    if image.data.len() != expected {
        return Err(Malformed::Length {
            len: image.data.len(),
            expected,
        });
    }
    let rows = || image.data.chunks(step).map(|r| &r[..row]);
    let pixels = match encoding {
        Encoding::Mono8 => {
            return Ok(Gray::Message {
                data: &image.data,
                step,
                width,
                height,
            });
        }
        Encoding::Mono16 => {
            let big = image.is_bigendian != 0;
            rows()
                .flat_map(|r| r.chunks_exact(2))
                .map(|b| {
                    let b = [b[0], b[1]];
                    grey_of_16_bits(if big {
                        u16::from_be_bytes(b)
                    } else {
                        u16::from_le_bytes(b)
                    })
                })
                .collect()
        }
        Encoding::Rgb8 | Encoding::Bgr8 => {
            let rgb = encoding == Encoding::Rgb8;
            rows()
                .flat_map(|r| r.chunks_exact(3))
                .map(|p| {
                    let (r, g, b) = if rgb {
                        (p[0], p[1], p[2])
                    } else {
                        (p[2], p[1], p[0])
                    };
                    grey_of_colour(r, g, b)
                })
                .collect()
        }
    };
    Ok(Gray::Converted(pixels))
}

/// A 16-bit sample as 8 bits: times 255 / 65535 in single precision, rounded to the nearest
/// level, ties to even (OpenCV's `convertTo` to `CV_8U`).
fn grey_of_16_bits(v: u16) -> u8 {
    (f32::from(v) * (255.0f32 / 65535.0f32)).round_ties_even() as u8
}

/// Luminance of an 8-bit colour: OpenCV's fixed-point `cvtColor` to grey (4.6), weights
/// 0.299, 0.587, 0.114 in units of 2⁻¹⁵, rounded.
fn grey_of_colour(r: u8, g: u8, b: u8) -> u8 {
    const SHIFT: u32 = 15;
    const R: u32 = 9798;
    const G: u32 = 19235;
    const B: u32 = 3735;
    let sum = u32::from(r) * R + u32::from(g) * G + u32::from(b) * B + (1 << (SHIFT - 1));
    (sum >> SHIFT) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(encoding: &str, width: u32, height: u32, step: u32, data: Vec<u8>) -> Image {
        Image {
            encoding: encoding.to_string(),
            width,
            height,
            step,
            data,
            ..Image::default()
        }
    }

    /// The grey pixels of `image` read as `size`, in one buffer.
    fn pixels(image: &Image, size: (u32, u32)) -> Vec<u8> {
        let gray = gray(image, size).unwrap_or_else(|e| panic!("{e}"));
        let mut parts = Vec::new();
        gray.push_parts(&mut parts)
            .unwrap_or_else(|e| panic!("{e}"));
        parts.concat()
    }

    /// A 3×2 grey ramp.
    const GREY: [u8; 6] = [0, 50, 100, 150, 200, 255];

    #[test]
    fn mono8_rows_are_taken_as_they_are_with_or_without_padding() {
        assert_eq!(
            pixels(&image("mono8", 3, 2, 3, GREY.to_vec()), (3, 2)),
            GREY
        );
        let padded = image("mono8", 3, 2, 4, vec![0, 50, 100, 9, 150, 200, 255, 9]);
        let read = gray(&padded, (3, 2));
        let mut parts = Vec::new();
        if let Ok(g) = &read {
            g.push_parts(&mut parts).unwrap_or_else(|e| panic!("{e}"));
        }
        assert_eq!(parts, [&[0u8, 50, 100][..], &[150, 200, 255][..]]);
    }

    #[test]
    fn colour_and_16_bits_read_as_the_grey_they_hold() {
        // Equal channels are their grey; 16 bits v·257 are v.
        let rgb: Vec<u8> = GREY.iter().flat_map(|v| [*v; 3]).collect();
        assert_eq!(pixels(&image("rgb8", 3, 2, 9, rgb.clone()), (3, 2)), GREY);
        assert_eq!(pixels(&image("bgr8", 3, 2, 9, rgb), (3, 2)), GREY);
        let le: Vec<u8> = GREY
            .iter()
            .flat_map(|v| (u16::from(*v) * 257).to_le_bytes())
            .collect();
        assert_eq!(pixels(&image("mono16", 3, 2, 6, le), (3, 2)), GREY);
        let be: Vec<u8> = [1000u16, 65535]
            .iter()
            .flat_map(|v| v.to_be_bytes())
            .collect();
        let mut big = image("mono16", 2, 1, 4, be);
        big.is_bigendian = 1;
        assert_eq!(pixels(&big, (2, 1)), [4, 255]);
        // The channel order counts: pure red is brighter than pure blue.
        let red = pixels(&image("rgb8", 1, 1, 3, vec![255, 0, 0]), (1, 1));
        let blue = pixels(&image("bgr8", 1, 1, 3, vec![255, 0, 0]), (1, 1));
        assert_eq!((red[0], blue[0]), (76, 29));
    }

    #[test]
    fn malformed_images_say_what_is_wrong() {
        let refused = |image: Image| -> String {
            match gray(&image, (3, 2)) {
                Ok(g) => panic!("read {g:?}"),
                Err(e) => e.to_string(),
            }
        };
        let e = refused(image("yuv422", 3, 2, 6, vec![0; 12]));
        assert!(e.contains("encoding \"yuv422\" is not read"), "{e}");
        let e = refused(image("mono8", 4, 2, 4, vec![0; 8]));
        assert!(
            e.contains("4×2 pixels where the CameraInfo says 3×2"),
            "{e}"
        );
        let e = refused(image("rgb8", 3, 2, 6, vec![0; 12]));
        assert!(
            e.contains("step 6 bytes is shorter than a row of 3 rgb8 pixels (9 bytes)"),
            "{e}"
        );
        let e = refused(image("mono8", 3, 2, 3, vec![0; 5]));
        assert!(
            e.contains("5 bytes of data where step × height is 6 (truncated)"),
            "{e}"
        );
        let e = refused(image("mono8", 3, 2, 3, vec![0; 7]));
        assert!(e.contains("(too long)"), "{e}");
    }

    #[test]
    fn the_conversion_is_that_of_every_other_input_pixel_for_pixel() {
        use linetrack_vision::{ChannelOrder, to_gray8_ordered};
        use opencv::core::Mat;
        use opencv::prelude::*;
        // Every 16-bit value, and colours on a coarse grid of the cube plus its corners.
        let all16: Vec<u16> = (0..=u16::MAX).collect();
        let reference = to_gray8_ordered(
            Mat::from_slice(&all16).unwrap().try_clone().unwrap(),
            None,
            ChannelOrder::Bgr,
        )
        .unwrap();
        let ours: Vec<u8> = all16.iter().map(|&v| grey_of_16_bits(v)).collect();
        assert_eq!(reference.data_bytes().unwrap(), ours.as_slice());
        let levels: Vec<u8> = (0..=255u8).step_by(5).chain([1, 254]).collect();
        let mut colours = Vec::new();
        for &r in &levels {
            for &g in &levels {
                for &b in &levels {
                    colours.extend([r, g, b]);
                }
            }
        }
        let n = colours.len() / 3;
        for (order, rgb) in [(ChannelOrder::Rgb, true), (ChannelOrder::Bgr, false)] {
            let mat = Mat::from_slice(&colours)
                .and_then(|flat| flat.reshape(3, 1)?.try_clone())
                .unwrap();
            let reference = to_gray8_ordered(mat, None, order).unwrap();
            let ours: Vec<u8> = colours
                .chunks_exact(3)
                .map(|p| {
                    if rgb {
                        grey_of_colour(p[0], p[1], p[2])
                    } else {
                        grey_of_colour(p[2], p[1], p[0])
                    }
                })
                .collect();
            assert_eq!(ours.len(), n);
            assert_eq!(reference.data_bytes().unwrap(), ours.as_slice(), "{rgb}");
        }
    }
}
