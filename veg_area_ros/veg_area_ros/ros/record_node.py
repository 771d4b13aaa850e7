"""record_node: records topics into a rosbag2 folder (MCAP by default, sqlite3 on request) with the
pure-Python `rosbags` writer: messages are taken serialized (`raw=True`) and written as they came, never
deserialized. Topic types are discovered on the graph; a topic that appears late is picked up when it does.
Each topic's offered QoS goes into metadata.yaml as rosbag2 writes it, so `ros2 bag play` (and `veg-area
play`) offer it again: a latched camera_info is replayed latched. Ctrl-C / SIGTERM or `duration` closes the
bag properly; after a SIGKILL, `veg-area bag-recover` rebuilds it. A wanted topic never seen is a warning and
exit code 1 (a mistyped name records nothing)."""

from __future__ import annotations

import datetime as dt
import os
import time
from pathlib import Path

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..bags import STORAGES, BagError, BagRecorder, OfferedQos, topic_name_problem
from ..cdr import ImageMessageError, stamp_ns
from .messages import message_class
from .params import declare
from .run import run_nodes

DEFAULT_TOPICS = ["image_raw", "camera_info", "projected_area", "projected_area/info"]


STAMPED_TYPES = {"sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo", "sensor_msgs/msg/CompressedImage",
                 "veg_area_msgs/msg/ProjectedArea"}


def process_start_ns() -> int:
    """When this process started (the user's command), wall clock ns; now where /proc cannot say."""
    try:
        fields = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
        boot = next(int(line.split()[1]) for line in Path("/proc/stat").read_text().splitlines()
                    if line.startswith("btime"))
        return int((boot + int(fields[19]) / os.sysconf("SC_CLK_TCK")) * 1e9)
    except (OSError, ValueError, IndexError, StopIteration):
        return time.time_ns()


