//! Segment matchers behind one trait: LBD (appearance) and ℓ1 (geometry).

use crate::{
    AppearanceGates, BinaryDescriptors, FeatureMatch, FrontendConfig, GrayImage, HammingMatcher,
    LbdExtractor, LbdOptions, MatcherKind, VisionError,
};
use linetrack_geometry::{self as geometry, MatchCase, Segment, SegmentFeatures};
use linetrack_l1_matcher::{GrayView, L1Matcher, Match, SegmentProfiles};

/// Segments of one image and whatever a matcher computed on them.
#[derive(Debug, Clone, Default)]
pub struct LineFeatures {
    /// The detected segments.
    pub segments: Vec<Segment>,
    /// Appearance descriptors (LBD); empty for the geometric matcher.
    pub descriptors: BinaryDescriptors,
    /// Intensity profiles across the segments (the geometric matcher's photometric
    /// check); empty for LBD.
    pub profiles: SegmentProfiles,
}

impl LineFeatures {
    /// Empties every field, keeping the memory for the next image's.
    pub fn clear(&mut self) {
        self.segments.clear();
        self.descriptors.reset(0, 0);
        self.profiles.clear();
    }
}

/// A segment matcher.
pub trait SegmentMatcher: Send {
    /// Short name: `lbd` or `l1`.
    fn name(&self) -> &'static str;

    /// Computes what matching needs from the image: LBD descriptors, or the ℓ1 matcher's
    /// intensity profiles. Each matcher fills only its own field of `features`, so one set
    /// of features can be described by both.
    fn describe(
        &mut self,
        image: &GrayImage,
        features: &mut LineFeatures,
    ) -> Result<(), VisionError>;

    /// [`SegmentMatcher::describe`] for the right image of a stereo pair whose left
    /// segments are `left`, for stereo matching only: a matcher may leave out the segments
    /// that no left one could be matched with, as long as the stereo matches stay the same.
    /// LBD does (their descriptors would never be compared); by default all are described.
    fn describe_stereo_right(
        &mut self,
        image: &GrayImage,
        _left: &[Segment],
        features: &mut LineFeatures,
    ) -> Result<(), VisionError> {
        self.describe(image, features)
    }

    /// Whether frame-to-frame matching gains from being given the last frame's segments
    /// where the camera's motion predicts them rather than where they were.
    fn matches_predicted_positions(&self) -> bool {
        false
    }

    /// Replaces `out` with the matches between the two images' segments.
    fn match_lines(
        &mut self,
        case: MatchCase,
        first: &LineFeatures,
        second: &LineFeatures,
        out: &mut Vec<FeatureMatch>,
    );

    /// Frame to frame, `first`'s segments placed where the camera's motion predicts them:
    /// `predicted[i]` says whether segment `i` was moved so (the others are where they were
    /// seen). By default the same as [`SegmentMatcher::match_lines`].
    fn match_predicted(
        &mut self,
        first: &LineFeatures,
        _predicted: &[bool],
        second: &LineFeatures,
        out: &mut Vec<FeatureMatch>,
    ) {
        self.match_lines(MatchCase::FrameToFrame, first, second, out);
    }
}

/// Builds the matcher `kind` from `config`.
pub fn create_segment_matcher(
    kind: MatcherKind,
    config: &FrontendConfig,
) -> Result<Box<dyn SegmentMatcher>, VisionError> {
    Ok(match kind {
        MatcherKind::Lbd => Box::new(LbdSegmentMatcher::new(config.lbd, config.appearance_gates)?),
        MatcherKind::L1 => Box::new(L1SegmentMatcher::new(config)?),
    })
}

/// LBD descriptors matched mutual-best with a ratio test, gated by the epipolar geometry
/// (stereo: shared rows, disparity range) or by the displacement (frame to frame).
pub struct LbdSegmentMatcher {
    extractor: LbdExtractor,
    hamming: HammingMatcher,
    options: LbdOptions,
    gates: AppearanceGates,
    first: Vec<Option<SegmentFeatures>>,
    second: Vec<Option<SegmentFeatures>>,
    /// Per right segment, whether some left segment passes the stereo gates with it.
    partnered: Vec<bool>,
}

impl LbdSegmentMatcher {
    /// An LBD matcher.
    pub fn new(options: LbdOptions, gates: AppearanceGates) -> Result<Self, VisionError> {
        Ok(Self {
            extractor: LbdExtractor::new()?,
            hamming: HammingMatcher::new(),
            options,
            gates,
            first: Vec::new(),
            second: Vec::new(),
            partnered: Vec::new(),
        })
    }
}

