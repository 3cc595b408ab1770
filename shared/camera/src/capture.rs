//! Opening a stereo camera through OpenCV `videoio` and reading rectified grey pairs.
//!
//! A capture is named by one string ([`Device::parse`]):
//!
//! - `0`, `1`, … — a V4L2 device by index; `/dev/video0` — a V4L2 device by path;
//! - a string with `!` — a GStreamer pipeline ending in `appsink`
//!   (`v4l2src device=/dev/video0 ! videoconvert ! video/x-raw,format=GRAY8 ! appsink`);
//! - a path with `%` — numbered images read by OpenCV's `CAP_IMAGES` (`dir/%06d.png`).
//!
//! A stereo camera is either one capture delivering both images side by side in one frame
//! (left half, right half: [`split_side_by_side`]) or two captures (left, right) read one
//! after the other. Colour frames are converted to grey; every pair is checked against the
//! calibration's image size and rectified with maps computed once.

use crate::CameraError;
use crate::calibration::StereoCalibration;
use linetrack_datasets::Rectifier;
use linetrack_geometry::StereoRig;
use linetrack_vision::GrayImage;
use opencv::core::{Mat, MatTraitConst, Rect};
use opencv::imgproc;
use opencv::prelude::VideoCaptureTrait;
use opencv::prelude::VideoCaptureTraitConst;
use opencv::videoio::{self, VideoCapture};

/// How a capture string is opened.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeviceKind {
    /// A V4L2 device by index (`/dev/videoN`).
    V4l2Index(i32),
    /// A V4L2 device by path.
    V4l2Path(String),
    /// A GStreamer pipeline ending in `appsink`.
    GStreamer(String),
    /// Numbered image files (`CAP_IMAGES`), a `printf` pattern.
    Images(String),
}

impl DeviceKind {
    /// What it is, for messages.
    pub fn describe(&self) -> String {
        match self {
            DeviceKind::V4l2Index(i) => format!("V4L2 device /dev/video{i}"),
            DeviceKind::V4l2Path(p) => format!("V4L2 device {p}"),
            DeviceKind::GStreamer(p) => format!("GStreamer pipeline `{p}`"),
            DeviceKind::Images(p) => format!("image sequence {p}"),
        }
    }
}

/// One opened capture.
pub struct Device {
    kind: DeviceKind,
    capture: VideoCapture,
    frame: Mat,
}

impl std::fmt::Debug for Device {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Device")
            .field("kind", &self.kind)
            .finish_non_exhaustive()
    }
}

impl Device {
    /// What kind of capture `spec` names; an empty or unrecognisable string is refused.
    pub fn parse(spec: &str) -> Result<DeviceKind, CameraError> {
        let spec = spec.trim();
        if spec.is_empty() {
            return Err(CameraError::Spec {
                spec: spec.to_string(),
                message: "empty capture".to_string(),
            });
        }
        if spec.contains('!') {
            return Ok(DeviceKind::GStreamer(spec.to_string()));
        }
        if let Ok(index) = spec.parse::<i32>() {
            return if index >= 0 {
                Ok(DeviceKind::V4l2Index(index))
            } else {
                Err(CameraError::Spec {
                    spec: spec.to_string(),
                    message: "a V4L2 device index is 0 or more".to_string(),
                })
            };
        }
        if spec.starts_with("/dev/") {
            return Ok(DeviceKind::V4l2Path(spec.to_string()));
        }
        if spec.contains('%') {
            return Ok(DeviceKind::Images(spec.to_string()));
        }
        Err(CameraError::Spec {
            spec: spec.to_string(),
            message: "not a V4L2 device (an index or /dev/videoN), a GStreamer pipeline (with `!`, ending in appsink) or a numbered image pattern (with `%`, e.g. dir/%06d.png)".to_string(),
        })
    }

    /// Opens the capture `spec` names.
    pub fn open(spec: &str) -> Result<Self, CameraError> {
        let kind = Self::parse(spec)?;
        let opened = match &kind {
            DeviceKind::V4l2Index(i) => VideoCapture::new(*i, videoio::CAP_V4L2),
            DeviceKind::V4l2Path(p) => VideoCapture::from_file(p, videoio::CAP_V4L2),
            DeviceKind::GStreamer(p) => VideoCapture::from_file(p, videoio::CAP_GSTREAMER),
            DeviceKind::Images(p) => VideoCapture::from_file(p, videoio::CAP_IMAGES),
        };
        let cannot = |reason: String| CameraError::Open {
            device: kind.describe(),
            reason,
        };
        let capture = opened.map_err(|e| cannot(e.message.clone()))?;
        if !capture.is_opened().map_err(|e| cannot(e.message.clone()))? {
            let hint = match &kind {
                DeviceKind::GStreamer(_) => {
                    " (is the pipeline valid, does it end in appsink, are its GStreamer plugins installed?)"
                }
                DeviceKind::Images(_) => " (no file matches the pattern's first number?)",
                _ => " (does the device exist, is it free, may this user open it?)",
            };
            return Err(cannot(format!("OpenCV could not open it{hint}")));
        }
        Ok(Self {
            kind,
            capture,
            frame: Mat::default(),
        })
    }

