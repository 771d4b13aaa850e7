"""A fast stream thinned before it costs a reader anything: a DDS content filter (ROS 2's content-filtered
subscription) on the messages' header stamp. No ROS here; the console node applies the filter.

Every message a Python node takes costs it about half a millisecond (the executor, the transport and the
message), so a viewer that takes every result of a 300 Hz measurement spends a seventh of a core on results it
shows a few of. The filter passes the messages whose stamp lies in one of a few windows a second, each one and a
half frame periods wide: a steady stream has at least one frame in every window at any phase (a camera at
exactly 30 Hz never misses them all), and about `per_s` a second pass whatever the rate. The stream's rate comes
from a counter the messages carry (the area node's frames measured), so the thinned messages still tell it.
A stream slow enough that the windows would pass half of it is not filtered at all."""

from __future__ import annotations

import math
from dataclasses import dataclass

NS_PER_S = 1_000_000_000
WINDOW_PERIODS = 1.5  # each window is this many frame periods wide: never empty for a steady stream
RATE_SPAN_S = 2.0  # the rate is measured over at least this much of the stream's time
REFILTER_CHANGE = 0.25  # the windows are moved only when the rate changed by more than this share


def stamp_windows(rate_hz: float | None, per_s: float) -> tuple[str, list[str]] | None:
    """A content filter (expression, parameters) passing about `per_s` messages a second of a stream at
    `rate_hz` by their header stamp, or None where it would pass half or more (or the rate is not known)."""
    if rate_hz is None or not math.isfinite(rate_hz) or rate_hz <= 0 or per_s <= 0:
        return None
    width_ns = int(WINDOW_PERIODS * NS_PER_S / rate_hz)
    count = max(1, math.ceil(per_s / WINDOW_PERIODS))
    period_ns = NS_PER_S // count
    if 2 * width_ns >= period_ns:
        return None
    terms, parameters = [], []
    for k, (start, end) in enumerate(window_bounds(width_ns, count)):
        terms.append(f"(header.stamp.nanosec >= %{2 * k} AND header.stamp.nanosec < %{2 * k + 1})")
        parameters += [str(start), str(end)]
    return " OR ".join(terms), parameters


def window_bounds(width_ns: int, count: int) -> list[tuple[int, int]]:
    """The windows [start, end) within each second's nanoseconds, evenly spaced."""
    period_ns = NS_PER_S // count
    return [(k * period_ns, k * period_ns + width_ns) for k in range(count)]


def passes(stamp_ns: int, parameters: list[str]) -> bool:
    """Whether a message stamped `stamp_ns` passes the filter of these parameters (as DDS evaluates it)."""
    nanosec = stamp_ns % NS_PER_S
    bounds = [int(p) for p in parameters]
    return any(start <= nanosec < end for start, end in zip(bounds[::2], bounds[1::2], strict=True))


@dataclass
class StreamRate:
    """A stream's rate from a counter its messages carry and their stamps, however thinned the messages that
    bring them; None until RATE_SPAN_S of it has been seen. A counter that went back (the node restarted, a
    replay began again) starts the measurement afresh."""

    rate_hz: float | None = None
    _since: tuple[float, int] | None = None

    def add(self, stamp_s: float, count: int) -> float | None:
        if count < 0 or not math.isfinite(stamp_s) or stamp_s <= 0:
            return self.rate_hz
        if self._since is None or count < self._since[1] or stamp_s < self._since[0]:
            self._since = (stamp_s, count)
            return self.rate_hz
        span = stamp_s - self._since[0]
        if span >= RATE_SPAN_S:
            self.rate_hz = (count - self._since[1]) / span
            self._since = (stamp_s, count)
        return self.rate_hz


@dataclass
class Thinning:
    """The filter a reader of one stream wants, moved only when the rate changed by more than REFILTER_CHANGE
    (each change costs the DDS reader a reconfiguration)."""

    per_s: float
    applied_rate_hz: float | None = None
    filtered: bool = False

    def change(self, rate_hz: float | None) -> tuple[str, list[str]] | bool | None:
        """The new filter for this rate, None to pass everything, or False when the applied one stays."""
        wanted = stamp_windows(rate_hz, self.per_s)
        if wanted is None:
            if not self.filtered:
                return False
            self.filtered, self.applied_rate_hz = False, None
            return None
        if self.filtered and abs(rate_hz / self.applied_rate_hz - 1) <= REFILTER_CHANGE:
            return False
        self.filtered, self.applied_rate_hz = True, rate_hz
        return wanted
