//! Once warm, the pose estimator's hot path (`MotionTracker::prepare` then
//! `update_prepared`, as the pose stage calls them) allocates no point list, descriptor
//! table, landmark list or observation list: it reuses those of the frames before. A global
//! allocator in this test binary counts the large allocations (Rust's heap: OpenCV's own
//! buffers are not seen here) while 24 real EuRoC frames are tracked.

#![allow(clippy::unwrap_used)] // a test on fixed inputs: failing loudly is right

use linetrack_datasets::StereoSequence;
use linetrack_odometry::{FrameStats, MatchedLines, MotionTracker, OdometryConfig, Preparation};
use linetrack_test_data::CountingAllocator;

/// Allocations at least this large are counted: a frame's 1500 points take 24 KiB, their
/// descriptors 48 KiB.
const LARGE_BYTES: usize = 16 * 1024;

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator::new(LARGE_BYTES);

/// Large allocations per frame while 24 real EuRoC frames are tracked, each prepared with
/// its point work (as the pose stage does when no frame waits) or without it (the update
/// then does it, as when frames queue up).
fn allocations_per_frame(preparation: Preparation) -> Vec<usize> {
    let dir = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
    let sequence = StereoSequence::open(&dir).unwrap();
    let mut tracker = MotionTracker::new(OdometryConfig::default(), sequence.rig).unwrap();
    let no_lines = MatchedLines {
        left: &[],
        right: &[],
        stereo: &[],
        tracked: Some(&[]),
    };
    let mut per_frame = Vec::new();
    for index in 0..24 {
        let frame = sequence.load_frame(index).unwrap();
        let before = ALLOCATOR.count();
        let prepared = tracker
            .prepare(&frame.left, &frame.right, preparation)
            .unwrap();
        let images = Some(((&frame.left, &frame.right), prepared));
        let result = tracker
            .update_prepared(images, no_lines, FrameStats::default())
            .unwrap();
        per_frame.push(ALLOCATOR.count() - before);
        if index > 0 {
            // Tracked on its points: the frames went through the whole path.
            assert!(result.stats.observations[0] > 100, "{:?}", result.stats);
        }
    }
    per_frame
}

#[test]
fn a_warm_tracker_allocates_no_large_list_per_frame() {
    // (One test: the counter is global, tests in parallel would count each other.)
    for preparation in [Preparation::CornersAndPoints, Preparation::Corners] {
        let per_frame = allocations_per_frame(preparation);
        // The first frames fill the spares and grow the lists to their size (and show that
        // the counter counts); the kept lists take turns, so warming up spans a few frames.
        assert!(per_frame[0] > 0, "{preparation:?}: {per_frame:?}");
        assert_eq!(per_frame[8..], [0; 16], "{preparation:?}: {per_frame:?}");
    }
}
