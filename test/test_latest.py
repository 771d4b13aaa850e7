"""The newest-frame slot between the area node's subscription and its worker (issue #7)."""

import threading
import time

from veg_area_ros.latest import LatestSlot


def test_newest_frame_wins_and_replaced_frames_are_counted():
    slot = LatestSlot[int]()
    for k in range(5):
        slot.put(k)
    assert slot.take(0.1) == 4
    assert (slot.received, slot.dropped) == (5, 4)
    assert slot.take(0.05) is None  # nothing new: waits, then gives up


def test_a_slow_consumer_holds_one_frame_and_sees_the_latest():
    slot = LatestSlot[int]()
    seen: list[int] = []

    def consume() -> None:
        while (item := slot.take(2.0)) is not None:
            seen.append(item)
            time.sleep(0.01)  # slower than the producer

    worker = threading.Thread(target=consume)
    worker.start()
    for k in range(300):
        slot.put(k)
        time.sleep(0.0005)
    time.sleep(0.05)
    slot.close()
    worker.join(5)
    assert not worker.is_alive()
    assert seen == sorted(seen) and seen[-1] == 299  # in order, and the last frame was measured
    assert slot.received == 300 and slot.dropped == 300 - len(seen) > 0
