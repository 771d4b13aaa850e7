"""Which camera frames the area node measured and which it skipped. No ROS here.

The node measures in its image callback on a depth-1 best-effort subscription: while it measures, DDS keeps
only the newest frame and discards older ones inside the middleware, without a copy into Python (taking
every frame into Python and dropping it there fell well behind, bench/ros_pipeline.py). Frames
skipped that way never reach the node; they are counted from `camera_info`, which ROS camera drivers (and
camera_node) publish with every frame under that frame's stamp, from the first frame the node takes on. A
camera_info that is not per frame (one latched calibration) leaves the count unknown (None), never a wrong
number. A frame that never arrived is *skipped* when the node was busy measuring between its camera_info
and the next one (its image waited in the depth-1 queue and a newer one replaced it), *lost* when the node
was mostly waiting then and the image still did not come (the transport lost it).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

REMEMBERED = 256  # stamps kept on each side: far more than frames in flight between the two topics
# frames announced and not yet taken: a node held up (a loaded machine) while a fast camera runs on; one
# forgotten beyond this is still counted, as skipped or lost, when it is dropped
WAITING = 4096


class FrameTally:
    def __init__(self) -> None:
        self._announced: deque[int] = deque()  # camera_info stamps not yet accounted for (at most WAITING)
        self._received_at: dict[int, int] = {}  # announced stamp -> when its camera_info was received (ns)
        self._heard: deque[int] = deque(maxlen=REMEMBERED)  # every stamp announced (one frame heard twice is one)
        self._taken: deque[int] = deque(maxlen=REMEMBERED)  # frames whose camera_info may still come
        self._per_frame = False  # a taken frame's stamp was announced: camera_info comes with every frame
        self.received = 0  # frames taken
        self._skipped = 0  # frames never taken while the node was busy, after the first frame taken
        self._lost = 0  # frames never taken although the node was idle, after the first frame taken
        self._busy_between: Callable[[int, int], bool] = lambda start, end: True  # the last `took` was given

    def announce(self, stamp_ns: int, received_ns: int = 0) -> None:
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
            self._received_at[stamp_ns] = received_ns
            if len(self._announced) > WAITING:  # so many newer frames since: its image will not come
                self._count_missing(self._announced.popleft(), received_ns)

    def _count_missing(self, missing: int, now_ns: int) -> None:
        """An announced frame whose image never came: skipped if the node was measuring between its camera_info
        and the next one's (or now: the time its image had to be taken), else lost. Nothing is counted before
        the node took its first frame: it was not listening."""
        until_ns = self._received_at.get(self._announced[0], now_ns) if self._announced else now_ns
        busy = self._busy_between(self._received_at.pop(missing, 0), until_ns)
        if self.received >= 1:
            if busy:
                self._skipped += 1
            else:
                self._lost += 1

    def took(self, stamp_ns: int, now_ns: int = 0,
             busy_between: Callable[[int, int], bool] = lambda start, end: True) -> None:
        """A frame with this stamp reached the node (at `now_ns`); announced frames older than it never did:
        skipped if `busy_between(their camera_info, the next one)` says the node was measuring meanwhile, else
        lost."""
        self._busy_between = busy_between
        while self._announced and self._announced[0] < stamp_ns:
            self._count_missing(self._announced.popleft(), now_ns)
        self.received += 1
        if self._announced and self._announced[0] == stamp_ns:
            self._received_at.pop(self._announced.popleft(), None)
            self._per_frame = True
        else:
            self._taken.append(stamp_ns)

    @property
    def skipped(self) -> int | None:
        """Frames the camera announced that were replaced while the node measured; None while unknown."""
        return self._skipped if self._per_frame else None

    @property
    def lost(self) -> int | None:
        """Frames the camera announced while the node was idle that never arrived; None while unknown."""
        return self._lost if self._per_frame else None
