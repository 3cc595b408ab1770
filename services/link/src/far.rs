//! The far side: a zenoh peer that connects to the onboard endpoint (and reconnects, every
//! 1 to 4 s, whenever the link comes back) and receives the forwarded messages.

use crate::wire::{Message, key};
use crate::{LinkError, peer_config};
use std::time::Duration;
use zenoh::Wait;
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::sample::Sample;

/// Samples zenoh holds for [`Receiver::next`]; more wait in zenoh's own buffers.
const BUFFERED: usize = 1024;

/// What [`Receiver::next`] got.
#[derive(Debug)]
pub enum Received {
    /// A message, with its encoded size.
    Message(Message, usize),
    /// A sample that is not a message of this link (it is skipped).
    Undecodable(LinkError),
}

/// The far side's session.
pub struct Receiver {
    session: zenoh::Session,
    subscriber: Subscriber<FifoChannelHandler<Sample>>,
}

impl Receiver {
    /// Connects to `endpoint` (`tcp/HOST:PORT`) and subscribes to every topic under
    /// `key_prefix`. Returns at once: the connection is made (and remade) in the background.
    pub fn connect(endpoint: &str, key_prefix: &str) -> Result<Self, LinkError> {
        let fail = |what| {
            let endpoint = endpoint.to_string();
            move |e: zenoh::Error| LinkError::Zenoh {
                what,
                endpoint,
                message: e.to_string(),
            }
        };
        let session = zenoh::open(peer_config("connect", endpoint)?)
            .wait()
            .map_err(fail("session"))?;
        let subscriber = session
            .declare_subscriber(key(key_prefix, "**"))
            .with(zenoh::handlers::FifoChannel::new(BUFFERED))
            .wait()
            .map_err(fail("subscriber"))?;
        Ok(Self {
            session,
            subscriber,
        })
    }

    /// The next message, waiting up to `timeout`; `None` when none came.
    pub fn next(&self, timeout: Duration) -> Option<Received> {
        let sample = self.subscriber.recv_timeout(timeout).ok().flatten()?;
        let bytes = sample.payload().to_bytes();
        Some(match Message::decode(sample.key_expr().as_str(), &bytes) {
            Ok(m) => Received::Message(m, bytes.len()),
            Err(e) => Received::Undecodable(e),
        })
    }

    /// Whether a peer (the onboard side) is connected now.
    pub fn connected(&self) -> bool {
        self.session.info().peers_zid().wait().next().is_some()
    }
}
