//! Table II: the odometry per sequence and configuration, with and without the simulated
//! illumination changes.

use linetrack_datasets::StereoSequence;
use linetrack_odometry::{Features, Odometry, OdometryConfig, metrics};
use linetrack_vision::{DetectorKind, MatcherKind, perturb};
use nalgebra::Isometry3;

/// The odometry configurations compared (all with LSD).
pub const CONFIGURATIONS: [(&str, Features, MatcherKind); 4] = [
    ("P+L, LBD", Features::PointsAndLines, MatcherKind::Lbd),
    ("P+L, ℓ1", Features::PointsAndLines, MatcherKind::L1),
    ("L, LBD", Features::LinesOnly, MatcherKind::Lbd),
    ("L, ℓ1", Features::LinesOnly, MatcherKind::L1),
];

/// One run of the odometry.
#[derive(Debug, Clone, Default)]
pub struct OdometryRun {
    /// Estimated poses (world = first camera).
    pub estimate: Vec<Isometry3<f64>>,
    /// Ground truth in the same frame, when known.
    pub truth: Option<Vec<Isometry3<f64>>>,
    /// Frames lost.
    pub lost: usize,
    /// Translational RPE RMSE per frame, metres.
    pub rpe_m: Option<f64>,
    /// ATE RMSE, metres.
    pub ate_m: Option<f64>,
}

/// Runs one configuration over the first `frames` frames.
pub fn run(
    sequence: &StereoSequence,
    features: Features,
    matcher: MatcherKind,
    frames: usize,
    illumination: crate::tracking::Illumination<'_>,
) -> anyhow::Result<OdometryRun> {
    let config = OdometryConfig {
        detector: DetectorKind::Lsd,
        matcher,
        features,
        ..OdometryConfig::default()
    };
    let mut odometry = Odometry::new(config, sequence.rig)?;
    let start_ns = sequence.frames.first().map_or(0, |f| f.timestamp_ns);
    let mut run = OdometryRun::default();
    let mut truth = Vec::new();
    for k in 0..frames.min(sequence.frames.len()) {
        let frame = sequence.load_frame(k).map_err(|e| anyhow::anyhow!("{e}"))?;
        let (left, right) = match illumination {
            Some(at) => {
                let (gain, bias) = at((frame.timestamp_ns - start_ns) as f64 * 1e-9);
                (
                    perturb(&frame.left, gain, bias)?,
                    perturb(&frame.right, gain, bias)?,
                )
            }
            None => (frame.left, frame.right),
        };
        let result = odometry.track(&left, &right)?;
        run.lost += usize::from(result.lost);
        run.estimate.push(result.pose);
        truth.push(frame.pose);
    }
    if let Some(truth) = truth
        .into_iter()
        .collect::<Option<Vec<_>>>()
        .filter(|t| !t.is_empty())
    {
        let first = truth[0].inverse();
        let truth: Vec<_> = truth.iter().map(|p| first * p).collect();
        run.rpe_m = metrics::rpe_translation_rmse(&run.estimate, &truth, 1);
        run.ate_m = metrics::ate_rmse(&run.estimate, &truth);
        run.truth = Some(truth);
    }
    Ok(run)
}
