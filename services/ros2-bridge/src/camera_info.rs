//! The stereo rig of two `sensor_msgs/CameraInfo`: focal length and principal point from
//! the left rectified projection `P`, the baseline from the right one's `Tx = −fx·B`.
//!
//! The images are taken as rectified (the `image_rect` topics of a ROS stereo pipeline),
//! so the two `P` must describe a rectified pair: the same size, no skew, `fx = fy`, the
//! same `fx, fy, cx, cy` left and right, the left the reference (`Tx = 0`), no vertical
//! offset (`Ty = 0`) and the right camera to the right (`Tx < 0`). A pair that is not is
//! refused naming the field. `R` and `D` are not looked at: in ROS they describe how the
//! raw images were rectified, and the rectified images share the raw ones' `CameraInfo`.

use crate::sensor_msgs::CameraInfo;
use linetrack_geometry::StereoRig;

/// Why two `CameraInfo` give no rig.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InfoError {
    /// The two images differ in size (or one is empty).
    #[error(
        "CameraInfo width × height: left {left_width}×{left_height}, right {right_width}×{right_height}: a stereo pair's images are one size"
    )]
    Size {
        /// Left width.
        left_width: u32,
        /// Left height.
        left_height: u32,
        /// Right width.
        right_width: u32,
        /// Right height.
        right_height: u32,
    },
    /// A value of one side's `CameraInfo` is not what a rectified pair has.
    #[error("{side} CameraInfo {field} = {value}: {why}")]
    Field {
        /// `left` or `right`.
        side: &'static str,
        /// The field (`p[3] (Tx)`, `binning_x`, …).
        field: &'static str,
        /// Its value.
        value: f64,
        /// What it should be.
        why: &'static str,
    },
    /// Left and right differ in a value rectified images share.
    #[error(
        "CameraInfo {field}: left {left}, right {right}: rectified images share their intrinsics"
    )]
    Differ {
        /// The field (`p[0] (fx)`, …).
        field: &'static str,
        /// Left's value.
        left: f64,
        /// Right's value.
        right: f64,
    },
}

/// Two values equal up to rounding of the printed calibration.
fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
}

/// Checks the entries of `info`'s `P` a rectified camera has fixed.
fn rectified(side: &'static str, info: &CameraInfo) -> Result<(), InfoError> {
    let field = |field, value, why| InfoError::Field {
        side,
        field,
        value,
        why,
    };
    if let Some((i, v)) = info.p.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        const NAMES: [&str; 12] = [
            "p[0]", "p[1]", "p[2]", "p[3]", "p[4]", "p[5]", "p[6]", "p[7]", "p[8]", "p[9]",
            "p[10]", "p[11]",
        ];
        return Err(field(NAMES[i], *v, "not a finite number"));
    }
    for (name, binning) in [("binning_x", info.binning_x), ("binning_y", info.binning_y)] {
        if binning > 1 {
            return Err(field(
                name,
                f64::from(binning),
                "binned images are not read (0 or 1)",
            ));
        }
    }
    let p = &info.p;
    let zero = "a rectified projection has 0 there";
    for (name, value, expected, why) in [
        ("p[1] (skew)", p[1], 0.0, zero),
        ("p[4]", p[4], 0.0, zero),
        ("p[8]", p[8], 0.0, zero),
        ("p[9]", p[9], 0.0, zero),
        ("p[10]", p[10], 1.0, "a rectified projection has 1 there"),
        ("p[11]", p[11], 0.0, zero),
        (
            "p[7] (Ty)",
            p[7],
            0.0,
            "a horizontal stereo pair has no vertical offset",
        ),
    ] {
        if !same(value, expected) {
            return Err(field(name, value, why));
        }
    }
    if !(p[0] > 0.0) {
        return Err(field(
            "p[0] (fx)",
            p[0],
            "the focal length must be positive",
        ));
    }
    if !same(p[0], p[5]) {
        return Err(field(
            "p[5] (fy)",
            p[5],
            "the rig has square pixels: fy must equal fx (p[0])",
        ));
    }
    Ok(())
}