    /// What it is, for messages.
    pub fn describe(&self) -> String {
        self.kind.describe()
    }

    /// Whether `CAP_PROP_POS_MSEC` is each frame's own capture time: V4L2's buffer
    /// timestamp is; OpenCV's GStreamer reader answers it with a position query at read
    /// time (opencv/opencv#19025), which jitters with the reader, so gaps in it are not
    /// lost frames.
    pub fn stamps_each_frame(&self) -> bool {
        matches!(
            self.kind,
            DeviceKind::V4l2Index(_) | DeviceKind::V4l2Path(_)
        )
    }

    /// The frame rate the driver announces, if any.
    pub fn driver_fps(&self) -> Option<f64> {
        self.capture
            .get(videoio::CAP_PROP_FPS)
            .ok()
            .filter(|f| f.is_finite() && *f > 0.0 && *f < 10_000.0)
    }

    /// Reads the next frame, as grey, with the driver's timestamp in milliseconds where it
    /// gives one (`CAP_PROP_POS_MSEC`: the GStreamer buffer's pts, the V4L2 buffer's time).
    /// A failed read (device gone, stream ended) is [`CameraError::Read`].
    pub fn read(&mut self) -> Result<(Mat, Option<f64>), CameraError> {
        let lost = |reason: String| CameraError::Read {
            device: self.kind.describe(),
            reason,
        };
        match self.capture.read(&mut self.frame) {
            Ok(true) if !self.frame.empty() => {}
            Ok(_) => {
                return Err(lost(
                    "no frame (the device is gone or the stream ended)".to_string(),
                ));
            }
            Err(e) => return Err(lost(e.message.clone())),
        }
        let stamp_ms = self
            .capture
            .get(videoio::CAP_PROP_POS_MSEC)
            .ok()
            .filter(|t| t.is_finite() && *t >= 0.0);
        let gray =
            to_gray(&self.frame).map_err(|e| lost(format!("converting to grey: {}", e.message)))?;
        Ok((gray, stamp_ms))
    }
}

/// One channel of 8 bits: a copy of a grey frame, colour converted (BGR, BGRA).
fn to_gray(frame: &Mat) -> Result<Mat, opencv::Error> {
    let mut gray = Mat::default();
    match frame.channels() {
        3 => imgproc::cvt_color_def(frame, &mut gray, imgproc::COLOR_BGR2GRAY)?,
        4 => imgproc::cvt_color_def(frame, &mut gray, imgproc::COLOR_BGRA2GRAY)?,
        _ => frame.copy_to(&mut gray)?,
    }
    if gray.depth() != opencv::core::CV_8U {
        let mut eight = Mat::default();
        gray.convert_to_def(&mut eight, opencv::core::CV_8U)?;
        return Ok(eight);
    }
    Ok(gray)
}

/// The two halves of a side-by-side frame (left half, right half), copied. An odd or empty width is
/// refused.
pub fn split_side_by_side(frame: &Mat) -> Result<(Mat, Mat), CameraError> {
    let (w, h) = (frame.cols(), frame.rows());
    if w < 2 || w % 2 != 0 || h < 1 {
        return Err(CameraError::Layout(format!(
            "a side-by-side frame needs an even, non-zero width; this one is {w}×{h}"
        )));
    }
    let half = w / 2;
    let view = |x: i32| -> Result<Mat, CameraError> {
        Mat::roi(frame, Rect::new(x, 0, half, h))
            .and_then(|roi| roi.try_clone())
            .map_err(|e| CameraError::OpenCv {
                context: "splitting a side-by-side frame",
                reason: e,
            })
    };
    Ok((view(0)?, view(half)?))
}

/// A pair read from the camera: rectified grey images and the driver's timestamp.
#[derive(Debug)]
pub struct StereoImages {
    /// The rectified left image.
    pub left: GrayImage,
    /// The rectified right image.
    pub right: GrayImage,
    /// The driver's timestamp of the (left) frame, milliseconds, where it gives one.
    pub driver_ms: Option<f64>,
}

/// A stereo camera: one side-by-side capture or two, and the rectification.
#[derive(Debug)]
pub struct StereoCamera {
    left: Device,
    right: Option<Device>,
    rectifier: std::sync::Arc<Rectifier>,
    size: (i32, i32),
}

