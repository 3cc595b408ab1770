//! ORB points (OpenCV features2d, or our own in [`native`]): extraction, the side worker that extracts the right
//! image and matches the stereo pair beside the caller, and (in the submodules) matching
//! by descriptor and sub-pixel refinement.

use crate::worker::{SideWorker, copy_image_into};
use crate::{
    AppearanceGates, BinaryDescriptors, FeatureMatch, GrayImage, OpenCvContext, OrbOptions,
    VisionError,
};
use linetrack_geometry::{MatchCase, Point};
use opencv::core::{KeyPoint, KeyPointTraitConst, Mat, MatTraitConst, Ptr, Vector};
use opencv::features2d::{Feature2DTrait, ORB, ORB_ScoreType};

mod matching;
mod native;
mod refine;
mod row_search;

pub use matching::{PointMatcher, points_may_match};
pub use native::{FastBriefExtractor, PointExtractor};
pub use refine::{MIN_TRACK_CORRELATION, refine_stereo_column, refine_track};
pub use row_search::{RowSearch, RowSearchSettings};

/// Points of one image with their descriptors (row k for `points[k]`).
#[derive(Debug, Clone, Default)]
pub struct PointFeatures {
    /// Keypoint positions, pixels.
    pub points: Vec<Point>,
    /// Pyramid level each point was detected at (0: full resolution); its position is
    /// quantised to that level's pixel, `scale_factor^level` full-resolution pixels.
    pub levels: Vec<u8>,
    /// ORB descriptors.
    pub descriptors: BinaryDescriptors,
}

impl PointFeatures {
    /// Makes this a copy of `other`, in the buffers it has (no allocation once they are
    /// large enough).
    pub fn copy_from(&mut self, other: &Self) {
        self.points.clone_from(&other.points);
        self.levels.clone_from(&other.levels);
        self.descriptors.copy_from(&other.descriptors);
    }
}

/// ORB detection and description; keeps its buffers.
pub struct OrbExtractor {
    orb: Ptr<ORB>,
    keypoints: Vector<KeyPoint>,
    raw: Mat,
}

impl OrbExtractor {
    /// An ORB extractor with `options`.
    pub fn new(options: &OrbOptions) -> Result<Self, VisionError> {
        let orb = ORB::create(
            options.features,
            options.scale_factor,
            options.levels,
            options.edge_threshold,
            0,
            2,
            ORB_ScoreType::HARRIS_SCORE,
            31,
            options.fast_threshold,
        )
        .context("creating the ORB extractor")?;
        Ok(Self {
            orb,
            keypoints: Vector::new(),
            raw: Mat::default(),
        })
    }

    /// Detects and describes points in `image` into `out`.
    pub fn extract(
        &mut self,
        image: &GrayImage,
        out: &mut PointFeatures,
    ) -> Result<(), VisionError> {
        self.keypoints.clear();
        let no_mask = Mat::default();
        self.orb
            .detect_and_compute(
                image.mat(),
                &no_mask,
                &mut self.keypoints,
                &mut self.raw,
                false,
            )
            .context("ORB detection")?;
        out.points.clear();
        out.points.extend(
            self.keypoints
                .iter()
                .map(|k| Point::new(f64::from(k.pt().x), f64::from(k.pt().y))),
        );
        out.levels.clear();
        out.levels.extend(
            self.keypoints
                .iter()
                .map(|k| u8::try_from(k.octave().max(0)).unwrap_or(u8::MAX)),
        );
        let row_bytes = usize::try_from(self.raw.cols()).unwrap_or(0);
        out.descriptors.reset(out.points.len(), row_bytes);
        out.descriptors.set_rows_from_mat(&self.raw)?;
        Ok(())
    }
}

/// A [`PointExtractor`] on a thread of its own ([`SideWorker`]): one image's points are found
/// there while the caller works on another, and two images' points can be matched there
/// too. The inputs are copied into the worker's buffers (reused from frame to frame) and
/// the results come back in buffers that are swapped, not reallocated.
pub struct OrbWorker {
    worker: SideWorker<OrbJob>,
}

