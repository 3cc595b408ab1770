//! What a motion estimate fits: the observations (a 3-D point or segment of the previous
//! frame and where it is seen now), their residuals and Jacobians under a motion `T`, and the
//! left-multiplied update `T ← exp(δ) · T`, δ = (ρ, φ). The Gauss–Newton refinement
//! ([`crate::motion`]) and its robust start ([`crate::robust`]) both build on them.

use linetrack_geometry::{Point, Segment, StereoRig};
use nalgebra::{
    Isometry3, Matrix2x3, Matrix3, Point3, SMatrix, Translation3, UnitQuaternion, Vector2, Vector3,
    Vector6,
};

/// A 3-D point of the previous frame and where it is seen now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointObservation {
    /// Position in the previous left camera frame, metres.
    pub position: Point3<f64>,
    /// Pixel in the current left image.
    pub pixel: Point,
    /// Column of its stereo partner in the current right image (same row: the rig is
    /// rectified), when it has one: with [`MotionConfig::stereo_reprojection`](crate::MotionConfig::stereo_reprojection) the point
    /// is reprojected into both images, so the current disparity is observed too.
    pub right_x: Option<f64>,
    /// Uncertainty weight in (0, 1].
    pub weight: f64,
}

/// A 3-D segment of the previous frame and the line it is seen on now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineObservation {
    /// Endpoints in the previous left camera frame, metres.
    pub endpoints: [Point3<f64>; 2],
    /// The observed line `a·u + b·v + c = 0` with `a² + b² = 1` (so residuals are pixels).
    pub line: Vector3<f64>,
    /// The line of its stereo partner in the current right image, in the same form, when
    /// it has one (see [`MotionConfig::stereo_reprojection`](crate::MotionConfig::stereo_reprojection)).
    pub right_line: Option<Vector3<f64>>,
    /// Uncertainty weight in (0, 1].
    pub weight: f64,
}

impl LineObservation {
    /// The observation of `endpoints` on the current segment `seen`; `None` if `seen` has
    /// no direction.
    pub fn new(endpoints: [Point3<f64>; 2], seen: &Segment, weight: f64) -> Option<Self> {
        Some(Self {
            endpoints,
            line: normalised_line(seen)?,
            right_line: None,
            weight,
        })
    }
}

/// The line through `segment` as `(a, b, c)` with `a·u + b·v + c = 0` and `a² + b² = 1`;
/// `None` when it has no direction.
pub fn normalised_line(segment: &Segment) -> Option<Vector3<f64>> {
    let (a, b) = (segment.start, segment.end);
    let line = Vector3::new(a.y - b.y, b.x - a.x, a.x * b.y - b.x * a.y);
    let norm = line.xy().norm();
    (norm > 1e-9 && line.iter().all(|v| v.is_finite())).then(|| line / norm)
}

/// `(π(p), ∂π/∂p)` for the left camera; `None` behind it.
fn project(rig: &StereoRig, p: &Point3<f64>) -> Option<(Vector2<f64>, Matrix2x3<f64>)> {
    if p.z <= 1e-6 {
        return None;
    }
    let (f, z) = (rig.focal_px, p.z);
    let pixel = Vector2::new(f * p.x / z + rig.cx_px, f * p.y / z + rig.cy_px);
    let jacobian = Matrix2x3::new(
        f / z,
        0.0,
        -f * p.x / (z * z),
        0.0,
        f / z,
        -f * p.y / (z * z),
    );
    Some((pixel, jacobian))
}

/// `(π_right(p), ∂π_right/∂p)`: the right camera sits `baseline` along the left one's x
/// axis; `None` behind it.
fn project_right(rig: &StereoRig, p: &Point3<f64>) -> Option<(Vector2<f64>, Matrix2x3<f64>)> {
    project(rig, &Point3::new(p.x - rig.baseline_m, p.y, p.z))
}

/// `∂p'/∂δ = [I | −[p']×]` for the left-multiplied update.
fn transform_jacobian(p: &Point3<f64>) -> SMatrix<f64, 3, 6> {
    let mut j = SMatrix::<f64, 3, 6>::zeros();
    j.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    j.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-p.coords.cross_matrix()));
    j
}

/// Residuals and Jacobians of one point observation under `t`: 2 rows.
pub fn point_residual(
    rig: &StereoRig,
    t: &Isometry3<f64>,
    obs: &PointObservation,
) -> Option<(Vector2<f64>, SMatrix<f64, 2, 6>)> {
    let p = t * obs.position;
    let (pixel, dpi) = project(rig, &p)?;
    Some((
        pixel - Vector2::new(obs.pixel.x, obs.pixel.y),
        dpi * transform_jacobian(&p),
    ))
}

/// The right-image column residual and its Jacobian row of one point observation under
/// `t`; `None` without a right column or behind the camera.
pub fn point_right_residual(
    rig: &StereoRig,
    t: &Isometry3<f64>,
    obs: &PointObservation,
) -> Option<(f64, SMatrix<f64, 1, 6>)> {
    let right_x = obs.right_x?;
    let p = t * obs.position;
    let (pixel, dpi) = project_right(rig, &p)?;
    Some((pixel.x - right_x, dpi.row(0) * transform_jacobian(&p)))
}

/// Residuals (signed endpoint-to-line distances, pixels) and Jacobians of one line
/// observation under `t`: 2 rows.
pub fn line_residual(
    rig: &StereoRig,
    t: &Isometry3<f64>,
    obs: &LineObservation,
) -> Option<(Vector2<f64>, SMatrix<f64, 2, 6>)> {
    let mut r = Vector2::zeros();
    let mut j = SMatrix::<f64, 2, 6>::zeros();
    let normal = obs.line.xy().transpose();
    for (row, endpoint) in obs.endpoints.iter().enumerate() {
        let p = t * endpoint;
        let (pixel, dpi) = project(rig, &p)?;
        r[row] = obs.line.x * pixel.x + obs.line.y * pixel.y + obs.line.z;
        j.set_row(row, &(normal * dpi * transform_jacobian(&p)));
    }
    Some((r, j))
}

/// The signed distances of the endpoints, projected into the current right image, to the
/// right line ([`LineObservation::right_line`]), and their Jacobian; `None` without a
/// right line or behind the camera.
pub fn line_right_residual(
    rig: &StereoRig,
    t: &Isometry3<f64>,
    obs: &LineObservation,
) -> Option<(Vector2<f64>, SMatrix<f64, 2, 6>)> {
    let line = obs.right_line?;
    let normal = line.xy().transpose();
    let mut r = Vector2::zeros();
    let mut j = SMatrix::<f64, 2, 6>::zeros();
    for (row, endpoint) in obs.endpoints.iter().enumerate() {
        let p = t * endpoint;
        let (pixel, dpi) = project_right(rig, &p)?;
        r[row] = line.x * pixel.x + line.y * pixel.y + line.z;
        j.set_row(row, &(normal * dpi * transform_jacobian(&p)));
    }
    Some((r, j))
}

/// Applies the left-multiplied update `δ = (ρ, φ)`.
pub(crate) fn apply_update(step: &Vector6<f64>, t: Isometry3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(step.fixed_rows::<3>(0).into_owned()),
        UnitQuaternion::from_scaled_axis(step.fixed_rows::<3>(3).into_owned()),
    ) * t
}
