"""The newest-frame hand-over between a fast producer (a subscription callback) and a slower consumer (the
area computation): one slot, a new frame replaces one not yet taken, and every replaced frame is counted.
Memory is bounded by one frame whatever the rates. No ROS here."""

from __future__ import annotations

import threading
from typing import Generic, TypeVar

T = TypeVar("T")


class LatestSlot(Generic[T]):
    def __init__(self) -> None:
        self._ready = threading.Condition()
        self._item: T | None = None
        self._closed = False
        self.received = 0  # frames put
        self.dropped = 0  # frames replaced before anybody took them

    def put(self, item: T) -> None:
        with self._ready:
            if self._item is not None:
                self.dropped += 1
            self._item = item
            self.received += 1
            self._ready.notify()

    def take(self, timeout: float | None = None) -> T | None:
        """The newest frame, waiting up to `timeout` s for one; None on timeout or once closed."""
        with self._ready:
            self._ready.wait_for(lambda: self._item is not None or self._closed, timeout)
            item, self._item = self._item, None
            return item

    def close(self) -> None:
        with self._ready:
            self._closed = True
            self._ready.notify_all()
