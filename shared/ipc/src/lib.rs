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

use crossbeam_channel::{Receiver, Sender, TrySendError};
use iceoryx2::config::Config;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::Path as IoxPath;
use iceoryx2::prelude::{
    AllocationStrategy, FileName, NodeBuilder, NodeName, SemanticString, ServiceName,
    SignalHandlingMode, ZeroCopySend, ipc,
};
use iceoryx2::sample::Sample;
use linetrack_msgs::{StageKind, Topic, wake_service_name};
use std::any::Any;
use std::collections::HashMap;
use std::fmt::Debug;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

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

/// Where a run's shared-memory resources live: every file is named with `prefix`, every
/// service with `run_id`, so runs (and tests) side by side never meet, and a run's leftovers
/// are found by prefix. Both the prefix and the root folder of iceoryx2's bookkeeping
/// belong to the user who runs the pipeline (`linetrack_u<uid>_`, `$XDG_RUNTIME_DIR` or
/// `/tmp/linetrack-<uid>`), so runs of different users never block each other, and
/// [`Scope::lock_down`] keeps every file of the scope readable and writable by its owner
/// only.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Scope {
    /// File-name prefix of the iceoryx2 resources (`linetrack_u<uid>_` unless
    /// `LINETRACK_IPC_PREFIX` says otherwise).
    pub prefix: String,
    /// The run.
    pub run_id: String,
    /// The folder of iceoryx2's node and service descriptions (`LINETRACK_IPC_ROOT`, else
    /// `$XDG_RUNTIME_DIR/linetrack-iceoryx2`, else `/tmp/linetrack-<uid>/iceoryx2`).
    pub root: PathBuf,
}

/// Where POSIX shared memory lives on Linux.
const SHM_DIR: &str = "/dev/shm";

/// The longest path a unix socket may have (`sun_path`, less its closing NUL).
const SOCKET_PATH_MAX: usize = 107;
/// What iceoryx2 adds to the root folder and the prefix for an event's socket: `/`, a
/// decimal 128-bit hash (up to 39 digits) and `.event`.
const EVENT_SOCKET_SUFFIX: usize = 1 + 39 + ".event".len();

impl Scope {
    /// The environment variable that overrides the prefix.
    pub const PREFIX_VAR: &'static str = "LINETRACK_IPC_PREFIX";
    /// The environment variable that overrides the root folder.
    pub const ROOT_VAR: &'static str = "LINETRACK_IPC_ROOT";

    /// A scope for `run_id` with the prefix from the environment or this user's default.
    pub fn new(run_id: &str) -> Self {
        let prefix = std::env::var(Self::PREFIX_VAR)
            .ok()
            .filter(|p| !p.is_empty())
            .unwrap_or_else(|| format!("linetrack_u{}_", rustix::process::getuid().as_raw()));
        Self::with_prefix(&prefix, run_id)
    }

    /// This scope with its root folder from the config (see [`Scope::root_from`]).
    pub fn with_configured_root(mut self, configured: Option<&Path>) -> Self {
        self.root = Self::root_from(configured);
        self
    }

    /// This scope with an explicit root folder (`linetrack ctl` reaching a recorded run).
    pub fn with_root(mut self, root: PathBuf) -> Self {
        self.root = root;
        self
    }

    /// A scope with an explicit prefix (tests, `linetrack ctl` reaching a recorded run).
    pub fn with_prefix(prefix: &str, run_id: &str) -> Self {
        Self {
            prefix: prefix.to_string(),
            run_id: run_id.to_string(),
            root: Self::default_root(),
        }
    }

    /// This user's root folder for iceoryx2's bookkeeping.
    pub fn default_root() -> PathBuf {
        Self::root_from(None)
    }

    /// The root folder: `LINETRACK_IPC_ROOT`, else `configured` (the config's `ipc.root`),
    /// else `$XDG_RUNTIME_DIR/linetrack-iceoryx2`, else `/tmp/linetrack-<uid>/iceoryx2`.
    pub fn root_from(configured: Option<&Path>) -> PathBuf {
        let from_env = |var: &str| {
            std::env::var_os(var)
                .filter(|v| !v.is_empty())
                .map(PathBuf::from)
        };
        from_env(Self::ROOT_VAR)
            .or_else(|| configured.map(Path::to_path_buf))
            .or_else(|| {
                from_env("XDG_RUNTIME_DIR")
                    .filter(|dir| dir.is_dir())
                    .map(|dir| dir.join("linetrack-iceoryx2"))
            })
            .unwrap_or_else(|| {
                PathBuf::from(format!(
                    "/tmp/linetrack-{}",
                    rustix::process::getuid().as_raw()
                ))
                .join("iceoryx2")
            })
    }

