"""What a node tells its log about its inputs and outputs: throttled warnings that count what they hid, a
watch that says why no frame comes, and publishing that survives back-pressure."""

from __future__ import annotations

import os
import time
from collections.abc import Callable

from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.node import Node
from rclpy.publisher import Publisher

from ..transport import choose_transport


class CountedWarnings:
    """Throttled log lines that say what the throttle hid. Throttled per kind and detail (a new problem is
    always shown); each line carries how many of its kind came so far and how many like it were not shown
    since its last line (rclpy's throttle drops them unsaid)."""

    def __init__(self, logger: RcutilsLogger, period_s: float = 5.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._logger, self._period, self._clock = logger, period_s, clock
        self._total: dict[str, int] = {}
        self._hidden: dict[tuple[str, str], int] = {}
        self._last: dict[tuple[str, str], float] = {}

    def __call__(self, kind: str, detail: str, level: str = "warning", like: str | None = None) -> None:
        """`like`: what makes two lines alike for the throttle, when the detail's numbers change every time."""
        self._total[kind] = self._total.get(kind, 0) + 1
        key, now = (kind, detail if like is None else like), self._clock()
        if key in self._last and now - self._last[key] < self._period:
            self._hidden[key] = self._hidden.get(key, 0) + 1
            return
        if len(self._last) > 1000:  # details with ever-new text must not grow this without bound
            self._last.clear()
        hidden = self._hidden.pop(key, 0)
        since = f", {hidden} like it not shown since its last line" if hidden else ""
        getattr(self._logger, level)(f"{kind}: {detail} ({self._total[kind]} so far{since})")
        self._last[key] = now

    def total(self, kind: str) -> int:
        return self._total.get(kind, 0)


def publish_safely(node: Node, publisher: Publisher, msg: object) -> bool:
    """Publish; a transport under back-pressure raises RCLError: log it (throttled) and go on. After Ctrl-C
    (the context is shut down) there is nobody to tell: nothing is sent, nothing logged."""
    if not node.context.ok():
        return False
    try:
        publisher.publish(msg)
        return True
    except Exception as exc:  # rclpy raises RCLError (not importable by a stable name) or RuntimeError
        node.get_logger().warning(f"publishing on {publisher.topic_name} failed: {exc}", throttle_duration_sec=5.0)
        return False


QUIET_INPUT_S = 10.0  # a node without frames for this long says why it may be


class InputWatch:
    """Says in the log, every QUIET_INPUT_S without a frame, whether a publisher of the node's image topic has
    matched at all, with the transport in use: the first thing to check when a camera gives no Af."""

    def __init__(self, node: Node, topic: str):
        self.node, self.topic = node, node.resolve_topic_name(topic)
        self.transport = choose_transport(dict(os.environ)).description
        self.frames = 0
        self._seen_at_last_check = 0
        node.create_timer(QUIET_INPUT_S, self._check)

    def frame(self) -> None:
        self.frames += 1

    def _check(self) -> None:
        if self.frames > self._seen_at_last_check:
            self._seen_at_last_check = self.frames
            return
        publishers = self.node.count_publishers(self.topic)
        if publishers == 0:
            reason = f"no publisher of {self.topic} matched"
        else:
            reason = f"{publishers} publisher(s) of {self.topic} matched but no frame arrived"
        self.node.get_logger().warning(f"{reason} in the last {QUIET_INPUT_S:g} s (transport: {self.transport}; "
                                       "another machine's nodes need the same transport and ROS_DOMAIN_ID)")
