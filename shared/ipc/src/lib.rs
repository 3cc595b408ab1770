//! The pipeline's transport behind one API, in two implementations:
//!
//! - **shared memory** ([`Bus::shared_memory`]): iceoryx2 publish-subscribe between
//!   processes. A publisher writes a message once into a loaned shared-memory sample; every
//!   subscriber reads that same memory in place ([`Received`] derefs into it). Publishers
//!   wake their topic's consumers through one iceoryx2 event service per stage, on which
//!   each stage blocks ([`Wake::wait`]): no polling.
//! - **local** ([`Bus::local`]): crossbeam channels between threads of one process, with
//!   the same fan-out and wake-up semantics; the baseline that measures what IPC costs.
//!
//! Every message is a slice of [`Record`]s under a user header, itself a [`Record`]: a
//! topic's publishers and subscribers agree on both types (iceoryx2 checks them when a
//! port opens its service), e.g. [`linetrack_msgs::SegmentsHeader`] over `[SegmentRecord]`.

mod bus;
mod ports;
mod scope;

pub use bus::{Bus, LocalHub};
pub use ports::{Inlet, LocalPayload, Outlet, Received, Wake};
pub use scope::{Resources, Scope};

use iceoryx2::prelude::ZeroCopySend;
use std::fmt::Debug;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Transport errors; each names the service and what failed.
#[derive(Debug, thiserror::Error)]
pub enum IpcError {
    /// A service, port or node could not be created or opened.
    #[error("{what} for {service}: {message}")]
    Setup {
        /// What was being created.
        what: &'static str,
        /// The service.
        service: String,
        /// The cause.
        message: String,
    },
    /// Publishing, receiving or waiting failed.
    #[error("{what} on {service}: {message}")]
    Transfer {
        /// The operation.
        what: &'static str,
        /// The service.
        service: String,
        /// The cause.
        message: String,
    },
}

fn setup<'a>(what: &'static str, service: &'a str) -> impl FnOnce(String) -> IpcError + 'a {
    move |message| IpcError::Setup {
        what,
        service: service.to_string(),
        message,
    }
}

fn transfer<'a>(what: &'static str, service: &'a str) -> impl FnOnce(String) -> IpcError + 'a {
    move |message| IpcError::Transfer {
        what,
        service: service.to_string(),
        message,
    }
}

/// What a message carries: fixed layout, no pointers.
pub trait Record: Debug + Copy + Default + ZeroCopySend + Send + Sync + 'static {}

impl<T: Debug + Copy + Default + ZeroCopySend + Send + Sync + 'static> Record for T {}

/// A shutdown flag: set by SIGINT/SIGTERM or by the program itself.
#[derive(Debug, Clone, Default)]
pub struct Shutdown(Arc<AtomicBool>);

