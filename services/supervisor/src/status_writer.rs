//! `status.json` written off the supervision loop. Writing it renames a new file over the
//! old one, and the kernel may hold that rename until the old file's pages are written back
//! (seen for over a second under load): on the loop, that stall stopped hang detection and
//! killed healthy stages as silent. The loop hands each status to [`StatusWriter::offer`],
//! which never touches the disk: a thread of its own writes the latest one (a newer status
//! replaces one not yet written), and the first failed write comes back to the loop through
//! [`StatusWriter::take_error`].

use crate::status::LiveStatus;
use linetrack_run_record::RecordError;
use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;

/// What writes one status (the run folder's `status.json`, or a test's sink).
type Write = Box<dyn FnMut(&LiveStatus) -> Result<(), RecordError> + Send>;

/// What the loop and the writer share.
#[derive(Default)]
struct Slot {
    /// The latest status not yet taken by the writer.
    pending: Option<LiveStatus>,
    /// The writer is writing a status it took.
    writing: bool,
    /// No more statuses come: write the pending one and end.
    closed: bool,
    /// The first failed write not yet taken by the loop.
    error: Option<RecordError>,
}

#[derive(Default)]
struct Shared {
    slot: Mutex<Slot>,
    /// Signalled on every change of the slot.
    changed: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Slot> {
        // The writer holds the lock only to move values; a panic there leaves it whole.
        self.slot.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn wait<'a>(&self, guard: MutexGuard<'a, Slot>) -> MutexGuard<'a, Slot> {
        self.changed
            .wait(guard)
            .unwrap_or_else(PoisonError::into_inner)
    }
}

/// The thread that writes `status.json` for the supervision loop.
pub(crate) struct StatusWriter {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl StatusWriter {
    /// A writer of `run_dir`'s `status.json` (whole or not at all, [`LiveStatus::write`]).
    pub(crate) fn start(run_dir: PathBuf) -> std::io::Result<Self> {
        Self::with(Box::new(move |status: &LiveStatus| status.write(&run_dir)))
    }

    /// A writer that hands each status to `write` on its own thread.
    fn with(mut write: Write) -> std::io::Result<Self> {
        let shared = Arc::new(Shared::default());
        let theirs = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("status-writer".to_string())
            .spawn(move || {
                let mut slot = theirs.lock();
                loop {
                    let Some(status) = slot.pending.take() else {
                        if slot.closed {
                            return;
                        }
                        slot = theirs.wait(slot);
                        continue;
                    };
                    slot.writing = true;
                    drop(slot);
                    let written = write(&status);
                    slot = theirs.lock();
                    slot.writing = false;
                    if let Err(e) = written {
                        slot.error.get_or_insert(e);
                    }
                    theirs.changed.notify_all();
                }
            })?;
        Ok(Self {
            shared,
            thread: Some(thread),
        })
    }

    /// Hands `status` to the writer without waiting for the disk; it replaces a status
    /// not yet written.
    pub(crate) fn offer(&self, status: LiveStatus) {
        self.shared.lock().pending = Some(status);
        self.shared.changed.notify_all();
    }

    /// The first write that failed since the last call, if one did.
    pub(crate) fn take_error(&self) -> Option<RecordError> {
        self.shared.lock().error.take()
    }

    /// Writes the status still pending, ends the thread and returns a failed write not
    /// yet taken. Later calls return `None`.
    pub(crate) fn close(&mut self) -> Option<RecordError> {
        let thread = self.thread.take()?;
        self.shared.lock().closed = true;
        self.shared.changed.notify_all();
        if thread.join().is_err() {
            tracing::error!("the status.json writer panicked: status.json may be stale");
        }
        self.take_error()
    }