impl StereoCamera {
    /// Opens `capture` (side by side when `capture_right` is `None`, else the left camera)
    /// rectified by `rectifier`.
    pub fn open(
        capture: &str,
        capture_right: Option<&str>,
        rectifier: std::sync::Arc<Rectifier>,
    ) -> Result<Self, CameraError> {
        let rig = rectifier.rig();
        let left = Device::open(capture)?;
        let right = capture_right.map(Device::open).transpose()?;
        Ok(Self {
            left,
            right,
            rectifier,
            size: (rig.width_px as i32, rig.height_px as i32),
        })
    }

    /// The capture(s), for messages.
    pub fn describe(&self) -> String {
        match &self.right {
            None => format!("{} (side by side)", self.left.describe()),
            Some(r) => format!("{} and {}", self.left.describe(), r.describe()),
        }
    }

    /// The frame rate the (left) driver announces, if any.
    pub fn driver_fps(&self) -> Option<f64> {
        self.left.driver_fps()
    }

    /// Whether the (left) driver stamps each frame with its capture time
    /// ([`Device::stamps_each_frame`]): only then are gaps in its timestamps lost frames.
    pub fn stamps_each_frame(&self) -> bool {
        self.left.stamps_each_frame()
    }

    /// Reads, checks and rectifies the next pair.
    pub fn read(&mut self) -> Result<StereoImages, CameraError> {
        let (left_raw, driver_ms) = self.left.read()?;
        let (left, right) = match &mut self.right {
            None => {
                let layout = format!(
                    " (its two {}×{} images side by side)",
                    self.size.0, self.size.1
                );
                check_size(
                    &left_raw,
                    (2 * self.size.0, self.size.1),
                    &self.left,
                    &layout,
                )?;
                split_side_by_side(&left_raw)?
            }
            Some(right_device) => {
                let (right_raw, _) = right_device.read()?;
                check_size(&left_raw, self.size, &self.left, "")?;
                check_size(&right_raw, self.size, right_device, "")?;
                (left_raw, right_raw)
            }
        };
        let wrap = |mat: Mat, side: &str| {
            GrayImage::from_mat(mat, &format!("{} {side}", self.left.describe()))
                .map_err(|e| CameraError::Frame(e.to_string()))
        };
        let (left, right) = (wrap(left, "left")?, wrap(right, "right")?);
        let rectify = |image: &GrayImage, is_right: bool| {
            self.rectifier
                .rectify(image, is_right)
                .map_err(CameraError::Dataset)
        };
        Ok(StereoImages {
            left: rectify(&left, false)?,
            right: rectify(&right, true)?,
            driver_ms,
        })
    }
}

/// Refuses a frame whose size is not the calibration's, naming the device and both sizes.
fn check_size(
    frame: &Mat,
    expected: (i32, i32),
    device: &Device,
    what: &str,
) -> Result<(), CameraError> {
    let got = (frame.cols(), frame.rows());
    if got != expected {
        return Err(CameraError::Size {
            device: device.describe(),
            got_width: got.0,
            got_height: got.1,
            expected_width: expected.0,
            expected_height: expected.1,
            layout: what.to_string(),
        });
    }
    Ok(())
}

/// The rectifier and rig of a calibration (maps computed once).
pub fn rectify_calibration(
    calibration: &StereoCalibration,
) -> Result<(Rectifier, StereoRig), CameraError> {
    let rectifier =
        Rectifier::new(&calibration.left, &calibration.right).map_err(CameraError::Dataset)?;
    let rig = rectifier.rig();
    Ok((rectifier, rig))
}

#[cfg(test)]
mod tests {
    use super::*;
    use opencv::core::{CV_8UC1, Scalar};
    use opencv::prelude::MatTrait;

    #[test]
    fn capture_strings_name_their_kind_or_are_refused() {
        assert_eq!(Device::parse("0").ok(), Some(DeviceKind::V4l2Index(0)));
        assert_eq!(
            Device::parse("/dev/video2").ok(),
            Some(DeviceKind::V4l2Path("/dev/video2".into()))
        );
        assert!(matches!(
            Device::parse("videotestsrc ! appsink"),
            Ok(DeviceKind::GStreamer(_))
        ));
        assert!(matches!(
            Device::parse("/tmp/x/%06d.png"),
            Ok(DeviceKind::Images(_))
        ));
        for bad in ["", "  ", "-1", "camera.avi"] {
            let err = Device::parse(bad)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(err.contains("capture"), "{bad:?}: {err}");
        }
    }

