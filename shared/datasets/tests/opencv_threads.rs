//! `opencv_on_calling_threads`, in a test binary of its own: it changes OpenCV's threading
//! for the whole process.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_datasets::{StereoSequence, opencv_on_calling_threads};

fn threads_of_this_process() -> usize {
    std::fs::read_dir("/proc/self/task").unwrap().count()
}

/// The real EuRoC excerpt needs rectifying: OpenCV splits building the maps and remapping
/// each frame over its thread pool, whose threads run at the priority of the thread that
/// started them. After the call, opening the sequence and reading it ahead starts no thread
/// but the reading one.
#[test]
fn opening_and_reading_rectified_frames_starts_only_the_reading_thread() {
    let before = threads_of_this_process();
    opencv_on_calling_threads().unwrap();
    assert_eq!(opencv::core::get_num_threads().unwrap(), 1);
    let dir = linetrack_test_data::euroc_dir().unwrap_or_else(|e| panic!("{e}"));
    let sequence = StereoSequence::open_euroc(&dir).unwrap();
    assert_eq!(threads_of_this_process(), before);
    // The last frames, read to the end: the reading thread is done before the process
    // ends (OpenCV must not be torn down under it). It is still reading when the first
    // frame arrives (it holds two ahead); after the last it may already be gone.
    let mut read = 0;
    for frame in sequence.into_stream(88, 2) {
        frame.unwrap();
        let threads = threads_of_this_process();
        if read == 0 {
            assert_eq!(threads, before + 1);
        } else {
            assert!(threads <= before + 1, "{threads} threads, {before} before");
        }
        read += 1;
    }
    assert_eq!(read, 7);
}
