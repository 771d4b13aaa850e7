"""record_node: records topics into a rosbag2 folder (MCAP by default, sqlite3 on request) with the
pure-Python `rosbags` writer: messages are taken serialized (`raw=True`) and written as they came, never
deserialized. Topic types are discovered on the graph; a topic that appears late is picked up when it does.
Each topic's offered QoS goes into metadata.yaml as rosbag2 writes it, so `ros2 bag play` (and `veg-area
play`) offer it again: a latched camera_info is replayed latched. Ctrl-C / SIGTERM or `duration` closes the
bag properly; after a SIGKILL, `veg-area bag-recover` rebuilds it. A wanted topic never seen is a warning and
exit code 1 (a mistyped name records nothing)."""

from __future__ import annotations

import datetime as dt
import importlib

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..bags import STORAGES, BagError, BagRecorder, OfferedQos
from .common import declare

DEFAULT_TOPICS = ["image_raw", "camera_info", "projected_area", "projected_area/info"]


def message_class(msgtype: str):
    """'sensor_msgs/msg/Image' -> the rclpy message class."""
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


class RecordNode(Node):
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
        if duration > 0:
            self.create_timer(duration, self._stop)
        self.output = output or dt.datetime.now().strftime("veg_area_%Y%m%d_%H%M%S")
        self.recorder = BagRecorder(self.output, storage)
        self.recording: dict[str, str] = {}  # resolved topic -> type
        self.topic_subscriptions = []
        self._discover()
        self.discovery = self.create_timer(0.2, self._discover)
        what = "every topic" if self.everything else ", ".join(self.wanted)
        self.get_logger().info(f"recording {what} into {self.output} ({storage})")

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
                cls, resolved, lambda data, t=resolved: self._write(t, data), self._qos_for(resolved), raw=True))
            self.get_logger().info(f"recording {resolved} ({msgtype})")

    def _write(self, topic: str, data: bytes) -> None:
        self.recorder.write(topic, self.get_clock().now().nanoseconds, data)

    def destroy_node(self) -> None:
        self.recorder.close()
        counts = ", ".join(f"{t} {n}" for t, n in self.recorder.counts.items())
        self.get_logger().info(f"bag {self.output} closed: {counts or 'no messages'}")
        never = [t for t in (self.resolve_topic_name(w) for w in self.wanted) if t not in self.recording]
        if never or (self.everything and not self.recording):
            self.get_logger().warning(f"never seen on the graph, not recorded: {', '.join(never) or 'any topic'} "
                                      "(a mistyped name? `ros2 topic list` shows what is published)")
            self.exit_code = 1
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    from .common import run_nodes

    return run_nodes([RecordNode], args)


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv))
