//! The right image's half of a stage's per-frame work (the detector's detection, the
//! matcher's LBD description), done on a thread of its own while the stage does the left
//! image's half, or after it on the stage's thread (`detect_sides_in_parallel = false`).

use linetrack_vision::{GrayImage, SideWorker, VisionError, copy_image_into};

/// The right side's state (its detector or describer and buffers), the copy of the right
/// image it works on, and the result of its last run.
struct RightJob<S, E> {
    state: S,
    image: Option<GrayImage>,
    result: Result<(), E>,
}

/// Work on each frame's right image beside the caller's on the left one.
pub struct RightImageWorker<S: Send + 'static, E: Send + 'static> {
    worker: SideWorker<RightJob<S, E>>,
}

impl<S: Send + 'static, E: Send + 'static> RightImageWorker<S, E> {
    /// `work` on `state` and each right image: on the thread `name` when `parallel`, else
    /// after the caller's part on the caller's thread.
    pub fn new(
        name: &'static str,
        parallel: bool,
        state: S,
        mut work: impl FnMut(&mut S, &GrayImage) -> Result<(), E> + Send + 'static,
    ) -> Result<Self, VisionError> {
        let job = RightJob {
            state,
            image: None,
            result: Ok(()),
        };
        let run = move |job: &mut RightJob<S, E>| {
            job.result = match &job.image {
                Some(image) => work(&mut job.state, image),
                None => Ok(()),
            };
        };
        let worker = if parallel {
            SideWorker::new(name, job, run)?
        } else {
            SideWorker::inline(name, job, run)
        };
        Ok(Self { worker })
    }

    /// The right side's state between frames (to warm it up, to swap buffers in and out).
    pub fn state(&mut self) -> Result<&mut S, VisionError> {
        Ok(&mut self.worker.job()?.state)
    }

    /// Runs the work on a copy of `right` while `left` runs here; returns the right side's
    /// state, the right side's result and the left side's.
    pub fn run_while<R>(
        &mut self,
        right: &GrayImage,
        left: impl FnOnce() -> R,
    ) -> Result<(&mut S, Result<(), E>, R), VisionError> {
        copy_image_into(&mut self.worker.job()?.image, right)?;
        let (job, left_done) = self.worker.run_while(left);
        let job = job?;
        let right_done = std::mem::replace(&mut job.result, Ok(()));
        Ok((&mut job.state, right_done, left_done))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_right_image_is_worked_on_beside_the_left_in_both_modes_and_errors_come_back() {
        for parallel in [true, false] {
            let mut worker = RightImageWorker::new(
                "test-right",
                parallel,
                Vec::<u8>::new(),
                |seen: &mut Vec<u8>, image: &GrayImage| {
                    let first = image
                        .pixels()
                        .and_then(|p| p.first().copied())
                        .unwrap_or_default();
                    seen.push(first);
                    if first == 0 { Err("black") } else { Ok(()) }
                },
            )
            .unwrap_or_else(|e| panic!("{e}"));
            let image = |value: u8| {
                GrayImage::from_pixels(4, 2, &[value; 8], "test").unwrap_or_else(|e| panic!("{e}"))
            };
            let (seen, right, left) = worker
                .run_while(&image(7), || "left")
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(
                (seen.as_slice(), right, left),
                ([7].as_slice(), Ok(()), "left")
            );
            let (seen, right, _) = worker
                .run_while(&image(0), || ())
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!((seen.as_slice(), right), ([7, 0].as_slice(), Err("black")));
            // The next run starts with no error of the last one's.
            let (_, right, _) = worker
                .run_while(&image(9), || ())
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(right, Ok(()));
            assert_eq!(worker.state().map(|s| s.clone()).ok(), Some(vec![7, 0, 9]));
        }
    }
}
