"""play_node: replays a rosbag2 bag as `ros2 bag play` does, for users without the ros2 CLI: every topic (or
those named) at the recorded pace (times `rate`), each offered with the QoS it was recorded with (a latched
camera_info is replayed latched; a bag without offered QoS is replayed reliable and volatile). Messages are
published serialized, never deserialized. Stops at the end of the bag."""

from __future__ import annotations

import time

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..bags import OfferedQos, play_messages, play_topics
from .messages import message_class
from .params import declare
from .run import run_nodes


def qos_profile(offered: OfferedQos) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_ALL if offered.history == "keep_all" else HistoryPolicy.KEEP_LAST,
                      depth=offered.depth,
                      reliability=ReliabilityPolicy.BEST_EFFORT if offered.reliability == "best_effort"
                      else ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if offered.durability == "transient_local"
                      else DurabilityPolicy.VOLATILE)


MATCH_SETTLE_S = 1.0  # a subscriber matched on the publisher's side: time for its own side to match too
LINGER_S = 1.0  # after the last message, before the publishers go

class PlayNode(Node):
    def __init__(self, name: str = "play_node", **kwargs):
        super().__init__(name, **kwargs)
        bag = declare(self, "bag", "", "The rosbag2 folder to replay.", read_only=True)
        names = [t for t in declare(self, "topics", [""], "Topics to replay ([''] = all).", read_only=True) if t]
        self.rate = declare(self, "rate", 1.0, "Pace: 1 = as recorded, 2 = twice as fast.", low=0.01, high=1000.0,
                            read_only=True)
        delay = declare(self, "delay", 1.0, "Seconds to wait before the first message (discovery).", low=0.0,
                        high=3600.0, read_only=True)
        self.wait_for_subscribers = declare(
            self, "wait_for_subscribers", 5.0, "After the delay, wait up to this long (s) until every replayed topic "
            "has a subscriber, so that a recorder or node started beside the player misses nothing.", low=0.0,
            high=3600.0, read_only=True)
        self.stop_requested = False
        self.exit_code = 0
        topics = play_topics(bag, names or None)
        self.publishers_by_topic = {}
        for topic in topics:
            offered = topic.replay_qos()
            self.publishers_by_topic[topic.name] = self.create_publisher(message_class(topic.msgtype), topic.name,
                                                                         qos_profile(offered))
            self.get_logger().info(f"replaying {topic.name} ({topic.msgtype}) {offered.reliability}, "
                                   f"{offered.durability}")
        self.messages = play_messages(bag, list(self.publishers_by_topic))
        self.pending = next(self.messages, None)
        self.published = 0
        self.matched_since: float | None = None  # since when every replayed topic has had a subscriber
        self.ended_at: float | None = None  # when the last message went
        self.first_recorded: int | None = None
        self.start = time.monotonic() + delay
        self.create_timer(0.001, self._play)

    def _subscribed(self) -> bool:
        """Every replayed topic has had a subscriber for MATCH_SETTLE_S, or the wait for them is over (the first
        message then goes). The publisher sees a match before the subscriber's side has completed it: a message
        sent at once can be lost, so the match is given time to settle."""
        now = time.monotonic()
        if self.first_recorded is not None or now >= self.start + self.wait_for_subscribers:
            return True
        if not all(publisher.get_subscription_count() > 0 for publisher in self.publishers_by_topic.values()):
            self.matched_since = None
            return False
        if self.matched_since is None:
            self.matched_since = now
        return now - self.matched_since >= MATCH_SETTLE_S

    def _play(self) -> None:
        now = time.monotonic()
        if now >= self.start and self.first_recorded is None:
            if not self._subscribed():
                return
            self.start = now  # the recorded pace counts from the first message
        while self.pending is not None and now >= self.start:
            topic, recorded, data = self.pending
            if self.first_recorded is None:
                self.first_recorded = recorded
            due = self.start + (recorded - self.first_recorded) * 1e-9 / self.rate
            if due > now:
                return
            self.publishers_by_topic[topic].publish(data)
            self.published += 1
            self.pending = next(self.messages, None)
        if self.pending is None and not self.stop_requested:
            # the last messages are delivered before the publishers go: a player that left at once lost them
            if self.ended_at is None:
                self.ended_at = now
            if now - self.ended_at < LINGER_S:
                return
            self.get_logger().info(f"end of the bag: {self.published} messages replayed")
            self.stop_requested = True


def main(args: list[str] | None = None) -> int:
    return run_nodes([PlayNode], args)


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv))
