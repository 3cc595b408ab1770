"""An independent ROS 2 stereo camera for the end-to-end test: Eclipse Cyclone DDS (its Python
binding) publishing sensor_msgs/Image and sensor_msgs/CameraInfo under their DDS names
(sensor_msgs::msg::dds_::Image_, sensor_msgs::msg::dds_::CameraInfo_), as a ROS 2 stereo
driver's rectified topics: /stereo/{left,right}/image_rect and /stereo/{left,right}/camera_info.

The frames come from --frames DIR, written by the test: frames.json (width, height, fx, cx, cy,
baseline_m, stamps_ns, and the raw files) and left.raw / right.raw (the rectified 8-bit frames,
one after the other). Each pair goes out with its CameraInfo, stamped with the frame's stamp;
then the camera waits for the pipeline's nav_msgs/Odometry of that stamp on --odom-topic before
the next pair (so that no frame's fate depends on scheduling). A few pairs go out as rgb8,
bgr8 and mono16 (the same grey). After pair --inject-after it publishes what must not become
a pose: an unpaired left image, an unpaired right image, and three pairs with a malformed
image (an unknown encoding, the wrong size, a step shorter than a row); the run goes on with
the next pair.

Writes one JSON line per published pair to --out, and exits 0 once the last pair's Odometry
came, 2 when one did not come within --timeout seconds.

usage: publish.py --domain N --frames DIR --out FILE [--odom-topic T] [--inject-after K]
                  [--timeout S]
"""

import argparse
import array
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
# The ROS 2 types and the loopback-only Cyclone DDS set-up of the subscriber.
from listen import Header, Odometry, Time, dds_topic  # noqa: E402

from dataclasses import dataclass  # noqa: E402

from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import array as idl_array, float64, sequence, uint8, uint32  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


@dataclass
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header
    height: uint32
    width: uint32
    encoding: str
    is_bigendian: uint8
    step: uint32
    data: sequence[uint8]


@dataclass
class RegionOfInterest(IdlStruct, typename="sensor_msgs::msg::dds_::RegionOfInterest_"):
    x_offset: uint32
    y_offset: uint32
    height: uint32
    width: uint32
    do_rectify: bool


@dataclass
class CameraInfo(IdlStruct, typename="sensor_msgs::msg::dds_::CameraInfo_"):
    header: Header
    height: uint32
    width: uint32
    distortion_model: str
    d: sequence[float64]
    k: idl_array[float64, 9]
    r: idl_array[float64, 9]
    p: idl_array[float64, 12]
    binning_x: uint32
    binning_y: uint32
    roi: RegionOfInterest


def stamp(ns):
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def encoded(grey, encoding):
    """The 8-bit grey bytes as `encoding` (the same grey once read back) and the bytes a pixel."""
    if encoding == "mono8":
        return grey, 1
    if encoding in ("rgb8", "bgr8"):
        return bytes(b for v in grey for b in (v, v, v)), 3
    if encoding == "mono16":
        return array.array("H", (v * 257 for v in grey)).tobytes(), 2
    raise ValueError(encoding)


class Camera:
    def __init__(self, participant, meta):
        qos = Qos(Policy.Reliability.Reliable(duration(seconds=2)), Policy.History.KeepLast(20),
                  Policy.Durability.Volatile, Policy.DataRepresentation(use_cdrv0_representation=True))
        self.meta = meta
        self.images = {}
        self.infos = {}
        for side in ("left", "right"):
            self.images[side] = DataWriter(
                participant, Topic(participant, dds_topic(f"/stereo/{side}/image_rect"), Image), qos=qos)
            self.infos[side] = DataWriter(
                participant, Topic(participant, dds_topic(f"/stereo/{side}/camera_info"), CameraInfo), qos=qos)

    def writers(self):
        return list(self.images.values()) + list(self.infos.values())

    def info(self, side, ns):
        m = self.meta
        fx, cx, cy = m["fx"], m["cx"], m["cy"]
        tx = 0.0 if side == "left" else -fx * m["baseline_m"]
        return CameraInfo(
            header=Header(stamp=stamp(ns), frame_id=f"stereo_{side}"),
            height=m["height"], width=m["width"], distortion_model="plumb_bob", d=[0.0] * 5,
            k=[fx, 0.0, cx, 0.0, fx, cy, 0.0, 0.0, 1.0], r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p=[fx, 0.0, cx, tx, 0.0, fx, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
            binning_x=0, binning_y=0,
            roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))

    def image(self, side, ns, grey, encoding="mono8", width=None, height=None, step=None):
        width = width or self.meta["width"]
        height = height or self.meta["height"]
        data, size = encoded(grey, encoding) if encoding in ("mono8", "rgb8", "bgr8", "mono16") else (grey, 1)
        self.images[side].write(Image(
            header=Header(stamp=stamp(ns), frame_id=f"stereo_{side}"), height=height, width=width,
            encoding=encoding, is_bigendian=0, step=step or width * size, data=data))

    def pair(self, ns, left, right, encoding="mono8"):
        for side in ("left", "right"):
            self.infos[side].write(self.info(side, ns))
        self.image("left", ns, left, encoding)
        self.image("right", ns, right, encoding)