/// What travels to the worker and back.
struct OrbJob {
    task: OrbTask,
    extractor: PointExtractor,
    image: Option<GrayImage>,
    points: PointFeatures,
    stereo: StereoJob,
    result: Result<(), VisionError>,
}

/// What the worker is to do with its job.
#[derive(Debug, Clone, Copy)]
enum OrbTask {
    /// Find the points of `image`.
    Extract,
    /// Match the stereo job's points.
    MatchStereo,
}

/// A stereo matching of points: copies of the two images' points, the matcher and its
/// settings, and the matches.
#[derive(Default)]
struct StereoJob {
    left: PointFeatures,
    right: PointFeatures,
    matcher: PointMatcher,
    gates: AppearanceGates,
    min_ratio: f64,
    matches: Vec<FeatureMatch>,
    /// How long the matching took, milliseconds.
    ms: f64,
}

impl OrbWorker {
    /// A worker with its own extractor made from `options`.
    pub fn new(options: &OrbOptions) -> Result<Self, VisionError> {
        let job = OrbJob {
            task: OrbTask::Extract,
            extractor: PointExtractor::new(options)?,
            image: None,
            points: PointFeatures::default(),
            stereo: StereoJob::default(),
            result: Ok(()),
        };
        // (Named for its main work, the right image's corners; it matches the stereo pair's
        // points too.)
        let worker = SideWorker::new("orb-right", job, |job: &mut OrbJob| {
            job.result = match (job.task, &job.image) {
                (OrbTask::Extract, Some(image)) => job.extractor.extract(image, &mut job.points),
                (OrbTask::Extract, None) => Ok(()),
                (OrbTask::MatchStereo, _) => {
                    let started = std::time::Instant::now();
                    let stereo = &mut job.stereo;
                    stereo.matcher.match_points(
                        MatchCase::Stereo,
                        &stereo.left,
                        &stereo.right,
                        &stereo.gates,
                        stereo.min_ratio,
                        &mut stereo.matches,
                    );
                    stereo.ms = started.elapsed().as_secs_f64() * 1e3;
                    Ok(())
                }
            };
        })?;
        Ok(Self { worker })
    }

    /// Finds `image`'s points into `out` on the worker while `here` runs on the calling
    /// thread; returns both outcomes once both are done.
    pub fn extract_while<R>(
        &mut self,
        image: &GrayImage,
        out: &mut PointFeatures,
        here: impl FnOnce() -> R,
    ) -> (Result<(), VisionError>, R) {
        let handed = self.worker.job().and_then(|job| {
            job.task = OrbTask::Extract;
            copy_image_into(&mut job.image, image)
        });
        if let Err(error) = handed {
            return (Err(error), here());
        }
        let (job, beside) = self.worker.run_while(here);
        let result = job.and_then(|job| {
            std::mem::swap(out, &mut job.points);
            std::mem::replace(&mut job.result, Ok(()))
        });
        (result, beside)
    }

    /// Replaces `out` with the stereo matches of `left`'s points among `right`'s
    /// ([`PointMatcher::match_points`] with `gates` and `min_ratio`), found on the worker
    /// while `here` runs on the calling thread; returns both outcomes once both are done
    /// (the matching's: its milliseconds on the worker). `out` is left empty when the
    /// worker's thread is lost.
    pub fn match_stereo_while<R>(
        &mut self,
        [left, right]: [&PointFeatures; 2],
        gates: &AppearanceGates,
        min_ratio: f64,
        out: &mut Vec<FeatureMatch>,
        here: impl FnOnce() -> R,
    ) -> (Result<f64, VisionError>, R) {
        out.clear();
        match self.worker.job() {
            Ok(job) => {
                job.task = OrbTask::MatchStereo;
                job.stereo.left.copy_from(left);
                job.stereo.right.copy_from(right);
                job.stereo.gates = *gates;
                job.stereo.min_ratio = min_ratio;
            }
            Err(error) => return (Err(error), here()),
        }
        let (job, beside) = self.worker.run_while(here);
        let result = job.and_then(|job| {
            std::mem::swap(out, &mut job.stereo.matches);
            std::mem::replace(&mut job.result, Ok(())).map(|()| job.stereo.ms)
        });
        (result, beside)
    }
}