    /// The iceoryx2 configuration of this scope (the root folder is created, owner-only,
    /// when missing).
    pub fn config(&self) -> Result<Config, IpcError> {
        let root = self.root.to_string_lossy();
        let socket_len = root.trim_end_matches('/').len() + self.prefix.len() + EVENT_SOCKET_SUFFIX;
        if socket_len > SOCKET_PATH_MAX {
            return Err(setup("iceoryx2 root folder", &root)(format!(
                "too long for iceoryx2's event sockets: the folder and the prefix {:?} take {} bytes \
                 of a socket path's {SOCKET_PATH_MAX}, {EVENT_SOCKET_SUFFIX} are needed after them; \
                 choose a shorter folder (`[ipc] root` in the config, or {})",
                self.prefix,
                socket_len - EVENT_SOCKET_SUFFIX,
                Self::ROOT_VAR
            )));
        }
        private_dir(&self.root).map_err(|message| setup("iceoryx2 root folder", &root)(message))?;
        let mut config = Config::default();
        config.global.prefix = FileName::new(self.prefix.as_bytes())
            .map_err(|e| setup("iceoryx2 prefix", &self.prefix)(format!("{e:?}")))?;
        let with_slash = format!("{}/", root.trim_end_matches('/'));
        let path = IoxPath::new(with_slash.as_bytes())
            .map_err(|e| setup("iceoryx2 root folder", &root)(format!("{e:?}")))?;
        config.global.set_root_path(&path);
        Ok(config)
    }

    /// Checks the scope's shared-memory files: one owned by another user is an error naming
    /// it (it would lock this user's runs out); one that others may read or write is made
    /// owner-only (iceoryx2 creates its global management segment world-writable).
    /// Returns how many files were tightened.
    pub fn lock_down(&self) -> Result<usize, IpcError> {
        lock_down_files(
            Path::new(SHM_DIR),
            &self.prefix,
            rustix::process::getuid().as_raw(),
        )
        .map_err(|message| setup("locking down shared memory", &self.prefix)(message))
    }
}

/// [`Scope::lock_down`] over the files of `dir` whose names start with `prefix`, for user `me`.
fn lock_down_files(dir: &Path, prefix: &str, me: u32) -> Result<usize, String> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut tightened = 0;
    for entry in entries.flatten() {
        if !entry.file_name().to_string_lossy().starts_with(prefix) {
            continue;
        }
        let path = entry.path();
        // A file that went away between listing and reading belonged to a node that ended.
        let Ok(meta) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        if meta.uid() != me {
            return Err(format!(
                "{} belongs to user {}, not to this user ({me}): another user's file in this \
                 user's namespace; remove it or set {} to another prefix",
                path.display(),
                meta.uid(),
                Scope::PREFIX_VAR
            ));
        }
        if meta.mode() & 0o077 != 0 {
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600))
                .map_err(|e| format!("{}: {e}", path.display()))?;
            tightened += 1;
        }
    }
    Ok(tightened)
}

/// Makes sure `dir` is a folder only this user can change, reached through folders and
/// links no other user can change ([`linetrack_private_dir`]): created (mode 0700, parents
/// too) when missing; refused, naming the path, when it or a folder or link above it is
/// another user's, or writable by others.
fn private_dir(dir: &Path) -> Result<(), String> {
    linetrack_private_dir::private_dir(dir, linetrack_private_dir::Create::Missing)
        .map(|_| ())
        .map_err(|e| {
            let cause = std::error::Error::source(&e)
                .map(|source| format!(": {source}"))
                .unwrap_or_default();
            format!("{e}{cause} (set {} to a folder of yours)", Scope::ROOT_VAR)
        })
}

/// iceoryx2 resources left in a scope: nodes (alive or dead) and services.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Resources {
    /// Nodes registered under the prefix.
    pub nodes: usize,
    /// Services whose static description exists under the prefix.
    pub services: usize,
}