def wait_for(what, ready, timeout):
    deadline = time.monotonic() + timeout
    while not ready():
        if time.monotonic() > deadline:
            print(f"publish.py: {what} within {timeout} s", file=sys.stderr)
            sys.exit(2)
        time.sleep(0.01)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--frames", required=True)
    parser.add_argument("--out", required=True)
    parser.add_argument("--odom-topic", default="/linetrack/odom")
    parser.add_argument("--inject-after", type=int, default=40)
    parser.add_argument("--timeout", type=float, default=60.0)
    args = parser.parse_args()

    with open(os.path.join(args.frames, "frames.json")) as f:
        meta = json.load(f)
    frame_bytes = meta["width"] * meta["height"]
    raw = {}
    for side in ("left", "right"):
        with open(os.path.join(args.frames, meta[side]), "rb") as f:
            raw[side] = f.read()
    stamps = meta["stamps_ns"]

    participant = DomainParticipant(args.domain)
    camera = Camera(participant, meta)
    odom_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10),
                   Policy.Durability.Volatile)
    odometry = DataReader(participant, Topic(participant, dds_topic(args.odom_topic), Odometry), qos=odom_qos)
    wait_for("no linetrack-ros2-source subscribed",
             lambda: all(w.get_matched_subscriptions() for w in camera.writers()), args.timeout)
    wait_for("no Odometry publisher", lambda: odometry.get_matched_publications(), args.timeout)

    came = set()

    def odometry_of(ns):
        def arrived():
            for o in odometry.take(N=100):
                if isinstance(o, Odometry):
                    came.add(o.header.stamp.sec * 1_000_000_000 + o.header.stamp.nanosec)
            return ns in came
        return arrived

    encodings = {10: "rgb8", 11: "bgr8", 12: "mono16"}
    with open(args.out, "w") as out:
        for i, ns in enumerate(stamps):
            left = raw["left"][i * frame_bytes:(i + 1) * frame_bytes]
            right = raw["right"][i * frame_bytes:(i + 1) * frame_bytes]
            encoding = encodings.get(i, "mono8")
            camera.pair(ns, left, right, encoding)
            out.write(json.dumps({"pair": i, "stamp_ns": ns, "encoding": encoding}) + "\n")
            out.flush()
            wait_for(f"no Odometry stamped {ns} (pair {i})", odometry_of(ns), args.timeout)
            if i == args.inject_after:
                inject(camera, ns, left, right, out)
    return 0


def inject(camera, ns, left, right, out):
    """What must not become a pose, between pair `ns` and the next (1 to 5 ms after it)."""
    ms = 1_000_000
    camera.image("left", ns + 1 * ms, left)
    camera.image("right", ns + 2 * ms, right)
    width, height = camera.meta["width"], camera.meta["height"]
    bad = [
        ("encoding", {"encoding": "yuv422", "step": 2 * width}, left + left),
        ("size", {"width": width - 112, "height": height}, left[: (width - 112) * height]),
        ("step", {"step": width - 1}, left[: (width - 1) * height]),
    ]
    for k, (what, fields, data) in enumerate(bad):
        t = ns + (3 + k) * ms
        for side in ("left", "right"):
            camera.infos[side].write(camera.info(side, t))
        camera.image("left", t, data, **fields)
        camera.image("right", t, right)
        out.write(json.dumps({"malformed": what, "stamp_ns": t}) + "\n")
    out.write(json.dumps({"unpaired": ["left", "right"], "stamp_ns": [ns + ms, ns + 2 * ms]}) + "\n")
    out.flush()


if __name__ == "__main__":
    sys.exit(main())
