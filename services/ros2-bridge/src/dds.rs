//! The DDS side (cargo feature `ros2`): a ROS 2 node with ros2-client over RustDDS that
//! publishes the poses, the path, the odometry and `/tf`.
//!
//! QoS: the pose topic is reliable, keep-last 10, volatile (ROS 2's default for a
//! publisher: a late subscriber does not get old poses, a slow one gets them all up to 10
//! behind); the path is reliable, keep-last 1, transient-local, so that a subscriber that
//! starts mid-run (RViz, `ros2 topic echo`) gets the trajectory so far at once. The odometry
//! is as the pose; `/tf` is reliable, keep-last [`TF_DEPTH`], volatile (tf2's broadcaster's
//! profile). A writer
//! whose subscriber does not keep up waits at most [`WRITE_WAIT`] and the write is
//! counted as failed: the bridge falls behind, never the pipeline.

use crate::ros_msgs::{
    DIAGNOSTIC_ARRAY_TYPE, DiagnosticArray, ODOMETRY_TYPE, Odometry, PATH_TYPE, POSE_STAMPED_TYPE,
    Path, PoseStamped, TF_MESSAGE_TYPE, TfMessage,
};
use crate::{BridgeError, PoseSink};
use linetrack_pipeline_config::{MAX_DOMAIN_ID, Ros2Config};
use ros2_client::dds::rustdds::{DomainParticipantBuilder, Topic};
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{
    Context, Message, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher, QosProfile,
};
use std::net::{IpAddr, Ipv4Addr};
use std::time::Duration;

/// The longest a write waits for room in a reliable writer's window.
pub const WRITE_WAIT: Duration = Duration::from_millis(20);
/// How long the node stays after the last write, so that reliable writers can deliver
/// (and repair) their last samples before the participant leaves.
pub const LINGER: Duration = Duration::from_millis(500);
/// History depth of the pose topic.
pub const POSE_DEPTH: usize = 10;
/// History depth of `/tf` (tf2's `TransformBroadcaster`'s).
pub const TF_DEPTH: usize = 100;
/// The topic of the transforms.
pub const TF_TOPIC: &str = "/tf";

/// The domain id: the config's, else `ROS_DOMAIN_ID`, else 0.
pub fn domain_id(config: &Ros2Config) -> Result<u16, BridgeError> {
    if let Some(id) = config.domain_id {
        return Ok(id);
    }
    match std::env::var("ROS_DOMAIN_ID") {
        Ok(text) if !text.trim().is_empty() => text
            .trim()
            .parse::<u16>()
            .ok()
            .filter(|id| *id <= MAX_DOMAIN_ID)
            .ok_or(BridgeError::DomainEnv(text)),
        _ => Ok(0),
    }
}

/// Whether discovery and traffic stay on the loopback interface: the config's
/// `localhost_only`, or `ROS_LOCALHOST_ONLY=1`.
pub fn localhost_only(config: &Ros2Config) -> bool {
    config.localhost_only || std::env::var("ROS_LOCALHOST_ONLY").is_ok_and(|v| v.trim() == "1")
}

/// The topic `topic` (config key `key`) of ROS type `type_name` (package, name) on `node`.
pub(crate) fn ros_topic(
    node: &Node,
    key: &'static str,
    topic: &str,
    type_name: (&str, &str),
    qos: &QosProfile,
) -> Result<Topic, BridgeError> {
    node.create_topic(
        &topic_name(key, topic)?,
        MessageTypeName::new(type_name.0, type_name.1),
        qos,
    )
    .map_err(|e| setup(key)(e.to_string()))
}

/// A topic's writer and the topic's name (for errors).
struct Writer<M: Message> {
    topic: String,
    publisher: Publisher<M>,
}

impl<M: Message> Writer<M> {
    /// The topic `topic` (config key `key`) of ROS type `type_name` on `node`, and its
    /// writer.
    fn new(
        node: &mut Node,
        key: &'static str,
        topic: &str,
        type_name: (&str, &str),
        qos: &QosProfile,
    ) -> Result<Self, BridgeError> {
        let made = ros_topic(node, key, topic, type_name, qos)?;
        let publisher = node
            .create_publisher::<M>(&made, None)
            .map_err(|e| setup(key)(e.to_string()))?;
        Ok(Self {
            topic: topic.to_string(),
            publisher,
        })
    }

