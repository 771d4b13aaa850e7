"""Which camera frames the area node measured and which it skipped. No ROS here.

The node measures in its image callback on a depth-1 best-effort subscription: while it measures, DDS keeps
only the newest frame and discards older ones inside the middleware, without a copy into Python (taking
every frame into Python and dropping it there fell well behind, bench/ros_pipeline.py). Frames
skipped that way never reach the node; they are counted from `camera_info`, which ROS camera drivers (and
camera_node) publish with every frame under that frame's stamp, from the first frame the node takes on. A
camera_info that is not per frame (one latched calibration) leaves the count unknown (None), never a wrong
number.
"""

from __future__ import annotations

from collections import deque

REMEMBERED = 256  # stamps kept on each side: far more than frames in flight between the two topics


class FrameTally:
    def __init__(self) -> None:
        self._announced: deque[int] = deque(maxlen=REMEMBERED)  # camera_info stamps not yet accounted for
        self._heard: deque[int] = deque(maxlen=REMEMBERED)  # every stamp announced (one frame heard twice is one)
        self._taken: deque[int] = deque(maxlen=REMEMBERED)  # frames whose camera_info may still come
        self._per_frame = False  # a taken frame's stamp was announced: camera_info comes with every frame
        self.received = 0  # frames taken
        self._skipped = 0  # frames announced after the first frame taken, never taken

    def announce(self, stamp_ns: int) -> None:
        """A camera_info with this stamp: a frame the camera published. The same stamp again (the node listens
        on two subscriptions, a latched one and one any publisher matches) is the same frame."""
        if stamp_ns in self._heard:
            return
        self._heard.append(stamp_ns)
        if stamp_ns in self._taken:  # its frame came first (two topics are not ordered)
            self._per_frame = True
            self._taken.remove(stamp_ns)
        elif not self._announced or stamp_ns > self._announced[-1]:  # a latched re-send is not a new frame
            self._announced.append(stamp_ns)

    def took(self, stamp_ns: int) -> None:
        """A frame with this stamp reached the node; announced frames older than it were skipped."""
        self.received += 1
        older = 0
        while self._announced and self._announced[0] < stamp_ns:
            self._announced.popleft()
            older += 1
        if self._announced and self._announced[0] == stamp_ns:
            self._announced.popleft()
            self._per_frame = True
        else:
            self._taken.append(stamp_ns)
        if self.received > 1:  # before the first frame the node was not listening: nothing was skipped
            self._skipped += older

    @property
    def skipped(self) -> int | None:
        """Frames the camera announced that never reached the node; None while that cannot be known."""
        return self._skipped if self._per_frame else None
