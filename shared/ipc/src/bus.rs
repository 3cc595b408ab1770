//! [`Bus`]: the transport's two implementations (iceoryx2 shared memory, crossbeam
//! channels in one process) and the services it opens ports on.

use crate::ports::{InletInner, LocalTopic, OutletInner, WakeInner};
use crate::{Inlet, IpcError, Outlet, Record, Scope, Wake, setup};
use crossbeam_channel::{Receiver, Sender};
use iceoryx2::node::Node;
use iceoryx2::prelude::{
    AllocationStrategy, NodeBuilder, NodeName, ServiceName, SignalHandlingMode, ipc,
};
use linetrack_msgs::{StageKind, Topic, TopicOf, wake_service_name};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

#[derive(Default)]
pub(crate) struct LocalRegistry {
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

pub(crate) enum BusKind {
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

    /// A publisher on `topic` (its types those of its messages: see
    /// [`linetrack_msgs::topics`]) whose messages hold up to `initial_len` records (more are
    /// allocated when needed), waking the topic's consumers.
    pub fn outlet<P: Record, H: Record>(
        &self,
        topic: TopicOf<P, H>,
        initial_len: usize,
    ) -> Result<Outlet<P, H>, IpcError> {
        let topic = topic.topic();
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

    /// A subscriber on `topic` (its types those of its messages).
    pub fn inlet<P: Record, H: Record>(
        &self,
        topic: TopicOf<P, H>,
    ) -> Result<Inlet<P, H>, IpcError> {
        let topic = topic.topic();
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
                local.subscribers.push((tx, rx.clone()));
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

pub(crate) fn pubsub_service<P: Record, H: Record>(
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
pub(crate) const MAX_NOTIFIERS: usize = 32;

pub(crate) fn event_service(
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