    /// The same when `topic` is configured (not empty).
    fn optional(
        node: &mut Node,
        key: &'static str,
        topic: &str,
        type_name: (&str, &str),
        qos: &QosProfile,
    ) -> Result<Option<Self>, BridgeError> {
        if topic.is_empty() {
            Ok(None)
        } else {
            Self::new(node, key, topic, type_name, qos).map(Some)
        }
    }

    fn publish(&self, message: M) -> Result<(), BridgeError> {
        self.publisher
            .publish(message)
            .map_err(|e| BridgeError::Write {
                topic: self.topic.clone(),
                message: e.to_string(),
            })
    }
}

/// Publishes on `writer` when there is one.
fn publish_if<M: Message>(writer: &Option<Writer<M>>, message: M) -> Result<(), BridgeError> {
    writer.as_ref().map_or(Ok(()), |w| w.publish(message))
}

/// A ROS 2 node with the pose, path, odometry, `/tf` and diagnostics writers.
pub struct DdsSink {
    poses: Writer<PoseStamped>,
    path: Option<Writer<Path>>,
    odometry: Option<Writer<Odometry>>,
    tf: Option<Writer<TfMessage>>,
    diagnostics: Option<Writer<DiagnosticArray>>,
    // Dropped last: the writers belong to it.
    _node: Node,
}

pub(crate) fn setup(what: &'static str) -> impl FnOnce(String) -> BridgeError {
    move |message| BridgeError::Setup { what, message }
}

fn name(
    key: &'static str,
    value: &str,
    made: Result<Name, impl std::fmt::Display>,
) -> Result<Name, BridgeError> {
    made.map_err(|e| BridgeError::Name {
        key,
        value: value.to_string(),
        message: e.to_string(),
    })
}

/// `topic` with its leading `/` (a relative topic is taken from the root).
fn absolute_topic(topic: &str) -> String {
    if topic.starts_with('/') {
        topic.to_string()
    } else {
        format!("/{topic}")
    }
}

/// Splits a topic `/a/b/c` into ros2-client's namespace `/a/b` and base name `c`.
pub(crate) fn topic_name(key: &'static str, topic: &str) -> Result<Name, BridgeError> {
    let absolute = absolute_topic(topic);
    let (namespace, base) = absolute.rsplit_once('/').unwrap_or(("", &absolute));
    let namespace = if namespace.is_empty() { "/" } else { namespace };
    name(key, topic, Name::new(namespace, base))
}

/// Joins `config`'s domain (loopback only when it says so) as the node `node_name`;
/// returns the node and the domain id.
pub fn join(config: &Ros2Config, node_name: &str) -> Result<(Node, u16), BridgeError> {
    let domain = domain_id(config)?;
    let mut participant = DomainParticipantBuilder::new(domain);
    if localhost_only(config) {
        participant = participant.with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)]);
    }
    let participant = participant
        .build()
        .map_err(|e| setup("participant")(e.to_string()))?;
    let context = Context::from_domain_participant(participant)
        .map_err(|e| setup("context")(e.to_string()))?;
    let name = NodeName::new("/", node_name).map_err(|e| BridgeError::Name {
        key: "node_name",
        value: node_name.to_string(),
        message: e.to_string(),
    })?;
    let node = context
        .new_node(name, NodeOptions::new().enable_rosout(false))
        .map_err(|e| setup("node")(e.to_string()))?;
    Ok((node, domain))
}

