//! A thread kept for its owner's life, for work that runs beside the caller's own: the
//! right image's side of a stereo step while the caller does the left's.

use crate::{GrayImage, VisionError};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

/// The work a [`SideWorker`] does on its job.
type Work<J> = Box<dyn FnMut(&mut J) + Send>;

/// One kind of work on a job of its own (the work's state and buffers), done on a thread
/// started once instead of once per frame, or on the caller's thread after the caller's
/// own part ([`SideWorker::inline`]), with the same calls. The job travels to the thread and
/// comes back, so nothing is borrowed across threads and, once the job's buffers are warm,
/// nothing is allocated per call.
pub struct SideWorker<J: Send + 'static> {
    name: &'static str,
    /// The job between calls (`None` only after the thread was lost with it).
    job: Option<J>,
    place: Place<J>,
}

/// Where the work runs.
enum Place<J> {
    /// On the caller's thread, after the caller's part.
    Inline(Work<J>),
    /// On a thread of its own.
    Thread {
        jobs: Option<SyncSender<J>>,
        done: Receiver<J>,
        thread: Option<JoinHandle<()>>,
    },
}

impl<J: Send + 'static> SideWorker<J> {
    /// Starts the thread `name`, which runs `work` on `job` each time it is handed it.
    pub fn new(
        name: &'static str,
        job: J,
        mut work: impl FnMut(&mut J) + Send + 'static,
    ) -> Result<Self, VisionError> {
        let (jobs, inbox) = sync_channel::<J>(1);
        let (outbox, done) = sync_channel::<J>(1);
        let thread = std::thread::Builder::new()
            .name(name.to_string())
            .spawn(move || {
                for mut job in inbox {
                    work(&mut job);
                    if outbox.send(job).is_err() {
                        break;
                    }
                }
            })
            .map_err(|error| VisionError::Worker {
                what: name,
                reason: format!("cannot start the thread: {error}"),
            })?;
        Ok(Self {
            name,
            job: Some(job),
            place: Place::Thread {
                jobs: Some(jobs),
                done,
                thread: Some(thread),
            },
        })
    }

    /// The same work without a thread: [`SideWorker::run_while`] runs it after the
    /// caller's part, on the caller's thread.
    pub fn inline(name: &'static str, job: J, work: impl FnMut(&mut J) + Send + 'static) -> Self {
        Self {
            name,
            job: Some(job),
            place: Place::Inline(Box::new(work)),
        }
    }

    /// The job, between calls: to hand it its input, or take its output.
    pub fn job(&mut self) -> Result<&mut J, VisionError> {
        let name = self.name;
        self.job.as_mut().ok_or_else(|| lost(name))
    }

    /// Runs the work on the job beside `here` (on the worker's thread while `here` runs on
    /// the calling thread, or after it inline); returns the job, worked on, and `here`'s
    /// result once both are done. A panic in the work is passed on to the caller.
    pub fn run_while<R>(&mut self, here: impl FnOnce() -> R) -> (Result<&mut J, VisionError>, R) {
        let Some(mut job) = self.job.take() else {
            return (Err(lost(self.name)), here());
        };
        let beside = match &mut self.place {
            Place::Inline(work) => {
                let beside = here();
                work(&mut job);
                self.job = Some(job);
                beside
            }
            Place::Thread {
                jobs, done, thread, ..
            } => {
                let sent = jobs.as_ref().is_some_and(|jobs| jobs.send(job).is_ok());
                let beside = here();
                match sent.then(|| done.recv().ok()).flatten() {
                    Some(job) => self.job = Some(job),
                    None => {
                        // The thread has ended: pass its panic on, or say it stopped.
                        *jobs = None;
                        if let Some(Err(panic)) = thread.take().map(JoinHandle::join) {
                            std::panic::resume_unwind(panic);
                        }
                    }
                }
                beside
            }
        };
        (self.job(), beside)
    }
}

impl<J: Send + 'static> Drop for SideWorker<J> {
    fn drop(&mut self) {
        if let Place::Thread { jobs, thread, .. } = &mut self.place {
            // Closing the job channel ends the thread's loop.
            *jobs = None;
            if let Some(thread) = thread.take() {
                let _ = thread.join();
            }
        }
    }
}

fn lost(name: &'static str) -> VisionError {
    VisionError::Worker {
        what: name,
        reason: "its thread has stopped".to_string(),
    }
}

/// Makes `slot` a copy of `image`, reusing its buffer when there is one of the same size.
pub fn copy_image_into(slot: &mut Option<GrayImage>, image: &GrayImage) -> Result<(), VisionError> {
    match slot {
        Some(copy) => copy.copy_from(image),
        None => {
            *slot = Some(image.clone());
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn double(job: &mut [u32; 3]) {
        job.iter_mut().for_each(|x| *x *= 2);
    }

    #[test]
    fn the_job_comes_back_worked_on_beside_the_callers_work_threaded_or_inline() {
        let threaded = SideWorker::new("doubler", [1, 2, 3], double);
        let threaded = threaded.unwrap_or_else(|e| panic!("{e}"));
        for mut worker in [threaded, SideWorker::inline("doubler", [1, 2, 3], double)] {
            for round in 0..3 {
                let (job, here) = worker.run_while(|| round + 10);
                assert!(job.is_ok());
                assert_eq!(here, round + 10);
            }
            assert_eq!(worker.job().ok().copied(), Some([8, 16, 24]));
        }
    }

    #[test]
    fn a_panic_in_the_work_reaches_the_caller() {
        let mut worker = SideWorker::new("panicker", 1_u32, |job: &mut u32| {
            assert!(*job < 5, "job {job} too large");
        })
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(worker.run_while(|| ()).0.ok().copied(), Some(1));
        if let Ok(job) = worker.job() {
            *job = 7;
        }
        let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let _ = worker.run_while(|| ());
        }));
        let message = caught
            .err()
            .and_then(|p| p.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        assert_eq!(message, "job 7 too large");
        // The job went with the thread: later calls say so instead of panicking again.
        let (job, ()) = worker.run_while(|| ());
        assert!(job.err().is_some_and(|e| e.to_string().contains("stopped")));
    }
}
