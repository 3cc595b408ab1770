//! Camera calibration and stereo rectification.
//!
//! An unrectified rig (EuRoC: two pinhole cameras with radial-tangential distortion and a
//! known relative pose) is rectified once with OpenCV's `stereoRectify`; the per-pixel maps
//! are precomputed with `initUndistortRectifyMap` and applied to every frame with `remap`.
//! What the rest of the system uses is the resulting [`StereoRig`]: one focal length, one
//! principal point, the baseline, and rows that are epipolar lines.

use crate::DatasetError;
use linetrack_geometry::StereoRig;
use linetrack_vision::GrayImage;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use opencv::calib3d;
use opencv::core::{self, Mat, MatTraitConst, Rect, Scalar, Size};
use opencv::imgproc;

/// One pinhole camera with radial-tangential distortion, as EuRoC's sensor.yaml gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeCamera {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal lengths and principal point `[fx, fy, cx, cy]`, pixels.
    pub intrinsics: [f64; 4],
    /// Radial-tangential coefficients `[k1, k2, p1, p2]` (zeros: no distortion).
    pub distortion: [f64; 4],
    /// The camera's pose in the body frame (EuRoC's T_BS): `p_body = T · p_camera`.
    pub body_from_camera: Isometry3<f64>,
}

/// Precomputed rectification of a stereo rig.
pub struct Rectifier {
    rig: StereoRig,
    /// Rotation from the raw left camera frame to the rectified left frame.
    left_rotation: Rotation3<f64>,
    maps: [(Mat, Mat); 2],
}

impl std::fmt::Debug for Rectifier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Rectifier")
            .field("rig", &self.rig)
            .field("left_rotation", &self.left_rotation)
            .finish_non_exhaustive()
    }
}

fn cv(context: &'static str) -> impl Fn(opencv::Error) -> DatasetError {
    move |reason| DatasetError::OpenCv { context, reason }
}

fn mat3(m: &Matrix3<f64>) -> Result<Mat, DatasetError> {
    let rows: Vec<[f64; 3]> = (0..3).map(|r| [m[(r, 0)], m[(r, 1)], m[(r, 2)]]).collect();
    Mat::from_slice_2d(&rows).map_err(cv("building a 3×3 matrix"))
}

fn camera_matrix(c: &PinholeCamera) -> Result<Mat, DatasetError> {
    let [fx, fy, cx, cy] = c.intrinsics;
    mat3(&Matrix3::new(fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0))
}

fn read(m: &Mat, r: i32, c: i32) -> Result<f64, DatasetError> {
    m.at_2d::<f64>(r, c)
        .copied()
        .map_err(cv("reading a rectification matrix"))
}

