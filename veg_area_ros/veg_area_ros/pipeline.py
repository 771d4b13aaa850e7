"""Overlapping the work of a sequential run on a machine's cores: the next frames read (decoded) while this one
is measured, and a function mapped over items by a few threads, with the results in the items' order. Both
lean on OpenCV, which releases Python's lock while it decodes, remaps and detects. Same items, same order,
same results as a plain loop; an error is raised where the loop would have met it.

Imports nothing of the package.
"""

from __future__ import annotations

import collections
import queue
import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

Item = TypeVar("Item")
Result = TypeVar("Result")
_END = object()


class _Failed:
    def __init__(self, error: BaseException):
        self.error = error


def prefetched(items: Iterator[Item], depth: int = 2) -> Iterator[Item]:
    """`items` read ahead by a thread, at most `depth` waiting: a video costs about the larger of decoding and
    measuring rather than their sum. Stopping early (a break, Ctrl-C) stops the reader and closes `items`."""
    waiting: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def put(item: Item) -> bool:
        while not stop.is_set():
            try:
                waiting.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def read() -> None:
        try:
            for item in items:
                if not put(item):
                    break
            else:
                put(_END)
        except BaseException as error:  # raised in the consumer, at the item where it happened
            put(_Failed(error))
        finally:
            close = getattr(items, "close", None)
            if close is not None:
                close()  # a video's capture released, a bag's reader closed

    reader = threading.Thread(target=read, name="prefetch", daemon=True)
    reader.start()
    try:
        while True:
            item = waiting.get()
            if item is _END:
                return
            if isinstance(item, _Failed):
                raise item.error
            yield item
    finally:
        stop.set()
        reader.join(timeout=10)


def ordered_map(function: Callable[[Item], Result], items: Iterable[Item], workers: int = 2,
                ahead: int = 4) -> Iterator[tuple[Item, Result]]:
    """(item, function(item)) in the items' order, computed by `workers` threads with at most `ahead` items
    taken beyond the one being returned (bounded memory for a folder of large photos)."""
    if workers <= 1:
        for item in items:
            yield item, function(item)
        return
    with ThreadPoolExecutor(workers, thread_name_prefix="ordered-map") as pool:
        pending: collections.deque = collections.deque()
        iterator = iter(items)
        try:
            for item in iterator:
                pending.append((item, pool.submit(function, item)))
                if len(pending) > ahead:
                    done, future = pending.popleft()
                    yield done, future.result()
            while pending:
                done, future = pending.popleft()
                yield done, future.result()
        finally:
            for _, future in pending:
                future.cancel()