/// The rig of a rectified stereo pair's `left` and `right` `CameraInfo`.
pub fn stereo_rig(left: &CameraInfo, right: &CameraInfo) -> Result<StereoRig, InfoError> {
    if (left.width, left.height) != (right.width, right.height)
        || left.width == 0
        || left.height == 0
    {
        return Err(InfoError::Size {
            left_width: left.width,
            left_height: left.height,
            right_width: right.width,
            right_height: right.height,
        });
    }
    rectified("left", left)?;
    rectified("right", right)?;
    for (field, i) in [
        ("p[0] (fx)", 0),
        ("p[5] (fy)", 5),
        ("p[2] (cx)", 2),
        ("p[6] (cy)", 6),
    ] {
        if !same(left.p[i], right.p[i]) {
            return Err(InfoError::Differ {
                field,
                left: left.p[i],
                right: right.p[i],
            });
        }
    }
    if !same(left.p[3], 0.0) {
        return Err(InfoError::Field {
            side: "left",
            field: "p[3] (Tx)",
            value: left.p[3],
            why: "the left camera is the pair's reference: Tx = 0",
        });
    }
    if !(right.p[3] < 0.0) {
        return Err(InfoError::Field {
            side: "right",
            field: "p[3] (Tx)",
            value: right.p[3],
            why: "Tx = −fx·baseline: negative for a right camera",
        });
    }
    let focal_px = left.p[0];
    Ok(StereoRig {
        focal_px,
        cx_px: left.p[2],
        cy_px: left.p[6],
        baseline_m: -right.p[3] / right.p[0],
        width_px: left.width,
        height_px: left.height,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rectified pair's info: f 458.6, c (367.2, 248.4), 752×480, baseline 0.11 m.
    pub(crate) fn info(tx: f64) -> CameraInfo {
        CameraInfo {
            width: 752,
            height: 480,
            p: [
                458.6, 0.0, 367.2, tx, 0.0, 458.6, 248.4, 0.0, 0.0, 0.0, 1.0, 0.0,
            ],
            ..CameraInfo::default()
        }
    }

    #[test]
    fn the_rig_comes_from_the_two_projections() {
        let rig = stereo_rig(&info(0.0), &info(-458.6 * 0.11)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (
                rig.focal_px,
                rig.cx_px,
                rig.cy_px,
                rig.width_px,
                rig.height_px
            ),
            (458.6, 367.2, 248.4, 752, 480)
        );
        assert!((rig.baseline_m - 0.11).abs() < 1e-15, "{rig:?}");
    }

    #[test]
    fn a_pair_that_is_not_rectified_or_not_one_size_is_refused_naming_the_field() {
        let right = info(-50.0);
        let refused = |left: &CameraInfo, right: &CameraInfo| -> String {
            match stereo_rig(left, right) {
                Ok(rig) => panic!("accepted {rig:?}"),
                Err(e) => e.to_string(),
            }
        };
        let small = CameraInfo {
            width: 640,
            ..info(0.0)
        };
        let e = refused(&small, &right);
        assert!(e.contains("left 640×480, right 752×480"), "{e}");
        let mut skewed = info(0.0);
        skewed.p[1] = 0.5;
        assert!(refused(&skewed, &right).contains("left CameraInfo p[1] (skew) = 0.5"));
        let mut other_cx = info(-50.0);
        other_cx.p[2] = 360.0;
        let e = refused(&info(0.0), &other_cx);
        assert!(e.contains("p[2] (cx): left 367.2, right 360"), "{e}");
        let mut fy = info(0.0);
        fy.p[5] = 460.0;
        assert!(refused(&fy, &right).contains("left CameraInfo p[5] (fy) = 460"));
        let mut ty = info(-50.0);
        ty.p[7] = 3.0;
        assert!(refused(&info(0.0), &ty).contains("right CameraInfo p[7] (Ty) = 3"));
        assert!(refused(&info(0.0), &info(50.0)).contains("right CameraInfo p[3] (Tx) = 50"));
        assert!(refused(&info(-50.0), &right).contains("left CameraInfo p[3] (Tx) = -50"));
        let mut nan = info(0.0);
        nan.p[0] = f64::NAN;
        assert!(refused(&nan, &right).contains("left CameraInfo p[0] = NaN"));
        let binned = CameraInfo {
            binning_x: 2,
            ..info(-50.0)
        };
        assert!(refused(&info(0.0), &binned).contains("right CameraInfo binning_x = 2"));
    }
}
