"""An independent ROS 2 subscriber for the end-to-end test: Eclipse Cyclone DDS (its Python
binding, a C DDS implementation unrelated to RustDDS) with the ROS 2 message types defined
here under their DDS names (geometry_msgs::msg::dds_::PoseStamped_, nav_msgs::msg::dds_::Path_,
nav_msgs::msg::dds_::Odometry_, tf2_msgs::msg::dds_::TFMessage_,
diagnostic_msgs::msg::dds_::DiagnosticArray_).

Reads /linetrack/pose (PoseStamped), /linetrack/path (Path), /linetrack/odom (Odometry),
/tf (TFMessage) and /diagnostics (DiagnosticArray) on one domain, loopback only, and writes one JSON line per message to --out.
Touches --ready once its readers exist. Ends on SIGTERM/SIGINT or after --timeout seconds.

usage: listen.py --domain N --out FILE --ready FILE [--pose-topic T] [--path-topic T]
                 [--odom-topic T] [--timeout S]
"""

import argparse
import json
import os
import signal
import sys
import time

# Discovery and data on loopback only, no multicast: unicast SPDP to 127.0.0.1 at the
# well-known ports of participant indices 0..19 (the bridge's RustDDS takes one of them).
os.environ["CYCLONEDDS_URI"] = (
    "<CycloneDDS><Domain id='any'><General>"
    "<Interfaces><NetworkInterface address='127.0.0.1'/></Interfaces>"
    "<AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
    "<MaxAutoParticipantIndex>20</MaxAutoParticipantIndex>"
    "<Peers><Peer address='127.0.0.1'/></Peers></Discovery>"
    "</Domain></CycloneDDS>"
)

from dataclasses import dataclass  # noqa: E402

from cyclonedds.core import Policy, Qos, WaitSet, ReadCondition, ViewState, InstanceState, SampleState  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import array, float64, int32, sequence, uint8, uint32  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Header
    pose: Pose


@dataclass
class Path(IdlStruct, typename="nav_msgs::msg::dds_::Path_"):
    header: Header
    poses: sequence[PoseStamped]


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3
    angular: Vector3


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: array[float64, 36]


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist
    covariance: array[float64, 36]


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped]


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str
    value: str


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: uint8
    name: str
    message: str
    hardware_id: str
    values: sequence[KeyValue]


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header
    status: sequence[DiagnosticStatus]


def xyz(v):
    return [v.x, v.y, v.z]


def odometry_json(o):
    return {
        "sec": o.header.stamp.sec,
        "nanosec": o.header.stamp.nanosec,
        "frame_id": o.header.frame_id,
        "child_frame_id": o.child_frame_id,
        "position": xyz(o.pose.pose.position),
        "orientation": [o.pose.pose.orientation.x, o.pose.pose.orientation.y,
                        o.pose.pose.orientation.z, o.pose.pose.orientation.w],
        "covariance": list(o.pose.covariance),
        "linear": xyz(o.twist.twist.linear),
        "angular": xyz(o.twist.twist.angular),
        "twist_covariance": list(o.twist.covariance),
    }


def transform_json(t):
    return {
        "sec": t.header.stamp.sec,
        "nanosec": t.header.stamp.nanosec,
        "frame_id": t.header.frame_id,
        "child_frame_id": t.child_frame_id,
        "position": xyz(t.transform.translation),
        "orientation": [t.transform.rotation.x, t.transform.rotation.y,
                        t.transform.rotation.z, t.transform.rotation.w],
    }


def pose_json(p):
    return {
        "sec": p.header.stamp.sec,
        "nanosec": p.header.stamp.nanosec,
        "frame_id": p.header.frame_id,
        "position": [p.pose.position.x, p.pose.position.y, p.pose.position.z],
        "orientation": [p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z, p.pose.orientation.w],
    }


def dds_topic(ros_topic):
    return "rt" + (ros_topic if ros_topic.startswith("/") else "/" + ros_topic)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--out", required=True)
    parser.add_argument("--ready", required=True)
    parser.add_argument("--pose-topic", default="/linetrack/pose")
    parser.add_argument("--path-topic", default="/linetrack/path")
    parser.add_argument("--odom-topic", default="/linetrack/odom")
    parser.add_argument("--timeout", type=float, default=300.0)
    args = parser.parse_args()

    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))

    participant = DomainParticipant(args.domain)
    # The bridge's QoS: reliable keep-last 10 volatile poses, a transient-local path.
    pose_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10),
                   Policy.Durability.Volatile)
    path_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1),
                   Policy.Durability.TransientLocal)
    pose_reader = DataReader(participant, Topic(participant, dds_topic(args.pose_topic), PoseStamped), qos=pose_qos)
    path_reader = DataReader(participant, Topic(participant, dds_topic(args.path_topic), Path), qos=path_qos)
    odom_reader = DataReader(participant, Topic(participant, dds_topic(args.odom_topic), Odometry), qos=pose_qos)
    # tf2's broadcaster profile: reliable, keep-last 100, volatile.
    tf_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(100),
                 Policy.Durability.Volatile)
    tf_reader = DataReader(participant, Topic(participant, "rt/tf", TFMessage), qos=tf_qos)
    diagnostics_reader = DataReader(participant, Topic(participant, "rt/diagnostics", DiagnosticArray),
                                    qos=pose_qos)
    waitset = WaitSet(participant)
    any_sample = SampleState.Any | ViewState.Any | InstanceState.Any
    waitset.attach(ReadCondition(pose_reader, any_sample))
    waitset.attach(ReadCondition(path_reader, any_sample))
    waitset.attach(ReadCondition(odom_reader, any_sample))
    waitset.attach(ReadCondition(tf_reader, any_sample))
    waitset.attach(ReadCondition(diagnostics_reader, any_sample))
    open(args.ready, "w").close()

    deadline = time.monotonic() + args.timeout
    with open(args.out, "w") as out:
        while not stop and time.monotonic() < deadline:
            waitset.wait(duration(milliseconds=100))
            # Skipped: the invalid samples that say a writer left (no data).
            for sample in pose_reader.take(N=100):
                if not isinstance(sample, PoseStamped):
                    continue
                out.write(json.dumps({"topic": "pose", **pose_json(sample)}) + "\n")
            for sample in path_reader.take(N=10):
                if not isinstance(sample, Path):
                    continue
                out.write(json.dumps({
                    "topic": "path",
                    "frame_id": sample.header.frame_id,
                    "sec": sample.header.stamp.sec,
                    "nanosec": sample.header.stamp.nanosec,
                    "poses": [pose_json(p) for p in sample.poses],
                }) + "\n")
            for sample in odom_reader.take(N=100):
                if not isinstance(sample, Odometry):
                    continue
                out.write(json.dumps({"topic": "odom", **odometry_json(sample)}) + "\n")
            for sample in tf_reader.take(N=100):
                if not isinstance(sample, TFMessage):
                    continue
                out.write(json.dumps({
                    "topic": "tf",
                    "transforms": [transform_json(t) for t in sample.transforms],
                }) + "\n")
            for sample in diagnostics_reader.take(N=10):
                if not isinstance(sample, DiagnosticArray):
                    continue
                out.write(json.dumps({
                    "topic": "diagnostics",
                    "sec": sample.header.stamp.sec,
                    "nanosec": sample.header.stamp.nanosec,
                    "status": [{
                        "level": s.level,
                        "name": s.name,
                        "message": s.message,
                        "values": {kv.key: kv.value for kv in s.values},
                    } for s in sample.status],
                }) + "\n")
            out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