impl SegmentMatcher for LbdSegmentMatcher {
    fn name(&self) -> &'static str {
        "lbd"
    }

    /// Its displacement gate is then centred on the prediction, which keeps far look-alikes
    /// out of the ratio test.
    fn matches_predicted_positions(&self) -> bool {
        true
    }

    fn describe(
        &mut self,
        image: &GrayImage,
        features: &mut LineFeatures,
    ) -> Result<(), VisionError> {
        self.extractor
            .compute(image, &features.segments, &mut features.descriptors)
    }

    /// Describes only the right segments that pass the stereo gates with some left one:
    /// [`LbdSegmentMatcher::match_lines`] never compares the others' descriptors, so the
    /// stereo matches are the ones a full description gives (tested on EuRoC frames).
    fn describe_stereo_right(
        &mut self,
        image: &GrayImage,
        left: &[Segment],
        features: &mut LineFeatures,
    ) -> Result<(), VisionError> {
        segment_features(left, &mut self.first);
        segment_features(&features.segments, &mut self.second);
        let (gates, lefts) = (self.gates, &self.first);
        self.partnered.clear();
        self.partnered.extend(self.second.iter().map(|b| {
            b.as_ref().is_some_and(|b| {
                lefts
                    .iter()
                    .flatten()
                    .any(|a| passes_stereo_gates(&gates, a, b))
            })
        }));
        let partnered = &self.partnered;
        self.extractor.compute_some(
            image,
            &features.segments,
            |k| partnered[k],
            &mut features.descriptors,
        )
    }

    fn match_lines(
        &mut self,
        case: MatchCase,
        first: &LineFeatures,
        second: &LineFeatures,
        out: &mut Vec<FeatureMatch>,
    ) {
        segment_features(&first.segments, &mut self.first);
        segment_features(&second.segments, &mut self.second);
        let gates = self.gates;
        let (a_all, b_all) = (&self.first, &self.second);
        let admit = |i: usize, j: usize| {
            let (Some(a), Some(b)) = (&a_all[i], &b_all[j]) else {
                return false;
            };
            match case {
                MatchCase::Stereo => passes_stereo_gates(&gates, a, b),
                MatchCase::FrameToFrame => {
                    (a.mid - b.mid).norm()
                        <= gates.max_displacement_px + 0.5 * a.length.max(b.length)
                }
            }
        };
        self.hamming.match_mutual(
            &first.descriptors,
            &second.descriptors,
            self.options.min_distance_ratio,
            admit,
            out,
        );
    }
}

/// The geometry of each segment (`None` for a degenerate one), in `into`.
fn segment_features(segments: &[Segment], into: &mut Vec<Option<SegmentFeatures>>) {
    into.clear();
    into.extend(segments.iter().map(|s| SegmentFeatures::new(s).ok()));
}

/// The stereo gates: left segment `a` and right segment `b` share rows and lie within the
/// disparity range.
fn passes_stereo_gates(gates: &AppearanceGates, a: &SegmentFeatures, b: &SegmentFeatures) -> bool {
    shares_rows(a, b, gates.min_row_overlap)
        && b.x_max >= a.x_min - gates.max_disparity_px
        && b.x_min <= a.x_max - gates.min_disparity_px
}

/// The row gate of stereo segments: their row extents overlap, by at least `min_overlap`
/// of their union.
fn shares_rows(a: &SegmentFeatures, b: &SegmentFeatures, min_overlap: f64) -> bool {
    let overlap = geometry::overlap(a, b, MatchCase::Stereo);
    overlap > 0.0 && overlap >= min_overlap
}

/// The geometric ℓ1 matcher behind the common trait.
pub struct L1SegmentMatcher {
    matcher: L1Matcher,
    scratch: Vec<Match>,
}

impl L1SegmentMatcher {
    /// An ℓ1 matcher with `config.l1`.
    pub fn new(config: &FrontendConfig) -> Result<Self, VisionError> {
        let matcher = L1Matcher::new(config.l1.clone()).map_err(|e| VisionError::Config {
            origin: "[l1]".to_string(),
            message: e.to_string(),
        })?;
        Ok(Self {
            matcher,
            scratch: Vec::new(),
        })
    }
}

impl SegmentMatcher for L1SegmentMatcher {
    fn name(&self) -> &'static str {
        "l1"
    }

    fn describe(
        &mut self,
        image: &GrayImage,
        features: &mut LineFeatures,
    ) -> Result<(), VisionError> {
        let (width, height) = (image.width() as usize, image.height() as usize);
        let view = match image.pixels() {
            Some(pixels) => Some(GrayView::new(pixels, width, height, width).map_err(|e| {
                VisionError::RawSize {
                    origin: image.origin().to_string(),
                    len: e.len,
                    width,
                    height,
                }
            })?),
            None => None,
        };
        self.matcher
            .describe(view, &features.segments, &mut features.profiles);
        Ok(())
    }

    /// Its gates and flow filter are then re-centred on the prediction
    /// ([`L1Matcher::match_predicted`]).
    fn matches_predicted_positions(&self) -> bool {
        true
    }

    fn match_lines(
        &mut self,
        case: MatchCase,
        first: &LineFeatures,
        second: &LineFeatures,
        out: &mut Vec<FeatureMatch>,
    ) {
        self.matcher.match_with_profiles(
            case,
            &first.segments,
            &second.segments,
            Some((&first.profiles, &second.profiles)),
            &mut self.scratch,
        );
        self.hand_over(out);
    }

    fn match_predicted(
        &mut self,
        first: &LineFeatures,
        predicted: &[bool],
        second: &LineFeatures,
        out: &mut Vec<FeatureMatch>,
    ) {
        self.matcher.match_predicted(
            &first.segments,
            predicted,
            &second.segments,
            &mut self.scratch,
        );
        self.hand_over(out);
    }
}

impl L1SegmentMatcher {
    /// Replaces `out` with the last call's matches.
    fn hand_over(&self, out: &mut Vec<FeatureMatch>) {
        out.clear();
        out.extend(self.scratch.iter().map(|m| FeatureMatch {
            query: m.query,
            train: m.train,
            distance: m.error,
        }));
    }
}