impl DdsSink {
    /// Joins the domain and makes the node, topics and writers `config` names.
    pub fn new(config: &Ros2Config) -> Result<Self, BridgeError> {
        let (mut node, domain) = join(config, &config.node_name)?;
        let reliable =
            QosProfile::publisher_default().reliability_reliable(WhenFull::Wait(WRITE_WAIT));
        let pose_qos = reliable
            .clone()
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth: POSE_DEPTH });
        let poses = Writer::new(
            &mut node,
            "pose_topic",
            &config.pose_topic,
            POSE_STAMPED_TYPE,
            &pose_qos,
        )?;
        let path_qos = reliable
            .durability(Durability::TransientLocal)
            .history(History::KeepLast { depth: 1 });
        let path = Writer::optional(
            &mut node,
            "path_topic",
            &config.path_topic,
            PATH_TYPE,
            &path_qos,
        )?;
        let odometry = Writer::optional(
            &mut node,
            "odom_topic",
            &config.odom_topic,
            ODOMETRY_TYPE,
            &pose_qos,
        )?;
        let tf_qos = pose_qos
            .clone()
            .history(History::KeepLast { depth: TF_DEPTH });
        let tf = Writer::optional(
            &mut node,
            "tf",
            if config.tf { TF_TOPIC } else { "" },
            TF_MESSAGE_TYPE,
            &tf_qos,
        )?;
        let diagnostics = Writer::optional(
            &mut node,
            "diagnostics_topic",
            &config.diagnostics_topic,
            DIAGNOSTIC_ARRAY_TYPE,
            &pose_qos,
        )?;
        let wait = Duration::from_millis(config.wait_for_subscribers_ms);
        if !wait.is_zero() {
            let mut topics = vec![config.pose_topic.as_str()];
            topics.extend((!config.odom_topic.is_empty()).then_some(config.odom_topic.as_str()));
            topics.extend(config.tf.then_some(TF_TOPIC));
            wait_for_subscribers(&node, &topics, wait);
        }
        tracing::info!(
            "ROS 2 node {} on domain {domain}{}: {} and {}",
            config.node_name,
            if localhost_only(config) {
                " (localhost only)"
            } else {
                ""
            },
            config.pose_topic,
            if config.path_topic.is_empty() {
                "no path"
            } else {
                &config.path_topic
            }
        );
        Ok(Self {
            poses,
            path,
            odometry,
            tf,
            diagnostics,
            _node: node,
        })
    }
}

/// Waits until each of `topics` has a subscriber discovered on the domain, at most `wait`
/// (then says which have none and goes on): a volatile topic's messages reach only the
/// subscribers matched when they are written.
fn wait_for_subscribers(node: &Node, topics: &[&str], wait: Duration) {
    let deadline = std::time::Instant::now() + wait;
    let absolute: Vec<String> = topics.iter().map(|t| absolute_topic(t)).collect();
    loop {
        let missing: Vec<&str> = topics
            .iter()
            .zip(&absolute)
            .filter(|(_, a)| node.subscription_count(a) == 0)
            .map(|(t, _)| *t)
            .collect();
        if missing.is_empty() {
            tracing::info!("a subscriber on each of {topics:?}");
            return;
        }
        if std::time::Instant::now() >= deadline {
            tracing::warn!(
                "no subscriber on {missing:?} after {wait:?} (ros2.wait_for_subscribers_ms): \
                 publishing anyway"
            );
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

impl PoseSink for DdsSink {
    fn pose(&mut self, message: PoseStamped) -> Result<(), BridgeError> {
        self.poses.publish(message)
    }

    fn path(&mut self, message: Path) -> Result<(), BridgeError> {
        publish_if(&self.path, message)
    }

    fn wants_path(&self) -> bool {
        self.path.is_some()
    }

    fn odometry(&mut self, message: Odometry) -> Result<(), BridgeError> {
        publish_if(&self.odometry, message)
    }

    fn transform(&mut self, message: TfMessage) -> Result<(), BridgeError> {
        publish_if(&self.tf, message)
    }

    fn diagnostics(&mut self, message: DiagnosticArray) -> Result<(), BridgeError> {
        publish_if(&self.diagnostics, message)
    }

    fn finish(&mut self) {
        std::thread::sleep(LINGER);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics_split_into_namespace_and_name() {
        for (topic, dds) in [
            ("/linetrack/pose", "rt/linetrack/pose"),
            ("pose", "rt/pose"),
            ("/a/b/path", "rt/a/b/path"),
        ] {
            let name = topic_name("pose_topic", topic).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(
                name.to_dds_name(
                    "rt",
                    &NodeName::new("/", "n").unwrap_or_else(|e| panic!("{e}")),
                    ""
                ),
                dds
            );
        }
    }
}