    #[test]
    fn side_by_side_frames_split_into_their_halves() {
        let (w, h) = (8, 3);
        let mut frame = Mat::new_rows_cols_with_default(h, w, CV_8UC1, Scalar::all(0.0))
            .unwrap_or_else(|e| panic!("{e}"));
        for y in 0..h {
            for x in 0..w {
                *frame
                    .at_2d_mut::<u8>(y, x)
                    .unwrap_or_else(|e| panic!("{e}")) = (10 * x + y) as u8;
            }
        }
        let (left, right) = split_side_by_side(&frame).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (left.cols(), left.rows(), right.cols(), right.rows()),
            (4, 3, 4, 3)
        );
        for y in 0..h {
            for x in 0..4 {
                let at = |m: &Mat| *m.at_2d::<u8>(y, x).unwrap_or_else(|e| panic!("{e}"));
                assert_eq!(at(&left), (10 * x + y) as u8);
                assert_eq!(at(&right), (10 * (x + 4) + y) as u8);
            }
        }
        let odd = Mat::new_rows_cols_with_default(2, 7, CV_8UC1, Scalar::all(0.0))
            .unwrap_or_else(|e| panic!("{e}"));
        let err = split_side_by_side(&odd)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("7×2"), "{err}");
    }

    /// An ideal 752×480 rig: focal 400 px, 10 cm baseline, no distortion.
    fn ideal_rectifier() -> std::sync::Arc<Rectifier> {
        let camera = |x_m: f64| linetrack_datasets::PinholeCamera {
            width: 752,
            height: 480,
            intrinsics: [400.0, 400.0, 376.0, 240.0],
            distortion: [0.0; 4],
            body_from_camera: nalgebra::Isometry3::translation(x_m, 0.0, 0.0),
        };
        std::sync::Arc::new(
            Rectifier::new(&camera(0.0), &camera(0.1)).unwrap_or_else(|e| panic!("{e}")),
        )
    }

    #[test]
    fn a_gstreamer_side_by_side_stream_gives_rectified_pairs_with_growing_driver_time() {
        // The right half is the left one shifted 8 px: `spokes` cropped on either side.
        let src = |crop: &str| {
            format!(
                "videotestsrc num-buffers=3 pattern=spokes ! video/x-raw,width=760,height=480,framerate=20/1 ! videocrop {crop}=8 ! c."
            )
        };
        let pipeline = format!(
            "compositor name=c sink_1::xpos=752 ! video/x-raw,width=1504,height=480 ! videoconvert ! video/x-raw,format=GRAY8 ! appsink {} {}",
            src("right"),
            src("left")
        );
        let mut camera = StereoCamera::open(&pipeline, None, ideal_rectifier())
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(camera.driver_fps(), Some(20.0));
        let pairs: Vec<StereoImages> = (0..3)
            .map(|_| camera.read().unwrap_or_else(|e| panic!("{e}")))
            .collect();
        let times: Vec<f64> = pairs.iter().filter_map(|p| p.driver_ms).collect();
        // The compositor stamps its output with the pipeline's running time: growing.
        assert_eq!(times.len(), 3, "{times:?}");
        assert!(times.windows(2).all(|w| w[1] > w[0]), "{times:?}");
        let pair = &pairs[0];
        assert_eq!((pair.left.width(), pair.left.height()), (752, 480));
        let (Some(left), Some(right)) = (pair.left.pixels(), pair.right.pixels()) else {
            panic!("images not continuous");
        };
        // Away from the borders, right(x) = left(x + 8): disparity 8 px.
        let mut differing = 0;
        for y in 100..380 {
            for x in 100..600 {
                if left[y * 752 + x + 8] != right[y * 752 + x] {
                    differing += 1;
                }
            }
        }
        assert!(differing < 100, "{differing} pixels differ");
        // The stream ends after 3 buffers: the next read fails, naming the pipeline.
        let err = camera
            .read()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains("videotestsrc") && err.contains("read failed"),
            "{err}"
        );
    }

    #[test]
    fn frames_of_another_size_than_the_calibration_are_refused_naming_both() {
        let pipeline =
            "videotestsrc num-buffers=1 ! video/x-raw,format=GRAY8,width=1280,height=480 ! appsink";
        let mut camera =
            StereoCamera::open(pipeline, None, ideal_rectifier()).unwrap_or_else(|e| panic!("{e}"));
        let err = camera
            .read()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains("1280×480") && err.contains("1504×480") && err.contains("side by side"),
            "{err}"
        );
    }

    #[test]
    fn a_missing_device_is_refused_naming_it() {
        let err = Device::open("/dev/video-linetrack-none")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("/dev/video-linetrack-none"), "{err}");
        let err = Device::open("/nonexistent-linetrack/%06d.png")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("/nonexistent-linetrack/%06d.png"), "{err}");
    }
}