class RecordNode(Node):
    recorder: BagRecorder | None = None  # until the bag is created (a node that cannot start has none)

    def __init__(self, name: str = "record_node", **kwargs):
        super().__init__(name, **kwargs)
        self.wanted = list(declare(self, "topics", DEFAULT_TOPICS, "Topics to record.", read_only=True))
        self.everything = declare(self, "all", False, "Record every topic on the graph (then `topics` is ignored).",
                                  read_only=True)
        output = declare(self, "output", "", "Bag folder to create ('' = veg_area_<date-time>).", read_only=True)
        storage = declare(self, "storage", "mcap", "rosbag2 storage.", choices=tuple(STORAGES), read_only=True)
        duration = declare(self, "duration", 0.0, "Stop after this many seconds (0 = until Ctrl-C).", low=0.0,
                           high=1e9, read_only=True)
        self.stop_requested = False
        self.exit_code = 0
        self.started_ns = process_start_ns()
        self.first_stamp: dict[str, tuple[int, int]] = {}  # stamped topic -> (first stamp, messages by 1 s later)
        if duration > 0:
            self.create_timer(duration, self._stop)
        self.output = output or dt.datetime.now().strftime("veg_area_%Y%m%d_%H%M%S")
        for topic in self.wanted:
            problem = topic_name_problem(topic)
            if problem:
                raise BagError(problem)
        self.recorder = BagRecorder(self.output, storage)
        self.recording: dict[str, str] = {}  # resolved topic -> type
        self.topic_subscriptions = []
        self._discover()
        self.discovery = self.create_timer(0.2, self._discover)
        what = "every topic" if self.everything else ", ".join(self.wanted)
        self.get_logger().info(f"recording {what} into {self.output} ({storage})")
        if self.recorder.crash_safety_problem:
            self.get_logger().warning(self.recorder.crash_safety_problem)

    def _stop(self) -> None:
        self.stop_requested = True

    def _offered(self, topic: str) -> list[OfferedQos]:
        return [OfferedQos("best_effort" if q.reliability == ReliabilityPolicy.BEST_EFFORT else "reliable",
                           "transient_local" if q.durability == DurabilityPolicy.TRANSIENT_LOCAL else "volatile",
                           "keep_all" if q.history == HistoryPolicy.KEEP_ALL else "keep_last", max(int(q.depth), 1))
                for q in (info.qos_profile for info in self.get_publishers_info_by_topic(topic))]

    def _qos_for(self, topic: str) -> QoSProfile:
        """What every publisher offers: best effort if any publisher is (camera images), transient local if all
        are (latched camera_info), so that no publisher is left unmatched."""
        offered = [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
        best_effort = any(q.reliability == ReliabilityPolicy.BEST_EFFORT for q in offered)
        latched = bool(offered) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                          reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)

    def _discover(self) -> None:
        types = dict(self.get_topic_names_and_types())
        if self.everything:  # our own parameter and log topics are not data
            self.wanted = [t for t in types if t not in ("/rosout", "/parameter_events")]
        for topic in self.wanted:
            resolved = self.resolve_topic_name(topic)
            if resolved in self.recording or resolved not in types or not self.get_publishers_info_by_topic(resolved):
                continue
            msgtype = types[resolved][0]
            try:
                self.recorder.add_topic(resolved, msgtype, self._offered(resolved))
                cls = message_class(msgtype)
            except (BagError, ImportError, AttributeError, ValueError) as exc:
                self.get_logger().error(f"{resolved} not recorded: {exc}")
                self.recording[resolved] = msgtype
                continue
            self.recording[resolved] = msgtype
            self.topic_subscriptions.append(self.create_subscription(
                cls, resolved, lambda data, info, t=resolved: self._write(t, data, info), self._qos_for(resolved),
                raw=True))
            self.get_logger().info(f"recording {resolved} ({msgtype})")

    def _write(self, topic: str, data: bytes, info: dict | None = None) -> None:
        # MCAP's publish time: when the sender's middleware sent it (rclpy's message info), as rosbag2 keeps it
        sent = (info or {}).get("source_timestamp") or None
        if self.recorder.write_problem:  # said once; the node stops after this callback
            return
        try:
            self.recorder.write(topic, self.get_clock().now().nanoseconds, data, sent)
        except BagError as exc:
            self.get_logger().error(str(exc))
            self.exit_code, self.stop_requested = 1, True
            return
        if self.recording[topic] in STAMPED_TYPES or self.recording[topic].endswith("Stamped"):
            self._note_start(topic, data)

    def _note_start(self, topic: str, data: bytes) -> None:
        """What the bag misses before its first message of a stamped topic: the time from the command to that
        message's stamp (discovery takes 1-4 s), said at once and, with the rate of the first second, in frames
        at the end."""
        try:
            stamp = stamp_ns(data)
        except ImageMessageError:
            return
        if topic not in self.first_stamp:
            self.first_stamp[topic] = (stamp, 1)
            gap = (stamp - self.started_ns) / 1e9
            if gap > 0:
                self.get_logger().warning(f"{topic}: the first message recorded was stamped {gap:.2f} s after the "
                                          "command started; what was published before it is not in the bag")
            return
        first, count = self.first_stamp[topic]
        if stamp - first <= 1_000_000_000:
            self.first_stamp[topic] = (first, count + 1)

    def missed_before_start(self) -> dict[str, tuple[float, float | None]]:
        """Stamped topic -> (seconds from the command to its first recorded message, estimated messages missed
        in that time at the rate of its first recorded second; None when one message cannot give a rate)."""
        missed = {}
        for topic, (first, count) in self.first_stamp.items():
            gap = max(0.0, (first - self.started_ns) / 1e9)
            missed[topic] = (gap, gap * (count - 1) if count > 1 else None)
        return missed

    def destroy_node(self) -> None:
        if self.recorder is None:  # it could not start (the reason is said): nothing to close or count
            super().destroy_node()
            return
        counts = ", ".join(f"{t} {n}" for t, n in self.recorder.counts.items())
        try:
            self.recorder.close()
            self.get_logger().info(f"bag {self.output} closed: {counts or 'no messages'}")
        except BagError as exc:
            self.get_logger().error(f"{exc}; messages taken: {counts or 'none'}")
            self.exit_code = 1
        for topic, (gap, frames) in self.missed_before_start().items():
            if gap > 0:
                estimate = f", about {frames:.0f} messages" if frames is not None else ""
                self.get_logger().warning(f"{topic}: not recorded in the first {gap:.2f} s after the command"
                                          f"{estimate} (subscribing waits for discovery)")
        never = [t for t in (self.resolve_topic_name(w) for w in self.wanted) if t not in self.recording]
        if never:
            self.get_logger().warning(f"never seen on the graph, not recorded: {', '.join(never)} "
                                      "(a mistyped name? `ros2 topic list` shows what is published)")
            self.exit_code = 1
        elif self.everything and not self.recording:
            domain = os.environ.get("ROS_DOMAIN_ID", "0")
            self.get_logger().warning(f"no topic was seen on the graph (all): is anything publishing, on ROS_DOMAIN_ID "
                                      f"{domain} and within ROS_AUTOMATIC_DISCOVERY_RANGE?")
            self.exit_code = 1
        empty = [t for t in self.recording if not self.recorder.counts.get(t) and not self.everything
                 and not self.recorder.write_problem]
        if empty:  # seen and subscribed, yet nothing came: a QoS that did not match, or a publisher that stopped
            self.get_logger().warning(f"no message recorded of {', '.join(empty)} although it was on the graph "
                                      "(its publishers' QoS did not match, or they published nothing)")
            self.exit_code = 1
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_nodes([RecordNode], args)


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv))
