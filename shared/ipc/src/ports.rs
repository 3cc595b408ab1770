//! The ports a [`Bus`](crate::Bus) opens: [`Outlet`] publishes a topic, [`Inlet`] receives
//! it, [`Wake`] blocks a stage until a topic it consumes has news.

use crate::{IpcError, Record, transfer};
use crossbeam_channel::{Receiver, Sender, TrySendError};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use iceoryx2::sample::Sample;
use std::any::Any;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A message in the local transport, its types erased (see [`LocalPayload`]).
pub(crate) type LocalMessage = Arc<dyn Any + Send + Sync>;

/// A message in the local transport.
#[derive(Debug)]
pub struct LocalPayload<P, H> {
    pub(crate) header: H,
    pub(crate) payload: Vec<P>,
}

/// A local topic: its subscribers' queues and, for a topic with history, the last message
/// (handed to a subscriber that comes later, as iceoryx2's history does).
#[derive(Default)]
pub(crate) struct LocalTopic {
    /// Each subscriber's queue: its sending end, and a receiving end through which a full
    /// queue gives up its oldest message to the newest (iceoryx2's safe overflow).
    pub(crate) subscribers: Vec<(Sender<LocalMessage>, Receiver<LocalMessage>)>,
    pub(crate) last: Option<LocalMessage>,
}

pub(crate) enum OutletInner<P: Record, H: Record> {
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
    pub(crate) service_name: String,
    pub(crate) inner: OutletInner<P, H>,
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
                for (tx, oldest) in local.subscribers.iter() {
                    // A full queue loses its oldest message to this one, as a shared memory
                    // subscriber's safe overflow does; the gap shows in the records. (Should
                    // the subscriber take one meanwhile, one more old message is lost: never
                    // the newest.)
                    let mut sent = tx.try_send(Arc::clone(&message));
                    if let Err(TrySendError::Full(again)) = sent {
                        let _ = oldest.try_recv();
                        sent = tx.try_send(again);
                    }
                    delivered += usize::from(sent.is_ok());
                }
                for wake in wakes {
                    let _ = wake.try_send(());
                }
                Ok(delivered)
            }
        }
    }

    /// Hands the topic's history (see [`Topic::history`](linetrack_msgs::Topic::history)) to
    /// subscribers that connected since the last message: a publisher with nothing new to
    /// send calls it now and then.
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

pub(crate) enum InletInner<P: Record, H: Record> {
    Shm(Subscriber<ipc::Service, [P], H>),
    Local(Receiver<LocalMessage>, std::marker::PhantomData<(P, H)>),
}

/// Receives messages on one topic.
pub struct Inlet<P: Record, H: Record> {
    pub(crate) service_name: String,
    /// Messages it may hold at once: the topic's queue depth, which is also the
    /// subscriber's borrow limit.
    pub(crate) limit: usize,
    pub(crate) inner: InletInner<P, H>,
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

pub(crate) enum WakeInner {
    Shm(Box<Listener<ipc::Service>>),
    Local(Receiver<()>),
}

/// Blocks a stage until a topic it consumes has a message.
pub struct Wake {
    pub(crate) service_name: String,
    pub(crate) inner: WakeInner,
}

impl Wake {
    /// Blocks until woken or `timeout` passes; clears every pending wake-up.
    pub fn wait(&self, timeout: Duration) -> Result<(), IpcError> {
        match &self.inner {
            WakeInner::Shm(listener) => {
                // The listener's own timed wait ends on the kernel's tick: measured here
                // 4–8.5 ms after its timeout (p50 5.0 ms), which a source paced in real
                // time publishes late by. Its descriptor is polled with the timeout instead
                // (a high-resolution timer: 0.1–0.2 ms late), then what came is taken.
                // A signal (SIGINT, SIGTERM) cuts the wait short: the caller checks its flag.
                match poll_readable(listener.as_ref(), timeout) {
                    Ok(()) | Err(rustix::io::Errno::INTR) => {}
                    Err(e) => return Err(transfer("wait", &self.service_name)(e.to_string())),
                }
                match listener.try_wait(|_| {}) {
                    Ok(_) | Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => {
                        Ok(())
                    }
                    Err(e) => Err(transfer("wait", &self.service_name)(format!("{e:?}"))),
                }
            }
            WakeInner::Local(rx) => {
                let _ = rx.recv_timeout(timeout);
                while rx.try_recv().is_ok() {}
                Ok(())
            }
        }
    }
}

/// Waits until `listener`'s descriptor is readable (a notification came) or `timeout`
/// passes.
fn poll_readable(listener: &Listener<ipc::Service>, timeout: Duration) -> rustix::io::Result<()> {
    use iceoryx2::prelude::FileDescriptorBased;
    // SAFETY: the descriptor belongs to `listener`, which outlives this borrow and is not
    // closed meanwhile; it is only polled.
    #[allow(unsafe_code)]
    let fd =
        unsafe { rustix::fd::BorrowedFd::borrow_raw(listener.file_descriptor().native_handle()) };
    let mut fds = [rustix::event::PollFd::new(
        &fd,
        rustix::event::PollFlags::IN,
    )];
    let timeout = rustix::event::Timespec {
        tv_sec: i64::try_from(timeout.as_secs()).unwrap_or(i64::MAX),
        tv_nsec: i64::from(timeout.subsec_nanos()),
    };
    rustix::event::poll(&mut fds, Some(&timeout)).map(|_| ())
}