impl Scope {
    /// Counts the nodes and services that exist under this scope's prefix (of any run).
    pub fn resources(&self) -> Result<Resources, IpcError> {
        use iceoryx2::prelude::{CallbackProgression, Service as _};
        let config = self.config()?;
        let mut found = Resources::default();
        Node::<ipc::Service>::list(&config, |_| {
            found.nodes += 1;
            CallbackProgression::Continue
        })
        .map_err(|e| transfer("listing nodes", &self.prefix)(format!("{e:?}")))?;
        ipc::Service::list(&config, |_| {
            found.services += 1;
            CallbackProgression::Continue
        })
        .map_err(|e| transfer("listing services", &self.prefix)(format!("{e:?}")))?;
        Ok(found)
    }
}

impl Scope {
    /// Counts the nodes of processes that died without removing their resources.
    pub fn dead_nodes(&self) -> Result<usize, IpcError> {
        use iceoryx2::prelude::{CallbackProgression, NodeState};
        let config = self.config()?;
        let mut dead = 0;
        Node::<ipc::Service>::list(&config, |state| {
            if matches!(state, NodeState::Dead(_)) {
                dead += 1;
            }
            CallbackProgression::Continue
        })
        .map_err(|e| transfer("listing nodes", &self.prefix)(format!("{e:?}")))?;
        Ok(dead)
    }
}

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

type LocalMessage = Arc<dyn Any + Send + Sync>;

/// A message in the local transport.
#[derive(Debug)]
pub struct LocalPayload<P, H> {
    header: H,
    payload: Vec<P>,
}

/// A local topic: its subscribers' queues and, for a topic with history, the last message
/// (handed to a subscriber that comes later, as iceoryx2's history does).
#[derive(Default)]
struct LocalTopic {
    subscribers: Vec<Sender<LocalMessage>>,
    last: Option<LocalMessage>,
}

#[derive(Default)]
struct LocalRegistry {
    topics: HashMap<Topic, Arc<Mutex<LocalTopic>>>,
    wakes: HashMap<StageKind, (Sender<()>, Receiver<()>)>,
}

/// A handle on a local transport that can move to another thread.
#[derive(Clone, Default)]
pub struct LocalHub(Arc<Mutex<LocalRegistry>>);

impl LocalHub {
    /// A bus on this transport.
    pub fn bus(&self) -> Bus {
        Bus {
            kind: BusKind::Local(Arc::clone(&self.0)),
        }
    }
}

enum BusKind {
    Shm {
        node: Node<ipc::Service>,
        scope: Scope,
    },
    Local(Arc<Mutex<LocalRegistry>>),
}

/// The transport of one process (shared memory) or of all stages of one process (local).
pub struct Bus {
    kind: BusKind,
}