    /// Waits until every offered status is written (tests: no sleeping on the thread).
    #[cfg(test)]
    fn settle(&self) {
        let mut slot = self.shared.lock();
        while slot.pending.is_some() || slot.writing {
            slot = self.shared.wait(slot);
        }
    }
}

impl Drop for StatusWriter {
    fn drop(&mut self) {
        if let Some(e) = self.close() {
            tracing::error!("status.json: {}", linetrack_run_record::full_message(&e));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_run_record::RunEnd;
    use linetrack_test_data::Scratch;
    use std::sync::mpsc;

    fn status(frames: usize) -> LiveStatus {
        LiveStatus {
            run_id: "0000abcd".to_string(),
            ipc_prefix: "lt_test".to_string(),
            ipc_root: None,
            supervisor_pid: 1,
            stages: Vec::new(),
            detector: "fld".to_string(),
            frames,
            state: RunEnd::Running,
            reason: None,
        }
    }

    fn read(dir: &std::path::Path) -> LiveStatus {
        let text = std::fs::read_to_string(dir.join("status.json")).unwrap();
        serde_json::from_str(&text).unwrap()
    }

    #[test]
    fn the_last_status_is_on_disk_after_close() {
        let dir = Scratch::new("supervisor", "status-writer-close");
        let mut writer = StatusWriter::start(dir.to_path_buf()).unwrap();
        for frames in 0..50 {
            writer.offer(status(frames));
        }
        assert!(writer.close().is_none());
        assert_eq!(read(&dir).frames, 49);
        assert!(!dir.join("status.json.tmp").exists());
        assert!(writer.close().is_none(), "a second close is a no-op");
    }

    #[test]
    fn a_newer_status_replaces_one_not_yet_written() {
        let (started_tx, started) = mpsc::channel();
        let (release, released) = mpsc::channel::<()>();
        let (written_tx, written) = mpsc::channel();
        let mut writer = StatusWriter::with(Box::new(move |s: &LiveStatus| {
            started_tx.send(s.frames).unwrap();
            released.recv().unwrap();
            written_tx.send(s.frames).unwrap();
            Ok(())
        }))
        .unwrap();
        writer.offer(status(1));
        // The writer holds frame 1 (blocked on the disk): 2 and 3 wait, 3 replaces 2.
        assert_eq!(started.recv().unwrap(), 1);
        writer.offer(status(2));
        writer.offer(status(3));
        release.send(()).unwrap();
        assert_eq!(started.recv().unwrap(), 3);
        release.send(()).unwrap();
        assert!(writer.close().is_none());
        assert_eq!(written.try_iter().collect::<Vec<_>>(), [1, 3]);
    }

    #[test]
    fn offering_does_not_wait_for_a_blocked_write() {
        let (started_tx, started) = mpsc::channel();
        let (release, released) = mpsc::channel::<()>();
        let mut writer = StatusWriter::with(Box::new(move |s: &LiveStatus| {
            started_tx.send(s.frames).unwrap();
            released.recv().unwrap();
            Ok(())
        }))
        .unwrap();
        writer.offer(status(1));
        assert_eq!(started.recv().unwrap(), 1);
        // The write of 1 cannot end until released: these return regardless.
        for frames in 2..100 {
            writer.offer(status(frames));
            assert!(writer.take_error().is_none());
        }
        release.send(()).unwrap();
        assert_eq!(started.recv().unwrap(), 99);
        release.send(()).unwrap();
        assert!(writer.close().is_none());
    }

    #[test]
    fn a_failed_write_comes_back_naming_the_file() {
        // A run folder that is a file: every write fails (whoever runs the test).
        let dir = Scratch::new("supervisor", "status-writer-error");
        let not_a_dir = dir.join("plain-file");
        std::fs::write(&not_a_dir, b"x").unwrap();
        let mut writer = StatusWriter::start(not_a_dir.clone()).unwrap();
        writer.offer(status(1));
        writer.settle();
        let error = writer.take_error().expect("the write failed");
        let message = linetrack_run_record::full_message(&error);
        assert!(
            message.contains(&not_a_dir.join("status.json").display().to_string()),
            "{message}"
        );
        assert!(writer.take_error().is_none(), "taken once");
        // A failure at the last write is returned by close.
        writer.offer(status(2));
        assert!(writer.close().is_some());
    }
}
