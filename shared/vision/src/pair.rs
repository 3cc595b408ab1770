//! Detector × matcher on an image pair, timed per step: what the tools and the
//! evaluation run for one stereo pair or one pair of consecutive frames.

use crate::{
    DetectorKind, FeatureMatch, FrontendConfig, GrayImage, LineDetector, LineFeatures, MatcherKind,
    SegmentMatcher, VisionError,
};
use crate::{create_detector, create_segment_matcher};
use linetrack_geometry::MatchCase;
use serde::Serialize;
use std::time::Instant;

/// Milliseconds of each step of [`LinePairMatcher::run`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct PairTimings {
    /// Detection in the first and second image.
    pub detect_ms: [f64; 2],
    /// Description (LBD; nothing for ℓ1) in the first and second image.
    pub describe_ms: [f64; 2],
    /// Matching.
    pub match_ms: f64,
}

/// What one pair gave.
#[derive(Debug, Clone, Default)]
pub struct PairResult {
    /// Segments (and descriptors) of the first image.
    pub first: LineFeatures,
    /// Segments (and descriptors) of the second image.
    pub second: LineFeatures,
    /// The matches.
    pub matches: Vec<FeatureMatch>,
    /// Step times.
    pub timings: PairTimings,
}

/// A detector and a segment matcher, chosen by name.
pub struct LinePairMatcher {
    detector: Box<dyn LineDetector>,
    matcher: Box<dyn SegmentMatcher>,
}

fn timed<T>(ms: &mut f64, step: impl FnOnce() -> T) -> T {
    let started = Instant::now();
    let out = step();
    *ms = started.elapsed().as_secs_f64() * 1e3;
    out
}

impl LinePairMatcher {
    /// `detector` + `matcher` with their options from `config`.
    pub fn new(
        detector: DetectorKind,
        matcher: MatcherKind,
        config: &FrontendConfig,
    ) -> Result<Self, VisionError> {
        Ok(Self {
            detector: create_detector(detector, config)?,
            matcher: create_segment_matcher(matcher, config)?,
        })
    }

    /// `lsd+l1` and the like.
    pub fn name(&self) -> String {
        format!("{}+{}", self.detector.name(), self.matcher.name())
    }

    /// Matches already detected and described features (e.g. the left images of two
    /// frames, each from its own stereo run); returns the milliseconds it took.
    pub fn match_features(
        &mut self,
        case: MatchCase,
        first: &LineFeatures,
        second: &LineFeatures,
        out: &mut Vec<crate::FeatureMatch>,
    ) -> f64 {
        let mut ms = 0.0;
        timed(&mut ms, || {
            self.matcher.match_lines(case, first, second, out)
        });
        ms
    }

    /// Detects, describes and matches `first` against `second`.
    pub fn run(
        &mut self,
        case: MatchCase,
        first: &GrayImage,
        second: &GrayImage,
    ) -> Result<PairResult, VisionError> {
        let mut out = PairResult::default();
        let t = &mut out.timings;
        timed(&mut t.detect_ms[0], || {
            self.detector.detect(first, &mut out.first.segments)
        })?;
        timed(&mut t.detect_ms[1], || {
            self.detector.detect(second, &mut out.second.segments)
        })?;
        timed(&mut t.describe_ms[0], || {
            self.matcher.describe(first, &mut out.first)
        })?;
        timed(&mut t.describe_ms[1], || {
            self.matcher.describe(second, &mut out.second)
        })?;
        timed(&mut t.match_ms, || {
            self.matcher
                .match_lines(case, &out.first, &out.second, &mut out.matches)
        });
        Ok(out)
    }
}