impl Rectifier {
    /// Rectifies the rig made of `left` and `right` (poses relative to a common body frame).
    /// Errors name what is wrong with the calibration (sizes differ, non-finite values).
    pub fn new(left: &PinholeCamera, right: &PinholeCamera) -> Result<Self, DatasetError> {
        if (left.width, left.height) != (right.width, right.height)
            || left.width == 0
            || left.height == 0
        {
            return Err(DatasetError::Calibration(format!(
                "left is {}×{} but right is {}×{}: a stereo rig needs two equal, non-empty image sizes",
                left.width, left.height, right.width, right.height
            )));
        }
        for (name, c) in [("left", left), ("right", right)] {
            let values = c
                .intrinsics
                .iter()
                .chain(&c.distortion)
                .chain(c.body_from_camera.translation.vector.iter());
            if !values.clone().all(|v| v.is_finite())
                || !c
                    .body_from_camera
                    .rotation
                    .coords
                    .iter()
                    .all(|v| v.is_finite())
            {
                return Err(DatasetError::Calibration(format!(
                    "{name} camera has a non-finite intrinsic, distortion or pose value"
                )));
            }
            if c.intrinsics[0] <= 0.0 || c.intrinsics[1] <= 0.0 {
                return Err(DatasetError::Calibration(format!(
                    "{name} camera has a non-positive focal length {:?}",
                    &c.intrinsics[..2]
                )));
            }
        }
        // Points in the left camera frame → right camera frame: p_r = R p_l + t.
        let right_from_left = right.body_from_camera.inverse() * left.body_from_camera;
        let t = right_from_left.translation.vector;
        if t.norm() < 1e-6 {
            return Err(DatasetError::Calibration(
                "the two cameras are at the same place: no baseline".to_string(),
            ));
        }
        let size = Size::new(left.width as i32, left.height as i32);
        let (k1, k2) = (camera_matrix(left)?, camera_matrix(right)?);
        let (d1, d2) = (
            Mat::from_slice(&left.distortion).map_err(cv("distortion"))?,
            Mat::from_slice(&right.distortion).map_err(cv("distortion"))?,
        );
        let r = mat3(right_from_left.rotation.to_rotation_matrix().matrix())?;
        let t_values = [t.x, t.y, t.z];
        // A 3×1 column, as stereoRectify asserts.
        let t_mat = Mat::from_slice(&t_values)
            .and_then(|row| row.reshape(1, 3)?.try_clone())
            .map_err(cv("translation"))?;
        let (mut r1, mut r2, mut p1, mut p2, mut q) = (
            Mat::default(),
            Mat::default(),
            Mat::default(),
            Mat::default(),
            Mat::default(),
        );
        let (mut roi1, mut roi2) = (Rect::default(), Rect::default());
        calib3d::stereo_rectify(
            &k1,
            &d1,
            &k2,
            &d2,
            size,
            &r,
            &t_mat,
            &mut r1,
            &mut r2,
            &mut p1,
            &mut p2,
            &mut q,
            calib3d::CALIB_ZERO_DISPARITY,
            0.0,
            size,
            Some(&mut roi1),
            Some(&mut roi2),
        )
        .map_err(cv("stereoRectify"))?;
        let mut maps = [
            (Mat::default(), Mat::default()),
            (Mat::default(), Mat::default()),
        ];
        for ((k, d, rr, p), map) in [(&k1, &d1, &r1, &p1), (&k2, &d2, &r2, &p2)]
            .into_iter()
            .zip(maps.iter_mut())
        {
            calib3d::init_undistort_rectify_map(
                k,
                d,
                rr,
                p,
                size,
                core::CV_16SC2,
                &mut map.0,
                &mut map.1,
            )
            .map_err(cv("initUndistortRectifyMap"))?;
        }
        let focal_px = read(&p1, 0, 0)?;
        let baseline_m = -read(&p2, 0, 3)? / read(&p2, 0, 0)?;
        let rig = StereoRig {
            focal_px,
            cx_px: read(&p1, 0, 2)?,
            cy_px: read(&p1, 1, 2)?,
            baseline_m,
            width_px: left.width,
            height_px: left.height,
        };
        if !(rig.focal_px.is_finite()
            && rig.focal_px > 0.0
            && rig.baseline_m.is_finite()
            && rig.baseline_m > 0.0)
        {
            return Err(DatasetError::Calibration(format!(
                "rectification gave an unusable rig {rig:?} (is the right camera to the right?)"
            )));
        }
        let mut m = Matrix3::zeros();
        for row in 0..3 {
            for col in 0..3 {
                m[(row, col)] = read(&r1, row as i32, col as i32)?;
            }
        }
        Ok(Self {
            rig,
            left_rotation: Rotation3::from_matrix_unchecked(m),
            maps,
        })
    }

    /// The rectified rig: what matching and triangulation use.
    pub fn rig(&self) -> StereoRig {
        self.rig
    }

    /// Pose of the rectified left camera given the pose of the raw left camera.
    pub fn rectified_left_pose(&self, raw_left_pose: &Isometry3<f64>) -> Isometry3<f64> {
        // p_rect = R1 p_raw, so the rectified camera's pose is the raw one rotated by R1ᵀ.
        let rotation = UnitQuaternion::from_rotation_matrix(&self.left_rotation.inverse());
        raw_left_pose * Isometry3::from_parts(Translation3::from(Vector3::zeros()), rotation)
    }

    /// Rectifies one image of the pair (`right = false`: left camera).
    pub fn rectify(&self, image: &GrayImage, right: bool) -> Result<GrayImage, DatasetError> {
        if (image.width(), image.height()) != (self.rig.width_px as i32, self.rig.height_px as i32)
        {
            return Err(DatasetError::Calibration(format!(
                "{} is {}×{} but the calibration is for {}×{}",
                image.origin(),
                image.width(),
                image.height(),
                self.rig.width_px,
                self.rig.height_px
            )));
        }
        let (map1, map2) = &self.maps[usize::from(right)];
        let mut out = Mat::default();
        imgproc::remap(
            image.mat(),
            &mut out,
            map1,
            map2,
            imgproc::INTER_LINEAR,
            core::BORDER_CONSTANT,
            Scalar::all(0.0),
        )
        .map_err(cv("remap"))?;
        GrayImage::from_mat(out, &format!("{} (rectified)", image.origin()))
            .map_err(DatasetError::Image)
    }
}