impl Bus {
    /// The shared-memory transport, as a node named `node_name` in `scope`.
    pub fn shared_memory(scope: &Scope, node_name: &str) -> Result<Self, IpcError> {
        let config = scope.config()?;
        scope.lock_down()?;
        let name = NodeName::new(node_name)
            .map_err(|e| setup("node name", node_name)(format!("{e:?}")))?;
        let node = NodeBuilder::new()
            .name(&name)
            .config(&config)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| setup("iceoryx2 node", node_name)(format!("{e:?}")))?;
        scope.lock_down()?;
        Ok(Self {
            kind: BusKind::Shm {
                node,
                scope: scope.clone(),
            },
        })
    }

    /// A fresh local transport.
    pub fn local() -> Self {
        LocalHub::default().bus()
    }

    /// Another handle on the same local transport, to hand to another thread; `None` for
    /// shared memory, where each process makes its own bus.
    pub fn local_hub(&self) -> Option<LocalHub> {
        match &self.kind {
            BusKind::Local(registry) => Some(LocalHub(Arc::clone(registry))),
            BusKind::Shm { .. } => None,
        }
    }

    /// Removes the shared-memory resources of processes of this scope that died without
    /// cleaning up; returns how many such processes were cleaned (0 for local).
    pub fn remove_stale_resources(&self) -> u64 {
        match &self.kind {
            BusKind::Shm { node, .. } => node.try_cleanup_dead_nodes().cleanups,
            BusKind::Local(_) => 0,
        }
    }

    fn lock_local(registry: &Mutex<LocalRegistry>) -> std::sync::MutexGuard<'_, LocalRegistry> {
        registry
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    fn local_wake_sender(registry: &Mutex<LocalRegistry>, stage: StageKind) -> Sender<()> {
        let mut r = Self::lock_local(registry);
        r.wakes
            .entry(stage)
            .or_insert_with(|| crossbeam_channel::bounded(1))
            .0
            .clone()
    }

    /// A publisher on `topic` whose messages hold up to `initial_len` records (more are
    /// allocated when needed), waking the topic's consumers.
    pub fn outlet<P: Record, H: Record>(
        &self,
        topic: Topic,
        initial_len: usize,
    ) -> Result<Outlet<P, H>, IpcError> {
        match &self.kind {
            BusKind::Shm { node, scope } => {
                let service_name = topic.service_name(&scope.run_id);
                let service = pubsub_service::<P, H>(node, topic, &service_name)?;
                let publisher = service
                    .publisher_builder()
                    .initial_max_slice_len(initial_len.max(1))
                    .allocation_strategy(AllocationStrategy::PowerOfTwo)
                    .create()
                    .map_err(|e| setup("publisher", &service_name)(format!("{e:?}")))?;
                let mut notifiers = Vec::new();
                for &stage in topic.consumers() {
                    let wake_name = wake_service_name(&scope.run_id, stage);
                    let event = event_service(node, &wake_name)?;
                    notifiers.push(
                        event
                            .notifier_builder()
                            .create()
                            .map_err(|e| setup("notifier", &wake_name)(format!("{e:?}")))?,
                    );
                }
                Ok(Outlet {
                    service_name,
                    inner: OutletInner::Shm {
                        publisher,
                        notifiers,
                    },
                })
            }
            BusKind::Local(registry) => {
                let subscribers =
                    Arc::clone(Self::lock_local(registry).topics.entry(topic).or_default());
                let wakes = topic
                    .consumers()
                    .iter()
                    .map(|&s| Self::local_wake_sender(registry, s))
                    .collect();
                Ok(Outlet {
                    service_name: topic.name().to_string(),
                    inner: OutletInner::Local {
                        subscribers,
                        keep_last: topic.history() > 0,
                        wakes,
                        _message: std::marker::PhantomData,
                    },
                })
            }
        }
    }

    /// A subscriber on `topic`.
    pub fn inlet<P: Record, H: Record>(&self, topic: Topic) -> Result<Inlet<P, H>, IpcError> {
        match &self.kind {
            BusKind::Shm { node, scope } => {
                let service_name = topic.service_name(&scope.run_id);
                let service = pubsub_service::<P, H>(node, topic, &service_name)?;
                let subscriber = service
                    .subscriber_builder()
                    .buffer_size(topic.queue_depth())
                    .create()
                    .map_err(|e| setup("subscriber", &service_name)(format!("{e:?}")))?;
                Ok(Inlet {
                    service_name,
                    limit: topic.queue_depth(),
                    inner: InletInner::Shm(subscriber),
                })
            }
            BusKind::Local(registry) => {
                let (tx, rx) = crossbeam_channel::bounded(topic.queue_depth());
                let shared =
                    Arc::clone(Self::lock_local(registry).topics.entry(topic).or_default());
                let mut local = shared.lock().unwrap_or_else(|p| p.into_inner());
                if let Some(last) = &local.last {
                    let _ = tx.try_send(Arc::clone(last));
                }
                local.subscribers.push(tx);
                Ok(Inlet {
                    service_name: topic.name().to_string(),
                    limit: topic.queue_depth(),
                    inner: InletInner::Local(rx, std::marker::PhantomData),
                })
            }
        }
    }

    /// What wakes `stage` when a topic it consumes has a message.
    pub fn wake(&self, stage: StageKind) -> Result<Wake, IpcError> {
        match &self.kind {
            BusKind::Shm { node, scope } => {
                let wake_name = wake_service_name(&scope.run_id, stage);
                let event = event_service(node, &wake_name)?;
                let listener = event
                    .listener_builder()
                    .create()
                    .map_err(|e| setup("listener", &wake_name)(format!("{e:?}")))?;
                Ok(Wake {
                    service_name: wake_name,
                    inner: WakeInner::Shm(Box::new(listener)),
                })
            }
            BusKind::Local(registry) => {
                let mut r = Self::lock_local(registry);
                let rx = r
                    .wakes
                    .entry(stage)
                    .or_insert_with(|| crossbeam_channel::bounded(1))
                    .1
                    .clone();
                Ok(Wake {
                    service_name: stage.name().to_string(),
                    inner: WakeInner::Local(rx),
                })
            }
        }
    }
}