impl Shutdown {
    /// A flag that SIGINT and SIGTERM set.
    pub fn on_signals() -> Result<Self, std::io::Error> {
        let flag = Shutdown::default();
        for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
            signal_hook::flag::register(signal, Arc::clone(&flag.0))?;
        }
        Ok(flag)
    }

    /// Asks for shutdown.
    pub fn request(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// Whether shutdown was asked for.
    pub fn requested(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// Makes a write past the file size limit (`RLIMIT_FSIZE`, `ulimit -f`) fail with `EFBIG`
/// ("File too large") instead of killing the process: SIGXFSZ, whose default ends the
/// process, is caught and dropped. Every process that writes records calls this as it
/// starts (the stage runtime's `node_main`, the supervisor's `run`), so that the limit is
/// met like a full disk: the write's error names the file and the run's records-failed
/// path takes over.
pub fn survive_the_file_size_limit() -> Result<(), std::io::Error> {
    // A handler (not SIG_IGN, which would need `unsafe`) has the same effect on the write:
    // the kernel returns EFBIG either way; the flag is not read.
    signal_hook::flag::register(
        signal_hook::consts::SIGXFSZ,
        Arc::new(AtomicBool::new(false)),
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_root_too_long_for_a_socket_path_is_refused_naming_it() {
        let long = format!("/tmp/{}", "d".repeat(80));
        let err = super::Scope::with_prefix("linetrack_u1000_", "run")
            .with_root(std::path::PathBuf::from(&long))
            .config()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains(&long) && err.contains("too long") && err.contains("[ipc] root"),
            "{err}"
        );
    }

    use super::*;
    use crate::ports::WakeInner;
    use crate::scope::{SHM_DIR, lock_down_files};
    use linetrack_msgs::StageKind;
    use linetrack_msgs::{FrameHeader, SegmentRecord, SegmentsHeader};
    use linetrack_test_data::Scratch;
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    use std::path::Path;
    use std::time::Duration;

    #[test]
    fn a_scope_leaves_nothing_that_other_users_can_write() {
        let scratch = Scratch::new("ipc", "root");
        let root = scratch.join("iceoryx2");
        let scope = Scope {
            root: root.clone(),
            ..unique_scope("private")
        };
        let bus = Bus::shared_memory(&scope, "private").unwrap_or_else(|e| panic!("{e}"));
        let _outlet = bus
            .outlet::<SegmentRecord, SegmentsHeader>(linetrack_msgs::topics::SEGMENTS, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        let _inlet = bus
            .inlet::<SegmentRecord, SegmentsHeader>(linetrack_msgs::topics::SEGMENTS)
            .unwrap_or_else(|e| panic!("{e}"));
        let mode = |path: &Path| {
            std::fs::symlink_metadata(path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
                .mode()
        };
        assert_eq!(mode(&root) & 0o777, 0o700, "{}", root.display());
        let mut files = 0;
        for entry in std::fs::read_dir(SHM_DIR)
            .unwrap_or_else(|e| panic!("{e}"))
            .flatten()
        {
            if entry
                .file_name()
                .to_string_lossy()
                .starts_with(&scope.prefix)
            {
                files += 1;
                let path = entry.path();
                assert_eq!(
                    mode(&path) & 0o077,
                    0,
                    "{} is open to others",
                    path.display()
                );
            }
        }
        assert!(
            files > 0,
            "the bus made no shared memory under {}",
            scope.prefix
        );
    }

    #[test]
    fn another_users_file_in_the_namespace_is_named_and_open_files_are_tightened() {
        let dir = Scratch::new("ipc", "lockdown");
        let open = dir.join("lt_x_node.global_mgmt");
        std::fs::write(&open, b"0123").unwrap_or_else(|e| panic!("{e}"));
        std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o666))
            .unwrap_or_else(|e| panic!("{e}"));
        std::fs::write(dir.join("other_prefix"), b"").unwrap_or_else(|e| panic!("{e}"));
        let me = rustix::process::getuid().as_raw();
        assert_eq!(lock_down_files(&dir, "lt_x_", me), Ok(1));
        let mode = std::fs::metadata(&open)
            .unwrap_or_else(|e| panic!("{e}"))
            .mode();
        assert_eq!(mode & 0o777, 0o600);
        assert_eq!(lock_down_files(&dir, "lt_x_", me), Ok(0), "already tight");
        // Seen by another user, the same file is someone else's: refused, by name.
        let err = lock_down_files(&dir, "lt_x_", me.wrapping_add(1)).unwrap_err();
        assert!(
            err.contains("lt_x_node.global_mgmt") && err.contains(Scope::PREFIX_VAR),
            "{err}"
        );
    }

    #[test]
    fn a_root_folder_open_to_others_is_refused() {
        let dir = Scratch::new("ipc", "openroot");
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o777))
            .unwrap_or_else(|e| panic!("{e}"));
        let scope = Scope {
            root: dir.to_path_buf(),
            ..unique_scope("openroot")
        };
        let err = scope
            .config()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains(&dir.display().to_string()) && err.contains("other users"),
            "{err}"
        );
        // Beside the open folder, not in it: the link's own folder is private.
        let links = Scratch::new("ipc", "linkroot");
        let link = links.join("root");
        std::os::unix::fs::symlink(&dir, &link).unwrap_or_else(|e| panic!("{e}"));
        let err = Scope {
            root: link,
            ..unique_scope("linkroot")
        }
        .config()
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
        // This user's own link is followed; the folder it leads to is judged.
        assert!(
            err.contains(&dir.display().to_string()) && err.contains("other users"),
            "{err}"
        );
        // Another user's folder above the root (a `linetrack-<uid>` folder someone else made).
        if rustix::process::geteuid().as_raw() == 0 {
            let theirs = Scratch::new("ipc", "theirsroot");
            std::os::unix::fs::chown(&theirs, Some(65534), Some(65534))
                .unwrap_or_else(|e| panic!("{e}"));
            let err = Scope {
                root: theirs.join("iceoryx2"),
                ..unique_scope("theirsroot")
            }
            .config()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
            assert!(
                err.contains(&theirs.display().to_string()) && err.contains("user 65534"),
                "{err}"
            );
            assert!(!theirs.join("iceoryx2").exists());
        }
    }

    fn unique_scope(tag: &str) -> Scope {
        Scope::with_prefix(
            &format!("ltipc{}_", std::process::id()),
            &format!("{tag}{}", std::process::id()),
        )
    }

    fn round_trip(publisher_bus: &Bus, subscriber_bus: &Bus) {
        let mut inlet = subscriber_bus
            .inlet::<SegmentRecord, SegmentsHeader>(linetrack_msgs::topics::SEGMENTS)
            .unwrap_or_else(|e| panic!("{e}"));
        let wake = subscriber_bus
            .wake(StageKind::Matcher)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut outlet = publisher_bus
            .outlet::<SegmentRecord, SegmentsHeader>(linetrack_msgs::topics::SEGMENTS, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        let a = [SegmentRecord {
            endpoints: [1.0, 2.0, 3.0, 4.0],
        }];
        let b = [SegmentRecord {
            endpoints: [5.0, 6.0, 7.0, 8.0],
        }; 9];
        let mut header = SegmentsHeader::from(FrameHeader::new(7, 0, 0));
        header.detection.left_count = 1;
        // More records than the initial length: the publisher grows its slices.
        let delivered = outlet
            .publish(&header, &[&a, &b])
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(delivered, 1);
        wake.wait(Duration::from_secs(2))
            .unwrap_or_else(|e| panic!("{e}"));
        let got = inlet
            .receive()
            .unwrap_or_else(|e| panic!("{e}"))
            .unwrap_or_else(|| panic!("no message"));
        assert_eq!(got.header().frame.frame_id, 7);
        assert_eq!(got.header().detection.left_count, 1);
        assert_eq!(got.payload().len(), 10);
        assert_eq!(got.payload()[0], a[0]);
        assert_eq!(got.payload()[9], b[0]);
        assert!(inlet.receive().unwrap_or_else(|e| panic!("{e}")).is_none());
    }

    /// Runs `test` with a publishing and a subscribing bus of one process (threads).
    fn with_local_buses(test: fn(&Bus, &Bus)) {
        let bus = Bus::local();
        let peer = bus
            .local_hub()
            .unwrap_or_else(|| panic!("local bus has peers"))
            .bus();
        test(&bus, &peer);
    }

    /// Runs `test` with a publishing and a subscribing shared-memory bus, in a scope of its
    /// own named by `tag`.
    fn with_shared_memory_buses(tag: &str, test: fn(&Bus, &Bus)) {
        let scope = unique_scope(tag);
        let publisher =
            Bus::shared_memory(&scope, "test-publisher").unwrap_or_else(|e| panic!("{e}"));
        let subscriber =
            Bus::shared_memory(&scope, "test-subscriber").unwrap_or_else(|e| panic!("{e}"));
        test(&publisher, &subscriber);
    }

    #[test]
    fn local_messages_fan_out_with_payload_intact() {
        with_local_buses(round_trip);
    }

    #[test]
    fn shared_memory_messages_arrive_in_place() {
        with_shared_memory_buses("rt", round_trip);
    }

    /// Publishes three frames more than the frames topic's queue holds, none received: the
    /// subscriber then reads the newest ones, in order.
    fn a_full_queue_gives_up_its_oldest(publisher_bus: &Bus, subscriber_bus: &Bus) {
        let topic = linetrack_msgs::topics::FRAMES;
        let mut inlet = subscriber_bus
            .inlet::<u8, FrameHeader>(topic)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut outlet = publisher_bus
            .outlet::<u8, FrameHeader>(topic, 1)
            .unwrap_or_else(|e| panic!("{e}"));
        let depth = linetrack_msgs::Topic::Frames.queue_depth() as u64;
        for id in 0..depth + 3 {
            outlet
                .publish(&FrameHeader::new(id, 0, 1), &[&[0]])
                .unwrap_or_else(|e| panic!("{e}"));
        }
        let mut seen = Vec::new();
        while let Some(message) = inlet.receive().unwrap_or_else(|e| panic!("{e}")) {
            seen.push(message.header().frame_id);
        }
        assert_eq!(seen, (3..depth + 3).collect::<Vec<_>>());
    }

    #[test]
    fn a_full_local_queue_gives_up_its_oldest_message_as_shared_memory_does() {
        with_local_buses(a_full_queue_gives_up_its_oldest);
        with_shared_memory_buses("overflow", a_full_queue_gives_up_its_oldest);
    }

    #[test]
    fn dropping_every_port_and_node_leaves_no_resources() {
        let scope = unique_scope("gone");
        {
            let bus = Bus::shared_memory(&scope, "test-lifetime").unwrap_or_else(|e| panic!("{e}"));
            let _outlet = bus
                .outlet::<SegmentRecord, SegmentsHeader>(linetrack_msgs::topics::SEGMENTS, 4)
                .unwrap_or_else(|e| panic!("{e}"));
            let during = scope.resources().unwrap_or_else(|e| panic!("{e}"));
            assert!(during.nodes >= 1 && during.services >= 1, "{during:?}");
        }
        assert_eq!(
            scope.resources().unwrap_or_else(|e| panic!("{e}")),
            Resources::default()
        );
    }

    /// Whether `wake` has a wake-up pending (taking it), without waiting.
    fn woken(wake: &Wake) -> bool {
        match &wake.inner {
            WakeInner::Shm(listener) => {
                listener
                    .try_wait(|_| {})
                    .unwrap_or_else(|e| panic!("{e:?}"))
                    > 0
            }
            WakeInner::Local(rx) => rx.try_recv().is_ok(),
        }
    }

    /// Publishes one (empty) segments message on `bus`.
    fn publish_segments(bus: &Bus) {
        bus.outlet::<SegmentRecord, SegmentsHeader>(linetrack_msgs::topics::SEGMENTS, 4)
            .and_then(|mut segments| {
                segments.publish(&SegmentsHeader::from(FrameHeader::new(3, 0, 0)), &[])
            })
            .unwrap_or_else(|e| panic!("{e}"));
    }

    /// A frame wakes the stages that read it (the pose estimator, the detector, the
    /// matcher), and segments only theirs (the matcher).
    fn each_topic_wakes_its_readers_only(publisher_bus: &Bus, subscriber_bus: &Bus) {
        let wake = |stage| subscriber_bus.wake(stage).unwrap_or_else(|e| panic!("{e}"));
        let (pose, detector, matcher) = (
            wake(StageKind::PoseEstimator),
            wake(StageKind::LineDetector),
            wake(StageKind::Matcher),
        );
        let _images = subscriber_bus
            .inlet::<u8, FrameHeader>(linetrack_msgs::topics::FRAMES)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut frames = publisher_bus
            .outlet::<u8, FrameHeader>(linetrack_msgs::topics::FRAMES, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        frames
            .publish(&FrameHeader::new(3, 0, 0), &[&[1, 2], &[3, 4]])
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(woken(&pose) && woken(&detector) && woken(&matcher));
        publish_segments(publisher_bus);
        assert!(woken(&matcher));
        assert!(!woken(&pose) && !woken(&detector));
    }

    #[test]
    fn each_topic_wakes_its_readers_only_locally() {
        with_local_buses(each_topic_wakes_its_readers_only);
    }

    #[test]
    fn each_topic_wakes_its_readers_only_in_shared_memory() {
        with_shared_memory_buses("wake", each_topic_wakes_its_readers_only);
    }

    /// A wait with nothing to wake it lasts its timeout; one with a wake-up pending returns
    /// long before its (very long) timeout and takes the wake-up.
    fn a_wait_times_out_or_takes_its_wake_up(publisher_bus: &Bus, subscriber_bus: &Bus) {
        let wake = subscriber_bus
            .wake(StageKind::Matcher)
            .unwrap_or_else(|e| panic!("{e}"));
        let started = std::time::Instant::now();
        wake.wait(Duration::from_millis(30))
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(started.elapsed() >= Duration::from_millis(25));
        let _inlet = subscriber_bus
            .inlet::<SegmentRecord, SegmentsHeader>(linetrack_msgs::topics::SEGMENTS)
            .unwrap_or_else(|e| panic!("{e}"));
        publish_segments(publisher_bus);
        let started = std::time::Instant::now();
        wake.wait(Duration::from_secs(600))
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(started.elapsed() < Duration::from_secs(300));
        assert!(!woken(&wake), "the wait took the wake-up");
    }

    #[test]
    fn a_local_wait_times_out_or_takes_its_wake_up() {
        with_local_buses(a_wait_times_out_or_takes_its_wake_up);
    }

    #[test]
    fn a_shared_memory_wait_times_out_or_takes_its_wake_up() {
        with_shared_memory_buses("wait", a_wait_times_out_or_takes_its_wake_up);
    }
}
