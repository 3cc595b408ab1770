//! The ground-station link: the pipeline's poses, status reports, segments, tracks and
//! down-scaled images forwarded to another host over zenoh, and the far side's receiver.
//!
//! - [`wire`]: what goes on the link, one [`wire::Message`] per zenoh sample under the key
//!   `<key_prefix>/<topic>`, encoded with postcard (always built: no zenoh needed).
//! - `onboard` (feature `zenoh`): the `linetrack-link` process's loop. It reads the allowed
//!   topics from the run's shared memory as one more subscriber (the pipeline's publishers
//!   never wait for a subscriber, so a slow link cannot slow a stage) and hands each message
//!   to a sender thread through a bounded queue: when the link is down or stalled, the queue
//!   is full and messages are dropped and counted, never waited for.
//! - `far` (feature `zenoh`): the far side's session (`linetrack watch`): connects to the
//!   onboard endpoint and reconnects whenever the link comes back.
//!
//! Without the `zenoh` feature the crate is [`wire`] only, so the default build of the
//! workspace compiles no zenoh.

#![warn(missing_docs)]

pub mod wire;

#[cfg(feature = "zenoh")]
pub mod far;
#[cfg(feature = "zenoh")]
pub mod onboard;

/// The link's errors; each names what failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The zenoh session, a publisher or a subscriber could not be made.
    #[error("zenoh {what} ({endpoint}): {message}")]
    Zenoh {
        /// What was being made.
        what: &'static str,
        /// The endpoint or key involved.
        endpoint: String,
        /// zenoh's message.
        message: String,
    },
    /// A received sample is not a message of this link.
    #[error("sample on {key}: not a linetrack link message ({message})")]
    Decode {
        /// The sample's key.
        key: String,
        /// The decoder's message.
        message: String,
    },
    /// A message could not be encoded.
    #[error("encoding a {topic} message: {message}")]
    Encode {
        /// The topic.
        topic: &'static str,
        /// The encoder's message.
        message: String,
    },
    /// The run's shared memory.
    #[error(transparent)]
    Ipc(#[from] linetrack_ipc::IpcError),
    /// The sender thread could not be started.
    #[error("starting the link's sender thread: {0}")]
    Thread(std::io::Error),
    /// Writing the link's counters.
    #[error("writing {path}: {source}")]
    Write {
        /// The file.
        path: std::path::PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// A zenoh peer config: `listen` or `connect` on `endpoint`, no multicast scouting (the
/// two sides find each other by the endpoint alone), a lost connection retried every
/// 0.25 s at first, then every second.
#[cfg(feature = "zenoh")]
fn peer_config(side: &str, endpoint: &str) -> Result<zenoh::Config, LinkError> {
    let fail = |message: String| LinkError::Zenoh {
        what: "config",
        endpoint: endpoint.to_string(),
        message,
    };
    let mut config = zenoh::Config::default();
    let endpoints = serde_json::to_string(&[endpoint]).map_err(|e| fail(e.to_string()))?;
    for (key, value) in [
        ("mode", "\"peer\"".to_string()),
        ("scouting/multicast/enabled", "false".to_string()),
        (
            "open/return_conditions/connect_scouted",
            "false".to_string(),
        ),
        (
            "connect/retry",
            "{period_init_ms: 250, period_max_ms: 1000, period_increase_factor: 2}".to_string(),
        ),
        (&format!("{side}/endpoints"), endpoints),
    ] {
        config
            .insert_json5(key, &value)
            .map_err(|e| fail(format!("{key} = {value}: {e}")))?;
    }
    Ok(config)
}