fn pubsub_service<P: Record, H: Record>(
    node: &Node<ipc::Service>,
    topic: Topic,
    service_name: &str,
) -> Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, [P], H>,
    IpcError,
> {
    let name = ServiceName::new(service_name)
        .map_err(|e| setup("service name", service_name)(format!("{e:?}")))?;
    node.service_builder(&name)
        .publish_subscribe::<[P]>()
        .user_header::<H>()
        .max_publishers(topic.max_publishers())
        .max_subscribers(8)
        .subscriber_max_buffer_size(topic.queue_depth())
        .subscriber_max_borrowed_samples(topic.queue_depth())
        .history_size(topic.history())
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| setup("publish-subscribe service", service_name)(format!("{e:?}")))
}

/// Notifiers one stage's wake service takes: one per outlet of a topic the stage consumes,
/// in every process of the run. The recorder's and the supervisor's are the busiest (the
/// status outlet of every process, a standby detector's and `linetrack ctl`'s too).
const MAX_NOTIFIERS: usize = 32;

fn event_service(
    node: &Node<ipc::Service>,
    service_name: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<ipc::Service>, IpcError> {
    let name = ServiceName::new(service_name)
        .map_err(|e| setup("service name", service_name)(format!("{e:?}")))?;
    node.service_builder(&name)
        .event()
        .max_listeners(4)
        .max_notifiers(MAX_NOTIFIERS)
        .open_or_create()
        .map_err(|e| setup("event service", service_name)(format!("{e:?}")))
}

enum OutletInner<P: Record, H: Record> {
    Shm {
        publisher: Publisher<ipc::Service, [P], H>,
        notifiers: Vec<Notifier<ipc::Service>>,
    },
    Local {
        subscribers: Arc<Mutex<LocalTopic>>,
        keep_last: bool,
        wakes: Vec<Sender<()>>,
        _message: std::marker::PhantomData<(P, H)>,
    },
}

/// Publishes messages on one topic.
pub struct Outlet<P: Record, H: Record> {
    service_name: String,
    inner: OutletInner<P, H>,
}

impl<P: Record, H: Record> Outlet<P, H> {
    /// Publishes `header` with the concatenation of `parts` as payload, written once into
    /// shared memory, and wakes the consumers. Returns how many subscribers got it.
    pub fn publish(&mut self, header: &H, parts: &[&[P]]) -> Result<usize, IpcError> {
        let len: usize = parts.iter().map(|p| p.len()).sum();
        match &mut self.inner {
            OutletInner::Shm {
                publisher,
                notifiers,
            } => {
                let mut sample = publisher
                    .loan_slice_uninit(len)
                    .map_err(|e| transfer("loan", &self.service_name)(format!("{e:?}")))?;
                *sample.user_header_mut() = *header;
                let mut offset = 0;
                let payload = sample.payload_mut();
                for part in parts {
                    payload[offset..offset + part.len()].write_copy_of_slice(part);
                    offset += part.len();
                }
                // SAFETY: `parts` hold exactly `len` records in all, and every one of them was
                // written into the payload's `len` slots above, so the payload is initialised.
                #[allow(unsafe_code)]
                let sample = unsafe { sample.assume_init() };
                let delivered = sample
                    .send()
                    .map_err(|e| transfer("send", &self.service_name)(format!("{e:?}")))?;
                for notifier in notifiers.iter() {
                    notifier
                        .notify()
                        .map_err(|e| transfer("notify", &self.service_name)(format!("{e:?}")))?;
                }
                Ok(delivered)
            }
            OutletInner::Local {
                subscribers,
                keep_last,
                wakes,
                ..
            } => {
                let mut payload = Vec::with_capacity(len);
                for part in parts {
                    payload.extend_from_slice(part);
                }
                let message: LocalMessage = Arc::new(LocalPayload {
                    header: *header,
                    payload,
                });
                let mut local = subscribers.lock().unwrap_or_else(|p| p.into_inner());
                if *keep_last {
                    local.last = Some(Arc::clone(&message));
                }
                let mut delivered = 0;
                for tx in local.subscribers.iter() {
                    match tx.try_send(Arc::clone(&message)) {
                        Ok(()) => delivered += 1,
                        // A full queue loses the message for that subscriber, as a shared
                        // memory subscriber's overflow would; the gap shows in the records.
                        Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {}
                    }
                }
                for wake in wakes {
                    let _ = wake.try_send(());
                }
                Ok(delivered)
            }
        }
    }

    /// Hands the topic's history (see [`Topic::history`]) to subscribers that connected
    /// since the last message: a publisher with nothing new to send calls it now and then.
    /// (A local subscriber gets the history when it is created.)
    pub fn update_connections(&self) -> Result<(), IpcError> {
        use iceoryx2::port::update_connections::UpdateConnections;
        match &self.inner {
            OutletInner::Shm { publisher, .. } => publisher
                .update_connections()
                .map_err(|e| transfer("update connections", &self.service_name)(format!("{e:?}"))),
            OutletInner::Local { .. } => Ok(()),
        }
    }

    /// The service name.
    pub fn service_name(&self) -> &str {
        &self.service_name
    }
}

enum InletInner<P: Record, H: Record> {
    Shm(Subscriber<ipc::Service, [P], H>),
    Local(Receiver<LocalMessage>, std::marker::PhantomData<(P, H)>),
}

/// Receives messages on one topic.
pub struct Inlet<P: Record, H: Record> {
    service_name: String,
    /// Messages it may hold at once: the topic's queue depth, which is also the
    /// subscriber's borrow limit.
    limit: usize,
    inner: InletInner<P, H>,
}

/// A received message: in shared memory, read in place, or a local message.
pub enum Received<P: Record, H: Record> {
    /// A shared-memory sample.
    Shm(Sample<ipc::Service, [P], H>),
    /// A local message.
    Local(Arc<LocalPayload<P, H>>),
}

impl<P: Record, H: Record> Received<P, H> {
    /// A message that never went through a bus (a stage's input built in place: tests,
    /// tools).
    pub fn local(header: H, payload: Vec<P>) -> Self {
        Received::Local(Arc::new(LocalPayload { header, payload }))
    }

    /// The header.
    pub fn header(&self) -> &H {
        match self {
            Received::Shm(s) => s.user_header(),
            Received::Local(m) => &m.header,
        }
    }

    /// The records.
    pub fn payload(&self) -> &[P] {
        match self {
            Received::Shm(s) => s.payload(),
            Received::Local(m) => &m.payload,
        }
    }
}

impl<P: Record, H: Record> Inlet<P, H> {
    /// The oldest waiting message, if any.
    pub fn receive(&mut self) -> Result<Option<Received<P, H>>, IpcError> {
        match &mut self.inner {
            InletInner::Shm(subscriber) => subscriber
                .receive()
                .map(|s| s.map(Received::Shm))
                .map_err(|e| transfer("receive", &self.service_name)(format!("{e:?}"))),
            InletInner::Local(rx, _) => match rx.try_recv() {
                Ok(message) => match message.downcast::<LocalPayload<P, H>>() {
                    Ok(m) => Ok(Some(Received::Local(m))),
                    Err(_) => Err(transfer("receive", &self.service_name)(
                        "a message of another type".to_string(),
                    )),
                },
                Err(_) => Ok(None),
            },
        }
    }

    /// The waiting messages, oldest first, at most [`Inlet::limit`] of them: a publisher
    /// that keeps sending while they are taken can never push the subscriber past its
    /// borrow limit. A full batch may leave more waiting.
    pub fn receive_all(&mut self) -> Result<Vec<Received<P, H>>, IpcError> {
        let mut all = Vec::new();
        while all.len() < self.limit
            && let Some(m) = self.receive()?
        {
            all.push(m);
        }
        Ok(all)
    }

    /// The most messages [`Inlet::receive_all`] returns (and a subscriber may borrow).
    pub fn limit(&self) -> usize {
        self.limit
    }

    /// The service name.
    pub fn service_name(&self) -> &str {
        &self.service_name
    }
}

enum WakeInner {
    Shm(Box<Listener<ipc::Service>>),
    Local(Receiver<()>),
}

/// Blocks a stage until a topic it consumes has a message.
pub struct Wake {
    service_name: String,
    inner: WakeInner,
}

impl Wake {
    /// Blocks until woken or `timeout` passes; clears every pending wake-up.
    pub fn wait(&self, timeout: Duration) -> Result<(), IpcError> {
        match &self.inner {
            WakeInner::Shm(listener) => match listener.timed_wait(|_| {}, timeout) {
                // A signal (SIGINT, SIGTERM) cut the wait short: the caller checks its flag.
                Ok(_) | Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => Ok(()),
                Err(e) => Err(transfer("wait", &self.service_name)(format!("{e:?}"))),
            },
            WakeInner::Local(rx) => {
                let _ = rx.recv_timeout(timeout);
                while rx.try_recv().is_ok() {}
                Ok(())
            }
        }
    }
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
    use linetrack_msgs::{FrameHeader, SegmentRecord, SegmentsHeader};

    #[test]
    fn a_scope_leaves_nothing_that_other_users_can_write() {
        let root = linetrack_test_data::scratch_path("ipc", "root").join("iceoryx2");
        let scope = Scope {
            root: root.clone(),
            ..unique_scope("private")
        };
        let bus = Bus::shared_memory(&scope, "private").unwrap_or_else(|e| panic!("{e}"));
        let _outlet = bus
            .outlet::<SegmentRecord, SegmentsHeader>(Topic::Segments, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        let _inlet = bus
            .inlet::<SegmentRecord, SegmentsHeader>(Topic::Segments)
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
        let dir =
            linetrack_test_data::scratch_dir("ipc", "lockdown").unwrap_or_else(|e| panic!("{e}"));
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
        let dir =
            linetrack_test_data::scratch_dir("ipc", "openroot").unwrap_or_else(|e| panic!("{e}"));
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o777))
            .unwrap_or_else(|e| panic!("{e}"));
        let scope = Scope {
            root: dir.clone(),
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
        let link = linetrack_test_data::scratch_path("ipc", "linkroot");
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
        // Another user's folder above the root (a `/tmp/linetrack-<uid>` someone else made).
        if rustix::process::geteuid().as_raw() == 0 {
            let theirs = linetrack_test_data::scratch_dir("ipc", "theirsroot")
                .unwrap_or_else(|e| panic!("{e}"));
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
            .inlet::<SegmentRecord, SegmentsHeader>(Topic::Segments)
            .unwrap_or_else(|e| panic!("{e}"));
        let wake = subscriber_bus
            .wake(StageKind::Matcher)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut outlet = publisher_bus
            .outlet::<SegmentRecord, SegmentsHeader>(Topic::Segments, 4)
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

    #[test]
    fn dropping_every_port_and_node_leaves_no_resources() {
        let scope = unique_scope("gone");
        {
            let bus = Bus::shared_memory(&scope, "test-lifetime").unwrap_or_else(|e| panic!("{e}"));
            let _outlet = bus
                .outlet::<SegmentRecord, SegmentsHeader>(Topic::Segments, 4)
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
            .inlet::<u8, FrameHeader>(Topic::Frames)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut frames = publisher_bus
            .outlet::<u8, FrameHeader>(Topic::Frames, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        frames
            .publish(&FrameHeader::new(3, 0, 0), &[&[1, 2], &[3, 4]])
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(woken(&pose) && woken(&detector) && woken(&matcher));
        let mut segments = publisher_bus
            .outlet::<SegmentRecord, SegmentsHeader>(Topic::Segments, 4)
            .unwrap_or_else(|e| panic!("{e}"));
        segments
            .publish(&SegmentsHeader::from(FrameHeader::new(3, 0, 0)), &[])
            .unwrap_or_else(|e| panic!("{e}"));
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

    #[test]
    fn a_wait_without_messages_times_out() {
        let bus = Bus::local();
        let wake = bus
            .wake(StageKind::Matcher)
            .unwrap_or_else(|e| panic!("{e}"));
        let started = std::time::Instant::now();
        wake.wait(Duration::from_millis(30))
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(started.elapsed() >= Duration::from_millis(25));
    }
}
